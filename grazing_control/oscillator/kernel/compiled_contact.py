"""Compiled mirror of the Kelvin-Voigt stop's bracketing (:func:`grazing_control.oscillator.
contact._bracket` on a region's gap or contact force), in the same floating point
operations and the same order, so that it gives the same floats (tests/
test_compliant_flow_bits.py runs the flow's digest on both paths).

The bracketing is about half of the compliant flow's time (issue 30, the suite's CPU:
cProfile of test_stop_selection's fits, docs/benchmarks.md "The compliant stop's hot
path"): its safeguarded secant mostly bisects, some 50 evaluations of the region's
closed form per switching time. Compiled by the kernel's ``jit``, whose on-disk cache
is stamped by every file of the folder (:mod:`.caching`).
"""

from __future__ import annotations

import math

import numpy as np

from .caching import jit

__all__ = ["GAP", "FORCE", "bracket_region"]

#: what is bracketed: the gap delta (_Region.gap) or the force k delta + c delta'
#: (_Region.force_value)
GAP, FORCE = 0, 1


@jit
def _ulp(x):
    """math.ulp(x) for finite x."""
    a = abs(x)
    return np.nextafter(a, np.inf) - a


@jit
def _value(h, kind, k, c, tau0, omega, lag, amp, offset, beta, big_om, c1, c2, av, wa, wb,
           kk, rate):
    """_Region.gap (kind GAP) or _Region.force_value (kind FORCE) at h."""
    psi = tau0 + omega * h - lag
    e = math.exp(-beta * h)
    oh = big_om * h
    cs = math.cos(oh)
    sn = math.sin(oh)
    d = amp * math.cos(psi) + offset + e * (c1 * cs + c2 * sn)
    if kind == GAP:
        if kk != 0.0:
            return d + kk * math.exp(-rate * h)
        return d
    v = av * math.sin(psi) + e * (wa * cs - wb * sn)
    if kk != 0.0:
        ek = kk * math.exp(-rate * h)
        d, v = d + ek, v - rate * ek
    return k * d + c * v


@jit
def bracket_region(lo, hi, sign, flo, fhi, kind, k, c, tau0, omega, lag, amp, offset, beta,
                   big_om, c1, c2, av, wa, wb, kk, rate):
    """contact._bracket with ``value`` the region's gap or force (:func:`_value`)."""
    flo, fhi = sign * flo, sign * fhi
    while True:
        width = hi - lo
        if not width > 4.0 * _ulp(hi):
            break
        x = lo + width * (flo / (flo - fhi)) if fhi != flo else 0.5 * (lo + hi)
        if not lo < x < hi or (x - lo) < 0.01 * width or (hi - x) < 0.01 * width:
            x = 0.5 * (lo + hi)
        fx = sign * _value(x, kind, k, c, tau0, omega, lag, amp, offset, beta, big_om, c1,
                           c2, av, wa, wb, kk, rate)
        if fx >= 0.0:
            hi, fhi = x, fx
        else:
            lo, flo = x, fx
    return hi

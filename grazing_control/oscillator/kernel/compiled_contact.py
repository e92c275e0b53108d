"""Compiled mirror of the Kelvin-Voigt stop's certified switching search
(:func:`grazing_control.oscillator.contact._first_crossing` on a region's gap or contact
force, or a friction's slip end: :func:`first_crossing_region`) and its bracketing
(``contact._bracket``, :func:`bracket_region`), in the same floating point operations and
the same order, so that it gives the same floats (tests/test_compliant_flow_bits.py runs
the flow's digests on both paths).

The search is most of the compliant flow's time (issue 30, the suite's CPU: cProfile of
test_stop_selection's fits, docs/benchmarks.md "The compliant stop's hot path"): an
interval is excluded or bisected on a bound of the second derivative, and a root's
safeguarded secant mostly bisects, some 50 evaluations of the region's closed form per
switching time. Compiled by the kernel's ``jit``, whose on-disk cache is stamped by every
file of the folder (:mod:`.caching`).
"""

from __future__ import annotations

import math

import numpy as np

from .caching import jit

__all__ = ["GAP", "FORCE", "SLIP", "NONE", "bracket_region", "first_crossing_region"]

#: what is bracketed: the gap delta (_Region.gap) or the force k delta + c delta'
#: (_Region.force_value); SLIP: the end of a friction's slip, -s delta' with the slip's
#: direction s in ``k`` (contact.advance_compliant's h_stop: the event -s (delta',
#: delta''), the bound _Region.bound(3, h), bracketed on the event's first value)
GAP, FORCE, SLIP = 0, 1, 2


@jit
def _ulp(x):
    """math.ulp(x) for finite x."""
    a = abs(x)
    return np.nextafter(a, np.inf) - a


@jit
def _value(h, kind, k, c, tau0, omega, lag, amp, offset, beta, big_om, c1, c2, av, wa, wb,
           kk, rate):
    """_Region.gap (kind GAP), _Region.force_value (kind FORCE) or -k delta' (SLIP: the
    first value of contact's slip event, ``-s * reg(h)[1]``) at h."""
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
    if kind == SLIP:
        return -k * v
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


# ------------------------------------------------------------ the certified search
#: :func:`first_crossing_region`'s answer where there is no crossing (times are >= 0)
NONE = -1.0
#: contact._MAX_DEPTH: the bisection's deepest level
_MAX_DEPTH = 60
_EPS = 2.0 ** -52
#: the region's constants in the tuple ``R`` of :func:`first_crossing_region`, in this
#: order (contact._Region's attributes; bn2 .. kn3 its _bn[2], _bn[3], _an[2], ...)
(_TAU0, _OMEGA, _LAG, _AMP, _OFFSET, _BETA, _BIG_OM, _C1, _C2, _AV, _WA, _WB, _KK, _RATE,
 _AA, _B2, _W2, _R2, _BN2, _BN3, _AN2, _AN3, _KN2, _KN3) = range(24)


@jit
def _state(R, h):
    """_Region.__call__: (delta, delta', delta'') at h."""
    psi = R[_TAU0] + R[_OMEGA] * h - R[_LAG]
    cp = math.cos(psi)
    e = math.exp(-R[_BETA] * h)
    oh = R[_BIG_OM] * h
    c = math.cos(oh)
    s = math.sin(oh)
    w = e * (R[_C1] * c + R[_C2] * s)
    wv = e * (R[_WA] * c - R[_WB] * s)
    d = R[_AMP] * cp + R[_OFFSET] + w
    v = R[_AV] * math.sin(psi) + wv
    acc = R[_AA] * cp - R[_B2] * wv - R[_W2] * w
    kk = R[_KK]
    if kk != 0.0:
        ek = kk * math.exp(-R[_RATE] * h)
        return d + ek, v - R[_RATE] * ek, acc + R[_R2] * ek
    return d, v, acc


@jit
def _event(R, kind, k, c, h):
    """The searched function and its derivative at h: the gap (delta, delta') (contact's
    ``reg(h)[:2]``), the force (k delta + c delta', k delta' + c delta'')
    (contact._force_event) or the slip's velocity (-k delta', -k delta'') (SLIP, ``k``
    the slip's direction s: contact's ``-s * u for u in reg(h)[1:]``)."""
    d, v, a = _state(R, h)
    if kind == GAP:
        return d, v
    if kind == SLIP:
        return -k * v, -k * a
    return k * d + c * v, k * v + c * a


@jit
def _bound2(R, kind, k, c, h):
    """A bound on the searched function's second derivative on [h, inf): _Region.bound(2,
    h) for the gap, _Region.force_bound(k, c, h) for the force, _Region.bound(3, h) for
    the slip's velocity."""
    e = math.exp(-R[_BETA] * h)
    kk = R[_KK]
    if kind == GAP:
        out = R[_BN2] * e + R[_AN2]
        if kk != 0.0:
            out += R[_KN2] * math.exp(-R[_RATE] * h)
        return out
    if kind == SLIP:
        out = R[_BN3] * e + R[_AN3]
        if kk != 0.0:
            out += R[_KN3] * math.exp(-R[_RATE] * h)
        return out
    b2 = R[_BN2] * e + R[_AN2]
    b3 = R[_BN3] * e + R[_AN3]
    if kk != 0.0:
        ek = math.exp(-R[_RATE] * h)
        b2 += R[_KN2] * ek
        b3 += R[_KN3] * ek
    return k * b2 + c * b3


@jit
def _bracket_r(R, kind, k, c, lo, hi, sign, flo, fhi):
    return bracket_region(lo, hi, sign, flo, fhi, kind, k, c, R[_TAU0], R[_OMEGA], R[_LAG],
                          R[_AMP], R[_OFFSET], R[_BETA], R[_BIG_OM], R[_C1], R[_C2], R[_AV],
                          R[_WA], R[_WB], R[_KK], R[_RATE])


@jit
def _crossing_in(R, kind, k, c, a, b, fa0, fa1, fb0, fb1, sign, margin, start, stack):
    """contact._crossing_in, its recursion as a stack of pending intervals (the left half
    first, as the recursion takes it): the crossing's time or NONE."""
    # a row: a, b, f(a), f'(a), f(b), f'(b), depth, start
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = a, b, fa0, fa1
    stack[0, 4], stack[0, 5], stack[0, 6], stack[0, 7] = fb0, fb1, 0.0, 1.0 if start else 0.0
    top = 1
    while top > 0:
        top -= 1
        a, b, fa0, fa1 = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        fb0, fb1, depth, start = stack[top, 4], stack[top, 5], stack[top, 6], stack[top, 7] != 0.0
        sa, sb = sign * fa0, sign * fb0
        da, db = sign * fa1, sign * fb1
        if start and sa >= -margin and da < 0.0:
            sa = -0.0  # on the surface and leaving it: not a crossing
        m = _bound2(R, kind, k, c, a) * (b - a) * (1.0 + 1e-12)
        if sa >= 0.0 and not start:
            return a
        if (da > 0.0 and db > 0.0 or da < 0.0 and db < 0.0) and abs(da) + abs(db) > m:
            # monotone: a crossing iff the ends straddle 0
            if sb >= 0.0 and sa < 0.0:
                return _bracket_r(R, kind, k, c, a, b, sign, fa0, fb0)
            continue
        upper = (sb if sb > sa else sa) + 0.125 * (b - a) * m      # Python's max(sa, sb)
        if upper < -margin:
            continue
        if depth >= _MAX_DEPTH or b - a <= 4.0 * _ulp(b):
            if sa < 0.0 <= sb:
                return _bracket_r(R, kind, k, c, a, b, sign, fa0, fb0)
            continue
        mid = 0.5 * (a + b)
        fm0, fm1 = _event(R, kind, k, c, mid)
        # the right half below the left one: the left is searched first
        stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = mid, b, fm0, fm1
        stack[top, 4], stack[top, 5], stack[top, 6], stack[top, 7] = fb0, fb1, depth + 1.0, 0.0
        top += 1
        stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = a, mid, fa0, fa1
        stack[top, 4], stack[top, 5], stack[top, 6] = fm0, fm1, depth + 1.0
        stack[top, 7] = 1.0 if start else 0.0
        top += 1
    return NONE


@jit
def first_crossing_region(R, kind, k, c, horizon, sign, scale):
    """contact._first_crossing on a region's gap (``kind`` GAP: the event reg(h)[:2], the
    bound reg.bound(2, h)), contact force (FORCE: contact._force_event and
    _force_bound), the bracketing by :func:`bracket_region`, or a friction's slip (SLIP:
    the slip's direction s in ``k``, bracketed on the event): the first h in (0, horizon]
    at which sign * f(h) >= 0 after being < 0, or NONE. ``R``: the region's constants
    (:data:`_TAU0` ...)."""
    margin = 64.0 * _EPS * scale
    n = max(1, int(math.ceil(horizon / (0.25 * math.pi))))
    stack = np.empty((_MAX_DEPTH + 2, 8))
    a = 0.0
    fa0, fa1 = _event(R, kind, k, c, 0.0)
    start = True
    for j in range(1, n + 1):
        b = horizon if j == n else j * horizon / n
        fb0, fb1 = _event(R, kind, k, c, b)
        root = _crossing_in(R, kind, k, c, a, b, fa0, fa1, fb0, fb1, sign, margin, start,
                            stack)
        if root != NONE:
            return root
        a, fa0, fa1, start = b, fb0, fb1, False
    return NONE

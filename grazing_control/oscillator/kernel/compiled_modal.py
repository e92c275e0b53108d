"""Compiled mirror of the n-DOF certified event search
(:func:`grazing_control.oscillator.ndof.impact.next_impact`; issue 32: the rig of n
masses at physical speed).

The same algorithm as the pure path, function by function and in the same floating
point operations and order, so that it returns the same floats (tests/test_ndof_compiled.py,
thousands of seeded cases against the pure path, near-grazing ones included):

=====================  ==========================================================
here                   the pure path
=====================  ==========================================================
:func:`make_eval`      ``ndof.impact._Eval.__init__`` (written out term by term there)
:func:`evaluate`       ``_Eval.__call__`` (``cmath.exp(lam * h)`` as CPython computes it)
:func:`jerk_bound`     ``_Eval.jerk_bound``
:func:`gap_rounding`   ``_Eval.gap_rounding``
:func:`bracket`        ``oscillator.impact._bracket``
:func:`search`         ``oscillator.impact._search`` (its recursion on an explicit stack)
:func:`next_impact`    ``ndof.impact._next_impact`` with ``oscillator.impact._scan_window``,
                       ``_danger_halfwidth``, ``_far_from_wall``
=====================  ==========================================================

The interval search (:func:`bracket`, :func:`search`, the window's ``danger_halfwidth``
and ``far_from_wall``) is the 1-DOF kernel's, written once for both models in
:mod:`.interval_search` and imported here: it reaches this model's :func:`evaluate`,
:func:`jerk_bound` and :func:`gap_rounding` (``terms`` the array of modes), as the pure
path's ``_search`` runs over either evaluator.

CPython's arithmetic, written out: a complex times a float promotes the float to a
complex (Python 3.11), ``(a + ib) h = (a h - b 0) + i (a 0 + b h)``; a product of two
complex numbers is ``(ac - bd) + i (ad + bc)``; ``cmath.exp(x + iy)`` is
``(e^x cos y, e^x sin y)`` (below e^709, which a decaying mode never reaches);
``abs`` of a complex number is libm's ``hypot``; ``x ** 2`` is libm's ``pow``, which this
module calls with the exponent passed at run time (``two``: a literal 2 would become a
multiplication, oscillator/kernel/compiled.py ``power``). The powers of the model's
numbers and everything else that depends on the flow only come computed by the pure
path's :func:`~grazing_control.oscillator.ndof.impact.search_constants`.

numba's on-disk cache of these functions is stamped by every file of the kernel folder
(:mod:`.caching`), so an edit of the search recompiles this module's callers of it. A
start beyond the wall comes back as
``STATUS_BEYOND_WALL`` with the gap, through
:func:`grazing_control.oscillator.kernel.modal_search`'s function, and ndof.impact raises
the pure path's error with it.
"""

from __future__ import annotations

import math

import numpy as np

from .caching import jit
from .interval_search import (NONE, bracket, danger_halfwidth, far_from_wall, search,
                              search_stack, ulp)

__all__ = ["make_eval", "evaluate", "jerk_bound", "gap_rounding", "bracket", "search",
           "search_stack", "next_impact", "NONE", "STATUS_OK", "STATUS_BEYOND_WALL"]

TWO_PI = 2.0 * math.pi
_EPS = 2.0 ** -52
STATUS_OK = 0
STATUS_BEYOND_WALL = 2  # InitialStateError (info: the gap at the start)

# the search constants' scalars (ndof.impact.SearchConstants.scalars), in this order
_OMEGA, _LAG, _AMP, _DD, _N, _AW3, _DRIFT, _OMEGA2, _RHO, _RHO2, _STEP, _TWO = range(12)
# the evaluator: ev = (omega, lag, amp, dd, tau0, n, aw3, cabs, acc_err, m0, m1, zmag, rho,
# drift, two) and the terms, one row a mode: (Re lam, Im lam, Re c, Im c, Re c lam,
# Im c lam, Re c lam^2, Im c lam^2, |c| |lam|^3, e^{max(Re lam, 0) horizon})
_CABS, _ACC_ERR, _M0, _M1, _ZMAG = 7, 8, 9, 10, 11



@jit
def make_eval(table, S, tau0, z0, horizon):
    """ndof.impact._Eval.__init__ (without the lag's transient): (ev, terms), the comment
    above. ``table``, ``S``: the flow's ``SearchConstants.table`` and ``.scalars``."""
    m, n2 = table.shape[0], z0.shape[0]
    terms = np.empty((m, 10))
    zmag = 0.0
    for k in range(m):
        br = 0.0
        bi = 0.0
        s = 0.0
        for j in range(n2):                   # beta_k = (V^-1 z0)_k
            zl = z0[j]
            br += table[k, 6 + j] * zl
            bi += table[k, 6 + n2 + j] * zl
            s += table[k, 6 + 2 * n2 + j] * abs(zl)
        vr, vi = table[k, 2], table[k, 3]
        cr = vr * br - vi * bi
        ci = vr * bi + vi * br
        lr, li = table[k, 0], table[k, 1]
        c1r = cr * lr - ci * li               # c lambda
        c1i = cr * li + ci * lr
        terms[k, 0], terms[k, 1], terms[k, 2], terms[k, 3] = lr, li, cr, ci
        terms[k, 4], terms[k, 5] = c1r, c1i
        terms[k, 6] = c1r * lr - c1i * li     # (c lambda) lambda
        terms[k, 7] = c1r * li + c1i * lr
        terms[k, 8] = math.hypot(cr, ci) * table[k, 5]
        terms[k, 9] = math.exp(max(lr, 0.0) * horizon)
        zmag += table[k, 4] * s
    cabs = 0.0
    grow = 0.0
    for k in range(m):
        cabs += math.hypot(terms[k, 2], terms[k, 3]) * terms[k, 9]
        grow = terms[k, 9] if k == 0 or terms[k, 9] > grow else grow
    zmag = zmag * grow + 0.0
    norm2 = 0.0
    for j in range(n2):
        norm2 += z0[j] * z0[j]
    drift = S[_DRIFT] * math.sqrt(norm2)
    omega, lag, amp, dd, rho, rho2 = S[_OMEGA], S[_LAG], S[_AMP], S[_DD], S[_RHO], S[_RHO2]
    n = 2.0 * S[_N] + 2.0
    phase0 = abs(tau0) + abs(lag) + 1.0
    acc_err = (8.0 * _EPS * (amp * S[_OMEGA2] * (4.0 + phase0 + omega * horizon)
                             + zmag * rho2 * (n + rho * horizon))
               + 2.0 * horizon * drift * rho2)
    m0 = 8.0 * _EPS * (zmag * n + abs(dd) + 2.0 * amp * (1.0 + phase0))
    m1 = 8.0 * _EPS * (zmag * rho + 2.0 * amp * omega) + 2.0 * drift
    ev = (omega, lag, amp, dd, tau0, S[_N], S[_AW3], cabs, acc_err, m0, m1, zmag, rho, drift,
          S[_TWO])
    return ev, terms


@jit
def evaluate(ev, terms, h):
    """_Eval.__call__: (g, v, acc, z_w) at time h, the exact closed form."""
    zx = 0.0
    v = 0.0
    a = 0.0
    for k in range(terms.shape[0]):
        lr, li = terms[k, 0], terms[k, 1]
        xr = lr * h - li * 0.0                # lam * h, h promoted to complex
        xi = lr * 0.0 + li * h
        el = math.exp(xr)                     # cmath.exp
        er = el * math.cos(xi)
        ei = el * math.sin(xi)
        zx += terms[k, 2] * er - terms[k, 3] * ei
        v += terms[k, 4] * er - terms[k, 5] * ei
        a += terms[k, 6] * er - terms[k, 7] * ei
    omega, lag, amp, dd, tau0 = ev[0], ev[1], ev[2], ev[3], ev[4]
    psi = tau0 + omega * h - lag
    sh = math.sin(0.5 * psi)
    g = zx - dd - 2.0 * amp * sh * sh
    vel = -amp * omega * math.sin(psi) + v
    acc = -amp * omega * omega * math.cos(psi) + a
    return g, vel, acc, zx


@jit
def jerk_bound(ev, terms, h):
    """_Eval.jerk_bound: J >= max |g'''| on [h, horizon]."""
    j = ev[6]
    for k in range(terms.shape[0]):
        re = terms[k, 0]
        j += terms[k, 8] * (math.exp(re * h) if re <= 0.0 else terms[k, 9])
    return j


@jit
def gap_rounding(ev, h, g, zx):
    """_Eval.gap_rounding: bound on |computed g(h) - exact g(h)|."""
    dd = ev[3]
    s2 = abs(zx - dd - g)
    phase = abs(ev[4]) + ev[0] * h + abs(ev[1]) + 1.0
    return (8.0 * _EPS * (ev[_ZMAG] * (2.0 * ev[5] + 2.0 + ev[12] * h) + abs(dd) + s2
                          + math.sqrt(2.0 * ev[2] * s2) * phase)
            + 2.0 * h * ev[13])


@jit
def next_impact(table, S, tau0, z0, horizon, max_step, stack):
    """ndof.impact._next_impact (inputs checked, horizon > 0): (time of the first impact
    in (0, horizon] or NONE, status, info); ``max_step`` <= 0: the default window;
    STATUS_BEYOND_WALL with info = the gap where the pure path raises InitialStateError."""
    ev, terms = make_eval(table, S, tau0, z0, horizon)
    # whole-window exclusion: g <= sup |z_w| - Delta d <= sum |c_k| - Delta d
    if ev[_CABS] * (1.0 + 4.0 * _EPS) + ev[_M0] + ev[_M1] * horizon < ev[3]:
        return NONE, STATUS_OK, 0.0
    step = max_step if max_step > 0.0 else S[_STEP]
    count = max(1, int(math.ceil(horizon / step)))
    # impact._scan_window
    a = 0.0
    ga, va, acca, zxa = evaluate(ev, terms, 0.0)
    # on the wall up to rounding: above it, or below it while leaving (v < 0)
    if (ga > 0.0 or ga < 0.0 and va < 0.0) and abs(ga) <= gap_rounding(ev, 0.0, ga, zxa):
        ga = 0.0
    if ga > 0.0:
        return NONE, STATUS_BEYOND_WALL, ga
    if ga == 0.0 and va > 0.0:
        return 0.0, STATUS_OK, 0.0  # on the wall, moving into it
    fa = (ga, va, acca, zxa)
    w = danger_halfwidth(ev[_CABS], ev[3], ev[2], ev[_M0], ev[_M1], horizon)
    valid = True  # fa holds the values at a
    omega, lag = ev[0], ev[1]
    for k in range(1, count + 1):
        b = horizon if k == count else k * (horizon / count)
        if k > 1 and w >= 0.0 and far_from_wall(tau0 + omega * a - lag,
                                                tau0 + omega * b - lag, w):
            a, valid = b, False  # g < 0 on all of [a, b]: the search would find nothing
            continue
        if not valid:
            fa = evaluate(ev, terms, a)
            valid = True
        fb = evaluate(ev, terms, b)
        r = search(ev, terms, a, b, fa, fb, stack)
        if r != NONE:
            return r, STATUS_OK, 0.0
        a, fa = b, fb
    return NONE, STATUS_OK, 0.0

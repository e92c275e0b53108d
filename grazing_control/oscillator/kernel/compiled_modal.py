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

CPython's arithmetic, written out: a complex times a float promotes the float to a
complex (Python 3.11), ``(a + ib) h = (a h - b 0) + i (a 0 + b h)``; a product of two
complex numbers is ``(ac - bd) + i (ad + bc)``; ``cmath.exp(x + iy)`` is
``(e^x cos y, e^x sin y)`` (below e^709, which a decaying mode never reaches);
``abs`` of a complex number is libm's ``hypot``; ``x ** 2`` is libm's ``pow``, which this
module calls with the exponent passed at run time (``two``: a literal 2 would become a
multiplication, oscillator/kernel/compiled.py ``power``). The powers of the model's
numbers and everything else that depends on the flow only come computed by the pure
path's :func:`~grazing_control.oscillator.ndof.impact.search_constants`.

Only this module's functions are compiled here and none calls another file's, so numba's
on-disk cache (``cache=True``, keyed on this file) never loads stale code
(oscillator/kernel/compiled.py, module docstring); :func:`ulp` and the stack's layout
are therefore this module's own. A start beyond the wall comes back as
``STATUS_BEYOND_WALL`` with the gap, through
:func:`grazing_control.oscillator.kernel.modal_search`'s function, and ndof.impact raises
the pure path's error with it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["make_eval", "evaluate", "jerk_bound", "gap_rounding", "bracket", "search",
           "search_stack", "next_impact", "NONE", "STATUS_OK", "STATUS_BEYOND_WALL"]

TWO_PI = 2.0 * math.pi
_MAX_DEPTH = 64
_EPS = 2.0 ** -52
NONE = -1.0  # "no impact" (times are >= 0)
STATUS_OK = 0
STATUS_BEYOND_WALL = 2  # InitialStateError (info: the gap at the start)

# the search constants' scalars (ndof.impact.SearchConstants.scalars), in this order
_OMEGA, _LAG, _AMP, _DD, _N, _AW3, _DRIFT, _OMEGA2, _RHO, _RHO2, _STEP, _TWO = range(12)
# the evaluator: ev = (omega, lag, amp, dd, tau0, n, aw3, cabs, acc_err, m0, m1, zmag, rho,
# drift, two) and the terms, one row a mode: (Re lam, Im lam, Re c, Im c, Re c lam,
# Im c lam, Re c lam^2, Im c lam^2, |c| |lam|^3, e^{max(Re lam, 0) horizon})
_CABS, _ACC_ERR, _M0, _M1, _ZMAG = 7, 8, 9, 10, 11

jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@jit
def ulp(x):
    """math.ulp(x) for finite x: the gap from |x| to the next float up."""
    a = abs(x)
    return np.nextafter(a, np.inf) - a


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
def bracket(ev, terms, lo, hi, which, sign, flo, fhi):
    """impact._bracket: root of g (which = 0) or v (which = 1) in [lo, hi]."""
    d = flo - fhi
    x = lo + (hi - lo) * (flo / d) if d != 0.0 else 0.5 * (lo + hi)
    if not lo < x < hi:
        x = 0.5 * (lo + hi)
    probed = False
    while hi - lo > 4.0 * ulp(hi):
        g, v, acc, _zx = evaluate(ev, terms, x)
        if which == 0:
            fx, dfx = sign * g, sign * v
        else:
            fx, dfx = sign * v, sign * acc
        if fx >= 0.0:
            hi = x
        else:
            lo = x
        xn = x - fx / dfx if dfx > 0.0 else lo
        probe = 2.0 * ulp(x)
        if abs(xn - x) < probe:  # 2 ulps past the root; bisect if the last probe failed
            xn = 0.5 * (lo + hi) if probed else (x - probe if fx >= 0.0 else x + probe)
            probed = not probed
        else:
            probed = False
        if not lo < xn < hi:
            xn = 0.5 * (lo + hi)
        if xn == x:
            xn = 0.5 * (lo + hi)
            if xn == x:
                break
        x = xn
    return hi


@jit
def _certified(ev, terms, a, b, ga, va, acca, zxa, gb, vb, accb, zxb):
    """The certified cases of impact._search on [a, b]: (decided, time), decided = 1 with
    time >= 0 (impact) or NONE (none), decided = 0 when the interval must be split."""
    jw = jerk_bound(ev, terms, a) * (b - a) * (1.0 + 1e-12) + 2.0 * ev[_ACC_ERR]
    concave = acca < 0.0 and accb < 0.0 and -(acca + accb) > jw
    convex = acca > 0.0 and accb > 0.0 and (acca + accb) > jw
    if concave:  # v decreasing: at most one maximum
        if va <= 0.0:
            return 1, NONE
        if vb >= 0.0:
            return 1, (bracket(ev, terms, a, b, 0, 1.0, ga, gb) if gb >= 0.0 else NONE)
        tm = bracket(ev, terms, a, b, 1, -1.0, va, vb)
        gm = evaluate(ev, terms, tm)[0]
        return 1, (bracket(ev, terms, a, tm, 0, 1.0, ga, gm) if gm >= 0.0 else NONE)
    if convex:  # v increasing: g below the chord unless it ends above 0
        if gb < 0.0:
            return 1, NONE
        if ga < 0.0:
            return 1, bracket(ev, terms, a, b, 0, 1.0, ga, gb)
        if va >= 0.0:  # at rest on the wall and pushed into it
            return 1, a
        tmin = bracket(ev, terms, a, b, 1, 1.0, va, vb) if vb > 0.0 else b
        gmin = evaluate(ev, terms, tmin)[0]
        if gmin >= 0.0:  # the dip below the wall is below rounding: at rest, pushed in
            return 1, tmin
        return 1, (bracket(ev, terms, tmin, b, 0, 1.0, gmin, gb) if gmin < 0.0 <= gb
                   else NONE)
    curvature = max(0.0, 0.5 * (jw - acca - accb))
    upper = max(ga, gb) + 0.125 * math.pow(b - a, ev[14]) * curvature
    if upper < 0.0 and (upper + ev[_M0] + ev[_M1] * b < 0.0 or
                        upper + max(gap_rounding(ev, a, ga, zxa), gap_rounding(ev, b, gb, zxb))
                        < 0.0):
        return 1, NONE
    return 0, NONE


@jit
def search(ev, terms, a, b, fa, fb, stack):
    """impact._search(f, a, b, fa, fb, 0): first impact time in (a, b], or NONE; the
    recursion (left half first) on an explicit stack of pending right halves."""
    top = 0
    ga, va, acca, zxa = fa[0], fa[1], fa[2], fa[3]
    gb, vb, accb, zxb = fb[0], fb[1], fb[2], fb[3]
    depth = 0
    while True:
        decided, t = _certified(ev, terms, a, b, ga, va, acca, zxa, gb, vb, accb, zxb)
        if not decided:
            if depth >= _MAX_DEPTH or b - a <= 4.0 * ulp(b):
                decided = 1
                t = bracket(ev, terms, a, b, 0, 1.0, ga, gb) if ga < 0.0 <= gb else NONE
        if decided:
            if t != NONE:
                return t
            if top == 0:
                return NONE
            top -= 1  # the pending right half of the nearest ancestor
            a, b = stack[top, 0], stack[top, 1]
            ga, va, acca, zxa = stack[top, 2], stack[top, 3], stack[top, 4], stack[top, 5]
            gb, vb, accb, zxb = stack[top, 6], stack[top, 7], stack[top, 8], stack[top, 9]
            depth = int(stack[top, 10])
            continue
        mid = 0.5 * (a + b)
        gm, vm, accm, zxm = evaluate(ev, terms, mid)
        stack[top, 0], stack[top, 1] = mid, b
        stack[top, 2], stack[top, 3], stack[top, 4], stack[top, 5] = gm, vm, accm, zxm
        stack[top, 6], stack[top, 7], stack[top, 8], stack[top, 9] = gb, vb, accb, zxb
        stack[top, 10] = depth + 1
        top += 1
        b, gb, vb, accb, zxb = mid, gm, vm, accm, zxm
        depth += 1


def search_stack():
    """The work array of :func:`search`: one row per pending interval."""
    return np.empty((_MAX_DEPTH + 2, 11))


@jit
def _danger_halfwidth(ev, horizon):
    """impact._danger_halfwidth; -1.0 for None."""
    s = (ev[_CABS] * (1.0 + 4.0 * _EPS) - ev[3] + ev[_M0] + ev[_M1] * horizon) / (2.0 * ev[2])
    if s >= 1.0:
        return -1.0
    return 2.0 * math.asin(math.sqrt(max(s, 0.0))) + 1e-9


@jit
def _far_from_wall(psi_a, psi_b, w):
    """impact._far_from_wall."""
    k = math.ceil((psi_a - w) / TWO_PI)
    return TWO_PI * k - w > psi_b


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
    w = _danger_halfwidth(ev, horizon)
    valid = True  # fa holds the values at a
    omega, lag = ev[0], ev[1]
    for k in range(1, count + 1):
        b = horizon if k == count else k * (horizon / count)
        if k > 1 and w >= 0.0 and _far_from_wall(tau0 + omega * a - lag,
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

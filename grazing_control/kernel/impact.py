"""Compiled mirror of :mod:`grazing_control.impact` (numba, nopython, cached).

Function by function the same algorithm as the pure-Python core, in the same floating
point operations and the same order, so that a fix there ports here line by line:

=========================  =======================================================
grazing_control.impact     here
=========================  =======================================================
``_Eval(p, tau0, z)``      :func:`make_eval` -> a tuple ``ev``; ``ev(h)`` is
                           :func:`evaluate`, ``ev.jerk_bound`` :func:`jerk_bound`
``_bracket``               :func:`bracket`
``_search`` (recursive)    :func:`search`: the same depth-first, left-first order
                           with an explicit stack
``next_impact``            :func:`next_impact` (None -> -1.0; InitialStateError ->
                           status STATUS_BEYOND_WALL)
``_release_time``,         :func:`release_time`, :func:`resting_on_wall`,
``_resting_on_wall``,      :func:`release_skip`
``_release_skip``
``advance``                :func:`advance` (no monodromy: that stays in the core);
                           impacts go to a caller's array, one row
                           (dt, phase, v-, v+, sticking, release) each
=========================  =======================================================

Model parameters travel as the tuple ``P`` of :func:`params_tuple` (derived quantities
computed once, by :class:`~grazing_control.params.OscillatorParams` itself, so that
both paths use the very same floats). Errors cannot be raised from compiled code with
the core's messages, so they come back as a status code and one number, and the
Python wrapper (:mod:`grazing_control.kernel`) raises the core's exception.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["params_tuple", "make_eval", "evaluate", "jerk_bound", "bracket", "search",
           "search_stack", "next_impact", "release_time", "resting_on_wall", "release_skip",
           "advance", "STATUS_OK", "STATUS_IMPACT_CAP", "STATUS_BEYOND_WALL", "STATUS_NONFINITE",
           "IMPACT_FIELDS"]

TWO_PI = 2.0 * math.pi
_MAX_DEPTH = 64
NONE = -1.0  # "no impact" (times are >= 0)

STATUS_OK = 0
STATUS_IMPACT_CAP = 1  # ImpactCapError
STATUS_BEYOND_WALL = 2  # InitialStateError
STATUS_NONFINITE = 4  # a non-finite start state or time (the core's search would not end)

#: Columns of an impact row.
IMPACT_FIELDS = ("dt", "phase", "v_minus", "v_plus", "sticking", "release")

# P: the model parameters, see params_tuple
_ZETA, _R, _OMEGA, _WD, _LAG, _AMP, _DD, _D, _PERIOD, _TAU2, _TWO, _THIRD = range(12)

jit = numba.njit(cache=True, nogil=True, error_model="numpy")


def params_tuple(p):
    """(zeta, r, omega, omega_d, lag, amplitude, delta_d, d, period, tau2, 2, 1/3) of an
    OscillatorParams.

    The last two are the exponents of the core's ``x ** 2`` and ``x ** (1 / 3)``: CPython
    computes those with libm's pow, which is not always x * x to the last bit, while
    LLVM turns a constant exponent 2 into a multiplication. Passed at run time, they
    keep the kernel on pow, the same function, and so on the same floats (:func:`power`).
    """
    return (p.zeta, p.r, p.omega, p.omega_d, p.lag, p.amplitude, p.delta_d, p.d, p.period,
            p.tau2, 2.0, 1.0 / 3.0)


@jit
def power(x, y):
    """x ** y as CPython computes it for floats (libm pow); y must come from P."""
    return math.pow(x, y)


@jit
def ulp(x):
    """math.ulp(x) for finite x: the gap from |x| to the next float up."""
    a = abs(x)
    return np.nextafter(a, np.inf) - a


@jit
def amplitude_bound(zeta, dx, dv):
    """flow.amplitude_bound."""
    wd = math.sqrt(1.0 - zeta * zeta)
    return math.hypot(dx, (dv + zeta * dx) / wd)


@jit
def transition_matrix(zeta, h):
    """flow.transition_matrix."""
    wd = math.sqrt(1.0 - zeta * zeta)
    e = math.exp(-zeta * h)
    c = math.cos(wd * h)
    s = math.sin(wd * h) / wd
    return (e * (c + zeta * s), e * s, -e * s, e * (c - zeta * s))


@jit
def propagate(zeta, dx, dv, h):
    """flow.propagate."""
    f11, f12, f21, f22 = transition_matrix(zeta, h)
    return f11 * dx + f12 * dv, f21 * dx + f22 * dv


# ------------------------------------------------------------------ _Eval
@jit
def make_eval(P, tau0, dx0, dv0):
    """impact._Eval.__init__: (zeta, wd, omega, lag, amp, dd, tau0, dx0, c2, aw2, aw3, |C|, 2)."""
    wd = P[_WD]
    amp = P[_AMP]
    omega = P[_OMEGA]
    aw2 = amp * omega * omega
    c2 = (dv0 + P[_ZETA] * dx0) / wd
    return (P[_ZETA], wd, omega, P[_LAG], amp, P[_DD], tau0, dx0, c2, aw2, aw2 * omega,
            math.hypot(dx0, c2), P[_TWO])


@jit
def evaluate(ev, h):
    """impact._Eval.__call__: (g, v, acc, dx, dv) at time h, exact closed form.

    Also returns e^{-zeta h} (6th), which :func:`jerk_bound` reuses at the same h.
    """
    zeta, wd, omega, lag, amp, dd, tau0, c1, c2, aw2, _aw3, _cabs, _two = ev
    e = math.exp(-zeta * h)
    c = math.cos(wd * h)
    s = math.sin(wd * h)
    dx = e * (c1 * c + c2 * s)
    dv = e * ((wd * c2 - zeta * c1) * c - (wd * c1 + zeta * c2) * s)
    psi = tau0 + omega * h - lag
    sh = math.sin(0.5 * psi)
    g = dx - dd - 2.0 * amp * sh * sh
    v = -amp * omega * math.sin(psi) + dv
    acc = -aw2 * math.cos(psi) - 2.0 * zeta * dv - dx
    return g, v, acc, dx, dv, e


@jit
def jerk_bound(ev, e):
    """impact._Eval.jerk_bound at h, given e = e^{-zeta h}: J >= max |g'''| on [h, inf)."""
    return ev[10] + ev[11] * e


# ------------------------------------------------------------------ _bracket
@jit
def bracket(ev, lo, hi, which, sign):
    """impact._bracket: root of g (which = 0) or v (which = 1) in [lo, hi]."""
    x = 0.5 * (lo + hi)
    while hi - lo > 4.0 * ulp(hi):
        g, v, acc, _dx, _dv, _e = evaluate(ev, x)
        if which == 0:
            fx, dfx = sign * g, sign * v
        else:
            fx, dfx = sign * v, sign * acc
        if fx >= 0.0:
            hi = x
        else:
            lo = x
        xn = x - fx / dfx if dfx > 0.0 else lo
        if not lo < xn < hi:
            xn = 0.5 * (lo + hi)
        if xn == x:
            xn = 0.5 * (lo + hi)
            if xn == x:
                break
        x = xn
    return hi


# ------------------------------------------------------------------ _search
@jit
def _certified(ev, a, b, ea, ga, va, acca, gb, vb, accb):
    """The certified cases of impact._search on [a, b].

    Returns (decided, time): decided = 1 with time >= 0 (impact) or NONE (none), or
    decided = 0 when the interval must be split.
    """
    jw = jerk_bound(ev, ea) * (b - a)
    concave = acca < 0.0 and accb < 0.0 and -(acca + accb) > jw
    convex = acca > 0.0 and accb > 0.0 and (acca + accb) > jw
    if concave:  # v decreasing: at most one maximum
        if va <= 0.0:
            return 1, NONE
        if vb >= 0.0:
            return 1, (bracket(ev, a, b, 0, 1.0) if gb >= 0.0 else NONE)
        tm = bracket(ev, a, b, 1, -1.0)
        return 1, (bracket(ev, a, tm, 0, 1.0) if evaluate(ev, tm)[0] >= 0.0 else NONE)
    if convex:  # v increasing: g below the chord unless it ends above 0
        if gb < 0.0:
            return 1, NONE
        if ga < 0.0:
            return 1, bracket(ev, a, b, 0, 1.0)
        if va >= 0.0:  # at rest on the wall and pushed into it
            return 1, a
        tmin = bracket(ev, a, b, 1, 1.0) if vb > 0.0 else b
        gmin = evaluate(ev, tmin)[0]
        return 1, (bracket(ev, tmin, b, 0, 1.0) if gmin < 0.0 <= gb else NONE)
    # below the chord plus the curvature allowance (docs/theory.md, "Impact detection")
    curvature = max(0.0, 0.5 * (jw - acca - accb))
    if max(ga, gb) + 0.125 * power(b - a, ev[12]) * curvature < 0.0:
        return 1, NONE
    return 0, NONE


@jit
def search(ev, a, b, fa, fb, stack):
    """impact._search(f, a, b, fa, fb, 0): first impact time in (a, b], or NONE.

    The recursion (left half first, then the right half) runs on an explicit stack of
    pending right halves (``stack``, from :func:`search_stack`), which visits the
    intervals in the same order.
    """
    top = 0
    ea, ga, va, acca = fa[5], fa[0], fa[1], fa[2]
    gb, vb, accb = fb[0], fb[1], fb[2]
    depth = 0
    while True:
        decided, t = _certified(ev, a, b, ea, ga, va, acca, gb, vb, accb)
        if not decided:
            if depth >= _MAX_DEPTH or b - a <= 4.0 * ulp(b):
                decided = 1
                t = bracket(ev, a, b, 0, 1.0) if ga < 0.0 <= gb else NONE
        if decided:
            if t != NONE:
                return t
            if top == 0:
                return NONE
            top -= 1  # the pending right half of the nearest ancestor
            row = stack[top]
            a, b, ea, ga, va, acca, gb, vb, accb = (row[0], row[1], row[2], row[3], row[4],
                                                    row[5], row[6], row[7], row[8])
            depth = int(row[9])
            continue
        mid = 0.5 * (a + b)
        gm, vm, accm, _dx, _dv, em = evaluate(ev, mid)
        row = stack[top]
        row[0], row[1], row[2], row[3], row[4], row[5] = mid, b, em, gm, vm, accm
        row[6], row[7], row[8], row[9] = gb, vb, accb, depth + 1
        top += 1
        b, gb, vb, accb = mid, gm, vm, accm
        depth += 1


def search_stack():
    """The work array of :func:`search`: one row per pending interval."""
    return np.empty((_MAX_DEPTH + 2, 10))


# ------------------------------------------------------------------ next_impact
@jit
def next_impact(P, tau0, dx0, dv0, horizon, max_step, stack):
    """impact.next_impact: (time of the first impact in (0, horizon] or NONE, status, gap).

    ``max_step`` <= 0 means the default T / 8. status is STATUS_BEYOND_WALL (and gap the
    offending x - d) where the core raises InitialStateError.
    """
    if not (math.isfinite(dx0) and math.isfinite(dv0) and math.isfinite(tau0)
            and math.isfinite(horizon)):
        return NONE, STATUS_NONFINITE, dx0 if not math.isfinite(dx0) else dv0
    if horizon <= 0.0:
        return NONE, STATUS_OK, 0.0
    if amplitude_bound(P[_ZETA], dx0, dv0) < P[_DD]:
        return NONE, STATUS_OK, 0.0
    ev = make_eval(P, tau0, dx0, dv0)
    step = max_step if max_step > 0.0 else P[_PERIOD] / 8.0
    n = max(1, int(math.ceil(horizon / step)))
    a = 0.0
    fa = evaluate(ev, 0.0)
    ga = fa[0]
    scale = abs(dx0) + abs(P[_DD]) + 2.0 * P[_AMP] * power(math.sin(0.5 * (tau0 - P[_LAG])),
                                                          P[_TWO])
    if 0.0 < ga <= 8.0 * ulp(scale):
        ga = 0.0  # on the wall up to rounding
    if ga > 0.0:
        return NONE, STATUS_BEYOND_WALL, ga
    if ga == 0.0 and fa[1] > 0.0:
        return 0.0, STATUS_OK, 0.0  # on the wall, moving into it
    fa = (ga, fa[1], fa[2], fa[3], fa[4], fa[5])
    for k in range(1, n + 1):
        b = horizon if k == n else k * (horizon / n)
        fb = evaluate(ev, b)
        r = search(ev, a, b, fa, fb, stack)
        if r != NONE:
            return r, STATUS_OK, 0.0
        a, fa = b, fb
    return NONE, STATUS_OK, 0.0


# ------------------------------------------------------------------ sticking
@jit
def release_time(P, tau, horizon):
    """impact._release_time: time after phase tau until cos(tau) - d < 0."""
    d = P[_D]
    if d >= 1.0:
        return 0.0
    if d <= -1.0:
        return math.inf
    alpha = math.acos(d)
    t = tau % TWO_PI
    rel = alpha - t if t < alpha else alpha + TWO_PI - t
    if math.cos(tau) - d <= 0.0 and rel > 1e-14:
        return 0.0
    return rel / P[_OMEGA]


@jit
def resting_on_wall(P, tau, dx, dv):
    """impact._resting_on_wall: x = d and v = 0 up to rounding."""
    s = math.sin(0.5 * (tau - P[_LAG]))
    vp = -P[_AMP] * P[_OMEGA] * math.sin(tau - P[_LAG])
    g_scale = abs(dx) + abs(P[_DD]) + 2.0 * P[_AMP] * s * s
    g = dx - P[_DD] - 2.0 * P[_AMP] * s * s
    return abs(g) <= 8.0 * ulp(g_scale) and abs(vp + dv) <= 8.0 * ulp(abs(vp) + abs(dv))


@jit
def release_skip(P, tau, dx):
    """impact._release_skip: time after leaving the wall at rest with |gap| below rounding."""
    eps = 8.0 * ulp(abs(dx) + abs(P[_DD]) + 2.0 * P[_AMP])
    force = abs(math.cos(tau) - P[_D])
    jerk = abs(P[_OMEGA] * math.sin(tau))
    out = math.inf
    if force > 0.0:
        out = math.sqrt(2.0 * eps / force)
    if jerk > 0.0:
        out = min(out, power(6.0 * eps / jerk, P[_THIRD]))
    return out if out < math.inf else 0.0


# ------------------------------------------------------------------ advance
@jit
def _wall_state(P, tau):
    """(x_p - d, v_p) at phase tau, as advance computes them at an impact."""
    xp_minus_d = -2.0 * P[_AMP] * power(math.sin(0.5 * (tau - P[_LAG])), P[_TWO]) - P[_DD]
    vp = -P[_AMP] * P[_OMEGA] * math.sin(tau - P[_LAG])
    return xp_minus_d, vp


@jit
def advance(P, tau0, dx, dv, duration, max_impacts, chatter_time, out, n0, stack):
    """impact.advance without the monodromy: the exact event-driven segment.

    Impacts are written to rows n0, n0 + 1, ... of ``out`` (at least n0 + max_impacts
    rows, columns IMPACT_FIELDS). ``chatter_time`` < 0 means the default 1e-6 T.
    ``stack`` is :func:`search`'s work array (:func:`search_stack`).

    Returns
    -------
    (dx, dv, n, status, info)
        The deviation at the end, the number of rows used (n0 + impacts), and the
        status: STATUS_OK; STATUS_IMPACT_CAP (info = the phase, as in the core's message);
        STATUS_BEYOND_WALL (info = x - d).
    """
    zeta, r, omega = P[_ZETA], P[_R], P[_OMEGA]
    chatter = chatter_time if chatter_time >= 0.0 else 1e-6 * P[_PERIOD]
    n = n0
    t = 0.0
    tau = tau0
    h = NONE
    searched = False
    if resting_on_wall(P, tau, dx, dv):
        if math.cos(tau) - P[_D] > 0.0:
            h = 0.0  # at rest on the wall (to rounding) and pushed into it: sticks at once
            searched = True
        else:  # leaving from rest: no impact while the gap is below its rounding
            t = min(duration, release_skip(P, tau, dx))
            dx, dv = propagate(zeta, dx, dv, t)
            tau = (tau0 + omega * t) % TWO_PI
    if not searched and t < duration:
        h, status, info = next_impact(P, tau, dx, dv, duration - t, 0.0, stack)
        if status != STATUS_OK:
            return dx, dv, n, status, info
    while True:
        remaining = duration - t
        if h == NONE or remaining <= 0.0:
            if remaining > 0.0:
                f11, f12, f21, f22 = transition_matrix(zeta, remaining)
                dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
            return dx, dv, n, STATUS_OK, 0.0
        if n - n0 >= max_impacts:
            return dx, dv, n, STATUS_IMPACT_CAP, tau % TWO_PI
        f11, f12, f21, f22 = transition_matrix(zeta, h)
        dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
        t += h
        tau = (tau + omega * h) % TWO_PI
        xp_minus_d, vp = _wall_state(P, tau)
        v_minus = vp + dv
        v_plus = -r * v_minus
        # on the wall exactly: dx = d - x_p
        dx = -xp_minus_d
        dv = v_plus - vp
        force = math.cos(tau) - P[_D]
        t_inf = max(0.0, 2.0 * r * v_minus / ((1.0 - r) * force)) if force > 0.0 else math.inf
        height = v_plus * v_plus / (2.0 * force) if force > 0.0 else math.inf
        if t_inf < chatter or height < 1e3 * ulp(abs(dx) + abs(P[_DD]) + P[_AMP]):
            # chattering: sum the geometric sequence and stick (velocity -> 0)
            out[n, 0], out[n, 1], out[n, 2], out[n, 3], out[n, 4] = t, tau, v_minus, v_plus, 1.0
            t += t_inf
            tau = (tau + omega * t_inf) % TWO_PI
            stick = release_time(P, tau, duration - t)
            out[n, 5] = t + stick if t + stick <= duration else math.inf
            n += 1
            t = min(duration, t + stick)
            tau = (tau0 + omega * t) % TWO_PI
            xp_minus_d, vp = _wall_state(P, tau)
            dx, dv = -xp_minus_d, -vp
            if t < duration:
                skip = min(duration - t, release_skip(P, tau, dx))
                dx, dv = propagate(zeta, dx, dv, skip)
                t += skip
                tau = (tau0 + omega * t) % TWO_PI
            h = NONE
            if t < duration:
                h, status, info = next_impact(P, tau, dx, dv, duration - t, 0.0, stack)
                if status != STATUS_OK:
                    return dx, dv, n, status, info
            continue
        out[n, 0], out[n, 1], out[n, 2], out[n, 3], out[n, 4] = t, tau, v_minus, v_plus, 0.0
        out[n, 5] = math.nan
        n += 1
        h = NONE
        if t < duration:
            h, status, info = next_impact(P, tau, dx, dv, duration - t, 0.0, stack)
            if status != STATUS_OK:
                return dx, dv, n, status, info

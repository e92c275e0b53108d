"""Compiled mirror of :mod:`grazing_control.oscillator.impact` and of :func:`simulate.period_step`.

Function by function the same algorithm as the pure-Python core, in the same floating
point operations and the same order, so that a fix there ports here line by line; the
table of which function mirrors which is in docs/sweeps.md ("The compiled exact
kernel"), as are the two values computed once instead of again (the window grid of a
period from Pi2, e^{-zeta a} of the jerk bound), bit-identically.

The certified interval search (``impact._search``, ``_bracket``) is not here: it is
written once for this closed form and the n-DOF modal sum, in :mod:`.interval_search`,
which reaches this model's :func:`evaluate`, :func:`jerk_bound` and :func:`gap_rounding`
(``terms`` None). numba's on-disk cache keys a function on its own file; the kernel's
``jit`` (:mod:`.caching`) stamps every function of the folder by all its files, so an
edit of any of them recompiles everything.

Model parameters travel as the tuple ``P`` of ``kernel.params_tuple`` (derived quantities
computed once, by :class:`~grazing_control.oscillator.params.OscillatorParams` itself, so that
both paths use the very same floats). Errors cannot be raised from compiled code with
the core's messages, so they come back as a status code and one number, and the
Python wrapper (:mod:`grazing_control.oscillator.kernel`) raises the core's exception.
"""

from __future__ import annotations

import math

import numpy as np

from .caching import jit
from .interval_search import NONE, danger_halfwidth, scan_windows, search_stack, ulp

__all__ = ["check_state", "wall_rounding", "make_eval", "evaluate",
           "evaluate_row", "window_grid", "jerk_bound", "gap_rounding", "search_stack",
           "next_impact", "next_impact_unchecked", "release_time",
           "resting_on_wall", "release_skip", "on_wall_at_rest", "leave_wall", "advance",
           "STATUS_OK", "STATUS_IMPACT_CAP", "STATUS_BEYOND_WALL", "STATUS_NONFINITE",
           "IMPACT_FIELDS", "MAX_AMPLITUDE", "period_step", "run",
           "STATUS_BUFFER_FULL", "STATUS_CORRECTION", "MAX_IMPACTS", "period_jacobian",
           "lyapunov_run", "particular", "states_between"]

TWO_PI = 2.0 * math.pi
_EPS = 2.0 ** -52
#: impact.MAX_AMPLITUDE: the largest deviation amplitude |C| accepted.
MAX_AMPLITUDE = 1e150

STATUS_OK = 0
STATUS_IMPACT_CAP = 1  # ImpactCapError
STATUS_BEYOND_WALL = 2  # InitialStateError
STATUS_NONFINITE = 4  # NonFiniteStateError: (dx, dv) returned are the offending state

#: Columns of an impact row.
IMPACT_FIELDS = ("dt", "phase", "v_minus", "v_plus", "sticking", "release")

# P: the model parameters, in this order (kernel.params_tuple builds it)
_ZETA, _R, _OMEGA, _WD, _LAG, _AMP, _DD, _D, _PERIOD, _TAU2, _TWO, _THIRD = range(12)


@jit
def power(x, y):
    """x ** y as CPython computes it for floats (libm pow); y must come from P."""
    return math.pow(x, y)


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


@jit
def check_state(zeta, dx, dv):
    """impact.check_state: (dx, dv) finite with |C| <= MAX_AMPLITUDE; also returns |C|."""
    if not (math.isfinite(dx) and math.isfinite(dv)):
        return False, math.nan
    size = amplitude_bound(zeta, dx, dv)
    return size <= MAX_AMPLITUDE, size


@jit
def wall_rounding(P, tau, dx, dv):
    """impact._wall_rounding: rounding (gap, velocity) of a state at phase tau."""
    psi = tau - P[_LAG]
    s2 = 2.0 * P[_AMP] * power(math.sin(0.5 * psi), P[_TWO])
    vp = -P[_AMP] * P[_OMEGA] * math.sin(psi)
    phase = abs(tau) + abs(P[_LAG]) + TWO_PI + 1.0
    eg = 8.0 * _EPS * (abs(dx) + abs(P[_DD]) + s2 + math.sqrt(2.0 * P[_AMP] * s2) * phase)
    ev = 8.0 * _EPS * (abs(vp) + abs(dv) + P[_AMP] * P[_OMEGA] * phase)
    return eg, ev


# ------------------------------------------------------------------ _Eval
# ev = (zeta, wd, omega, lag, amp, dd, tau0, dx0, c2, aw2, aw3, cabs, 2, acc_err, m0, m1)
@jit
def make_eval(P, tau0, dx0, dv0):
    """impact._Eval.__init__ as a tuple ``ev`` (see the comment above)."""
    wd = P[_WD]
    amp = P[_AMP]
    omega = P[_OMEGA]
    lag = P[_LAG]
    c2 = (dv0 + P[_ZETA] * dx0) / wd
    aw2 = amp * omega * omega
    aw3 = aw2 * omega
    cabs = math.hypot(dx0, c2)
    acc_err = 8.0 * _EPS * (aw2 * (4.0 + abs(tau0) + abs(lag)) + 4.0 * cabs)
    # gap_rounding(h) <= m0 + m1 h for every h (s2 <= 2 a): a cheap first test
    phase0 = abs(tau0) + abs(lag) + 1.0
    m0 = 8.0 * _EPS * (2.0 * cabs + abs(P[_DD]) + 2.0 * amp * (1.0 + phase0))
    m1 = 8.0 * _EPS * (cabs * wd + 2.0 * amp * omega)
    return (P[_ZETA], wd, omega, lag, amp, P[_DD], tau0, dx0, c2, aw2, aw3, cabs, P[_TWO],
            acc_err, m0, m1)


@jit
def evaluate(ev, h):
    """impact._Eval.__call__: (g, v, acc, dx, dv) at time h, exact closed form.

    Also returns e^{-zeta h} (6th), which :func:`jerk_bound` reuses at the same h.
    """
    zeta, wd, omega, lag, amp, dd, tau0, c1, c2, aw2 = (ev[0], ev[1], ev[2], ev[3], ev[4],
                                                        ev[5], ev[6], ev[7], ev[8], ev[9])
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
def evaluate_row(ev, grid, k):
    """:func:`evaluate` at h = grid[k, 0] from the transcendental values stored in row k.

    The same operations on the same floats as :func:`evaluate` (the stored values are
    libm's results for the same arguments), hence bit-identical results.
    """
    zeta, wd, omega, amp, dd, c1, c2, aw2 = (ev[0], ev[1], ev[2], ev[4], ev[5], ev[7], ev[8],
                                            ev[9])
    e, c, s = grid[k, 1], grid[k, 2], grid[k, 3]
    dx = e * (c1 * c + c2 * s)
    dv = e * ((wd * c2 - zeta * c1) * c - (wd * c1 + zeta * c2) * s)
    sh = grid[k, 4]
    g = dx - dd - 2.0 * amp * sh * sh
    v = -amp * omega * grid[k, 5] + dv
    acc = -aw2 * grid[k, 6] - 2.0 * zeta * dv - dx
    return g, v, acc, dx, dv, e


@jit
def window_grid(P, tau0, horizon):
    """The window ends of next_impact(P, tau0, ., ., horizon) and what evaluate needs there.

    Row k (k = 0..n) holds h_k and e^{-zeta h}, cos(wd h), sin(wd h), sin(psi / 2),
    sin(psi), cos(psi) at h_k; row 0 also holds (tau0, horizon) in columns 7, 8. These
    depend on the start phase and the horizon only, not on the state: every period of a
    run starts at (tau2, T), so its first search reuses them (:func:`next_impact`).
    """
    step = P[_PERIOD] / 8.0
    n = max(1, int(math.ceil(horizon / step)))
    grid = np.zeros((n + 1, 9))
    for k in range(n + 1):
        h = 0.0 if k == 0 else (horizon if k == n else k * (horizon / n))
        psi = tau0 + P[_OMEGA] * h - P[_LAG]
        grid[k, 0] = h
        grid[k, 1] = math.exp(-P[_ZETA] * h)
        grid[k, 2] = math.cos(P[_WD] * h)
        grid[k, 3] = math.sin(P[_WD] * h)
        grid[k, 4] = math.sin(0.5 * psi)
        grid[k, 5] = math.sin(psi)
        grid[k, 6] = math.cos(psi)
    grid[0, 7] = tau0
    grid[0, 8] = horizon
    return grid


@jit
def jerk_bound(ev, e):
    """impact._Eval.jerk_bound at h, given e = e^{-zeta h}: J >= max |g^(3)| on [h, inf)."""
    return ev[10] + ev[11] * e


@jit
def gap_rounding(ev, h, g, dx):
    """impact._Eval.gap_rounding: bound on |computed g(h) - exact g(h)|."""
    s2 = abs(dx - ev[5] - g)
    phase = abs(ev[6]) + ev[2] * h + abs(ev[3]) + 1.0
    return 8.0 * _EPS * (ev[11] * (2.0 + ev[1] * h) + abs(ev[5]) + s2
                         + math.sqrt(2.0 * ev[4] * s2) * phase)


@jit
def next_impact(P, tau0, dx0, dv0, horizon, max_step, stack, grid):
    """impact.next_impact: (time of the first impact in (0, horizon] or NONE, status, info).

    ``max_step`` <= 0 means the default T / 8. status: STATUS_NONFINITE where the core
    raises NonFiniteStateError, STATUS_BEYOND_WALL (info = x - d) where it raises
    InitialStateError. ``stack``: the work array of :func:`search`; ``grid``: a
    :func:`window_grid`, used when it was made for this (tau0, horizon) with the default
    step (else ignored; it may have no rows).
    """
    ok, _size = check_state(P[_ZETA], dx0, dv0)
    if not ok or not (math.isfinite(tau0) and math.isfinite(horizon)):
        return NONE, STATUS_NONFINITE, 0.0
    return next_impact_unchecked(P, tau0, dx0, dv0, horizon, max_step, stack, grid)


@jit
def next_impact_unchecked(P, tau0, dx0, dv0, horizon, max_step, stack, grid):
    """impact._next_impact: :func:`next_impact` without the checks (advance made them)."""
    if horizon <= 0.0:
        return NONE, STATUS_OK, 0.0
    # whole-window exclusion: g <= |z_x| - Delta d <= |C| - Delta d (|C| rounded up)
    if amplitude_bound(P[_ZETA], dx0, dv0) * (1.0 + 4.0 * _EPS) < P[_DD]:
        return NONE, STATUS_OK, 0.0
    ev = make_eval(P, tau0, dx0, dv0)
    step = max_step if max_step > 0.0 else P[_PERIOD] / 8.0
    n = max(1, int(math.ceil(horizon / step)))
    cached = (max_step <= 0.0 and grid.shape[0] > 0 and grid[0, 7] == tau0
              and grid[0, 8] == horizon)
    fa = evaluate_row(ev, grid, 0) if cached else evaluate(ev, 0.0)
    ga = fa[0]
    # on the wall up to rounding: above it, or below it while leaving (v < 0)
    if (ga > 0.0 or ga < 0.0 and fa[1] < 0.0) and abs(ga) <= wall_rounding(P, tau0, dx0, dv0)[0]:
        ga = 0.0
    if ga > 0.0:
        return NONE, STATUS_BEYOND_WALL, ga
    if ga == 0.0 and fa[1] > 0.0:
        return 0.0, STATUS_OK, 0.0  # on the wall, moving into it
    fa = (ga, fa[1], fa[2], fa[3], fa[4], fa[5])
    w = danger_halfwidth(ev[11], ev[5], ev[4], ev[14], ev[15], horizon)
    return (scan_windows(ev, None, horizon, n, w, ev[6], ev[2], ev[3], fa, stack, grid,
                         cached), STATUS_OK, 0.0)


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
    """impact._resting_on_wall: x = d and v = 0 up to rounding (phase included)."""
    eg, ev = wall_rounding(P, tau, dx, dv)
    s = math.sin(0.5 * (tau - P[_LAG]))
    g = dx - P[_DD] - 2.0 * P[_AMP] * s * s
    vp = -P[_AMP] * P[_OMEGA] * math.sin(tau - P[_LAG])
    return abs(g) <= eg and abs(vp + dv) <= ev


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


@jit
def on_wall_at_rest(P, tau):
    """impact._on_wall_at_rest: deviation of (x, v) = (d, 0) at phase tau."""
    xp_minus_d = -2.0 * P[_AMP] * power(math.sin(0.5 * (tau - P[_LAG])), P[_TWO]) - P[_DD]
    return -xp_minus_d, P[_AMP] * P[_OMEGA] * math.sin(tau - P[_LAG])


@jit
def leave_wall(P, tau0, t, duration, dx, dv):
    """impact._leave_wall (without the monodromy): (t, tau, dx, dv) after the skip."""
    skip = min(duration - t, release_skip(P, (tau0 + P[_OMEGA] * t) % TWO_PI, dx))
    f11, f12, f21, f22 = transition_matrix(P[_ZETA], skip)
    dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
    t += skip
    return t, (tau0 + P[_OMEGA] * t) % TWO_PI, dx, dv


# ------------------------------------------------------------------ advance
@jit
def advance(P, tau0, dx, dv, duration, max_impacts, chatter_time, out, n0, stack, grid):
    """impact.advance without the monodromy: the exact event-driven segment.

    Impacts are written to rows n0, n0 + 1, ... of ``out`` (at least n0 + max_impacts
    rows, columns IMPACT_FIELDS). ``chatter_time`` < 0 means the default 1e-6 T.
    ``stack`` is :func:`search`'s work array (:func:`search_stack`), ``grid`` a
    :func:`window_grid` for (tau0, duration) or an empty (0, 9) array.

    Returns
    -------
    (dx, dv, n, status, info)
        The deviation at the end, the number of rows used (n0 + impacts), and the
        status: STATUS_OK; STATUS_IMPACT_CAP (info = the phase, as in the core's message);
        STATUS_BEYOND_WALL (info = x - d); STATUS_NONFINITE ((dx, dv) = the state that
        failed impact.check_state, or the start state when tau0 or duration is not finite).
    """
    ok, _size = check_state(P[_ZETA], dx, dv)
    if not ok or not (math.isfinite(tau0) and math.isfinite(duration)):
        return dx, dv, n0, STATUS_NONFINITE, 0.0
    zeta, r, omega = P[_ZETA], P[_R], P[_OMEGA]
    aw, lag_abs, wd = P[_AMP] * omega, abs(P[_LAG]), P[_WD]
    chatter = chatter_time if chatter_time >= 0.0 else 1e-6 * P[_PERIOD]
    n = n0
    t = 0.0
    tau = tau0
    contacts = 0
    # at rest on the wall (to rounding): a contact at rest now, handled in the loop
    if resting_on_wall(P, tau, dx, dv):
        h = 0.0
    elif duration > 0.0:
        h, status, info = next_impact_unchecked(P, tau, dx, dv, duration, 0.0, stack, grid)
        if status != STATUS_OK:
            return dx, dv, n, status, info
    else:
        h = NONE
    while True:
        remaining = duration - t
        if h == NONE or remaining <= 0.0:
            if remaining > 0.0:
                f11, f12, f21, f22 = transition_matrix(zeta, remaining)
                dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
            return dx, dv, n, STATUS_OK, 0.0
        if contacts >= max_impacts:
            return dx, dv, n, STATUS_IMPACT_CAP, tau % TWO_PI
        contacts += 1
        # velocity rounding after the flow: terms of size |C| <= |dx| + |dv + zeta dx| / omega_d
        flow_err = 8.0 * _EPS * (abs(dx) + abs(dv + zeta * dx) / wd) * (2.0 + h)
        f11, f12, f21, f22 = transition_matrix(zeta, h)
        dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
        t += h
        tau = (tau + omega * h) % TWO_PI
        wall_dx, wall_dv = on_wall_at_rest(P, tau)  # (d, 0) at this phase
        vp = -wall_dv
        v_minus = vp + dv
        force = math.cos(tau) - P[_D]
        # the velocity's rounding (wall_rounding) plus that of the flow
        v_tol = 8.0 * _EPS * (abs(vp) + abs(dv) + aw * (tau + lag_abs + TWO_PI + 1.0)) + flow_err
        dx = wall_dx  # on the wall exactly
        if v_minus <= v_tol:  # contact at rest, below the velocity's rounding
            dv = wall_dv
            if force <= 0.0:  # tangency: v- = 0 changes nothing; leave the wall
                t, tau, dx, dv = leave_wall(P, tau0, t, duration, dx, dv)
                h = NONE
                if t < duration:
                    h, status, info = next_impact_unchecked(P, tau, dx, dv, duration - t, 0.0,
                                                            stack, grid)
                    if status != STATUS_OK:
                        return dx, dv, n, status, info
                continue
            v_minus, t_inf, height = 0.0, 0.0, 0.0  # pushed into the wall: sticks
        else:
            t_inf = max(0.0, 2.0 * r * v_minus / ((1.0 - r) * force)) if force > 0.0 \
                else math.inf
            # the next bounce rises v+^2 / (2 F): below ~1e3 ulps of the gap, not resolvable
            height = power(r * v_minus, P[_TWO]) / (2.0 * force) if force > 0.0 else math.inf
        v_plus = -r * v_minus if v_minus > 0.0 else 0.0  # at rest: +0.0, not -0.0
        dv = v_plus - vp
        if t_inf < chatter or height < 1e3 * ulp(abs(dx) + abs(P[_DD]) + P[_AMP]):
            # chattering: sum the geometric sequence and stick (velocity -> 0)
            t_hit, tau_hit = t, tau
            t += t_inf
            tau = (tau + omega * t_inf) % TWO_PI
            stick = release_time(P, tau, duration - t)
            release = t + stick if t + stick <= duration else math.inf
            out[n, 0], out[n, 1], out[n, 2], out[n, 3] = t_hit, tau_hit, v_minus, v_plus
            out[n, 4], out[n, 5] = 1.0, release
            n += 1
            t = min(duration, t + stick)
            tau = (tau0 + omega * t) % TWO_PI
            dx, dv = on_wall_at_rest(P, tau)
            if t < duration:
                t, tau, dx, dv = leave_wall(P, tau0, t, duration, dx, dv)
            h = NONE
            if t < duration:
                h, status, info = next_impact_unchecked(P, tau, dx, dv, duration - t, 0.0, stack,
                                                        grid)
                if status != STATUS_OK:
                    return dx, dv, n, status, info
            continue
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = t, tau, v_minus, v_plus
        out[n, 4], out[n, 5] = 0.0, math.nan
        n += 1
        h = NONE
        if t < duration:
            h, status, info = next_impact_unchecked(P, tau, dx, dv, duration - t, 0.0, stack, grid)
            if status != STATUS_OK:
                return dx, dv, n, status, info

# ======================================================= simulate.period_step, the loop
# :func:`period_step` is one forcing period from a Pi2 sample with the correction applied
# ``delay`` after it, exactly as the core's; :func:`run` chains periods with the
# controller of Eq. 28 (dv_correction = c1 dx + c2 dv at samples k >= control_after), as
# :func:`grazing_control.dynamics.simulation.simulate.simulate` does: the whole inner loop of a sweep point
# or of an exact simulation.

#: The impact buffer of :func:`run` is full: resume at the returned period with more room.
STATUS_BUFFER_FULL = 3
#: simulate's check: the correction c1 dx + c2 dv is not finite or exceeds 1e150 (info).
STATUS_CORRECTION = 5
#: The core's default cap of impacts per advance call.
MAX_IMPACTS = 10000


@jit
def period_step(P, dx, dv, dv_correction, delay, out, n0, stack, grid):
    """simulate.period_step: (dx, dv, n, status, info); impact rows n0..n-1 of ``out``.

    ``out`` needs n0 + 2 MAX_IMPACTS rows when delay > 0 (two advance calls), n0 +
    MAX_IMPACTS otherwise. Impact times count from the sample. The caller validates
    0 <= delay < T. ``grid``: window_grid(P, tau2, T) (or empty), reused when delay = 0.
    """
    if delay == 0.0:
        return advance(P, P[_TAU2], dx, dv + dv_correction, P[_PERIOD], MAX_IMPACTS, -1.0,
                       out, n0, stack, grid)
    dx1, dv1, n1, status, info = advance(P, P[_TAU2], dx, dv, delay, MAX_IMPACTS, -1.0, out, n0,
                                          stack, grid)
    if status != STATUS_OK:
        return dx1, dv1, n1, status, info
    tau = (P[_TAU2] + P[_OMEGA] * delay) % TWO_PI
    dx2, dv2, n2, status, info = advance(P, tau, dx1, dv1 + dv_correction, P[_PERIOD] - delay,
                                         MAX_IMPACTS, -1.0, out, n1, stack, grid)
    for i in range(n1, n2):
        out[i, 0] += delay
        out[i, 5] += delay
    return dx2, dv2, n2, status, info


@jit
def run(P, k0, periods, dx, dv, controlled, c1, c2, control_after, delay, record_from,
        dev, corr, counts, impacts, n_impacts, scratch, stack):
    """Periods k0 .. periods-1 from the Pi2 deviation (dx, dv) at sample k0.

    Sample k (>= record_from) is stored at row k - record_from of ``dev`` (deviation
    before the correction), ``corr`` (the correction) and ``counts`` (impacts in the
    period). Impact rows (k, time since sample 0, phase, v-, v+) are appended to
    ``impacts`` from row ``n_impacts`` when it has any rows (an exact simulation) and
    skipped when it has none (a sweep); ``scratch`` holds one period's impacts
    (2 MAX_IMPACTS rows).

    Returns
    -------
    (k, dx, dv, n_impacts, status, info)
        k = periods and STATUS_OK when done. STATUS_BUFFER_FULL: period k did not fit in
        ``impacts``; (dx, dv) is still sample k's, so the call can be resumed from k with
        a larger array. STATUS_CORRECTION: simulate's overflow check of the correction
        (info) failed at sample k, whose (dx, dv) are returned. Any other status is the
        core's error at period k, with (dx, dv) the state it is about (impact.advance).
    """
    period = P[_PERIOD]
    keep = impacts.shape[0] > 0
    grid = window_grid(P, P[_TAU2], period)
    for k in range(k0, periods):
        dvc = 0.0
        kick_delay = 0.0  # as simulate: the period is split at the delay only under control
        if controlled and k >= control_after:
            dvc = c1 * dx + c2 * dv
            kick_delay = delay
            if not abs(dvc) <= 1e150:  # simulate's check: an input overflowed
                return k, dx, dv, n_impacts, STATUS_CORRECTION, dvc
        ndx, ndv, n, status, info = period_step(P, dx, dv, dvc, kick_delay, scratch, 0, stack,
                                                grid)
        if status != STATUS_OK:  # (ndx, ndv): the state the error is about
            return k, ndx, ndv, n_impacts, status, info
        if keep:
            if n_impacts + n > impacts.shape[0]:
                return k, dx, dv, n_impacts, STATUS_BUFFER_FULL, 0.0
            for i in range(n):
                impacts[n_impacts, 0] = k
                impacts[n_impacts, 1] = k * period + scratch[i, 0]
                impacts[n_impacts, 2] = scratch[i, 1]
                impacts[n_impacts, 3] = scratch[i, 2]
                impacts[n_impacts, 4] = scratch[i, 3]
                n_impacts += 1
        if k >= record_from:
            j = k - record_from
            dev[j, 0] = dx
            dev[j, 1] = dv
            corr[j] = dvc
            counts[j] = n
        dx, dv = ndx, ndv
    return periods, dx, dv, n_impacts, STATUS_OK, 0.0


# ------------------------------------------------------------------ dense output
@jit
def particular(P, tau):
    """flow.particular: the non-impacting periodic motion (x_p, v_p) at phase tau."""
    psi = tau - P[_LAG]
    a = P[_AMP]
    return a * math.cos(psi), -a * P[_OMEGA] * math.sin(psi)


@jit
def states_between(P, tau0, dx, dv, impacts, times, out):
    """simulate.states_between: the physical (x, v) at ``times`` into ``out`` (returned).

    Dense output of one segment from phase ``tau0``: ``(dx, dv)`` is the deviation at its
    start, ``impacts`` its impact rows (columns IMPACT_FIELDS, as :func:`advance` writes
    them), ``times`` (sorted) count from its start. Between events the closed-form flow
    z(t) = Phi(t - t0) z(t0) (flow.propagate, docs/theory.md "Deviation coordinates") is
    evaluated and y = y_p(tau0 + omega t) + z (flow.to_physical); after an impact the
    flow restarts from (d, v+) at the impact's phase, and after a sticking one the mass
    rests at (d, 0) until its release, then flows from (d, 0). The same floating-point
    operations in the same order as the Python function, so bit for bit its numbers
    (``min(release, 1e300)`` written as CPython's ``min`` evaluates it).
    """
    n = impacts.shape[0]
    zeta, omega, d = P[_ZETA], P[_OMEGA], P[_D]
    t0, zx, zv, stuck_until = 0.0, dx, dv, -math.inf
    k = 0
    for j in range(times.shape[0]):
        t = times[j]
        while k < n and impacts[k, 0] <= t:
            if impacts[k, 4] != 0.0:  # on the wall at rest until the release, then from (d, 0)
                release = impacts[k, 5]
                stuck_until = release
                t0 = 1e300 if 1e300 < release else release
                xp, vp = particular(P, tau0 + omega * t0)
                zx, zv = d - xp, 0.0 - vp
            else:
                t0 = impacts[k, 0]
                xp, vp = particular(P, impacts[k, 1])
                zx, zv = d - xp, impacts[k, 3] - vp
            k += 1
        if t < stuck_until:
            out[j, 0] = d
            out[j, 1] = 0.0
            continue
        zxt, zvt = propagate(zeta, zx, zv, t - t0)
        xp, vp = particular(P, tau0 + omega * t)
        out[j, 0] = xp + zxt
        out[j, 1] = vp + zvt
    return out


# ------------------------------------------------------------------ tangent propagation
# the Lyapunov spectrum on Pi2 (docs/theory_lyapunov.md)
@jit
def period_jacobian(P, rows, n, kick_time, c1, c2):
    """DP of one period from its impact rows: (m11, m12, m21, m22, stuck).

    The product, in time order, of the flow's transition matrices Phi(h), the saltation
    matrix S = [[-r, 0], [(1 + r)(cos tau - d) / v-, -r]] of every impact and, at
    ``kick_time`` after the sample (the actuation delay; 0: at the sample), the kick
    M <- M + e2 (c1, c2) (c1 = c2 = 0: no kick): M2 (M1 + e2 k^T), as
    :func:`grazing_control.dynamics.maps.maps.pi2_map`'s monodromy (docs/theory_delay.md, D3).
    A sticking impact makes the map singular (every nearby state leaves the wall at the
    same release): M = 0 and stuck = 1.
    """
    zeta, r, d, period = P[_ZETA], P[_R], P[_D], P[_PERIOD]
    m11, m12, m21, m22 = 1.0, 0.0, 0.0, 1.0
    t = 0.0
    kicked = False
    stuck = 0
    for i in range(n + 1):
        at = rows[i, 0] if i < n else period
        if not kicked and kick_time < at or (not kicked and i == n):
            f11, f12, f21, f22 = transition_matrix(zeta, kick_time - t)
            m11, m12, m21, m22 = (f11 * m11 + f12 * m21, f11 * m12 + f12 * m22,
                                  f21 * m11 + f22 * m21, f21 * m12 + f22 * m22)
            m21 += c1
            m22 += c2
            t = kick_time
            kicked = True
        f11, f12, f21, f22 = transition_matrix(zeta, at - t)
        m11, m12, m21, m22 = (f11 * m11 + f12 * m21, f11 * m12 + f12 * m22,
                              f21 * m11 + f22 * m21, f21 * m12 + f22 * m22)
        t = at
        if i == n:
            break
        if rows[i, 4] != 0.0:
            m11, m12, m21, m22 = 0.0, 0.0, 0.0, 0.0
            stuck = 1
            continue
        s21 = (1.0 + r) * (math.cos(rows[i, 1]) - d) / rows[i, 2]
        m11, m12, m21, m22 = -r * m11, -r * m12, s21 * m11 - r * m21, s21 * m12 - r * m22
    return m11, m12, m21, m22, stuck


@jit
def lyapunov_run(P, periods, transient, dx, dv, controlled, c1, c2, control_after, delay,
                 scratch, stack):
    """The Lyapunov spectrum of the Pi2 map along the orbit from (dx, dv).

    The orbit is :func:`run`'s (the same period_step calls, so the same floats); from
    period ``transient`` on, an orthonormal pair of tangent vectors Q is carried through
    each period's Jacobian (:func:`period_jacobian`) and re-orthonormalised
    (Gram-Schmidt: DP Q = Q' R), accumulating log R11, log R22.

    Returns (k, dx, dv, status, info, sum_log1, sum_log2, impacts, stuck_periods,
    sum_log_det_gain): k = periods when done; the sums run over periods transient..k-1;
    ``sum_log_det_gain`` is the sum of log|1 + c2| over controlled measured periods (for
    the determinant identity, docs/theory_lyapunov.md).
    """
    period = P[_PERIOD]
    grid = window_grid(P, P[_TAU2], period)
    q11, q12, q21, q22 = 1.0, 0.0, 0.0, 1.0
    l1 = 0.0
    l2 = 0.0
    lg = 0.0
    impacts = 0
    stuck_periods = 0
    for k in range(periods):
        dvc = 0.0
        kick_delay = 0.0
        on = controlled and k >= control_after
        if on:
            dvc = c1 * dx + c2 * dv
            kick_delay = delay
            if not abs(dvc) <= 1e150:
                return k, dx, dv, STATUS_CORRECTION, dvc, l1, l2, impacts, stuck_periods, lg
        ndx, ndv, n, status, info = period_step(P, dx, dv, dvc, kick_delay, scratch, 0, stack,
                                                grid)
        if status != STATUS_OK:
            return k, ndx, ndv, status, info, l1, l2, impacts, stuck_periods, lg
        if k >= transient:
            a1 = c1 if on else 0.0
            a2 = c2 if on else 0.0
            m11, m12, m21, m22, stuck = period_jacobian(P, scratch, n, kick_delay, a1, a2)
            impacts += n
            stuck_periods += stuck
            if on:
                lg += math.log(abs(1.0 + c2))
            # (b1 b2) = DP Q, Gram-Schmidt
            b11 = m11 * q11 + m12 * q21
            b21 = m21 * q11 + m22 * q21
            b12 = m11 * q12 + m12 * q22
            b22 = m21 * q12 + m22 * q22
            r11 = math.hypot(b11, b21)
            if r11 > 0.0:
                q11, q21 = b11 / r11, b21 / r11
            proj = q11 * b12 + q21 * b22
            u1 = b12 - proj * q11
            u2 = b22 - proj * q21
            r22 = math.hypot(u1, u2)
            if r22 > 0.0:
                q12, q22 = u1 / r22, u2 / r22
            else:
                q12, q22 = -q21, q11
            l1 += math.log(r11) if r11 > 0.0 else -math.inf
            l2 += math.log(r22) if r22 > 0.0 else -math.inf
        dx, dv = ndx, ndv
    return periods, dx, dv, STATUS_OK, 0.0, l1, l2, impacts, stuck_periods, lg

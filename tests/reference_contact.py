"""Independent reference for the Kelvin-Voigt stop: DOP853 at rtol 2.3e-14 (Hairer's
Fortran code with solve_ivp's events, tests/dop853_events.py).

Physical coordinates, the equation of motion written directly (no closed form), one
region at a time with terminal events, restarted at every switch. A contact entry that
the event location could miss (a penetration shorter than a step) is caught by a
terminal event at each maximum of x: if x > d there, the entry is the root of x - d
between the previous stop and that maximum, found by brentq on the solution inside
that step.
"""

from __future__ import annotations

import math

import numpy as np

from scipy.optimize import brentq

from grazing_control.oscillator.flow import propagate, to_deviation, to_physical

from dop853_events import solve

TWO_PI = 2.0 * math.pi
RTOL = 2.3e-14
ATOL = 1e-15
DEBUG = False
#: DOP853's largest step; refine() makes it smaller for a case the default leaves in doubt
MAX_STEP = [0.05]


def _solve(rhs, t0, y0, t1, events):
    return solve(rhs, t0, y0, t1, events, rtol=RTOL, atol=ATOL, max_step=MAX_STEP[0],
                 first_step=1e-9)


def gap_events(d):
    """solve_ivp's terminal events x - d rising and falling, and the maxima of x (x' = 0
    falling, not terminal: where an entry inside one step is looked for)."""
    def gap_up(t, y):
        return y[0] - d
    gap_up.terminal, gap_up.direction = True, 1.0

    def top(t, y):
        return y[1]
    top.terminal, top.direction = False, -1.0

    def gap_down(t, y):
        return y[0] - d
    gap_down.terminal, gap_down.direction = True, -1.0
    return gap_up, top, gap_down


def seeded_start(rng, p, held="stick"):
    """The start of a seeded case after its model and law are drawn (the draws of
    tests/test_contact.py's cases, in that order): random states up to 1 below the stop,
    grazing flights whose free maximum is 1e-9..1e-3 either side of it, and deep
    clearances (``held``) where the forcing holds the mass in the stop.
    Returns (kind, p, tau0, x, v)."""
    kind = rng.choice(["random", "graze", held])
    if kind == "random":
        return kind, p, rng.uniform(0, TWO_PI), p.d - rng.uniform(0, 1), rng.uniform(-1, 1)
    if kind == held:
        p = p.with_(delta_d=-rng.uniform(0.5, 1.5))
        return kind, p, rng.uniform(0, TWO_PI), p.d - rng.uniform(0, 0.1), rng.uniform(-0.2, 0.2)
    eps = rng.choice([1, -1]) * 10 ** rng.uniform(-9, -3)
    tau_m, back = rng.uniform(0, TWO_PI), rng.uniform(0.1, 3)
    dx, dv = to_deviation(p, tau_m, p.d + eps, 0.0)  # a free maximum eps from the stop
    dx, dv = propagate(p.zeta, dx, dv, -back)
    tau0 = (tau_m - p.omega * back) % TWO_PI
    x, v = to_physical(p, tau0, dx, dv)
    return kind, p, tau0, min(x, p.d), v


def slip_or_stick(p, at_rest, t, y, duration, f_sta, forced, sgn, sticks):
    """The friction's step of the references: the slip's sign into ``sgn[0]`` (the forced
    one after a release, else x''s sign, else along G at rest), or a stick at x = y[0]
    while |G| <= F_s, G = ``at_rest(t, x)``, ended at the first sign change of |G| - F_s
    on a grid of 4000 points per period refined by brentq (appended to ``sticks``).
    Returns (t, y, forced) after a stick (t = ``duration`` if it lasts), else None."""
    if forced is not None:
        sgn[0] = forced
    elif y[1] != 0.0:
        sgn[0] = math.copysign(1.0, y[1])
    else:
        g = at_rest(t, y[0])
        sgn[0] = 0.0 if abs(g) <= f_sta else math.copysign(1.0, g)
    if sgn[0] != 0.0:
        return None
    xs = y[0]
    ts = np.linspace(t, duration, max(3, int(4000 * (duration - t) / p.period)))
    gs = np.array([abs(at_rest(u, xs)) - f_sta for u in ts])
    out = np.flatnonzero(gs[1:] > 0.0)
    if len(out) == 0:
        sticks.append((t, math.inf))
        return duration, [xs, 0.0], None
    j = out[0]
    tr = brentq(lambda u: abs(at_rest(u, xs)) - f_sta, ts[j], ts[j + 1],
                xtol=1e-16) if gs[j] < 0.0 else ts[j]
    sticks.append((t, tr))
    return tr, [xs, 0.0], math.copysign(1.0, at_rest(tr, xs))


def reference_advance(p, law, tau0, x, v, duration, friction=None, force=0.0):
    """(x, v, contacts[, sticks]) after ``duration``; contacts as (t_entry, t_exit or inf).

    ``force``: a constant force on the mass (a force pulse), written into every right-hand
    side and the force at rest (not the shift of the stop the plant uses for it).

    With ``friction`` (kinetic F_f, static F_s) the slip direction enters the right-hand
    side, a slip ends at the event x' = 0, and a stick (|G| <= F_s, G = cos tau - x -
    k_c max(x - d, 0)) ends at the first sign change of |G| - F_s on a grid of 4000 points
    per period refined by brentq; the sticks are returned as a fourth element.
    """
    k, c, d, zeta, w = law.stiffness, law.damping, p.d, p.zeta, p.omega
    f_kin = friction.kinetic if friction is not None else 0.0
    f_sta = friction.static if friction is not None else 0.0
    sgn = [0.0]
    fo = force if callable(force) else (lambda t, f=float(force): f)

    def free(t, y):
        return [y[1], math.cos(w * t + tau0) + fo(t) - 2.0 * zeta * y[1] - y[0]
                - sgn[0] * f_kin]

    def touch(t, y):
        return [y[1], math.cos(w * t + tau0) + fo(t) - 2.0 * zeta * y[1] - y[0]
                - sgn[0] * f_kin - k * (y[0] - d) - c * y[1]]

    gap_up, top, gap_down = gap_events(d)

    def force_down(t, y):
        return k * (y[0] - d) + c * y[1]
    force_down.terminal, force_down.direction = True, -1.0

    def force_up(t, y):
        return k * (y[0] - d) + c * y[1]
    force_up.terminal, force_up.direction = True, 1.0

    def stop(t, y):
        return y[1]
    stop.terminal = True

    def at_rest(t, xx):
        return math.cos(w * t + tau0) + fo(t) - xx - k * max(xx - d, 0.0)

    t, y = 0.0, [x, v]
    contacts, sticks = [], []
    delta = x - d
    region = "below" if delta <= 0.0 else ("contact" if k * delta + c * v > 0.0 else "above")
    entry = 0.0
    guard = 0
    forced = None
    while t < duration:
        guard += 1
        assert guard < 100000
        if DEBUG:
            print(region, t, y)
        if friction is not None:
            stuck = slip_or_stick(p, at_rest, t, y, duration, f_sta, forced, sgn, sticks)
            forced = None
            if stuck is not None:
                t, y, forced = stuck
                if t >= duration:
                    break
                continue
            stop.direction = -sgn[0]
        extra = [stop] if friction is not None else []
        if region == "below":
            sol = _solve(free, t, y, duration, [gap_up, top] + extra)
            hit = [s for s in sol.t_events[0] if s > t]
            halted = [s for s in (sol.t_events[2] if extra else []) if s > t]
            end = hit[0] if hit else (halted[0] if halted else sol.t[-1])
            missed = [s for s in sol.t_events[1] if t < s <= end and sol.sol(s)[0] > d]
            if missed:  # an entry inside one step: the root of x - d before that maximum
                lo = max([t] + [s for s in sol.t_events[1] if s < missed[0]])
                end = brentq(lambda s: sol.sol(s)[0] - d, lo, missed[0], xtol=1e-16)
                hit, halted = [end], []
            if hit:
                t, y = end, list(sol.sol(end))
                region, entry = "contact", t
                continue
            if halted:
                t, y = end, [min(sol.sol(end)[0], d), 0.0]
                continue
            t, y = duration, list(sol.y[:, -1])
        elif region == "contact":
            sol = _solve(touch, t, y, duration, [force_down] + extra)
            ev = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
            if ev:
                te0, i = min(ev)
                t, y = te0, list(sol.sol(te0))
                if i == 1:
                    y[1] = 0.0
                    continue
                contacts.append((entry, t))
                region = "above" if y[0] > d else "below"
                continue
            t, y = duration, list(sol.y[:, -1])
        else:
            sol = _solve(free, t, y, duration, [force_up, gap_down] + extra)
            ev = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
            if ev:
                te0, i = min(ev)
                if i == 0 and sol.sol(te0)[0] < d:  # a missed return below x = d first
                    if sol.sol(t)[0] <= d:  # already on the stop at the start (rounding)
                        te0, i = t, 1
                    else:
                        te0, i = brentq(lambda s: sol.sol(s)[0] - d, t, te0, xtol=1e-16), 1
                t, y = te0, list(sol.sol(te0))
                if i == 0:
                    region, entry = "contact", t
                elif i == 1:
                    region = "below"
                else:
                    y[1] = 0.0
                continue
            t, y = duration, list(sol.y[:, -1])
    if region == "contact":
        contacts.append((entry, math.inf))
    if friction is not None:
        return y[0], y[1], contacts, sticks
    return y[0], y[1], contacts


def assert_matches(seg, reference, args, rel_tol, time_tol, label):
    """A seeded case against ``reference(*args)`` -> (x, v, [(t_in, t_out)]): the end
    state to ``rel_tol`` (1 + |x| + |v|) (a case beyond it compared once more with the
    reference at a largest step of 0.005, :func:`refined`; the first comparison alone
    cannot fail the test), contacts counted exactly, entry and exit times to
    ``time_tol``. Returns the number of contacts lasting to the segment's end."""
    xr, vr, ref = reference(*args)
    tol = rel_tol * (1.0 + abs(xr) + abs(vr))
    if not (abs(seg.x - xr) <= tol and abs(seg.v - vr) <= tol):
        xr, vr, ref = refined(reference, *args)
    assert abs(seg.x - xr) <= tol and abs(seg.v - vr) <= tol, (label, seg, xr, vr)
    assert len(seg.contacts) == len(ref), (label, seg.contacts, ref)
    lasting = 0
    for c, (t_in, t_out) in zip(seg.contacts, ref):
        assert abs(c.dt - t_in) <= time_tol, (label, c, t_in)
        if math.isinf(t_out):
            assert math.isinf(c.duration), (label, c)
            lasting += 1
        else:
            assert abs(c.dt + c.duration - t_out) <= time_tol, (label, c, t_out)
    return lasting


def refined(fun, *args, max_step=0.005, **kwargs):
    """``fun(*args)`` with DOP853's largest step ``max_step``: the reference again, more
    accurate (its own error at rtol 2.3e-14 grows with long contacts; 0.05 left 2.4e-12 in
    one case of 6000, 0.01 left 3e-15 there)."""
    old = MAX_STEP[0]
    MAX_STEP[0] = max_step
    try:
        return fun(*args, **kwargs)
    finally:
        MAX_STEP[0] = old


def apex_jump(p, advance, tau_m, height, kinetic=0.0):
    """Velocity change of one near-grazing contact, pulled back to the free apex
    (docs/theory_contact.md §12, §14): the flow ``advance(p, tau0, x, v, duration)``
    through the contact minus the same flow with the stop far away, from 3 apex-times
    before to 3 after the apex (d + height, 0) at phase tau_m, the difference mapped
    back to the apex by Phi. With Coulomb friction of kinetic level ``kinetic`` the
    flight before the apex is the slip with x' > 0 (x + F_f obeys the frictionless
    equation) and the pull-back runs along the slip after it (the difference of two
    slips in the same direction obeys the linear flow). Returns (dv, alpha)."""
    alpha = p.d + height - math.cos(tau_m)
    s = 3.0 * math.sqrt(2.0 * height / (alpha - kinetic))
    dx, dv = to_deviation(p, tau_m, p.d + height + kinetic, 0.0)
    bx, bv = propagate(p.zeta, dx, dv, -s)
    tau0 = tau_m - p.omega * s
    x, v = to_physical(p, tau0, bx, bv)
    seg = advance(p, tau0, x - kinetic, v, 2.0 * s)
    free = advance(p.with_(delta_d=1.0), tau0, x - kinetic, v, 2.0 * s)
    tau1 = tau0 + 2.0 * p.omega * s
    ex, ev = to_deviation(p, tau1, seg.x, seg.v)
    fx, fv = to_deviation(p, tau1, free.x, free.v)
    return propagate(p.zeta, ex - fx, ev - fv, -s)[1], alpha

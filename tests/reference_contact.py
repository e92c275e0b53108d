"""Independent reference for the Kelvin-Voigt stop: scipy's DOP853 at rtol 1e-13.

Physical coordinates, the equation of motion written directly (no closed form), one
region at a time with terminal events, restarted at every switch. A contact entry that
the event location could miss (a penetration shorter than a step) is caught by a
terminal event at each maximum of x: if x > d there, the entry is the root of x - d
between the previous stop and that maximum, found by brentq on the dense output.
"""

from __future__ import annotations

import math

from scipy.integrate import solve_ivp
from scipy.optimize import brentq

RTOL = 2.5e-14
ATOL = 1e-15
DEBUG = False


def _solve(rhs, t0, y0, t1, events):
    return solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol=RTOL, atol=ATOL,
                     events=events, dense_output=True, max_step=0.05, first_step=1e-9)


def reference_advance(p, law, tau0, x, v, duration):
    """(x, v, contacts) after ``duration``; contacts as (t_entry, t_exit or inf)."""
    k, c, d, zeta, w = law.stiffness, law.damping, p.d, p.zeta, p.omega

    def free(t, y):
        return [y[1], math.cos(w * t + tau0) - 2.0 * zeta * y[1] - y[0]]

    def touch(t, y):
        return [y[1], math.cos(w * t + tau0) - 2.0 * zeta * y[1] - y[0]
                - k * (y[0] - d) - c * y[1]]

    def gap_up(t, y):
        return y[0] - d
    gap_up.terminal, gap_up.direction = True, 1.0

    def top(t, y):
        return y[1]
    top.terminal, top.direction = False, -1.0

    def force_down(t, y):
        return k * (y[0] - d) + c * y[1]
    force_down.terminal, force_down.direction = True, -1.0

    def force_up(t, y):
        return k * (y[0] - d) + c * y[1]
    force_up.terminal, force_up.direction = True, 1.0

    def gap_down(t, y):
        return y[0] - d
    gap_down.terminal, gap_down.direction = True, -1.0

    t, y = 0.0, [x, v]
    contacts = []
    delta = x - d
    region = "below" if delta <= 0.0 else ("contact" if k * delta + c * v > 0.0 else "above")
    entry = 0.0
    guard = 0
    while t < duration:
        if DEBUG: print(region, t, y)
        guard += 1
        assert guard < 100000
        if region == "below":
            sol = _solve(free, t, y, duration, [gap_up, top])
            hit = [s for s in sol.t_events[0] if s > t]
            end = hit[0] if hit else sol.t[-1]
            missed = [s for s in sol.t_events[1] if s < end and sol.sol(s)[0] > d]
            if missed:  # an entry inside one step: the root of x - d before that maximum
                lo = max([t] + [s for s in sol.t_events[1] if s < missed[0]])
                end = brentq(lambda s: sol.sol(s)[0] - d, lo, missed[0], xtol=1e-16)
                hit = [end]
            if hit:
                t, y = end, list(sol.sol(end))
                region, entry = "contact", t
                continue
            t, y = duration, list(sol.y[:, -1])
        elif region == "contact":
            sol = _solve(touch, t, y, duration, [force_down])
            if len(sol.t_events[0]):
                t, y = sol.t_events[0][0], list(sol.y_events[0][0])
                contacts.append((entry, t))
                region = "above" if y[0] > d else "below"
                continue
            contacts.append((entry, math.inf))
            t, y = duration, list(sol.y[:, -1])
        else:
            sol = _solve(free, t, y, duration, [force_up, gap_down])
            ev = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
            if ev:
                te0, i = min(ev)
                if i == 0 and sol.sol(te0)[0] < d:  # a missed return below x = d first
                    te0, i = brentq(lambda s: sol.sol(s)[0] - d, t, te0, xtol=1e-16), 1
                t, y = te0, list(sol.sol(te0))
                if i == 0:
                    region, entry = "contact", t
                else:
                    region = "below"
                continue
            t, y = duration, list(sol.y[:, -1])
    return y[0], y[1], contacts

"""DOP853 with ``solve_ivp``'s events, stepped by Hairer's Fortran code
(``scipy.integrate.ode``): the integrator of the contact references
(tests/reference_contact.py, tests/reference_hertz.py).

``solve_ivp`` steps DOP853 in Python: the references on it took about 5 times the CPU
they take on the Fortran original (benchmarks/bench_contact_reference.py; docs/
benchmarks.md, "The contact references on Hairer's DOP853"), and about a tenth of the
test workers' CPU. The method, its tolerances, largest and first step are the same;
what differs is how a state inside a step is had:

- the events are checked as ``solve_ivp`` checks them: their signs at the ends of each
  accepted step (``find_active_events``' rule), a root of an active one located by
  brentq at ``xtol = rtol = 4 eps``; the integration stops in the step of the first
  terminal one, at its root, and the roots of that step after it are dropped;
- the state at a time ``s`` inside a step is not DOP853's 7th-order interpolant but one
  DOP853 step of length ``s - t_i`` from the step's start ``t_i`` (shorter than the step
  the error control accepted there, so it is one step, and smooth in ``s``).

Only what the references read is kept: ``t_events``, ``t`` and ``y`` (the accepted
steps' ends, the last one the end or the terminal root), ``status`` and ``sol(s)``.
"""

from __future__ import annotations

import bisect

import numpy as np
from scipy.integrate import ode
from scipy.optimize import brentq

EPS = np.finfo(float).eps
#: steps one call may take (the references' longest: a period at max_step 0.005)
NSTEPS = 10 ** 7


def _integrator(rhs, rtol, atol, max_step, first_step=0.0):
    r = ode(rhs)
    r.set_integrator("dop853", rtol=rtol, atol=atol, nsteps=NSTEPS, max_step=max_step,
                     first_step=first_step)
    return r


class Solution:
    """What ``solve_ivp`` returns, for the fields the references read."""

    def __init__(self, rhs, rtol, atol, max_step, ts, ys, t_events, status):
        self._step = (rhs, rtol, atol, max_step)
        self.t = np.array(ts)
        self.y = np.array(ys).T
        self.t_events = [np.array(e) for e in t_events]
        self.status = status
        self._one_step = None

    def sol(self, s):
        """The state at ``s`` (t[0] <= s <= t[-1]): one DOP853 step from the last
        accepted step's start at or before ``s``."""
        i = bisect.bisect_right(self.t, s) - 1
        i = min(max(i, 0), len(self.t) - 1)
        t_i = self.t[i]
        if s == t_i:
            return self.y[:, i].copy()
        if self._one_step is None:
            self._one_step = _integrator(*self._step)
        r, h = self._one_step, s - t_i
        r._integrator.first_step = h                    # read by the reset below
        r._integrator.max_step = max(self._step[3], h)
        r.set_initial_value(self.y[:, i], t_i)
        return np.array(r.integrate(s))


def solve(rhs, t0, y0, t1, events, rtol, atol, max_step, first_step):
    """``solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol, atol, events, max_step,
    first_step)`` for t1 > t0, each event a function ``g(t, y)`` with ``terminal``
    (True or absent) and ``direction`` (absent: 0) read at this call."""
    direction = [float(getattr(e, "direction", 0.0)) for e in events]
    terminal = np.array([bool(getattr(e, "terminal", False)) for e in events])
    count = range(len(events))
    ts, ys = [], []
    brackets = []          # (step index, active event indices) of each step with a change
    g_old = [None]

    def on_step(t, y):     # plain floats: numpy's per-call cost was most of a step's
        y = y.copy()
        g_new = [e(t, y) for e in events]
        ts.append(t)
        ys.append(y)
        g = g_old[0]
        g_old[0] = g_new
        if g is None:
            return 0
        active = [k for k in count if (g[k] <= 0.0 <= g_new[k] and direction[k] >= 0.0)
                  or (g[k] >= 0.0 >= g_new[k] and direction[k] <= 0.0)]
        if not active:
            return 0
        brackets.append((len(ts) - 2, np.array(active)))
        return -1 if terminal[active].any() else 0

    r = _integrator(rhs, rtol, atol, max_step, first_step)
    r.set_solout(on_step)
    r.set_initial_value(y0, t0)
    r.integrate(t1)
    if not r.successful():
        raise RuntimeError(f"DOP853 failed at t = {r.t}: status {r.get_return_code()}")
    sol = Solution(rhs, rtol, atol, max_step, ts, ys, [], 0)
    t_events = [[] for _ in events]
    for i, active in brackets:
        roots = np.array([_root(events[k], sol, ts[i], ts[i + 1]) for k in active])
        if terminal[active].any():     # the last bracket: the integration stopped in it
            order = np.argsort(roots)
            active, roots = active[order], roots[order]
            first = np.flatnonzero(terminal[active])[0]
            active, roots = active[:first + 1], roots[:first + 1]
            y_root = sol.sol(roots[-1])
            sol.t = np.append(sol.t[:i + 1], roots[-1])
            sol.y = np.column_stack([sol.y[:, :i + 1], y_root])
            sol.status = 1
        for k, root in zip(active, roots):
            t_events[k].append(root)
    sol.t_events = [np.array(e) for e in t_events]
    return sol


def _root(event, sol, t_a, t_b):
    """``solve_ivp``'s ``solve_event_equation``, on :meth:`Solution.sol`."""
    return brentq(lambda s: event(s, sol.sol(s)), t_a, t_b, xtol=4 * EPS, rtol=4 * EPS)

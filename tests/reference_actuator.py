"""An independent reference for the motion through a first-order actuator: scipy's DOP853
of (x, v, f) with the lag as an ODE, tau_a f' = u(t) - f (or f = u for tau_a = 0),
x'' + 2 zeta x' + x = cos(tau2 + omega t) + f, event location at the wall x = d and the
impact law v -> -r v there (rtol 1e-13, max_step 0.05 by default). Shared by tests/test_actuator.py,
tests/test_plant_actuator.py and benchmarks/bench_actuator_reference.py.
"""

import math

import numpy as np
from scipy.integrate import solve_ivp


def lag_reference(p, x, v, f0, pieces, duration, times=(), max_step=0.05):
    """(x, v, f) at ``duration``, the impacts [(t, v-)] and the physical (x, v) at
    ``times`` (sorted, in (0, duration]). ``pieces``: [(t_on, u, impulse)] switches of
    the command u (piecewise constant, 0 before the first) and impulses (an impulse J
    through the lag adds J / tau_a to f, without lag J to v), with the actuator's
    ``tau_a`` = pieces' attribute (see :func:`pulse_pieces`). The event is located
    where the sign of the gap changes between steps: a penetration shorter than
    ``max_step`` (a shallow impact) can be missed; use a smaller one there."""
    tau_a = pieces.tau_a
    times = np.asarray(times, dtype=float)
    dense = np.full((times.size, 2), np.nan)

    def rhs(t, y, cmd):
        force = y[2] if tau_a > 0.0 else cmd
        df = (cmd - y[2]) / tau_a if tau_a > 0.0 else 0.0
        return [y[1], -2 * p.zeta * y[1] - y[0] + math.cos(p.tau2 + p.omega * t) + force, df]

    def wall(t, y, cmd):
        return y[0] - p.d
    wall.terminal, wall.direction = True, 1
    y, impacts, cmd = [x, v, f0], [], 0.0
    bounds = [(t, u, j) for t, u, j in pieces.switches] + [(duration, None, 0.0)]
    t = 0.0
    for t1, u_next, impulse in bounds:
        while t < t1:
            sol = solve_ivp(rhs, (t, t1), y, method="DOP853", rtol=1e-13, atol=1e-15,
                            events=wall, args=(cmd,), max_step=max_step, dense_output=True)
            t_end = float(sol.t_events[0][0]) if sol.status == 1 else t1
            inside = (times > t) & (times <= t_end)
            if inside.any():
                dense[inside] = sol.sol(times[inside])[:2].T
            if sol.status == 1:
                xe, ve, fe = sol.y_events[0][0]
                impacts.append((t_end, ve))
                y = [p.d, -p.r * ve, fe]
                t = t_end + 1e-12
            else:
                t, y = t1, list(sol.y[:, -1])
        if u_next is not None:
            if impulse:
                if tau_a > 0.0:
                    y[2] += impulse / tau_a
                else:
                    y[1] += impulse
            cmd = u_next
            if tau_a == 0.0:
                y[2] = cmd
    return np.array(y), impacts, dense


class Pieces:
    """A command's switches [(t, u, impulse)] through an actuator of lag ``tau_a``."""

    def __init__(self, switches, tau_a):
        self.switches, self.tau_a = list(switches), tau_a


def pulse_pieces(on, width, force, tau_a):
    """A pulse of ``force`` on [on, on + width] (width 0: an impulse ``force``)."""
    if width > 0.0:
        return Pieces([(on, force, 0.0), (on + width, 0.0, 0.0)], tau_a)
    return Pieces([(on, 0.0, force)], tau_a)

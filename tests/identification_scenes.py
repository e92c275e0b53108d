"""Synthetic recordings for the identification tests: the exact simulation (the same
period_step and dense output sim_node uses), in a rig's units, through the package's
SensorModel; and a wrong model (a soft wall: a penalty spring, solve_ivp)."""

import math

import numpy as np
from scipy.integrate import solve_ivp

from grazing_control.dynamics.identification import Recording
from grazing_control.dynamics.simulation.simulate import period_step, states_between
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

#: A scene with impacts of every size: off the 1/1 orbit, d below grazing.
SCENE = OscillatorParams(delta_d=-0.05)


def exact_motion(p, periods, samples_per_period=16, deviation=(0.3, -0.2), ns=False,
                 gains=None, control_after=0):
    """(t, x, v, tau, impacts [t, v-, v+, phase], corrections [t, dv]) of the exact
    motion, nondimensional, sampled on t_j = j T / samples_per_period (rounded to whole ns
    if ``ns``); with ``gains`` the controller of Eq. 28 acts at the Pi2 samples k >=
    control_after (t = k T)."""
    T = p.period
    n = periods * samples_per_period
    t = np.arange(n) * (T / samples_per_period)
    if ns:
        t = np.round(t * 1e9) / 1e9
    dx, dv = deviation
    xs, vs, imps, corr = np.empty(n), np.empty(n), [], []
    for k in range(periods):
        dvc = gains.c1 * dx + gains.c2 * dv if gains is not None and k >= control_after else 0.0
        if dvc:
            corr.append((k * T, dvc))
        seg = period_step(p, dx, dv, dvc)
        sel = (t >= k * T) & (t < (k + 1) * T)
        out = states_between(p, p.tau2, dx, dv + dvc, seg.impacts, t[sel] - k * T)
        xs[sel], vs[sel] = out[:, 0], out[:, 1]
        for i in seg.impacts:
            imps.append((k * T + i.dt, i.v_minus, i.v_plus, i.phase))
        dx, dv = seg.dx, seg.dv
    tau = p.tau2 + p.omega * t
    return t, xs, vs, tau, np.array(imps).reshape(-1, 4), np.array(corr).reshape(-1, 2)


def rig_recording(p=SCENE, periods=24, *, noise=0.0, seed=0, velocity=True, sin=True,
                  Omega=1.0, A=1.0, theta=0.0, impacts=True, samples_per_period=16,
                  deviation=(0.3, -0.2), gains=None, control_after=0):
    """A Recording of the exact motion in a rig's units (natural frequency Omega, forcing
    amplitude A, force theta behind the reference), measured by SensorModel(noise, seed)."""
    t, x, v, tau, imp, corr = exact_motion(p, periods, samples_per_period, deviation,
                                           gains=gains, control_after=control_after)
    L = A / Omega ** 2
    sensor = SensorModel(noise=noise, velocity=velocity, seed=seed)
    xm, vm = sensor.measure(0, x * L, v * L * Omega)
    ref = tau - theta
    it = imp[:, 0] / Omega if impacts else np.zeros(0)
    return Recording(t / Omega, xm, vm, np.cos(ref), np.sin(ref) if sin else np.full(t.size, np.nan),
                     it, imp[:, 1] * L * Omega if impacts else np.zeros(0),
                     imp[:, 2] * L * Omega if impacts else np.zeros(0), corr[:, 0] / Omega)


def soft_wall_recording(p=SCENE, periods=24, *, stiffness=1e3, damping=None, noise=0.0, seed=0,
                        samples_per_period=16, deviation=(0.3, -0.2)):
    """The motion against a soft wall (contact force -k (x - d) - c v for x > d, c from
    the restitution r of a linear contact), by solve_ivp (DOP853, rtol 1e-12) phase by
    phase: free flight until x = d, contact until x = d again (events); the 'impacts' are
    the contacts' entries (time, v-) and exits (v+)."""
    if damping is None:   # r = exp(-pi zeta_c / sqrt(1 - zeta_c^2)) for the contact
        lr = math.log(p.r)
        zc = -lr / math.hypot(math.pi, lr)
        damping = 2.0 * zc * math.sqrt(stiffness)
    d = p.d

    def free(t, y):
        return [y[1], math.cos(p.omega * t + p.tau2) - 2 * p.zeta * y[1] - y[0]]

    def contact(t, y):
        f = free(t, y)
        return [f[0], f[1] - stiffness * (y[0] - d) - damping * y[1]]

    def wall(t, y):
        return y[0] - d

    wall.terminal = True
    T = p.period
    n = periods * samples_per_period
    t = np.arange(n) * (T / samples_per_period)
    x, v = np.empty(n), np.empty(n)
    y = [p.x_ref + deviation[0], p.v_ref + deviation[1]]
    t0, inside, imps, entry = 0.0, False, [], None
    while t0 < t[-1]:
        wall.direction = -1.0 if inside else 1.0
        sol = solve_ivp(contact if inside else free, (t0, t[-1]), y, rtol=1e-12, atol=1e-13,
                        method="DOP853", events=wall, dense_output=True,
                        first_step=1e-6 if t0 > 0 else None)
        t1 = sol.t[-1]
        sel = (t >= t0) & (t <= t1)
        if np.any(sel):
            x[sel], v[sel] = sol.sol(t[sel])
        if sol.status != 1:
            break
        y = sol.y_events[0][0].copy()
        y[0] = d
        if inside:
            imps.append((entry[0], entry[1], y[1]))
        else:
            entry = (sol.t_events[0][0], y[1])
        t0, inside = sol.t_events[0][0], not inside
    imps = np.array(imps).reshape(-1, 3)
    sensor = SensorModel(noise=noise, seed=seed)
    xm, vm = sensor.measure(0, x, v)
    tau = p.tau2 + p.omega * t
    return Recording(t, xm, vm, np.cos(tau), np.sin(tau), imps[:, 0], imps[:, 1], imps[:, 2])

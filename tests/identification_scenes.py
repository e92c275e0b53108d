"""Synthetic recordings for the identification tests: the exact simulation (the same
period_step and dense output sim_node uses), in a rig's units, through the package's
SensorModel; and a wrong model (a soft wall: a penalty spring, solve_ivp)."""

import math

import numpy as np
from scipy.integrate import solve_ivp

from grazing_control.dynamics.identification import Recording
from grazing_control.dynamics.simulate import period_step, states_between
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

#: A scene with impacts of every size: off the 1/1 orbit, d below grazing.
SCENE = OscillatorParams(delta_d=-0.05)


def exact_motion(p, periods, samples_per_period=16, deviation=(0.3, -0.2), ns=False):
    """(t, x, v, tau, impacts [t, v-, v+, phase]) of the exact motion, nondimensional,
    sampled on t_j = j T / samples_per_period (rounded to whole ns if ``ns``)."""
    T = p.period
    n = periods * samples_per_period
    t = np.arange(n) * (T / samples_per_period)
    if ns:
        t = np.round(t * 1e9) / 1e9
    dx, dv = deviation
    xs, vs, imps = np.empty(n), np.empty(n), []
    for k in range(periods):
        seg = period_step(p, dx, dv)
        sel = (t >= k * T) & (t < (k + 1) * T)
        out = states_between(p, p.tau2, dx, dv, seg.impacts, t[sel] - k * T)
        xs[sel], vs[sel] = out[:, 0], out[:, 1]
        for i in seg.impacts:
            imps.append((k * T + i.dt, i.v_minus, i.v_plus, i.phase))
        dx, dv = seg.dx, seg.dv
    tau = p.tau2 + p.omega * t
    return t, xs, vs, tau, np.array(imps).reshape(-1, 4)


def rig_recording(p=SCENE, periods=24, *, noise=0.0, seed=0, velocity=True, sin=True,
                  Omega=1.0, A=1.0, theta=0.0, impacts=True, samples_per_period=16,
                  deviation=(0.3, -0.2)):
    """A Recording of the exact motion in a rig's units (natural frequency Omega, forcing
    amplitude A, force theta behind the reference), measured by SensorModel(noise, seed)."""
    t, x, v, tau, imp = exact_motion(p, periods, samples_per_period, deviation)
    L = A / Omega ** 2
    sensor = SensorModel(noise=noise, velocity=velocity, seed=seed)
    xm, vm = sensor.measure(0, x * L, v * L * Omega)
    ref = tau - theta
    it = imp[:, 0] / Omega if impacts else np.zeros(0)
    return Recording(t / Omega, xm, vm, np.cos(ref), np.sin(ref) if sin else np.full(t.size, np.nan),
                     it, imp[:, 1] * L * Omega if impacts else np.zeros(0),
                     imp[:, 2] * L * Omega if impacts else np.zeros(0))


def soft_wall_recording(p=SCENE, periods=24, *, stiffness=1e3, damping=None, noise=0.0, seed=0,
                        samples_per_period=16, deviation=(0.3, -0.2)):
    """The motion against a soft wall (contact force -k (x - d) - c v for x > d, c from
    the restitution of a linear contact), by solve_ivp at tight tolerances; the 'impacts'
    are the contacts' entries (v-) and exits (v+)."""
    if damping is None:   # r = exp(-pi zeta_c / sqrt(1 - zeta_c^2)) for the contact
        lr = math.log(p.r)
        zc = -lr / math.hypot(math.pi, lr)
        damping = 2.0 * zc * math.sqrt(stiffness)
    d = p.d

    def f(t, y):
        x, v = y
        force = math.cos(p.omega * t + p.tau2) - 2 * p.zeta * v - x
        if x > d:
            force -= stiffness * (x - d) + damping * v
        return [v, force]

    T = p.period
    n = periods * samples_per_period
    t = np.arange(n) * (T / samples_per_period)
    y0 = [p.x_ref + deviation[0], p.v_ref + deviation[1]]
    sol = solve_ivp(f, (0, t[-1]), y0, t_eval=t, rtol=1e-12, atol=1e-13, max_step=0.01,
                    method="DOP853")
    x, v = sol.y
    # contacts: entries and exits on a fine grid
    fine = solve_ivp(f, (0, t[-1]), y0, rtol=1e-12, atol=1e-13, max_step=0.002,
                     method="DOP853", dense_output=True)
    tf = np.arange(0, t[-1], 0.002)
    xf, vf = fine.sol(tf)
    inside = xf > d
    starts = np.flatnonzero(~inside[:-1] & inside[1:])
    ends = np.flatnonzero(inside[:-1] & ~inside[1:])
    imps = []
    for s in starts:
        e = ends[ends > s]
        if e.size:
            imps.append((tf[s], vf[s], vf[e[0] + 1]))
    imps = np.array(imps).reshape(-1, 3)
    sensor = SensorModel(noise=noise, seed=seed)
    xm, vm = sensor.measure(0, x, v)
    tau = p.tau2 + p.omega * t
    return Recording(t, xm, vm, np.cos(tau), np.sin(tau), imps[:, 0], imps[:, 1], imps[:, 2])

"""The estimator's model of the actuator (estimation.trajectory with an actuator): the
plant's actuated map (actuator.actuated_step, itself checked against solve_ivp in
tests/test_actuator.py) at the period's end and its dense output (actuator.lag_states
over the plant's legs) at every sample, over >= 1000 seeded cases with a force carried
over from the previous period and impacts during the force's transient; the Jacobian
and the wall's sensitivity against finite differences; no actuator is today's
trajectory bit for bit."""

import math

import numpy as np
import pytest

from grazing_control.dynamics.simulation.actuation import pulse_force, pulse_start
from grazing_control.dynamics.simulation.actuator import Actuator, actuated_step, lag_flow, lag_states
from grazing_control.dynamics.estimation.motion import section_force, trajectory
from grazing_control.oscillator.params import OscillatorParams, ParameterError

TWO_PI = 2.0 * math.pi


def plant_states(p, z0, force0, dv, start, width, act, limit, s):
    """The plant's (x, v) deviation at the times s: actuated_step's legs, each a lag_flow
    read by lag_states (the simulator's dense output, plant/engine.py)."""
    tau_a = act.time_constant
    on, off = start + act.latency, start + act.latency + width
    f_cmd = pulse_force(dv, width, limit)
    out = np.full((s.size, 2), np.nan)
    z, f, t = (float(z0[0]), float(z0[1])), force0, 0.0
    for end, u in ((on, 0.0), (off, f_cmd), (p.period, 0.0)):
        if end > t:
            flow = lag_flow(p, (p.tau2 + p.omega * t) % TWO_PI, z[0], z[1], end - t, u,
                            f - u if tau_a > 0.0 else 0.0, tau_a)
            mask = (s > t) & (s <= end)
            if mask.any():
                psi = p.tau2 + p.omega * s[mask] - p.lag
                xv = lag_states(p, flow, s[mask] - t)
                out[mask, 0] = xv[:, 0] - p.amplitude * np.cos(psi)
                out[mask, 1] = xv[:, 1] + p.amplitude * p.omega * np.sin(psi)
            z, f = (flow.dx, flow.dv), flow.force if tau_a > 0.0 else u
        t = end
    return out


def random_case(rng):
    p = OscillatorParams(delta_d=float(rng.uniform(-2e-2, 2e-3)))
    width = float(rng.uniform(0.05, 0.6))
    tau_a = 0.0 if rng.random() < 0.1 else float(p.period / TWO_PI / rng.uniform(1.0, 20.0))
    latency = 0.0 if rng.random() < 0.5 else float(rng.uniform(0.0, 0.5))
    act = Actuator(tau_a, latency)
    delay = float(rng.uniform(0.5 * width, p.period - 0.5 * width - latency - 1e-3))
    z0 = (float(rng.normal(0.0, 0.03)), float(rng.normal(0.0, 0.03)))
    dv = float(rng.normal(0.0, 0.05))
    force0 = float(rng.normal(0.0, 0.2)) if tau_a > 0.0 else 0.0
    limit = math.inf if rng.random() < 0.7 else float(abs(dv) / width * rng.uniform(0.3, 1.5))
    return p, width, delay, act, z0, dv, force0, limit


@pytest.mark.parametrize("seed", range(4))
def test_the_actuated_trajectory_is_the_plants_actuated_map_at_every_sample(seed):
    rng = np.random.default_rng(seed)
    transient = cases = 0
    for _ in range(260):
        p, width, delay, act, z0, dv, force0, limit = random_case(rng)
        start = pulse_start(p.period, delay, width)
        s = np.sort(rng.uniform(0.0, p.period, 12))
        s[-1] = p.period
        try:
            out, _jac, end, _m, imps = trajectory(p, z0, s, dv, delay, width=width,
                                                  force_limit=limit, actuator=act,
                                                  force0=force0)
        except ValueError:          # a chattering or sticking motion: no fit
            continue
        x, v, f_end, plant_imps = actuated_step(p, *z0, force0, dv, start=start, width=width,
                                                actuator=act, force_limit=limit)
        assert len(imps) == len(plant_imps)
        scale = 1.0 + float(np.abs(end).max())
        assert np.abs(np.array(end) - (x, v)).max() <= 1e-11 * scale
        assert section_force(p, force0, dv, delay, width, limit, act) == pytest.approx(
            f_end, rel=1e-12, abs=1e-15)
        want = plant_states(p, z0, force0, dv, start, width, act, limit, s)
        assert np.abs(out - want).max() <= 1e-11 * scale
        # an impact while the force still moves: the carried force's decay, the pulse
        # and 3 tau_a after it
        on, tau3 = start + act.latency, 3.0 * act.time_constant
        transient += sum(i[0] < tau3 and force0 != 0.0 or on < i[0] < on + width + tau3
                         for i in imps)
        cases += 1
    assert cases >= 250 and transient >= 10


def test_the_jacobian_and_the_wall_sensitivity_through_the_actuator_are_the_fd_ones():
    rng = np.random.default_rng(42)
    checked = 0
    for _ in range(80):
        p, width, delay, act, z0, dv, force0, limit = random_case(rng)
        s = np.linspace(0.1, p.period, 25)
        kw = dict(width=width, force_limit=limit, actuator=act, force0=force0)
        try:
            out, jac, end, mono, imps, gs, gend = trajectory(p, z0, s, dv, delay, wall=True,
                                                             **kw)
            h = 1e-7
            cols = []
            for e in (np.array([h, 0.0]), np.array([0.0, h])):
                up = trajectory(p, np.add(z0, e), s, dv, delay, **kw)
                dn = trajectory(p, np.subtract(z0, e), s, dv, delay, **kw)
                cols.append((up, dn))
            wall = [trajectory(p.with_(delta_d=p.delta_d + sg * h), z0, s, dv, delay, **kw)
                    for sg in (1.0, -1.0)]
        except ValueError:
            continue
        if any(len(u[4]) != len(imps) or len(d[4]) != len(imps) for u, d in cols + [wall]):
            continue                  # an impact appears within h: not differentiable
        for i, (up, dn) in enumerate(cols):
            fd = (up[0] - dn[0]) / (2 * h)
            np.testing.assert_allclose(jac[:, :, i], fd, atol=2e-5 * (1 + np.abs(fd).max()))
            np.testing.assert_allclose(mono[:, i], (np.array(up[2]) - dn[2]) / (2 * h),
                                       atol=2e-5 * (1 + np.abs(mono).max()))
        fd = (wall[0][0] - wall[1][0]) / (2 * h)
        np.testing.assert_allclose(gs, fd, atol=2e-5 * (1 + np.abs(fd).max()))
        checked += bool(imps)
    assert checked >= 30


def test_no_actuator_or_the_ideal_one_is_todays_pulse_bit_for_bit():
    rng = np.random.default_rng(3)
    for _ in range(50):
        p, width, delay, _a, z0, dv, _f, limit = random_case(rng)
        s = np.sort(rng.uniform(0.0, p.period, 10))
        try:
            a = trajectory(p, z0, s, dv, delay, width=width, force_limit=limit)
        except ValueError:
            continue
        for act in (None, Actuator()):
            b = trajectory(p, z0, s, dv, delay, width=width, force_limit=limit, actuator=act)
            for x, y in zip(a[:4], b[:4]):
                np.testing.assert_array_equal(x, y)


def test_a_latency_past_the_period_is_refused_naming_it():
    p = OscillatorParams(delta_d=-1e-3)
    with pytest.raises(ParameterError, match=r"^actuator_latency=.* is invalid: valid range"):
        trajectory(p, (0.0, 0.0), np.array([1.0]), 0.01, 3.0, width=0.1,
                   actuator=Actuator(0.05, p.period - 3.0))

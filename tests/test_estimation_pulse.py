"""The estimator's model of the rig's force pulse (estimation.trajectory with width > 0):
the exact pulse map of the plant (actuation.pulse_step, itself checked against
solve_ivp in tests/test_actuation_pulse.py) at every sample time and at the period's
end, over seeded random cases with impacts before, during and after the pulse; the
Jacobian against finite differences; width 0 the kick bit for bit."""

import math

import numpy as np
import pytest

from grazing_control.dynamics.simulation.actuation import flow_with_force, pulse_start, pulse_step
from grazing_control.dynamics.estimation.motion import correction_legs, trajectory
from grazing_control.oscillator import kernel
from grazing_control.oscillator.params import OscillatorParams, ParameterError

TWO_PI = 2.0 * math.pi


def pulse_state_at(p, z0, dv, start, width, limit, t):
    """The plant's state at time t after the section: the pulse map's pieces cut at t."""
    advance = kernel.exact_advance()
    force = max(-limit, min(limit, dv / width))
    dx, dv_ = z0
    now, n_imp = 0.0, 0
    for duration, f in ((start, 0.0), (width, force), (p.period - start - width, 0.0)):
        d = min(duration, t - now)
        if d <= 0.0:
            break
        seg = flow_with_force(p, (p.tau2 + p.omega * now) % TWO_PI, dx, dv_, d, f, advance)
        dx, dv_ = seg.dx, seg.dv
        n_imp += len(seg.impacts)
        now += d
    return np.array([dx, dv_]), n_imp


def random_case(rng):
    p = OscillatorParams(delta_d=float(rng.uniform(-2e-2, 2e-3)))
    width = float(rng.uniform(0.01, 0.6))
    delay = float(rng.uniform(0.5 * width, p.period - 0.5 * width - 1e-3))
    z0 = (float(rng.normal(0.0, 0.03)), float(rng.normal(0.0, 0.03)))
    dv = float(rng.normal(0.0, 0.05))
    limit = math.inf if rng.random() < 0.7 else float(abs(dv) / width * rng.uniform(0.3, 1.5))
    return p, width, delay, z0, dv, limit


@pytest.mark.parametrize("seed", range(4))
def test_the_pulse_trajectory_is_the_plants_pulse_map_at_every_sample(seed):
    rng = np.random.default_rng(seed)
    during = 0
    for _ in range(250):
        p, width, delay, z0, dv, limit = random_case(rng)
        start = pulse_start(p.period, delay, width)
        s = np.sort(rng.uniform(0.0, p.period, 12))
        s[-1] = p.period
        try:
            out, _jac, end, _m, imps = trajectory(p, z0, s, dv, delay, width=width,
                                                  force_limit=limit)
        except ValueError:          # a sticking motion: the model refuses to fit it
            continue
        seg = pulse_step(p, *z0, dv, start=start, width=width, force_limit=limit)
        assert len(imps) == len(seg.impacts)
        scale = 1.0 + float(np.abs(end).max())
        assert np.abs(np.array(end) - (seg.dx, seg.dv)).max() <= 1e-11 * scale
        for j, t in enumerate(s):
            want, _n = pulse_state_at(p, z0, dv, start, width, limit, t)
            assert np.abs(out[j] - want).max() <= 1e-11 * scale, (j, t)
        during += sum(start < i[0] < start + width for i in imps)
    assert during > 0            # impacts inside the pulse were exercised


def test_the_jacobian_through_a_pulse_is_the_finite_difference_one():
    rng = np.random.default_rng(42)
    checked = 0
    for _ in range(60):
        p, width, delay, z0, dv, limit = random_case(rng)
        s = np.linspace(0.1, p.period, 25)
        try:
            out, jac, end, mono, _ = trajectory(p, z0, s, dv, delay, width=width,
                                                force_limit=limit)
        except ValueError:
            continue
        h = 1e-7
        for i in range(2):
            e = np.zeros(2)
            e[i] = h
            try:
                up = trajectory(p, np.add(z0, e), s, dv, delay, width=width,
                                force_limit=limit)
                dn = trajectory(p, np.subtract(z0, e), s, dv, delay, width=width,
                                force_limit=limit)
            except ValueError:
                break
            if len(up[4]) != len(dn[4]):
                break                 # an impact appears within h: not differentiable
            fd = (up[0] - dn[0]) / (2 * h)
            np.testing.assert_allclose(jac[:, :, i], fd, atol=2e-5 * (1 + np.abs(fd).max()))
            np.testing.assert_allclose(mono[:, i], (np.array(up[2]) - dn[2]) / (2 * h),
                                       atol=2e-5 * (1 + np.abs(mono).max()))
        else:
            checked += 1
    assert checked >= 30


def test_width_zero_is_the_kick_bit_for_bit():
    rng = np.random.default_rng(3)
    for _ in range(50):
        p, _w, delay, z0, dv, _l = random_case(rng)
        s = np.sort(rng.uniform(0.0, p.period, 10))
        try:
            a = trajectory(p, z0, s, dv, delay)
        except ValueError:
            continue
        b = trajectory(p, z0, s, dv, delay, width=0.0)
        for x, y in zip(a[:4], b[:4]):
            np.testing.assert_array_equal(x, y)


def test_a_pulse_too_wide_for_the_period_is_refused_naming_it():
    p = OscillatorParams(delta_d=-1e-3)
    with pytest.raises(ParameterError, match=r"^pulse_width=.* is invalid: valid range is "):
        correction_legs(0.1, 1.0, p.period, width=p.period)
    # no correction: no pulse, one leg
    assert correction_legs(0.0, 1.0, p.period, width=0.3) == [(0.0, 1.0, 0.0, 0.0),
                                                               (1.0, p.period, 0.0, 0.0)]

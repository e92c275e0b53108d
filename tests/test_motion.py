"""dynamics/estimation/motion.py, the motion the model filter fits, for every model
(docs/theory_estimation.md, (E11)): a model file's motion of motion.trajectory (free,
through the kick, the force pulse and the first-order actuator) against the exact core
and the 1-DOF closed form, and model_update on a stream of one coordinate's position
against the exact n-DOF flow (the 1-DOF motion: tests/test_estimation*.py)."""

import dataclasses
import math

import numpy as np
import pytest

from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.estimation import motion as mo
from grazing_control.dynamics.estimation import section_state as ss
from grazing_control.dynamics.maps.modal_map import actuated_step
from grazing_control.dynamics.simulation import actuation
from grazing_control.dynamics.simulation import actuator as act
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.forced import actuated_mass
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.oscillator.params import ParameterError

from test_family import CHAIN, _study

RATE = 200                      # samples per period (T/200, the sensor)


def _exact_samples(model, z0, s, correction, delay):
    """z at the times s (sorted, in (0, T]) by the certified core alone: advance from
    sample to sample, the kick applied at ``delay`` (an independent route: no Jacobians,
    no reconstruction of the impacts)."""
    flow = NdofFlow.of(model)
    legs = [(0.0, delay, 0.0), (delay, model.period, correction)] if delay > 0.0 else \
        [(0.0, model.period, correction)]
    out, z = [], np.array(z0, dtype=float)
    for start, end, kick in legs:
        z = z.copy()
        z[model.n + model.i_a] += kick
        t = start
        for tj in [x for x in s if start < x <= end] + [end]:
            if tj > t:
                z = advance(flow, (flow.tau2 + model.omega * t) % (2 * math.pi), z, tj - t).z
                t = tj
            if tj in s:
                out.append(z.copy())
    return np.array(out[:len(s)]), z


def test_n1_model_motion_is_the_1dof_closed_form():
    """The n = 1 model file through the n-DOF motion equals section_state's closed form
    (states, Jacobians, monodromy) with an impact in the period, with and without delay."""
    m, p = _study()
    m, p = dataclasses.replace(m, delta_d=-0.05), p.with_(delta_d=-0.05)
    s = np.linspace(0.0, p.period, RATE + 1)[1:]
    for z0, corr, delay in (((0.01, -0.02), 0.03, 2.0), ((0.0, 0.0), -0.01, 0.0)):
        a = mo.trajectory(p, z0, s, corr, delay)
        b = mo.trajectory(m, z0, s, corr, delay)
        assert len(a[4]) == len(b[4]) == 1
        assert np.max(np.abs(a[0] - b[0])) <= 1e-13
        assert np.max(np.abs(np.array(a[2]) - b[2])) <= 1e-13
        assert np.max(np.abs(a[1] - b[1])) <= 1e-12 * np.max(np.abs(a[1]))
        assert np.max(np.abs(a[3] - b[3])) <= 1e-12 * np.max(np.abs(a[3]))


def test_n_dof_motion_against_the_core_and_finite_differences():
    """Chain, an impact after a delayed kick: the states at T/200 equal the core's
    sample-to-sample flow to 1e-14, the Jacobians central differences to 1e-9."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.05)
    s = np.linspace(0.0, m.period, RATE + 1)[1:]
    z0, corr, delay = np.array([0.01, -0.02, 0.005, 0.01]), 0.03, 2.0
    out, jac, end, mono, impacts = mo.trajectory(m, z0, s, corr, delay)
    truth, end_truth = _exact_samples(m, z0, s, corr, delay)
    assert len(impacts) == 1 and impacts[0][0] > delay
    assert np.max(np.abs(out - truth)) <= 1e-14
    assert np.max(np.abs(end - end_truth)) <= 1e-14
    h = 1e-6
    for j in range(4):
        e = np.zeros(4)
        e[j] = h
        fd = (mo.trajectory(m, z0 + e, s, corr, delay)[0]
              - mo.trajectory(m, z0 - e, s, corr, delay)[0]) / (2 * h)
        assert np.max(np.abs(fd - jac[:, :, j])) <= 1e-9


@pytest.mark.parametrize("shape", ["kick", "pulse", "actuator"])
def test_n_dof_wall_sensitivity_is_that_of_finite_differences(shape):
    """(E12) on the chain at Delta d = -0.05, one impact after the delayed correction (a
    kick, a pulse of width 1, the pulse through the actuator tau_a 0.4 / latency 0.2 from
    force0 0.003): d end / d Delta d (|.| ~ 5) and d z(s_j) / d Delta d equal central
    differences with h = 1e-7 to 1e-8 (measured 5.9e-10, 2.7e-9, 2.1e-9; the samples
    within 1e-3 of the impact jump with it), zero before the impact; the other outputs
    are those without ``wall``, bit for bit."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.05)
    s = np.linspace(0.0, m.period, RATE + 1)[1:]
    z0, corr, delay = np.array([0.01, -0.02, 0.005, 0.01]), 0.03, 2.0
    kw = {"kick": {}, "pulse": {"width": 1.0},
          "actuator": {"width": 1.0, "actuator": act.Actuator(0.4, 0.2), "force0": 0.003}}[shape]
    out, jac, end, mono, imps, gs, gend = mo.trajectory(m, z0, s, corr, delay, wall=True, **kw)
    plain = mo.trajectory(m, z0, s, corr, delay, **kw)
    for a, b in zip(plain[:4], (out, jac, end, mono)):
        assert np.array_equal(a, b)
    assert plain[4] == imps and len(imps) == 1 and np.linalg.norm(gend) > 4.0
    h = 1e-7
    up, down = (mo.trajectory(dataclasses.replace(m, delta_d=m.delta_d + e), z0, s, corr,
                              delay, **kw) for e in (h, -h))
    assert np.max(np.abs((up[2] - down[2]) / (2 * h) - gend)) <= 1e-8
    far = np.abs(s - imps[0][0]) > 1e-3
    assert np.max(np.abs(((up[0] - down[0]) / (2 * h) - gs)[far])) <= 1e-8
    assert np.all(gs[s < imps[0][0]] == 0.0)


def test_n1_wall_sensitivity_is_the_1dof_closed_forms():
    """The n = 1 model file's (E12) equals the 1-DOF closed form's (E8), an independent
    implementation, to 1e-12 relative with an impact after a delayed kick."""
    m, p = _study()
    m, p = dataclasses.replace(m, delta_d=-0.05), p.with_(delta_d=-0.05)
    s = np.linspace(0.0, p.period, RATE + 1)[1:]
    a = mo.trajectory(p, (0.01, -0.02), s, 0.03, 2.0, wall=True)
    b = mo.trajectory(m, (0.01, -0.02), s, 0.03, 2.0, wall=True)
    assert len(a[4]) == len(b[4]) == 1
    assert np.max(np.abs(a[5] - b[5])) <= 1e-12 * np.max(np.abs(a[5]))
    assert np.max(np.abs(np.array(a[6]) - b[6])) <= 1e-12 * np.max(np.abs(a[6]))


@pytest.fixture(scope="module")
def controlled_chain():
    """The chain at Delta d = -1e-3 under the design mu = 0.2 (one impact per period,
    v- ~ 0.03), from a start near its 1/1 orbit: the true Pi2 states z_k, the known
    corrections k^T z_k and the exact deviations of every coordinate at T/200."""
    return closed_loop_chain(lambda m: nd.gain_family(m, 0.2),
                             lambda m, z, s, dv: _exact_samples(m, z, s, dv, 0.0))


def closed_loop_chain(gains, exact):
    """6 periods of the chain at Delta d = -1e-3 under the gains ``gains(m)`` from near
    its 1/1 orbit, each period by ``exact(m, z, s, correction) -> (samples, end)``:
    (m, s, the true Pi2 states, the corrections, the samples at T/200)."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    k = gains(m)
    s = np.linspace(0.0, m.period, RATE + 1)[1:]
    z = np.array([2e-3, -1e-3, 1e-3, 2e-3])
    states, corrections, samples = [], [], []
    for _ in range(6):
        states.append(z)
        corrections.append(float(k @ z))
        zs, z = exact(m, z, s, corrections[-1])
        samples.append(zs)
    states.append(z)
    return m, s, np.array(states), corrections, samples


@pytest.mark.parametrize("coordinate", [0, 1])
def test_noise_free_samples_of_one_position_give_the_pi2_state(controlled_chain, coordinate):
    """Position of x0 (the wall coordinate) or x1 only, no noise (sigma 1e-12): from a
    prior 1e-3 off, the filter's Pi2 state is the exact one to 1e-10 after one period
    and stays there (each period's samples determine all 2n coordinates)."""
    m, s, states, corrections, samples = controlled_chain
    prior = ss.FilterState(tuple(states[0] + 1e-3), 1e-4 * np.eye(4))
    nan = np.full(len(s), math.nan)
    for k in range(len(corrections)):
        prior, chi2, count = ss.model_update(m, prior, s, samples[k][:, coordinate], nan,
                                             1e-12, corrections[k], floor=0.0,
                                             coordinate=coordinate)
        assert count == RATE
        assert np.max(np.abs(np.array(prior.z) - states[k + 1])) <= 1e-10


@pytest.mark.parametrize("coordinate", [0, 1])
def test_noisy_filter_error_spread_matches_its_covariance(controlled_chain, coordinate):
    """Position of x0 or x1 with noise sigma = 1e-4 at T/200, 40 seeded runs of 6 periods
    from a prior drawn from its covariance (1e-4)^2 I: each coordinate's final error over
    its reported standard deviation has a spread of 1 (+-25 %), and the normalised square
    e^T P^-1 e is not above chi^2_4's mean (4 + 3 standard errors). Its mean is below 4
    (measured 2.1 .. 2.9): the three directions that the period's samples determine best
    sit at the filter's floor (1e-2 sigma, model_update), which is conservative there; the
    fourth, seen weakly through one position (std 5e-5 .. 5e-4), carries the spread."""
    m, s, states, corrections, samples = controlled_chain
    sigma, runs = 1e-4, 40
    rng = np.random.default_rng(32)
    nan = np.full(len(s), math.nan)
    p0 = (1e-4) ** 2 * np.eye(4)
    chi2s, scores = [], []
    for _ in range(runs):
        prior = ss.FilterState(tuple(states[0] + rng.multivariate_normal(np.zeros(4), p0)), p0)
        for k in range(len(corrections)):
            y = samples[k][:, coordinate] + sigma * rng.standard_normal(len(s))
            prior, chi2, count = ss.model_update(m, prior, s, y, nan, sigma, corrections[k],
                                                 coordinate=coordinate)
            assert chi2 < count + ss.CHI2_SIGMAS * math.sqrt(2.0 * count)   # no reset
        e = np.array(prior.z) - states[-1]
        chi2s.append(float(e @ np.linalg.solve(prior.cov, e)))
        scores.append(e / np.sqrt(np.diag(prior.cov)))
    spread = np.std(np.array(scores), axis=0)
    assert np.all((spread > 0.75) & (spread < 1.25)), spread
    assert np.mean(chi2s) <= 4.0 + 3.0 * math.sqrt(8.0 / runs)


def test_a_fit_whose_plain_gauss_newton_overshoots_is_finished_by_step_halving(
        controlled_chain, monkeypatch):
    """Found by the Monte Carlo above with a wider prior (1e-3) and no floor: in period 3
    of a run the full Gauss-Newton steps circle at ~3e-7 without converging (a large
    residual on a trajectory curved by an impact with v- = 0.036). model_update then
    takes halved steps (section_state._line_search takes a fraction t < 1 of a
    Gauss-Newton step) down the cost: the fit converges, its residual is the noise's
    (chi^2 / n ~ 1) and its error is within 4 reported standard deviations of the true
    state."""
    m, s, states, corrections, samples = controlled_chain
    calls = []
    original = ss._line_search

    def line_search(*a):
        out = original(*a)
        calls.extend([out[0]] if out[0] < 1.0 else [])
        return out

    monkeypatch.setattr(ss, "_line_search", line_search)
    rng = np.random.default_rng(32)
    nan = np.full(len(s), math.nan)
    p0 = (1e-3) ** 2 * np.eye(4)
    prior = ss.FilterState(tuple(states[0] + rng.multivariate_normal(np.zeros(4), p0)), p0)
    for k in range(4):
        y = samples[k][:, 1] + 1e-4 * rng.standard_normal(len(s))
        prior, chi2, count = ss.model_update(m, prior, s, y, nan, 1e-4, corrections[k],
                                             floor=0.0, coordinate=1)
    assert calls and abs(chi2 / count - 1.0) < 0.3
    e = np.array(prior.z) - states[4]
    assert np.all(np.abs(e) <= 4.0 * np.sqrt(np.diag(prior.cov)))


def test_a_coordinate_outside_the_model_is_refused(controlled_chain):
    m, s, states, corrections, samples = controlled_chain
    prior = ss.FilterState(tuple(states[0]), 1e-4 * np.eye(4))
    with pytest.raises(ParameterError, match="coordinate=2 is invalid: valid range is 0 <= "
                                             "coordinate < n = 2"):
        ss.model_update(m, prior, s, samples[0][:, 0], np.full(len(s), math.nan), 1e-4,
                        corrections[0], coordinate=2)


# ------------------------------------- the pulse and the actuator: motion and filter (E11)

FILTER_PULSE = (0.5, 0.6)        # centred 0.5 after the sample, width 0.6: on [0.2, 0.8]


def _exact_pulse_samples(model, z0, s, correction, delay, width):
    """z at the times s (sorted, in (0, T]) by the certified core alone: advance_with_force
    from sample to sample, the force m_a correction / width on the pulse (an independent
    route: no events, no Jacobians, no reconstruction of the impacts). Returns (samples,
    end, impacts in the period)."""
    from grazing_control.oscillator.ndof.forced import advance_with_force

    flow = NdofFlow.of(model)
    start = actuation.pulse_start(model.period, delay, width)
    force = actuated_mass(flow) * correction / width
    edges = sorted(set([start, start + width, model.period] + [float(x) for x in s]))
    out, z, t, count = {}, np.array(z0, dtype=float), 0.0, 0
    for tj in edges:
        f = force if start <= t < start + width else 0.0
        seg = advance_with_force(flow, (flow.tau2 + model.omega * t) % (2 * math.pi), z,
                                 tj - t, f)
        z, t, count = np.array(seg.z), tj, count + len(seg.impacts)
        out[tj] = z.copy()
    return np.array([out[float(x)] for x in s]), z, count


@pytest.fixture(scope="module")
def pulsed_chain():
    """The chain at Delta d = -1e-3 under the pulse design mu = 0.2 (the pulse of
    FILTER_PULSE), 6 periods from near its 1/1 orbit: the true Pi2 states, the known
    corrections and the exact deviations at T/200 (one impact per period)."""
    def exact(m, z, s, dv):
        zs, end, count = _exact_pulse_samples(m, z, s, dv, *FILTER_PULSE)
        assert count == 1
        return zs, end

    return closed_loop_chain(lambda m: nd.gain_family(m, 0.2, nd.Actuation(*FILTER_PULSE)),
                             exact)


def test_pulsed_motion_against_the_core_and_finite_differences(pulsed_chain):
    """motion.trajectory with the pulse: the states at T/200 equal the core's
    sample-to-sample flow to 1e-14, the Jacobians fourth-order differences to 1e-10
    relative (measured 4e-12; |d z / d z0| reaches 30 after the impact, v- ~ 0.03); n = 1
    equals the 1-DOF pulsed trajectory (1e-13)."""
    from grazing_control.dynamics.estimation import motion as mo

    m, s, states, corrections, samples = pulsed_chain
    out, jac, end, _mono, imps = mo.trajectory(m, states[0], s, corrections[0],
                                               FILTER_PULSE[0], width=FILTER_PULSE[1])
    assert len(imps) == 1
    assert np.max(np.abs(out - samples[0])) <= 1e-14
    assert np.max(np.abs(end - states[1])) <= 1e-14
    h = 1e-6
    for j in range(4):
        e = np.zeros(4)
        e[j] = h

        def f(t):
            return mo.trajectory(m, states[0] + t * e, s, corrections[0], FILTER_PULSE[0],
                                 width=FILTER_PULSE[1])[0]

        fd = (8.0 * (f(1) - f(-1)) - (f(2) - f(-2))) / (12.0 * h)
        assert np.max(np.abs(fd - jac[:, :, j])) <= 1e-10 * np.abs(jac).max()
    m1, p = _study()
    m1, p = dataclasses.replace(m1, delta_d=-0.05), p.with_(delta_d=-0.05)
    s1 = np.linspace(0.0, p.period, 201)[1:]
    a = mo.trajectory(p, (0.01, -0.02), s1, 0.03, 2.0, width=1.0)
    b = mo.trajectory(m1, (0.01, -0.02), s1, 0.03, 2.0, width=1.0)
    assert len(a[4]) == len(b[4]) == 1
    assert np.max(np.abs(a[0] - b[0])) <= 1e-13
    assert np.max(np.abs(a[1] - b[1])) <= 1e-12 * np.max(np.abs(a[1]))


def test_noise_free_pulsed_filter_recovers_the_pi2_state_from_x0(pulsed_chain):
    """Position of x0 (the wall coordinate) only, no noise (sigma 1e-12), the pulse in the
    model: from a prior 1e-3 off, the filter's Pi2 state is the exact one to 1e-10 after
    every period."""
    from grazing_control.dynamics.estimation import section_state as ss

    m, s, states, corrections, samples = pulsed_chain
    prior = ss.FilterState(tuple(states[0] + 1e-3), 1e-4 * np.eye(4))
    nan = np.full(len(s), math.nan)
    for k in range(len(corrections)):
        prior, _chi2, _count = ss.model_update(m, prior, s, samples[k][:, 0], nan, 1e-12,
                                               corrections[k], FILTER_PULSE[0], floor=0.0,
                                               width=FILTER_PULSE[1])
        assert np.max(np.abs(np.array(prior.z) - states[k + 1])) <= 1e-10


def test_noisy_pulsed_filter_error_spread_matches_its_covariance(pulsed_chain):
    """x0 with noise sigma = 1e-4 at T/200, the pulse in the model, 40 seeded runs of 6
    periods from a prior drawn from (1e-4)^2 I: the final error over the reported
    standard deviation, pooled over the 4 coordinates (160 scores, sampling error ~6 %),
    has a spread within 0.9 .. 1.1 (measured 0.918), each coordinate's within 1 +- 25 %
    (a spread over 40 runs has a sampling error of ~11 %; measured 0.89 .. 0.99; over
    300 runs 0.92 .. 0.96, below 1 by the filter's floor 1e-2 sigma, conservative as
    in E11), and no period is reset by the chi^2 test."""
    from grazing_control.dynamics.estimation import section_state as ss

    m, s, states, corrections, samples = pulsed_chain
    sigma, runs = 1e-4, 40
    rng = np.random.default_rng(32)
    nan = np.full(len(s), math.nan)
    p0 = (1e-4) ** 2 * np.eye(4)
    scores = []
    for _ in range(runs):
        prior = ss.FilterState(tuple(states[0] + rng.multivariate_normal(np.zeros(4), p0)), p0)
        for k in range(len(corrections)):
            y = samples[k][:, 0] + sigma * rng.standard_normal(len(s))
            prior, chi2, count = ss.model_update(m, prior, s, y, nan, sigma, corrections[k],
                                                 FILTER_PULSE[0], width=FILTER_PULSE[1])
            assert chi2 < count + ss.CHI2_SIGMAS * math.sqrt(2.0 * count)
        e = np.array(prior.z) - states[-1]
        scores.append(e / np.sqrt(np.diag(prior.cov)))
    spread = np.std(np.array(scores), axis=0)
    pooled = math.sqrt(float(np.mean(np.square(np.array(scores)))))
    assert 0.9 < pooled < 1.1, pooled
    assert np.all((spread > 0.75) & (spread < 1.25)), spread


def test_actuated_motion_against_the_plant_and_finite_differences():
    """motion.trajectory through the first-order actuator on the chain (tau_a 0.4,
    latency 0.2, width 1 centred 2.0 after the sample, force0 0.003 at the section, one
    impact): the end state is the plant's actuated_step bit for bit (measured 0.0), the
    force at the next section section_force = actuated_step's to 1e-20, the samples every
    7th of T/200 lag_advance's to 1e-14 (measured 6.7e-16), the Jacobians fourth-order
    differences (h 1e-5) to 1e-9 relative (measured 3.4e-11); n = 1 equals the 1-DOF
    actuated trajectory (states 2.5e-16, Jacobians 8e-15)."""
    from grazing_control.dynamics.estimation import motion as mo
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.oscillator.ndof.forced import lag_advance

    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.05)
    flow, period = NdofFlow.of(m), m.period
    lag = act.Actuator(0.4, 0.2)
    z0, dv, delay, width, f0 = np.array([0.01, -0.02, 0.03, 0.0]), 0.05, 2.0, 1.0, 0.003
    start = pulse_start(period, delay, width)
    s = np.linspace(0.0, period, 201)[1:]
    out, jac, end, _mono, imps = mo.trajectory(m, z0, s, dv, delay, width=width,
                                               actuator=lag, force0=f0)
    z_end, f_end, i_end = actuated_step(flow, z0, f0, dv, start=start, width=width,
                                        time_constant=0.4, latency=0.2)
    assert len(imps) == len(i_end) == 1
    assert np.array_equal(end, z_end)
    assert abs(mo.section_force(m, f0, dv, delay, width, math.inf, lag) - f_end) <= 1e-20
    u = actuated_mass(flow) * dv / width
    legs = ((0.0, start + 0.2, 0.0), (start + 0.2, start + 1.2, u), (start + 1.2, period, 0.0))
    for j in range(0, s.size, 7):
        z, f = z0.copy(), f0
        for a, b, command in legs:
            if min(b, s[j]) > a:
                seg = lag_advance(flow, (flow.tau2 + m.omega * a) % (2 * math.pi), z,
                                  min(b, s[j]) - a, command, f - command, 0.4)
                z, f = np.array(seg.z), seg.force
        assert np.max(np.abs(z - out[j])) <= 1e-14, j
    h = 1e-5
    for j in range(4):
        e = np.zeros(4)
        e[j] = h

        def g(t):
            return mo.trajectory(m, z0 + t * e, s, dv, delay, width=width, actuator=lag,
                                 force0=f0)[0]

        fd = (8.0 * (g(1) - g(-1)) - (g(2) - g(-2))) / (12.0 * h)
        assert np.max(np.abs(fd - jac[:, :, j])) <= 1e-9 * np.abs(jac).max()
    m1, p = _study()
    m1, p = dataclasses.replace(m1, delta_d=-0.05), p.with_(delta_d=-0.05)
    s1 = np.linspace(0.0, p.period, 201)[1:]
    a = mo.trajectory(p, (0.01, -0.02), s1, 0.03, 2.0, width=1.0, actuator=lag, force0=0.002)
    b = mo.trajectory(m1, (0.01, -0.02), s1, 0.03, 2.0, width=1.0, actuator=lag, force0=0.002)
    assert len(a[4]) == len(b[4]) == 1
    assert np.max(np.abs(a[0] - b[0])) <= 1e-13
    assert np.max(np.abs(a[1] - b[1])) <= 1e-12 * np.max(np.abs(a[1]))


def _mp_end(m, z0, corr, delay, delta_d, t_guess):
    """The deviation at T of the chain's motion from z0 (kick ``corr`` on v_{i_a} at
    ``delay``, one impact near ``t_guess``), in mpmath (at the caller's precision) from
    the model's matrices alone: the free flow by expm, the impact time by findroot, the
    impact law."""
    import mpmath as mp

    n, w, a = m.n, m.i_w, m.i_a
    M, C, K = (mp.matrix(x.tolist()) for x in (m.M, m.C, m.K))
    om = mp.mpf(m.omega)
    A = mp.zeros(2 * n)
    minv = M ** -1
    for i in range(n):
        A[i, n + i] = 1
    A[n:, :n], A[n:, n:] = -minv * K, -minv * C
    X = mp.lu_solve(K - om ** 2 * M + 1j * om * C, mp.matrix(m.f.tolist()))
    tau2 = (-mp.arg(X[w])) % (2 * mp.pi) + mp.mpf(m.pi2_offset)
    d = abs(X[w]) + delta_d

    def xp(s):
        e = mp.expj(tau2 + om * s)
        return mp.matrix([mp.re(X[i] * e) for i in range(n)]
                         + [mp.re(1j * om * X[i] * e) for i in range(n)])

    def flow(y, s0, s):
        return xp(s) + mp.expm(A * (s - s0)) * (y - xp(s0))

    y = xp(0) + mp.matrix([mp.mpf(float(x)) for x in z0])
    y = flow(y, 0, delay)
    y[n + a] += corr
    ti = mp.findroot(lambda s: flow(y, delay, s)[w] - d, mp.mpf(t_guess))
    y = flow(y, delay, ti)
    y[n + w] = -mp.mpf(m.r) * y[n + w]
    T = 2 * mp.pi / om
    return flow(y, ti, T) - xp(T)


def test_n_dof_wall_sensitivity_against_mpmath():
    """d end / d Delta d of the chain's motion with one impact (the kick case of the
    finite-difference test) against an independent 40-digit motion (mpmath: expm,
    findroot, the impact law; central difference with h = 1e-15, exact to ~1e-30): equal
    to 1e-12 relative (measured 1.7e-15)."""
    import mpmath as mp

    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.05)
    z0, corr, delay = np.array([0.01, -0.02, 0.005, 0.01]), 0.03, 2.0
    *_rest, imps, _gs, gend = mo.trajectory(m, z0, np.empty(0), corr, delay, wall=True)
    with mp.workdps(40):
        h = mp.mpf("1e-15")
        up, down = [_mp_end(m, z0, mp.mpf(corr), mp.mpf(delay), mp.mpf(m.delta_d) + e,
                            imps[0][0]) for e in (h, -h)]
        exact = np.array([float(x) for x in (up - down) / (2 * h)])
    assert len(imps) == 1
    assert np.max(np.abs(exact - gend)) <= 1e-12 * np.max(np.abs(exact)), exact - gend


def test_a_model_moved_to_another_clearance_shares_its_flow():
    """modal_flow of a model from NdofModel.with_clearance is its source's flow (built
    once) carrying the moved model: every array and number that NdofFlow.of gives the
    moved model itself, float for float (the flow does not depend on Delta d)."""
    from grazing_control.oscillator.ndof.flow import NdofFlow

    base = load_model(CHAIN)
    moved = base.with_clearance(base.delta_d + 3e-4)
    shared, own = mo.modal_flow(moved), NdofFlow.of(moved)
    assert shared.model is moved
    assert shared.modes is mo.modal_flow(base).modes          # not built again
    for field in dataclasses.fields(NdofFlow):
        if field.name != "model":
            assert np.array_equal(getattr(shared, field.name), getattr(own, field.name)), \
                field.name
    assert np.array_equal(shared.transition(0.7), own.transition(0.7))

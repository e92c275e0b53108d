"""The Pi2 state from sampled, noisy positions (grazing_control.dynamics.estimation.section_state).

The exact trajectory the model fits is checked against the simulator's own dense output
and period map and its Jacobian against finite differences; each estimator's covariance
against seeded Monte Carlo; impact detection's rate and timing error against the exact
impacts; the design helper's covariance against the closed form (nearest) and the
least-squares formula evaluated by brute force (arc).
"""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.estimation.section_state import (
    arc_fit, detect_impact, deviation_samples, estimate_covariance, nearest_estimate,
    unkick)
from grazing_control.dynamics.estimation.motion import phi_rows, trajectory
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.simulation.simulate import period_step, states_between
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.flow import to_deviation
from grazing_control.oscillator.impact import advance
from grazing_control.oscillator.params import OscillatorParams, ParameterError

P = OscillatorParams(delta_d=-5e-6)


def _gains(p, c2, delay=0.0):
    return Gains(degenerate_c1(p, c2, delay), c2, delay)


def test_phi_rows_is_the_matrix_exponential():
    rng = np.random.default_rng(1)
    h = rng.uniform(-12.0, 12.0, 50)
    a = np.array([[0.0, 1.0], [-1.0, -2.0 * P.zeta]])
    assert np.allclose(phi_rows(P.zeta, h), np.array([expm(a * t) for t in h]),
                       rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("c2, delay", [(-0.3, 0.0), (-1.0, 6.0)])
def test_trajectory_is_the_simulators_motion_and_its_jacobian_the_finite_difference(c2, delay):
    g = _gains(P, c2, delay)
    z = orbit_11(P, g).pi2_deviation
    z = (z[0] + 3e-4, z[1] - 2e-4)
    dv = 1.7e-3
    s = np.linspace(0.01, P.period, 300)
    dev, jac, end, mono, imps = trajectory(P, z, s, dv, delay)
    assert len(imps) == 1
    seg = period_step(P, z[0], z[1], dv, delay=delay)
    assert np.allclose(end, (seg.dx, seg.dv), rtol=0, atol=1e-12)
    # dense output of the simulator: one leg from the sample, or two around the kick
    if delay == 0.0:
        xv = states_between(P, P.tau2, z[0], z[1] + dv, seg.impacts, s)
    else:
        first = s <= delay
        xv1 = states_between(P, P.tau2, z[0], z[1], [], s[first])
        tau = P.tau2 + P.omega * delay
        a = advance(P, P.tau2, z[0], z[1], delay)
        b = advance(P, tau, a.dx, a.dv + dv, P.period - delay)
        xv2 = states_between(P, tau, a.dx, a.dv + dv, b.impacts, s[~first] - delay)
        xv = np.vstack([xv1, xv2])
    want = np.array([to_deviation(P, P.tau2 + P.omega * t, x, v) for t, (x, v) in zip(s, xv)])
    assert np.allclose(dev, want, rtol=0, atol=1e-11)
    eps = 1e-7
    for i in range(2):
        zp, zm = list(z), list(z)
        zp[i] += eps
        zm[i] -= eps
        dp = trajectory(P, zp, s, dv, delay)
        dm = trajectory(P, zm, s, dv, delay)
        fd = (dp[0] - dm[0]) / (2 * eps)
        far = np.abs(s - imps[0][0]) > 1e-3       # the samples not at the moving impact
        assert np.allclose(jac[far, :, i], fd[far], rtol=1e-5, atol=1e-5)
        assert np.allclose(mono[:, i], (np.array(dp[2]) - np.array(dm[2])) / (2 * eps),
                           rtol=1e-5, atol=1e-5)


def test_arc_fit_recovers_the_state_exactly_without_noise_also_through_a_known_kick():
    z = (2e-3, -1e-3)
    s = np.linspace(-2.0, 0.0, 40)
    kick_at, dv = -1.1, 4e-3
    # motion: from z at 0 backward; before the kick the state lacks dv
    after = np.einsum("nij,j->ni", phi_rows(P.zeta, s), z)
    before = s <= kick_at
    after[before] -= dv * phi_rows(P.zeta, s[before] - kick_at)[:, :, 1]
    est = arc_fit(P, s, after[:, 0], np.full(s.size, math.nan), 1e-4, 0.0, [(kick_at, dv)])
    assert np.allclose(est.z, z, rtol=0, atol=1e-12)
    y, w = unkick(P, s, after[:, 0], after[:, 1], [(kick_at, dv)])
    assert np.allclose(y, np.einsum("nij,j->ni", phi_rows(P.zeta, s), z)[:, 0], atol=1e-15)


@pytest.mark.parametrize("velocity", [False, True])
def test_arc_fit_covariance_is_the_monte_carlo_covariance(velocity):
    rng = np.random.default_rng(7)
    s = np.linspace(-2.3, 0.0, 50)
    sigma = 1e-4
    z = np.array([1e-3, 2e-3])
    clean = np.einsum("nij,j->ni", phi_rows(P.zeta, s), z)
    errs = []
    for _ in range(3000):
        y = clean[:, 0] + sigma * rng.standard_normal(s.size)
        w = clean[:, 1] + sigma * rng.standard_normal(s.size) if velocity \
            else np.full(s.size, math.nan)
        est = arc_fit(P, s, y, w, sigma)
        errs.append(np.array(est.z) - z)
    errs = np.array(errs)
    emp = np.cov(errs.T)
    # variances within 10 %, the correlation within 4 standard errors (4 / sqrt(n))
    scale = np.sqrt(np.outer(np.diag(emp), np.diag(emp)))
    assert np.allclose(emp, est.cov, rtol=0.1, atol=4.0 / math.sqrt(len(errs)) * scale)
    chi2 = np.einsum("ni,ij,nj->n", errs, np.linalg.inv(est.cov), errs)
    assert abs(chi2.mean() - 2.0) < 5.0 * 2.0 / math.sqrt(len(errs))


def test_nearest_covariance_is_the_monte_carlo_covariance():
    rng = np.random.default_rng(3)
    s = np.array([-0.2, -0.1, 0.0])
    sigma = 1e-4
    errs, est = [], None
    for _ in range(20000):
        y = sigma * rng.standard_normal(3)
        est = nearest_estimate(s, y, np.full(3, math.nan), sigma)
        errs.append(est.z)
    emp = np.cov(np.array(errs).T)
    assert np.allclose(emp, est.cov, rtol=0.05)
    with_v = nearest_estimate(s, np.zeros(3), np.array([0.0, 0.0, 1e-3]), sigma)
    assert with_v.z == (0.0, 1e-3) and np.array_equal(with_v.cov, sigma ** 2 * np.eye(2))


def _noisy_period(p, g, z, rng, sigma, rate=200):
    """Samples of one period of the controlled orbit (deviations, s in (0, T]) and its
    exact impact times."""
    s = np.arange(1, rate + 1) * p.period / rate
    dv = g.c1 * z[0] + g.c2 * z[1]
    dev, _j, _e, _m, imps = trajectory(p, z, s, dv)
    return s, dev[:, 0] + sigma * rng.standard_normal(s.size), dv, [i[0] for i in imps]


@pytest.mark.parametrize("delta_d, c2", [(-5e-6, -0.3), (-9e-6, -1.0), (-5e-6, 0.007)])
def test_impacts_are_detected_from_positions_with_a_timing_error_below_one_sample(delta_d, c2):
    """Seeded noisy periods of the controlled orbit perturbed by up to 1e-3: detection
    rate >= 99 % at sigma = 1e-4 and 200 samples per period; on
    impact-free arcs (the samples after the impact) no false detection in >= 99 %.
    Timing error: median < T/2000, 95 % < T/200, all < 2 T/200."""
    p = OscillatorParams(delta_d=delta_d)
    g = _gains(p, c2)
    z0 = np.array(orbit_11(p, g).pi2_deviation)
    rng = np.random.default_rng(11)
    sigma, n, hits, errors, false = 1e-4, 200, 0, [], 0
    h = p.period / 200
    for _ in range(n):
        z = z0 + rng.uniform(-1e-3, 1e-3, 2) * np.abs(z0)
        s, y, dv, imps = _noisy_period(p, g, z, rng, sigma)
        y, _w = unkick(p, s, y, np.full(s.size, math.nan), [(0.0, dv)])
        found = detect_impact(p, s, y, sigma)
        if found is not None and len(imps) == 1:
            hits += 1
            errors.append(found - imps[0])
        late = s > imps[0] + 0.05
        false += detect_impact(p, s[late], y[late], sigma) is not None
    assert hits >= 0.99 * n
    errors = np.abs(errors)
    assert np.median(errors) < 0.1 * h and np.quantile(errors, 0.95) < h
    assert np.max(errors) < 2.0 * h
    assert false <= 0.01 * n


def test_the_design_covariance_is_the_closed_form_and_the_least_squares_formula():
    g = _gains(P, -0.3)
    h = P.period / 100
    assert np.allclose(estimate_covariance(P, g, 100, estimator="nearest"),
                       [[1, 1 / h], [1 / h, 2 / h ** 2]])
    assert np.array_equal(estimate_covariance(P, g, 100, estimator="nearest", velocity=True),
                          np.eye(2))
    # arc: brute force the information of the samples after the orbit's impact
    z = orbit_11(P, g).pi2_deviation
    s = np.arange(1, 100) * h          # the samples strictly between two sections
    imp = trajectory(P, z, s, g.c1 * z[0] + g.c2 * z[1])[4][0][0]
    rows = np.array([expm(np.array([[0, 1], [-1, -2 * P.zeta]]) * (t - P.period))[0]
                     for t in s if t > imp])
    assert np.allclose(estimate_covariance(P, g, 100, estimator="arc"),
                       np.linalg.inv(rows.T @ rows), rtol=1e-9)
    # the model's stationary covariance lies below the single period's arc fit
    model = estimate_covariance(P, g, 100)
    assert np.all(np.diag(model) < np.diag(estimate_covariance(P, g, 100, estimator="arc")))


def test_bad_input_is_refused_with_the_parameter_named():
    g = _gains(P, -0.3)
    with pytest.raises(ParameterError, match="estimator='kalman'"):
        estimate_covariance(P, g, 100, estimator="kalman")
    with pytest.raises(ParameterError, match="rate=1"):
        estimate_covariance(P, g, 1)
    with pytest.raises(ParameterError, match="sensor_noise=0.0"):
        arc_fit(P, [0.0, 1.0], [0.0, 0.0], [math.nan, math.nan], 0.0)
    with pytest.raises(ValueError, match="needs 2"):
        arc_fit(P, [0.0], [0.0], [math.nan], 1e-4)


def test_deviation_samples_subtract_the_periodic_motion():
    s = np.array([0.0, 1.0])
    psi = P.tau2 + P.omega * s - P.lag
    x = P.amplitude * np.cos(psi) + 1e-3
    v = -P.amplitude * P.omega * np.sin(psi) - 2e-3
    y, w = deviation_samples(P, s, x, v)
    assert np.allclose(y, 1e-3, atol=1e-15) and np.allclose(w, -2e-3, atol=1e-15)
    assert np.isnan(deviation_samples(P, s, x)[1]).all()

"""The augmented filter's stationary covariance over a model file (issue 32;
grazing_control.dynamics.estimation.augmented.augmented_covariance, docs/theory_estimation.md
(E13)): the (2n + 2) x (2n + 2) fixed point of E5 over theta = (z, b, Delta d).

Three yardsticks: the n = 1 model file (config/models/study_1dof.yaml) against the 1-DOF
closed form (an independent implementation of the motion and of its wall sensitivity,
E8); the two-mass chain with the bias and the wall off against the plain n-DOF filter's
covariance (dynamics/design/noise.py, filter_covariance); and the chain's closed loop
through the core with the augmented filter estimating a wall that walks as the filter
assumes (seeded Monte-Carlo), its errors against the predicted covariance.
"""

import dataclasses

import numpy as np
import pytest

from grazing_control.dynamics.design.noise import filter_covariance
from grazing_control.dynamics.design.tuning import optimize_noise
from grazing_control.dynamics.estimation.augmented import (
    AugmentedStreamEstimator, augmented_covariance)
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.design.family import evaluate_design
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.shooting import find_periodic

from test_augmented_ndof import DELAY, MODEL, RATE, T, closed_loop
from test_family import _study


@pytest.fixture(scope="module")
def chain_design():
    """tests/test_augmented_ndof.py's design: the gains and the controlled 1/1 orbit."""
    gains = evaluate_design(MODEL, -0.22, DELAY).gains
    target = find_periodic(ModalMap(MODEL, gains, DELAY),
                           np.array([-0.04, 0.03, -0.05, 0.03])).state
    return gains, target


def _relative(a, b):
    """max |a - b| over each entry's scale sqrt(b_ii b_jj) (0 where both are 0)."""
    scale = np.sqrt(np.outer(np.diag(b), np.diag(b)))
    return float(np.max(np.abs(a - b)[scale > 0] / scale[scale > 0]))


@pytest.mark.parametrize("kwargs", [{}, {"bias": False, "wall": False}, {"bias": False},
                                    {"wall_noise": 1e-7}])
def test_the_n1_model_file_gives_the_1dof_covariance(kwargs):
    """The study's oscillator as the n = 1 model file, the least-noise gains with delay 3,
    200 samples per period: the 4 x 4 covariance equals the 1-DOF one's entry by entry
    to 1e-12 of sqrt(P_ii P_jj) (measured 1.4e-13 with both augmentations), given the
    orbit or finding it (controlled_orbit)."""
    m, p = _study()
    g = optimize_noise(p, 3.0).gains()
    k = np.array([g.c1, g.c2])
    one = augmented_covariance(p, g, RATE, **kwargs)
    given = augmented_covariance(m, k, RATE, target=orbit_11(p, g).pi2_deviation,
                                 delay=g.delay, **kwargs)
    found = augmented_covariance(m, k, RATE, delay=g.delay, **kwargs)
    assert one.shape == given.shape == (4, 4)
    assert _relative(given, one) <= 1e-12 and _relative(found, one) <= 1e-12


@pytest.mark.parametrize("coordinate", [0, 1])
def test_without_augmentation_it_is_the_plain_n_dof_filters(chain_design, coordinate):
    """The chain (Delta d = -1e-3, mu = -0.22, delay 1, T/200), bias and wall off: the z
    block is filter_covariance (the same samples: not the one at t_k) times sigma^2 to
    1e-10 of its largest entry (measured 1.8e-14 through x0, 4.4e-13 through x1), the
    rest 0; bias and wall on, 6 x 6, the bias and wall's shares of the z block's
    variances positive (the wall's walk costs, measured up to 0.05 % through x0)."""
    gains, target = chain_design
    sigma = 1e-4
    off = augmented_covariance(MODEL, gains, RATE, bias=False, wall=False, target=target,
                               delay=DELAY, coordinate=coordinate, sigma=sigma)
    plain = filter_covariance(MODEL, gains, target, RATE, coordinate, DELAY,
                              section_sample=False, periods=5000) * sigma ** 2
    assert off.shape == (6, 6) and np.all(off[4:] == 0.0) and np.all(off[:, 4:] == 0.0)
    assert np.max(np.abs(off[:4, :4] - plain)) <= 1e-10 * np.max(np.abs(plain))
    on = augmented_covariance(MODEL, gains, RATE, target=target, delay=DELAY,
                              coordinate=coordinate, sigma=sigma)
    assert np.all(np.diag(on)[4:] > 0.0)
    assert np.all(np.diag(on[:4, :4]) > np.diag(plain))
    assert np.allclose(on, on.T, rtol=0.0, atol=0.0)


def test_bad_arguments_are_refused(chain_design):
    gains, target = chain_design
    with pytest.raises(ParameterError, match="gains"):
        augmented_covariance(MODEL, gains[:2], RATE, target=target)
    with pytest.raises(ParameterError, match="coordinate=2"):
        augmented_covariance(MODEL, gains, RATE, target=target, coordinate=2)
    with pytest.raises(ParameterError, match="target is missing"):
        augmented_covariance(MODEL, gains, RATE, width=1.0)


#: The Monte-Carlo's noise: sigma 1e-5 and a walk of 1e-7 per period (test_augmented_ndof's
#: sigma 1e-4 and walk 1e-6 scaled by 0.1: the same loop in its linear regime; at 1e-4
#: the second order shows, see the test's docstring).
MC_SIGMA, MC_WALK = 1e-5, 1e-7
MC_SEEDS, MC_PERIODS, MC_SKIP = 4, 400, 30


def test_the_covariance_is_that_of_the_closed_loops_errors(chain_design, monkeypatch):
    """The chain's closed loop in the core (tests/test_augmented_ndof.py's, position of x0
    at T/200 with sigma 1e-5), the augmented filter estimating Delta d (no bias, no floor)
    while the plant's Delta d walks by N(0, 1e-7^2) per period as the filter assumes: over
    4 seeds x 370 periods (after 30), the errors (z^ - z, Delta d^ - Delta d) against the
    predicted 5 x 5 covariance (floor 0, the same sigma and walk).

    Tolerances from the sampling error, measured by batch means (40 blocks of 37
    periods): the standard error of a std ratio is 0.02 for z (the errors' lag-1
    correlation -0.08) and 0.05 for Delta d (0.88: its error is a slow walk), of the mean
    normalised error squared e^T P^-1 e (5 if P is right) 0.15. Bounds at 3 of them:
    z's stds within 6 % (measured +2.2 to +3.0 %), Delta d's within 16 % (-3.2 %), the
    mean e^T P^-1 e in 5 +- 0.45 (5.02). The test can fail: the prediction with the
    sample at t_k fitted (section_sample) is off by 14-16 % in z; at sigma 1e-4 the
    two tightest directions of P (std 7e-8) carry 2.5 and 3.2 times their variance (the
    motion's curvature through the impact, sigma^2 against sigma), e^T P^-1 e 8.8."""
    import test_augmented_ndof

    monkeypatch.setattr(test_augmented_ndof, "SIGMA", MC_SIGMA)
    gains, target = chain_design
    errors = []
    for seed in range(MC_SEEDS):
        rng = np.random.default_rng(100 + seed)
        walk = MODEL.delta_d + np.concatenate(
            [[0.0], np.cumsum(MC_WALK * rng.standard_normal(MC_PERIODS))])
        plants = [dataclasses.replace(MODEL, delta_d=float(w)) for w in walk]
        est = AugmentedStreamEstimator(MODEL, MC_SIGMA, "stream", T / RATE, bias=False,
                                       wall=True, wall_noise=MC_WALK, floor=0.0)
        dz, zs, walls, _ = closed_loop((gains, target), est, MC_PERIODS,
                                       plant=lambda k: plants[k], seed=seed)
        assert est.resets <= 1, (seed, est.resets)       # the start only
        errors.append(np.column_stack([zs - (dz + target), walls - walk[:MC_PERIODS]])[MC_SKIP:])
    e = np.vstack(errors)
    act = [0, 1, 2, 3, 5]
    p = augmented_covariance(MODEL, gains, RATE, bias=False, wall_noise=MC_WALK, floor=0.0,
                             sigma=MC_SIGMA, target=target, delay=DELAY)[np.ix_(act, act)]
    ratio = np.sqrt(np.mean(e ** 2, axis=0) / np.diag(p))
    assert np.all(np.abs(ratio[:4] - 1.0) <= 0.06), ratio
    assert abs(ratio[4] - 1.0) <= 0.16, ratio
    nees = float(np.mean(np.einsum("ij,jk,ik->i", e, np.linalg.inv(p), e)))
    assert abs(nees - 5.0) <= 0.45, nees

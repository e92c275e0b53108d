"""Measurement noise through the closed loop (grazing_control.dynamics.design.noise).

The noise gain (std of the Pi2 position per unit measurement noise, from the discrete
Lyapunov equation of the loop linearised about the controlled orbit) against the
spread of the exact closed loop simulated with seeded noise (the faults' measurement
noise, the same draw the nodes use): within 10 % for small sigma, at both study scenes,
three gains and a delayed design.
"""

import math

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.design.noise import loop_linearisation, noise_covariance, noise_gain
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.faults import FaultModel
from grazing_control.studies.robustness.faults import simulate_with_faults


def _gains(p, c2, delay=0.0):
    return Gains(degenerate_c1(p, c2, delay), c2, delay)


@pytest.mark.parametrize("delta_d, c2, delay", [(-5e-6, -1.0, 0.0), (-5e-6, -0.3, 0.0),
                                                (-9e-6, -1.8, 0.0), (-9e-6, 0.05, 0.0),
                                                (-5e-6, -1.0, 6.0), (-9e-6, 0.5, 2.0)])
def test_noise_gain_predicts_the_simulated_spread(delta_d, c2, delay):
    p = OscillatorParams(delta_d=delta_d)
    g = _gains(p, c2, delay)
    z = orbit_11(p, g).pi2_deviation
    sigma = 1e-10
    run = simulate_with_faults(p, g, FaultModel(noise=sigma, seed=11), 6000, deviation=z)
    simulated = np.std(run[200:, 0] - z[0]) / sigma
    assert abs(simulated / noise_gain(p, g) - 1.0) < 0.1


def test_the_study_gain_amplifies_noise_about_200_times_and_small_gains_far_less():
    """The reporter's measurement at Delta d = -5e-6: ~195x with c2 = -1, ~46x with
    c2 = -0.3, ~1080x with c2 = -1.8; near c2 = 0 (c1 small too) about 1x."""
    p = OscillatorParams(delta_d=-5e-6)
    gains = {c2: noise_gain(p, _gains(p, c2)) for c2 in (-1.8, -1.0, -0.3, 0.007)}
    assert 180 < gains[-1.0] < 210 and 40 < gains[-0.3] < 52 and 950 < gains[-1.8] < 1150
    assert gains[0.007] < 2.0


def test_covariance_scales_with_the_measurement_covariance():
    p = OscillatorParams(delta_d=-5e-6)
    g = _gains(p, -1.0)
    base = noise_covariance(p, g)
    assert np.allclose(noise_covariance(p, g, 4.0 * np.eye(2)), 4.0 * base, rtol=1e-12)
    # position-only noise: only c1 sees it
    only_x = noise_covariance(p, g, np.diag([1.0, 0.0]))
    assert np.allclose(only_x, base * g.c1 ** 2 / (g.c1 ** 2 + g.c2 ** 2), rtol=1e-12)


def test_linearisation_is_the_jacobian_of_the_closed_loop():
    """J from loop_linearisation against central differences of the exact closed loop."""
    from grazing_control.dynamics.maps.maps import pi2_map

    p = OscillatorParams(delta_d=-1e-4)
    for g in (_gains(p, -1.0), _gains(p, 0.5, 2.0)):
        z = np.array(orbit_11(p, g).pi2_deviation)
        j, _, _ = loop_linearisation(p, g, z)
        h = 1e-7 * max(abs(z).max(), 1e-6)
        fd = np.column_stack([
            (np.array(pi2_map(p, *(z + h * e), g)[:2]) - np.array(pi2_map(p, *(z - h * e), g)[:2]))
            / (2 * h) for e in np.eye(2)])
        assert np.allclose(j, fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())


def test_an_unstable_loop_has_no_stationary_spread():
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(-1.0, -1.0)   # not the degenerate c1: the singular eigenvalue is back
    with pytest.raises(ValueError, match="not stable"):
        noise_gain(p, g)
    assert math.isfinite(noise_gain(p, _gains(p, -1.0)))

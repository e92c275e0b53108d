"""Newton shooting, Floquet multipliers and test functions over the model protocol
(grazing_control.dynamics.orbits.shooting), on two models: an n-dimensional affine map whose
fixed point and multipliers are known in closed form, and the 1-DOF oscillator, where
the explicit impact-phase route (orbit_11) is the independent reference.
"""

import math

import numpy as np
import pytest

from affine_model import Affine
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.orbits.shooting import (ShootingFailed, bifurcation_tests,
                                               find_periodic, floquet_multipliers, iterate)
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams


@pytest.mark.parametrize("n", [3, 4, 6])
def test_fixed_point_of_an_affine_map(n):
    m = Affine(mu=0.4, dimension=n)
    o = find_periodic(m, np.zeros(n))
    assert np.allclose(o.state, m.fixed_point(), rtol=1e-13, atol=1e-13)
    assert np.allclose(o.monodromy, m.matrix(), rtol=0, atol=1e-14)


def test_period_two_orbit_of_an_affine_map_is_its_fixed_point():
    m = Affine(mu=0.4)
    o = find_periodic(m, np.ones(4), periods=2)
    assert np.allclose(o.state, m.fixed_point(), rtol=1e-12)
    assert np.allclose(o.monodromy, m.matrix() @ m.matrix(), atol=1e-13)


def test_multipliers_of_an_n_dimensional_map():
    m = Affine(mu=-0.7, rho=0.8, theta=0.9, dimension=5)
    lam = floquet_multipliers(m.matrix())
    expected = sorted([-0.7, 0.8 * np.exp(0.9j), 0.8 * np.exp(-0.9j), 0.3, 0.15],
                      key=lambda z: -abs(z))
    assert np.allclose(np.abs(lam), np.abs(expected), rtol=1e-12)
    assert np.allclose(np.sort_complex(lam), np.sort_complex(np.array(expected)), atol=1e-12)


def test_two_by_two_multipliers_keep_the_small_one_accurate():
    """Near grazing the large multiplier grows like 1/v-: the cancellation-free formula
    keeps the small one to full relative precision where the naive root loses it."""
    big, small = 1e9, 3e-9
    j = np.array([[big + small, 0.0], [0.0, 0.0]])
    lam = floquet_multipliers(j, det=big * small)
    assert lam[0] == big + small
    assert math.isclose(lam[1].real, big * small / (big + small), rel_tol=1e-15)


@pytest.mark.parametrize("delta_d, c2", [(-1e-4, None), (-5e-6, -1.0), (-1e-9, -1.0),
                                         (-3e-5, -0.5)])
def test_one_dof_shooting_agrees_with_the_explicit_branch(delta_d, c2):
    p = OscillatorParams(delta_d=delta_d)
    g = None if c2 is None else Gains(degenerate_c1(p, c2), c2)
    exact = orbit_11(p, g)
    z = np.array(exact.pi2_deviation)
    o = find_periodic(OneDOF(p, g), z * (1.0 + 1e-6))
    assert np.allclose(o.state, z, rtol=1e-9, atol=1e-15)
    model = OneDOF(p, g)
    lam = floquet_multipliers(o.monodromy, model.jacobian_det(1, len(o.impacts)))
    assert np.allclose(lam, exact.multipliers, rtol=1e-7, atol=1e-12)


def test_iterate_counts_impact_times_from_the_first_sample():
    p = OscillatorParams(delta_d=-1e-3)
    z, jac, impacts = iterate(OneDOF(p), np.array(orbit_11(p).pi2_deviation), 3)
    assert len(impacts) == 3
    assert all(k * p.period < i.dt < (k + 1) * p.period for k, i in enumerate(impacts))


def test_failures_are_shooting_failed():
    with pytest.raises(ShootingFailed, match="did not converge"):
        find_periodic(Affine(mu=0.4), np.zeros(4), max_iter=0)
    p = OscillatorParams(delta_d=-1e-3)
    with pytest.raises(ShootingFailed):          # far beyond the wall
        find_periodic(OneDOF(p), np.array([5.0, 0.0]))
    with pytest.raises(ValueError, match="guess"):
        find_periodic(Affine(), np.zeros(3))
    with pytest.raises(ValueError, match="periods"):
        find_periodic(Affine(), np.zeros(4), periods=0)


def test_test_functions_change_sign_at_their_bifurcations():
    for mu, sign in ((-0.9, 1), (-1.1, -1)):
        t = bifurcation_tests(floquet_multipliers(Affine(mu=mu).matrix()))
        assert np.sign(t["period-doubling"]) == sign
    folds = [bifurcation_tests(floquet_multipliers(Affine(mu=mu).matrix()))["fold"]
             for mu in (0.9, 1.1)]
    assert folds[0] * folds[1] < 0
    ns = [bifurcation_tests(floquet_multipliers(Affine(rho=rho).matrix()))["neimark-sacker"]
          for rho in (0.95, 1.05)]
    assert ns[0] * ns[1] < 0
    assert math.isnan(bifurcation_tests([0.5, 0.2])["neimark-sacker"])

"""The model protocol (grazing_control.dynamics.maps.model) and its 1-DOF implementation.

OneDOF is the study's oscillator on Pi2: its step is the exact Pi2 map, its Jacobian
the monodromy, checked here against central finite differences of the step itself; its
exact determinant against the matrix; its parameter family against OscillatorParams'
validation.
"""

import math

import numpy as np
import pytest

from affine_model import Affine
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.maps import pi2_map
from grazing_control.dynamics.maps.model import OneDOF, PeriodMap
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError

P = OscillatorParams(delta_d=-1e-3)
G = Gains(degenerate_c1(P, -1.0), -1.0)


def test_both_models_implement_the_protocol():
    assert isinstance(OneDOF(P), PeriodMap)
    assert isinstance(OneDOF(P, G), PeriodMap)
    assert isinstance(Affine(), PeriodMap)
    assert not isinstance(P, PeriodMap)


@pytest.mark.parametrize("gains", [None, G, Gains(-0.4, -0.3, 1.5)])
def test_one_dof_step_is_the_pi2_map(gains):
    z = np.array([0.01, -0.02])
    s = OneDOF(P, gains).step(z, jacobian=True)
    seg = pi2_map(P, 0.01, -0.02, gains, monodromy=True)
    assert (s.state[0], s.state[1]) == (seg.dx, seg.dv)
    assert s.jacobian.ravel().tolist() == list(seg.monodromy)
    assert s.impacts == tuple(seg.impacts)
    assert OneDOF(P, gains).step(z).jacobian is None


@pytest.mark.parametrize("gains", [None, G, Gains(-0.4, -0.3, 1.5)])
def test_one_dof_jacobian_matches_central_differences(gains):
    """Away from grazing (one impact with v- ~ 0.1) the step is smooth: the Jacobian
    (Phi, S, G in time order) equals central differences to O(h^2)."""
    model = OneDOF(P, gains)
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(20):
        z = rng.normal(scale=0.05, size=2)
        s = model.step(z, jacobian=True)
        if not s.impacts or min(i.v_minus for i in s.impacts) < 1e-2:
            continue
        checked += 1
        h = 1e-6
        fd = np.column_stack([(model.step(z + h * e).state - model.step(z - h * e).state)
                              / (2 * h) for e in np.eye(2)])
        assert np.allclose(s.jacobian, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())
    assert checked >= 5


@pytest.mark.parametrize("gains", [None, G])
def test_exact_determinant_is_that_of_the_jacobian(gains):
    model = OneDOF(P, gains)
    z = np.array([0.01, -0.02])
    s = model.step(z, jacobian=True)
    exact = model.jacobian_det(1, len(s.impacts))
    assert math.isclose(exact, np.linalg.det(s.jacobian), rel_tol=1e-9)


def test_no_exact_determinant_with_a_delay():
    assert OneDOF(P, Gains(-0.4, -0.3, 1.5)).jacobian_det(1, 1) is None


def test_parameter_family():
    model = OneDOF(P, G)
    assert model.with_parameter("delta_d", -2e-3).params.delta_d == -2e-3
    assert model.with_parameter("c2", -0.5).gains.c2 == -0.5
    assert model.with_parameter("zeta", 0.02).parameter("zeta") == 0.02
    assert model.parameter("c1") == G.c1
    with pytest.raises(ValueError, match="'nope' is invalid: valid names are zeta"):
        model.with_parameter("nope", 1.0)
    with pytest.raises(ParameterError, match="zeta"):
        model.with_parameter("zeta", 2.0)
    with pytest.raises(ValueError, match="without gains"):
        OneDOF(P).parameter("c1")


def test_section_geometry_and_grazing_point():
    model = OneDOF(P)
    assert model.section_phase == P.tau2 and model.period == P.period
    assert model.coordinates == ("x - x**", "v - v**")
    assert model.grazing_state().tolist() == [0.0, 0.0]

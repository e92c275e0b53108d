"""The n-DOF model and its loader: shipped files load, bad input is refused by name."""

import math
from pathlib import Path

import numpy as np
import pytest

from grazing_control.oscillator.ndof import NdofModel, load_model, model_from_mapping
from grazing_control.oscillator.params import OscillatorParams, ParameterError

MODELS = Path(__file__).resolve().parent.parent / "config" / "models"


def _base():
    return dict(M=[[1.0, 0.0], [0.0, 2.0]], C=[[0.1, 0.0], [0.0, 0.1]],
                K=[[2.0, -1.0], [-1.0, 2.0]], f=[0.0, 1.0], omega=0.8, i_w=0)


def test_study_file_matches_the_1dof_params():
    m = load_model(MODELS / "study_1dof.yaml")
    p = OscillatorParams(delta_d=-5e-6)
    assert m.n == 1
    assert m.C[0, 0] == 2 * p.zeta and m.omega == p.omega and m.r == p.r
    assert m.delta_d == p.delta_d and m.pi2_offset == p.pi2_offset


def test_two_mass_chain_loads():
    m = load_model(MODELS / "two_mass_chain.yaml")
    assert m.n == 2 and m.i_w == 0 and m.i_a == 1 and m.f.tolist() == [0.0, 1.0]
    assert np.all(np.linalg.eigvalsh(m.K) > 0)
    with pytest.raises(ValueError):
        m.M[0, 0] = 3.0  # frozen arrays


@pytest.mark.parametrize(
    "change, name",
    [
        (dict(M=[[1.0, 0.5], [0.0, 1.0]]), "M"),
        (dict(M=[[1.0, 0.0], [0.0, -1.0]]), "M"),
        (dict(C=[[1.0]]), "C"),
        (dict(K=[[-1.0, 0.0], [0.0, 1.0]]), "K"),
        (dict(f=[1.0]), "f"),
        (dict(omega=0.0), "omega"),
        (dict(omega=math.nan), "omega"),
        (dict(i_w=2), "i_w"),
        (dict(i_a=-1), "i_a"),
        (dict(r=0.0), "r"),
        (dict(r=1.5), "r"),
        (dict(pi2_offset=7.0), "pi2_offset"),
        (dict(bogus=1), "bogus"),
    ],
)
def test_bad_input_names_the_field(change, name):
    with pytest.raises(ParameterError, match=name):
        model_from_mapping({**_base(), **change})


def test_missing_field_and_non_mapping():
    data = _base()
    del data["omega"]
    with pytest.raises(ParameterError, match="omega"):
        model_from_mapping(data)
    with pytest.raises(ParameterError, match="mapping"):
        model_from_mapping([1, 2])


def test_r_one_allowed_and_phase_reduced():
    m = NdofModel(**_base(), r=1.0, phase=2 * math.pi + 0.5)
    assert m.r == 1.0 and abs(m.phase - 0.5) < 1e-12


def test_with_clearance_moves_only_the_wall_and_checks_it_by_name():
    """NdofModel.with_clearance: the model of dataclasses.replace(m, delta_d=...), field for
    field, with m's validated arrays shared (not copied, not checked again) and
    ``dynamics`` pointing at the model it came from, through any chain of moves; a
    clearance that is not a finite real number is refused naming delta_d."""
    import dataclasses

    m = NdofModel(**_base(), delta_d=-1e-3)
    moved = m.with_clearance(2e-4).with_clearance(-3e-5)
    again = dataclasses.replace(m, delta_d=-3e-5)
    for field in dataclasses.fields(NdofModel):
        a, b = getattr(moved, field.name), getattr(again, field.name)
        assert np.array_equal(a, b) and type(a) is type(b), field.name
    assert moved.M is m.M and moved.K is m.K and moved.f is m.f
    assert moved.dynamics is m and m.dynamics is m and again.dynamics is again
    assert m.delta_d == -1e-3                                   # m itself unchanged
    for bad in (math.nan, math.inf, "0.1", True, None):
        with pytest.raises(ParameterError, match="delta_d"):
            m.with_clearance(bad)

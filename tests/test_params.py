"""Tests of grazing_control.oscillator.params: defaults, validation, derived quantities.

Derived values are compared with their closed forms (spec sections 1-3) evaluated
independently in mpmath at 50 digits.
"""

import doctest
import math
from dataclasses import FrozenInstanceError, fields

import numpy as np
import pytest
from mpmath import mp, mpf

import grazing_control.oscillator.params as params_module
from grazing_control.oscillator.params import (STUDY_R, STUDY_ZETA, OscillatorParams,
                                               ParameterError, study_omega)

mp.dps = 50
FIELDS = [f.name for f in fields(OscillatorParams)]


# ------------------------------------------------------------------- defaults
def test_defaults_are_the_study_reference_set():
    p = OscillatorParams()
    assert p.zeta == 0.01 == STUDY_ZETA
    assert p.r == 0.68 == STUDY_R
    assert p.omega == 2.0 * math.sqrt(1.0 - 0.01**2) / 3.0 + 5e-4 == study_omega()
    assert p.delta_d == 0.0
    assert p.tau0 == 0.0
    assert p.pi2_offset == math.pi / 2
    assert FIELDS == ["zeta", "r", "omega", "delta_d", "tau0", "pi2_offset"]


def test_every_field_is_documented():
    doc = OscillatorParams.__doc__
    params_section = doc.split("Parameters\n    ----------")[1].split("Notes\n")[0]
    for name in FIELDS:
        assert f"{name} : float" in params_section, name


def test_frozen_and_with_revalidates():
    p = OscillatorParams()
    with pytest.raises(FrozenInstanceError):
        p.zeta = 0.2
    q = p.with_(delta_d=-1e-3, r=0.5)
    assert (q.delta_d, q.r, q.zeta) == (-1e-3, 0.5, p.zeta)
    assert p.delta_d == 0.0  # unchanged
    with pytest.raises(ParameterError, match=r"^r=1\.5 is invalid"):
        p.with_(r=1.5)


def test_from_d_sets_the_wall_exactly():
    p = OscillatorParams.from_d(0.5, r=0.5)
    assert p.r == 0.5
    assert p.delta_d == 0.5 - p.d_star
    assert abs(p.d - 0.5) <= 2 * math.ulp(0.5)
    with pytest.raises(ParameterError, match=r"^d=inf is invalid.*finite"):
        OscillatorParams.from_d(math.inf)


def test_numbers_are_normalised():
    p = OscillatorParams(zeta=np.float64(0.02), r=1 / 2, omega=1, tau0=-1.0)
    assert type(p.zeta) is float and type(p.omega) is float and p.omega == 1.0
    assert p.tau0 == pytest.approx(2 * math.pi - 1.0, abs=1e-15)
    assert 0.0 <= OscillatorParams(tau0=2 * math.pi).tau0 < 2 * math.pi
    assert OscillatorParams(tau0=4 * math.pi + 0.5).tau0 == pytest.approx(0.5, abs=1e-14)


def test_tau0_reduction_stays_below_two_pi():
    assert 0.0 <= OscillatorParams(tau0=-1e-300).tau0 < 2 * math.pi


# ----------------------------------------------------------------- validation
RANGE_CASES = [
    ("zeta", 0.0, "0 < zeta < 1"),
    ("zeta", -0.1, "0 < zeta < 1"),
    ("zeta", 1.0, "0 < zeta < 1"),
    ("zeta", 2.5, "0 < zeta < 1"),
    ("r", 0.0, "0 < r < 1"),
    ("r", 1.0, "0 < r < 1"),
    ("r", -0.3, "0 < r < 1"),
    ("omega", 0.0, "finite omega > 0"),
    ("omega", -1.0, "finite omega > 0"),
    ("pi2_offset", 0.0, "0 < pi2_offset < 2*pi"),
    ("pi2_offset", 2 * math.pi, "0 < pi2_offset < 2*pi"),
    ("pi2_offset", -1.0, "0 < pi2_offset < 2*pi"),
    ("pi2_offset", 7.0, "0 < pi2_offset < 2*pi"),
]


@pytest.mark.parametrize("name,value,valid", RANGE_CASES)
def test_out_of_range_names_parameter_and_range(name, value, valid):
    with pytest.raises(ParameterError) as info:
        OscillatorParams(**{name: value})
    msg = str(info.value)
    assert msg.startswith(f"{name}={value!r} is invalid")
    assert f"valid range is {valid}" in msg


@pytest.mark.parametrize("name", FIELDS)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_rejected_for_every_field(name, value):
    with pytest.raises(ParameterError) as info:
        OscillatorParams(**{name: value})
    msg = str(info.value)
    assert msg.startswith(f"{name}=") and "is invalid" in msg
    assert "finite" in msg


@pytest.mark.parametrize("name", FIELDS)
@pytest.mark.parametrize("value", ["0.5", None, True, 1 + 0j, [0.5], np.array(0.5)])
def test_non_numbers_rejected_for_every_field(name, value):
    with pytest.raises(ParameterError) as info:
        OscillatorParams(**{name: value})
    msg = str(info.value)
    assert msg.startswith(f"{name}=") and "is invalid" in msg
    assert "real number" in msg


def test_parameter_error_is_a_value_error():
    assert issubclass(ParameterError, ValueError)


# ------------------------------------------------------------ derived values
def _closed_forms(zeta, omega, delta_d, pi2_offset):
    z, w = mpf(zeta), mpf(omega)
    a = 1 / mp.sqrt((1 - w**2) ** 2 + (2 * z * w) ** 2)
    phi = mp.atan2(2 * z * w, 1 - w**2)
    tau_star = phi % (2 * mp.pi)
    tau2 = (tau_star + mpf(pi2_offset)) % (2 * mp.pi)
    return {
        "omega_d": mp.sqrt(1 - z**2),
        "period": 2 * mp.pi / w,
        "amplitude": a,
        "lag": phi,
        "d_star": a,
        "d": a + mpf(delta_d),
        "tau_star": tau_star,
        "tau2": tau2,
        "a_star": mp.cos(tau_star) - a,
        "x_ref": a * mp.cos(tau2 - phi),
        "v_ref": -a * w * mp.sin(tau2 - phi),
    }


@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        {"delta_d": -5e-6},
        {"zeta": 0.2, "omega": 1.7, "delta_d": 0.3, "pi2_offset": 4.0},
        {"zeta": 0.05, "omega": 0.3, "pi2_offset": 0.1},
        {"zeta": 0.5, "omega": 1.0},  # at resonance, allowed for zeta > 0
    ],
)
def test_derived_values_match_closed_forms(kwargs):
    p = OscillatorParams(**kwargs)
    ref = _closed_forms(p.zeta, p.omega, p.delta_d, p.pi2_offset)
    for name, value in ref.items():
        got = getattr(p, name)
        assert abs(mpf(got) - value) <= 4e-16 * max(1, abs(value)), (name, got, value)
    assert p.non_sticking == (ref["a_star"] < 0)


def test_study_grazing_values():
    """The study set: d* ~ 1.8015, tau* small and positive, regular grazing (a* < 0)."""
    p = OscillatorParams()
    assert p.d_star == pytest.approx(1.8014983149537960, rel=1e-15)
    assert 0 < p.tau_star < 0.05
    assert p.a_star == pytest.approx(math.cos(p.tau_star) - p.d_star, rel=1e-15)
    assert p.non_sticking and p.a_star < -0.8
    # X** lies on the non-impacting motion at the Pi2 phase
    assert p.x_ref == pytest.approx(p.d_star * math.cos(p.tau2 - p.lag), abs=1e-15)
    assert p.v_ref == pytest.approx(-p.d_star * p.omega, rel=1e-15)
    assert p.d == p.d_star
    assert OscillatorParams(delta_d=-5e-6).d == p.d_star - 5e-6


@pytest.mark.parametrize("omega", [0.05, 0.5, 0.99, 1.0, 1.3, 3.0])
@pytest.mark.parametrize("zeta", [0.01, 0.3, 0.9])
def test_grazing_acceleration_closed_form(zeta, omega):
    """cos(phi) = (1 - omega^2) a, hence a* = cos tau* - d* = -omega^2 d* < 0 (Eq. 3)."""
    p = OscillatorParams(zeta=zeta, omega=omega)
    assert p.a_star == pytest.approx(-omega**2 * p.d_star, rel=1e-12, abs=1e-15)
    assert p.non_sticking


def test_docstring_examples():
    result = doctest.testmod(params_module, verbose=False)
    assert result.failed == 0

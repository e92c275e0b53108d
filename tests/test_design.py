"""Specification tests of grazing_control.dynamics.design.gains (spec section 6, study Eqs. 33-38).

Every number is checked against a route that does not share the code under test:

* N_g from ``scipy.linalg.expm`` of the system matrix (not the closed-form Phi);
* Floquet multipliers from Newton shooting on the exact Pi2 map (``orbits.shoot``),
  next to the impact-phase route (``orbits.orbit_11``);
* the admissible set's end points by what fails there: exact multipliers crossing the
  unit circle, and the 1/1 branch born at grazing leaving the impacting side.

Measured (study parameters): the study's (impacting-side) admissible set
c2 = (-2.0190440882, 0.2820918413); with the non-impacting side too (rho(N_g) < 1)
the combined default set is (-2.0190440882, 0.1065759767);
at the lower end lambda0 = -1 (flip) with gamma1 ~ 187 > 0, so only stability fails;
at the upper end lambda0 = +1 *and* gamma1 = 0 at the same c2 (a +1 limit multiplier
is a fold of Delta d(psi) at grazing, i.e. kappa = 0), so both conditions fail there.
For c2 = -1 the exact multipliers approach lambda0 = (0.320611, 0) with an error
0.2238 v- (4.8e-6 at Delta d = -1e-10).
"""

import math
import os

import numpy as np
import pytest
import yaml
from scipy.linalg import expm

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import (admissible_c2, controller_parameters,
                                             degenerate_c1, evaluate_design,
                                             existence_coefficient, limit_multipliers,
                                             write_controller_yaml)
from grazing_control.dynamics.maps.maps import pi2_map, smooth_return_matrix
from grazing_control.dynamics.orbits.orbits import _orbit_from_phase, wall_offset_at_phase, orbit_11, shoot
from grazing_control.oscillator.params import OscillatorParams

P = OscillatorParams()
C2_VALUES = (-3.0, -2.0, -1.0, -0.5, 0.0, 0.25, 1.0, 5.0)


def _gains(c2, p=P):
    return Gains(degenerate_c1(p, c2), c2)


def _n_g_expm(p, gains):
    """N_g = Phi(T - s) G Phi(s) with Phi = expm(A t) (independent of flow.transition_matrix)."""
    a = np.array([[0.0, 1.0], [-1.0, -2.0 * p.zeta]])
    s = p.pi2_offset / p.omega
    g = np.array([[1.0, 0.0], [gains.c1, 1.0 + gains.c2]])
    return expm(a * (p.period - s)) @ g @ expm(a * s)


def _shoot_at(p, gains, guess):
    """Newton shooting on the exact Pi2 map from a perturbed guess; residual checked.

    tol=1e-8: near grazing |z| ~ 1e-6 while the map's rounding floor is ~1e-15
    absolute, so a relative step of 1e-14 is unreachable (see
    test_continuation.test_shoot_converges_from_the_exact_orbit).
    """
    guess = np.asarray(guess) * (1.0 + 1e-6)  # Newton has something to do
    s = shoot(p, gains=gains, deviation=guess, tol=1e-8)
    seg = pi2_map(p, *s.pi2_deviation, gains)
    assert len(seg.impacts) == 1
    assert max(abs(seg.dx - s.pi2_deviation[0]), abs(seg.dv - s.pi2_deviation[1])) < 1e-13
    return s


@pytest.fixture(scope="module")
def interval():
    """The study's set: the impacting-side conditions only."""
    intervals = admissible_c2(P, conditions="impacting")
    assert len(intervals) == 1, intervals
    return intervals[0]


# ------------------------------------------------------------------ degenerate c1
@pytest.mark.parametrize("c2", C2_VALUES)
def test_degenerate_c1_zeroes_n_g12(c2):
    g = _gains(c2)
    assert abs(smooth_return_matrix(P, g)[0, 1]) <= 1e-14
    # independent route: matrix exponential
    n = _n_g_expm(P, g)
    assert abs(n[0, 1]) <= 1e-12 * np.max(np.abs(n))
    # and the entry is really controlled by c1: a change of c1 moves it
    off = smooth_return_matrix(P, Gains(g.c1 + 1e-3, c2))[0, 1]
    assert abs(off) > 1e-6


def test_degenerate_c1_is_affine_in_c2():
    c2s = np.array([-2.0, -0.3, 1.7])
    c1s = np.array([degenerate_c1(P, c) for c in c2s])
    slope01 = (c1s[1] - c1s[0]) / (c2s[1] - c2s[0])
    slope02 = (c1s[2] - c1s[0]) / (c2s[2] - c2s[0])
    assert slope01 == pytest.approx(slope02, rel=1e-12)
    # slope from N_g,12 = Q11 P12 + Q12 (c1 P12 + (1 + c2) P22): dc1/dc2 = -P22 / P12,
    # with P = Phi(s) from expm
    a = np.array([[0.0, 1.0], [-1.0, -2.0 * P.zeta]])
    ps = expm(a * P.pi2_offset / P.omega)
    assert slope01 == pytest.approx(-ps[1, 1] / ps[0, 1], rel=1e-12)


def test_degenerate_c1_for_other_parameters():
    q = OscillatorParams(zeta=0.05, r=0.5, omega=1.3, pi2_offset=1.0)
    for c2 in (-1.5, 0.4):
        g = _gains(c2, q)
        n = _n_g_expm(q, g)
        assert abs(n[0, 1]) <= 1e-12 * np.max(np.abs(n))


# ------------------------------------------------------------------ limit multipliers
def _sorted(lam):
    return np.sort_complex(np.asarray(lam, dtype=complex))


@pytest.mark.parametrize("c2", (-1.0, -0.5, 0.0))
def test_limit_multipliers_match_exact_orbit_at_small_delta_d(c2):
    g = _gains(c2)
    lam0 = _sorted(limit_multipliers(P, g))
    o = orbit_11(P.with_(delta_d=-1e-10), g)
    assert np.max(np.abs(_sorted(o.multipliers) - lam0)) < 1e-5


@pytest.mark.parametrize("c2", (-2.0, -1.0, -0.5, 0.0, 0.2))
def test_limit_multipliers_error_shrinks_like_v_minus(c2):
    """lambda = lambda0 + O(delta2) (Eqs. 23, 25), delta2 ~ v- ~ sqrt|Delta d|: the error
    falls by ~10 when Delta d falls by 100 (measured ratios 0.099-0.100)."""
    g = _gains(c2)
    lam0 = _sorted(limit_multipliers(P, g))
    errs = []
    for dd in (-1e-6, -1e-8, -1e-10):
        q = P.with_(delta_d=dd)
        o = orbit_11(q, g)
        s = _shoot_at(q, g, o.pi2_deviation)  # exact Pi2 map, Newton
        assert s.label == "1/1"
        np.testing.assert_allclose(_sorted(s.multipliers), _sorted(o.multipliers), atol=1e-9)
        errs.append(np.max(np.abs(_sorted(s.multipliers) - lam0)))
    for a, b in zip(errs[:-1], errs[1:]):
        assert 0.05 < b / a < 0.2, errs


def test_c2_minus_one_has_an_exact_zero_multiplier():
    g = _gains(-1.0)
    assert np.linalg.det(np.array([[1.0, 0.0], [g.c1, 1.0 + g.c2]])) == 0.0
    lam0 = limit_multipliers(P, g)
    assert lam0[1] == 0.0
    assert abs(lam0[0]) == pytest.approx(0.3206108, abs=1e-6)
    q = P.with_(delta_d=-1e-8)
    s = _shoot_at(q, g, orbit_11(q, g).pi2_deviation)
    assert abs(np.linalg.det(s.monodromy)) <= 1e-14
    assert s.multipliers[1] == 0.0


def test_limit_determinant_is_exact():
    for c2 in (-1.7, -0.4, 0.1):
        lam0 = limit_multipliers(P, _gains(c2))
        det = P.r ** 2 * math.exp(-2.0 * P.zeta * P.period) * (1.0 + c2)
        assert (lam0[0] * lam0[1]).real == pytest.approx(det, rel=1e-12)


# ------------------------------------------------------------------ admissible set
def test_admissible_c2_is_one_interval_containing_the_study_gain(interval):
    lo, hi = interval
    assert lo == pytest.approx(-2.0190440881, abs=1e-8)
    assert hi == pytest.approx(0.2820918413, abs=1e-8)
    assert lo < -1.0 < hi
    # a wider scan finds the same set
    wide = admissible_c2(P, -10.0, 10.0, 801, conditions="impacting")
    assert len(wide) == 1
    assert wide[0] == pytest.approx(interval, abs=1e-9)


@pytest.mark.parametrize("end", (0, 1))
def test_just_inside_each_end_admissible_just_outside_not(interval, end):
    x = interval[end]
    inward = 1.0 if end == 0 else -1.0
    for eps in (1e-6, 1e-3):
        assert evaluate_design(P, x + inward * eps).admissible_impacting
        assert not evaluate_design(P, x - inward * eps).admissible_impacting


def test_lower_end_is_a_flip_of_the_exact_multipliers(interval):
    lo = interval[0]
    # only stability fails: gamma1 > 0 on both sides
    for c2 in (lo - 1e-3, lo + 1e-3):
        assert evaluate_design(P, c2).gamma1 > 100.0
    assert evaluate_design(P, lo).multipliers_limit[0].real == pytest.approx(-1.0, abs=1e-9)
    # exact Floquet multipliers at Delta d = -1e-10 by Newton shooting on the Pi2 map
    q = P.with_(delta_d=-1e-10)
    lead = {}
    for c2 in (lo - 1e-3, lo + 1e-3):
        g = _gains(c2)
        s = _shoot_at(q, g, orbit_11(q, g).pi2_deviation)
        assert s.label == "1/1"
        lead[c2] = s.multipliers[0]
        assert abs(lead[c2].imag) == 0.0 and lead[c2].real < 0.0
    assert abs(lead[lo - 1e-3]) > 1.0 > abs(lead[lo + 1e-3])


def test_upper_end_is_where_the_branch_leaves_the_impacting_side(interval):
    hi = interval[1]
    # at this end gamma1 and 1 - lambda0 vanish together (lambda0 = +1 is a fold at grazing)
    assert abs(existence_coefficient(P, _gains(hi))) < 1e-6
    assert evaluate_design(P, hi).multipliers_limit[0].real == pytest.approx(1.0, abs=1e-9)
    inside, outside = _gains(hi - 1e-3), _gains(hi + 1e-3)
    assert existence_coefficient(P, inside) > 0.0 > existence_coefficient(P, outside)

    # Inside: the physical branch points near grazing lie on Delta d < 0 (checked by the
    # exact flow: one impact per period, periodic), with multipliers inside the circle.
    # Outside: they lie on Delta d > 0, and their exact multiplier is > 1.
    for g, sign in ((inside, -1.0), (outside, 1.0)):
        for psi in (-1e-4, -1e-3):
            dd, v, _ = wall_offset_at_phase(P, psi, g)
            assert v > 0.0
            assert math.copysign(1.0, dd) == sign
            o = _orbit_from_phase(P, psi, g, check=True)
            s = _shoot_at(P.with_(delta_d=dd), g, o.pi2_deviation)
            assert s.label == "1/1"
            assert s.impacts[0].v_minus == pytest.approx(v, rel=1e-6)
            if sign < 0:
                assert np.max(np.abs(s.multipliers)) < 1.0
            else:
                assert np.max(np.abs(s.multipliers)) > 1.0

    # Inside, the 1/1 motion is born at grazing: v- -> 0 like sqrt|Delta d|. Outside,
    # any 1/1 orbit at Delta d -> 0- keeps a finite v- (no continuous transition).
    def v_minus(g, dd):
        return orbit_11(P.with_(delta_d=dd), g).v_minus

    assert v_minus(inside, -1e-10) / v_minus(inside, -1e-8) == pytest.approx(0.1, rel=0.2)
    v_out = [v_minus(outside, dd) for dd in (-1e-8, -1e-10)]
    assert min(v_out) > 1e-2
    assert v_out[1] / v_out[0] > 0.5


# ------------------------------------------------------------------ controller YAML
def test_write_controller_yaml_shape_and_round_trip(tmp_path):
    g = _gains(-1.0)
    path = tmp_path / "controller.yaml"
    write_controller_yaml(path, P, g)
    doc = yaml.safe_load(path.read_text())
    assert list(doc) == ["/**"]
    assert list(doc["/**"]) == ["ros__parameters"]
    params = doc["/**"]["ros__parameters"]
    assert set(params) == {"c1", "c2", "actuation_delay", "x_ref", "v_ref", "zeta", "r", "omega",
                           "pi2_offset"}
    assert all(isinstance(v, float) for v in params.values())
    assert params == controller_parameters(P, g)  # exact: floats round-trip
    assert params["c1"] == g.c1 and params["c2"] == -1.0
    assert params["x_ref"] == P.x_ref and params["v_ref"] == P.v_ref
    assert (params["zeta"], params["r"], params["omega"], params["pi2_offset"]) == (
        P.zeta, P.r, P.omega, P.pi2_offset)
    # round trip: the parameters rebuild the same model and gains
    q = OscillatorParams(zeta=params["zeta"], r=params["r"], omega=params["omega"],
                         pi2_offset=params["pi2_offset"])
    assert q == P
    assert degenerate_c1(q, params["c2"]) == params["c1"]
    assert sorted(os.listdir(tmp_path)) == ["controller.yaml"]


def test_write_controller_yaml_custom_node_name(tmp_path):
    path = tmp_path / "c.yaml"
    write_controller_yaml(path, P, Gains(0.5, -0.25), node_name="other")
    doc = yaml.safe_load(path.read_text())
    assert doc["/other"]["ros__parameters"]["c1"] == 0.5


def test_failed_write_into_missing_directory_leaves_nothing(tmp_path):
    path = tmp_path / "missing" / "controller.yaml"
    with pytest.raises(OSError):
        write_controller_yaml(path, P, _gains(-1.0))
    assert not path.exists()
    assert list(tmp_path.iterdir()) == []


def test_failed_replace_leaves_no_temporary_file(tmp_path):
    target = tmp_path / "controller.yaml"
    target.mkdir()  # a directory in the way: the final rename fails
    (target / "keep").write_text("x")
    with pytest.raises(OSError):
        write_controller_yaml(target, P, _gains(-1.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["controller.yaml"]
    assert target.is_dir() and sorted(os.listdir(target)) == ["keep"]


def test_failed_write_keeps_an_existing_file(tmp_path, monkeypatch):
    path = tmp_path / "controller.yaml"
    path.write_text("old\n")

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(yaml, "safe_dump", boom)
    with pytest.raises(RuntimeError):
        write_controller_yaml(path, P, _gains(-1.0))
    assert path.read_text() == "old\n"
    assert sorted(os.listdir(tmp_path)) == ["controller.yaml"]


# ------------------------------------------------------------------ non-impacting side
def test_combined_set_adds_the_non_impacting_condition():
    """Default set = impacting conditions and rho(N_g) < 1 (issue 7): (-2.0190, 0.10658)."""
    (lo, hi), = admissible_c2(P)
    (ilo, ihi), = admissible_c2(P, conditions="impacting")
    (nlo, nhi), = admissible_c2(P, conditions="non-impacting")
    assert (lo, hi) == (max(ilo, nlo), min(ihi, nhi))
    assert hi == pytest.approx(0.1065759767, abs=1e-9) and nlo == pytest.approx(-2.1065759767, abs=1e-9)
    with pytest.raises(ValueError, match="conditions"):
        admissible_c2(P, conditions="both")


@pytest.mark.parametrize("c2, grows", [(0.1065759767 - 1e-2, False), (0.1065759767 + 1e-2, True)])
def test_non_impacting_controlled_motion_flips_at_the_upper_end(c2, grows):
    """On the non-impacting side (Delta d = +1e-3, wall out of reach of a 1e-9 deviation)
    the exact controlled Pi2 map contracts below the end and grows above it, at the rate
    rho(N_g) per period (a flip: the eigenvalue N11 of the degenerate N_g passes -1)."""
    from grazing_control.dynamics.simulation.simulate import simulate

    q = P.with_(delta_d=1e-3)
    g = _gains(c2)
    n = 200
    res = simulate(q, n + 1, deviation=(1e-9, 0.0), gains=g)
    assert res.impacts_per_period.sum() == 0
    size = np.linalg.norm(res.pi2_deviation, axis=1)
    assert bool(size[n] > size[0]) is grows
    rate = (size[n] / size[n - 40]) ** (1 / 40)
    rho = float(np.max(np.abs(evaluate_design(P, c2).multipliers_free)))
    assert rate == pytest.approx(rho, rel=1e-2)
    assert evaluate_design(P, c2).free_stable is (not grows)

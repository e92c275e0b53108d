"""Tests of grazing_control.dynamics.orbits.two_parameter and `grazing continue2` (issue 18 s1).

Independent references:

* closed forms of the degenerate grazing points: omega* = 2 omega_d / m (Phi12(T) = 0,
  spec after Eq. 17), zeta* = sqrt(1 - (m omega / 2)^2), and for the controlled orbit
  the design itself (c1 from Eq. 38 at the study's omega and c2);
* the closed-form kappa of the uncontrolled curves at omega = 2 omega_d / m, written out
  here from docs/theory_two_parameter.md (T7), against the ZDM-series route of the code;
* Newton shooting on the exact Pi2 map (orbits.shoot: exact flow, certified impacts) for
  the multipliers -1 and +1 on the curves, instead of the impact-phase branch;
* the fold as the turning point of Delta d(psi) (central differences of the branch);
* the one-parameter continuation continue_11 for the study's PD point.
"""

import math

import numpy as np
import pytest

from grazing_control.cli.commands import main
from grazing_control.dynamics.orbits.continuation import continue_11
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.maps import pi2_map
from grazing_control.dynamics.orbits.orbits import wall_offset_at_phase, shoot, _orbit_from_phase
from grazing_control.dynamics.orbits.two_parameter import (KINDS, Family, asymptotic_coefficient,
                                                    codim2_points, continue_curve, curve_point,
                                                    fitted_exponent, local_shape,
                                                    regular_tests, two_parameter_diagram)
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError

P = OscillatorParams()
PD, FOLD = KINDS
PD_STUDY = -1.005268252976113e-05       # continue_11 at the study's omega (test_continuation)
G_STUDY = Gains(degenerate_c1(P, -1.0), -1.0)


@pytest.fixture(scope="module")
def omega_diagram():
    return two_parameter_diagram(Family(P, None, "omega"), 0.45, 2.1)


def _closed_form_kappa(p, kind):
    """(T7): kappa at omega* = 2 omega_d / m, uncontrolled, sigma = (-1)^m e^{-zeta T}."""
    m = round(2.0 * p.omega_d / p.omega)
    t, a, r, w = p.period, p.amplitude, p.r, p.omega
    s = (-1) ** m * math.exp(-p.zeta * t)
    e = math.exp(-2.0 * p.zeta * t)
    if kind == FOLD:
        return 2.0 * math.pi ** 2 * (1 + r) ** 2 * a * e / (w * w * (1 - s) ** 2 * (1 + r * s) ** 2)
    return (-4.0 * math.pi ** 2 * (1 + r) ** 2 * a * e / (w * w * (1 - s) ** 2 * (1 - r * s) ** 2)
            * (1.0 + (1 + r * s) ** 2 / (2.0 * (1 - r * s) ** 2)))


def _point_at(curve, fam, value):
    """The curve solved at ``value`` from the interpolation of its two points around it."""
    pts = curve.points
    for a, b in zip(pts[:-1], pts[1:]):
        if (a.value - value) * (b.value - value) <= 0.0 and a.value != b.value:
            w = (value - a.value) / (b.value - a.value)
            return curve_point(fam, curve.kind, value, a.psi + w * (b.psi - a.psi))
    raise AssertionError(f"the curve does not reach {value}")


# ------------------------------------------------------------------ codimension two
def test_degenerate_points_are_two_omega_d_over_m(omega_diagram):
    found = [c.value for c in omega_diagram.codim2]
    expected = [2.0 * P.omega_d / m for m in (4, 3, 2, 1)]
    assert len(found) == 4
    assert np.max(np.abs(np.array(found) - expected)) < 1e-10


def test_curves_meet_grazing_at_the_degenerate_points_detected_along_them(omega_diagram):
    # every arc joins two consecutive resonances (or leaves the range): the far end is
    # detected as psi crossing 0 along the curve, not seeded
    stars = {m: 2.0 * P.omega_d / m for m in (1, 2, 3, 4)}
    arcs = {(c.kind, tuple(round(2.0 * P.omega_d / x) for x in c.codim2)) for c in omega_diagram.curves}
    assert arcs == {(PD, (4,)), (FOLD, (4, 3)), (PD, (3, 2)), (FOLD, (2, 1)), (PD, (1,))}
    for c in omega_diagram.curves:
        for x in c.codim2:
            assert abs(x - stars[round(2.0 * P.omega_d / x)]) < 1e-10
        for q in c.points:
            if q.psi == 0.0:
                assert q.delta_d == 0.0
                assert abs(q.value - stars[round(2.0 * P.omega_d / q.value)]) < 1e-10


def test_degenerate_points_in_zeta_and_for_the_controlled_orbit():
    (z,) = codim2_points(Family(P, None, "zeta"), 0.001, 0.9)
    assert abs(z - math.sqrt(1.0 - (P.omega) ** 2)) < 1e-10        # m = 2: omega_d = omega
    (w,) = codim2_points(Family(P, G_STUDY, "omega"), 0.6, 0.75)
    assert abs(w - P.omega) < 1e-10                                 # the design's omega
    (c2,) = codim2_points(Family(P, G_STUDY, "c2"), -3.0, 1.0)
    assert abs(c2 - (-1.0)) < 1e-10                                 # the design's c2
    assert codim2_points(Family(P, None, "r"), 0.05, 0.95) == []    # N_g does not involve r


# ------------------------------------------------------------------ the curves themselves
def test_curve_points_have_the_multiplier_by_shooting(omega_diagram):
    checked = 0
    for c in omega_diagram.curves:
        target = -1.0 if c.kind == PD else 1.0
        phys = [q for q in c.points if q.physical and q.psi != 0.0 and abs(q.delta_d) > 1e-7]
        for q in phys[len(phys) // 4::max(1, len(phys) // 3)][:3]:
            p = P.with_(omega=q.value, delta_d=q.delta_d)
            z = _orbit_from_phase(p, q.psi, None, check=True).pi2_deviation
            # the exact Pi2 map (core flow, certified impacts): periodic, its monodromy
            # (Phi, S in time order) has the multiplier
            seg = pi2_map(p, *z, monodromy=True)
            assert len(seg.impacts) == 1
            assert max(abs(seg.dx - z[0]), abs(seg.dv - z[1])) < 1e-12 * (1.0 + max(map(abs, z)))
            lam = np.linalg.eigvals(np.array(seg.monodromy).reshape(2, 2))
            assert np.min(np.abs(lam - target)) < 1e-9, (c.kind, q.value, lam)
            assert np.min(np.abs(q.multipliers - target)) < 1e-9
            if c.kind == PD:   # Newton shooting converges there (J - I is regular)
                sh = shoot(p, deviation=z)
                assert np.min(np.abs(sh.multipliers - target)) < 1e-9
                assert abs(sh.pi2_deviation[0] - z[0]) < 1e-12 * (1.0 + abs(z[0]))
            checked += 1
    assert checked >= 10


def test_fold_curve_is_the_turning_point_of_delta_d(omega_diagram):
    fold = next(c for c in omega_diagram.curves if c.kind == FOLD and len(c.codim2) == 2)
    for q in fold.points[5::20]:
        p = P.with_(omega=q.value)
        h = 1e-6 * abs(q.psi)
        slope = (wall_offset_at_phase(p, q.psi + h)[0] - wall_offset_at_phase(p, q.psi - h)[0]) / (2.0 * h)
        scale = abs(wall_offset_at_phase(p, 1.01 * q.psi)[0] - q.delta_d) / (0.01 * abs(q.psi))
        assert abs(slope) < 1e-5 * max(scale, 1e-300) + 1e-12


def test_study_pd_point_lies_on_the_pd_curve(omega_diagram):
    fam = Family(P, None, "omega")
    curve = next(c for c in omega_diagram.curves if c.kind == PD and len(c.codim2) == 2)
    psi = _point_at(curve, fam, P.omega)
    dd = wall_offset_at_phase(P, psi)[0]
    one = next(b for b in continue_11(P, -1e-3, 0.0).bifurcations if b.type == "period-doubling")
    assert abs(dd - one.delta_d) < 1e-12 * abs(one.delta_d)
    assert abs(dd - PD_STUDY) < 1e-12 * abs(PD_STUDY)
    # and in the zeta and r planes through the study's point
    for name, lo, hi in (("zeta", 0.001, 0.9), ("r", 0.05, 0.95)):
        f = Family(P, None, name)
        d = two_parameter_diagram(f, lo, hi, (PD,), max_points=200)
        c = next(c for c in d.curves)
        assert abs(wall_offset_at_phase(P, _point_at(c, f, f.base))[0] - PD_STUDY) < 1e-12 * abs(PD_STUDY)


def test_regularised_tests_equal_v_times_det_of_j_plus_minus_i():
    from grazing_control.dynamics.orbits.continuation import branch_monodromy

    for gains in (None, G_STUDY, Gains(0.3, 0.2)):
        for psi in (-0.3, -1e-3, 2e-2, 0.7):
            dd, v, g_pd, g_f = regular_tests(P, gains, psi)
            _dd, _v, tr, det = branch_monodromy(P, psi, gains)
            assert g_pd == pytest.approx(v * (1.0 + tr + det), rel=1e-9, abs=1e-15)
            assert g_f == pytest.approx(v * (1.0 - tr + det), rel=1e-9, abs=1e-15)
    # at grazing both are +-N_g,12 K, K = (1 + r) a*
    _dd, v, g_pd, g_f = regular_tests(P, None, 0.0)
    n12 = math.exp(-P.zeta * P.period) * math.sin(P.omega_d * P.period) / P.omega_d
    assert v == 0.0 and g_pd == pytest.approx(n12 * (1 + P.r) * P.a_star, rel=1e-12)
    assert g_f == -g_pd


# ------------------------------------------------------------------ local shape
@pytest.mark.parametrize("m", [1, 2, 3, 4])
def test_kappa_from_the_zdm_series_equals_the_closed_form(m):
    star = 2.0 * P.omega_d / m
    for kind in KINDS:
        a = asymptotic_coefficient(Family(P, None, "omega"), kind, star)
        assert a.kappa == pytest.approx(_closed_form_kappa(P.with_(omega=star), kind), rel=1e-6)
        # PD on the side where Phi12(T) > 0, fold on the other ((T6), section 4.3)
        assert a.side == (1 if (kind == PD) == (m % 2 == 1) else -1)


def test_fold_from_the_multiplier_is_the_turning_point_of_the_series():
    # c_F of (T4) from the multiplier +1 against the turning point of (P3), -kappa1'/(2 kappa2)
    from grazing_control.dynamics.maps.perturbation import series_coefficients

    for fam, star in ((Family(P, None, "omega"), 2.0 * P.omega_d / 3.0),
                      (Family(P, None, "zeta"), math.sqrt(1.0 - P.omega ** 2)),
                      (Family(P, G_STUDY, "c2"), -1.0)):
        h = 1e-6
        up, down = (series_coefficients(*fam.at(star + s * h)) for s in (1, -1))
        at = series_coefficients(*fam.at(star))
        k1 = (up.kappa1 - down.kappa1) / (2.0 * h)
        a = asymptotic_coefficient(fam, FOLD, star)
        assert a.kappa == pytest.approx(-k1 * k1 / (4.0 * at.kappa2), rel=1e-9)
        assert a.side * a.rate == pytest.approx(-k1 / (2.0 * at.kappa2), rel=1e-9)


def test_local_shape_fits_exponent_two_and_kappa(omega_diagram):
    for c in omega_diagram.codim2:
        for a, shape, (p, kappa) in zip(c.asymptotics, c.shapes, c.fits):
            assert abs(p - 2.0) < 1e-3, (c.value, a.kind, p)
            assert kappa == pytest.approx(a.kappa, rel=1e-3)
            # the error of the leading order falls with the offset: O(mu - mu*)
            err = np.abs(shape[:, 1] / (a.kappa * shape[:, 0] ** 2) - 1.0)
            assert err[0] < err[-1] and err[0] < 2e-4
            assert np.all(np.sign(shape[:, 1]) == (-1 if a.kind == PD else 1))


def test_local_shape_of_the_controlled_curves():
    for fam, star in ((Family(P, G_STUDY, "omega"), P.omega), (Family(P, G_STUDY, "c2"), -1.0)):
        for kind in KINDS:
            a = asymptotic_coefficient(fam, kind, star)
            shape = local_shape(fam, kind, star, [1e-6, 1e-5, 1e-4])
            p, kappa = fitted_exponent(shape)
            assert abs(p - 2.0) < 1e-3 and kappa == pytest.approx(a.kappa, rel=1e-3)


def test_codim2_seed_continues_into_the_physical_side_only():
    fam = Family(P, None, "omega")
    star = 2.0 * P.omega_d / 3.0
    c = continue_curve(fam, PD, 0.0, star, 0.6, 0.7, max_points=30)
    assert "unphysical side (v- < 0)" in c.ends
    assert all(q.v_minus > 0.0 for q in c.points if q.psi != 0.0)
    assert all(q.value >= star for q in c.points)     # m = 3: PD above omega*


def test_family_refuses_bad_input():
    with pytest.raises(ParameterError, match="parameter='x' is invalid"):
        Family(P, None, "x")
    with pytest.raises(ParameterError, match="needs the controller's gains"):
        Family(P, None, "c2")
    with pytest.raises(ParameterError, match="zeta"):
        two_parameter_diagram(Family(P, None, "zeta"), 0.5, 1.5)
    with pytest.raises(ParameterError, match="range"):
        two_parameter_diagram(Family(P, None, "omega"), 0.7, 0.6)


# ------------------------------------------------------------------ the command
def test_command_writes_the_diagram_and_data(tmp_path, capsys):
    import json

    out = tmp_path / "c2"
    assert main(["continue2", "--from", "0.6", "--to", "0.75", "--max-points", "60",
                 "--json", "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    for name in ("two_parameter", "two_parameter_absolute", "two_parameter_local"):
        for ext in ("png", "svg"):
            assert (out / f"{name}.{ext}").stat().st_size > 1000
    assert json.loads((out / "continue2.json").read_text())["codim2"] == doc["codim2"]
    (star,) = doc["codim2"]
    assert star["m"] == 3 and abs(star["difference"]) < 1e-10
    rows = (out / "continue2_curves.csv").read_text().splitlines()
    assert rows[0].startswith("curve,kind,omega,psi,delta_d,d,")
    assert len(rows) - 1 == sum(len(c["points"]) for c in doc["curves"])
    assert main(["continue2", "--from", "0.6", "--to", "0.75", "--max-points", "20",
                 "--out", str(out)]) == 0
    assert "degenerate grazing at omega = 0.66663333249995" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--parameter", "c2"], "needs the controller's gains"),
    (["--from", "0.8", "--to", "0.7"], "--from=0.8, --to=0.7 are invalid"),
    (["--parameter", "zeta", "--from", "0.5", "--to", "1.5"], "zeta=1.5 is invalid"),
    (["--max-points", "1"], "invalid"),
    (["--max-points", "1000000"], "--max-points=1000000 is invalid"),
    (["--from", "1e-6", "--to", "0.5"], "omega=1e-06 is invalid with zeta=0.01"),
    (["--parameter", "r", "--from", "0.5", "--to", "1.0"], "r=1.0 is invalid"),
    (["--design"], "design=True is invalid with parameter='omega'"),
])
def test_command_refuses_bad_input_in_one_line(argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) if argv == ["--max-points", "1"] else _nothing():
        status = main(["continue2", "--out", str(tmp_path / "x")] + argv)
        assert status == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_uncontrolled_branch_closed_form_of_the_derivation():
    # (T3): Delta d(psi) = (1 + r) a omega M12 sin psi / D - 2 a sin^2(psi/2),
    # v- = -a omega sin psi det(I - M) / D, D = (1 - M11)(1 + r M22) + r M12 M21, M = Phi(T)
    from grazing_control.oscillator.flow import transition_matrix

    for p in (P, P.with_(omega=0.9), P.with_(zeta=0.2, r=0.3, omega=1.5)):
        m11, m12, m21, m22 = transition_matrix(p.zeta, p.period)
        d = (1 - m11) * (1 + p.r * m22) + p.r * m12 * m21
        a, w = p.amplitude, p.omega
        for psi in (-1e-3, -0.1, 0.5, 2.0):
            dd = (1 + p.r) * a * w * m12 * math.sin(psi) / d - 2 * a * math.sin(psi / 2) ** 2
            v = -a * w * math.sin(psi) * ((1 - m11) * (1 - m22) - m12 * m21) / d
            got = wall_offset_at_phase(p, psi)
            assert dd == pytest.approx(got[0], rel=1e-12) and v == pytest.approx(got[1], rel=1e-12)


def test_controlled_pd_curve_is_the_end_of_the_mistuning_band():
    # the controlled orbit (study design) on a plant with omega (1 + e): the exact band
    # end of dynamics.design.mismatch (orbit_11 scanned and bisected in log|Delta d| to 1e-3)
    from grazing_control.dynamics.design.mismatch import instability_band

    e = 1e-4
    band = instability_band(P, G_STUDY, "omega", e)
    shape = local_shape(Family(P, G_STUDY, "omega"), PD, P.omega, [P.omega * e])
    assert shape[0, 1] == pytest.approx(band.end, rel=2e-3)


def test_degenerate_points_crowding_at_low_omega_are_all_found():
    stars = codim2_points(Family(P, None, "omega"), 0.08, 0.3)
    ms = sorted(round(2.0 * P.omega_d / x) for x in stars)
    assert ms == list(range(7, 25))          # 2 omega_d / 25 = 0.079996 < 0.08
    assert max(abs(x - 2.0 * P.omega_d / round(2.0 * P.omega_d / x)) for x in stars) < 1e-10
    with pytest.raises(ParameterError, match="degenerate grazing points"):
        codim2_points(Family(P, None, "omega"), 0.01, 2.0)


# ------------------------------------------------------------------ the design family
DESIGN = Family(P, G_STUDY, "c2", design=True)


def test_design_family_curves_meet_grazing_at_the_ends_of_the_admissible_set():
    from grazing_control.dynamics.design.gains import admissible_c2, limit_multipliers

    ((lo, hi),) = admissible_c2(P, conditions="impacting")     # the design module's own ends
    (pd,) = codim2_points(DESIGN, -4.0, 2.0, kind=PD)
    (fold,) = codim2_points(DESIGN, -4.0, 2.0, kind=FOLD)
    assert abs(pd - lo) < 1e-10 and abs(fold - hi) < 1e-10
    assert np.min(np.abs(limit_multipliers(*DESIGN.at(pd)) + 1.0)) < 1e-12
    assert np.min(np.abs(limit_multipliers(*DESIGN.at(fold)) - 1.0)) < 1e-12
    d = two_parameter_diagram(DESIGN, -4.0, 2.0, max_points=150)
    met = {(c.kind, round(x, 9)) for c in d.curves for x in c.codim2}
    assert {(PD, round(pd, 9)), (FOLD, round(fold, 9))} <= met


def test_design_family_local_shapes_quadratic_pd_cubic_fold():
    from grazing_control.dynamics.maps.perturbation import series_coefficients

    (pd,) = codim2_points(DESIGN, -4.0, 2.0, kind=PD)
    (fold,) = codim2_points(DESIGN, -4.0, 2.0, kind=FOLD)
    # the upper end: lambda0 = +1 and gamma1 = -kappa2 = 0 at once (T10)
    assert abs(series_coefficients(*DESIGN.at(fold)).kappa2) < 1e-12
    for kind, star, exponent in ((PD, pd, 2), (FOLD, fold, 3)):
        a = asymptotic_coefficient(DESIGN, kind, star)
        assert a.exponent == exponent
        shape = local_shape(DESIGN, kind, star, [1e-6, 1e-5, 1e-4])
        p, kappa = fitted_exponent(shape, exponent)
        assert abs(p - exponent) < 1e-3 and kappa == pytest.approx(a.kappa, rel=1e-3)


def test_design_family_curve_points_have_the_multiplier():
    d = two_parameter_diagram(DESIGN, -4.0, 2.0, max_points=150)
    checked = 0
    for c in d.curves:
        target = -1.0 if c.kind == PD else 1.0
        # next to grazing the Pi2 map's own monodromy loses digits (4e-8 from -1 at
        # Delta d = -2.3e-9, where the branch's is within 3e-12): |Delta d| >= 1e-7 here
        for q in [q for q in c.points if q.physical and abs(q.delta_d) >= 1e-7][3::12]:
            p, gains = DESIGN.at(q.value)
            z = _orbit_from_phase(p.with_(delta_d=q.delta_d), q.psi, gains).pi2_deviation
            seg = pi2_map(p.with_(delta_d=q.delta_d), *z, gains, monodromy=True)
            lam = np.linalg.eigvals(np.array(seg.monodromy).reshape(2, 2))
            assert len(seg.impacts) == 1 and np.min(np.abs(lam - target)) < 1e-8
            checked += 1
    assert checked >= 6


def test_design_needs_c2():
    with pytest.raises(ParameterError, match="design=True is invalid with parameter='omega'"):
        Family(P, G_STUDY, "omega", design=True)


def test_command_design_family(tmp_path, capsys):
    import json

    assert main(["continue2", "--parameter", "c2", "--c2", "-1", "--design", "--max-points",
                 "40", "--json", "--out", str(tmp_path / "d")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["design"] is True
    ends = sorted((c["value"], tuple(c["curves"])) for c in doc["codim2"])
    assert [k for _v, k in ends] == [(PD,), (FOLD,)]
    from grazing_control.dynamics.design.gains import admissible_c2

    ((lo, hi),) = admissible_c2(P, conditions="impacting")
    assert abs(ends[0][0] - lo) < 1e-10 and abs(ends[1][0] - hi) < 1e-10
    assert [c["curves"][k]["exponent"] for c, k in zip(sorted(doc["codim2"], key=lambda c: c["value"]), (PD, FOLD))] == [2, 3]


def test_every_point_lies_in_the_range(omega_diagram):
    assert all(0.45 <= q.value <= 2.1 for c in omega_diagram.curves for q in c.points)
    # a corrector step that left the range landed the curve outside it before (0.599992)
    p = P.with_(pi2_offset=3.0)
    fam = Family(p, Gains(degenerate_c1(p, -1.0), -1.0), "omega")
    d = two_parameter_diagram(fam, 0.6, 0.7, max_points=100)
    values = [q.value for c in d.curves for q in c.points]
    assert min(values) == 0.6 and max(values) <= 0.7


def test_pd_curve_agrees_with_one_parameter_continuation_along_it(omega_diagram):
    # continue_11 at fixed omega: Brent on 1 + tr J + det J (the 1/v- form, unregularised)
    curve = next(c for c in omega_diagram.curves if c.kind == PD and len(c.codim2) == 2)
    fam = Family(P, None, "omega")
    for w in (0.67, 0.72, 0.8, 0.9):
        dd = wall_offset_at_phase(P.with_(omega=w), _point_at(curve, fam, w))[0]
        one = continue_11(P.with_(omega=w), 2.0 * dd, 0.5 * dd, points=40)
        (b,) = [b for b in one.bifurcations if b.type == "period-doubling"]
        assert abs(b.delta_d - dd) < 1e-11 * abs(dd)


def test_grazing_curve_in_absolute_clearance(omega_diagram):
    w = omega_diagram.grazing[:, 0]
    a = 1.0 / np.sqrt((1.0 - w ** 2) ** 2 + (2.0 * P.zeta * w) ** 2)
    assert np.max(np.abs(omega_diagram.grazing[:, 1] / a - 1.0)) < 1e-14
    for c in omega_diagram.curves:
        for q in c.points[::10]:
            aq = 1.0 / math.hypot(1.0 - q.value ** 2, 2.0 * P.zeta * q.value)
            assert q.d == pytest.approx(aq + q.delta_d, rel=1e-14, abs=1e-15)

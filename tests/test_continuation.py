"""Specification tests of grazing_control.dynamics.orbits.continuation (spec sections 5-6, Fig. 1c-d, 2c-e).

Independent routes used to earn the numbers:

* Newton shooting on the exact Pi2 map (``orbits.shoot``: exact flow, certified impact
  detection, monodromy as the product of Phi, S, G) instead of the impact-phase
  linear system that the continuation is built on;
* a central finite-difference Jacobian of the exact Pi2 map (``maps.pi2_map``);
* the exact flow over several periods (``simulate.simulate``);
* closed forms: det J = r^2 e^{-2 zeta T} (1 + c2), log-log slopes of the scalings.

Measured on the study's parameters (zeta = 0.01, r = 0.68, omega = 2 omega_d/3 + 5e-4):

* uncontrolled, Delta d in [-1e-1, -1e-12]: exactly one period-doubling point, at
  Delta d_PD = -1.005268252976e-05 (v- = 3.304e-3), identical to the last digit for
  50, 200 and 400 points; no fold, no Neimark-Sacker point. Shooting at
  Delta d_PD (1 -+ 1e-6): most negative multiplier -1.0000041 (towards grazing) and
  -0.9999959 (away). Finite-difference Jacobian (h = 1e-8): -1.0000039.
* max|lambda| ~ |Delta d|^s with s = -1.00003 on [1e-12, 1e-8] (|Delta d| max|lambda|
  -> 2.5636e-5); v- ~ |Delta d|^1.00000 (uncontrolled), ~ |Delta d|^0.49999
  (controlled, c2 = -1, c1 degenerate).
* controlled (c2 = -1, c1 degenerate): multipliers bounded (max 0.3206), converging to
  lambda0 = (0.320611, 0) with error / v- = 0.2238 (log-log slope 1.000).
* folds: c2 = 0.5 with the non-degenerate c1 = 0.789 (degenerate: 0.489) has an
  S-shaped 1/1 branch with two folds, at Delta d = -0.0235669353591 and
  -0.0234667812936 (v- = 1.73 and 2.29), multipliers (1, 0.5745); confirmed by two
  coexisting shooting orbits with multipliers either side of +1.
  Closer folds exist (c2 = 1, c1 = c1_deg + 0.03: Delta d ~ -9.87e-5; c2 = -2, c1
  degenerate: -0.2396), but there Delta d(psi) has a single minimum and returns to
  Delta d > 0, so neither end of a continue_11 range (each resolved to the phase
  nearest grazing) can lie beyond it: continue_11 cannot pass such a fold by design.
* Neimark-Sacker: none can exist on a Delta d continuation of this model. det J =
  r^2 e^{-2 zeta T} (1 + c2) does not depend on Delta d, so the NS test det J - 1 never
  changes sign along the branch; for det J > 1 (c2 = 3 here) the complex pair sits on
  |lambda| = sqrt(det J) = 1.2378 wherever it is complex. Tested below.
"""

import math

import numpy as np
import pytest

from grazing_control.dynamics.orbits.continuation import Branch, branch_monodromy, continue_11
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1, limit_multipliers
from grazing_control.dynamics.maps.maps import pi2_map
from grazing_control.dynamics.orbits.orbits import _orbit_from_phase, orbit_11, shoot
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate

P = OscillatorParams()
PD_STUDY = -1.005268252976113e-05
G_DEG = Gains(degenerate_c1(P, -1.0), -1.0)
G_FOLD = Gains(0.789, 0.5)  # non-degenerate: degenerate_c1(P, 0.5) = 0.489


def _det(p, gains=None):
    return p.r ** 2 * math.exp(-2.0 * p.zeta * p.period) * (1.0 if gains is None else 1.0 + gains.c2)


def _shoot(p, gains, guess, rel=1e-6):
    """Newton shooting on the exact Pi2 map from a perturbed guess; residual checked.

    tol=1e-8: a relative step of 1e-14 is below the map's rounding floor near grazing
    (~1e-15 absolute against |z| ~ 1e-6; see test_shoot_converges_from_the_exact_orbit).
    """
    s = shoot(p, gains=gains, deviation=np.asarray(guess) * (1.0 + rel), tol=1e-8)
    seg = pi2_map(p, *s.pi2_deviation, gains)
    assert len(seg.impacts) == 1
    assert max(abs(seg.dx - s.pi2_deviation[0]), abs(seg.dv - s.pi2_deviation[1])) < 1e-12
    return s


def _slope(x, y):
    return float(np.polyfit(np.log(np.abs(x)), np.log(np.abs(y)), 1)[0])


@pytest.fixture(scope="module")
def study_branch():
    return continue_11(P, -1e-1, -1e-12, points=200)


@pytest.fixture(scope="module")
def controlled_branch():
    return continue_11(P, -1e-4, -1e-12, G_DEG, points=60)


# ------------------------------------------------------------------ period doubling
def test_uncontrolled_branch_has_exactly_one_period_doubling(study_branch):
    kinds = [b.type for b in study_branch.bifurcations]
    assert kinds == ["period-doubling"]  # no fold, no NS, no grazing end in range
    pd = study_branch.bifurcations[0]
    assert pd.delta_d == pytest.approx(PD_STUDY, rel=1e-9)
    assert pd.multipliers[0] == pytest.approx(-1.0, abs=1e-9)
    assert (pd.multipliers[0] * pd.multipliers[1]).real == pytest.approx(_det(P), rel=1e-12)
    assert study_branch.points[0].delta_d == pytest.approx(-1e-1, rel=1e-12)
    assert study_branch.points[-1].delta_d == pytest.approx(-1e-12, rel=1e-9)
    assert len(study_branch.points) == 200


def test_period_doubling_is_stable_under_grid_changes(study_branch):
    ref = study_branch.bifurcations[0].delta_d
    for n in (50, 400):
        b = continue_11(P, -1e-1, -1e-12, points=n)
        pds = [x for x in b.bifurcations if x.type == "period-doubling"]
        assert len(pds) == 1
        assert pds[0].delta_d == pytest.approx(ref, rel=1e-10)
    # the direction of continuation does not matter either
    rev = continue_11(P, -1e-12, -1e-1, points=77)
    assert [x.type for x in rev.bifurcations] == ["period-doubling"]
    assert rev.bifurcations[0].delta_d == pytest.approx(ref, rel=1e-10)
    assert rev.points[0].delta_d == pytest.approx(-1e-12, rel=1e-9)


def test_period_doubling_confirmed_by_shooting_on_both_sides(study_branch):
    pd = study_branch.bifurcations[0].delta_d
    lead = {}
    for f in (1.0 - 1e-6, 1.0 + 1e-6):  # towards grazing, away from grazing
        q = P.with_(delta_d=pd * f)
        s = _shoot(q, None, orbit_11(q).pi2_deviation)
        assert s.label == "1/1"
        real = [z.real for z in s.multipliers if z.imag == 0.0]
        lead[f] = min(real)
    assert lead[1.0 - 1e-6] < -1.0 < lead[1.0 + 1e-6]
    assert lead[1.0 - 1e-6] == pytest.approx(-1.0, abs=1e-5)


def test_period_doubling_multiplier_from_finite_differences(study_branch):
    pd = study_branch.bifurcations[0].delta_d
    q = P.with_(delta_d=pd)
    z = np.array(_shoot(q, None, orbit_11(q).pi2_deviation).pi2_deviation)
    h = 1e-8  # truncation ~ h^2 (3.6e-4 at 1e-7, 3.9e-6 at 1e-8), rounding ~ 1e-15 / h
    jac = np.empty((2, 2))
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        a, b = pi2_map(q, *(z + e)), pi2_map(q, *(z - e))
        assert len(a.impacts) == len(b.impacts) == 1
        jac[:, k] = [(a.dx - b.dx) / (2 * h), (a.dv - b.dv) / (2 * h)]
    lam = np.linalg.eigvals(jac)
    assert np.min(lam.real) == pytest.approx(-1.0, abs=1e-5)
    assert np.linalg.det(jac) == pytest.approx(_det(P), rel=1e-5)


def test_stable_away_from_grazing_unstable_towards_it(study_branch):
    pd = study_branch.bifurcations[0].delta_d
    away = [pt for pt in study_branch.points if pt.delta_d < pd]
    near = [pt for pt in study_branch.points if pt.delta_d > pd]
    assert len(away) > 50 and len(near) > 50
    assert all(pt.stable for pt in away)
    assert not any(pt.stable for pt in near)


def test_largest_multiplier_grows_like_one_over_delta_d():
    """Measured slope of log max|lambda| against log|Delta d| on [1e-12, 1e-8]: -1.00003."""
    b = continue_11(P, -1e-8, -1e-12, points=40)
    dd = np.array([pt.delta_d for pt in b.points])
    lam = np.array([np.max(np.abs(pt.multipliers)) for pt in b.points])
    assert _slope(dd, lam) == pytest.approx(-1.0, abs=0.01)
    assert lam[-1] > 1e6
    assert np.all(np.diff(lam) > 0.0)  # monotone towards grazing
    # the product with |Delta d| settles (2.5636e-5)
    prod = lam * np.abs(dd)
    assert prod[-1] == pytest.approx(prod[-2], rel=1e-6)
    # the small multiplier follows from the exact determinant
    for pt in b.points:
        assert (pt.multipliers[0] * pt.multipliers[1]).real == pytest.approx(_det(P), rel=1e-9)


def test_impact_velocity_scaling_uncontrolled_linear():
    """Non-degenerate grazing: v- ~ |Delta d|^1 (measured slope 0.999998)."""
    b = continue_11(P, -1e-8, -1e-12, points=40)
    dd = [pt.delta_d for pt in b.points]
    v = [pt.v_minus for pt in b.points]
    assert all(x > 0 for x in v)
    assert _slope(dd, v) == pytest.approx(1.0, abs=0.05)


def test_impact_velocity_scaling_controlled_square_root(controlled_branch):
    """Degenerate grazing (N_g,12 = 0): v- ~ |Delta d|^(1/2) (measured slope 0.49999)."""
    pts = [pt for pt in controlled_branch.points if pt.delta_d > -1e-8]
    assert len(pts) > 20
    slope = _slope([pt.delta_d for pt in pts], [pt.v_minus for pt in pts])
    assert slope == pytest.approx(0.5, abs=0.05)


def test_branch_points_reproduce_orbit_11_and_the_exact_flow(study_branch, controlled_branch):
    for branch, gains in ((study_branch, None), (controlled_branch, G_DEG)):
        for pt in branch.points[:: max(1, len(branch.points) // 6)]:
            q = P.with_(delta_d=pt.delta_d)
            o = orbit_11(q, gains)
            assert o.v_minus == pytest.approx(pt.v_minus, rel=1e-8)
            np.testing.assert_allclose(np.abs(o.multipliers), np.abs(pt.multipliers), rtol=1e-7)
            # exact flow, up to three periods from the orbit's Pi2 point: one impact each,
            # at the branch's impact velocity, and back to the same point
            # Tolerances: the map's rounding floor is ~1e-15 absolute (v- from a Pi2
            # sample is ill-conditioned as v- -> 0: 2.5e-6 relative at v- = 3.4e-10,
            # checked against mpmath), and errors grow by max|lambda| per period.
            # An unstable orbit is followed only while the grown error stays small.
            grow = 1.0 + np.max(np.abs(pt.multipliers))
            scale = max(abs(o.pi2_deviation[0]), abs(o.pi2_deviation[1]))
            n = 3 if 1e-14 * grow ** 2 < 1e-4 * scale else 1
            res = simulate(q, n, deviation=o.pi2_deviation, gains=gains)
            assert res.impacts_per_period.tolist() == [1] * n
            after = list(res.pi2_deviation[1:]) + [res.final_deviation]
            for k in range(n):
                tol = grow ** k
                assert abs(res.impacts[k, 3] - pt.v_minus) <= (1e-9 * pt.v_minus + 1e-14) * tol
                err = np.max(np.abs(np.subtract(after[k], o.pi2_deviation)))
                assert err <= (1e-10 * scale + 1e-14) * tol * grow


def test_check_option_agrees_with_plain_branch(controlled_branch):
    checked = continue_11(P, -1e-4, -1e-12, G_DEG, points=60, check=True)
    assert [pt.psi for pt in checked.points] == [pt.psi for pt in controlled_branch.points]


# ------------------------------------------------------------------ controlled branch
def test_controlled_branch_is_bounded_and_tends_to_lambda0(controlled_branch):
    lam0 = np.sort_complex(limit_multipliers(P, G_DEG))
    pts = controlled_branch.points
    assert all(pt.stable for pt in pts)
    assert max(np.max(np.abs(pt.multipliers)) for pt in pts) < 0.33
    assert [b.type for b in controlled_branch.bifurcations] == []
    err = np.array([np.max(np.abs(np.sort_complex(pt.multipliers) - lam0)) for pt in pts])
    v = np.array([pt.v_minus for pt in pts])
    assert err[-1] < 1e-5
    assert np.all(np.diff(err) < 0.0)
    # error linear in v- (lambda = lambda0 + O(delta2)): slope 1 and a steady ratio 0.224
    assert _slope(v, err) == pytest.approx(1.0, abs=0.05)
    ratio = err / v
    assert np.max(ratio) / np.min(ratio) < 1.05


# ------------------------------------------------------------------ grazing end
def test_grazing_end_is_reported():
    b = continue_11(P, -1e-4, 0.0, G_DEG, points=30)
    last = b.bifurcations[-1]
    assert last.type == "grazing" and last.delta_d == 0.0
    np.testing.assert_array_equal(last.multipliers, limit_multipliers(P, G_DEG))
    u = continue_11(P, 0.0, -1e-6, points=10)
    assert [x.type for x in u.bifurcations][-1] == "grazing"
    assert np.all(np.isinf(np.abs(u.bifurcations[-1].multipliers)))  # unbounded uncontrolled
    assert all(x.type != "grazing" for x in continue_11(P, -1e-4, -1e-9, points=10).bifurcations)


def test_range_ending_at_grazing_samples_the_branch_towards_grazing():
    """A range with an end at 0 must still sample (-1e-4, 0) and see the PD inside it.

    Regression (found at a83d817, fixed in 39e12ff): all points collapsed onto the nonzero end (lo_mag ==
    hi_mag when one psi is 0), so the PD at -1.005e-5 was not found.
    """
    b = continue_11(P, -1e-4, 0.0, points=50)
    dd = np.array([pt.delta_d for pt in b.points])
    assert len(set(dd.tolist())) == len(dd)
    assert np.all(np.diff(dd) > 0.0)
    assert dd[-1] > -1e-9
    pds = [x for x in b.bifurcations if x.type == "period-doubling"]
    assert len(pds) == 1 and pds[0].delta_d == pytest.approx(PD_STUDY, rel=1e-10)


# ------------------------------------------------------------------ check=True robustness
def test_check_drops_unphysical_points_instead_of_raising():
    """check=True verifies each point by the exact flow and drops those that fail.

    Regression (a83d817, fixed in 39e12ff): a branch point whose Pi2 sample lies beyond
    the wall made _orbit_from_phase raise InitialStateError, which continue_11 did not
    catch (it catches only OrbitNotFound), so the whole call failed.
    """
    b = continue_11(P, -1e-3, -1.0, points=60, check=True)
    assert 0 < len(b.points) <= 60
    for pt in b.points[::10]:
        o = _orbit_from_phase(P, pt.psi, None, check=True)
        assert o.v_minus == pytest.approx(pt.v_minus, rel=1e-12)


def test_shoot_converges_from_the_exact_orbit():
    """Newton shooting started on the fixed point must converge.

    Regression (a83d817, fixed in 39e12ff): orbits.shoot stopped only when
    |step| <= tol |z| with tol = 1e-14, but the Pi2 map's rounding floor is ~1e-15
    absolute; near grazing |z| ~ 4e-3 (here, controlled, Delta d = -1e-5), so the
    criterion was never met and OrbitNotFound was raised from the exact solution.
    """
    q = P.with_(delta_d=-1e-5)
    o = orbit_11(q, G_DEG)
    s = shoot(q, gains=G_DEG, deviation=o.pi2_deviation)
    assert s.label == "1/1"


# ------------------------------------------------------------------ fold
def test_two_folds_on_an_s_shaped_branch():
    b50 = continue_11(P, -0.023, -0.0245, G_FOLD, points=50, check=True)
    b = continue_11(P, -0.023, -0.0245, G_FOLD, points=200)
    folds = [x for x in b.bifurcations if x.type == "fold"]
    assert [x.type for x in b.bifurcations] == ["fold", "fold"]
    assert len(b50.points) == 50  # every point passed the exact-flow check
    for x, y in zip(folds, [x for x in b50.bifurcations if x.type == "fold"]):
        assert x.delta_d == pytest.approx(y.delta_d, rel=1e-10)
    lower, upper = folds
    assert lower.delta_d == pytest.approx(-0.0235669353591, rel=1e-9)
    assert upper.delta_d == pytest.approx(-0.0234667812936, rel=1e-9)
    for f in folds:
        assert f.multipliers[0] == pytest.approx(1.0, abs=1e-9)
        assert f.multipliers[1].real == pytest.approx(_det(P, G_FOLD), rel=1e-9)
    # between the folds three 1/1 orbits coexist; the end points lie beyond them
    assert b.points[0].delta_d > upper.delta_d and b.points[-1].delta_d < lower.delta_d


@pytest.mark.parametrize("which", (0, 1))
def test_fold_confirmed_by_two_shooting_orbits(which):
    """Just inside the fold, two distinct 1/1 orbits (exact Pi2 map, Newton) coexist and
    their real multipliers lie on either side of +1."""
    b = continue_11(P, -0.023, -0.0245, G_FOLD, points=50)
    fold = [x for x in b.bifurcations if x.type == "fold"][which]
    # the fold is a turning point of Delta d(psi): pick the two branch phases whose
    # Delta d is the same, just on the existing side of the fold
    dpsi = 4e-3
    psis = (fold.psi - dpsi, fold.psi + dpsi)
    orbits = [_orbit_from_phase(P, psi, G_FOLD, check=True) for psi in psis]
    dd_a, dd_b = (branch_monodromy(P, psi, G_FOLD)[0] for psi in psis)
    # both on the existing side of the fold (it is an extremum of Delta d(psi))
    assert (dd_a - fold.delta_d) * (dd_b - fold.delta_d) > 0.0
    assert abs(dd_a - dd_b) < 1e-3 * abs(fold.delta_d)
    q = P.with_(delta_d=0.5 * (dd_a + dd_b))
    shot = [_shoot(q, G_FOLD, o.pi2_deviation, rel=0.0) for o in orbits]
    assert np.max(np.abs(np.subtract(shot[0].pi2_deviation, shot[1].pi2_deviation))) > 1e-4
    lead = sorted(max(z.real for z in s.multipliers if z.imag == 0.0) for s in shot)
    assert lead[0] < 1.0 < lead[1]
    assert lead[1] - lead[0] < 0.1


# ------------------------------------------------------------------ Neimark-Sacker
def test_no_neimark_sacker_when_det_exceeds_one():
    g = Gains(3.305, 3.0)  # c2 = 3: det J = 4 r^2 e^{-2 zeta T} = 1.532 > 1
    det = _det(P, g)
    assert det > 1.0
    b = continue_11(P, -1e-8, -1e-3, g, points=100, check=True)
    assert "neimark-sacker" not in [x.type for x in b.bifurcations]
    complex_pts = [pt for pt in b.points if pt.multipliers[0].imag != 0.0]
    assert len(complex_pts) >= 3
    for pt in complex_pts:
        np.testing.assert_allclose(np.abs(pt.multipliers), math.sqrt(det), rtol=1e-12)
        assert not pt.stable
    # the test function det J - 1 is the same at every point of the branch
    dets = {branch_monodromy(P, pt.psi, g)[3] for pt in b.points}
    assert len(dets) == 1
    # independent: shooting multipliers of a complex point
    pt = complex_pts[len(complex_pts) // 2]
    q = P.with_(delta_d=pt.delta_d)
    s = _shoot(q, g, orbit_11(q, g).pi2_deviation)
    assert np.linalg.det(s.monodromy) == pytest.approx(det, rel=1e-9)
    np.testing.assert_allclose(np.sort_complex(s.multipliers), np.sort_complex(pt.multipliers),
                               atol=1e-8)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"start": 1e-3, "stop": -1e-6}, "start"),
        ({"start": -1e-3, "stop": 1e-6}, "stop"),
        ({"start": math.nan, "stop": -1e-6}, "start"),
        ({"start": -1e-3, "stop": math.nan}, "stop"),
        ({"start": -math.inf, "stop": -1e-6}, "start"),
        ({"start": -1e-3, "stop": -1e-6, "points": 1}, "points"),
        ({"start": -1e-3, "stop": -1e-6, "points": 0}, "points"),
        ({"start": -1e-3, "stop": -1e-3}, "start"),
    ],
)
def test_bad_input_raises_value_error_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        continue_11(P, **kwargs)


def test_return_type():
    b = continue_11(P, -1e-3, -1e-6, points=2)
    assert isinstance(b, Branch)
    assert len(b.points) == 2


# ------------------------------------------- continue_orbit: any model, by shooting
from affine_model import Affine  # noqa: E402
from grazing_control.dynamics.orbits.continuation import continue_orbit  # noqa: E402
from grazing_control.dynamics.maps.model import OneDOF  # noqa: E402


def test_generic_continuation_locates_period_doubling_and_neimark_sacker_exactly():
    """The affine model's multiplier mu crosses -1 at mu = -1, its pair's modulus rho
    crosses 1 at rho = 1: both located to the tolerance of Brent's method."""
    m = Affine(mu=-0.5)
    br = continue_orbit(m, "mu", np.linspace(-0.5, -1.5, 11), m.fixed_point())
    assert [b.type for b in br.bifurcations] == ["period-doubling"]
    assert abs(br.bifurcations[0].value + 1.0) < 1e-12
    assert br.stopped == "end" and len(br.points) == 11
    m = Affine(mu=0.2, rho=0.8)
    br = continue_orbit(m, "rho", np.linspace(0.8, 1.3, 6), m.fixed_point())
    assert [b.type for b in br.bifurcations] == ["neimark-sacker"]
    assert abs(br.bifurcations[0].value - 1.0) < 1e-12


def test_generic_continuation_of_the_1_1_branch_agrees_with_the_explicit_route():
    """Uncontrolled, in Delta d: the period doubling where continue_11 puts it (to the
    shooting tolerance), and the multipliers of every point as orbit_11's."""
    exact = continue_11(P, -1e-4, -1e-7)
    pd = [b.delta_d for b in exact.bifurcations if b.type == "period-doubling"]
    values = -np.logspace(-4, -6, 30)
    br = continue_orbit(OneDOF(P.with_(delta_d=-1e-4)), "delta_d", values,
                        orbit_11(P.with_(delta_d=-1e-4)).pi2_deviation)
    found = [b.value for b in br.bifurcations if b.type == "period-doubling"]
    assert len(found) == 1 and len(pd) == 1
    assert abs(found[0] - pd[0]) < 1e-10 * abs(pd[0])
    for pt in br.points[::7]:
        lam = orbit_11(P.with_(delta_d=pt.value)).multipliers
        assert np.allclose(pt.multipliers, lam, rtol=1e-8, atol=1e-12)


def test_generic_continuation_of_the_controlled_branch_ends_at_grazing():
    """With the degenerate gains the 1/1 orbit stays stable down to grazing; continued
    past Delta d = 0 the orbit stops impacting there, and the end is a grazing."""
    p = P.with_(delta_d=-1e-3)
    g = Gains(degenerate_c1(p, -1.0), -1.0)
    br = continue_orbit(OneDOF(p, g), "delta_d", np.linspace(-1e-3, 1e-4, 23),
                        orbit_11(p, g).pi2_deviation)
    assert all(pt.stable for pt in br.points)
    kinds = [b.type for b in br.bifurcations]
    assert kinds == ["grazing"]
    assert abs(br.bifurcations[0].value) < 1e-12
    assert br.points[-1].value < 0.0 and "0 impacts" in br.stopped


def test_generic_continuation_refuses_bad_values():
    with pytest.raises(ValueError, match="at least two finite"):
        continue_orbit(Affine(), "mu", [0.5], np.zeros(4))
    with pytest.raises(ValueError, match="'nope' is invalid"):
        continue_orbit(Affine(), "nope", [0.5, 0.6], np.zeros(4))

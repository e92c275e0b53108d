"""Tests of grazing_control.dynamics.orbits.orbits: periodic orbits and their Floquet multipliers.

Three independent routes must agree: the explicit impact-phase shooting of
orbit_11, Newton shooting on the Pi2 map (shoot), and a 50-digit Newton iteration on
the mpmath reference map (tests/reference.py) whose Jacobian is a 50-digit finite
difference. Multipliers are checked against finite differences of the exact map.

Where the 2/2 and 1/2 orbits were found (brute-force simulation from X**, 2000
periods, attractor classified by its period on Pi2 and impacts per period):

* 2/2: study parameters, Delta d = -1e-5 (between the period-doubling of the
  1/1 branch and the chaotic band; 1/1 attractor for Delta d <= -1.6e-5, chaotic
  for -6e-6 >= Delta d >= -1e-7). Attractor point on Pi2 ~ (-2.2127e-3, -1.19959).
* 1/2: omega = 3.2 (other parameters of the study), Delta d = -0.01 (the same
  motion exists for -0.03 <= Delta d <= -1e-5 at omega = 3.2, and at omega = 4).
"""

import math

import numpy as np
import pytest
from mpmath import mp, mpf

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.maps import pi2_map
from grazing_control.dynamics.orbits.orbits import (OrbitNotFound, branch_brackets, wall_offset_at_phase,
                                             find_branch_phase, monodromy_det, multipliers,
                                             orbit_11, shoot)
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate

from reference import RefModel

STUDY = OscillatorParams()


def _design(p):
    return Gains(degenerate_c1(p, -1.0), -1.0)


ORBIT_CASES = [
    (-0.05, False),
    (-1e-3, False),
    (-5e-6, False),   # unstable 1/1 near grazing, multiplier ~ -3.9
    (-5e-6, True),    # study scene, controlled
    (-9e-6, True),    # study scene, controlled
]


def _case(delta_d, controlled):
    p = STUDY.with_(delta_d=delta_d)
    return p, (_design(p) if controlled else None)


def _fd_step(orb):
    """FD step: below the map's square-root scale v-^2 near grazing, else 1e-6.

    The Pi2 map is smooth only on a scale ~ v-^2 in the state (the impact velocity
    behaves like the square root of the gap), so h = 1e-3 v-^2 for low-velocity
    impacts; the rounding floor ~1e-15 / h stays below 1e-6 relative.
    """
    vmin = min(i.v_minus for i in orb.impacts)
    return min(1e-6, 1e-3 * vmin**2)


def _fd_jacobian(p, z, periods, gains, h):
    """Fourth-order central differences of P^n on Pi2 (see test_maps._fd)."""
    def pn(zz):
        dx, dv = zz
        for _ in range(periods):
            seg = pi2_map(p, dx, dv, gains)
            dx, dv = seg.dx, seg.dv
        return np.array([dx, dv])

    jac = np.zeros((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        jac[:, j] = (-pn(z + 2 * e) + 8 * pn(z + e) - 8 * pn(z - e) + pn(z - 2 * e)) / (12 * h)
    return jac


# --------------------------------------------------------------------- 1/1
@pytest.mark.parametrize("delta_d,controlled", ORBIT_CASES)
def test_orbit_11_is_a_fixed_point_with_one_impact(delta_d, controlled):
    p, gains = _case(delta_d, controlled)
    orb = orbit_11(p, gains)
    assert orb.label == "1/1" and orb.periods == 1 and len(orb.impacts) == 1
    assert orb.v_minus > 0
    seg = pi2_map(p, *orb.pi2_deviation, gains)
    assert len(seg.impacts) == 1
    assert abs(seg.dx - orb.pi2_deviation[0]) < 1e-12
    assert abs(seg.dv - orb.pi2_deviation[1]) < 1e-12
    assert seg.impacts[0].v_minus == pytest.approx(orb.v_minus, rel=1e-9)
    # physical and deviation coordinates agree
    assert orb.pi2[0] == pytest.approx(p.x_ref + orb.pi2_deviation[0], abs=1e-15)
    assert orb.pi2[1] == pytest.approx(p.v_ref + orb.pi2_deviation[1], abs=1e-15)


@pytest.mark.parametrize("delta_d,controlled", ORBIT_CASES)
def test_orbit_11_agrees_with_newton_shooting(delta_d, controlled):
    p, gains = _case(delta_d, controlled)
    orb = orbit_11(p, gains)
    guess = np.array(orb.pi2_deviation) * (1 + 1e-3)
    newton = shoot(p, deviation=guess, gains=gains)
    assert newton.label == "1/1"
    assert np.allclose(newton.pi2_deviation, orb.pi2_deviation, rtol=0, atol=1e-12)
    lam_a, lam_b = orb.multipliers, newton.multipliers
    assert np.allclose(lam_a, lam_b, rtol=0, atol=1e-8 * max(1.0, np.max(np.abs(lam_a))))


def test_shoot_converges_with_default_tolerance_on_the_study_scene():
    """Near grazing the deviation |z| ~ 3e-3 is far below the map's absolute rounding
    floor relative to 1e-14 (the phase is a float, ~1e-15 absolute): Newton must stop
    at that floor rather than raise (this failed before commit 39e12ff)."""
    p, gains = _case(-5e-6, True)
    orb = orbit_11(p, gains)
    for factor in (1.0, 1 + 1e-3, 1 - 1e-2):
        guess = np.array(orb.pi2_deviation) * factor
        newton = shoot(p, deviation=guess, gains=gains)
        assert np.allclose(newton.pi2_deviation, orb.pi2_deviation, rtol=0, atol=1e-12)


@pytest.mark.parametrize("delta_d,controlled", [(-0.05, False), (-5e-6, True), (-5e-6, False)])
def test_orbit_11_is_the_fixed_point_of_the_mpmath_reference(delta_d, controlled):
    """The 50-digit Newton fixed point of the reference Pi2 map equals orbit_11.pi2
    to 1e-12 (physical coordinates)."""
    p, gains = _case(delta_d, controlled)
    orb = orbit_11(p, gains)
    ref = RefModel.from_params(p)
    g = None if gains is None else (gains.c1, gains.c2)
    x, v = ref.fixed_point(*orb.pi2, periods=1, gains=g)
    assert abs(float(x - mpf(orb.pi2[0]))) < 1e-12
    assert abs(float(v - mpf(orb.pi2[1]))) < 1e-12
    (_, _), counts = ref.pi2_map(x, v, 1, g)
    assert counts == [1]


@pytest.mark.parametrize("delta_d,controlled", ORBIT_CASES)
def test_multipliers_vs_finite_differences(delta_d, controlled):
    p, gains = _case(delta_d, controlled)
    orb = orbit_11(p, gains)
    jac = _fd_jacobian(p, np.array(orb.pi2_deviation), 1, gains, _fd_step(orb))
    lam_fd = np.linalg.eigvals(jac)
    lam_fd = lam_fd[np.argsort(-np.abs(lam_fd))]
    lam = orb.multipliers
    scale = np.max(np.abs(lam))
    assert np.allclose(lam, lam_fd, rtol=0, atol=1e-6 * scale), (lam, lam_fd)
    # det is exact: e^{-2 zeta T} r^2 (1 + c2)
    assert np.prod(lam).real == pytest.approx(
        monodromy_det(p, gains, 1, 1), rel=1e-9, abs=1e-300)
    assert orb.stable == bool(np.max(np.abs(lam_fd)) < 1)


def test_stability_of_the_study_branches():
    """Uncontrolled near grazing the 1/1 orbit is unstable (multiplier ~ 1/v- grows);
    with the degenerate design it is stable with bounded multipliers (spec 5, 6)."""
    largest = []
    for dd in (-1e-5, -1e-6, -1e-7):
        p = STUDY.with_(delta_d=dd)
        free = orbit_11(p)
        ctl = orbit_11(p, _design(p))
        assert not free.stable and ctl.stable
        largest.append(abs(free.multipliers[0]))
        assert abs(ctl.multipliers[0]) < 0.5
    assert largest[0] < largest[1] < largest[2]


def test_multipliers_function_is_cancellation_free():
    """A monodromy with a huge multiplier keeps the small one accurate (vs mpmath)."""
    mp.dps = 50
    m = np.array([[1e9, 3.0], [-7e8, -2.0]])
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    lam = multipliers(m, det)
    mm = mp.matrix([[mpf(m[0, 0]), mpf(m[0, 1])], [mpf(m[1, 0]), mpf(m[1, 1])]])
    ev = sorted(mp.eig(mm)[0], key=lambda z: -abs(z))
    for a, b in zip(lam, ev):
        assert abs(complex(a) - complex(b)) <= 1e-14 * abs(complex(b))
    rot = multipliers(np.array([[0.0, -1.0], [1.0, 0.0]]))
    assert np.allclose(sorted(rot, key=lambda z: z.imag), [-1j, 1j])


def test_wall_offset_at_phase_solves_the_periodicity_system():
    """(Delta d, v-) from wall_offset_at_phase at impact phase tau* + psi reproduces a 1/1 orbit
    whose impact happens at that phase with that velocity."""
    for psi in (0.01, 0.05, 0.2):
        dd, v, _ = wall_offset_at_phase(STUDY, psi)
        if v <= 0:
            continue
        orb = orbit_11(STUDY.with_(delta_d=dd))
        assert orb.v_minus == pytest.approx(v, rel=1e-9)
        assert orb.impact_phase == pytest.approx((STUDY.lag + psi) % (2 * math.pi), abs=1e-12)


def test_orbit_11_not_found_on_the_non_impacting_side():
    with pytest.raises(OrbitNotFound):
        orbit_11(STUDY.with_(delta_d=0.01))


# ------------------------------------------------------------ 2/2 and 1/2
def _attractor(p, periods=600):
    res = simulate(p, periods)
    return res.pi2_deviation[-1]


def _check_periodic_orbit(p, orb, periods, impacts_per_cycle):
    """Simulate from the orbit: it repeats with the given period and impact count, and
    is not of a smaller period."""
    assert orb.label == f"{impacts_per_cycle}/{periods}"
    res = simulate(p, 8 * periods, deviation=orb.pi2_deviation)
    dev = res.pi2_deviation
    assert np.max(np.abs(dev[periods:] - dev[:-periods])) < 1e-10
    counts = res.impacts_per_period.reshape(-1, periods).sum(axis=1)
    assert np.all(counts == impacts_per_cycle)
    for smaller in range(1, periods):
        assert np.max(np.abs(dev[smaller:] - dev[:-smaller])) > 1e-6
    return res


def test_2_2_orbit_near_grazing():
    p = STUDY.with_(delta_d=-1e-5)
    guess = _attractor(p)
    orb = shoot(p, deviation=guess, periods=2)
    _check_periodic_orbit(p, orb, 2, 2)
    assert len(orb.impacts) == 2 and all(i.v_minus > 0 for i in orb.impacts)
    assert orb.stable  # it is the attractor
    jac = _fd_jacobian(p, np.array(orb.pi2_deviation), 2, None, _fd_step(orb))
    lam_fd = np.linalg.eigvals(jac)
    lam_fd = lam_fd[np.argsort(-np.abs(lam_fd))]
    assert np.allclose(orb.multipliers, lam_fd, rtol=0, atol=1e-6)
    assert np.allclose(orb.pi2_deviation, guess, rtol=0, atol=1e-8)
    # it is a period-doubled orbit, distinct from the (unstable) 1/1 orbit
    one = orbit_11(p)
    assert not one.stable
    assert np.max(np.abs(np.array(one.pi2_deviation) - orb.pi2_deviation)) > 1e-5


def test_2_2_orbit_with_default_tolerance():
    p = STUDY.with_(delta_d=-1e-5)
    guess = _attractor(p)
    orb = shoot(p, deviation=guess, periods=2)
    assert orb.label == "2/2"
    assert np.allclose(orb.pi2_deviation, guess, rtol=0, atol=1e-8)


def test_1_2_orbit():
    p = OscillatorParams(omega=3.2, delta_d=-0.01)
    guess = _attractor(p, 300)
    orb = shoot(p, deviation=guess, periods=2)
    res = _check_periodic_orbit(p, orb, 2, 1)
    assert sorted(res.impacts_per_period[:2]) == [0, 1]
    assert orb.stable
    jac = _fd_jacobian(p, np.array(orb.pi2_deviation), 2, None, _fd_step(orb))
    lam_fd = np.linalg.eigvals(jac)
    assert np.allclose(sorted(np.abs(orb.multipliers)), sorted(np.abs(lam_fd)), atol=1e-6)
    # the 50-digit reference: the orbit is a fixed point of P^2 with one impact
    ref = RefModel.from_params(p)
    (x, v), counts = ref.pi2_map(*orb.pi2, periods=2)
    assert sum(counts) == 1
    assert abs(float(x - mpf(orb.pi2[0]))) < 1e-12 and abs(float(v - mpf(orb.pi2[1]))) < 1e-12


def test_shoot_validates_its_arguments():
    with pytest.raises(ValueError, match="periods=0 is invalid"):
        shoot(STUDY.with_(delta_d=-0.05), 0.0, 0.0, periods=0)
    with pytest.raises(ValueError, match="give the guess"):
        shoot(STUDY.with_(delta_d=-0.05))


# ------------------------------------------------------- branch labels (issue 7)
def test_orbit_near_grazing_is_on_the_branch_born_at_grazing():
    o = orbit_11(OscillatorParams(delta_d=-5e-6))
    assert o.branch == "grazing" and 0 < o.v_minus < 1e-2


def test_far_orbit_past_a_fold_is_labelled_issue_7():
    """Issue 7: at zeta 0.2, r 0.3, omega 1.5, Delta d = -1e-3 `grazing orbit` returned
    a 1/1 orbit with v- = 1.31 without saying that it is far from grazing. The branch
    born at grazing goes to Delta d > 0 (v- -> 0 as Delta d -> 0+), turns at a fold near
    Delta d = 0.114 and comes back: the orbit is on it, past the fold."""
    p = OscillatorParams(zeta=0.2, r=0.3, omega=1.5, delta_d=-1e-3)
    o = orbit_11(p)
    assert o.branch == "grazing past a fold" and o.v_minus == pytest.approx(1.3095, abs=1e-4)
    # the fold, independently: Delta d(psi) on a fine grid from grazing to the orbit
    psi_orbit = (o.impact_phase - p.tau_star + math.pi) % (2 * math.pi) - math.pi
    psis = np.linspace(0.0, psi_orbit, 4001)[1:]
    dds = np.array([wall_offset_at_phase(p, s)[0] for s in psis])
    vs = np.array([wall_offset_at_phase(p, s)[1] for s in psis])
    assert np.all(vs > 0)  # one arc with v- > 0 from grazing to the orbit
    assert 0.1 < dds.max() < 0.13 and dds[0] > 0  # born towards Delta d > 0, turns
    (lo, hi, kind, fold), = branch_brackets(p, p.delta_d)
    assert kind == "grazing past a fold" and fold == pytest.approx(dds.max(), rel=0.05)
    # on the near side of the fold at Delta d = 0.01 both orbits exist; the near one first
    near = orbit_11(p.with_(delta_d=0.01))
    assert near.branch == "grazing" and near.v_minus < 0.05
    assert [b[2] for b in branch_brackets(p, 0.01)] == ["grazing", "grazing past a fold"]


def test_orbit_on_another_branch_is_found_and_labelled_issue_7():
    """A controlled case where no 1/1 orbit of the branch born at grazing has this
    Delta d (the old search said "no 1/1 orbit born at grazing") but a physical one
    exists on an arc separated from grazing by v- <= 0: returned, labelled 'other',
    and checked by the exact flow (one impact, back to the same Pi2 point)."""
    from grazing_control.dynamics.maps.maps import pi2_map

    p = OscillatorParams(zeta=0.006638694214357835, r=0.6869943793584391,
                         omega=1.069458758465759, delta_d=-0.0009979230443342096,
                         pi2_offset=6.178984565892156)
    g = Gains(-9.152301501092964, -0.4013223587735988)
    with pytest.raises(OrbitNotFound):
        find_branch_phase(p, p.delta_d, g)
    with pytest.raises(OrbitNotFound, match="born at grazing"):
        orbit_11(p, g, branch="grazing")
    o = orbit_11(p, g)
    assert o.branch == "other" and o.v_minus > 1.0
    seg = pi2_map(p, *o.pi2_deviation, g)
    assert len(seg.impacts) == 1
    assert abs(seg.dx - o.pi2_deviation[0]) < 1e-9 and abs(seg.dv - o.pi2_deviation[1]) < 1e-9
    with pytest.raises(ValueError, match="branch="):
        orbit_11(p, g, branch="far")


# ------------------------------------------------------- fold or rounding (issue 20, item 4)
@pytest.mark.parametrize("c2, delay", [(-0.5, 0.0), (0.0, 0.0), (0.1, 0.0), (-1.0, 0.5)])
def test_near_grazing_controlled_orbit_is_not_past_a_fold(c2, delay):
    """Issue 20: at Delta d = -1e-10 these orbits (5e-6 rad from grazing, v- ~ 3e-5) were
    labelled "grazing past a fold": the 'fold' was the rounding wobble of Delta d(psi)
    at |psi| ~ 1e-15. They are on the branch born at grazing, before any fold."""
    p = OscillatorParams(delta_d=-1e-10)
    g = Gains(degenerate_c1(p, c2, delay), c2, delay)
    o = orbit_11(p, g)
    assert o.branch == "grazing"
    assert abs(o.impact_phase - p.tau_star) < 2e-5 and 0.0 < o.v_minus < 1e-4


@pytest.mark.parametrize("c2, delay", [(-0.5, 0.0), (0.1, 0.0), (-1.0, 0.5), (-1.0, 0.0)])
def test_delta_d_rounding_bounds_the_wobble_and_is_not_vacuous(c2, delay):
    """Against Delta d = -gamma1 psi^2 (D9; the psi^3 term is below 1e-33 here): the error
    of wall_offset_at_phase's Delta d stays inside the bound for |psi| <= 6e-12 on both sides,
    and reaches at least a tenth of it (measured 0.55 ... 0.72 of the bound at most)."""
    from grazing_control.dynamics.design.gains import existence_coefficient
    from grazing_control.dynamics.orbits.orbits import _delta_d_rounding, _psi_grid

    p = OscillatorParams()
    g = Gains(degenerate_c1(p, c2, delay), c2, delay)
    gamma1 = existence_coefficient(p, g)
    ratios = []
    for m in _psi_grid()[:60]:
        for psi in (-m, m):
            err = abs(wall_offset_at_phase(p, psi, g)[0] + gamma1 * psi * psi)
            ratios.append(err / _delta_d_rounding(p, psi, g))
    assert 0.1 < max(ratios) <= 1.0


def test_the_branch_scan_is_the_same_at_every_delta_d():
    """orbits._branch_values scans the branch once per oscillator, gains and side, at Delta
    d = 0 (issue 30, the suite's CPU): the scan at each p's own Delta d, computed here
    point by point, gives the same floats (wall_offset_at_phase and the rounding bound do
    not read p.delta_d), without and with a delayed controller, on both sides."""
    from grazing_control.dynamics.orbits.orbits import (_branch_values, _delta_d_rounding,
                                                        _psi_grid)
    from test_compliant_flow_bits import _canonical

    P = OscillatorParams()
    for delta_d, gains in ((-1e-3, None), (2e-5, Gains(degenerate_c1(P, -1.0), -1.0)),
                           (-0.3, Gains(degenerate_c1(P, -0.5, 0.5), -0.5, 0.5))):
        p = P.with_(delta_d=delta_d)
        for sign in (-1.0, 1.0):
            direct = []
            for m in _psi_grid():
                point = wall_offset_at_phase(p, sign * m, gains)
                direct.append((sign * m, point[0], point[1],
                               _delta_d_rounding(p, sign * m, gains, point)))
            assert _canonical(_branch_values(p, gains, sign, rounding=True)) == \
                _canonical(direct)
            assert _canonical(_branch_values(p, gains, sign)) == \
                _canonical([row[:3] for row in direct])

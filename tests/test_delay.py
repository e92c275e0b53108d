"""Specification tests of the actuation delay (docs/theory_delay.md, issue 8 section 1).

A correction k^T z computed from the Pi2 sample z and applied delta later is, while no
impact falls inside the delay, a kick on Pi2 along b_delta = Phi(-delta) e2
(G_delta = I + b_delta k^T); the design with that kick (c1(c2; delta) from
N_g,12(delta) = 0) removes the singular multiplier of the delayed 1/1 orbit.

References that share no code with what they check:

* the exact trajectory of :func:`grazing_control.dynamics.simulation.simulate.period_step` with ``delay``
  and central finite differences of it (the Pi2 map's Jacobian);
* ``scipy.linalg.expm`` for Phi, and mpmath's ``expm`` at 50 digits for N_g,12(delta) = 0
  and for the 1/1 branch near grazing (lambda0, gamma1 by symmetric quotients at
  psi = 1e-12, where their O(psi^2) error is 1e-24);
* the perturbation route (:mod:`grazing_control.dynamics.maps.perturbation`, theory_zdm.md), which
  reaches lambda0 and gamma1 through the normal-form map, not the exact branch.
"""

import json
import math

import numpy as np
import pytest
from mpmath import mp, mpf
from scipy.linalg import expm

from grazing_control.cli import main
from grazing_control.oscillator.control import (Gains, gain_determinant, gain_matrix,
                                                kick_direction)
from grazing_control.dynamics.design.gains import (admissible_c2, degenerate_c1, evaluate_design,
                                             existence_coefficient, limit_multipliers,
                                             max_design_delay)
from grazing_control.oscillator.flow import transition_matrix
from grazing_control.dynamics.maps.maps import period_matrix, pi1_map, pi2_map
from grazing_control.dynamics.orbits.orbits import orbit_11, shoot
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.maps.perturbation import (existence_coefficient_perturbation,
                                                   limit_multipliers_perturbation)
from grazing_control.dynamics.simulation.simulate import period_step, simulate

P = OscillatorParams()
A = np.array([[0.0, 1.0], [-1.0, -2.0 * P.zeta]])
DELAYS = (0.3, 2.0, 4.5, 6.0)
#: delayed designs with an admissible c2 (docs/theory_delay.md, section 5 table)
DESIGNS = ((0.5, -1.0), (2.0, 0.5), (4.5, -1.0))


def _phi(t, zeta=P.zeta):
    return expm(np.array([[0.0, 1.0], [-1.0, -2.0 * zeta]]) * t)


def _step_map(p, gains, delay):
    """z -> the exact next sample with the correction k^T z applied ``delay`` after it."""
    def f(dx, dv):
        return period_step(p, dx, dv, gains.c1 * dx + gains.c2 * dv, delay=delay)
    return f


def _fd(mapping, z, h):
    """Fourth-order central differences of z -> mapping(z) (a Segment); same impact count."""
    jac = np.zeros((2, 2))
    base = len(mapping(*z).impacts)
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        vals = []
        for k in (2, 1, -1, -2):
            seg = mapping(*(z + k * e))
            assert len(seg.impacts) == base
            vals.append(np.array([seg.dx, seg.dv]))
        jac[:, j] = (-vals[0] + 8 * vals[1] - 8 * vals[2] + vals[3]) / (12 * h)
    return jac


# ------------------------------------------------------------------ section 1: the kick on Pi2
def test_kick_direction_is_the_flow_backwards_from_the_kick():
    assert kick_direction(P.zeta, 0.0) == (0.0, 1.0)
    for d in DELAYS:
        b = np.array(kick_direction(P.zeta, d))
        np.testing.assert_allclose(b, _phi(-d)[:, 1], rtol=1e-13)
        # flowing b for delta gives e2: the kick at delta is the kick b at the sample
        np.testing.assert_allclose(_phi(d) @ b, [0.0, 1.0], atol=1e-14)


@pytest.mark.parametrize("delay", DELAYS)
def test_delayed_correction_equals_a_kick_on_pi2_along_b(delay):
    """Far from the wall (Delta d = 1, no impact) the exact delayed period is
    Phi(T) (I + b_delta k^T) z for random z and gains, to rounding."""
    p = P.with_(delta_d=1.0)
    rng = np.random.default_rng(8)
    for _ in range(50):
        z = rng.uniform(-0.1, 0.1, 2)
        k = rng.uniform(-2.0, 2.0, 2)
        seg = period_step(p, z[0], z[1], k @ z, delay=delay)
        assert seg.impacts == []
        b = _phi(-delay)[:, 1]
        want = _phi(p.period) @ (z + b * (k @ z))
        np.testing.assert_allclose([seg.dx, seg.dv], want, rtol=1e-12, atol=1e-15)
        g = np.array(gain_matrix(Gains(k[0], k[1], delay), p.zeta)).reshape(2, 2)
        np.testing.assert_allclose(g, np.eye(2) + np.outer(b, k), rtol=1e-13, atol=1e-14)
        assert gain_determinant(Gains(k[0], k[1], delay), p.zeta) == pytest.approx(
            np.linalg.det(g), rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("delay", DELAYS)
def test_delayed_pi2_map_is_period_step_and_its_monodromy_the_finite_differences(delay):
    """pi2_map with delayed gains follows period_step(delay) bit for bit, and its
    monodromy M2 (M1 + e2 k^T) matches finite differences, with impacts too."""
    p = P.with_(delta_d=-5e-3)
    g = Gains(0.4, -0.7, delay)
    rng = np.random.default_rng(3)
    seen_impact = False
    for _ in range(12):
        z = rng.uniform(-0.05, 0.05, 2)
        seg = pi2_map(p, z[0], z[1], g, monodromy=True)
        ref = _step_map(p, g, delay)(*z)
        assert (seg.dx, seg.dv) == (ref.dx, ref.dv)
        assert [i.dt for i in seg.impacts] == [i.dt for i in ref.impacts]
        seen_impact |= bool(seg.impacts)
        if seg.impacts and min(i.v_minus for i in seg.impacts) < 1e-3:
            continue  # too near a grazing of the map for a difference quotient
        jac = _fd(_step_map(p, g, delay), z, 1e-6)
        np.testing.assert_allclose(np.array(seg.monodromy).reshape(2, 2), jac, rtol=2e-7, atol=2e-7)
    assert seen_impact


def test_with_an_impact_inside_the_delay_the_kick_on_pi2_no_longer_holds():
    """Where the stop of docs/theory_delay.md section 1 bites: the impact falls between the
    sample and the kick. The exact delayed map (and its M2 (M1 + e2 k^T) monodromy) still
    hold; the kick on Pi2 along b_delta gives another state and another Jacobian."""
    p = P.with_(delta_d=-1e-2)
    g = Gains(0.4, -0.7, 8.0)  # delta = 8 > T - s: past the grazing phase
    z = np.array([0.0, 0.0])  # on the grazing orbit: impacts at ~T - s = 7.06
    seg = pi2_map(p, *z, g, monodromy=True)
    assert seg.impacts and seg.impacts[0].dt < g.delay
    jac = _fd(_step_map(p, g, g.delay), z + 1e-3, 1e-6)
    seg = pi2_map(p, *(z + 1e-3), g, monodromy=True)
    np.testing.assert_allclose(np.array(seg.monodromy).reshape(2, 2), jac, rtol=1e-6, atol=1e-6)
    # the equivalent-kick picture: kick b_delta k^T z at the sample, then the full period
    zz = z + 1e-3
    b = np.array(kick_direction(p.zeta, g.delay))
    kicked = zz + b * (g.c1 * zz[0] + g.c2 * zz[1])
    other = period_step(p, kicked[0], kicked[1])
    assert abs(other.dx - seg.dx) + abs(other.dv - seg.dv) > 1e-3


@pytest.mark.parametrize("delay", [-1.0, -1e308, 1e308, math.nan, math.inf, -math.inf,
                                   "T - s", 100.0])
def test_every_design_entry_refuses_a_delay_out_of_range_by_name(delay):
    """The design's entry points (c1, the condition values, their breakpoints, the
    admissible sets) refuse a delay outside 0 <= delay < T - s with ParameterError
    naming it, huge and infinite ones included (they overflowed a transition matrix)."""
    from grazing_control.dynamics.design.gains import breakpoints, condition_values

    delay = max_design_delay(P) if delay == "T - s" else delay
    for entry in (lambda: degenerate_c1(P, -1.0, delay),
                  lambda: condition_values(P, -1.0, delay),
                  lambda: breakpoints(P, delay),
                  lambda: admissible_c2(P, n=5, delay=delay)):
        with pytest.raises(ParameterError, match=r"delay=.* is invalid: valid range is 0 <= delay"):
            entry()


def test_the_delay_must_end_before_the_next_sample_and_be_valid():
    with pytest.raises(ValueError, match="delay"):
        period_step(P, 0.0, 0.0, 0.1, delay=P.period)
    with pytest.raises(ParameterError, match="delay"):
        Gains(1.0, 1.0, -1e-3)
    for bad in (math.nan, math.inf, "x"):
        with pytest.raises(ParameterError, match="delay"):
            Gains(1.0, 1.0, bad)
    with pytest.raises(ValueError, match="zeta"):
        gain_matrix(Gains(1.0, 1.0, 0.5))
    with pytest.raises(ValueError, match="delay"):  # the kick after the Pi1 return
        pi1_map(P, 0.0, 0.0, Gains(0.1, 0.1, max_design_delay(P) + 0.1))
    with pytest.raises(ParameterError, match="delay"):
        degenerate_c1(P, -1.0, max_design_delay(P))
    # where Phi12(T - s - delta) = 0 no c1 zeroes N_g,12: c1 grows without bound there
    singular = max_design_delay(P) - math.pi / P.omega_d
    assert 0.0 < singular < max_design_delay(P)
    assert abs(degenerate_c1(P, -1.0, singular)) > 1e12
    assert abs(degenerate_c1(P, -1.0, singular + 1e-6)) > 1e3


def test_zero_delay_is_todays_controller_bit_for_bit():
    """delay = 0 builds G, N_g, c1 and the Pi2 map with today's operations: equal, not close."""
    s = P.pi2_offset / P.omega
    q11, q12, _q21, _q22 = transition_matrix(P.zeta, P.period - s)
    p11, p12, _p21, p22 = transition_matrix(P.zeta, s)
    for c2 in (-2.0, -1.0, 0.1):
        c1 = degenerate_c1(P, c2, 0.0)
        assert c1 == degenerate_c1(P, c2) == -(q11 * p12 + q12 * (1.0 + c2) * p22) / (q12 * p12)
        g0, g = Gains(c1, c2), Gains(c1, c2, 0.0)
        assert gain_matrix(g) == (1.0, 0.0, c1, 1.0 + c2)
        assert period_matrix(P, g) == period_matrix(P, g0)
        a, b = evaluate_design(P, c2, 0.0), evaluate_design(P, c2)
        assert a.c1 == b.c1 and a.gamma1 == b.gamma1
        assert np.array_equal(a.multipliers_limit, b.multipliers_limit)
        z = (1e-3, -2e-3)
        seg = pi2_map(P.with_(delta_d=-1e-3), *z, g)
        ref = period_step(P.with_(delta_d=-1e-3), z[0], z[1], c1 * z[0] + c2 * z[1])
        assert (seg.dx, seg.dv) == (ref.dx, ref.dv)


def test_cli_design_delay_zero_equals_the_undelayed_design(capsys):
    outs = []
    for extra in ([], ["--delay", "0"]):
        assert main(["design", "--c2", "-1", "--json", *extra]) == 0
        d = json.loads(capsys.readouterr().out)
        d.pop("seconds")
        outs.append(d)
    assert outs[0] == outs[1]
    assert outs[0]["actuation_delay"] == 0.0


# ------------------------------------------------------------------ section 2: design with delay
def _mp_phi(zeta, t):
    return mp.expm(mp.matrix([[0, 1], [-1, -2 * zeta]]) * t)


def _mp_system(p, delay):
    """(zeta, r, omega, a, T, s, phi(t)) at 50 digits from the float parameters."""
    zeta, w = mpf(p.zeta), mpf(p.omega)
    return zeta, mpf(p.r), w, 1 / mp.sqrt((1 - w * w) ** 2 + (2 * zeta * w) ** 2), \
        2 * mp.pi / w, mpf(p.pi2_offset) / w, mpf(delay)


def _mp_m(p, c1, c2, delay, sigma):
    """Phi(T - sigma) (I + b k^T) Phi(sigma), b = Phi(-delay) e2, at 50 digits."""
    zeta, _r, _w, _a, period, _s, dl = _mp_system(p, delay)
    b = _mp_phi(zeta, -dl)[:, 1]
    g = mp.eye(2) + b * mp.matrix([[c1, c2]])
    return _mp_phi(zeta, period - sigma) * g * _mp_phi(zeta, sigma)


def _mp_c1(p, c2, delay):
    """c1 with N_g,12(delay) = 0 at 50 digits (N_g,12 is affine in c1)."""
    with mp.workdps(50):
        s = mpf(p.pi2_offset) / mpf(p.omega)
        n0 = _mp_m(p, 0, mpf(c2), delay, s)[0, 1]
        n1 = _mp_m(p, 1, mpf(c2), delay, s)[0, 1]
        return -n0 / (n1 - n0)


@pytest.mark.parametrize("delay", (0.0, 0.3, 2.0, 4.5, 6.0, 7.0))
@pytest.mark.parametrize("c2", (-2.0, -1.0, 0.5))
def test_degenerate_c1_with_delay_against_mpmath(delay, c2):
    c1 = degenerate_c1(P, c2, delay)
    ref = _mp_c1(P, c2, delay)
    assert abs(c1 - float(ref)) <= 1e-13 * max(1.0, abs(c1))
    # and N_g,12 vanishes in double precision too
    n = period_matrix(P, Gains(c1, c2, delay))
    assert abs(n[1]) <= 1e-15 * max(map(abs, n))


def _mp_branch(p, c1, c2, delay, psi):
    """(Delta d, v-, tr J) on the delayed 1/1 branch at impact phase tau* + psi, 50 digits
    (docs/theory.md section 5 written again: periodicity M (u - r v e2) = u + v e2)."""
    zeta, r, w, a, _period, s, _dl = _mp_system(p, delay)
    m = _mp_m(p, c1, c2, delay, s - psi / w)
    bm = m - mp.eye(2)
    u0 = mp.matrix([2 * a * mp.sin(psi / 2) ** 2, a * w * mp.sin(psi)])
    wv = mp.matrix([r * m[0, 1], 1 + r * m[1, 1]])
    lhs = mp.matrix([[bm[0, 0], -wv[0]], [bm[1, 0], -wv[1]]])
    dd, v = mp.lu_solve(lhs, -(bm * u0))
    lag = mp.atan2(2 * zeta * w, 1 - w * w)
    s21 = (1 + r) * (mp.cos(lag + psi) - (a + dd)) / v
    tr = -r * (m[0, 0] + m[1, 1]) + m[0, 1] * s21
    return dd, v, tr


@pytest.mark.parametrize("delay, c2", ((0.0, -2.0), (0.0, -0.5), (0.0, 0.2), *DESIGNS, (6.0, -1.2)))
def test_limit_multipliers_and_gamma1_against_a_50_digit_branch(delay, c2):
    """The closed forms of lambda0 and gamma1 (issue 7: the old difference quotients were
    off by up to 1.2e-9 and 2.6e-8) against symmetric quotients of the exact branch at
    50 digits, psi = 1e-12: agreement to 1e-12."""
    g = Gains(degenerate_c1(P, c2, delay), c2, delay)
    with mp.workdps(50):
        c1 = _mp_c1(P, c2, delay)
        psi = mpf("1e-12")
        ddp, vp, trp = _mp_branch(P, c1, mpf(c2), delay, psi)
        ddm, vm, trm = _mp_branch(P, c1, mpf(c2), delay, -psi)
        gamma1 = -(ddp + ddm) / (2 * psi * psi)
        tr0 = (trp + trm) / 2
    assert existence_coefficient(P, g) == pytest.approx(float(gamma1), rel=1e-12)
    lam = np.sort_complex(limit_multipliers(P, g))
    det0 = lam[0] * lam[1]
    assert (lam[0] + lam[1]).real == pytest.approx(float(tr0), rel=1e-12, abs=1e-14)
    assert det0.real == pytest.approx(
        P.r ** 2 * math.exp(-2 * P.zeta * P.period) * gain_determinant(g, P.zeta), rel=1e-13)


@pytest.mark.parametrize("delay, c2", ((0.0, -1.0), (0.0, 0.2), *DESIGNS, (6.0, -1.2)))
def test_closed_forms_equal_the_perturbation_route(delay, c2):
    """Two derivations, one from the exact branch, one from the normal-form map: 1e-13."""
    g = Gains(degenerate_c1(P, c2, delay), c2, delay)
    assert existence_coefficient(P, g) == pytest.approx(
        existence_coefficient_perturbation(P, g), rel=1e-13)
    np.testing.assert_allclose(np.sort_complex(limit_multipliers(P, g)),
                               np.sort_complex(limit_multipliers_perturbation(P, g)),
                               rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("delay, c2", DESIGNS)
def test_delayed_design_bounds_the_multipliers_and_the_undelayed_one_does_not(delay, c2):
    """With c1(c2; delta) the delayed 1/1 orbit's multipliers tend to lambda0(delta); with
    today's c1(c2; 0) acting at delta the largest grows like 1/|Delta d|."""
    g = evaluate_design(P, c2, delay).gains()
    g0 = Gains(degenerate_c1(P, c2), c2, delay)
    lam0 = np.sort_complex(limit_multipliers(P, g))
    errs, large = [], []
    for dd in (-1e-6, -1e-8, -1e-10):
        q = P.with_(delta_d=dd)
        o = orbit_11(q, g)
        assert o.label == "1/1" and o.v_minus > 0.0
        errs.append(np.max(np.abs(np.sort_complex(o.multipliers) - lam0)))
        large.append(abs(orbit_11(q, g0).multipliers[0]))
    assert errs[-1] < 1e-4 and errs[-1] <= errs[0]
    assert np.max(np.abs(lam0)) < 1.0
    # 1/|Delta d|: two decades of Delta d, two decades of multiplier (ratios ~100)
    for a, b in zip(large[:-1], large[1:]):
        assert 50.0 < b / a < 200.0, large


@pytest.mark.parametrize("delay, c2", DESIGNS)
def test_delayed_orbit_multipliers_against_finite_differences_of_period_step(delay, c2):
    """The orbit's monodromy (M(theta) S with G_delta) has the eigenvalues of the finite-
    difference Jacobian of the exact delayed Pi2 map built from period_step(delay);
    Newton shooting on that map finds the same orbit."""
    g = evaluate_design(P, c2, delay).gains()
    q = P.with_(delta_d=-1e-6)
    o = orbit_11(q, g)
    z = np.array(o.pi2_deviation)
    seg = _step_map(q, g, delay)(*z)
    assert len(seg.impacts) == 1
    assert max(abs(seg.dx - z[0]), abs(seg.dv - z[1])) < 1e-13
    jac = _fd(_step_map(q, g, delay), z, 1e-7)
    lam_fd = np.sort_complex(np.linalg.eigvals(jac))
    np.testing.assert_allclose(lam_fd, np.sort_complex(o.multipliers), atol=1e-6)
    s = shoot(q, gains=g, deviation=z * (1 + 1e-6), tol=1e-8)
    np.testing.assert_allclose(s.pi2_deviation, z, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(np.sort_complex(s.multipliers), np.sort_complex(o.multipliers),
                               atol=1e-8)


def test_delayed_design_suppresses_the_chaos_in_the_core():
    """Study scene at Delta d = -5e-6 with the delayed design (delta = 2, c2 = 0.5): the
    samples settle on the delayed 1/1 orbit; today's gains at the same delay do not."""
    q = P.with_(delta_d=-5e-6)
    g = evaluate_design(P, 0.5, 2.0).gains()
    o = orbit_11(q, g)
    res = simulate(q, 1400, gains=g, control_after=1000)
    assert np.max(np.abs(res.pi2_deviation[-50:] - o.pi2_deviation)) < 1e-10
    bad = Gains(degenerate_c1(P, 0.5), 0.5, 2.0)
    res = simulate(q, 1400, gains=bad, control_after=1000)
    assert np.max(np.abs(res.pi2_deviation[-50:] - o.pi2_deviation)) > 1e-4


def test_admissible_sets_for_a_delay_and_the_yaml(tmp_path, capsys):
    sets = {c: admissible_c2(P, delay=2.0, conditions=c)
            for c in ("combined", "impacting", "non-impacting")}
    (lo, hi), = sets["combined"]
    assert lo < 0.5 < hi
    # the combined set is the intersection of the other two
    (a, b), = sets["impacting"]
    (c, d), = sets["non-impacting"]
    assert (lo, hi) == pytest.approx((max(a, c), min(b, d)), abs=1e-12)
    for c2, ok in ((lo + 1e-6, True), (hi - 1e-6, True), (lo - 1e-6, False), (hi + 1e-6, False)):
        assert evaluate_design(P, c2, 2.0).admissible is ok
    out = tmp_path / "c.yaml"
    assert main(["design", "--c2", "0.5", "--delay", "2", "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    import yaml
    params = yaml.safe_load(out.read_text())["/**"]["ros__parameters"]
    assert params["actuation_delay"] == 2.0 == d["actuation_delay"]
    assert params["c1"] == degenerate_c1(P, 0.5, 2.0) == d["c1"]
    assert d["admissible"] is True and d["admissible_c2"] == pytest.approx([lo, hi], abs=1e-12)


def test_cli_delay_errors_are_one_line(capsys):
    for argv in (["design", "--c2", "-1", "--delay", "7.5"],
                 ["design", "--c2", "-1", "--delay", "-1"],
                 ["orbit", "--delta-d", "-1e-6", "--delay", "1"],
                 ["design", "--c2", "-1", "--delay", "nan"]):
        try:
            status = main(argv)
        except SystemExit as exc:
            status = exc.code
        err = capsys.readouterr().err
        assert status == 2, argv
        assert err.startswith("grazing: error:") and err.count("\n") == 1 and "delay" in err


def test_simulate_models_the_delay_only_with_the_exact_flow():
    q = P.with_(delta_d=-5e-6)
    g = evaluate_design(P, 0.5, 2.0).gains()
    auto = simulate(q, 20, gains=g, control_after=5, fidelity="auto")
    exact = simulate(q, 20, gains=g, control_after=5)
    assert auto.fidelity == "exact" and "delay" in auto.fidelity_reason
    assert np.array_equal(auto.pi2_deviation, exact.pi2_deviation)
    # before control_after the samples are the uncontrolled run's, bit for bit
    assert np.array_equal(exact.pi2_deviation[:6], simulate(q, 6).pi2_deviation)
    for fidelity in ("zdm2", "zdm1", "ode"):
        with pytest.raises(ValueError, match="actuation delay"):
            simulate(q, 3, gains=g, fidelity=fidelity)


def test_orbit_with_its_impact_inside_the_delay_window_by_newton_shooting():
    """delta = 8 > T - s: the kick acts after the impact. Newton shooting on the exact
    delayed Pi2 map still finds the 1/1 orbit; its multipliers (det from the matrix, not
    the product formula, which no longer holds) match finite differences of period_step."""
    q = P.with_(delta_d=-1e-1)
    g = Gains(0.05, -0.1, 8.0)
    guess = simulate(q, 300, gains=g).final_deviation  # the run settles on it
    o = shoot(q, gains=g, deviation=guess)
    assert o.label == "1/1" and o.impacts[0].dt < g.delay
    z = np.array(o.pi2_deviation)
    jac = _fd(_step_map(q, g, g.delay), z, 1e-6)
    np.testing.assert_allclose(np.sort_complex(o.multipliers), np.sort_complex(np.linalg.eigvals(jac)),
                               atol=1e-6)
    det_formula = math.exp(-2 * q.zeta * q.period) * q.r ** 2 * gain_determinant(g, q.zeta)
    assert abs(np.linalg.det(jac) - det_formula) > 1e-3

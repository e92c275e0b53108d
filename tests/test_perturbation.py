"""Perturbation route for the near-grazing 1/1 motion against the exact shooting route.

Exact: grazing_control.dynamics.orbits.orbits (impact-phase shooting), continuation.continue_11
(period-doubling point), design.limit_multipliers / existence_coefficient /
admissible_c2. Perturbation: grazing_control.dynamics.maps.perturbation (docs/theory_zdm.md,
sections 5-9). Bounds asserted here were measured (study parameters) and are
quoted in the docstrings.
"""

import math

import numpy as np
import pytest

from grazing_control.dynamics.orbits.continuation import continue_11
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import (admissible_c2, degenerate_c1,
                                             existence_coefficient, limit_multipliers)
from grazing_control.oscillator.flow import transition_matrix
from grazing_control.dynamics.orbits.orbits import wall_offset_at_phase, multipliers, orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.perturbation import (admissible_c2_perturbation,
                                                   characteristic_roots, delta2_from_delta_d,
                                                   existence_coefficient_perturbation,
                                                   fixed_point_series,
                                                   limit_multipliers_perturbation,
                                                   normal_form_fixed_point,
                                                   perturbation_multipliers,
                                                   period_doubling_perturbation,
                                                   series_coefficients)

P = OscillatorParams()
C2_DEGENERATE = -1.0
GC = Gains(degenerate_c1(P, C2_DEGENERATE), C2_DEGENERATE)
DELTA_D = -np.logspace(-4, -9, 11)
#: Exact period-doubling point of the uncontrolled branch (continuation.continue_11).
PD_EXACT = -1.005268252976113e-05


def slope(x, y):
    return float(np.polyfit(np.log10(np.abs(x)), np.log10(y), 1)[0])


def rel_errors(gains, truncation, which=0):
    out = []
    for dd in DELTA_D:
        q = P.with_(delta_d=float(dd))
        ex = orbit_11(q, gains).multipliers
        est = perturbation_multipliers(q, gains, truncation)
        out.append(abs(est[which] - ex[which]) / abs(ex[which]))
    return np.array(out)


def exact_fixed_point(p, psi, gains):
    """(delta2 = v-, Delta d, z on Pi1, t1) of the exact branch at impact phase tau* + psi."""
    dd, v, _m = wall_offset_at_phase(p, psi, gains)
    t1 = psi / p.omega
    a, w = p.amplitude, p.omega
    zc = (dd + 2.0 * a * math.sin(0.5 * psi) ** 2, v + a * w * math.sin(psi))
    f = transition_matrix(p.zeta, -t1)
    return v, dd, (f[0] * zc[0] + f[1] * zc[1], f[2] * zc[0] + f[3] * zc[1]), t1


@pytest.mark.parametrize("c2", [None, -1.0, 0.0])
def test_fixed_point_series_matches_exact_branch(c2):
    """Delta d, z and t1 from the series at the exact delta2: error O(delta2^3)."""
    gains = None if c2 is None else Gains(degenerate_c1(P, c2), c2)
    c = series_coefficients(P, gains)
    d2s, errs = [], []
    for mag in (1e-3, 3e-4, 1e-4, 3e-5):
        psi = math.copysign(mag, c.tau1)  # the physical side: t1 has the sign of tau1
        v, dd, z, t1 = exact_fixed_point(P, psi, gains)
        assert v > 0.0
        dds, zx, zv, t1s = fixed_point_series(c, v)
        d2s.append(v)
        errs.append(max(abs(dds - dd), abs(zx - z[0]), abs(zv - z[1]), abs(t1s - t1) * v))
    errs = np.array(errs)
    # third order, or already at the rounding floor (uncontrolled: kappa3 ~ 0)
    assert np.all(errs < 5.0 * np.array(d2s) ** 3)
    if c2 is not None:
        assert abs(slope(d2s, errs) - 3.0) < 0.15


@pytest.mark.parametrize("c2", [-2.0, -1.5, -1.0, -0.5, 0.0, 0.28])
def test_degenerate_limit_and_existence_agree_with_exact_design(c2):
    """lambda0 (Eq. 23) and gamma1 (Eq. 36) by both routes: the exact route's closed forms
    (docs/theory_delay.md section 4) and the series agree to 1e-13 (the former difference
    quotients: 2e-9 and 1.6e-6)."""
    g = Gains(degenerate_c1(P, c2), c2)
    c = series_coefficients(P, g)
    assert c.degenerate and c.chi_m1 == pytest.approx(0.0, abs=1e-15)
    ex, pe = limit_multipliers(P, g), limit_multipliers_perturbation(P, g)
    assert np.max(np.abs(np.sort_complex(ex) - np.sort_complex(pe))) < 1e-13
    gamma1 = existence_coefficient(P, g)
    assert existence_coefficient_perturbation(P, g) == pytest.approx(gamma1, rel=1e-13)


def test_uncontrolled_eigenvalues_converge_to_shooting():
    """Non-degenerate truncation (Eq. 26, 'limit') and with chi1 ('practical'), against
    orbit_11 over Delta d in [-1e-4, -1e-9]. The relative error of the large multiplier
    is O(delta2^2) = O(|Delta d|^2) for Eq. 26 and O(|Delta d|^3) with chi1, until the
    rounding floor (~3e-16). Measured, Eq. 26: 3.7e-6 at -1e-4, 1.6e-9 at -1e-6,
    1.1e-15 at -1e-9 (slope 2.00 past the PD point); with chi1: 3.1e-7 at -1e-4,
    2.3e-12 at -1e-6, floor from -3e-8 (slope 3.1)."""
    lim = rel_errors(None, "limit")
    pra = rel_errors(None, "practical")
    assert lim[0] < 5e-6 and pra[0] < 5e-7 and lim[-1] < 5e-15 and pra[-1] < 1e-15
    # improves as Delta d -> 0 (strictly, while above the rounding floor)
    for errs in (lim, pra):
        above = errs[errs > 1e-14]
        assert np.all(np.diff(above) < 0.0)
    past_pd = np.abs(DELTA_D) <= 4e-6  # the PD point (-1.005e-5) is where |lambda1| ~ 1
    assert abs(slope(DELTA_D[past_pd], lim[past_pd]) - 2.0) < 0.15
    sel = past_pd & (pra > 1e-14)
    assert abs(slope(DELTA_D[sel], pra[sel]) - 3.0) < 0.3
    assert np.all(pra[pra > 1e-14] < lim[pra > 1e-14])


def test_controlled_degenerate_eigenvalues_converge_to_shooting():
    """c2 = -1, c1 degenerate: lambda0 (Eq. 23) has error O(delta2) = O(|Delta d|^0.5),
    the practical truncation (Eq. 25) O(delta2^2) = O(|Delta d|). Measured: lambda0
    1.5e-2 at -1e-4 to 4.7e-5 at -1e-9 (slope 0.50); practical 4.9e-5 to 4.9e-10
    (slope 1.00)."""
    lim = rel_errors(GC, "limit")
    pra = rel_errors(GC, "practical")
    for errs, order in ((lim, 0.5), (pra, 1.0)):
        assert np.all(np.diff(errs) < 0.0)
        assert abs(slope(DELTA_D, errs) - order) < 0.15
    assert lim[0] < 2e-2 and pra[0] < 1e-4 and pra[-1] < 1e-9
    # the small multiplier is exactly 0 (det G = 0 for c2 = -1)
    assert abs(perturbation_multipliers(P.with_(delta_d=-1e-6), GC)[1]) < 1e-15


def test_period_doubling_point_both_routes():
    """Exact (continuation): -1.005268252976e-5. Perturbation, Eq. 26: -1.0052684062e-5
    (relative difference 1.5e-7); with chi1: -1.0052682509e-5 (2.0e-9)."""
    branch = continue_11(P, -1e-4, -1e-6, points=12)
    pd = [b for b in branch.bifurcations if b.type == "period-doubling"]
    assert len(pd) == 1
    exact = pd[0].delta_d
    assert exact == pytest.approx(PD_EXACT, rel=1e-12)
    dd_lim, d2 = period_doubling_perturbation(P, truncation="limit")
    dd_pra, _ = period_doubling_perturbation(P, truncation="practical")
    assert abs(dd_lim / exact - 1.0) < 3e-7
    assert abs(dd_pra / exact - 1.0) < 1e-8
    # at that point the truncated characteristic equation has a root at -1
    c = series_coefficients(P)
    lam = characteristic_roots(c, d2, "limit")
    assert np.min(np.abs(lam + 1.0)) < 1e-12


def test_leading_order_map_fails_in_the_degenerate_case():
    """The leading-order ZDM drops the O(delta^2) position correction, whose derivative
    is O(1): its chi0 and psi0 are wrong (theory_zdm.md, section 9). Its lambda0 is
    {N11, N22 (1 - (1 + r) p1)} (N lower triangular). For c2 = -1 the first row of N is
    zero, so this coincides with the exact lambda0 = 0.3206108 (difference 3e-11).
    Elsewhere it is wrong: c2 = -0.5: leading {-0.451844, 0.320611} vs exact
    0.388535 +- 0.201362i (|lambda|max 0.4518 vs 0.4376, a stable design appears less
    stable); c2 = 0: {-0.903689, 0.320611} vs 0.616765 +- 0.051120i. Admissible c2:
    leading (-2.106576, 0.106576) vs exact (-2.019044, 0.282092)."""
    expected = {
        -1.0: (np.array([0.3206108337, 0.0]), 1e-9),
        -0.5: (np.array([-0.4518442569, 0.3206108337]), 1e-9),
        0.0: (np.array([-0.9036885138, 0.3206108337]), 1e-9),
    }
    for c2, (lead_ref, tol) in expected.items():
        g = Gains(degenerate_c1(P, c2), c2)
        exact = limit_multipliers(P, g)
        lead = limit_multipliers_perturbation(P, g, zdm_order=1)
        assert np.allclose(np.sort(lead.real), np.sort(lead_ref), atol=tol)
        diff = np.max(np.abs(np.sort_complex(lead) - np.sort_complex(exact)))
        if c2 == -1.0:  # equal; the exact route's symmetric quotient is good to ~1e-10
            assert diff < 1e-9
        else:
            assert diff > 0.3
        # the formula is what the leading-order map itself does (Newton on N_g o D1)
        z, jac = normal_form_fixed_point(P.with_(delta_d=-1e-11), g, order=1)
        assert np.allclose(np.sort_complex(multipliers(jac)), np.sort_complex(lead), atol=1e-4)
    lead_set = admissible_c2_perturbation(P, zdm_order=1)
    assert len(lead_set) == 1
    assert lead_set[0][0] == pytest.approx(-2.106575977, abs=1e-6)
    assert lead_set[0][1] == pytest.approx(0.106575977, abs=1e-6)


def test_second_order_normal_form_map_eigenvalues_converge():
    """Newton on N_g o D2 directly: its multipliers approach the exact ones as O(delta2)
    (c2 = -0.5: relative error 4.2e-4, 4.3e-5, 4.3e-6 at Delta d = -1e-5, -1e-7, -1e-9)."""
    g = Gains(degenerate_c1(P, -0.5), -0.5)
    errs = []
    for dd in (-1e-5, -1e-7, -1e-9):
        q = P.with_(delta_d=dd)
        ex = orbit_11(q, g).multipliers
        _z, jac = normal_form_fixed_point(q, g, order=2)
        lam = np.sort_complex(multipliers(jac))
        errs.append(np.max(np.abs(lam - np.sort_complex(ex))) / np.max(np.abs(ex)))
    assert abs(slope([1e-5, 1e-7, 1e-9], errs) - 0.5) < 0.1 and errs[-1] < 1e-5


@pytest.mark.parametrize("conditions, expected", (
    ("impacting", (-2.019044088, 0.2820918413)),
    ("non-impacting", (-2.1065759767, 0.1065759767)),
    ("combined", (-2.019044088, 0.1065759767))))
def test_admissible_c2_both_routes(conditions, expected):
    """Exact (design.admissible_c2, closed forms) and perturbation agree to 1e-12 on every
    end point, for each set of conditions (the combined set is the default)."""
    ex = admissible_c2(P, conditions=conditions)
    pe = admissible_c2_perturbation(P, conditions=conditions)
    assert len(ex) == len(pe) == 1
    diff = np.abs(np.subtract(ex[0], pe[0]))
    assert np.all(diff < 1e-12), diff
    assert pe[0] == pytest.approx(expected, abs=1e-9)
    if conditions == "combined":
        assert admissible_c2(P) == ex and admissible_c2_perturbation(P) == pe


def test_delta2_from_delta_d():
    c = series_coefficients(P)
    for dd in (-1e-9, -1e-6, -1e-4):
        d2 = delta2_from_delta_d(c, dd)
        assert d2 > 0.0 and c.kappa1 * d2 + c.kappa2 * d2 ** 2 == pytest.approx(dd, rel=1e-12)
        assert d2 == pytest.approx(orbit_11(P.with_(delta_d=dd)).v_minus, rel=1e-6)
    # the uncontrolled 1/1 branch born at grazing lives on the impacting side
    assert math.isnan(delta2_from_delta_d(c, 1e-6))
    cg = series_coefficients(P, GC)
    assert cg.kappa1 == 0.0 or abs(cg.kappa1) < 1e-15
    assert delta2_from_delta_d(cg, -1e-8) == pytest.approx(math.sqrt(1e-8 / -cg.kappa2), rel=1e-6)
    assert math.isnan(perturbation_multipliers(P.with_(delta_d=1e-6))[0].real)
    with pytest.raises(ValueError):
        series_coefficients(P, zdm_order=3)

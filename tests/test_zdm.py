"""Zero-time discontinuity mapping at Pi1: closed forms, order of accuracy, normal-form maps.

The reference is the exact flow with impacts of the core (grazing_control.dynamics.maps.maps.pi1_map,
through zdm.exact_return for states whose trajectory has already hit the wall at
Pi1) and, for the ZDM alone, the exact ZDM evaluated in mpmath at 40 digits.
A model file of any n (docs/theory_ndof.md §10, the same entries) is checked against the
exact local map of the certified core (oscillator/ndof/impact.advance), the 1-DOF ZDM for
n = 1, finite differences, and the limit multipliers of the design through its fixed
points (the second half of this file).
Predicted orders (docs/theory_zdm.md, section 3): with H_max = eps and the state
scaled self-similarly (gap ~ eps, gap rate ~ sqrt(eps)), the error of the
leading-order ZDM is O(eps), of the second-order ZDM O(eps^1.5).
"""

import dataclasses
import math
from pathlib import Path

import mpmath as mp
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.maps import zdm as zd
from grazing_control.dynamics.orbits import modal_branch
from grazing_control.oscillator.ndof import NdofModel, load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import advance

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.flow import propagate
from grazing_control.dynamics.maps.maps import pi1_map
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.zdm import (crossing, exact_return, h_max, local_grazing,
                                          normal_form_jacobian, normal_form_map, zdm,
                                          zdm_exact, zdm_jacobian, zdm_leading, zdm_second)

P0 = OscillatorParams()
GAINS = {"uncontrolled": None, "controlled": Gains(degenerate_c1(P0, -1.0), -1.0)}
#: Position of the maximum of the gap relative to Pi1, in units of sqrt(eps):
#: 3 -> impact after Pi1 (physical state); 0 -> maximum on Pi1; -2 -> impact before.
SHAPES = (3.0, 0.0, -2.0)
PREDICTED = {1: 1.0, 2: 1.5}


def state_with_hmax(p, eps, c):
    """Deviation on Pi1 whose smooth trajectory has its gap maximum H_max = eps exactly,
    at local time t_m = c sqrt(eps): built at the maximum (gap eps, rate 0) with the
    core's deviation formulas and flowed back to Pi1 exactly."""
    tm = c * math.sqrt(eps)
    zx = eps + p.delta_d + 2.0 * p.amplitude * math.sin(0.5 * p.omega * tm) ** 2
    zv = p.amplitude * p.omega * math.sin(p.omega * tm)
    return propagate(p.zeta, zx, zv, -tm)


def slope(eps, err):
    return float(np.polyfit(np.log10(eps), np.log10(err), 1)[0])


def test_constructed_states_have_the_requested_hmax():
    for eps in (1e-4, 1e-8, 1e-12):
        for c in SHAPES:
            p = P0.with_(delta_d=0.1 * math.sqrt(eps))
            t_max, hm, t1, v = crossing(p, state_with_hmax(p, eps, c))
            assert hm == pytest.approx(eps, rel=1e-8)
            assert t_max == pytest.approx(c * math.sqrt(eps), rel=1e-6, abs=1e-9 * math.sqrt(eps))
            assert v > 0.0 and (t1 > 0.0) == (c == 3.0)


def test_exact_zdm_closed_form_matches_the_core_flow():
    """N_g o D_exact equals the exact Pi1 map (only the near-grazing impact in the period)."""
    for name, gains in GAINS.items():
        for eps in (1e-4, 1e-7, 1e-10):
            for c in SHAPES:
                p = P0.with_(delta_d=0.1 * math.sqrt(eps))
                z = state_with_hmax(p, eps, c)
                ref = exact_return(p, z, gains)
                assert len(ref.impacts) == 1
                got = normal_form_map(p, z, gains, "exact")
                scale = math.hypot(ref.dx, ref.dv)
                # the reference's phase is rounded to ulp(tau*) ~ 3.5e-18: absolute floor
                assert max(abs(got[0] - ref.dx), abs(got[1] - ref.dv)) < 1e-12 * scale + 1e-16, name


def test_exact_return_is_pi1_map_for_physical_states():
    p = P0.with_(delta_d=1e-4)
    z = state_with_hmax(p, 1e-8, 3.0)
    a, b = exact_return(p, z), pi1_map(p, *z)
    assert (a.dx, a.dv, len(a.impacts)) == (b.dx, b.dv, len(b.impacts))


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("name", list(GAINS))
def test_normal_form_map_order_against_pi1_map(order, name):
    """Error of N_g o D_k against the exact map falls like eps^{1, 1.5}.

    The wall sits at Delta d = 0.1 sqrt(eps) > 0 so that the returning trajectory stays
    clear of the wall at the end of the period (one impact per period, asserted), and
    all deviations are O(sqrt(eps)) so that the reference keeps full relative precision.
    eps goes down to 1e-12 for the leading order; for the second order to 1e-11, below
    which its error (~1e-18) is under the reference's rounding floor (~1e-17).
    """
    gains = GAINS[name]
    eps = 10.0 ** -np.arange(4, 13 if order == 1 else 12)
    for c in SHAPES:
        errs = []
        for e in eps:
            p = P0.with_(delta_d=0.1 * math.sqrt(e))
            z = state_with_hmax(p, e, c)
            ref = exact_return(p, z, gains)
            assert len(ref.impacts) == 1
            got = normal_form_map(p, z, gains, order)
            errs.append(max(abs(got[0] - ref.dx), abs(got[1] - ref.dv)))
        s = slope(eps, errs)
        assert abs(s - PREDICTED[order]) < 0.15, (c, s, errs)
        assert all(b < a for a, b in zip(errs, errs[1:])), errs


def _mp_exact_zdm(p, z):
    """Exact ZDM in 40-digit arithmetic (same formula as zdm_exact, independent code)."""
    with mp.workdps(40):
        zeta, w, a, r = mp.mpf(p.zeta), mp.mpf(p.omega), mp.mpf(p.amplitude), mp.mpf(p.r)
        dd = mp.mpf(p.delta_d)
        wd = mp.sqrt(1 - zeta ** 2)

        def phi(h):
            e, c, s = mp.exp(-zeta * h), mp.cos(wd * h), mp.sin(wd * h) / wd
            return e * (c + zeta * s), e * s, -e * s, e * (c - zeta * s)

        z0 = [mp.mpf(z[0]), mp.mpf(z[1])]

        def gap(t):
            f = phi(t)
            return f[0] * z0[0] + f[1] * z0[1] - dd - 2 * a * mp.sin(w * t / 2) ** 2

        def rate(t):
            f = phi(t)
            return f[2] * z0[0] + f[3] * z0[1] - a * w * mp.sin(w * t)

        alpha = a * w * w
        tm = mp.findroot(rate, z0[1] / alpha)
        hm = gap(tm)
        t1 = mp.findroot(gap, tm - mp.sqrt(2 * hm / alpha))
        v = rate(t1)
        f = phi(-t1)
        return z0[0] - (1 + r) * v * f[1], z0[1] - (1 + r) * v * f[3]


@pytest.mark.parametrize("order", [1, 2])
def test_zdm_order_against_mpmath_over_full_range(order):
    """The ZDM alone against the exact ZDM at 40 digits, eps = 1e-4 ... 1e-12, Delta d = 0."""
    eps = 10.0 ** -np.arange(4, 13)
    for c in SHAPES:
        errs = []
        for e in eps:
            z = state_with_hmax(P0, e, c)
            ref = _mp_exact_zdm(P0, z)
            got = zdm(P0, z, order)
            errs.append(max(float(abs(got[0] - ref[0])), float(abs(got[1] - ref[1]))))
        s = slope(eps, errs)
        assert abs(s - PREDICTED[order]) < 0.15, (c, s, errs)
    # and the double-precision exact ZDM is at the rounding floor
    for e in (1e-4, 1e-12):
        z = state_with_hmax(P0, e, -2.0)
        ref = _mp_exact_zdm(P0, z)
        got = zdm_exact(P0, z)
        assert max(float(abs(got[0] - ref[0])), float(abs(got[1] - ref[1]))) < 1e-14 * math.sqrt(e)


def test_no_impact_is_identity():
    p = P0.with_(delta_d=1e-6)
    z = (p.delta_d - 1e-8, 1e-5)  # H = -1e-8 + 1e-10 / (2 alpha) < 0
    assert h_max(p, z, order=1) < 0.0 and h_max(p, z, order=2) < 0.0
    for order in (1, 2, "exact"):
        assert zdm(p, z, order) == z
        assert zdm_jacobian(p, z, order) == (1.0, 0.0, 0.0, 1.0)


def test_state_leaving_the_wall_gets_minus_one_plus_r_times_its_velocity():
    """On the wall moving out (e1 = 0, e2 = v): exact D = (z_x, z_v - (1 + r) v); the
    second order is exact to O(v^3), the leading order to O(v^2) (position t1 = 0)."""
    p = P0
    for v in (1e-3, 1e-5):
        z = (p.delta_d, v)
        ex = zdm_exact(p, z)
        assert ex[0] == pytest.approx(z[0], abs=1e-15 * v)
        assert ex[1] == pytest.approx(v - (1.0 + p.r) * v, rel=1e-12)
        assert abs(zdm_second(p, z)[1] - ex[1]) < 5.0 * v ** 3
        assert abs(zdm_leading(p, z)[1] - ex[1]) < 5.0 * v ** 2


@pytest.mark.parametrize("order", [1, 2, "exact"])
def test_jacobians_match_finite_differences(order):
    p = P0.with_(delta_d=2e-4)
    z = (2e-4 + 3e-7, 1e-3)
    jac = np.array(zdm_jacobian(p, z, order)).reshape(2, 2)
    fd = np.zeros((2, 2))
    for j, h in enumerate((1e-12, 1e-10)):
        zp, zm = list(z), list(z)
        zp[j] += h
        zm[j] -= h
        fd[:, j] = (np.array(zdm(p, zp, order)) - np.array(zdm(p, zm, order))) / (2 * h)
    assert np.allclose(jac, fd, rtol=1e-6, atol=1e-6 * np.abs(jac).max())
    det = np.linalg.det(jac)
    if order == "exact":  # the ZDM is the impact law conjugated by the flow
        assert det == pytest.approx(p.r ** 2, rel=1e-12)
    if order == 2:  # r^2 + O(delta)
        assert det == pytest.approx(p.r ** 2, rel=1e-3)
    if order == 1:  # 1 - (1 + r) e2 / V: not r^2, the defect behind section 9
        assert abs(det - p.r ** 2) > 0.5
    full = np.array(normal_form_jacobian(p, z, GAINS["controlled"], order)).reshape(2, 2)
    from grazing_control.dynamics.maps.zdm import smooth_map
    assert np.allclose(full, np.array(smooth_map(p, GAINS["controlled"])).reshape(2, 2) @ jac)


def test_local_coefficients():
    g = local_grazing(P0)
    assert g.alpha == pytest.approx(-P0.a_star)
    # alpha = a omega^2 at grazing: x_p satisfies the equation of motion at tau*
    assert g.alpha == pytest.approx(P0.amplitude * P0.omega ** 2, rel=1e-13)
    with pytest.raises(ValueError):
        zdm(P0, (0.0, 0.0), order=3)
    with pytest.raises(ValueError):  # far from grazing: no local event at Pi1
        crossing(P0, (0.0, 5.0))


# -- a model file of any n (docs/theory_ndof.md §10) ------------------------------------

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
CHAIN = MODELS / "two_mass_chain.yaml"


def _match(a, b) -> float:
    cost = np.abs(np.subtract.outer(np.asarray(a), np.asarray(b)))
    i, j = linear_sum_assignment(cost)
    return float(cost[i, j].max())


def _three_dof() -> NdofModel:
    rng = np.random.default_rng(7)
    a = rng.normal(size=(3, 3))
    m = a @ a.T + 3 * np.eye(3)
    k = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.5]])
    return NdofModel(M=m, C=0.02 * m + 0.03 * k, K=k, f=[0.3, 0.0, 1.0], omega=0.7, i_w=1,
                     i_a=2, r=0.8, pi2_offset=2.0)


def _near_grazing(model, delta, seed):
    """A virtual Pi1 state with z = O(delta), e1 = O(delta^2) > 0, Delta d = -delta/2."""
    rng = np.random.default_rng(seed)
    m = dataclasses.replace(model, delta_d=-0.5 * delta)
    z = delta * rng.normal(size=2 * m.n)
    z[m.i_w] = m.delta_d + delta * delta * (0.2 + rng.random())
    return m, z


def _local_map_by_the_core(m, z):
    """The exact local map from the certified core: start on the smooth flow well before
    the crossing (real = smooth there), advance with impacts past the event, pull back
    with the smooth flow: Phi(-t_b) X(t_b)."""
    flow = NdofFlow.of(m)
    t_max, h, t1, _v = zd.crossing(m, z)
    width = math.sqrt(2.0 * h / zd.local_grazing(m).alpha)
    ta, tb = t1 - 3.0 * width, t_max + 3.0 * width
    seg = advance(flow, flow.tau_star + m.omega * ta, flow.transition(ta) @ z, tb - ta)
    assert len(seg.impacts) == 1
    assert seg.impacts[0].dt + ta == pytest.approx(t1, abs=1e-12 + 1e-9 * abs(t1))
    return flow.transition(-tb) @ seg.z


@pytest.mark.parametrize("make", [lambda: load_model(CHAIN), _three_dof])
def test_exact_zdm_is_the_core_local_map(make):
    for seed, delta in ((0, 1e-2), (1, 1e-3), (2, 1e-5)):
        m, z = _near_grazing(make(), delta, seed)
        ours = zd.zdm(m, z, "exact")
        ref = _local_map_by_the_core(m, z)
        jump = np.abs(ours - z).max()
        assert np.abs(ours - ref).max() < 1e-9 * jump + 1e-15


@pytest.mark.parametrize("make", [lambda: load_model(CHAIN), _three_dof])
def test_truncations_converge_at_their_orders_against_the_core(make):
    """|D1 - D| ~ delta^2 and |D2 - D| ~ delta^3, D the core's local map (fitted slopes;
    measured on the chain 1.99 and 3.03)."""
    deltas = np.geomspace(3e-2, 3e-4, 5)
    for order, slope in ((1, 2.0), (2, 3.0)):
        errs = []
        for delta in deltas:
            m, z = _near_grazing(make(), delta, 11)
            errs.append(np.abs(zd.zdm(m, z, order) - _local_map_by_the_core(m, z)).max())
        assert abs(np.polyfit(np.log(deltas), np.log(errs), 1)[0] - slope) < 0.15


def test_n1_is_the_1dof_zdm():
    """n = 1: the exact ZDM equals the 1-DOF closed form (zdm_exact) to rounding; the two
    second-order maps (different O(delta^3) terms) differ by O(delta^3), the two
    leading-order ones (the closed form's alpha includes Delta d) by O(delta^2)."""
    base = load_model(MODELS / "study_1dof.yaml")
    diffs, lead = [], []
    deltas = (1e-2, 1e-3, 1e-4)
    for delta in deltas:
        m, z = _near_grazing(base, delta, 3)
        p = OscillatorParams(zeta=0.01, r=m.r, omega=m.omega, delta_d=m.delta_d)
        ours = zd.zdm(m, z, "exact")
        theirs = np.array(zd.zdm_exact(p, (z[0], z[1])))
        assert np.abs(ours - theirs).max() < 1e-12 * np.abs(ours - z).max()
        lead.append(np.abs(zd.zdm(m, z, 1) - np.array(zd.zdm_leading(p, tuple(z)))).max())
        diffs.append(np.abs(zd.zdm(m, z, 2) - np.array(zd.zdm_second(p, tuple(z)))).max())
    assert abs(np.polyfit(np.log(deltas), np.log(diffs), 1)[0] - 3.0) < 0.2
    assert abs(np.polyfit(np.log(deltas), np.log(lead), 1)[0] - 2.0) < 0.2


@pytest.mark.parametrize("order", [1, 2, "exact"])
def test_model_file_jacobians_against_finite_differences(order):
    m, z = _near_grazing(load_model(CHAIN), 1e-2, 5)
    jac = zd.zdm_jacobian(m, z, order)
    h = 1e-9
    fd = np.column_stack([(zd.zdm(m, z + h * e, order) - zd.zdm(m, z - h * e, order)) / (2 * h)
                          for e in np.eye(4)])
    assert np.abs(jac - fd).max() < 1e-6 * np.abs(jac).max()
    if order == "exact":
        assert np.linalg.det(jac) == pytest.approx(m.r ** 2, rel=1e-10)


def test_model_file_no_crossing_is_the_identity():
    m = dataclasses.replace(load_model(CHAIN), delta_d=1e-3)
    z = np.array([0.0, 1e-4, 1e-4, 0.0])
    assert zd.crossing(m, z)[2] is None
    for order in zd.ORDERS:
        assert np.array_equal(zd.zdm(m, z, order), z)
        assert np.array_equal(zd.zdm_jacobian(m, z, order), np.eye(4))
    with pytest.raises(ValueError, match="order"):
        zd.zdm(m, z, 3)


def _fixed_point(m, k, order, guess):
    z = guess.copy()
    for _ in range(40):
        step = np.linalg.solve(zd.normal_form_jacobian(m, z, k, order) - np.eye(4),
                               z - zd.normal_form_map(m, z, k, order))
        z = z + step
        if np.abs(step).max() < 1e-15 * np.abs(z).max():
            break
    return z, np.linalg.eigvals(zd.normal_form_jacobian(m, z, k, order))


def test_second_order_map_gives_the_limit_multipliers_and_the_leading_order_does_not():
    """Fixed points of N o D on Pi1 near the exact branch: with D2 the multipliers
    approach the limit spectrum of family as O(|Delta d|^1/2); with D1 they are
    {mu} U spec(N~ (I - (1 + r) p1 e_v e_v^T)) at every Delta d (§10), not the limit; the
    {-(1 + 2 r) mu} U zeros of docs/ndof.md is not the limit either."""
    base = load_model(CHAIN)
    mu = 0.2
    k = nd.gain_family(base, mu)
    lim = nd.limit_multipliers(base, mu)
    n_mat = nd.smooth_map(base, k)
    keep = [1, 2, 3]
    nt = n_mat[np.ix_(keep, keep)]
    ev = np.eye(3)[1]
    p1 = -(1 + base.r) * ev @ np.linalg.solve(np.eye(3) - nt, nt @ ev)
    lead = np.append(np.linalg.eigvals(nt @ (np.eye(3) - (1 + base.r) * p1 * np.outer(ev, ev))), mu)
    naive = np.append(nd.transmission_zeros(base), -(1 + 2 * base.r) * mu)
    assert _match(lead, lim) > 0.2 and _match(naive, lim) > 0.2
    errs = {1: [], 2: [], "exact": []}
    for dd in (1e-6, 1e-8):
        m = dataclasses.replace(base, delta_d=-dd)
        bp = modal_branch.orbit_at(m, k, -dd)
        virtual = nd._transition(m, -bp.psi / m.omega) @ bp.state
        for order in errs:
            z, lam = _fixed_point(m, k, order, virtual)
            errs[order].append(_match(lam, lead if order == 1 else lim))
            if order == "exact":
                assert np.abs(z - virtual).max() < 1e-10 * np.abs(virtual).max()
    assert max(errs[1]) < 1e-9          # D1: exactly that spectrum at every Delta d
    for order in (2, "exact"):
        assert 7 < errs[order][0] / errs[order][1] < 14 and errs[order][1] < 1e-3

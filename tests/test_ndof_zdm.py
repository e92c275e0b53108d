"""The n-DOF discontinuity map (docs/theory_ndof.md §10) against the exact local map of
the certified core (oscillator/ndof/impact.advance), the 1-DOF ZDM for n = 1, finite
differences, and the limit multipliers of ndof_design through its fixed points."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from grazing_control.dynamics.orbits import ndof_branch

from grazing_control.dynamics.design import ndof_design as nd

from grazing_control.dynamics.maps import ndof_zdm as nz

from grazing_control.dynamics.maps import zdm
from grazing_control.oscillator.ndof import NdofModel, load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.oscillator.params import OscillatorParams

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
    t_max, h, t1, _v = nz.crossing(m, z)
    width = math.sqrt(2.0 * h / nz.local_grazing(m).alpha)
    ta, tb = t1 - 3.0 * width, t_max + 3.0 * width
    seg = advance(flow, flow.tau_star + m.omega * ta, flow.transition(ta) @ z, tb - ta)
    assert len(seg.impacts) == 1
    assert seg.impacts[0].dt + ta == pytest.approx(t1, abs=1e-12 + 1e-9 * abs(t1))
    return flow.transition(-tb) @ seg.z


@pytest.mark.parametrize("make", [lambda: load_model(CHAIN), _three_dof])
def test_exact_zdm_is_the_core_local_map(make):
    for seed, delta in ((0, 1e-2), (1, 1e-3), (2, 1e-5)):
        m, z = _near_grazing(make(), delta, seed)
        ours = nz.zdm(m, z, "exact")
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
            errs.append(np.abs(nz.zdm(m, z, order) - _local_map_by_the_core(m, z)).max())
        assert abs(np.polyfit(np.log(deltas), np.log(errs), 1)[0] - slope) < 0.15


def test_n1_is_the_1dof_zdm():
    """n = 1: the exact ZDM equals dynamics/maps/zdm.py's to rounding; the two second-order
    maps (different O(delta^3) terms) differ by O(delta^3), the two leading-order ones
    (zdm.py's alpha includes Delta d) by O(delta^2)."""
    base = load_model(MODELS / "study_1dof.yaml")
    diffs, lead = [], []
    deltas = (1e-2, 1e-3, 1e-4)
    for delta in deltas:
        m, z = _near_grazing(base, delta, 3)
        p = OscillatorParams(zeta=0.01, r=m.r, omega=m.omega, delta_d=m.delta_d)
        ours = nz.zdm(m, z, "exact")
        theirs = np.array(zdm.zdm_exact(p, z[0], z[1]))
        assert np.abs(ours - theirs).max() < 1e-12 * np.abs(ours - z).max()
        lead.append(np.abs(nz.zdm(m, z, 1) - np.array(zdm.zdm_leading(p, *z))).max())
        diffs.append(np.abs(nz.zdm(m, z, 2) - np.array(zdm.zdm_second(p, *z))).max())
    assert abs(np.polyfit(np.log(deltas), np.log(diffs), 1)[0] - 3.0) < 0.2
    assert abs(np.polyfit(np.log(deltas), np.log(lead), 1)[0] - 2.0) < 0.2


@pytest.mark.parametrize("order", [1, 2, "exact"])
def test_jacobians_against_finite_differences(order):
    m, z = _near_grazing(load_model(CHAIN), 1e-2, 5)
    jac = nz.zdm_jacobian(m, z, order)
    h = 1e-9
    fd = np.column_stack([(nz.zdm(m, z + h * e, order) - nz.zdm(m, z - h * e, order)) / (2 * h)
                          for e in np.eye(4)])
    assert np.abs(jac - fd).max() < 1e-6 * np.abs(jac).max()
    if order == "exact":
        assert np.linalg.det(jac) == pytest.approx(m.r ** 2, rel=1e-10)


def test_no_crossing_is_the_identity():
    m = dataclasses.replace(load_model(CHAIN), delta_d=1e-3)
    z = np.array([0.0, 1e-4, 1e-4, 0.0])
    assert nz.crossing(m, z)[2] is None
    for order in nz.ORDERS:
        assert np.array_equal(nz.zdm(m, z, order), z)
        assert np.array_equal(nz.zdm_jacobian(m, z, order), np.eye(4))
    with pytest.raises(ValueError, match="order"):
        nz.zdm(m, z, 3)


def _fixed_point(m, k, order, guess):
    z = guess.copy()
    for _ in range(40):
        step = np.linalg.solve(nz.normal_form_jacobian(m, z, k, order) - np.eye(4),
                               z - nz.normal_form_map(m, z, k, order))
        z = z + step
        if np.abs(step).max() < 1e-15 * np.abs(z).max():
            break
    return z, np.linalg.eigvals(nz.normal_form_jacobian(m, z, k, order))


def test_second_order_map_gives_the_limit_multipliers_and_the_leading_order_does_not():
    """Fixed points of N o D on Pi1 near the exact branch: with D2 the multipliers
    approach the limit spectrum of ndof_design as O(|Delta d|^1/2); with D1 they are
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
        bp = ndof_branch.orbit_at(m, k, -dd)
        virtual = nd._transition(m, -bp.psi / m.omega) @ bp.state
        for order in errs:
            z, lam = _fixed_point(m, k, order, virtual)
            errs[order].append(_match(lam, lead if order == 1 else lim))
            if order == "exact":
                assert np.abs(z - virtual).max() < 1e-10 * np.abs(virtual).max()
    assert max(errs[1]) < 1e-9          # D1: exactly that spectrum at every Delta d
    for order in (2, "exact"):
        assert 7 < errs[order][0] / errs[order][1] < 14 and errs[order][1] < 1e-3

"""The delay-aware n-DOF design (docs/theory_ndof.md §14): the gain family for a kick
acting a known delay after Pi2, checked against the 1-DOF delayed design on the n = 1
model file and against finite differences of the exact n-DOF map with the delayed kick
on the two-mass chain."""

import dataclasses
import math

import numpy as np
import pytest
import yaml

from grazing_control.dynamics.design import gains as design
from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits import modal_branch
from grazing_control.dynamics.orbits.shooting import find_periodic
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.params import ParameterError

from test_family import CHAIN, _match, _study


def _fd_jacobian(P, z, h):
    """Fourth-order central differences of P.step at z, step h."""
    d = len(z)
    jac = np.zeros((d, d))
    for j in range(d):
        e = np.zeros(d)
        e[j] = h

        def f(t):
            return P.step(z + t * e).state

        jac[:, j] = (8.0 * (f(1) - f(-1)) - (f(2) - f(-2))) / (12.0 * h)
    return jac


@pytest.mark.parametrize("delay", [0.3, 2.0, 4.5, 6.0, 7.0])
def test_n1_delayed_family_is_the_1dof_delayed_design(delay):
    """The n = 1 model file: k(mu; delay) = (c1, c2) with c1 = design.degenerate_c1(c2;
    delay) ((D5) of docs/theory_delay.md) to 1e-12, and the limit multipliers and gamma1
    of the delayed design equal the 1-DOF closed forms (D8), (D9) with G_delay."""
    m, p = _study()
    for mu in (-0.5, 0.0, 0.3):
        k = nd.gain_family(m, mu, delay)
        c1 = design.degenerate_c1(p, float(k[1]), delay)
        assert abs(k[0] - c1) <= 1e-12 * max(1.0, abs(c1))
        g = Gains(c1, float(k[1]), delay)
        lam = nd.limit_multipliers(m, mu, delay)
        assert _match(lam, design.limit_multipliers(p, g)) <= 1e-12
        g1 = design.existence_coefficient(p, g)
        assert abs(nd.existence_coefficient(m, mu, delay) - g1) <= 1e-12 * max(1.0, abs(g1))


def test_zero_delay_is_todays_design_bit_for_bit():
    m = load_model(CHAIN)
    for mu in (-0.3, 0.2):
        assert np.array_equal(nd.gain_family(m, mu, 0.0), nd.gain_family(m, mu))
        assert np.array_equal(nd.limit_multipliers(m, mu, 0.0), nd.limit_multipliers(m, mu))
    assert nd.admissible_mu(m, delay=0.0) == nd.admissible_mu(m)


def test_the_delayed_family_makes_w_a_left_eigenvector_of_the_delayed_smooth_map():
    """w^T N(k(mu; delay); delay) = mu w^T, with N(k; delay) = Phi(T) + Phi(T - s - delay)
    b k^T Phi(s) built here from the flow alone (§14, (N8))."""
    m = load_model(CHAIN)
    flow = NdofFlow.of(m)
    s = m.pi2_offset / m.omega
    b = np.eye(2 * m.n)[m.n + m.i_a]
    for delay in (0.5, 4.0, 9.0):
        for mu in (-0.4, 0.1):
            k = nd.gain_family(m, mu, delay)
            n_mat = flow.transition(m.period) + np.outer(
                flow.transition(m.period - s - delay) @ b, k @ flow.transition(s))
            w = np.eye(2 * m.n)[m.i_w]
            assert np.max(np.abs(w @ n_mat - mu * w)) <= 1e-12 * np.abs(n_mat).max()


def test_the_delayed_map_is_the_smooth_delayed_kick_far_from_the_wall_and_its_jacobian_is_d3():
    """Without impacts (the wall far away) one delayed step is Phi(T) z + Phi(T - delay) b
    k^T z to 1e-12; with impacts in the period the Jacobian M2 (M1 + b k^T) equals
    fourth-order finite differences of the map."""
    m = load_model(CHAIN)
    far = dataclasses.replace(m, delta_d=50.0)
    flow = NdofFlow.of(far)
    k = nd.gain_family(m, 0.0, 4.0)
    b = np.eye(4)[far.n + far.i_a]
    rng = np.random.default_rng(5)
    for _ in range(5):
        z = rng.normal(scale=0.3, size=4)
        st = ModalMap(far, k, 4.0).step(z)
        want = flow.transition(far.period) @ z + flow.transition(far.period - 4.0) @ b * (k @ z)
        assert not st.impacts
        assert np.max(np.abs(st.state - want)) <= 1e-12 * max(1.0, np.abs(want).max())
    near = dataclasses.replace(m, delta_d=-0.1)
    z = np.array([-0.05, -0.02, 0.03, 0.01])
    for delay, kicked_first in ((4.0, True), (11.9, False)):   # the impact at t = 11.50
        P = ModalMap(near, k, delay)
        st = P.step(z, jacobian=True)
        assert len(st.impacts) == 1 and (st.impacts[0].dt > delay) == kicked_first
        fd = _fd_jacobian(P, z, 1e-5)
        assert np.max(np.abs(fd - st.jacobian)) <= 1e-7 * np.abs(st.jacobian).max()
        assert P.jacobian_det(1, 1) is None


@pytest.mark.parametrize("delay, mu", [(0.5, 0.2), (4.0, 0.0)])
def test_delayed_design_limit_multipliers_against_finite_differences_of_the_exact_map(delay, mu):
    """Chain, the design k(mu; delay) acting delay after the sample: the delayed 1/1 branch
    is a fixed point of the exact delayed ModalMap (1e-13), and the multipliers of the
    finite-difference Jacobian of that map at the orbit converge to the design's limit
    spectrum like |Delta d|^(1/2) (as the undelayed ones, §12): error/sqrt|Delta d| in
    (0.05, 20) and below 1e-3 at Delta d = -1e-8."""
    check_limit_against_the_exact_map(delay, mu, delay)


def check_limit_against_the_exact_map(actuation, mu, delay, width=0.0):
    """On the chain: the design k(mu; actuation)'s branch is a fixed point of the exact
    ModalMap(delay, width) (1e-13, the same v-), and the multipliers of that map's
    finite-difference Jacobian at the shot orbit approach the limit spectrum like
    |Delta d|^(1/2): error / sqrt|Delta d| in (0.05, 20), below 1e-3 at Delta d = -1e-8.
    Returns the errors at Delta d = -1e-4, -1e-6, -1e-8."""
    m0 = load_model(CHAIN)
    k = nd.gain_family(m0, mu, actuation)
    limit = nd.limit_multipliers(m0, mu, actuation)
    assert np.max(np.abs(limit)) < 1.0
    errors = []
    for dd in (-1e-4, -1e-6, -1e-8):
        m = dataclasses.replace(m0, delta_d=dd)
        bp = modal_branch.orbit_at(m, k, dd, delay=actuation)
        P = ModalMap(m, k, delay, width)
        st = P.step(bp.pi2_state)
        assert len(st.impacts) == 1
        assert abs(st.impacts[0].v_minus - bp.v_minus) <= 1e-9 * bp.v_minus
        assert np.max(np.abs(st.state - bp.pi2_state)) <= 1e-13
        orbit = find_periodic(P, bp.pi2_state)
        jac = _fd_jacobian(P, orbit.state, 1e-2 * bp.v_minus ** 2)
        err = _match(np.linalg.eigvals(jac), limit)
        assert 0.05 < err / math.sqrt(-dd) < 20.0, (dd, err)
        errors.append(err)
    assert errors[-1] < 1e-3
    return errors


def test_the_undelayed_design_acting_late_grows_like_one_over_delta_d():
    """What the delay-aware design removes: k(mu; 0) acting 4.0 after the sample leaves
    the singular multiplier (max|lambda| x >= 50 per two decades of Delta d)."""
    m0 = load_model(CHAIN)
    k = nd.gain_family(m0, 0.0)
    rho = []
    for dd in (-1e-4, -1e-6):
        m = dataclasses.replace(m0, delta_d=dd)
        bp = modal_branch.orbit_at(m, k, dd, delay=4.0)
        orbit = find_periodic(ModalMap(m, k, 4.0), bp.pi2_state)
        assert len(orbit.impacts) == 1
        rho.append(float(np.max(np.abs(np.linalg.eigvals(orbit.monodromy)))))
    assert rho[1] > 50.0 * rho[0] > 50.0


def test_delays_outside_the_window_are_refused_naming_the_delay():
    m = load_model(CHAIN)
    reach = m.period - m.pi2_offset / m.omega
    for bad in (-0.1, reach, 1e308, math.nan, True):
        with pytest.raises(ParameterError, match="delay=.*valid range is 0 <= delay < T - s"):
            nd.gain_family(m, 0.2, bad)
    with pytest.raises(ParameterError, match="delay=.*valid range is 0 <= delay < T"):
        ModalMap(m, nd.gain_family(m, 0.2), m.period)


def test_the_gain_file_carries_the_delay(tmp_path):
    m = load_model(CHAIN)
    d = nd.evaluate_design(m, 0.0, 4.0)
    nd.write_gain_yaml(tmp_path / "k.yaml", m, d, CHAIN)
    par = yaml.safe_load((tmp_path / "k.yaml").read_text())["/**"]["ros__parameters"]
    assert par["actuation_delay"] == 4.0
    assert np.allclose(par["gains"], nd.gain_family(m, 0.0, 4.0), rtol=0, atol=0)
    undelayed = nd.evaluate_design(m, 0.0)
    with pytest.raises(ParameterError, match="not on the family"):
        nd.write_gain_yaml(tmp_path / "x.yaml", m, dataclasses.replace(undelayed, delay=4.0),
                           CHAIN)


def test_sections_with_stable_zeros_for_a_delayed_kick():
    """With delay 4 on the chain: at the middle of every interval found the delayed
    kick's zeros are inside and the delay is below T - s; at the middle of every gap
    they are not (or the delay is too long there)."""
    m = load_model(CHAIN)
    found = nd.sections_with_stable_zeros(m, points=60, delay=4.0)
    assert found
    edges = [0.0] + [x for iv in found for x in iv] + [2 * math.pi]
    for j in range(len(edges) - 1):
        mid = 0.5 * (edges[j] + edges[j + 1])
        inside = j % 2 == 1
        try:
            radius = float(np.max(np.abs(nd.transmission_zeros(
                dataclasses.replace(m, pi2_offset=mid), 4.0))))
        except ParameterError:
            radius = math.inf
        assert (radius < 1.0) == inside, (mid, radius)
        if inside:
            assert 4.0 < m.period - mid / m.omega


# ------------------------------------------- the delayed kick's 1/1 orbit and branch
def test_the_delayed_kick_is_the_kick_on_the_section_delay_later_with_gain_phi_minus_delay_t_k():
    """docs/theory_ndof.md §14, (N8b): with no impact inside the delay, the kick k^T z of
    the Pi2 sample acting D later is the undelayed kick on Pi2' = Pi2 + D (pi2_offset +
    omega D) with the gain k' = Phi(-D)^T k, whose state there is Phi(D) z. Two routes
    through different code: the family (k(mu; D) mapped is k'(mu) of the moved section,
    1e-14) and the branch (psi, v-, multipliers, Pi2 states at Delta d = -1e-4, -1e-6, 1e-12)."""
    m0 = load_model(CHAIN)
    delay, mu = 0.5, 0.2
    moved = dataclasses.replace(m0, pi2_offset=m0.pi2_offset + m0.omega * delay)
    phi = NdofFlow.of(m0).transition(-delay)
    k = nd.gain_family(m0, mu, delay)
    k_moved = phi.T @ k
    assert np.max(np.abs(k_moved - nd.gain_family(moved, mu))) <= 1e-14 * np.max(np.abs(k))
    for dd in (-1e-4, -1e-6):
        m, mm = (dataclasses.replace(x, delta_d=dd) for x in (m0, moved))
        a = modal_branch.orbit_at(m, k, dd, delay=delay)
        b = modal_branch.orbit_at(mm, k_moved, dd)
        assert abs(a.psi - b.psi) <= 1e-12 * abs(a.psi)
        assert abs(a.v_minus - b.v_minus) <= 1e-12 * a.v_minus
        la = modal_branch.branch_multipliers(m, k, a, delay)
        lb = modal_branch.branch_multipliers(mm, k_moved, b)
        assert _match(la, lb) <= 1e-12
        z_moved = NdofFlow.of(m).transition(delay) @ a.pi2_state
        assert np.max(np.abs(z_moved - b.pi2_state)) <= 1e-14


@pytest.mark.parametrize("dd", [-1e-4, -1e-6])
def test_the_delayed_orbit_against_shooting_and_finite_differences_of_the_delayed_map(dd):
    """one_one.orbit with a delay (the explicit branch, §14) against Newton shooting on the exact
    delayed ModalMap from the local map's prediction: the same Pi2 state (1e-13), the
    multipliers of the map's (D3) Jacobian (1e-9 relative) and of its fourth-order
    finite-difference Jacobian (step 1e-2 v-^2; 1e-6), on the design family (bounded)
    and off it (k_x0 + 0.05: the singular multiplier ~ 1/v- that the delay-aware gains
    remove)."""
    from grazing_control.dynamics.orbits.near_grazing import predicted_orbit
    from grazing_control.dynamics.orbits.one_one import EXPLICIT, orbit

    m0 = load_model(CHAIN)
    delay = 0.5
    m = dataclasses.replace(m0, delta_d=dd)
    family = nd.gain_family(m0, 0.2, delay)
    for k in (family, family + np.array([0.05, 0.0, 0.0, 0.0])):
        o = orbit(m, k, delay=delay)
        assert o.route == EXPLICIT
        P = ModalMap(m, k, delay)
        shot = find_periodic(P, predicted_orbit(m, k, delay=delay)[0])
        assert len(shot.impacts) == 1 and shot.impacts[0].dt > delay
        assert np.max(np.abs(shot.state - o.state)) <= 1e-13
        lam = np.linalg.eigvals(shot.monodromy)
        big = max(1.0, float(np.max(np.abs(lam))))
        assert _match(o.multipliers, lam) <= 1e-9 * big
        fd = np.linalg.eigvals(_fd_jacobian(P, o.state, 1e-2 * o.v_minus ** 2))
        assert _match(o.multipliers, fd) <= 1e-6 * big
    assert np.max(np.abs(o.multipliers)) > 1.0      # off the family: 6.29 at -1e-4


def test_the_delayed_branch_is_exact_point_by_point_and_tends_to_the_delayed_limit():
    """continue_branch with a delay on 8 points from -1e-3 to -1e-10: each point is the
    delayed orbit solved on its own from psi = 0 (orbit_at, 1e-12 in v-), the points
    down to -1e-5 are fixed points of the exact delayed map (1e-13), and the multipliers
    tend to design --delay's limit spectrum like |Delta d|^(1/2) (error / sqrt|Delta d|
    in (0.05, 20)): the issue's 'continue with few points' on the delayed kick."""
    m0 = load_model(CHAIN)
    delay, mu = 0.5, 0.2
    k = nd.gain_family(m0, mu, delay)
    limit = nd.limit_multipliers(m0, mu, delay)
    values = -np.geomspace(1e-3, 1e-10, 8)
    branch = modal_branch.continue_branch(dataclasses.replace(m0, delta_d=values[0]), k,
                                          values, delay=delay)
    assert branch.stopped == "end" and len(branch.points) == 8
    for p, dd in zip(branch.points, values):
        m = dataclasses.replace(m0, delta_d=dd)
        alone = modal_branch.orbit_at(m, k, dd, delay=delay)
        assert p.value == pytest.approx(dd, rel=1e-13)
        assert abs(p.v_min - alone.v_minus) <= 1e-12 * alone.v_minus
        if dd <= -1e-5:
            st = ModalMap(m, k, delay).step(p.state)
            assert len(st.impacts) == 1
            assert np.max(np.abs(st.state - p.state)) <= 1e-13
        err = _match(p.multipliers, limit)
        assert 0.05 < err / math.sqrt(-dd) < 20.0, (dd, err)


def test_the_shooting_route_of_continue_on_the_delayed_map_agrees_with_the_delayed_branch():
    """The route `continue --delay` falls back to where the start is off the branch
    (continuation.continue_orbit on the exact delayed ModalMap) against the branch in the
    impact phase, from -1e-3 to -1e-5 (v- >= 3e-3, where shooting resolves the impact):
    the same Pi2 states (1e-12) and v- (1e-9 relative), multipliers (1e-9)."""
    from grazing_control.dynamics.orbits.continuation import continue_orbit

    m0 = load_model(CHAIN)
    delay = 0.5
    k = nd.gain_family(m0, 0.2, delay)
    values = -np.geomspace(1e-3, 1e-5, 3)
    m = dataclasses.replace(m0, delta_d=values[0])
    explicit = modal_branch.continue_branch(m, k, values, delay=delay)
    start = modal_branch.orbit_at(m, k, values[0], delay=delay).pi2_state
    shot = continue_orbit(ModalMap(m, k, delay), "delta_d", values, start)
    assert len(shot.points) == len(explicit.points) == 3
    for a, b in zip(explicit.points, shot.points):
        assert b.value == pytest.approx(a.value, rel=1e-14)
        assert np.max(np.abs(a.state - b.state)) <= 1e-12
        assert abs(a.v_min - b.v_min) <= 1e-9 * a.v_min
        assert _match(a.multipliers, b.multipliers) <= 1e-9


@pytest.mark.timeout(60)   # a hang guard: before, this orbit ran for minutes
def test_an_unstable_delayed_loop_fails_naming_its_divergence():
    """The 2-mass chain at mu = 0 with a delay of 2 (gains ~170): no 1/1 orbit on the
    branch, shooting fails, and the last guess's simulation diverges 6x a period. It used
    to run on until |z| ~ 1e25, where each period's certified impact search took 11-39 s
    (`grazing orbit` ran for over 100 s); now the simulation stops once the state leaves
    max |z| <= DIVERGED d* and the failure names it."""
    from grazing_control.dynamics.orbits.near_grazing import DIVERGED, with_delta_d
    from grazing_control.dynamics.orbits.one_one import orbit
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    model = with_delta_d(load_model(CHAIN), -1e-4)
    k = np.asarray(nd.gain_family(model, 0.0, 2.0), dtype=float)
    with pytest.raises(OrbitNotFound) as err:
        orbit(model, k, delay=2.0)
    bound = DIVERGED * NdofFlow.of(model).d_star
    assert f"simulation: the motion left |z| <= {bound:.3g} at period " in str(err.value)
    assert "diverging" in str(err.value)

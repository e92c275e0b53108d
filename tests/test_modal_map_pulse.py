"""dynamics/maps/modal_map.py with a force pulse or a first-order actuator (pulse_step,
actuated_step; issue 32, docs/theory_ndof.md §15): the exact pulsed map against the 1-DOF pulse/actuator maps (n = 1), the 50-digit
reference (tests/reference_ndof.py) and DOP853; the pulse-aware design against the 1-DOF
(P1) and finite differences of the exact pulsed map. The motion through the pulse and the
actuator that the filter fits: tests/test_motion.py."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.maps.modal_map import ModalMap, actuated_step, pulse_step
from grazing_control.dynamics.orbits import modal_branch
from grazing_control.dynamics.simulation import actuation
from grazing_control.dynamics.simulation import actuator as act
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.forced import actuated_mass, pulse_input
from grazing_control.oscillator.params import ParameterError

from reference_ndof import load_reference
from test_ndof_delay import _fd_jacobian, check_limit_against_the_exact_map
from test_family import CHAIN, _match, _random_model, _study

#: (z, Delta v, start, width): a pulse before the impact, one holding it (the study's
#: impact comes ~7 after Pi2), the kick
N1_CASES = [((1e-3, 2e-3), 0.01, 0.5, 1.0), ((-0.01, 0.003), -0.02, 2.0, 0.7),
            ((1e-3, 2e-3), 0.01, 6.5, 1.0), ((0.0, 0.0), 0.05, 7.0, 1.5),
            ((2e-3, -1e-3), 0.02, 1.0, 0.0)]


@pytest.mark.parametrize("z, dv, start, width", N1_CASES)
def test_n1_pulse_and_actuator_maps_are_the_1dof_ones(z, dv, start, width):
    """n = 1 (config/models/study_1dof.yaml): pulse_step = the 1-DOF pulse_step and
    actuated_step = the 1-DOF actuated_step (two actuators; a force limit 0.005 that clips
    |Delta v| / w >= 0.01) to 1e-12, same impacts."""
    m, p = _study()
    flow = NdofFlow.of(m)
    a = pulse_step(flow, z, dv, start=start, width=width)
    b = actuation.pulse_step(p, z[0], z[1], dv, start=start, width=width)
    assert np.max(np.abs(a.state - (b.dx, b.dv))) <= 1e-12
    assert [i.dt for i in a.impacts] == pytest.approx([i.dt for i in b.impacts], abs=1e-12)
    if width == 0.0:
        return
    for tau_a, lat, limit in ((0.3, 0.0, math.inf), (0.5, 0.2, math.inf), (0.3, 0.1, 0.005)):
        za, fa, ia = actuated_step(flow, z, 0.01, dv, start=start, width=width,
                                   time_constant=tau_a, latency=lat, force_limit=limit)
        xb, vb, fb, ib = act.actuated_step(p, z[0], z[1], 0.01, dv, start=start, width=width,
                                           actuator=act.Actuator(tau_a, lat),
                                           force_limit=limit)
        assert np.max(np.abs(za - (xb, vb))) <= 1e-12 and abs(fa - fb) <= 1e-12
        assert [i.dt for i in ia] == pytest.approx([i.dt for i in ib], abs=1e-10)
    a = pulse_step(flow, z, dv, start=start, width=width, force_limit=0.005)
    b = actuation.pulse_step(p, z[0], z[1], dv, start=start, width=width, force_limit=0.005)
    assert np.max(np.abs(a.state - (b.dx, b.dv))) <= 1e-12


@pytest.mark.parametrize("start, width", [(11.0, 1.0), (3.0, 2.0), (0.0, 0.0)])
def test_chain_pulse_map_against_the_50_digit_reference(start, width):
    """Two-mass chain at Delta d = -0.1: one pulsed period (the impact at ~11.48 inside the
    pulse [11, 12], after it, and the kick) equals the mpmath reference to 1e-13."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.1)
    ref = load_reference(CHAIN, delta_d=-0.1)
    z = [-0.05, -0.02, 0.03, 0.01]
    a = pulse_step(NdofFlow.of(m), z, 0.05, start=start, width=width)
    zr, ir = ref.pulse_map(z, 0.05, start, width)
    assert np.max(np.abs(a.state - np.array([float(x) for x in zr]))) <= 1e-13
    assert [i.dt for i in a.impacts] == pytest.approx([float(i[0]) for i in ir], abs=1e-12)


def test_non_diagonal_mass_pulse_against_the_reference():
    """A random 3-DOF model with a full M: the impulse m_a Delta v (m_a = 1 / (M^-1)_aa),
    the static deflection K^-1 e_a F; one pulsed period against the reference (1e-12)."""
    m = _random_model(3, n=3)
    m = dataclasses.replace(m, delta_d=-0.2 * NdofFlow.of(m).d_star)
    ref = load_reference_from(m)
    flow = NdofFlow.of(m)
    z = 0.01 * np.arange(1, 7) / 6.0
    out = pulse_step(flow, z, 0.03, start=0.2 * m.period, width=0.3 * m.period)
    zr, ir = ref.pulse_map(list(z), 0.03, 0.2 * m.period, 0.3 * m.period)
    assert len(out.impacts) == len(ir) == 1
    scale = 1.0 + float(np.abs(out.state).max())
    assert np.max(np.abs(out.state - np.array([float(x) for x in zr]))) <= 1e-12 * scale
    assert actuated_mass(flow) == pytest.approx(1.0 / np.linalg.inv(m.M)[m.i_a, m.i_a],
                                                rel=1e-14)


def load_reference_from(model):
    from reference_ndof import NdofRef

    return NdofRef(M=model.M.tolist(), C=model.C.tolist(), K=model.K.tolist(),
                   f=model.f.tolist(), omega=model.omega, i_w=model.i_w,
                   delta_d=model.delta_d, r=model.r, i_a=model.i_a, phase=model.phase,
                   pi2_offset=model.pi2_offset)


def test_pulse_input_vector_against_the_reference_far_from_the_wall():
    """(N10): far from the wall one pulsed period is linear, P(z) = Phi(T) (z + b_w Delta v);
    the reference's P(0, Delta v) - P(0, 0) gives Phi(T) b_w Delta v (1e-12)."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=50.0)
    ref = load_reference(CHAIN, delta_d=50.0)
    flow = NdofFlow.of(m)
    for start, width in ((0.5, 1.0), (4.0, 3.0)):
        zr, ir = ref.pulse_map([0.0] * 4, 0.1, start, width)
        assert not ir
        want = flow.transition(m.period) @ pulse_input(flow, start, width) * 0.1
        assert np.max(np.abs(np.array([float(x) for x in zr]) - want)) <= 1e-13


def _dop853_actuated(model, z, force, dv, start, width, tau_a, lat):
    """One actuated period by DOP853 (rtol 1e-12) with impact events: an independent
    check of actuated_step (physical coordinates, the lag tau_a F' = u - F)."""
    flow = NdofFlow.of(model)
    n, w, a = model.n, model.i_w, model.i_a
    minv = np.linalg.inv(model.M)
    d = flow.d_star + model.delta_d
    on, off = start + lat, start + lat + width
    u_on = actuated_mass(flow) * dv / width

    def rhs(t, y, u):
        x, v, f = y[:n], y[n:2 * n], y[2 * n]
        e = np.zeros(n)
        e[a] = f
        acc = minv @ (model.f * math.cos(flow.tau2 + model.omega * t) + e
                      - model.C @ v - model.K @ x)
        return np.concatenate([v, acc, [(u - f) / tau_a]])

    def hit(t, y, u):
        return y[w] - d
    hit.terminal, hit.direction = True, 1.0
    y = np.concatenate([flow.to_physical(flow.tau2, z), [force]])
    t, impacts = 0.0, []
    for end, u in ((on, 0.0), (off, u_on), (model.period, 0.0)):
        while t < end:
            sol = solve_ivp(rhs, (t, end), y, method="DOP853", rtol=1e-12, atol=1e-14,
                            events=hit, args=(u,))
            y, t = sol.y[:, -1].copy(), sol.t[-1]
            if sol.status == 1:
                impacts.append(t)
                y[w] = d
                y[n + w] *= -model.r
    tau = flow.tau2 + model.omega * model.period
    return flow.to_deviation(tau, y[:2 * n]), y[2 * n], impacts


def test_chain_actuated_step_against_the_reference_and_dop853():
    """Chain, Delta d = -0.1, the lag tau_a = 0.8 and latency 0.3, the pulse commanded at
    3 (the impact in the force's decay) and at 10.8 (on [11.1, 12.1], holding the impact):
    actuated_step against the 50-digit reference (1e-13; measured 4e-15) and DOP853
    (1e-9)."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.1)
    ref = load_reference(CHAIN, delta_d=-0.1)
    z = np.array([-0.05, -0.02, 0.03, 0.01])
    for start in (3.0, 10.8):
        za, fa, ia = actuated_step(NdofFlow.of(m), z, 0.02, 0.05, start=start, width=1.0,
                                   time_constant=0.8, latency=0.3)
        zr, fr, ir = ref.actuated_map(list(z), 0.02, 0.05, start, 1.0, 0.8, 0.3)
        assert np.max(np.abs(za - np.array([float(x) for x in zr]))) <= 1e-13
        assert abs(fa - float(fr)) <= 1e-15
        assert [i.dt for i in ia] == pytest.approx([float(i[0]) for i in ir], abs=1e-12)
        zd, fd, idd = _dop853_actuated(m, z, 0.02, 0.05, start, 1.0, 0.8, 0.3)
        assert len(ia) == len(idd) == 1
        assert abs(ia[0].dt - idd[0]) <= 1e-9
        assert np.max(np.abs(za - zd)) <= 1e-9 and abs(fa - fd) <= 1e-12


def test_pulsed_map_jacobian_against_finite_differences():
    """ModalMap(width): its Jacobian (the pieces' monodromies, the force's dependence on z
    through the pulse's input and its clearance) equals fourth-order differences to 1e-7,
    with the impact after the pulse and inside it."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-0.1)
    k = nd.gain_family(load_model(CHAIN), 0.0, 4.0)
    z = np.array([-0.05, -0.02, 0.03, 0.01])
    for delay, width in ((4.0, 1.0), (11.5, 1.0), (1.0, 0.5)):
        P = ModalMap(m, k, delay, width)
        st = P.step(z, jacobian=True)
        assert len(st.impacts) == 1
        fd = _fd_jacobian(P, z, 1e-5)
        assert np.max(np.abs(fd - st.jacobian)) <= 1e-7 * np.abs(st.jacobian).max()
        assert P.jacobian_det(1, 1) is None


@pytest.mark.parametrize("delay, width, tau_a, lat", [(0.3, 0.5, 0.0, 0.0),
                                                      (2.0, 1.0, 0.0, 0.0),
                                                      (4.5, 0.7, 0.3, 0.1),
                                                      (1.0, 1.0, 1.0, 0.0)])
def test_n1_pulse_family_is_the_1dof_p1_design(delay, width, tau_a, lat):
    """n = 1: k(mu; pulse)_0 = the 1-DOF actuated_c1 ((P1), docs/theory_pulse.md §7) for
    the same c2, pulse and actuator, to 1e-12 relative."""
    m, p = _study()
    pulse = nd.Actuation(delay, width, tau_a, lat)
    for mu in (-0.5, 0.0, 0.3):
        k = nd.gain_family(m, mu, pulse)
        start = actuation.pulse_start(p.period, delay, width)
        c1 = act.actuated_c1(p, float(k[1]), act.Actuator(tau_a, lat), start, width)
        assert abs(k[0] - c1) <= 1e-12 * abs(c1)


@pytest.mark.parametrize("delay, width, mu", [(4.0, 1.0, 0.0), (0.5, 0.6, 0.2)])
def test_pulse_design_limit_multipliers_against_finite_differences_of_the_exact_map(
        delay, width, mu):
    """Chain, the design k(mu; pulse) carried by the pulse of ``width`` centred ``delay``
    after the sample: the pulsed 1/1 branch is a fixed point of the exact pulsed ModalMap
    (1e-13), and the multipliers of the finite-difference Jacobian of that map at the
    orbit approach the design's limit spectrum like |Delta d|^(1/2) (measured ratio
    err / sqrt|Delta d| 0.48 ... 0.68)."""
    check_limit_against_the_exact_map(nd.Actuation(delay, width), mu, delay, width)


def test_actuator_design_limit_multipliers_against_finite_differences_of_the_actuated_map():
    """Chain, the design k(0; pulse of width 1 centred at 4 through tau_a = 0.2, L = 0.1):
    the (2n + 1)-state actuated map's 1/1 orbit (Newton from the ideal pulse's branch,
    one impact), the multipliers of its fourth-order finite-difference Jacobian: the 2n
    largest approach the design's limit spectrum like |Delta d|^(1/2) (measured 5.8e-3,
    5.8e-4, 5.7e-5 at Delta d = -1e-4, -1e-6, -1e-8), the force's own is ~0. The force
    left after the grazing phase (a share e^{-(T - s - 4.6) / 0.2} ~ 1e-16 here) is not in
    the design (§15): for a slow actuator it limits the approach (tau_a = 0.5: error
    6.5e-3 at -1e-8; tau_a = 1: 0.54 at -1e-6)."""
    from grazing_control.dynamics.simulation.actuation import newton_fixed_point

    m0 = load_model(CHAIN)
    pulse = nd.Actuation(4.0, 1.0, 0.2, 0.1)
    k = nd.gain_family(m0, 0.0, pulse)
    limit = nd.limit_multipliers(m0, 0.0, pulse)
    ideal = nd.Actuation(4.0, 1.0)
    for dd in (-1e-4, -1e-6, -1e-8):
        m = dataclasses.replace(m0, delta_d=dd)
        flow = NdofFlow.of(m)
        bp = modal_branch.orbit_at(m, nd.gain_family(m0, 0.0, ideal), dd, delay=ideal)

        def step(y):
            z, f, imps = actuated_step(flow, y[:4], y[4], float(k @ y[:4]),
                                       start=pulse.start(m), width=1.0, time_constant=0.2,
                                       latency=0.1)
            return np.append(z, f), imps

        y, imps, _res, _jac = newton_fixed_point(step, np.append(bp.pi2_state, 0.0),
                                                 1e-2 * bp.v_minus ** 2)
        h = 1e-2 * imps[0].v_minus ** 2
        y, imps, res, _jac = newton_fixed_point(step, y, h)
        assert res <= 1e-13 and len(imps) == 1
        jac = np.zeros((5, 5))
        for j in range(5):
            e = np.zeros(5)
            e[j] = h

            def f(t):
                return step(y + t * e)[0]

            jac[:, j] = (8.0 * (f(1) - f(-1)) - (f(2) - f(-2))) / (12.0 * h)
        lam = np.linalg.eigvals(jac)
        lam = lam[np.argsort(-np.abs(lam))]
        err = _match(lam[:4], limit)
        assert 0.05 < err / math.sqrt(-dd) < 20.0, (dd, err)
        assert abs(lam[4]) < 1e-6
    assert err < 1e-4


def test_pulse_design_entry_point_and_gain_file(tmp_path):
    import yaml

    m = load_model(CHAIN)
    d = nd.pulse_design(m, 0.0, 4.0, 1.0, 0.2, 0.1)
    assert np.array_equal(d.gains, nd.gain_family(m, 0.0, nd.Actuation(4.0, 1.0, 0.2, 0.1)))
    assert np.array_equal(nd.pulse_design(m, 0.1, 4.0).gains, nd.gain_family(m, 0.1, 4.0))
    nd.write_gain_yaml(tmp_path / "k.yaml", m, d, CHAIN)
    par = yaml.safe_load((tmp_path / "k.yaml").read_text())["/**"]["ros__parameters"]
    assert (par["actuation_delay"], par["pulse_width"], par["actuator_bandwidth"],
            par["actuator_latency"]) == (4.0, 1.0, 1.0 / 0.2, 0.1)


def test_pulses_that_do_not_fit_are_refused_naming_the_width():
    m = load_model(CHAIN)
    reach = m.period - m.pi2_offset / m.omega
    with pytest.raises(ParameterError, match="width=.*valid range is start \\+ latency \\+ "
                                             "width < T - s"):
        nd.gain_family(m, 0.0, nd.Actuation(reach - 0.5, 2.0))
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ParameterError, match="width="):
            nd.Actuation(1.0, bad)
        with pytest.raises(ParameterError, match="width="):
            ModalMap(m, nd.gain_family(m, 0.0), 1.0, bad)
    for bad in (m.period, 1e308, "x", None, True):
        with pytest.raises(ParameterError, match="width=.* is invalid: valid range is a finite "
                                                 "width, 0 <= width < T"):
            ModalMap(m, nd.gain_family(m, 0.0), 1.0, bad)
    rigid = dataclasses.replace(m, K=[[1.0, -1.0], [-1.0, 1.0]])
    with pytest.raises(ParameterError, match="K is invalid for a force pulse"):
        pulse_step(NdofFlow.of(rigid), np.zeros(4), 0.1, start=1.0, width=1.0)

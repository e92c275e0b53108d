"""The explicit n-DOF 1/1 branch (docs/theory_ndof.md §5, §7; the pulse's, §18) against the
exact period map ModalMap (with the pulse: ModalMap(width), the integrated flow, shooting
on random models), the 1-DOF branch for n = 1, and its own Taylor coefficients."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.orbits import modal_branch as nb

from grazing_control.dynamics.design import family as nd

from grazing_control.dynamics.orbits import orbits
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.params import OscillatorParams, ParameterError

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
CHAIN = MODELS / "two_mass_chain.yaml"


@pytest.mark.parametrize("gains", ["design", "none", "bad"])
def test_branch_orbit_is_a_fixed_point_of_the_exact_period_map(gains):
    """The Pi2 state of a branch point, stepped once by ModalMap at its Delta d, returns to
    itself with one impact of the same v-, and the exact Jacobian has the branch's
    multipliers."""
    base = load_model(CHAIN)
    k = {"design": nd.gain_family(base, 0.2), "none": np.zeros(4),
         "bad": nd.cancel_first_markov(base, 0.2, 0.5, smooth_branch=False)}[gains]
    v1 = nb.branch_coefficients(base, k)[2]
    for psi in (1e-2, 1e-4):
        bp = nb.orbit_at_phase(base, k, math.copysign(psi, v1))
        assert bp.v_minus > 0
        step = ModalMap(dataclasses.replace(base, delta_d=bp.delta_d), k).step(bp.pi2_state, True)
        # the core works with physical states of size ~ d* = 3.2: absolute rounding ~1e-15
        assert np.abs(step.state - bp.pi2_state).max() < 1e-14 + 1e-12 * np.abs(bp.pi2_state).max()
        assert len(step.impacts) == 1
        assert step.impacts[0].v_minus == pytest.approx(bp.v_minus, rel=1e-9)
        ours = np.sort_complex(np.linalg.eigvals(bp.monodromy))
        theirs = np.sort_complex(np.linalg.eigvals(step.jacobian))
        assert np.abs(ours - theirs).max() < 1e-10 * np.abs(ours).max() / bp.v_minus


def test_n1_branch_is_the_1dof_branch():
    m = load_model(MODELS / "study_1dof.yaml")
    p = OscillatorParams(zeta=0.01, r=m.r, omega=m.omega, pi2_offset=m.pi2_offset)
    for gains in (None, Gains(-0.3, -1.0)):
        k = np.zeros(2) if gains is None else np.array([gains.c1, gains.c2])
        for psi in (0.05, -1e-3, 1e-6):
            dd, v, _m = orbits.wall_offset_at_phase(p, psi, gains)
            bp = nb.orbit_at_phase(m, k, psi)
            assert bp.delta_d == pytest.approx(dd, rel=1e-9, abs=1e-15 * abs(v))
            assert bp.v_minus == pytest.approx(v, rel=1e-10)


def test_branch_coefficients_are_the_taylor_coefficients():
    """Delta d = d1 psi - gamma1 psi^2 + ..., v- = v1 psi + ...: for gains off the family
    (d1 != 0) and on it (d1 = 0), checked by symmetric quotients of the exact branch."""
    base = load_model(CHAIN)
    for k in (np.zeros(4), nd.gain_family(base, -0.1),
              nd.cancel_first_markov(base, 0.2, 0.5, smooth_branch=True)):
        d1, g1, v1 = nb.branch_coefficients(base, k)
        h = 1e-4
        a, b = nb.orbit_at_phase(base, k, h), nb.orbit_at_phase(base, k, -h)
        assert (a.delta_d - b.delta_d) / (2 * h) == pytest.approx(d1, rel=1e-6, abs=1e-6)  # + O(h^2)
        assert -(a.delta_d + b.delta_d) / (2 * h * h) == pytest.approx(g1, rel=1e-5)
        assert (a.v_minus - b.v_minus) / (2 * h) == pytest.approx(v1, rel=1e-7)


def test_bad_psi_and_no_orbit_are_refused():
    base = load_model(CHAIN)
    k = nd.gain_family(base, 0.2)
    with pytest.raises(ParameterError, match="psi"):
        nb.orbit_at_phase(base, k, base.pi2_offset + 0.01)
    with pytest.raises(ValueError, match="no 1/1 orbit"):
        nb.orbit_at(base, k, 1e-6)       # gamma1 > 0: none on the non-impacting side


# ------------------------------------------------------------------ the branch's fold
def test_the_fold_of_the_chain_branch_has_the_multiplier_one_and_is_an_exact_orbit():
    """The chain at omega 0.8 (tests/models): its branch born at grazing (on Delta d > 0)
    turns back at a fold. There Delta d(psi) is extremal, the monodromy has the
    multiplier 1, and one period of the exact map (ModalMap) returns to the orbit."""
    m = load_model(Path(__file__).parent / "models" / "two_mass_chain_w08.yaml")
    fold = nb.branch_fold(m, None)
    assert fold is not None and fold.v_minus > 0.0
    lam = np.linalg.eigvals(fold.monodromy)
    assert np.min(np.abs(lam - 1.0)) < 1e-6, lam
    for h in (1e-3, -1e-3):                       # a maximum of Delta d(psi)
        assert nb.orbit_at_phase(m, np.zeros(4), fold.psi + h).delta_d < fold.delta_d
    step = ModalMap(dataclasses.replace(m, delta_d=fold.delta_d)).step(fold.pi2_state)
    assert len(step.impacts) == 1
    assert np.max(np.abs(step.state - fold.pi2_state)) < 1e-12 * max(1.0, np.abs(fold.pi2_state).max())


def test_for_n_1_the_fold_is_the_turning_point_of_the_1dof_closed_form_branch():
    """n = 1: the turning point of Delta d(psi) found by branch_fold equals the extremum
    of the 1-DOF core's explicit branch (orbits.wall_offset_at_phase, an independent closed form)
    located on a dense grid and refined by a parabola, to 1e-9 relative."""
    from grazing_control.dynamics.orbits import orbits

    m = load_model(MODELS / "study_1dof.yaml")
    fold = nb.branch_fold(m, None)
    p = OscillatorParams(zeta=0.01, r=m.r, omega=m.omega, delta_d=0.0)
    psi = fold.psi + np.linspace(-1e-3, 1e-3, 41)
    dd = np.array([orbits.wall_offset_at_phase(p, float(x))[0] for x in psi])
    i = int(np.argmax(dd) if dd[20] > dd[0] else np.argmin(dd))
    c = np.polyfit(psi[i - 2:i + 3] - psi[i], dd[i - 2:i + 3], 2)
    extremum = c[2] - c[1] ** 2 / (4.0 * c[0])
    assert abs(fold.delta_d - extremum) < 1e-9 * abs(extremum)


def test_continue_names_the_fold_where_it_stops(capsys):
    """`grazing continue --model` on the chain at omega 0.8 from 1e-3 towards 0.1: the
    continuation in Delta d stops at the turning point, and the command names the fold
    (the explicit branch's) beyond its last point."""
    import json

    from grazing_control import cli

    path = Path(__file__).parent / "models" / "two_mass_chain_w08.yaml"
    assert cli.main(["continue", "--model", str(path), "--from", "1e-3", "--to", "0.1",
                     "--json"]) in (0, None)
    out = json.loads(capsys.readouterr().out)
    fold = nb.branch_fold(load_model(path), None)
    assert out["fold"] is not None and out["fold"]["delta_d"] == pytest.approx(fold.delta_d,
                                                                             rel=1e-12)
    assert out["branch"][-1]["delta_d"] < out["fold"]["delta_d"]


@pytest.mark.parametrize("s, grazing", [(0.3, False), (1e6, False), (1e12, False),
                                        (1e6, True), (1e12, True)])
def test_structured_multipliers_are_the_eigenvalues_of_b_plus_s_p_q(s, grazing):
    """B + s p q^T for a random 6x6 B, p, q, against mpmath's eigenvalues at 60 digits:
    every multiplier to 1e-13 relative. numpy on the assembled matrix errs by ~eps s
    (measured here: 7.5e-9 relative at s = 1e6, 1.7e-3 at 1e12). ``grazing``: p with
    q^T B^-1 p = 0, so det J = det B while one multiplier grows like s, and another
    goes to 0 like 1/s (the near-grazing structure): that one comes from the
    determinant."""
    from mpmath import mp

    rng = np.random.default_rng(7)
    B, p, q = rng.normal(size=(6, 6)), rng.normal(size=6), rng.normal(size=6)
    if grazing:
        u = rng.normal(size=6)
        x = np.linalg.solve(B, p)
        p = p - B @ u * (q @ x) / (q @ u)
    with mp.workdps(60):
        J = mp.matrix(B.tolist()) + mp.mpf(s) * mp.matrix(p.tolist()) * mp.matrix(q.tolist()).T
        want = [complex(z) for z in mp.eig(J, left=False, right=False)]
        det = float(mp.det(J))
    got = nb.structured_multipliers(B, p, q, s, det)
    assert got.size == 6 and np.all(np.diff(np.abs(got)) <= 0.0)
    for w in want:
        assert np.min(np.abs(got - w)) <= 1e-13 * abs(w), (w, got)
    assert all(np.any(got == np.conj(z)) for z in got)      # exact conjugate pairs
    if grazing:
        assert abs(got[-1]) < 1e-3 * abs(got[-2])          # the determinant's multiplier


def test_the_walk_to_the_orbit_is_the_same_at_every_delta_d():
    """orbit_at's walk in psi is made once per model content but Delta d (modal_branch._psi_walk,
    issue 30's suite CPU): the orbit found at one Delta d after a walk made at another is,
    bit for bit, the one found after a walk of its own (orbit_at_phase does not read
    model.delta_d), with the kick on Pi2 and 4.0 after it."""
    from test_compliant_flow_bits import _canonical

    base = load_model(CHAIN)
    k = nd.gain_family(base, 0.0)
    for delay in (0.0, 4.0):
        dds = [-1e-4, -3e-7]
        alone = []
        for dd in dds:
            nb._WALKS.clear()
            alone.append(nb.orbit_at(dataclasses.replace(base, delta_d=dd), k, dd, delay=delay))
        nb._WALKS.clear()
        nb.orbit_at(dataclasses.replace(base, delta_d=0.5 * dds[0]), k, 0.5 * dds[0], delay=delay)
        walked = [nb.orbit_at(dataclasses.replace(base, delta_d=dd), k, dd, delay=delay)
                  for dd in dds]
        assert len(nb._WALKS) == 2         # one walk a side, both sides asked for
        for a, b in zip(alone, walked):    # every float of the point, arrays too
            assert _canonical([np.asarray(x).tolist() for x in a]) == \
                _canonical([np.asarray(x).tolist() for x in b])


# ------------------------------------------------------------------ the pulse (§18)
#: The 3-mass chain of the issue: M diag(1, 1.2, 0.9), the wall on x0, forced and
#: actuated on x2 (its design with the pulse of width 0.5 centred 0.5 is admissible).
THREE = dict(M=np.diag([1.0, 1.2, 0.9]),
             C=np.array([[0.05, -0.02, 0.0], [-0.02, 0.05, -0.02], [0.0, -0.02, 0.05]]),
             K=np.array([[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 2.2]]),
             f=np.array([0.0, 0.0, 1.0]), omega=0.45, i_w=0, r=0.7, i_a=2, phase=0.0,
             pi2_offset=1.5, delta_d=0.0)


def _pulse_case(which):
    """(model, Actuation, k) of the pulse designs checked: the chain with the pulse of
    width 1 centred 1 after the sample (mu -0.17, the middle of its admissible set) and
    the 3-mass chain with width 0.5 centred 0.5 (mu 0.73, the middle of (0.647, 0.810))."""
    from grazing_control.oscillator.ndof.model import NdofModel

    if which == "chain":
        m, act, mu = load_model(CHAIN), nd.Actuation(1.0, 1.0), -0.1698021039256156
    else:
        m, act, mu = NdofModel(**THREE), nd.Actuation(0.5, 0.5), 0.7285532188753283
    return m, act, nd.gain_family(m, mu, act)


@pytest.mark.parametrize("which", ["chain", "three"])
def test_pulse_branch_is_the_orbit_of_the_exact_pulsed_map(which):
    """The branch with the pulse's b_w (§18, (N14)) against the exact pulsed map
    ModalMap(model, k, delay, width) (the pulse flowed with impacts), -1e-3 .. -1e-10:

    * the fixed-point residual |P(z) - z| is rounding (1e-13 absolute on states ~ d*;
      measured <= 8e-14), one impact after the pulse with the same v-, and the map's
      Jacobian is the branch's B + s p q^T (1e-8 of its norm ~ 1/v-; measured 3e-14 ..
      3.4e-9, as the map's own v- from its event search: 3.3e-9 off at v- = 5e-6);
    * where shooting converges (-1e-3 .. -1e-6) Newton from the branch state stays there
      (1e-11 relative; measured <= 6e-13) and LAPACK's multipliers of its monodromy are
      the branch's to 1e-10 of max(1, |lambda|) at -1e-3, -1e-4 and 1e-8 at -1e-6, where
      they lose ~eps ||J|| ~ eps / v- (measured <= 3e-9);
    * fourth-order differences of the exact map (step 1e-3 v-^2): the Jacobian to 1e-7
      of its norm (measured <= 1.7e-8), and at -1e-4 the multipliers to 1e-5 (measured
      1.1e-9 chain, 2.9e-6 three: an error ||dJ|| ~ 1/v- moves them by kappa ||dJ||)."""
    from grazing_control.dynamics.orbits.shooting import find_periodic
    from test_family import _match
    from test_ndof_delay import _fd_jacobian

    m0, act, k = _pulse_case(which)
    for dd in (-1e-3, -1e-4, -1e-6, -1e-8, -1e-10):
        m = dataclasses.replace(m0, delta_d=dd)
        bp = nb.orbit_at(m, k, dd, delay=act)
        assert nb.other_contacts(m, k, bp, act) == 0
        lam = nb.branch_multipliers(m, k, bp, act)
        B, p, q, s = nb.pi2_factors(m, k, bp, act)
        mono = B + s * np.outer(p, q)
        P = ModalMap(m, k, act.delay, act.width)
        step = P.step(bp.pi2_state, jacobian=True)
        assert len(step.impacts) == 1 and step.impacts[0].dt > act.end(m)
        assert step.impacts[0].v_minus == pytest.approx(bp.v_minus, rel=1e-6)
        assert np.max(np.abs(step.state - bp.pi2_state)) <= 1e-13
        assert np.max(np.abs(step.jacobian - mono)) <= 1e-8 * np.abs(mono).max()
        if dd <= -1e-6:
            o = find_periodic(P, bp.pi2_state)
            assert len(o.impacts) == 1
            scale = np.max(np.abs(bp.pi2_state))
            assert np.max(np.abs(o.state - bp.pi2_state)) <= 1e-11 * scale
            err = _match(np.linalg.eigvals(o.monodromy), lam) / max(1.0, np.abs(lam).max())
            assert err <= (1e-10 if dd <= -1e-4 else 1e-8), (dd, err)
        if dd in (-1e-4, -1e-6):
            fd = _fd_jacobian(P, bp.pi2_state, 1e-3 * bp.v_minus ** 2)
            assert np.max(np.abs(fd - mono)) <= 1e-7 * np.abs(mono).max()
            if dd == -1e-4:
                assert _match(np.linalg.eigvals(fd), lam) <= 1e-5


def _deviation_flow(model, z0, pieces):
    """The deviation z' = A z + B F by DOP853 (rtol 1e-13) over ``pieces`` (duration,
    force) in turn, away from the wall: the forced linear flow of §15 integrated, not
    Phi's closed form."""
    from scipy.integrate import solve_ivp

    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.oscillator.ndof.forced import force_input

    flow = NdofFlow.of(model)
    a, b = flow.A, force_input(flow)
    z = np.array(z0, dtype=float)
    for duration, force in pieces:
        if duration > 0.0:
            sol = solve_ivp(lambda t, y, f=force: a @ y + b * f, (0.0, duration), z,
                            method="DOP853", rtol=1e-13, atol=1e-16)
            z = sol.y[:, -1]
    return z


@pytest.mark.parametrize("which", ["chain", "three"])
def test_the_pulse_is_a_jump_on_a_later_section_and_the_branch_is_periodic_under_it(which):
    """(N13) and (N14) against the integrated flow (DOP853, not Phi's closed form): the
    pulse F = m_a Delta v / w from rest moves the deviation to beta Delta v at its end,
    beta = (I - Phi(w)) sigma m_a / w (1e-10 relative; measured 2e-15); and from the
    branch orbit's state just after its impact, sigma to Pi2, the pulse of the sample's
    k^T z on [s0, s0 + w] after it and the rest of the period bring the deviation back
    to the state just before the impact, z- = M(psi) z+ (1e-9 relative; measured
    <= 1.4e-13)."""
    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.oscillator.ndof.forced import actuated_mass, static_deflection

    m0, act, k = _pulse_case(which)
    flow = NdofFlow.of(m0)
    ma, w, s0 = actuated_mass(flow), act.width, act.start(m0)
    beta = (np.eye(2 * m0.n) - flow.transition(w)) @ static_deflection(flow) * ma / w
    got = _deviation_flow(m0, np.zeros(2 * m0.n), [(w, ma / w)])
    assert np.max(np.abs(got - beta)) <= 1e-10 * np.abs(beta).max()
    for dd in (-1e-3, -1e-6):
        m = dataclasses.replace(m0, delta_d=dd)
        bp = nb.orbit_at(m, k, dd, delay=act)
        sigma = (m.pi2_offset - bp.psi) / m.omega
        z_plus = np.array(bp.state)
        z_plus[m.n + m.i_w] -= (1.0 + m.r) * bp.v_minus
        z2 = _deviation_flow(m, z_plus, [(sigma, 0.0)])
        assert np.max(np.abs(z2 - bp.pi2_state)) <= 1e-10 * np.abs(z2).max()
        force = ma * float(k @ z2) / w
        back = _deviation_flow(m, z2, [(s0, 0.0), (w, force), (m.period - sigma - s0 - w, 0.0)])
        assert np.max(np.abs(back - bp.state)) <= 1e-9 * np.abs(bp.state).max()


def test_a_contact_inside_the_pulse_takes_the_orbit_off_the_branch():
    """The global check flows the pulse (§18): a random 3-mass model (seed 2107) with the
    pulse of width 0.3 R centred 0.5 R (R = T - s), mu 0.5, at Delta d = -0.03: the
    branch point of that Delta d meets the wall once more, inside the pulse (the exact
    pulsed map from its Pi2 state has its impact in [start, end]); other_contacts counts
    it, and the one entry does not return that point as an orbit (it finds another
    1/1 orbit, v- = 0.30, by shooting from a simulation)."""
    from grazing_control.dynamics.orbits import one_one
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound
    from test_family import _random_model

    m0 = _random_model(2107, n=3)
    reach = m0.period - m0.pi2_offset / m0.omega
    act = nd.Actuation(0.35 * reach, 0.3 * reach)
    k = nd.gain_family(m0, 0.5, act)
    m = dataclasses.replace(m0, delta_d=-0.03)
    bp = nb.orbit_at(m, k, -0.03, psi_max=1.0, delay=act)
    assert bp.v_minus > 0.0 and nb.other_contacts(m, k, bp, act) == 1
    step = ModalMap(m, k, act.delay, act.width).step(bp.pi2_state)
    assert any(act.start(m) <= i.dt <= act.end(m) for i in step.impacts)
    try:
        got = one_one.orbit(m, k, delay=act.delay, width=act.width)
    except OrbitNotFound:
        return
    assert got.route != one_one.EXPLICIT
    assert np.max(np.abs(got.state - bp.pi2_state)) > 1e-6


def test_random_pulse_branches_against_shooting():
    """A differential test over 60 seeded random models (2 and 3 masses, full M and K),
    pulses (delay in [0, 0.7 R), width up to 0.9 of what fits before the grazing phase),
    family members mu in (-0.6, 0.6), at Delta d = +-1e-3, +-1e-5: every branch orbit
    found (116 of the 240 cases: the other side has none) is checked globally and,
    from its state, Newton shooting on the exact pulsed map converges to it (1e-11 of
    the state; measured 6.7e-14) with one impact and the same multipliers (1e-9 of
    max(1, |lambda|); measured 5.6e-10 where |lambda| ~ 30, LAPACK's eps ||J||)."""
    from grazing_control.dynamics.orbits.shooting import find_periodic
    from test_family import _match, _random_model

    compared = 0
    for seed in range(60):
        rng = np.random.default_rng(1000 + seed)
        m0 = _random_model(1000 + seed, n=2 + seed % 2)
        reach = m0.period - m0.pi2_offset / m0.omega
        delay = float(rng.uniform(0.0, 0.7 * reach))
        width = float(rng.uniform(0.05, 1.0) * min(reach, 2 * (reach - delay)) * 0.9)
        act = nd.Actuation(delay, width)
        k = nd.gain_family(m0, float(rng.uniform(-0.6, 0.6)), act)
        for dd in (-1e-3, -1e-5, 1e-3, 1e-5):
            m = dataclasses.replace(m0, delta_d=dd)
            try:
                bp = nb.orbit_at(m, k, dd, delay=act)
            except (ValueError, ParameterError):
                continue
            assert nb.other_contacts(m, k, bp, act) == 0
            lam = nb.branch_multipliers(m, k, bp, act)
            o = find_periodic(ModalMap(m, k, delay, width), bp.pi2_state)
            assert len(o.impacts) == 1
            scale = max(1.0, np.abs(bp.pi2_state).max())
            assert np.max(np.abs(o.state - bp.pi2_state)) <= 1e-11 * scale, (seed, dd)
            err = _match(np.linalg.eigvals(o.monodromy), lam)
            assert err <= 1e-9 * max(1.0, np.abs(lam).max()), (seed, dd, err)
            compared += 1
    assert compared >= 100

"""The explicit n-DOF 1/1 branch (docs/theory_ndof.md §5, §7) against the exact period
map ModalMap, the 1-DOF branch for n = 1, and its own Taylor coefficients."""

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

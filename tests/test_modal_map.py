"""Tests of grazing_control.dynamics.maps.modal_map: the n-DOF Pi2 map as a PeriodMap.

Yardsticks: the 1-DOF core (the n = 1 model file against OneDOF and orbit_11), the
50-digit reference of tests/reference_ndof.py (states, impacts, central-difference
Jacobians, the 1/1 orbit and its multipliers), an explicit impact-phase construction of
the 1/1 orbit (a linear solve, no shooting), and the determinant formula.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from mpmath import mpf
from scipy.optimize import brentq

from grazing_control.dynamics.orbits.continuation import continue_orbit
from grazing_control.dynamics.maps.model import OneDOF, PeriodMap
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.orbits.shooting import (bifurcation_tests, find_periodic,
                                               floquet_multipliers, iterate)
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from reference_ndof import load_reference

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
CHAIN = Path(__file__).parent / "models" / "two_mass_chain_w08.yaml"   # pinned: see the file
STUDY = MODELS / "study_1dof.yaml"


SHIPPED = MODELS / "two_mass_chain.yaml"    # the shipped example (omega 0.5)


def _chain(gains=None, path=CHAIN, **changes):
    return ModalMap(dataclasses.replace(load_model(path), **changes), gains)


# ----------------------------------------------------------------- the protocol
def test_is_a_period_map_with_named_coordinates_and_parameters():
    m = _chain([0.1, -0.2, 0.3, 0.4], delta_d=-1e-3)
    assert isinstance(m, PeriodMap)
    assert m.dimension == 4 and m.period == pytest.approx(2 * math.pi / 0.8, rel=1e-15)
    assert m.section_phase == m.flow.tau2
    assert m.coordinates == ("x0 - x0**", "x1 - x1**", "v0 - v0**", "v1 - v1**")
    assert np.array_equal(m.grazing_state(), np.zeros(4))
    assert m.parameter("delta_d") == -1e-3 and m.parameter("r") == 0.68
    assert m.parameter("k2") == 0.3
    assert m.with_parameter("k2", 0.5).parameter("k2") == 0.5
    assert m.with_parameter("delta_d", -1e-5).parameter("delta_d") == -1e-5
    assert m.with_parameter("omega", 0.9).flow.d_star != m.flow.d_star
    assert m.with_parameter("r", 0.5).parameter("k3") == 0.4  # the gains stay


@pytest.mark.parametrize("call,match", [
    (lambda m: m.parameter("nope"), "'nope' is invalid: valid names are delta_d, omega, r"),
    (lambda m: m.parameter("k4"), "k4"),
    (lambda m: m.with_parameter("r", 1.5), "r=1.5 is invalid"),
    (lambda m: m.with_parameter("omega", -1.0), "omega=-1.0 is invalid"),
    (lambda m: ModalMap(m.model, [1.0, 2.0]), r"gains=\[1.0, 2.0\] is invalid: valid range is 2n = 4 finite"),
    (lambda m: ModalMap(m.model, [1.0, 2.0, np.inf, 0.0]), "gains"),
    (lambda m: m.step([0.0, 0.0]), "2n = 4"),
    (lambda m: ModalMap(m.model).parameter("k0"), "without gains"),
])
def test_bad_parameters_raise_parameter_error(call, match):
    with pytest.raises(ParameterError, match=match):
        call(_chain([0.0] * 4, delta_d=-1e-3))


def test_jacobian_det_is_the_product_formula():
    """det DP^n = e^{tr(A) n T} r^(2m) (1 + k_{n+i_a})^n against numpy's determinant of
    the map's Jacobian along trajectories with 0, 1 and 2 impacts per period."""
    rng = np.random.default_rng(81)
    seen = set()
    for gains in (None, [0.3, -0.2, 0.1, 0.45]):
        m = _chain(gains, delta_d=-0.01)
        z = 0.01 * rng.normal(size=4)
        for periods in (1, 3):
            for _ in range(5):
                zn, jac, imps = iterate(m, z, periods)
                exact = m.jacobian_det(periods, len(imps))
                assert abs(np.linalg.det(jac) / exact - 1) < 1e-8
                seen.add(len(imps) // periods)
                z = zn
    assert {0, 1, 2} <= seen or len(seen) >= 2


# ------------------------------------------------------- n = 1 reproduces the 1-DOF core
def _one_dof(gains):
    m = load_model(STUDY)
    p = OscillatorParams(zeta=0.5 * m.C[0, 0], r=m.r, omega=m.omega, delta_d=m.delta_d,
                         pi2_offset=m.pi2_offset)
    return ModalMap(m, gains), OneDOF(p, None if gains is None else Gains(*gains))


@pytest.mark.parametrize("gains", [None, (-0.15, 0.25)])
def test_n1_model_file_reproduces_the_1dof_pi2_map(gains):
    """config/models/study_1dof.yaml with gains (k0, k1) = (c1, c2): along 400 iterates of
    the 1-DOF map at Delta d = -5e-6 (near grazing, chaotic uncontrolled) every step from
    the same state agrees with OneDOF: states to 1e-12 (measured 6e-15), impact times to
    1e-12 (measured 7e-15), v- to 1e-12 (measured 6e-15), Jacobians to 1e-12 + 1e-14 / v-
    relative (measured 2.1e-12 at v- = 2.9e-3, 1.4e-13 controlled). The Jacobian's
    singular column is (1 + r) a / v-, and both cores find v- to ~1e-15 absolute (the
    rounding of the impact time and phase: over 98 impacts the RMS error of v- against the
    50-digit tests/reference.py is 1.1e-15 here and 1.4e-15 in the 1-DOF core), hence the
    1e-14 / v- term; at the worst step both Jacobians are within it of the exact one."""
    from reference import RefModel

    nd, od = _one_dof(gains)
    z = np.array([2e-4, -1e-4])
    impacts, v_low, worst = 0, math.inf, (0.0, None, None)
    for _ in range(400):
        a, b = nd.step(z, jacobian=True), od.step(z, jacobian=True)
        assert len(a.impacts) == len(b.impacts)
        assert np.abs(a.state - b.state).max() < 1e-12
        v_min = min((i.v_minus for i in b.impacts), default=math.inf)
        err = np.abs(a.jacobian - b.jacobian).max() / np.abs(b.jacobian).max()
        assert err < 1e-12 + 1e-14 / v_min
        if err > worst[0]:
            worst = (err, z, a.jacobian, b.jacobian, v_min)
        for x, y in zip(a.impacts, b.impacts):
            assert abs(x.dt - y.dt) < 1e-12 and abs(x.v_minus - y.v_minus) < 1e-12
            v_low = min(v_low, y.v_minus)
        impacts += len(a.impacts)
        z = b.state
    assert impacts > 300 and v_low < 1e-2
    # the worst step against the 50-digit 1-DOF reference (central differences, 1e-20)
    _err, z, Jn, J1, v_min = worst
    ref = RefModel.from_params(od.params)
    h, J = mpf("1e-20"), np.zeros((2, 2))
    for j in range(2):
        d = [mpf(0), mpf(0)]
        d[j] = h
        (xp, vp), _ = ref.pi2_map(ref.x_ref + mpf(z[0]) + d[0], ref.v_ref + mpf(z[1]) + d[1], gains=gains)
        (xm, vm), _ = ref.pi2_map(ref.x_ref + mpf(z[0]) - d[0], ref.v_ref + mpf(z[1]) - d[1], gains=gains)
        J[:, j] = [float((xp - xm) / (2 * h)), float((vp - vm) / (2 * h))]
    for jac in (Jn, J1):
        assert np.abs(jac - J).max() < (1e-12 + 1e-14 / v_min) * np.abs(J).max()


def test_n1_1_1_orbit_and_multipliers_are_the_1dof_ones():
    """find_periodic + floquet_multipliers on the n = 1 ModalMap give orbit_11's state and
    multipliers to 1e-10, uncontrolled and controlled, from Delta d = -1e-3 to -1e-6."""
    for gains in (None, (-0.1, 0.1)):
        for dd in (-1e-3, -1e-5, -1e-6):
            nd, od = _one_dof(gains)
            nd = nd.with_parameter("delta_d", dd)
            ref = orbit_11(od.params.with_(delta_d=dd), od.gains)
            guess = np.array(ref.pi2_deviation) * (1 + 1e-6)
            o = find_periodic(nd, guess)
            lam = floquet_multipliers(o.monodromy)
            assert np.abs(o.state - np.array(ref.pi2_deviation)).max() < 1e-10 * np.abs(o.state).max()
            exact = np.sort_complex(ref.multipliers)
            assert np.abs(np.sort_complex(lam) - exact).max() < 1e-10 * np.abs(exact).max()


# -------------------------------------------------------------- 2-mass vs the reference
@pytest.mark.parametrize("delta_d,gains", [(-0.05, None), (-1e-4, [0.2, -0.1, 0.3, 0.25])])
def test_step_and_jacobian_match_mpmath(delta_d, gains):
    """One step of the 2-mass map from a near-grazing state: the state to 1e-12 of its
    size, the impacts (times to 1e-12 T, v- to 1e-11 relative), and the Jacobian against
    the 50-digit central differences of the reference map (step 1e-15) to 1e-10."""
    m = _chain(gains, delta_d=delta_d)
    ref = load_reference(CHAIN, delta_d=delta_d)
    z = np.array([0.2, -0.3, 0.1, 0.4]) * abs(delta_d)
    s = m.step(z, jacobian=True)
    zr, imps = ref.pi2_map(list(z), gains)
    zr = np.array([float(x) for x in zr])
    assert len(imps) == len(s.impacts) >= 1
    assert np.abs(s.state - zr).max() < 1e-12 * np.abs(zr).max()
    for a, (t, _phase, vm, _vp) in zip(s.impacts, imps):
        assert abs(a.dt - float(t)) < 1e-12 * m.period and abs(a.v_minus / float(vm) - 1) < 1e-11
    J = np.array(ref.jacobian(list(z), gains).tolist(), dtype=float)
    assert np.abs(s.jacobian - J).max() < 1e-10 * np.abs(J).max()


def _branch(m: ModalMap):
    """The uncontrolled 1/1 orbit explicit in its impact phase tau* + psi (no shooting):
    just before the impact z- = Phi(T) (R z- + c), c the affine part of the reset
    v_w -> -r v_w in deviation coordinates, a linear solve; Delta d is then the wall
    position of z-, the orbit's Pi2 state the flow from the impact. Returns
    psi -> (Delta d, v-, Pi2 state)."""
    model, flow = m.model, m.flow
    n, w, r = model.n, model.i_w, model.r
    R = np.eye(2 * n)
    R[n + w, n + w] = -r
    phi = flow.transition(model.period)

    def at(psi):
        vp = -flow.d_star * model.omega * math.sin(psi)
        c = np.zeros(2 * n)
        c[n + w] = -(1 + r) * vp
        zm = np.linalg.solve(np.eye(2 * n) - phi @ R, phi @ c)
        dd = zm[w] - 2 * flow.d_star * math.sin(psi / 2) ** 2
        s = ((flow.tau2 - flow.tau_star - psi) % (2 * math.pi)) / model.omega
        return dd, vp + zm[n + w], flow.transition(s) @ (R @ zm + c)

    return at


def _branch_side(m):
    """(sign of psi, sign of Delta d) of the 1/1 branch born at grazing with v- > 0."""
    at = _branch(m)
    sgn = -1.0 if at(-1e-6)[1] > 0 else 1.0
    return sgn, math.copysign(1.0, at(sgn * 1e-6)[0])


def _branch_phase(m, delta_d):
    """The impact phase psi of the branch's orbit at delta_d."""
    at, sgn = _branch(m), _branch_side(m)[0]
    return brentq(lambda p: at(p)[0] - delta_d, sgn * 1e-16, sgn * 0.1, xtol=1e-300, rtol=1e-15)


def _orbit_guess(m, delta_d):
    return _branch(m)(_branch_phase(m, delta_d))


def test_1_1_orbit_near_grazing_and_its_multiplier_growth():
    """The uncontrolled 1/1 orbit born at grazing, found by find_periodic on ModalMap at
    |Delta d| = 1e-4 .. 1e-8 on the side where it exists (for the shipped 2-mass chain,
    omega = 0.8: Delta d > 0, coexisting with the non-impacting orbit; computed here from
    the file), agrees with the explicit impact-phase construction (state to 1e-9, v- to
    1e-6 relative). Its largest multiplier grows like 1 / v-, and v- like the construction
    says: both Delta d and v- are linear in the impact phase (docs/theory_ndof_flow.md
    section 8), so below the crossover |Delta d| << a1^2 / (d*/2) (0.265 for the shipped
    file) the multiplier grows like |Delta d|^(-1), not ^(-1/2). Fitted (measured): -1.0001
    for |lambda|max, +1.0000 for v-."""
    m0 = _chain()
    _sgn, side = _branch_side(m0)
    rows, predicted = [], []
    for e in (4, 5, 6, 7, 8):
        dd = side * 10.0 ** -e
        _, v, guess = _orbit_guess(m0, dd)
        m = m0.with_parameter("delta_d", dd)
        o = find_periodic(m, guess)
        assert len(o.impacts) == 1
        assert np.abs(o.state - guess).max() < 1e-9 * np.abs(guess).max()
        assert abs(o.impacts[0].v_minus / v - 1) < 1e-6
        lam = floquet_multipliers(o.monodromy)
        rows.append((abs(dd), abs(lam[0]), o.impacts[0].v_minus))
        predicted.append(v)
    a = np.log(np.array(rows))
    slope_lam = np.polyfit(a[:, 0], a[:, 1], 1)[0]
    slope_v = np.polyfit(a[:, 0], a[:, 2], 1)[0]
    assert abs(slope_v - np.polyfit(a[:, 0], np.log(predicted), 1)[0]) < 0.02
    assert abs(slope_lam + slope_v) < 0.02
    a1 = _orbit_guess(m0, side * 1e-9)[0] / abs(_branch_phase(m0, side * 1e-9))
    if a1 ** 2 / (0.5 * m0.flow.d_star) > 1e-2:  # the linear regime over the whole fit
        assert abs(slope_lam + 1.0) < 0.02, slope_lam
        assert abs(slope_v - 1.0) < 0.02, slope_v


@pytest.mark.parametrize("path", [CHAIN, SHIPPED], ids=["omega0.8", "shipped"])
@pytest.mark.parametrize("exponent", [3, 6])
def test_1_1_orbit_and_multipliers_match_mpmath(exponent, path):
    """The 1/1 orbit near grazing (|Delta d| = 1e-3, 1e-6) and its four multipliers
    against the 50-digit reference (Newton on the reference map with its 50-digit
    central-difference Jacobian, mpmath eig): state to 1e-10 relative, multipliers to
    1e-10 + 4e-15 / v- of the largest (the float map knows v- to ~1e-15 absolute, and the
    largest multiplier is ~ 1 / v-)."""
    m0 = _chain(path=path)
    side = _branch_side(m0)[1]
    dd = side * 10.0 ** -exponent
    m = m0.with_parameter("delta_d", dd)
    o = find_periodic(m, _orbit_guess(m0, dd)[2])
    lam = floquet_multipliers(o.monodromy)
    ref = load_reference(path, delta_d=dd)
    zs, J, imps = ref.fixed_point(list(o.state))
    assert len(imps) == 1
    zs = np.array([float(x) for x in zs])
    assert np.abs(o.state - zs).max() < 1e-10 * np.abs(zs).max()
    exact = np.array([complex(x) for x in ref.multipliers(J)])
    tol = 1e-10 + 4e-15 / o.impacts[0].v_minus
    assert np.abs(np.sort_complex(lam) - np.sort_complex(exact)).max() < tol * abs(exact[0])


# ---------------------------------------------------------------- continuation
def test_continue_orbit_follows_the_1_1_branch_to_its_grazing_end():
    """continue_orbit in Delta d on ModalMap, from 1e-3 towards and past grazing on the
    branch's side: the branch is followed (the step halving of continue_orbit keeps the
    predictor off the coexisting non-impacting orbit) down to |Delta d| < 1e-9 and ends in
    a 'grazing' event within 1e-9 of Delta d = 0 (measured: points down to 6e-13, the
    event at 4e-13); its multipliers are those of direct shooting from the explicit
    construction to 1e-12 + 1e-14 / v- (two float computations, each ~1e-15 / v-, above)."""
    m0 = _chain()
    side = _branch_side(m0)[1]
    start = side * 1e-3
    br = continue_orbit(m0.with_parameter("delta_d", start), "delta_d",
                        side * np.linspace(1e-3, -2e-4, 7), _orbit_guess(m0, start)[2])
    kinds = [b.type for b in br.bifurcations]
    assert kinds[-1] == "grazing" and abs(br.bifurcations[-1].value) < 1e-9
    assert abs(br.points[-1].value) < 1e-9 and all(p.impacts == 1 for p in br.points)
    checked = [pt for pt in br.points if pt.v_min > 1e-8][::4]
    assert len(checked) >= 4
    for pt in checked:
        o = find_periodic(m0.with_parameter("delta_d", pt.value), _orbit_guess(m0, pt.value)[2])
        lam = floquet_multipliers(o.monodromy)
        assert np.abs(np.sort_complex(lam) - np.sort_complex(pt.multipliers)).max() \
            < (1e-12 + 1e-14 / pt.v_min) * np.abs(lam).max()


def test_continue_orbit_detects_period_doubling_and_neimark_sacker_on_modal_map():
    """The 2-impact attractor of the 2-mass chain at Delta d = -0.01, continued in the
    gain k2 (a kick on v1 from x0 - x0**): a period doubling and a Neimark-Sacker
    bifurcation (prod (lambda_i lambda_j - 1) of shooting.bifurcation_tests) are located;
    direct shooting there gives a multiplier -1, resp. a complex pair of modulus 1, to
    1e-9 (measured: k2 = 0.81718, 1.72758). omega and pi2_offset are pinned here (the file's
    may be retuned)."""
    m = _chain(np.zeros(4), delta_d=-0.01, omega=0.8, pi2_offset=math.pi / 2)
    z = np.zeros(4)
    for _ in range(300):  # settle on the attractor
        z = m.step(z).state
    br = continue_orbit(m, "k2", np.linspace(0.0, 2.0, 11), z)
    assert br.stopped == "end" and all(p.impacts == 2 for p in br.points)
    found = {b.type: b.value for b in br.bifurcations}
    assert set(found) == {"period-doubling", "neimark-sacker"}
    pd, ns = found["period-doubling"], found["neimark-sacker"]
    near = {p.value: p.state for p in br.points}
    for value, kind in ((pd, "pd"), (ns, "ns")):
        guess = near[min(near, key=lambda v: abs(v - value))]
        lam = floquet_multipliers(find_periodic(m.with_parameter("k2", value), guess).monodromy)
        if kind == "pd":
            assert np.min(np.abs(lam + 1.0)) < 1e-9
        else:
            pair = lam[np.abs(lam.imag) > 1e-6]
            assert pair.size == 2 and np.max(np.abs(np.abs(pair) - 1.0)) < 1e-9
            assert math.isfinite(bifurcation_tests(lam)["neimark-sacker"])



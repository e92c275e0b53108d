"""The n-DOF design (docs/theory_ndof.md §3-§9): gain family, transmission zeros, limit
multipliers, existence, admissible mu, the bad gains, and the acceptance of issue 17 on
the shipped two-mass chain against exact shooting on ModalMap."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.optimize import brentq, linear_sum_assignment

from grazing_control.dynamics.design import gains as design

from grazing_control.dynamics.orbits import modal_branch

from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.shooting import find_periodic, floquet_multipliers
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import NdofModel, load_model
from grazing_control.oscillator.params import OscillatorParams, ParameterError

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
CHAIN = MODELS / "two_mass_chain.yaml"
STUDY = MODELS / "study_1dof.yaml"


def _match(a, b) -> float:
    """Largest distance between two multisets of eigenvalues, optimally paired."""
    cost = np.abs(np.subtract.outer(np.asarray(a), np.asarray(b)))
    i, j = linear_sum_assignment(cost)
    return float(cost[i, j].max())


def _random_model(seed: int, n: int | None = None) -> NdofModel:
    rng = np.random.default_rng(seed)
    n = n or int(rng.integers(2, 4))
    a = rng.normal(size=(n, n))
    b = rng.normal(size=(n, n))
    m = a @ a.T + n * np.eye(n)
    k = b @ b.T + 0.5 * np.eye(n)
    return NdofModel(M=m, C=0.03 * m + 0.02 * k, K=k, f=rng.normal(size=n),
                     omega=float(rng.uniform(0.3, 1.5)), i_w=int(rng.integers(n)),
                     i_a=int(rng.integers(n)), r=float(rng.uniform(0.3, 0.9)),
                     pi2_offset=float(rng.uniform(0.2, 6.0)))


def _study():
    m = load_model(STUDY)
    p = OscillatorParams(zeta=0.01, r=m.r, omega=m.omega, delta_d=m.delta_d,
                         pi2_offset=m.pi2_offset)
    return m, p


# ------------------------------------------------------------------ the family (§3)
@pytest.mark.parametrize("seed", range(12))
def test_family_makes_w_a_left_eigenvector_and_kills_every_markov_parameter(seed):
    m = _random_model(seed)
    for mu in (-0.7, 0.0, 0.45):
        k = nd.gain_family(m, mu)
        n_mat = nd.smooth_map(m, k)
        w = np.eye(2 * m.n)[m.i_w]
        scale = np.abs(n_mat).max()
        assert np.abs(w @ n_mat - mu * w).max() < 1e-12 * scale
        assert nd.family_mu(m, k) == pytest.approx(mu, abs=1e-12 * scale)
        markov = nd.markov_parameters(m, k)
        powers = [np.linalg.norm(np.linalg.matrix_power(n_mat, j)) for j in range(1, 2 * m.n + 1)]
        assert np.all(np.abs(markov) < 1e-12 * np.array(powers))
    # affine in mu: k(mu) = k(0) + mu (k(1) - k(0))
    k0, k1 = nd.gain_family(m, 0.0), nd.gain_family(m, 1.0)
    assert np.allclose(nd.gain_family(m, 0.3), k0 + 0.3 * (k1 - k0), rtol=1e-12, atol=1e-12)


def test_n1_family_is_the_study_line_c1_of_c2():
    """mu = N_g,11 = -(1 + c2) Q12 e^{-2 zeta s}/P12 and k(mu) = (c1(c2), c2), Eq. 38."""
    m, p = _study()
    s = p.pi2_offset / p.omega
    p12 = nd._transition(m, s)[0, 1]
    q12 = nd._transition(m, p.period - s)[0, 1]
    for c2 in (-2.0, -1.0, -0.5, 0.0, 0.25):
        mu = -(1.0 + c2) * q12 * math.exp(-2 * p.zeta * s) / p12
        k = nd.gain_family(m, mu)
        assert abs(k[0] - design.degenerate_c1(p, c2)) < 1e-10 * max(1, abs(k[0]))
        assert abs(k[1] - c2) < 1e-10


def test_no_family_where_the_kick_cannot_reach_the_wall_coordinate():
    """c = w^T Phi(T - s) b = 0 at some pi2_offset: a clear ParameterError there."""
    m = load_model(CHAIN)
    c = lambda x: nd._reach_value(dataclasses.replace(m, pi2_offset=x))  # noqa: E731
    xs = np.linspace(0.05, 6.2, 200)
    vals = [c(x) for x in xs]
    i = next(i for i in range(len(xs) - 1) if vals[i] * vals[i + 1] < 0)
    root = brentq(c, xs[i], xs[i + 1], xtol=1e-15)
    bad = dataclasses.replace(m, pi2_offset=root)
    for call in (lambda: nd.gain_family(bad, 0.1), lambda: nd.transmission_zeros(bad),
                 lambda: nd.admissible_mu(bad)):
        with pytest.raises(ParameterError, match="pi2_offset"):
            call()


@pytest.mark.parametrize("mu", [math.nan, math.inf, "0.1", None])
def test_bad_mu_is_refused(mu):
    with pytest.raises(ParameterError, match="mu"):
        nd.gain_family(load_model(CHAIN), mu)


def test_bad_gains_and_conditions_are_refused():
    m = load_model(CHAIN)
    with pytest.raises(ParameterError, match="gains"):
        nd.smooth_map(m, [1.0, 2.0])
    # one check, one line for every use of a model file's gains (issue 32: the design
    # family and the shooting near grazing refused them in other words)
    from grazing_control.dynamics.orbits import near_grazing
    from grazing_control.studies.sweeps.model_file import diagram

    uses = {"family": lambda k: nd.smooth_map(m, k),
            "explicit branch": lambda k: modal_branch.orbit_at_phase(m, k, 0.01),
            "near grazing": lambda k: near_grazing.kick_matrix(m, k),
            "modal map": lambda k: ModalMap(m, k),
            "sweep": lambda k: diagram(m, [-1e-6], periods=2, transient=1, gains=k)}
    for bad, shown in (([1.0, 2.0], "[1.0, 2.0]"), (np.array([0.0, 0.0, math.nan, 1.0]),
                                                     "[0.0, 0.0, nan, 1.0]"), ("x", "'x'")):
        for use, call in uses.items():
            with pytest.raises(ParameterError) as err:
                call(bad)
            assert str(err.value) == (f"gains={shown} is invalid: valid range is 2n = 4 finite "
                                      "real numbers (the kick's gain on each of x0..x1, "
                                      "v0..v1)"), use
    with pytest.raises(ValueError, match="conditions"):
        nd.admissible_mu(m, "both")


# ---------------------------------------------------------- transmission zeros (§4)
@pytest.mark.parametrize("seed", range(12))
def test_transmission_zeros_against_the_characteristic_polynomial(seed):
    """Pencil zeros = roots of w^T adj(lambda I - M) g = char(M - g w^T) - char(M)
    (determinant lemma), and = spec N(k(mu)) without mu, for every mu."""
    m = _random_model(seed)
    z = nd.transmission_zeros(m)
    assert z.shape == (2 * m.n - 1,)
    mm = nd.smooth_map(m)
    p, q, _ = nd._sections(m)
    w, _ev, b = nd._vectors(m)
    g = q @ b
    num = np.poly(mm - np.outer(g, w)) - np.poly(mm)
    assert abs(num[0]) < 1e-12 * np.abs(num).max()         # degree 2n - 1, leading c
    assert num[1] == pytest.approx(w @ g, rel=1e-9)
    assert _match(z, np.roots(num[1:])) < 1e-8 * max(1.0, np.abs(z).max())
    for mu in (-0.4, 0.8):
        eig = np.linalg.eigvals(nd.smooth_map(m, nd.gain_family(m, mu)))
        assert _match(np.append(z, mu), eig) < 1e-8 * max(1.0, np.abs(eig).max())
    assert _match(nd.free_multipliers(m, 0.8), np.append(z, 0.8)) == 0.0


# ------------------------------------------------- limit multipliers, existence (§6, §7)
def test_n1_limit_multipliers_existence_and_admissible_sets_are_the_1dof_design():
    """n = 1: lambda0 (Eq. 23, design.limit_multipliers), gamma1 (Eq. 36) and the three
    admissible sets (mapped c2 -> mu = N_g,11) agree with dynamics/design/gains.py to 1e-10."""
    m, p = _study()
    u0, sigma = design._c2_of_n11(p, 0.0)
    for c2 in (-1.7, -1.0, -0.5, 0.0, 0.2):
        g = Gains(design.degenerate_c1(p, c2), c2)
        mu = u0 + sigma * c2
        assert _match(nd.limit_multipliers(m, mu), design.limit_multipliers(p, g)) < 1e-10
        ref = design.existence_coefficient(p, g)
        assert abs(nd.existence_coefficient(m, mu) - ref) < 1e-10 * abs(ref)
        j0 = nd.limit_monodromy(m, mu)
        assert np.linalg.det(j0) == pytest.approx(p.r ** 2 * math.exp(-2 * p.zeta * p.period)
                                                  * (1 + c2), rel=1e-10, abs=1e-14)
    for cond in nd.CONDITIONS:
        ours = nd.admissible_mu(m, cond)
        theirs = design.admissible_c2(p, conditions=cond)
        assert len(ours) == len(theirs) == 1
        lo, hi = sorted(u0 + sigma * c for c in theirs[0])
        assert abs(ours[0][0] - lo) < 1e-10 and abs(ours[0][1] - hi) < 1e-10


@pytest.mark.parametrize("seed", [0, 3, 5])
def test_limit_multipliers_are_the_exact_branch_limit(seed):
    """The exact 1/1 branch (modal_branch, no expansion) at impact phase psi has
    multipliers within O(psi) of the limit spectrum, det J = r^2 det N exactly."""
    m = _random_model(seed, 3)
    mu = 0.25
    k = nd.gain_family(m, mu)
    lim = nd.limit_multipliers(m, mu)
    assert np.prod(lim).real == pytest.approx(m.r ** 2 * np.linalg.det(nd.smooth_map(m, k)),
                                              rel=1e-9)
    errs = []
    for psi in (1e-3, 1e-4, 1e-5):
        bp = modal_branch.orbit_at_phase(m, k, math.copysign(psi, modal_branch.branch_coefficients(m, k)[2]))
        errs.append(_match(np.linalg.eigvals(bp.monodromy), lim))
    assert 7 < errs[0] / errs[1] < 14 and 7 < errs[1] / errs[2] < 14


@pytest.mark.parametrize("seed", [1, 2, 4])
def test_existence_coefficient_is_the_branch_curvature(seed):
    """gamma1(mu) = -lim Delta d(psi) / psi^2 of the exact branch, and the general
    branch_coefficients on the family (d1 = 0 there)."""
    m = _random_model(seed, 2)
    for mu in (-0.3, 0.5):
        k = nd.gain_family(m, mu)
        g1 = nd.existence_coefficient(m, mu)
        d1, g1_general, _v1 = modal_branch.branch_coefficients(m, k)
        assert abs(d1) < 1e-10 * abs(g1) and g1_general == pytest.approx(g1, rel=1e-10)
        errs = []
        for psi in (1e-3, 1e-4):   # symmetric quotient: error O(psi^2)
            dd = [modal_branch.orbit_at_phase(m, k, x).delta_d for x in (psi, -psi)]
            errs.append(abs(-0.5 * (dd[0] + dd[1]) / psi ** 2 - g1))
        assert errs[1] < 1e-5 * abs(g1) and 70 < errs[0] / errs[1] < 130


# --------------------------------------------------------------- admissible mu (§8)
# seeds with non-empty sets, ends set by each condition (8: impacting only, 53: 0.009 wide)
@pytest.mark.parametrize("seed", [1, 8, 14, 17, 28, 53, 60, 73])
def test_admissible_mu_agrees_with_a_dense_grid_and_its_ends_are_switches(seed):
    m = _random_model(seed)
    sets = {c: nd.admissible_mu(m, c) for c in nd.CONDITIONS}
    assert sets["impacting"]

    designs = {}    # mu -> its design, evaluated once for the three conditions

    def ok(mu, cond):
        d = designs.get(mu)
        if d is None:
            d = designs[mu] = nd.evaluate_design(m, mu)
        return {"impacting": d.admissible_impacting, "non-impacting": d.free_stable,
                "combined": d.admissible}[cond]

    grid = np.linspace(-3.0, 3.0, 601)
    for cond, ivs in sets.items():
        inside = lambda mu: any(lo < mu < hi for lo, hi in ivs)  # noqa: E731
        for mu in grid:
            if min([abs(mu - e) for iv in ivs for e in iv] or [1.0]) > 1e-9:
                assert ok(mu, cond) == inside(mu), (cond, mu)
        for lo, hi in ivs:
            for end, out in ((lo, -1), (hi, 1)):
                if math.isfinite(end):
                    assert ok(end, cond) and not ok(end + out * 1e-9 * max(1, abs(end)), cond)


# ------------------------------------------------------------ the shipped example (§11)
def test_two_mass_chain_has_a_design():
    """Zeros inside, an admissible interval, and the uncontrolled 1/1 orbit born at
    grazing on the impacting side and unstable there (multiplier ~ 1/|Delta d|)."""
    m = load_model(CHAIN)
    assert np.abs(nd.transmission_zeros(m)).max() < 0.65
    (lo, hi), = nd.admissible_mu(m)
    assert lo < -0.3 and hi > 0.7
    best = nd.evaluate_design(m, 0.5 * (lo + hi))
    assert best.admissible and best.limit_radius < 0.8
    assert best.lambda0 is best.limit_multipliers and best.zeros_radius < 0.65
    free = np.zeros(2 * m.n)
    d1, _g1, v1 = modal_branch.branch_coefficients(m, free)
    assert d1 / v1 < 0          # Delta d < 0 where v- > 0
    lam = [np.abs(np.linalg.eigvals(modal_branch.orbit_at(m, free, -dd).monodromy)).max()
           for dd in (1e-4, 1e-6)]
    assert lam[0] > 10 and lam[1] / lam[0] == pytest.approx(100, rel=0.01)


# ------------------------------------------------------------- acceptance (issue 17)
def _exact_multipliers(model, gains, delta_d):
    m = dataclasses.replace(model, delta_d=delta_d)
    guess = modal_branch.orbit_at(m, gains, delta_d).pi2_state
    orbit = find_periodic(ModalMap(m, gains), guess)
    assert len(orbit.impacts) == 1 and orbit.impacts[0].v_minus > 0
    return floquet_multipliers(orbit.monodromy)


def test_controlled_multipliers_stay_bounded_and_converge_to_the_limit():
    """mu = 0.2 on the chain: exact multipliers (Newton shooting on ModalMap) bounded down
    to Delta d = -1e-10 and within ~1.1 |Delta d|^(1/2) of the predicted limit spectrum
    (measured 1.04e-2, 1.06e-4, 1.07e-5 at -1e-4, -1e-8, -1e-10: order 0.50)."""
    m = load_model(CHAIN)
    d = nd.evaluate_design(m, 0.2)
    assert d.admissible
    dds = np.array([1e-4, 1e-7, 1e-10])
    errs = []
    for dd in dds:
        lam = _exact_multipliers(m, d.gains, -dd)
        assert np.abs(lam).max() < 0.8
        errs.append(_match(lam, d.limit_multipliers))
    order = np.polyfit(np.log(dds), np.log(errs), 1)[0]
    assert abs(order - 0.5) < 0.02
    assert errs[-1] < 2e-5


@pytest.mark.parametrize("smooth, exponent", [(True, -0.25), (False, -0.5)])
def test_cancelling_only_the_first_markov_parameter_is_not_enough(smooth, exponent):
    """w^T N e_v = 0 alone: the largest exact multiplier grows like |Delta d|^-1/4 when
    G(1) = 0 too (smooth branch) and like |Delta d|^-1/2 otherwise (fitted, 3 points)."""
    m = load_model(CHAIN)
    k = nd.cancel_first_markov(m, 0.2, 0.5, smooth_branch=smooth)
    markov = nd.markov_parameters(m, k)
    assert abs(markov[0]) < 1e-14 and abs(markov[1]) > 1e-2
    d1, g1, _v1 = modal_branch.branch_coefficients(m, k)
    assert (abs(d1) < 1e-12) == smooth
    dds = np.array([1e-5, 1e-7, 1e-9])
    big = [np.abs(_exact_multipliers(m, k, -dd)).max() for dd in dds]
    assert big[-1] > 20
    assert abs(np.polyfit(np.log(dds), np.log(big), 1)[0] - exponent) < 0.02


def test_cancel_first_markov_with_zero_offset_is_the_design():
    m = load_model(CHAIN)
    assert np.allclose(nd.cancel_first_markov(m, 0.1, 0.0), nd.gain_family(m, 0.1), atol=1e-15)
    with pytest.raises(ParameterError, match="offset"):
        nd.cancel_first_markov(m, 0.1, math.nan)


# ----------------------------------------------------------- the parameter file
def test_write_gain_yaml_round_trips_and_refuses_a_foreign_design(tmp_path):
    m = load_model(CHAIN)
    d = nd.evaluate_design(m, 0.2)
    out = tmp_path / "gains.yaml"
    nd.write_gain_yaml(out, m, d, CHAIN)
    doc = yaml.safe_load(out.read_text())
    params = doc["/**"]["ros__parameters"]
    assert params["gains"] == [float(x) for x in d.gains] and len(params["gains"]) == 4
    assert params["model_file"] == str(CHAIN) and params["i_a"] == 1 and params["n"] == 2
    other = dataclasses.replace(m, pi2_offset=1.0)
    with pytest.raises(ParameterError, match="family"):
        nd.write_gain_yaml(tmp_path / "x.yaml", other, d, CHAIN)
    assert not (tmp_path / "x.yaml").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gains.yaml"]


@pytest.mark.parametrize("seed", [3, 11])
def test_sections_with_stable_zeros_are_where_every_zero_is_inside(seed):
    """The design aid of `grazing design --model` when no mu is admissible: the pi2_offset
    intervals it reports have all transmission zeros inside the unit circle, and the
    offsets between them do not (checked directly, at the midpoints and just beyond
    each bisected end); the shipped chain's own section lies in one."""
    model = _random_model(seed, 2)
    found = nd.sections_with_stable_zeros(model, points=240)

    def radius(s):
        return float(np.max(np.abs(nd.transmission_zeros(dataclasses.replace(model,
                                                                              pi2_offset=s)))))

    edges = [0.0] + [e for iv in found for e in iv] + [2 * math.pi]
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        if b - a > 1e-6:
            assert (radius(0.5 * (a + b)) < 1.0) == (i % 2 == 1), (i, a, b, found)
    for a, b in found:
        for end, outward in ((a, -1e-6), (b, 1e-6)):
            if 1e-5 < end < 2 * math.pi - 1e-5:
                assert radius(end + outward) >= 1.0 - 1e-9 and radius(end - outward) < 1.0
    chain = load_model(CHAIN)
    assert any(a < chain.pi2_offset < b for a, b in nd.sections_with_stable_zeros(chain))
    with pytest.raises(ParameterError, match="points=1 is invalid"):
        nd.sections_with_stable_zeros(chain, points=1)


# ------------------------------------------------- the predicted spread (§17, noise)
def _differences(f, y, h):
    """Fourth-order central differences of f at y, step h per column."""
    cols = []
    for j in range(y.size):
        e = np.zeros(y.size)
        e[j] = h
        cols.append((8.0 * (f(y + e) - f(y - e)) - (f(y + 2 * e) - f(y - 2 * e))) / (12.0 * h))
    return np.array(cols).T


@pytest.mark.parametrize("start, tau_a, force0", [(0.5, 0.1, 0.003), (8.0, 0.5, -0.02),
                                                  (2.0, 3.0, 0.1)])
def test_actuated_step_jacobian_is_the_exact_maps_derivative(start, tau_a, force0):
    """Chain at Delta d = -1e-3: d (z, F)_{k+1} / d (z, F, Delta v) of actuated_step
    (§17) against fourth-order differences of the map itself (measured 1.3e-9, 7e-10,
    3e-11 of entries up to 15): the rig scene's pulse (start 0.5, tau_a 0.1, the impact
    at 11.93), the impact under the decaying force (start 8, tau_a 0.5: the force there
    ~ e^-5 of its peak) and a slow actuator without impact, each from a force carried
    from the previous period."""
    from grazing_control.dynamics.maps.modal_map import actuated_step
    from grazing_control.oscillator.ndof.flow import NdofFlow

    flow = NdofFlow.of(dataclasses.replace(load_model(CHAIN), delta_d=-1e-3))
    y0 = np.array([-0.042, 0.026, -0.05, 0.025, force0, 0.1429])

    def f(y):
        z, force, _imps = actuated_step(flow, y[:4], y[4], y[5], start=start, width=1.0,
                                        time_constant=tau_a, latency=0.05)
        return np.append(z, force)

    _z, _f, imps, jac, inp = actuated_step(flow, y0[:4], y0[4], y0[5], start=start,
                                           width=1.0, time_constant=tau_a, latency=0.05,
                                           jacobian=True)
    assert len(imps) == (0 if start == 2.0 else 1)
    got = np.hstack([jac, inp[:, None]])
    assert np.max(np.abs(got - _differences(f, y0, 1e-6))) < 1e-8 * max(1.0, np.abs(got).max())


@pytest.mark.parametrize("delay", [0.0, 0.3, 3.0])
def test_n1_predicted_spread_is_the_1dof_noise_covariance(delay):
    """n = 1 (the study's model file) with the kick: the loop's orbit and Sigma of
    noise are the 1-DOF closed form's (noise.noise_covariance, exact saltation)
    to 1e-12 (measured 7e-15, 1e-13, 2.9e-13)."""
    from grazing_control.dynamics.design import noise
    from grazing_control.dynamics.design.noise import predicted_spread
    from grazing_control.dynamics.orbits.orbits import orbit_11

    m, p = _study()
    m, p = dataclasses.replace(m, delta_d=-1e-3), p.with_(delta_d=-1e-3)
    g = Gains(design.degenerate_c1(p, -0.3, delay), -0.3, delay)
    target = orbit_11(p, g).pi2_deviation
    want = noise.noise_covariance(p, g, np.eye(2), target)
    got = predicted_spread(m, [g.c1, g.c2], delay)
    np.testing.assert_allclose(got.orbit, target, rtol=1e-12, atol=1e-16)
    np.testing.assert_allclose(got.covariance, want, rtol=1e-12, atol=0)
    k = np.array([g.c1, g.c2])
    assert got.correction_variance == pytest.approx(k @ want @ k + k @ k, rel=1e-12)


@pytest.mark.parametrize("tau_a, latency", [(0.5, 0.0), (0.3, 0.1)])
def test_n1_through_the_lag_is_the_1dof_actuated_loop(tau_a, latency):
    """n = 1 through the first-order actuator (pulse 0.1 at delay 3, Delta d = -1e-3):
    the (z, F) orbit is the 1-DOF actuated_orbit's (measured 8e-15); the exact closed-loop
    Jacobian is the fourth-order differences of the 1-DOF map
    (dynamics.simulation.actuator.actuated_step, its own flow) to 1e-8; the 1-DOF
    prediction, whose monodromy is central differences (error ~1e-6 of it, measured
    1.1e-6), agrees to 5e-6 (measured 7e-7)."""
    from grazing_control.dynamics.design.noise import predicted_spread, spread_linearisation
    from grazing_control.dynamics.simulation import actuator as one

    m, p = _study()
    m, p = dataclasses.replace(m, delta_d=-1e-3), p.with_(delta_d=-1e-3)
    g = Gains(design.degenerate_c1(p, 0.03, 3.0), 0.03, 3.0)
    orb = one.actuated_orbit(p, g, 0.1, one.Actuator(tau_a, latency))
    act = nd.Actuation(3.0, 0.1, tau_a, latency)
    got = predicted_spread(m, [g.c1, g.c2], act)
    np.testing.assert_allclose(got.orbit, orb.state, rtol=0, atol=1e-13)
    start = act.start(m)

    def f(y):
        x, v, force, _ = one.actuated_step(p, y[0], y[1], y[2], g.c1 * y[0] + g.c2 * y[1],
                                           start=start, width=0.1,
                                           actuator=one.Actuator(tau_a, latency))
        return np.array([x, v, force])

    jac = spread_linearisation(m, [g.c1, g.c2], got.orbit, act)[0]
    ref = _differences(f, np.asarray(got.orbit), 1e-6)
    assert np.max(np.abs(jac - ref)) < 1e-8 * np.abs(jac).max()
    want = orb.noise_covariance(g)
    np.testing.assert_allclose(got.covariance[:2, :2], want[:2, :2], rtol=5e-6)


def _std_error(J, S, i, periods):
    """The relative standard error of a sample std of coordinate i over ``periods``
    samples of the stationary linear loop (J, S): sqrt(sum_tau rho(tau)^2 / (2 N)),
    rho(tau) = (J^|tau| S)_ii / S_ii (Gaussian; Bartlett)."""
    total, a = 1.0, S.copy()
    for _ in range(2000):
        a = J @ a
        rho = a[i, i] / S[i, i]
        total += 2.0 * rho ** 2
        if abs(rho) < 1e-8:
            break
    return math.sqrt(total / (2.0 * periods))


@pytest.mark.parametrize("pulse", [nd.Actuation(1.0, 1.0), nd.Actuation(1.0, 1.0, 0.1, 0.05)],
                         ids=["pulse", "pulse+actuator"])
def test_predicted_spread_is_the_plants_seeded_closed_loop(pulse):
    """Chain at Delta d = -1e-3, k(mu = -0.22) for the pulse (width 1 at delay 1; through
    tau_a 0.1, latency 0.05): the simulator's engine (plant.engine.Engine: its force
    carried from period to period, its seeded noises) in a closed loop of 1200 periods
    from the orbit, every coordinate measured with sigma 1e-5 and a velocity noise of
    1e-5 at each sample (the nonlinear loop against its linearisation and (N11)): one
    impact per period, and the std of every coordinate and of the force within 4 sampling standard errors of the prediction (the errors from the linear
    loop's correlations, 2.2-4.5 % here; measured ratios 0.980-1.015), the corrections'
    within 15 % (N12; measured with 2000 periods for each noise alone 0.975-0.999)."""
    from grazing_control.dynamics.design.noise import predicted_spread, spread_linearisation
    from grazing_control.plant.engine import Engine
    from grazing_control.plant.settings import load_model_file, settings_from_values

    model = dataclasses.replace(load_model_file(str(CHAIN)), delta_d=-1e-3)
    k = nd.evaluate_design(model, -0.22, pulse).gains
    pred = predicted_spread(model, k, pulse, velocity=1.0)
    values = {"delta_d": -1e-3, "actuation_delay": 1.0, "pulse_width": 1.0,
              "measurement_noise": 1e-5, "noise": 1e-5, "seed": 3}
    if pulse.time_constant:
        values.update(actuator_bandwidth=1.0 / pulse.time_constant,
                      actuator_latency=pulse.latency)
    eng = Engine(settings_from_values(values, str(CHAIN), model))
    eng.reset()
    eng.z = np.array(pred.orbit[:4])
    if pred.orbit.size > 4:
        eng.force = float(pred.orbit[4])
    ev = eng.sample()
    periods, rows, dvs = 1200, [], []
    for _ in range(periods):
        seen = eng.measured(ev)
        dv = float(k @ (np.append(seen.x, seen.v) - np.append(ev.x, ev.v) + eng.z))
        events = eng.begin_period(dv, 1.0)
        assert sum(e.kind == "impact" for e in events) == 1
        rows.append(np.append(eng.z, eng.force)[:pred.orbit.size])
        dvs.append(dv)
        ev, _ = eng.end_period()
    ratio = np.array(rows).std(axis=0) / (1e-5 * pred.std)
    J, _g, _ev = spread_linearisation(model, k, pred.orbit, pulse)
    for i, r in enumerate(ratio):
        if pred.std[i] > 1e-30:     # (the force at the section: e^-40 of the pulse's)
            assert abs(r - 1.0) < 4.0 * _std_error(J, pred.covariance, i, periods), (i, ratio)
    dv_ratio = np.std(dvs) / (1e-5 * pred.correction_std)
    assert abs(dv_ratio - 1.0) < 0.15, dv_ratio


def test_design_prints_the_predicted_spread_through_the_lag(capsys):
    """`grazing design --model CHAIN --delta-d -1e-3 --mu -0.22 --delay 1 --pulse-width 1
    --actuator-bandwidth 10 --actuator-latency 0.05 --json`: its ``spread`` is
    predicted_spread's (every coordinate measured; x0 only at --sensor-rate 50 through
    the filter over the samples before t_k; the velocity noise), the orbit (z*, F*) with
    spectral radius 0.8964 (docs/ndof_scene.md: the actuated orbit's |lambda|max); a
    --delta-d >= 0 is one line naming delta_d, status 2."""
    import json

    from grazing_control import cli
    from grazing_control.dynamics.design.noise import predicted_spread
    from grazing_control.dynamics.design.noise import filter_covariance
    from grazing_control.dynamics.simulation.actuator import Actuator

    argv = ["design", "--model", str(CHAIN), "--mu", "-0.22", "--delay", "1.0",
            "--pulse-width", "1.0", "--actuator-bandwidth", "10", "--actuator-latency",
            "0.05", "--sensor-rate", "50"]
    assert cli.main(argv + ["--delta-d", "-1e-3", "--json"]) in (0, None)
    got = json.loads(capsys.readouterr().out)["spread"]
    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    act = nd.Actuation(1.0, 1.0, 0.1, 0.05)
    k = nd.evaluate_design(model, -0.22, act).gains
    want = predicted_spread(model, k, act)
    assert got["spectral_radius"] == pytest.approx(0.8964, abs=5e-5)
    np.testing.assert_allclose(got["orbit"], want.orbit, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got["measured"]["std"], want.std, rtol=1e-12)
    r = filter_covariance(model, k, want.orbit[:4], 50, 0, 1.0, width=1.0,
                               section_sample=False, actuator=Actuator(0.1, 0.05),
                               force0=float(want.orbit[4]))
    pos = predicted_spread(model, k, act, measurement=r, orbit=want.orbit)
    np.testing.assert_allclose(got["position_only"]["std"], pos.std, rtol=1e-12)
    assert got["position_only"]["correction_std"] == pytest.approx(pos.correction_std,
                                                                   rel=1e-12)
    vel = predicted_spread(model, k, act, measurement=np.zeros((4, 4)), velocity=1.0,
                           orbit=want.orbit)
    np.testing.assert_allclose(got["velocity_noise"]["std"], vel.std, rtol=1e-12)
    assert cli.main(argv + ["--delta-d", "1e-3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "delta_d=0.001 is invalid" in err[0]

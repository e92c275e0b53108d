"""Periodic response and grazing of the n-DOF model against independent references."""

import math

import numpy as np

from grazing_control.oscillator.ndof import NdofModel
from grazing_control.oscillator.ndof.flow import (
    grazing_clearance, grazing_phase, harmonic_amplitudes, periodic_response)
from grazing_control.oscillator.params import OscillatorParams


def test_n1_reproduces_1dof_grazing():
    p = OscillatorParams()
    m = NdofModel(M=[[1.0]], C=[[2 * p.zeta]], K=[[1.0]], f=[1.0], omega=p.omega, i_w=0)
    assert abs(grazing_clearance(m) - p.d_star) < 1e-13 * p.d_star
    assert abs(grazing_phase(m) - p.tau_star % (2 * math.pi)) < 1e-12


def test_periodic_response_solves_the_ode_seeded_random_models():
    rng = np.random.default_rng(17)
    for _ in range(200):
        n = int(rng.integers(1, 5))
        a = rng.normal(size=(n, n)); M = a @ a.T + n * np.eye(n)
        b = rng.normal(size=(n, n)); K = b @ b.T + 0.1 * np.eye(n)
        C = 0.05 * M + 0.01 * K
        m = NdofModel(M=M, C=C, K=K, f=rng.normal(size=n), omega=float(rng.uniform(0.2, 2)),
                      i_w=int(rng.integers(n)), phase=float(rng.uniform(0, 6)))
        t = rng.uniform(0, 50, size=7)
        h = 1e-4
        x, v = periodic_response(m, t)
        xp, vp = periodic_response(m, t + h)
        xm, vm = periodic_response(m, t - h)
        acc = (vp - vm) / (2 * h)  # finite difference, independent of X
        force = np.cos(m.omega * t + m.phase)[:, None] * m.f
        res = acc @ m.M.T + v @ m.C.T + x @ m.K.T - force
        assert np.max(np.abs(res)) < 1e-6 * (1 + np.max(np.abs(force)))
        assert np.allclose((xp - xm) / (2 * h), v, atol=1e-6)
        # maximum of the wall coordinate = d*, at tau*: brute-force grid
        ts = (np.linspace(0, 2 * math.pi, 20001) - m.phase) / m.omega
        xw = periodic_response(m, ts)[0][:, m.i_w]
        assert abs(xw.max() - grazing_clearance(m)) < 1e-7 * (1 + grazing_clearance(m))
        tg = (grazing_phase(m) - m.phase) / m.omega
        xg, vg = periodic_response(m, tg)
        assert abs(xg[m.i_w] - grazing_clearance(m)) < 1e-12 * (1 + abs(xg[m.i_w]))
        assert abs(vg[m.i_w]) < 1e-12 * (1 + np.abs(harmonic_amplitudes(m)).max() * m.omega)


# --------------------------------------------------------------- NdofFlow (exact flow)
import dataclasses
from pathlib import Path

import pytest
import scipy.linalg
from mpmath import mp, mpf

from grazing_control.oscillator.flow import transition_matrix
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.params import ParameterError

from reference_ndof import load_reference

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"


def _random_model(rng, n, **kw):
    """A random n-DOF model with non-proportional damping (complex modes)."""
    a = rng.normal(size=(n, n)); M = a @ a.T + n * np.eye(n)
    b = rng.normal(size=(n, n)); K = b @ b.T + 0.2 * np.eye(n)
    c = rng.normal(size=(n, n)); C = 0.02 * M + 0.01 * K + 0.02 * c @ c.T
    return NdofModel(M=M, C=C, K=K, f=rng.normal(size=n), omega=float(rng.uniform(0.3, 2.0)),
                     i_w=int(rng.integers(n)), i_a=int(rng.integers(n)), **kw)


@pytest.mark.parametrize("name", ["two_mass_chain.yaml", "study_1dof.yaml"])
def test_transition_matches_mpmath_expm_and_eigen(name):
    """Phi(h) = e^{Ah} agrees with the 50-digit reference (its eigendecomposition, itself
    checked against mpmath's expm to 1e-45) to 1e-14 relative, over 0.1 .. 3 periods;
    d*, tau*, tau2 and X_p(tau) agree to 1e-14."""
    m = load_model(MODELS / name)
    flow = NdofFlow.of(m)
    ref = load_reference(MODELS / name)
    assert abs(flow.d_star - float(ref.d_star)) < 1e-14 * flow.d_star
    assert abs(flow.tau_star - float(ref.tau_star)) < 1e-14
    assert abs(flow.tau2 - float(ref.tau2)) < 1e-14
    for h in (0.1, 0.5 * m.period, m.period, 3.0 * m.period):
        exact = ref.transition(h)
        assert mp.norm(exact - ref.transition_expm(h)) < mpf("1e-45")
        phi = flow.transition(h)
        err = np.abs(phi - np.array(exact.tolist(), dtype=float)).max()
        assert err < 1e-14 * max(1.0, np.abs(phi).max()), (h, err)
    for tau in (0.0, 1.3, flow.tau_star, 5.9):
        xp = np.array([float(x) for x in ref.particular(tau)])
        assert np.abs(flow.particular(tau) - xp).max() < 1e-14 * np.abs(xp).max()


def test_transition_is_the_matrix_exponential_for_random_models():
    """Seeded random models n = 1..4 (non-proportional damping): Phi(h) equals mpmath's
    expm(A h) at 30 digits to 1e-13 (scipy's expm is off by up to 2.4e-13 on the same
    cases, the modal form by 2.2e-14: measured), and Phi(a) Phi(b) = Phi(a + b), Phi(0) = I."""
    rng = np.random.default_rng(3)
    for _ in range(30):
        flow = NdofFlow.of(_random_model(rng, int(rng.integers(1, 5))))
        for h in rng.uniform(0.0, 20.0, size=2):
            with mp.workdps(30):
                ref = np.array(mp.expm(mp.matrix(flow.A.tolist()) * mpf(h)).tolist(), dtype=float)
            assert np.abs(flow.transition(h) - ref).max() < 1e-13 * max(1.0, np.abs(ref).max())
        a, b = rng.uniform(0, 5, size=2)
        assert np.allclose(flow.transition(a) @ flow.transition(b), flow.transition(a + b),
                           rtol=1e-13, atol=1e-13)
        assert np.abs(flow.transition(0.0) - np.eye(2 * flow.n)).max() < 1e-14 * flow.condition


def test_deviation_round_trip_and_gap_near_grazing_at_full_relative_precision():
    """to_physical(to_deviation(X)) = X; the gap in deviation coordinates equals the
    50-digit physical x_w - d at phases 1e-9 .. 1e-3 from tau* with deviations 1e-12 ..
    1e-4 to 1e-12 RELATIVE (no cancellation against d* ~ 1.95), up to the rounding of
    the float phase itself."""
    rng = np.random.default_rng(5)
    m = dataclasses.replace(load_model(MODELS / "two_mass_chain.yaml"), delta_d=-1e-9)
    flow = NdofFlow.of(m)
    ref = load_reference(MODELS / "two_mass_chain.yaml", delta_d=-1e-9)
    X = rng.normal(size=4)
    assert np.allclose(flow.to_physical(1.1, flow.to_deviation(1.1, X)), X, rtol=0, atol=1e-15)
    for _ in range(30):
        tau = flow.tau_star + rng.choice([-1, 1]) * 10 ** rng.uniform(-9, -3)
        z = rng.normal(size=4) * 10 ** rng.uniform(-12, -4)
        exact = ref.particular(tau)[m.i_w] + mpf(float(z[m.i_w])) - ref.d
        g = flow.gap(tau, z)
        # beyond 1e-12 relative, only the float phase tau moves the gap: d* |psi| ulp(tau)
        phase = flow.d_star * abs(tau - flow.tau_star) * 2 * math.ulp(tau)
        assert abs(g - float(exact)) <= 1e-12 * abs(float(exact)) + phase, (tau, z, g, exact)


def test_n1_flow_is_the_1dof_closed_form():
    """n = 1 (config/models/study_1dof.yaml): Phi(h) equals the 1-DOF closed form
    (oscillator.flow.transition_matrix) to 1e-14; d*, tau*, tau2 those of OscillatorParams."""
    m = load_model(MODELS / "study_1dof.yaml")
    p = OscillatorParams(zeta=0.5 * m.C[0, 0], r=m.r, omega=m.omega, delta_d=m.delta_d,
                         pi2_offset=m.pi2_offset)
    flow = NdofFlow.of(m)
    for h in (0.01, 1.0, 9.42, 30.0):
        assert np.abs(flow.transition(h) - np.array(transition_matrix(p.zeta, h)).reshape(2, 2)).max() < 1e-14
    assert abs(flow.d_star - p.d_star) < 1e-15 * p.d_star
    assert abs(flow.tau_star - p.tau_star) < 1e-15 and abs(flow.tau2 - p.tau2) < 1e-15


@pytest.mark.parametrize("change,match", [
    (dict(C=[[0.0]], omega=1.0), "omega"),                   # undamped resonance
    (dict(f=[1.0, 0.0], M=np.eye(2), C=0.01 * np.eye(2), K=np.diag([1.0, 2.0]), i_w=1), "f="),
    (dict(C=[[2.0]]), "defective"),                          # critically damped: Jordan block
])
def test_bad_models_are_refused_with_parameter_error(change, match):
    base = dict(M=[[1.0]], C=[[0.02]], K=[[1.0]], f=[1.0], omega=0.7, i_w=0)
    base.update(change)
    with pytest.raises(ParameterError, match=match):
        NdofFlow.of(NdofModel(**base))

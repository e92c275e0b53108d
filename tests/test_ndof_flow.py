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

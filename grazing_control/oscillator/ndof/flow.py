"""Non-impacting periodic response of the n-DOF oscillator and its grazing (issue 17).

With forcing ``f cos(omega t + phase)`` the periodic (particular) solution is
``x_p(t) = Re(X exp(i(omega t + phase)))`` where X solves the complex linear system
``(K - omega^2 M + i omega C) X = f`` (substitute into M x'' + C x' + K x; the
derivation in docs/ndof_model.md, "Periodic response").
The wall coordinate's maximum on it is ``|X[i_w]|``: the grazing clearance d*, reached
(with zero velocity) at the phase ``omega t + phase = -arg X[i_w]`` (mod 2 pi); for
n = 1 this is the 1-DOF a(omega) and tau* = phi (oscillator/params.py).
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.oscillator.ndof.model import NdofModel

__all__ = ["harmonic_amplitudes", "grazing_clearance", "grazing_phase", "periodic_response"]


def harmonic_amplitudes(model: NdofModel) -> np.ndarray:
    """Complex amplitudes X of the periodic response, (K - w^2 M + i w C) X = f."""
    w = model.omega
    D = model.K - w * w * model.M + 1j * w * model.C
    if np.linalg.cond(D) > 1e14:
        raise ValueError(f"omega={w!r} is invalid: at an undamped resonance of the model")
    return np.linalg.solve(D, model.f.astype(complex))


def grazing_clearance(model: NdofModel) -> float:
    """d* = max over t of x_p[i_w](t) = |X[i_w]|."""
    return float(abs(harmonic_amplitudes(model)[model.i_w]))


def grazing_phase(model: NdofModel) -> float:
    """Forcing phase tau* in [0, 2 pi) where x_p[i_w] = d*: tau* = -arg X[i_w] mod 2 pi."""
    return float((-np.angle(harmonic_amplitudes(model)[model.i_w])) % (2 * math.pi))


def periodic_response(model: NdofModel, t) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of x_p at times t (shape (..., n) each)."""
    X = harmonic_amplitudes(model)
    e = np.exp(1j * (model.omega * np.asarray(t, dtype=float)[..., None] + model.phase))
    return np.real(X * e), np.real(1j * model.omega * X * e)

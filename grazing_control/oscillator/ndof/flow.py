"""Exact free flow of the n-DOF oscillator, its periodic response and grazing (issue 17).

With forcing ``f cos(omega t + phase)`` the periodic (particular) solution is
``x_p(t) = Re(X exp(i(omega t + phase)))`` where X solves the complex linear system
``(K - omega^2 M + i omega C) X = f`` (substitute into M x'' + C x' + K x; the
derivation in docs/ndof_model.md, "Periodic response").
The wall coordinate's maximum on it is ``|X[i_w]|``: the grazing clearance d*, reached
(with zero velocity) at the phase ``omega t + phase = -arg X[i_w]`` (mod 2 pi); for
n = 1 this is the 1-DOF a(omega) and tau* = phi (oscillator/params.py).
"""

from __future__ import annotations

import cmath
import functools
import math

import numpy as np

from dataclasses import dataclass

from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

__all__ = ["harmonic_amplitudes", "grazing_clearance", "grazing_phase", "periodic_response",
           "NdofFlow", "MAX_CONDITION", "matvec", "matmul"]

TWO_PI = 2.0 * math.pi
#: Largest condition number of the modal matrix V accepted: the flow's rounding grows like
#: cond(V) eps (docs/theory_ndof_flow.md, "Rounding"); beyond it A is (nearly) defective.
MAX_CONDITION = 1e8


def harmonic_amplitudes(model: NdofModel) -> np.ndarray:
    """Complex amplitudes X of the periodic response, (K - w^2 M + i w C) X = f."""
    w = model.omega
    D = model.K - w * w * model.M + 1j * w * model.C
    if np.linalg.cond(D) > 1e14:
        raise ParameterError(f"omega={w!r} is invalid: at an undamped resonance of the model")
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


@dataclass(frozen=True, eq=False)
class NdofFlow:
    """The exact flow of an :class:`NdofModel` between impacts (docs/theory_ndof_flow.md).

    Build it once with :meth:`NdofFlow.of`; it caches the periodic response (d*, tau*,
    the complex amplitudes) and the modal decomposition of A.

    Attributes
    ----------
    model : NdofModel
    A : (2n, 2n) ndarray
        Free-flight matrix [[0, I], [-M^-1 K, -M^-1 C]] (section 1).
    d_star, tau_star, tau2 : float
        Grazing clearance |X_w|, grazing phase -arg X_w and the phase of Pi2,
        (tau* + pi2_offset) mod 2 pi.
    amplitudes : (n,) complex ndarray
        X of the periodic response x_p = Re(X e^{i tau}).
    eigenvalues : (m,) complex ndarray
        One eigenvalue of A per real eigenvalue and per complex-conjugate pair (the one
        with positive imaginary part); ``weights`` (2 for a pair, 1 for a real one).
    condition : float
        cond_2(V) of the modal matrix (<= :data:`MAX_CONDITION`).
    defect : float
        ||A V - V Lambda||_2 ||V^-1||_2: the computed decomposition is exact for A + E,
        ||E|| <= defect (section 5, "Rounding").
    """

    model: NdofModel
    A: np.ndarray
    d_star: float
    tau_star: float
    tau2: float
    amplitudes: np.ndarray
    eigenvalues: np.ndarray
    weights: np.ndarray
    modes: np.ndarray
    inverse: np.ndarray
    condition: float
    defect: float

    @classmethod
    def of(cls, model: NdofModel) -> "NdofFlow":
        """The flow of ``model`` (docs/theory_ndof_flow.md, sections 1-2).

        Raises
        ------
        ParameterError
            omega at an undamped resonance, a wall coordinate that the forcing does not
            move (d* = 0: no grazing), or a (nearly) defective A (cond(V) above
            :data:`MAX_CONDITION`: a critically damped mode, or an undamped rigid-body
            mode), whose modal flow would not be exact.
        """
        if not isinstance(model, NdofModel):
            raise ParameterError(f"model={model!r} is invalid: expected an NdofModel")
        n = model.n
        X = harmonic_amplitudes(model)
        d_star = float(abs(X[model.i_w]))
        if not d_star > 0.0:
            raise ParameterError(f"f={model.f.tolist()!r} is invalid: it does not move the wall "
                                 f"coordinate i_w={model.i_w} (d* = 0: no grazing)")
        tau_star = float((-np.angle(X[model.i_w])) % TWO_PI)
        tau2 = (tau_star + model.pi2_offset) % TWO_PI
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -np.linalg.solve(model.M, model.K)
        A[n:, n:] = -np.linalg.solve(model.M, model.C)
        lam, V = np.linalg.eig(A)
        cond = float(np.linalg.cond(V))
        if not cond <= MAX_CONDITION:
            raise ParameterError(
                f"C, K are invalid: the free flow's matrix A is (nearly) defective, cond(V) = "
                f"{cond:.3g} > {MAX_CONDITION:.0e} (a critically damped mode or an undamped "
                f"rigid-body mode); valid: damping away from critical on every mode")
        U = np.linalg.inv(V)
        defect = float(np.linalg.norm(A @ V - V * lam, 2) * np.linalg.norm(U, 2))
        keep = lam.imag >= 0.0
        weights = np.where(lam.imag > 0.0, 2.0, 1.0)[keep]
        if weights.sum() != 2 * n or np.sum(lam.imag > 0.0) != np.sum(lam.imag < 0.0):
            raise ParameterError("C, K are invalid: the eigenvalues of A do not come in "
                                 "conjugate pairs (non-finite matrices?)")
        for a in (A, X):
            a.setflags(write=False)
        return cls(model, A, d_star, tau_star, tau2, X, lam[keep], weights,
                   V[:, keep] * weights, U[keep, :], cond, defect)

    # ------------------------------------------------------------- the free flow
    @property
    def n(self) -> int:
        """Degrees of freedom."""
        return self.model.n

    @property
    def period(self) -> float:
        """Forcing period T = 2 pi / omega (the model's)."""
        return self.model.period

    def transition(self, h: float) -> np.ndarray:
        """Phi(h) = e^{A h} = Re(sum_k w_k v_k e^{lambda_k h} u_k^T) (section 2), (2n, 2n).

        In an order of operations that the compiled n-DOF flow
        (oscillator/kernel/compiled_modal.py ``transition``) repeats, so that both give the
        same floats (tests/test_ndof_compiled.py): e_k = cmath.exp(lambda_k h), and NumPy's
        ``einsum("ik,k,kj->ij")`` (the model filter's ``modal_transitions`` order): for each
        entry the complex products (v_ik e_k) u_kj written out, their real parts summed over
        k from 0.0. Before issue 32's compiled advance it was ``((V e) @ U).real``, whose
        BLAS sums in its own order (docs/theory_ndof_flow.md section 4, the size of the
        change)."""
        h = float(h)
        e = np.array([cmath.exp(x * h) for x in self._eigenvalues])
        return np.einsum("ik,k,kj->ij", self.modes, e, self.inverse).real.copy()

    @functools.cached_property
    def _eigenvalues(self) -> list:
        """The eigenvalues as Python complex numbers (:meth:`transition`'s cmath.exp)."""
        return [complex(x) for x in self.eigenvalues]

    def particular(self, tau: float) -> np.ndarray:
        """X_p(tau) = (Re(X e^{i tau}), Re(i omega X e^{i tau})), the periodic response."""
        e = self.amplitudes * np.exp(1j * float(tau))
        return np.concatenate([e.real, (1j * self.model.omega * e).real])

    def to_deviation(self, tau: float, X) -> np.ndarray:
        """Physical state X at phase tau -> deviation z = X - X_p(tau)."""
        return np.asarray(X, dtype=float) - self.particular(tau)

    def to_physical(self, tau: float, z) -> np.ndarray:
        """Deviation z at phase tau -> physical state X = X_p(tau) + z."""
        return self.particular(tau) + np.asarray(z, dtype=float)

    # --------------------------------------------------------- the wall coordinate
    def gap(self, tau: float, z) -> float:
        """g = x_w - d = z_w - Delta d - 2 d* sin^2((tau - tau*) / 2) (section 3).

        x_p,w - d* = d* (cos psi - 1) = -2 d* sin^2(psi / 2), psi = tau - tau*: no
        cancellation near grazing.
        """
        s = math.sin(0.5 * (tau - self.tau_star))
        return float(z[self.model.i_w]) - self.model.delta_d - 2.0 * self.d_star * s * s

    def wall_velocity(self, tau: float, z) -> float:
        """v_w = -d* omega sin(tau - tau*) + z_{n + i_w}."""
        m = self.model
        return -self.d_star * m.omega * math.sin(tau - self.tau_star) + float(z[m.n + m.i_w])

    def wall_acceleration(self, tau: float, z) -> float:
        """Free acceleration of x_w: -d* omega^2 cos(tau - tau*) + (A z)_{n + i_w}."""
        m = self.model
        row = self.A[m.n + m.i_w]
        s = 0.0          # (A z)_{n + i_w} from 0.0 in the order of z (as the compiled flow)
        for a, x in zip(row.tolist(), np.asarray(z, dtype=float).tolist()):
            s += a * x
        return -self.d_star * m.omega ** 2 * math.cos(tau - self.tau_star) + s

    def on_wall(self, tau: float) -> tuple:
        """(z_w, z_{n+w}) of x_w = d, v_w = 0 at phase tau: (Delta d + 2 d* sin^2(psi/2),
        d* omega sin psi)."""
        psi = tau - self.tau_star
        s = math.sin(0.5 * psi)
        return (self.model.delta_d + 2.0 * self.d_star * s * s,
                self.d_star * self.model.omega * math.sin(psi))


def matvec(a: np.ndarray, x) -> np.ndarray:
    """a @ x: the products a_ij x_j, summed over j = 0, 1, ... from 0.0, each operation
    rounded once (NumPy's elementwise ones; no BLAS, whose order and fused multiply-adds
    are its own): the order that the compiled n-DOF flow (oscillator/kernel/compiled_modal.py)
    repeats, so that both give the same floats."""
    p = a * np.asarray(x, dtype=float)
    out = np.zeros(a.shape[0])
    for j in range(a.shape[1]):
        out = out + p[:, j]
    return out


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b in the order of :func:`matvec`: the products a_ij b_jc summed over j from 0.0."""
    p = a[:, :, None] * b
    out = np.zeros((a.shape[0], b.shape[1]))
    for j in range(a.shape[1]):
        out = out + p[:, j]
    return out

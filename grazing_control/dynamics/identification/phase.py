"""The forcing's phase reference: tau = omega t + tau0 from the recorded cos tau (and sin tau).

The state stream carries the shaker's phase reference in ``effort``: [cos tau] or
[cos tau, sin tau] at each sample (docs/nodes.md). Its frequency and phase are fitted
first and held fixed in the motion's fit (docs/theory_identification.md, "Phase
reference"): the reference is exact on a rig (read from the signal generator), so it
carries far more information on omega and tau0 than the motion does.

Initial guess: the phase of each sample (atan2(sin, cos); from cos alone, arccos with the
sign of -d(cos tau)/dt), unwrapped, regressed on t; then nonlinear least squares on the
residuals cos(omega t + tau0) - c_j (and sin) with the analytic Jacobian.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

__all__ = ["PhaseReference", "fit_phase", "PhaseError"]

TWO_PI = 2.0 * math.pi


class PhaseError(ValueError):
    """The reference is missing, too short, or not a harmonic signal (the message says why)."""


@dataclass(frozen=True)
class PhaseReference:
    """tau(t) = omega t + tau0 (tau0 in [0, 2 pi)); standard errors; residual RMS."""

    omega: float
    tau0: float
    omega_stderr: float
    tau0_stderr: float
    rms: float

    def phase(self, t):
        """tau at times t (not reduced modulo 2 pi)."""
        return self.omega * np.asarray(t) + self.tau0


def _initial(t, c, s):
    """(omega, tau0) by regressing the unwrapped sample phases on t (module docstring)."""
    if s is not None:
        tau = np.arctan2(s, c)
    else:
        cc = np.clip(c, -1.0, 1.0)
        slope = np.gradient(cc, t)
        tau = np.where(slope <= 0.0, np.arccos(cc), -np.arccos(cc))
    tau = np.unwrap(tau)
    A = np.column_stack([t, np.ones_like(t)])
    (omega, tau0), *_ = np.linalg.lstsq(A, tau, rcond=None)
    return omega, tau0


def fit_phase(t, cos_tau, sin_tau=None, *, tolerance: float = 1e-3) -> PhaseReference:
    """Fit tau = omega t + tau0 to the reference samples (module docstring).

    Parameters
    ----------
    t : (n,) sample times, increasing; at least 8 samples, more than 4 per forcing period
        (the unwrapping needs steps below pi; the sampling of the motion needs more anyway).
    cos_tau, sin_tau : the reference (sin_tau None or all NaN: cos only).
    tolerance : largest RMS residual of a harmonic reference.

    Raises
    ------
    PhaseError
        Too few samples, omega not positive, or residuals above ``tolerance``.
    """
    t = np.asarray(t, float)
    c = np.asarray(cos_tau, float)
    s = None if sin_tau is None else np.asarray(sin_tau, float)
    if s is not None and not np.all(np.isfinite(s)):
        s = None
    if t.size < 8 or not np.all(np.isfinite(c)):
        raise PhaseError(f"the phase reference (effort [cos tau]) has {t.size} samples or "
                         "non-finite values: need at least 8 finite samples")
    omega0, tau00 = _initial(t, c, s)
    if not omega0 > 0.0:
        raise PhaseError(f"the phase reference does not advance (omega = {omega0:.3g}): "
                         "is effort [cos tau] recorded?")

    def residual(q):
        tau = q[0] * t + q[1]
        out = [np.cos(tau) - c]
        if s is not None:
            out.append(np.sin(tau) - s)
        return np.concatenate(out)

    def jacobian(q):
        tau = q[0] * t + q[1]
        st, ct = np.sin(tau), np.cos(tau)
        rows = [np.column_stack([-st * t, -st])]
        if s is not None:
            rows.append(np.column_stack([ct * t, ct]))
        return np.vstack(rows)

    sol = least_squares(residual, [omega0, tau00], jac=jacobian, method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    res = sol.fun
    m = res.size
    rms = float(np.sqrt(np.mean(res ** 2)))
    if not rms <= tolerance or not sol.x[0] > 0.0:
        raise PhaseError(f"the phase reference is not harmonic: RMS residual {rms:.3g} of "
                         f"cos(omega t + tau0) (valid: <= {tolerance:g})")
    J = sol.jac
    sigma2 = float(res @ res) / max(m - 2, 1)
    try:
        cov = sigma2 * np.linalg.inv(J.T @ J)
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        se = np.array([math.inf, math.inf])
    return PhaseReference(float(sol.x[0]), float(sol.x[1] % TWO_PI), float(se[0]),
                          float(se[1]), rms)

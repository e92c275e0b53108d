"""Measurement noise through the closed loop: the linearised loop and its stationary spread.

The controlled 1/1 orbit z* on Pi2 (deviation coordinates, sampled before the
correction) is a fixed point of the closed-loop map. The controller does not see z_k
but a measurement (or an estimate) z_k + n_k, so the correction it applies is
k^T (z_k + n_k), k = (c1, c2). Linearised about z* (docs/robustness.md, "Noise through
the loop"):

    e_{k+1} = J e_k + M2 e2 k^T n_k,        J = M2 (M1 + e2 k^T),

with M1 the monodromy of the flow from the sample to the kick (I without a delay), M2
that of the flow from the kick to the next sample (docs/theory_delay.md, (D3)). For
independent noise of covariance sigma^2 R (R = I: equal sigma on x and v) the stationary
covariance of e solves the discrete Lyapunov equation

    Sigma = J Sigma J^T + sigma^2 (M2 e2)(M2 e2)^T (k^T R k),

and the **noise gain** is sqrt(Sigma_xx) / sigma: the standard deviation of the Pi2
position per unit measurement noise. Near grazing M2 carries the saltation term
(1 + r)(cos tau_i - d) / v-, so the gain grows like 1/v- unless k^T R k is small: the
choice of c2 along the admissible set matters (the study's c2 = -1 is not the best).
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import advance
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["loop_linearisation", "noise_covariance", "noise_gain"]


def loop_linearisation(p: OscillatorParams, gains: Gains, target):
    """(J, M2, dv*) at the orbit z* = ``target``: J = M2 (M1 + e2 k^T)
    (docs/theory_delay.md (D3)), M2 the monodromy of the flow from the kick to the next
    sample, dv* = k^T z* the correction on the orbit. Exact (closed-form flow and
    saltation), no finite differences."""
    dx, dv = target
    dvc = gains.c1 * dx + gains.c2 * dv
    if gains.delay == 0.0:
        m1 = (1.0, 0.0, 0.0, 1.0)
        second = advance(p, p.tau2, dx, dv + dvc, p.period, monodromy=True)
    else:
        first = advance(p, p.tau2, dx, dv, gains.delay, monodromy=True)
        m1 = first.monodromy
        tau = (p.tau2 + p.omega * gains.delay) % (2.0 * math.pi)
        second = advance(p, tau, first.dx, first.dv + dvc, p.period - gains.delay,
                         monodromy=True)
    m2 = np.array(second.monodromy).reshape(2, 2)
    j = m2 @ (np.array(m1).reshape(2, 2) + np.outer([0.0, 1.0], [gains.c1, gains.c2]))
    return j, m2, dvc


def noise_covariance(p: OscillatorParams, gains: Gains, measurement=None, target=None):
    """Stationary covariance of the Pi2 deviation per unit measurement variance (2x2).

    ``measurement``: the covariance R of the measurement (or estimate) error per unit
    sigma^2 (default I: independent noise of equal sigma on x and v). ``target``: the
    controlled orbit's Pi2 deviation (default: :func:`grazing_control.dynamics.orbits.orbits.orbit_11`
    at ``p.delta_d``). Raises ValueError when the loop is not stable (|lambda| >= 1):
    there is no stationary spread.
    """
    from scipy.linalg import solve_discrete_lyapunov

    from grazing_control.dynamics.orbits.orbits import orbit_11

    if target is None:
        target = orbit_11(p, gains).pi2_deviation
    j, m2, _ = loop_linearisation(p, gains, target)
    rho = float(np.max(np.abs(np.linalg.eigvals(j))))
    if not rho < 1.0:
        raise ValueError(f"the controlled orbit at delta_d={p.delta_d!r} is not stable "
                         f"(largest multiplier {rho:.6g}): no stationary spread")
    r = np.eye(2) if measurement is None else np.asarray(measurement, dtype=float)
    k = np.array([gains.c1, gains.c2])
    b = m2[:, 1]
    return solve_discrete_lyapunov(j, float(k @ r @ k) * np.outer(b, b))


def noise_gain(p: OscillatorParams, gains: Gains, measurement=None, target=None) -> float:
    """sqrt(Sigma_xx) / sigma: the std of the Pi2 position per unit measurement noise
    (module docstring; :func:`noise_covariance` for the arguments)."""
    return float(math.sqrt(max(noise_covariance(p, gains, measurement, target)[0, 0], 0.0)))

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

**n DOF** (docs/ndof_scene.md): the same loop over the exact n-DOF map
(:class:`grazing_control.dynamics.maps.modal_map.ModalMap`, gains k in R^{2n}, the kick on
v_{i_a} ``delay`` after the sample), linearised about its controlled orbit z*:

    e_{k+1} = J e_k + g k^T n_k,    J = M2 (M1 + b k^T),    g = M2 b,   b = e_{n + i_a},

and Sigma = J Sigma J^T + sigma^2 g g^T (k^T R k) (:func:`ndof_noise_covariance`). With
a force pulse of ``width`` w centred ``delay`` after the sample (docs/theory_ndof.md
section 15) J is ModalMap(model, k, delay, w)'s Jacobian and g the period's input
d z_{k+1} / d(Delta v) (:func:`grazing_control.dynamics.maps.modal_map.pulse_step`'s
``input``: M3 ((I - M_p) sigma - g_w sigma_w) m_a / w). R is
the model filter's error covariance on the orbit per unit sigma^2, for a sensor of one
coordinate's position at ``rate`` samples per period: the fixed point of (E5),
P = M (P^-1 + H^T H)^-1 M^T + floor^2 I, H the rows of that position in the exact
trajectory's Jacobian (:func:`ndof_filter_covariance`). Treating the estimate's errors
as independent from section to section is the approximation (the filter carries them
on); docs/ndof_scene.md checks the prediction against a seeded closed loop.
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import advance
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["loop_linearisation", "noise_covariance", "noise_gain", "ndof_loop_linearisation",
           "ndof_filter_covariance", "ndof_noise_covariance"]


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


def ndof_loop_linearisation(model, gains, target, delay: float = 0.0, width: float = 0.0):
    """(J, g) of the n-DOF loop at the orbit z* = ``target`` (module docstring): J the
    closed-loop map's Jacobian, g = M2 e_{n + i_a} the next sample's sensitivity to the
    kick (with a pulse ``width`` > 0: to the pulse's Delta v). Exact (the core's
    monodromies, :class:`ModalMap`'s step)."""
    from grazing_control.dynamics.maps.modal_map import ModalMap, pulse_step
    from grazing_control.oscillator.ndof.impact import advance as ndof_advance

    P = ModalMap(model, gains, delay, width)
    z = np.array(target, dtype=float)
    J = P.step(z, jacobian=True).jacobian
    flow, n = P.flow, model.n
    kick = float(P.gains @ z)
    if P.width != 0.0:
        out = pulse_step(flow, z, kick, start=P.pulse_start, width=P.width, jacobian=True)
        return J, np.array(out.input)
    first = ndof_advance(flow, flow.tau2, z, delay) if delay > 0.0 else None
    mid = np.array(z if first is None else first.z, dtype=float)
    mid[n + model.i_a] += kick
    second = ndof_advance(flow, (flow.tau2 + model.omega * delay) % (2.0 * math.pi), mid,
                          model.period - delay, monodromy=True)
    return J, np.array(second.monodromy)[:, n + model.i_a]


def ndof_filter_covariance(model, gains, target, rate: int, coordinate: int,
                           delay: float = 0.0, floor: float = 1e-2,
                           periods: int = 400, width: float = 0.0,
                           section_sample: bool = True, actuator=None,
                           force0: float = 0.0) -> np.ndarray:
    """The model filter's error covariance on the n-DOF orbit z* per unit sigma^2 (2n x 2n):
    the fixed point of (E5) for samples of coordinate ``coordinate``'s position at
    s_j = j T / rate, j = 1 .. rate (module docstring), iterated from 1e4 I for
    ``periods`` periods at most; the correction a pulse of ``width`` (0: the kick).
    ``section_sample`` False: the sample at the section itself (j = rate) is not fitted,
    as a controller that answers before t_k does (lockstep: the stream estimator does
    not wait for it, ``StreamEstimator.add_sample``; realtime with
    ``answer_after_section`` does). On the chain at T/200 that sample carries a tenth of
    the information: without it the covariance's std is 1.10-1.13 times larger
    (docs/ndof_scene.md). ``actuator`` (an
    :class:`~grazing_control.dynamics.simulation.actuator.Actuator`) and ``force0``: the
    pulse through the first-order lag from the force on the orbit at the section (the
    filter knows the force: the controller carries it from its own commands,
    docs/theory_ndof.md section 17)."""
    from grazing_control.dynamics.estimation.motion import trajectory

    z = np.array(target, dtype=float)
    last = int(rate) + (1 if section_sample else 0)
    s = model.period * np.arange(1, last) / rate
    kick = float(np.asarray(gains, dtype=float) @ z)
    _out, jac, _end, mono, _imps = trajectory(model, z, s, kick, delay, width=width,
                                               actuator=actuator, force0=force0)
    h = jac[:, coordinate, :]
    eye = np.eye(len(z))
    cov = 1e4 * eye
    for _ in range(periods):
        post = np.linalg.inv(np.linalg.inv(cov) + h.T @ h)
        new = mono @ post @ mono.T + floor ** 2 * eye
        new = 0.5 * (new + new.T)
        done = np.max(np.abs(new - cov)) <= 1e-12 * np.max(np.abs(new))
        cov = new
        if done:
            break
    return cov


def ndof_noise_covariance(model, gains, target, measurement, delay: float = 0.0,
                          width: float = 0.0):
    """Stationary covariance of the n-DOF Pi2 deviation per unit sigma^2 (2n x 2n):
    Sigma = J Sigma J^T + g g^T (k^T R k), R = ``measurement`` (module docstring), the
    correction a pulse of ``width`` (0: the kick). Raises ValueError when the loop is
    not stable."""
    from scipy.linalg import solve_discrete_lyapunov

    J, g = ndof_loop_linearisation(model, gains, target, delay, width)
    rho = float(np.max(np.abs(np.linalg.eigvals(J))))
    if not rho < 1.0:
        raise ValueError(f"the controlled orbit at delta_d={model.delta_d!r} is not stable "
                         f"(largest multiplier {rho:.6g}): no stationary spread")
    k = np.asarray(gains, dtype=float)
    r = np.asarray(measurement, dtype=float)
    return solve_discrete_lyapunov(J, float(k @ r @ k) * np.outer(g, g))

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

and Sigma = J Sigma J^T + sigma^2 g g^T (k^T R k) (:func:`noise_covariance`). With
a force pulse of ``width`` w centred ``delay`` after the sample (docs/theory_ndof.md
section 15) J is ModalMap(model, k, delay, w)'s Jacobian and g the period's input
d z_{k+1} / d(Delta v) (:func:`grazing_control.dynamics.maps.modal_map.pulse_step`'s
``input``: M3 ((I - M_p) sigma - g_w sigma_w) m_a / w). R is
the model filter's error covariance on the orbit per unit sigma^2, for a sensor of one
coordinate's position at ``rate`` samples per period: the fixed point of (E5),
P = M (P^-1 + H^T H)^-1 M^T + floor^2 I, H the rows of that position in the exact
trajectory's Jacobian (:func:`filter_covariance`). Treating the estimate's errors
as independent from section to section is the approximation (the filter carries them
on); docs/ndof_scene.md checks the prediction against a seeded closed loop.

One entry for every model (issue 32): :func:`noise_covariance` takes the 1-DOF
parameters (the closed form above, unchanged) or a model file of any n (the exact map
over its modal flow, n = 1 included).

**The predicted spread with the pulse and through the actuator's lag** (issue 32;
docs/theory_ndof.md section 17, :func:`predicted_spread`).

The loop's state on Pi2 is y = z (2n) for the kick and the ideal pulse, y = (z, F)
(2n + 1) through a first-order actuator (F the actuator's force at the section, carried
from period to period). Linearised about the controlled 1/1 orbit y*, with the
correction Delta v_k = k^T (z_k + n_k) (n_k the estimate's error, covariance sigma^2 R)
and a velocity noise xi_k on v_{i_a} at each sample (variance sigma_v^2):

    e_{k+1} = J e_k + g k^T n_k + e_v xi_k,    J = D_y f + g [k^T, 0],

f one period of the exact map (:func:`~grazing_control.dynamics.maps.modal_map.actuated_step`,
:class:`~grazing_control.dynamics.maps.modal_map.ModalMap`), g = d y_{k+1} / d(Delta v) and
e_v = e_{n + i_a}, both exact (no finite differences). For independent n_k and xi_k the
stationary covariance solves the discrete Lyapunov equation

    Sigma = J Sigma J^T + sigma^2 (k^T R k) g g^T + sigma_v^2 e_v e_v^T,      (N11)

and the corrections' variance is k^T Sigma_zz k + sigma^2 k^T R k (N12). For n = 1
with the kick this is :func:`noise_covariance` of the 1-DOF closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import advance
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from grazing_control.dynamics.design.family import Actuation

__all__ = ["loop_linearisation", "noise_covariance", "noise_gain", "filter_covariance",
           "LoopSpread", "loop_step", "controlled_orbit", "spread_linearisation",
           "predicted_spread"]


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


def noise_covariance(p, gains, measurement=None, target=None, delay: float = 0.0,
                     width: float = 0.0):
    """Stationary covariance of the Pi2 deviation per unit measurement variance.

    ``measurement``: the covariance R of the measurement (or estimate) error per unit
    sigma^2 (default I: independent noise of equal sigma on every coordinate).
    ``target``: the controlled orbit's Pi2 deviation (default for the 1-DOF oscillator:
    :func:`grazing_control.dynamics.orbits.orbits.orbit_11` at ``p.delta_d``). Raises
    ValueError when the loop is not stable (|lambda| >= 1): there is no stationary spread.

    ``p`` is the 1-DOF parameters (2x2, the closed form; ``gains`` a :class:`Gains` with
    its delay) or a model file (2n x 2n, the gain vector k, the kick ``delay`` after the
    sample or a pulse of ``width``: :func:`_modal_noise_covariance`, the target required).
    """
    if isinstance(p, NdofModel):
        return _modal_noise_covariance(p, gains, target, measurement, delay, width)
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


def _modal_loop_linearisation(model, gains, target, delay: float = 0.0, width: float = 0.0):
    """(J, g) of a model file's loop at the orbit z* = ``target`` (module docstring): J the
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


def filter_covariance(model, gains, target, rate: int, coordinate: int,
                      delay: float = 0.0, floor: float = 1e-2,
                      periods: int = 400, width: float = 0.0,
                      section_sample: bool = True, actuator=None,
                      force0: float = 0.0) -> np.ndarray:
    """The model filter's error covariance on a model file's orbit z* per unit sigma^2 (2n x 2n):
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


def _modal_noise_covariance(model, gains, target, measurement, delay: float = 0.0,
                            width: float = 0.0):
    """Stationary covariance of a model file's Pi2 deviation per unit sigma^2 (2n x 2n):
    Sigma = J Sigma J^T + g g^T (k^T R k), R = ``measurement`` (module docstring), the
    correction a pulse of ``width`` (0: the kick). Raises ValueError when the loop is
    not stable."""
    from scipy.linalg import solve_discrete_lyapunov

    if target is None:
        raise ParameterError("target is missing: a model file's noise covariance needs its "
                             "controlled orbit (controlled_orbit)")
    r = np.eye(2 * model.n) if measurement is None else measurement
    J, g = _modal_loop_linearisation(model, gains, target, delay, width)
    rho = float(np.max(np.abs(np.linalg.eigvals(J))))
    if not rho < 1.0:
        raise ValueError(f"the controlled orbit at delta_d={model.delta_d!r} is not stable "
                         f"(largest multiplier {rho:.6g}): no stationary spread")
    k = np.asarray(gains, dtype=float)
    r = np.asarray(r, dtype=float)
    return solve_discrete_lyapunov(J, float(k @ r @ k) * np.outer(g, g))


# -- a model file's spread with the pulse and through the lag (docs/theory_ndof.md §17) --

def _lagged(delay) -> bool:
    """Whether the correction goes through a first-order lag (a force state)."""
    return isinstance(delay, Actuation) and delay.time_constant > 0.0


def loop_step(model: NdofModel, gains, delay, y, jacobian: bool = False):
    """One period of the closed loop from y (z, or (z, F) through the lag) with the
    correction k^T z: (y_next, impacts) and with ``jacobian`` (D_y f at a fixed
    correction, g = d y_next / d(Delta v)). ``delay``: the kick's delay (a float) or
    an :class:`Actuation`."""
    from grazing_control.dynamics.maps.modal_map import ModalMap, actuated_step, pulse_step

    k = np.asarray(gains, dtype=float)
    y = np.asarray(y, dtype=float)
    d = 2 * model.n
    dv = float(k @ y[:d])
    flow = NdofFlow.of(model)
    if isinstance(delay, Actuation):
        lagged = _lagged(delay)
        out = actuated_step(flow, y[:d], float(y[d]) if lagged else 0.0, dv,
                            start=delay.start(model), width=delay.width,
                            time_constant=delay.time_constant, latency=delay.latency,
                            jacobian=jacobian)
        keep = d + 1 if lagged else d
        nxt = np.append(out[0], out[1])[:keep]
        if not jacobian:
            return nxt, list(out[2])
        return nxt, list(out[2]), out[3][:keep, :keep], out[4][:keep]
    # the kick ``delay`` after the sample (width 0; ModalMap checks 0 <= delay < T):
    # D_y f = M2 M1, g = M2 e_{n + i_a}
    out = pulse_step(flow, y, dv, start=ModalMap(model, None, delay).delay, width=0.0,
                     jacobian=jacobian)
    if not jacobian:
        return out.state, list(out.impacts)
    return out.state, list(out.impacts), out.jacobian, out.input


def controlled_orbit(model: NdofModel, gains, delay=0.0, guess=None, tol: float = 1e-13,
                     max_iter: int = 40) -> np.ndarray:
    """The closed loop's 1/1 orbit y* (z*, and F* through the lag) by Newton with the
    exact Jacobian from ``guess`` (default: the orbit of the ideal pulse / the kick on
    the 1/1 branch, :func:`grazing_control.dynamics.orbits.modal_branch.orbit_at`, the
    force 0); through a lag continued in tau_a from a tenth of it (8 steps), as the
    1-DOF :func:`grazing_control.dynamics.simulation.actuator.actuated_design`.

    Raises ValueError when Newton does not converge or the orbit has not one impact
    per period."""
    import dataclasses

    from grazing_control.dynamics.orbits import modal_branch

    k = np.asarray(gains, dtype=float)
    if guess is None:
        ideal = delay
        if isinstance(delay, Actuation):
            ideal = Actuation(delay.delay + delay.latency, delay.width)
        guess = modal_branch.orbit_at(model, k, model.delta_d, delay=ideal).pi2_state
    y = np.array(guess, dtype=float)
    if _lagged(delay):
        if y.size == 2 * model.n:
            y = np.append(y, 0.0)
        shares = np.geomspace(0.1, 1.0, 8)
        for share in shares:
            step = dataclasses.replace(delay, time_constant=delay.time_constant * float(share))
            y = _newton(model, k, step, y, tol, max_iter)
        return y
    return _newton(model, k, delay, y, tol, max_iter)


def _newton(model, k, delay, y, tol, max_iter):
    """Newton on f(y) - y = 0 with J = D_y f + g [k^T, 0] (exact)."""
    for _ in range(max_iter):
        nxt, imps, jac, g = loop_step(model, k, delay, y, jacobian=True)
        closed = jac + np.outer(g, _gain_row(k, y.size))
        step = np.linalg.solve(closed - np.eye(y.size), -(nxt - y))
        y = y + step
        if np.max(np.abs(step)) <= tol * max(1.0, float(np.max(np.abs(y)))):
            nxt, imps = loop_step(model, k, delay, y)
            if len(imps) != 1:
                raise ValueError(f"the controlled orbit has {len(imps)} impacts per period, "
                                 f"not 1")
            return y
    raise ValueError(f"Newton did not converge in {max_iter} iterations to the controlled "
                     f"1/1 orbit at delta_d={model.delta_d!r}")


def _gain_row(k, size: int) -> np.ndarray:
    """[k^T, 0]: the correction's row over y (the force does not enter it)."""
    row = np.zeros(size)
    row[:k.size] = k
    return row


def spread_linearisation(model: NdofModel, gains, orbit, delay=0.0):
    """(J, g, e_v) at the orbit y* (module docstring): the closed loop's Jacobian, the
    next state's sensitivity to the correction and the velocity noise's direction."""
    k = np.asarray(gains, dtype=float)
    y = np.asarray(orbit, dtype=float)
    _nxt, _imps, jac, g = loop_step(model, k, delay, y, jacobian=True)
    ev = np.zeros(y.size)
    ev[model.n + model.i_a] = 1.0
    return jac + np.outer(g, _gain_row(k, y.size)), g, ev


@dataclass(frozen=True)
class LoopSpread:
    """The loop's stationary spread per unit sigma (module docstring).

    orbit : y* on Pi2 (z*, and F* through the lag).
    covariance : Sigma of y per unit sigma^2, (N11).
    correction_variance : of Delta v per unit sigma^2, (N12).
    spectral_radius : max |eig J|.
    """

    orbit: np.ndarray
    covariance: np.ndarray
    correction_variance: float
    spectral_radius: float

    @property
    def std(self) -> np.ndarray:
        """sqrt(diag Sigma): the std of each coordinate of y per unit sigma."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @property
    def correction_std(self) -> float:
        return math.sqrt(max(self.correction_variance, 0.0))


def predicted_spread(model: NdofModel, gains, delay=0.0, *, measurement=None,
                     velocity: float = 0.0, orbit=None) -> LoopSpread:
    """The stationary spread of a model file's controlled loop per unit sigma (N11, N12):
    ``measurement`` R the estimate's error covariance per unit sigma^2 (2n x 2n; default
    I: every coordinate measured with sigma; 0: an exact state), ``velocity``
    sigma_v / sigma of the velocity noise at Pi2, ``delay`` the kick's delay or an
    :class:`Actuation` (pulse, lag), ``orbit`` y* (default :func:`controlled_orbit`).
    Raises ValueError where the loop is not stable (no stationary spread)."""
    from scipy.linalg import solve_discrete_lyapunov

    k = np.asarray(gains, dtype=float)
    d = 2 * model.n
    r = np.eye(d) if measurement is None else np.asarray(measurement, dtype=float)
    if r.shape != (d, d) or not np.all(np.isfinite(r)):
        raise ParameterError(f"measurement is invalid: expected a finite {d} x {d} covariance")
    if not (math.isfinite(velocity) and velocity >= 0.0):
        raise ParameterError(f"velocity={velocity!r} is invalid: valid range is a finite "
                             f"velocity >= 0 (sigma_v / sigma)")
    y = controlled_orbit(model, k, delay) if orbit is None else np.asarray(orbit, dtype=float)
    J, g, ev = spread_linearisation(model, k, y, delay)
    rho = float(np.max(np.abs(np.linalg.eigvals(J))))
    if not rho < 1.0:
        raise ValueError(f"the controlled orbit at delta_d={model.delta_d!r} is not stable "
                         f"(largest multiplier {rho:.6g}): no stationary spread")
    krk = float(k @ r @ k)
    sigma = solve_discrete_lyapunov(J, krk * np.outer(g, g) + velocity ** 2 * np.outer(ev, ev))
    var = float(k @ sigma[:d, :d] @ k) + krk
    return LoopSpread(y, sigma, var, rho)

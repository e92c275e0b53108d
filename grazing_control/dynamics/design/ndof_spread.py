"""The predicted spread of the controlled n-DOF loop with the pulse and through the
actuator's lag (issue 32; docs/theory_ndof.md section 17).

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
with the kick this is grazing_control.dynamics.design.noise.noise_covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.design.family import Actuation

__all__ = ["LoopSpread", "loop_step", "controlled_orbit", "loop_linearisation",
           "predicted_spread"]


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


def loop_linearisation(model: NdofModel, gains, orbit, delay=0.0):
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
    """The stationary spread of the controlled n-DOF loop per unit sigma (N11, N12):
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
    J, g, ev = loop_linearisation(model, k, y, delay)
    rho = float(np.max(np.abs(np.linalg.eigvals(J))))
    if not rho < 1.0:
        raise ValueError(f"the controlled orbit at delta_d={model.delta_d!r} is not stable "
                         f"(largest multiplier {rho:.6g}): no stationary spread")
    krk = float(k @ r @ k)
    sigma = solve_discrete_lyapunov(J, krk * np.outer(g, g) + velocity ** 2 * np.outer(ev, ev))
    var = float(k @ sigma[:d, :d] @ k) + krk
    return LoopSpread(y, sigma, var, rho)

"""The 1/1 orbit of an n-DOF model near grazing: prediction, shooting, multipliers vs Delta d.

The prediction is the leading-order local map of docs/theory_ndof.md ("Local map near
grazing"), written on Pi2 (docs/ndof_commands.md, "The starting guess"). With the state z
sampled on Pi2 before the kick (deviation from the grazing orbit), the kick
K = I + b k^T, the flow Phi_a from Pi2 to the next Pi1 and Phi_b from Pi1 to Pi2,

    P(z) = Phi_b D(Phi_a K z),    D(y) = y + u sqrt(H),
    H = w^T y + (e_{v_i_w}^T y)^2 / (2 |a|) - Delta d,   u = -(1 + r) omega sqrt(2 d*) e_{v_i_w},

(H: the largest penetration of the free flight x_w + v_w t - |a| t^2 / 2; u: the
velocity jump of the wall coordinate, v- = sqrt(2 |a| H) with the grazing acceleration
|a| = omega^2 d* of the harmonic response). With N = Phi_a K Phi_b, a fixed point has
y = (I - N)^-1 N u s at Pi1, and s = sqrt(H) solves s^2 (1 - c) = G1 s - Delta d with
G1 = w^T (I - N)^-1 N u = G(1), the singular transfer function at lambda = 1, and
c = (e_v^T (I - N)^-1 N u)^2 / (2 |a|): the positive root is the impact of the predicted
1/1 orbit. The velocity term is kept because on the design family (G == 0, so
w^T y = 0) it is of the order of H itself: without it the prediction is off by a
relative O(1) (measured: 40 % on the n = 1 file at c2 = -1). Newton shooting
(:func:`grazing_control.dynamics.shooting.find_periodic`) on the exact map then gives the
orbit and its monodromy; the prediction is only its starting guess.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.ndof_map import NdofMap
from grazing_control.dynamics.shooting import (ShootingFailed, find_periodic,
                                               floquet_multipliers, iterate)
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.params import ParameterError

__all__ = ["OrbitNotFound", "NdofOrbit", "Scaling", "with_delta_d", "kick_matrix",
           "smooth_map", "predicted_orbit", "orbit_11", "multiplier_scaling", "fit_exponent"]

TWO_PI = 2.0 * math.pi


class OrbitNotFound(RuntimeError):
    """No 1/1 orbit near grazing was found from any of the starting guesses."""


class NdofOrbit(NamedTuple):
    """A 1/1 orbit: Pi2 state (deviation, before the kick), its physical value, the
    Floquet multipliers (decreasing modulus), impact time since the sample, phase and
    velocity v-, and which starting guess converged."""

    delta_d: float
    state: np.ndarray
    physical: np.ndarray
    multipliers: np.ndarray
    monodromy: np.ndarray
    impact_dt: float
    impact_phase: float
    v_minus: float
    guess: str

    @property
    def stable(self) -> bool:
        return bool(np.max(np.abs(self.multipliers)) < 1.0)


def with_delta_d(model, delta_d: float):
    """The same model with the wall at Delta d (validated by the model)."""
    return dataclasses.replace(model, delta_d=float(delta_d))


def _gains(model, gains):
    if gains is None:
        return None
    k = np.asarray(gains, dtype=float).reshape(-1)
    if k.shape != (2 * model.n,) or not np.all(np.isfinite(k)):
        raise ParameterError(f"gains={np.asarray(gains).tolist()!r} is invalid: expected "
                             f"2n = {2 * model.n} finite values (x0..x{model.n - 1}, "
                             f"v0..v{model.n - 1})")
    return k


def kick_matrix(model, gains) -> np.ndarray:
    """K = I + b k^T, b the velocity unit vector of the actuated coordinate (the kick
    v[i_a] += k^T z at Pi2; issue 17, "The design"); I without gains."""
    n2 = 2 * model.n
    K = np.eye(n2)
    k = _gains(model, gains)
    if k is not None:
        K[model.n + model.i_a] += k
    return K


def smooth_map(model, gains=None):
    """(N, Phi_a, Phi_b, K): the smooth return map on Pi1 N = Phi_a K Phi_b and its
    factors (module docstring)."""
    flow = NdofFlow.of(model)
    off = model.pi2_offset / model.omega
    phi_a = flow.transition(model.period - off)
    phi_b = flow.transition(off)
    K = kick_matrix(model, gains)
    return phi_a @ K @ phi_b, phi_a, phi_b, K


def predicted_orbit(model, gains=None, delta_d: float | None = None):
    """Leading-order 1/1 orbit on Pi2 and its s = sqrt(H) (module docstring), or
    (None, nan) when the local map has no impacting fixed point there."""
    dd = model.delta_d if delta_d is None else float(delta_d)
    flow = NdofFlow.of(model)
    n, n2 = model.n, 2 * model.n
    N, _phi_a, phi_b, _K = smooth_map(model, gains)
    u = np.zeros(n2)
    u[n + model.i_w] = -(1.0 + model.r) * model.omega * math.sqrt(2.0 * flow.d_star)
    w = np.zeros(n2)
    w[model.i_w] = 1.0
    try:
        y_unit = np.linalg.solve(np.eye(n2) - N, N @ u)
    except np.linalg.LinAlgError:
        return None, math.nan
    g1 = float(w @ y_unit)
    # H = w^T y + v_w^2 / (2 |a|) - Delta d: the velocity term is of the order of H when
    # y ~ s (on the family, where w^T y = 0), so it stays: s^2 (1 - c) - G1 s + Delta d = 0
    c = float(y_unit[n + model.i_w]) ** 2 / (2.0 * model.omega ** 2 * flow.d_star)
    s = math.nan
    for a in ((1.0 - c), 1.0):
        disc = g1 * g1 - 4.0 * a * dd
        if a > 0.0 and disc >= 0.0:
            s = (g1 + math.sqrt(disc)) / (2.0 * a)
            if s > 0.0:
                break
    if not s > 0.0:
        return None, math.nan
    return phi_b @ (y_unit * s + u * s), s


def _multipliers(pmap, monodromy, impacts):
    det = None
    jd = getattr(pmap, "jacobian_det", None)
    if jd is not None and not any(getattr(i, "sticking", False) for i in impacts):
        det = jd(1, len(impacts))
    return floquet_multipliers(monodromy, det)


def orbit_11(model, gains=None, delta_d: float | None = None, *, tol: float = 1e-14,
             extra_guesses=()) -> NdofOrbit:
    """The 1/1 orbit at ``delta_d`` (default the model's), by Newton shooting.

    Starting guesses, in order: the leading-order prediction (:func:`predicted_orbit`),
    ``extra_guesses`` (name, state pairs), the grazing point z = 0, and the end of a
    200-period simulation from the prediction. The first that converges to an orbit with
    exactly one impact per period wins.

    Raises
    ------
    OrbitNotFound
        None converged to a 1/1 orbit (the message lists why each failed).
    """
    if delta_d is not None:
        model = with_delta_d(model, delta_d)
    pmap = NdofMap(model, _gains(model, gains))
    pred, _s = predicted_orbit(model, gains)
    guesses = [] if pred is None else [("discontinuity map", pred)]
    guesses += list(extra_guesses)
    guesses.append(("grazing point", np.zeros(pmap.dimension)))
    why = []
    tried_simulation = False
    i = 0
    while i < len(guesses):
        name, guess = guesses[i]
        i += 1
        try:
            o = find_periodic(pmap, guess, 1, tol=tol)
        except (ShootingFailed, ValueError, ArithmeticError) as exc:
            why.append(f"{name}: {' '.join(str(exc).split())[:120]}")
        else:
            if len(o.impacts) == 1 and o.impacts[0].v_minus > 0.0:
                imp = o.impacts[0]
                lam = _multipliers(pmap, o.monodromy, o.impacts)
                flow = NdofFlow.of(model)
                return NdofOrbit(model.delta_d, o.state, flow.to_physical(flow.tau2, o.state),
                                 lam, o.monodromy, float(imp.dt), float(imp.phase),
                                 float(imp.v_minus), name)
            why.append(f"{name}: converged to an orbit with {len(o.impacts)} impacts per period")
        if i == len(guesses) and not tried_simulation:
            tried_simulation = True
            try:
                z, _jac, _imp = iterate(pmap, pred if pred is not None else guesses[-1][1], 200)
                if np.all(np.isfinite(z)):
                    guesses.append(("simulation", z))
            except (ValueError, ArithmeticError, RuntimeError) as exc:
                why.append(f"simulation: {' '.join(str(exc).split())[:120]}")
    raise OrbitNotFound(f"no 1/1 orbit found at delta_d={model.delta_d!r} "
                        f"({'; '.join(why)})")


class Scaling(NamedTuple):
    """Multipliers of the 1/1 orbit on a grid of Delta d (rows in grid order; nan where
    no orbit was found, with the reason in ``errors``)."""

    delta_d: np.ndarray
    multipliers: np.ndarray
    v_minus: np.ndarray
    errors: tuple

    @property
    def largest(self) -> np.ndarray:
        return np.max(np.abs(self.multipliers), axis=1)


def multiplier_scaling(model, gains, deltas) -> Scaling:
    """The 1/1 orbit's multipliers at each Delta d of ``deltas`` (each by :func:`orbit_11`;
    the previous point's orbit is tried after the prediction)."""
    deltas = np.asarray(deltas, dtype=float).reshape(-1)
    n2 = 2 * model.n
    lam = np.full((deltas.size, n2), np.nan, dtype=complex)
    vm = np.full(deltas.size, np.nan)
    errors = []
    prev = None
    for j, dd in enumerate(deltas):
        extra = () if prev is None else (("previous point", prev),)
        try:
            o = orbit_11(model, gains, dd, extra_guesses=extra)
        except (OrbitNotFound, ValueError) as exc:
            errors.append(str(exc))
            prev = None
            continue
        lam[j], vm[j] = o.multipliers, o.v_minus
        prev = o.state
        errors.append("")
    return Scaling(deltas, lam, vm, tuple(errors))


def fit_exponent(delta_d, values) -> float:
    """Least-squares slope of log|values| against log|Delta d| (the growth exponent:
    -1/2 for |lambda| ~ |Delta d|^(-1/2)); nan with fewer than two finite points."""
    x = np.log(np.abs(np.asarray(delta_d, dtype=float)))
    y = np.log(np.abs(np.asarray(values, dtype=float)))
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 2:
        return math.nan
    return float(np.polyfit(x[ok], y[ok], 1)[0])

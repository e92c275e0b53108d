"""Zero-time discontinuity mapping of the n-DOF oscillator at Pi1 (issue 17).

Derived in docs/theory_ndof.md §10 (the n-DOF form of docs/theory_zdm.md). On
Pi1 = {tau = tau*} the state z in R^{2n} is the *virtual* deviation from the periodic
response (the smooth flow, wall ignored). There the wall coordinate of x_p is at its
maximum d* with zero velocity, so the gap and its rate are

    e1 = w^T z - Delta d,    e2 = e_v^T z,

and along the smooth flow through z the gap is (exactly)

    g(t) = w^T Phi(t) z - 2 d* sin^2(omega t / 2) - Delta d.               (Z0)

If it crosses the wall near t = 0 (local time t1, velocity v- > 0) the real motion
differs from the smooth one by the impact, and since the deviation flow is linear,

    D(z) = z - (1 + r) v- Phi(-t1) e_v                (exact ZDM, one crossing)    (Z2)

so that the exact Pi1 map is N(k) o D. Truncations, in the scale delta with z = O(delta),
e1 = O(delta^2), t1 = O(delta), alpha* = omega^2 d* (minus the grazing acceleration,
> 0: grazing of the periodic response is always regular), alpha(z) = alpha* - kappa^T z
(kappa^T = e_v^T A, the acceleration row), c = w - A e_v = (0, M^-1 C e_{i_w}):

* order 1 (error O(delta^2)): D1(z) = z - (1 + r) sqrt(2 alpha* H0) e_v,
  H0 = e1 + e2^2 / (2 alpha*);
* order 2 (error O(delta^3)): with H = e1 + e2^2 / (2 alpha(z)), v = sqrt(2 alpha(z) H),
  t1 = (e2 - v) / alpha(z),
      D2(z) = z - (1 + r) v e_v + (1 + r) v t1 (w - c).

In the form D = z + u sqrt(H) + O(delta^2): u = -(1 + r) sqrt(2 alpha*) e_v; the O(delta^2)
terms are -2(1 + r) H (w - c) + (1 + r)(e2 v / alpha*)(w - c) - (1 + r) e_v (v - v*) with
v* = sqrt(2 alpha* H): not a multiple of H alone (docs/theory_ndof.md §10).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.ndof.impact import saltation_matrix
from grazing_control.oscillator.ndof.model import NdofModel

from grazing_control.dynamics.maps.zdm import local_crossing
from grazing_control.dynamics.design.ndof_design import _flow, _transition, _vectors, smooth_map

__all__ = [
    "ORDERS",
    "LocalGrazing",
    "local_grazing",
    "gap_on_pi1",
    "h_max",
    "crossing",
    "zdm",
    "zdm_jacobian",
    "normal_form_map",
    "normal_form_jacobian",
]

#: Truncations accepted by :func:`zdm`.
ORDERS = (1, 2, "exact")


class LocalGrazing(NamedTuple):
    """The model's local data at grazing (§10): alpha* = omega^2 d*, the acceleration row
    kappa = A^T e_v, c = w - A e_v (the damping jump), w, e_v, d*."""

    alpha: float
    kappa: np.ndarray
    c: np.ndarray
    w: np.ndarray
    ev: np.ndarray
    d_star: float


def local_grazing(model: NdofModel) -> LocalGrazing:
    """alpha*, kappa, c of the model (§10)."""
    flow = _flow(model)
    a = flow.A
    w, ev, _b = _vectors(model)
    dstar = flow.d_star
    return LocalGrazing(model.omega ** 2 * dstar, a[model.n + model.i_w].copy(), w - a @ ev,
                        w, ev, dstar)


def _state(model: NdofModel, z) -> np.ndarray:
    z = np.asarray(z, dtype=float).reshape(-1)
    if z.shape != (2 * model.n,) or not np.all(np.isfinite(z)):
        raise ValueError(f"z={z!r} is invalid: expected {2 * model.n} finite values")
    return z


def gap_on_pi1(model: NdofModel, z):
    """(e1, e2) = (w^T z - Delta d, e_v^T z), the gap and its rate at Pi1 (§10)."""
    z = _state(model, z)
    return float(z[model.i_w]) - model.delta_d, float(z[model.n + model.i_w])


def h_max(model: NdofModel, z, order: int = 2) -> float:
    """Maximum of the gap along the local smooth flow, truncated (§10, (Z4)):
    order 1: e1 + e2^2 / (2 alpha*) (error O(delta^3)); order 2: e1 + e2^2 / (2 alpha(z))
    (error O(delta^4))."""
    g = local_grazing(model)
    e1, e2 = gap_on_pi1(model, z)
    if order == 1:
        alpha = g.alpha
    elif order == 2:
        alpha = g.alpha - float(g.kappa @ _state(model, z))
    else:
        raise ValueError(f"order={order!r} is invalid: valid values are 1, 2")
    return e1 + e2 * e2 / (2.0 * alpha)


class _Gap:
    """g, g', g'' of (Z0) at local time t."""

    def __init__(self, model, z):
        self.model, self.z = model, z
        self.loc = local_grazing(model)

    def __call__(self, t):
        zt = _transition(self.model, t) @ self.z
        om, ds = self.model.omega, self.loc.d_star
        sh = math.sin(0.5 * om * t)            # cos - 1 = -2 sin^2: no cancellation
        return (float(self.loc.w @ zt) - 2.0 * ds * sh * sh - self.model.delta_d,
                float(self.loc.ev @ zt) - ds * om * math.sin(om * t),
                float(self.loc.kappa @ zt) - ds * om * om * math.cos(om * t))


def crossing(model: NdofModel, z):
    """The local grazing event of the smooth flow through (tau*, z), exactly (§10).

    Returns (t_max, H_max, t1, v-): the local time of the gap's maximum near tau*, its
    value, and when H_max > 0 the time and velocity of the crossing before it (None,
    None otherwise). Raises ValueError when no maximum lies within a quarter period.
    """
    z = _state(model, z)
    f = _Gap(model, z)
    return local_crossing(f, f.loc.ev @ z / f.loc.alpha, f.loc.alpha, model.period,
                          f"z={z.tolist()}")


def _event(model, z, order):
    """(D(z), t1, v-) of the truncation ``order`` (1 or 2), or (z, None, None) if H <= 0."""
    g = local_grazing(model)
    e1, e2 = gap_on_pi1(model, z)
    rr = 1.0 + model.r
    alpha = g.alpha if order == 1 else g.alpha - float(g.kappa @ z)
    v2 = 2.0 * alpha * e1 + e2 * e2          # = 2 alpha H
    if not v2 > 0.0:
        return z.copy(), None, None
    v = math.sqrt(v2)
    t1 = (e2 - v) / alpha
    out = z - rr * v * g.ev
    if order == 2:
        out = out + rr * v * t1 * (g.w - g.c)
    return out, t1, v


def zdm(model: NdofModel, z, order=2) -> np.ndarray:
    """The ZDM D(z) at Pi1 of the given truncation (module docstring): 1, 2 or 'exact'
    ((Z2) with (t1, v-) from :func:`crossing`). The identity where the smooth flow does
    not reach the wall."""
    z = _state(model, z)
    if order in (1, 2):
        return _event(model, z, order)[0]
    if order != "exact":
        raise ValueError(f"order={order!r} is invalid: valid values are {ORDERS}")
    _tm, _hm, t1, v = crossing(model, z)
    if t1 is None:
        return z.copy()
    return z - (1.0 + model.r) * v * (_transition(model, -t1) @ local_grazing(model).ev)


def zdm_jacobian(model: NdofModel, z, order=2) -> np.ndarray:
    """dD/dz of :func:`zdm` (§10).

    'exact': Phi(-t1) S Phi(t1), S the saltation matrix at the crossing (det = r^2);
    1 and 2: the derivatives of the truncations, with grad v = (alpha w + e2 e_v - e1 kappa)/v
    (order 2; order 1 without the kappa term and alpha = alpha*).
    """
    z = _state(model, z)
    d = 2 * model.n
    g = local_grazing(model)
    rr = 1.0 + model.r
    if order == "exact":
        _tm, _hm, t1, v = crossing(model, z)
        if t1 is None:
            return np.eye(d)
        flow = _flow(model)
        fwd = _transition(model, t1)
        sal = saltation_matrix(flow, flow.tau_star + model.omega * t1, fwd @ z)
        return _transition(model, -t1) @ sal @ fwd
    if order not in (1, 2):
        raise ValueError(f"order={order!r} is invalid: valid values are {ORDERS}")
    _out, t1, v = _event(model, z, order)
    if v is None:
        return np.eye(d)
    e1, e2 = gap_on_pi1(model, z)
    if order == 1:
        grad_v = (g.alpha * g.w + e2 * g.ev) / v
        return np.eye(d) - rr * np.outer(g.ev, grad_v)
    alpha = g.alpha - float(g.kappa @ z)
    grad_v = (alpha * g.w + e2 * g.ev - e1 * g.kappa) / v
    grad_t = (g.ev - grad_v) / alpha + (e2 - v) * g.kappa / alpha ** 2
    grad_vt = t1 * grad_v + v * grad_t
    return np.eye(d) - rr * np.outer(g.ev, grad_v) + rr * np.outer(g.w - g.c, grad_vt)


def normal_form_map(model: NdofModel, z, gains=None, order=2) -> np.ndarray:
    """P(z) = N(k) D(z): the Pi1 map near grazing (§10); with order 'exact' it is the
    exact Pi1 map of every motion whose only contact in the period is the one near tau*."""
    return smooth_map(model, gains) @ zdm(model, z, order)


def normal_form_jacobian(model: NdofModel, z, gains=None, order=2) -> np.ndarray:
    """N(k) dD/dz."""
    return smooth_map(model, gains) @ zdm_jacobian(model, z, order)

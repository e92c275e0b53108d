"""Zero-time discontinuity mapping (Nordmark) at the section Pi1, and normal-form maps.

Spec section 7 (study Eqs. 7-8); derived for this model in docs/theory_zdm.md.

On Pi1 = {tau = tau*} the state is the deviation z = (z_x, z_v) from the non-impacting
motion (:mod:`grazing_control.oscillator.flow`); there x_p = d* and v_p = 0, so the gap to the
wall and its rate are simply

    e1 = z_x - Delta d,    e2 = z_v.

The *virtual* state z is the state of the smooth flow (wall ignored). If the smooth
trajectory through (tau*, z) crosses the wall near tau* (local time t1, velocity
v- > 0), the real trajectory differs from it by the impact; the zero-time
discontinuity mapping (ZDM) D is the correction, applied at tau* with no time
elapsed, such that

    exact Pi1 map = N_g o D,      N_g = Phi(T - s) G Phi(s)   (Eqs. 29-32),

for every trajectory whose only impact in the period is that low-velocity one.
Because the flow is linear in deviation coordinates, D is known in closed form
(docs/theory_zdm.md, section 2):

    D(z) = z - (1 + r) v- Phi(-t1) (0, 1)^T                        (exact),

and the truncations expand (t1, v-) in the small scale delta ~ sqrt(H_max):

* leading order (error O(delta^2)): D1(z) = z - (1 + r) sqrt(2 alpha H0) (0, 1),
  H0 = e1 + e2^2 / (2 alpha);
* second order (error O(delta^3)): adds the position correction (1 + r) V t1, the
  O(delta^2) velocity terms, and the cubic term of H_max.

alpha = d - cos tau* > 0 is minus the acceleration at the point (x = d, v = 0,
tau = tau*) of the wall; beta = -omega sin tau* + 2 zeta alpha is the jerk there.

One entry for every model (issue 32): each function takes the model first, then the
virtual state z on Pi1. The 1-DOF oscillator (:class:`OscillatorParams`, z a pair
(z_x, z_v), results as tuples of floats) keeps the closed forms above, the certified
fast path of the study (Eqs. (Z7), (Z8) with the cubic c3 of H_max), unchanged bit for
bit. A model file of any n (:class:`NdofModel`, z an array in R^{2n}, results as arrays)
supplies its flow Phi(t), the wall row w and the velocity row e_v instead
(docs/theory_ndof.md §10): with w = e_{i_w}, e_v = e_{n + i_w}, the gap and its rate are

    e1 = w^T z - Delta d,    e2 = e_v^T z,
    g(t) = w^T Phi(t) z - 2 d* sin^2(omega t / 2) - Delta d,                (Z0)
    D(z) = z - (1 + r) v- Phi(-t1) e_v                (exact ZDM, one crossing)  (Z2)

and for n = 1 (w = e1, e_v = e2) this is the exact ZDM above to rounding
(tests/test_zdm.py). Its truncations use alpha* = omega^2 d* and alpha(z) = alpha* -
kappa^T z (kappa^T = e_v^T A, the acceleration row), c = w - A e_v = (0, M^-1 C e_{i_w}):

* order 1 (error O(delta^2)): D1(z) = z - (1 + r) sqrt(2 alpha* H0) e_v,
  H0 = e1 + e2^2 / (2 alpha*);
* order 2 (error O(delta^3)): with H = e1 + e2^2 / (2 alpha(z)), v = sqrt(2 alpha(z) H),
  t1 = (e2 - v) / alpha(z),
      D2(z) = z - (1 + r) v e_v + (1 + r) v t1 (w - c).

These differ from the 1-DOF closed forms at n = 1 by O(delta^2) (order 1: the 1-DOF
alpha includes Delta d) and O(delta^3) (order 2: other O(delta^3) terms): both are
truncations of the same exact map. In the form D = z + u sqrt(H) + O(delta^2):
u = -(1 + r) sqrt(2 alpha*) e_v; the O(delta^2) terms are -2(1 + r) H (w - c) + (1 + r)
(e2 v / alpha*)(w - c) - (1 + r) e_v (v - v*) with v* = sqrt(2 alpha* H): not a multiple
of H alone (docs/theory_ndof.md §10).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.flow import matmul2, propagate, transition_matrix
from grazing_control.oscillator.impact import Segment
from grazing_control.oscillator.ndof.impact import saltation_matrix
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.dynamics.maps.maps import flow_through_pi2, period_matrix, pi1_map
from grazing_control.dynamics.maps.model import is_model_file
from grazing_control.oscillator.params import OscillatorParams

__all__ = [
    "LocalGrazing",
    "ModalGrazing",
    "local_grazing",
    "gap_on_pi1",
    "h_max",
    "zdm_event",
    "zdm_leading",
    "zdm_second",
    "zdm_exact",
    "local_crossing",
    "zdm",
    "zdm_jacobian",
    "smooth_map",
    "normal_form_map",
    "normal_form_jacobian",
    "crossing",
    "exact_return",
    "ORDERS",
]

#: Truncations accepted by :func:`zdm` and :func:`normal_form_map`.
ORDERS = (1, 2, "exact")


def _design():
    """The model file's flow, rows and smooth map (dynamics/design/family.py), imported
    when a model file is first asked: that module's scipy imports (1.4 s) are nothing the
    nodes need, which import this one through plant.settings -> simulation.fidelity
    (tests/test_node_common.py)."""
    from grazing_control.dynamics.design import family

    return family


def _flow(model: NdofModel):
    return _design()._flow(model)


def _transition(model: NdofModel, t: float) -> np.ndarray:
    return _design()._transition(model, t)


# -- the local data at grazing ----------------------------------------------------------

class LocalGrazing(NamedTuple):
    """Coefficients of the 1-DOF local gap at (x = d, v = 0, tau = tau*) (theory_zdm.md, 1).

    alpha = d - cos tau* (> 0 for regular grazing, Eq. 3); beta = -omega sin tau*
    + 2 zeta alpha, the third time derivative of the gap there; c3 = beta / (6 alpha^3)
    - zeta / alpha^2, the cubic coefficient of H_max; k = 2 zeta - beta / alpha, the
    linear coefficient of the curvature at the maximum.
    """

    alpha: float
    beta: float
    c3: float
    k: float


class ModalGrazing(NamedTuple):
    """A model file's local data at grazing (docs/theory_ndof.md §10): alpha* = omega^2 d*,
    the acceleration row kappa = A^T e_v, c = w - A e_v (the damping jump), w, e_v, d*."""

    alpha: float
    kappa: np.ndarray
    c: np.ndarray
    w: np.ndarray
    ev: np.ndarray
    d_star: float


def local_grazing(model):
    """The model's local data at grazing: :class:`LocalGrazing` (alpha, beta, c3, k of the
    wall d = d* + Delta d at tau*) for the 1-DOF oscillator, :class:`ModalGrazing`
    (alpha*, kappa, c, w, e_v, d*) for a model file."""
    if is_model_file(model):
        return _modal_grazing(model)
    p = model
    alpha = -p.a_star + p.delta_d
    if not alpha > 0.0:
        raise ValueError(f"alpha = d - cos(tau*) = {alpha!r} <= 0: grazing at tau* is not "
                         "regular (Eq. 3), the ZDM does not apply")
    beta = -p.omega * math.sin(p.tau_star) + 2.0 * p.zeta * alpha
    c3 = beta / (6.0 * alpha ** 3) - p.zeta / alpha ** 2
    k = 2.0 * p.zeta - beta / alpha
    return LocalGrazing(alpha, beta, c3, k)


def _modal_grazing(model: NdofModel) -> ModalGrazing:
    flow = _flow(model)
    a = flow.A
    w, ev, _b = _design()._vectors(model)
    dstar = flow.d_star
    return ModalGrazing(model.omega ** 2 * dstar, a[model.n + model.i_w].copy(), w - a @ ev,
                        w, ev, dstar)


def _modal_state(model: NdofModel, z) -> np.ndarray:
    z = np.asarray(z, dtype=float).reshape(-1)
    if z.shape != (2 * model.n,) or not np.all(np.isfinite(z)):
        raise ValueError(f"z={z!r} is invalid: expected {2 * model.n} finite values")
    return z


def gap_on_pi1(model, z):
    """(e1, e2) = (gap, gap rate) of the virtual deviation z on Pi1: (z_x - Delta d, z_v)
    for the 1-DOF oscillator, (w^T z - Delta d, e_v^T z) for a model file (§10)."""
    if is_model_file(model):
        z = _modal_state(model, z)
        return float(z[model.i_w]) - model.delta_d, float(z[model.n + model.i_w])
    return z[0] - model.delta_d, z[1]


def h_max(model, z, order: int = 2) -> float:
    """Maximum of the gap along the local smooth flow through (tau*, z), truncated.

    1-DOF: order 1 H0 = e1 + e2^2 / (2 alpha) (error O(delta^3)); order 2 H0 + c3 e2^3
    (error O(delta^4)); theory_zdm.md, Eq. (Z4). A model file (§10): order 1
    e1 + e2^2 / (2 alpha*), order 2 e1 + e2^2 / (2 alpha(z)), with the same errors.
    """
    g = local_grazing(model)
    e1, e2 = gap_on_pi1(model, z)
    if is_model_file(model):
        if order == 1:
            alpha = g.alpha
        elif order == 2:
            alpha = g.alpha - float(g.kappa @ _modal_state(model, z))
        else:
            raise ValueError(f"order={order!r} is invalid: valid values are 1, 2")
        return e1 + e2 * e2 / (2.0 * alpha)
    h = e1 + e2 * e2 / (2.0 * g.alpha)
    if order == 2:
        h += g.c3 * e2 ** 3
    elif order != 1:
        raise ValueError(f"order={order!r} is invalid: valid values are 1, 2")
    return h


# -- the 1-DOF closed forms (the certified fast path) -------------------------------------

def zdm_event(p: OscillatorParams, z, order: int = 2):
    """Truncated 1-DOF ZDM at Pi1 with the grazing impact it implies: (dx', dv', t1, v-).

    t1 is the local time of the crossing (0 = Pi1) and v- the impact velocity, both to
    the map's order; (z_x, z_v, None, None) when the smooth flow does not reach the wall.

    order 1 (theory_zdm.md, Eq. (Z7)): with H0 = e1 + e2^2 / (2 alpha),
        v- = sqrt(2 alpha H0),  z -> (z_x, z_v - (1 + r) v-);  error O(delta^2).
    order 2 (Eq. (Z8)): with H = H0 + c3 e2^3, V = sqrt(2 (alpha + k e2) H),
        v- = V + beta V^2 / (3 alpha^2),
        z_x -> z_x + (1 + r) V t1,  z_v -> z_v - (1 + r)(v- + 2 zeta V t1);  error O(delta^3).
    In both, t1 = (e2 - V)/alpha (V = v- at order 1); delta = sqrt(H_max).
    """
    if order not in (1, 2):
        raise ValueError(f"order={order!r} is invalid: valid values are 1, 2")
    dx, dv = z
    g = local_grazing(p)
    e1, e2 = gap_on_pi1(p, z)
    h = e1 + e2 * e2 / (2.0 * g.alpha)
    if order == 2:
        h += g.c3 * e2 ** 3
    if not h > 0.0:
        return dx, dv, None, None
    rr = 1.0 + p.r
    if order == 1:
        v_minus = math.sqrt(2.0 * g.alpha * h)
        return dx, dv - rr * v_minus, (e2 - v_minus) / g.alpha, v_minus
    big_v = math.sqrt(2.0 * (g.alpha + g.k * e2) * h)
    v_minus = big_v + g.beta * big_v * big_v / (3.0 * g.alpha ** 2)
    t1 = (e2 - big_v) / g.alpha
    return (dx + rr * big_v * t1, dv - rr * (v_minus + 2.0 * p.zeta * big_v * t1), t1, v_minus)


def zdm_leading(p: OscillatorParams, z):
    """Leading-order 1-DOF ZDM at Pi1 (theory_zdm.md, Eq. (Z7)): a sqrt(H0) velocity jump.

    z -> z if H0 <= 0, else (z_x, z_v - (1 + r) sqrt(2 alpha H0)); see :func:`zdm_event`.
    Error O(delta^2) against the exact ZDM, delta = sqrt(H_max).
    """
    return zdm_event(p, z, 1)[:2]


def zdm_second(p: OscillatorParams, z):
    """Second-order 1-DOF ZDM at Pi1 (theory_zdm.md, Eq. (Z8)); see :func:`zdm_event`.

    Error O(delta^3) against the exact ZDM.
    """
    return zdm_event(p, z, 2)[:2]


def zdm_exact(p: OscillatorParams, z):
    """Exact 1-DOF ZDM: z - (1 + r) v- Phi(-t1) (0, 1)^T with (t1, v-) from :func:`crossing`.

    Local: it accounts for the one grazing event near tau* (theory_zdm.md, Eq. (Z2)).
    """
    dx, dv = z
    _tm, _hm, t1, v = crossing(p, z)
    if t1 is None:
        return dx, dv
    f11, f12, f21, f22 = transition_matrix(p.zeta, -t1)
    rr = (1.0 + p.r) * v
    return dx - rr * f12, dv - rr * f22


def _closed_form_jacobian(p: OscillatorParams, z, order):
    """(D11, D12, D21, D22) of the 1-DOF ZDM (:func:`zdm_jacobian`)."""
    if order == "exact":
        _tm, _hm, t1, v = crossing(p, z)
        if t1 is None:
            return 1.0, 0.0, 0.0, 1.0
        r = p.r
        k = (1.0 + r) * (math.cos(p.tau_star + p.omega * t1) - p.d) / v
        sal = (-r, 0.0, k, -r)
        return matmul2(transition_matrix(p.zeta, -t1),
                       matmul2(sal, transition_matrix(p.zeta, t1)))
    g = local_grazing(p)
    e1, e2 = gap_on_pi1(p, z)
    rr = 1.0 + p.r
    if order == 1:
        h0 = e1 + e2 * e2 / (2.0 * g.alpha)
        if not h0 > 0.0:
            return 1.0, 0.0, 0.0, 1.0
        big_v = math.sqrt(2.0 * g.alpha * h0)
        return 1.0, 0.0, -rr * g.alpha / big_v, 1.0 - rr * e2 / big_v
    if order != 2:
        raise ValueError(f"order={order!r} is invalid: valid values are {ORDERS}")
    h = e1 + e2 * e2 / (2.0 * g.alpha) + g.c3 * e2 ** 3
    if not h > 0.0:
        return 1.0, 0.0, 0.0, 1.0
    am = g.alpha + g.k * e2
    big_v = math.sqrt(2.0 * am * h)
    dv_de = (am / big_v, (g.k * h + am * (e2 / g.alpha + 3.0 * g.c3 * e2 * e2)) / big_v)
    t1 = (e2 - big_v) / g.alpha
    dt_de = (-dv_de[0] / g.alpha, (1.0 - dv_de[1]) / g.alpha)
    fac = 1.0 + 2.0 * g.beta * big_v / (3.0 * g.alpha ** 2)
    out = []
    for i in (0, 1):
        prod = dv_de[i] * t1 + big_v * dt_de[i]          # d(V t1)/de_i
        out.append((rr * prod, -rr * (fac * dv_de[i] + 2.0 * p.zeta * prod)))
    return 1.0 + out[0][0], out[1][0], out[0][1], 1.0 + out[1][1]


# -- the exact local crossing, for any model ------------------------------------------------

class _LocalGap:
    """1-DOF: gap, rate and acceleration of the smooth flow through (tau*, z) at local time t."""

    __slots__ = ("p", "z", "a", "w", "dd")

    def __init__(self, p, z):
        self.p, self.z = p, (z[0], z[1])
        self.a, self.w, self.dd = p.amplitude, p.omega, p.delta_d

    def __call__(self, t):
        zx, zv = propagate(self.p.zeta, self.z[0], self.z[1], t)
        s = math.sin(0.5 * self.w * t)
        g = zx - self.dd - 2.0 * self.a * s * s
        gd = zv - self.a * self.w * math.sin(self.w * t)
        gdd = -zx - 2.0 * self.p.zeta * zv - self.a * self.w ** 2 * math.cos(self.w * t)
        return g, gd, gdd


class _ModalGap:
    """A model file: g, g', g'' of (Z0) at local time t (§10)."""

    def __init__(self, model, z):
        self.model, self.z = model, z
        self.loc = _modal_grazing(model)

    def __call__(self, t):
        zt = _transition(self.model, t) @ self.z
        om, ds = self.model.omega, self.loc.d_star
        sh = math.sin(0.5 * om * t)            # cos - 1 = -2 sin^2: no cancellation
        return (float(self.loc.w @ zt) - 2.0 * ds * sh * sh - self.model.delta_d,
                float(self.loc.ev @ zt) - ds * om * math.sin(om * t),
                float(self.loc.kappa @ zt) - ds * om * om * math.cos(om * t))


def crossing(model, z):
    """The local grazing event of the smooth flow through (tau*, z), exactly.

    Returns (t_max, H_max, t1, v-): the local time of the maximum of the gap near
    tau*, its value, and, when H_max > 0, the time and velocity of the crossing
    before it (t1 = v- = None otherwise). Local time 0 is Pi1; t1 < 0 means the
    real trajectory has already hit the wall when it reaches Pi1. The gap is the
    closed form's (1-DOF) or (Z0) over the model's flow (a model file, §10); the
    search is :func:`local_crossing` for both.

    Raises
    ------
    ValueError
        If Newton's method finds no maximum of the gap within a quarter period of Pi1.
    """
    if is_model_file(model):
        z = _modal_state(model, z)
        f = _ModalGap(model, z)
        return local_crossing(f, f.loc.ev @ z / f.loc.alpha, f.loc.alpha, model.period,
                              f"z={z.tolist()}")
    dx, dv = z
    alpha = local_grazing(model).alpha
    return local_crossing(_LocalGap(model, z), dv / alpha, alpha, model.period,
                          f"z=({dx!r}, {dv!r})")


def local_crossing(gap, t: float, alpha: float, period: float, state: str):
    """(t_max, H_max, t1, v-) of a smooth gap near Pi1, for any model (:func:`crossing`;
    a model file's gap is docs/theory_ndof.md section 10).

    ``gap(t)`` returns (g, g', g'') at local time t; ``t`` starts Newton on g' (e2 / alpha);
    ``alpha`` (minus the grazing acceleration) sets the first bracket's width
    sqrt(2 H_max / alpha); ``state`` names the state in the error message. Newton finds the
    maximum (within a quarter ``period`` of Pi1, else ValueError), Brent the crossing
    before it to a few ulps.
    """
    f = gap
    for _ in range(60):  # Newton on the rate (concave gap near grazing)
        _g, gd, gdd = f(t)
        step = -gd / gdd
        t += step
        if abs(step) <= 4.0 * math.ulp(max(abs(t), 1e-300)):
            break
    else:
        t = math.nan
    if not (abs(t) < 0.25 * period and f(t)[2] < 0.0):
        raise ValueError(f"no local maximum of the gap near Pi1 for {state}: "
                         "not a near-grazing state")
    t_max = t
    hm = f(t_max)[0]
    if not hm > 0.0:
        return t_max, hm, None, None
    width = math.sqrt(2.0 * hm / alpha)
    lo = t_max - 2.0 * width
    while f(lo)[0] >= 0.0:
        lo = t_max - 2.0 * (t_max - lo)
    from scipy.optimize import brentq   # lazily: 0.25 s of import that a node never needs

    t1 = brentq(lambda s: f(s)[0], lo, t_max, xtol=1e-300, rtol=4.0 * 2.0 ** -52, maxiter=400)
    return t_max, hm, t1, f(t1)[1]


# -- the ZDM and the normal-form map, for any model ---------------------------------------

def _modal_event(model, z, order):
    """A model file's (D(z), t1, v-) of the truncation ``order`` (1 or 2), or (z, None,
    None) if H <= 0 (module docstring)."""
    g = _modal_grazing(model)
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


def zdm(model, z, order=2):
    """The ZDM D(z) at Pi1 of the given truncation: 1 (leading), 2 (second) or 'exact'
    ((Z2) with (t1, v-) from :func:`crossing`). The identity where the smooth flow does
    not reach the wall. 1-DOF: the closed forms (:func:`zdm_leading`, :func:`zdm_second`,
    :func:`zdm_exact`), a pair; a model file: the module docstring's, an array."""
    if not is_model_file(model):
        if order == 1:
            return zdm_leading(model, z)
        if order == 2:
            return zdm_second(model, z)
        if order == "exact":
            return zdm_exact(model, z)
        raise ValueError(f"order={order!r} is invalid: valid values are {ORDERS}")
    z = _modal_state(model, z)
    if order in (1, 2):
        return _modal_event(model, z, order)[0]
    if order != "exact":
        raise ValueError(f"order={order!r} is invalid: valid values are {ORDERS}")
    _tm, _hm, t1, v = crossing(model, z)
    if t1 is None:
        return z.copy()
    return z - (1.0 + model.r) * v * (_transition(model, -t1) @ _modal_grazing(model).ev)


def zdm_jacobian(model, z, order=2):
    """Jacobian dD/dz of the ZDM of the given truncation (1-DOF: as (D11, D12, D21, D22);
    a model file: a matrix).

    * 'exact': Phi(-t1) S Phi(t1), S the saltation matrix at the crossing (the ZDM is
      the impact law conjugated by the smooth flow; det = r^2), theory_zdm.md (Z3);
    * 1 and 2: the derivatives of the truncations: (Z7), (Z8) for the 1-DOF closed
      forms; for a model file grad v = (alpha w + e2 e_v - e1 kappa) / v (order 2; order 1
      without the kappa term and alpha = alpha*), docs/theory_ndof.md §10.

    The identity where H <= 0 (no impact).
    """
    if not is_model_file(model):
        return _closed_form_jacobian(model, z, order)
    z = _modal_state(model, z)
    d = 2 * model.n
    g = _modal_grazing(model)
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
    _out, t1, v = _modal_event(model, z, order)
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


def smooth_map(model, gains=None):
    """The smooth map through grazing on Pi1: N_g = Phi(T - s) G Phi(s) (Eqs. 29-32).

    1-DOF: a 4-tuple (N11, N12, N21, N22),
    :func:`grazing_control.dynamics.maps.maps.period_matrix` (Phi(T) evaluated directly
    uncontrolled); a model file: N(k) = Phi(T - s)(I + b k^T) Phi(s), a matrix
    (docs/theory_ndof.md §2; ``gains`` the vector k).
    """
    if is_model_file(model):
        return _design().smooth_map(model, gains)
    return period_matrix(model, gains)


def normal_form_map(model, z, gains=None, order=2):
    """Normal-form Poincare map on Pi1: P(z) = N_g D(z) (theory_zdm.md, section 4;
    docs/theory_ndof.md §10).

    Parameters
    ----------
    model : OscillatorParams or NdofModel
    z : (float, float) or array
        Virtual deviation on Pi1 (smooth flow, the wall ignored).
    gains : Gains or the vector k, optional
        Controller at Pi2, inside N_g.
    order : 1, 2 or 'exact'
        Truncation of the ZDM.

    Returns
    -------
    (float, float) or array
        The virtual deviation on Pi1 one period later. Equal to the exact Pi1 map
        (up to the truncation of D) while the near-grazing impact is the only one in
        the period.

    Examples
    --------
    >>> from grazing_control.oscillator.params import OscillatorParams
    >>> p = OscillatorParams(delta_d=1e-3)
    >>> normal_form_map(p, (1e-3, 0.0), order=1) == normal_form_map(p, (1e-3, 0.0), order=2)
    True
    """
    if is_model_file(model):
        return smooth_map(model, gains) @ zdm(model, z, order)
    n11, n12, n21, n22 = smooth_map(model, gains)
    wx, wv = zdm(model, z, order)
    return n11 * wx + n12 * wv, n21 * wx + n22 * wv


def normal_form_jacobian(model, z, gains=None, order=2):
    """Jacobian of :func:`normal_form_map`: N_g dD/dz (1-DOF as (J11, J12, J21, J22))."""
    if is_model_file(model):
        return smooth_map(model, gains) @ zdm_jacobian(model, z, order)
    return matmul2(smooth_map(model, gains), zdm_jacobian(model, z, order))


def exact_return(p: OscillatorParams, z, gains: Gains | None = None, *,
                 monodromy: bool = False) -> Segment:
    """Exact 1-DOF Pi1 map of a virtual state: the reference for the normal-form maps.

    If the smooth trajectory through (tau*, z) crosses the wall before tau* (t1 < 0),
    the real trajectory is followed from local time 2 t1 (before the crossing, where
    real and smooth flows agree) with the exact flow and impacts
    (:func:`grazing_control.oscillator.impact.advance`) to Pi2, the controller acts, and the
    flow continues to tau* + T; otherwise this is :func:`grazing_control.dynamics.maps.maps.pi1_map`.
    (A model file's reference is the certified core's local map, tests/test_zdm.py.)
    """
    dx, dv = z
    _tm, _hm, t1, _v = crossing(p, z)
    if t1 is None or t1 >= 0.0:
        return pi1_map(p, dx, dv, gains, monodromy=monodromy)
    ts = 2.0 * t1
    zs = propagate(p.zeta, dx, dv, ts)
    seg = flow_through_pi2(p, (p.tau_star + p.omega * ts) % (2.0 * math.pi), zs[0], zs[1],
                           p.pi2_offset / p.omega - ts, gains, monodromy=monodromy)
    mono = matmul2(seg.monodromy, transition_matrix(p.zeta, ts)) if monodromy else None
    impacts = [i._replace(dt=i.dt + ts) for i in seg.impacts]
    return Segment(seg.dx, seg.dv, impacts, mono)

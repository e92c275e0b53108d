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
"""

from __future__ import annotations

import math
from typing import NamedTuple

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.flow import matmul2, propagate, transition_matrix
from grazing_control.oscillator.impact import Segment
from grazing_control.dynamics.maps.maps import flow_through_pi2, period_matrix, pi1_map
from grazing_control.oscillator.params import OscillatorParams

__all__ = [
    "LocalGrazing",
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


class LocalGrazing(NamedTuple):
    """Coefficients of the local gap at (x = d, v = 0, tau = tau*) (theory_zdm.md, 1).

    alpha = d - cos tau* (> 0 for regular grazing, Eq. 3); beta = -omega sin tau*
    + 2 zeta alpha, the third time derivative of the gap there; c3 = beta / (6 alpha^3)
    - zeta / alpha^2, the cubic coefficient of H_max; k = 2 zeta - beta / alpha, the
    linear coefficient of the curvature at the maximum.
    """

    alpha: float
    beta: float
    c3: float
    k: float


def local_grazing(p: OscillatorParams) -> LocalGrazing:
    """alpha, beta, c3, k of the wall d = d* + Delta d at the grazing phase tau*."""
    alpha = -p.a_star + p.delta_d
    if not alpha > 0.0:
        raise ValueError(f"alpha = d - cos(tau*) = {alpha!r} <= 0: grazing at tau* is not "
                         "regular (Eq. 3), the ZDM does not apply")
    beta = -p.omega * math.sin(p.tau_star) + 2.0 * p.zeta * alpha
    c3 = beta / (6.0 * alpha ** 3) - p.zeta / alpha ** 2
    k = 2.0 * p.zeta - beta / alpha
    return LocalGrazing(alpha, beta, c3, k)


def gap_on_pi1(p: OscillatorParams, dx: float, dv: float):
    """(e1, e2) = (gap, gap rate) of the deviation (dx, dv) on Pi1: (dx - Delta d, dv)."""
    return dx - p.delta_d, dv


def h_max(p: OscillatorParams, dx: float, dv: float, order: int = 2) -> float:
    """Maximum of the gap x - d along the local smooth flow through (tau*, z).

    order 1: H0 = e1 + e2^2 / (2 alpha) (error O(delta^3));
    order 2: H0 + c3 e2^3 (error O(delta^4)); theory_zdm.md, Eq. (Z4).
    """
    g = local_grazing(p)
    e1, e2 = gap_on_pi1(p, dx, dv)
    h = e1 + e2 * e2 / (2.0 * g.alpha)
    if order == 2:
        h += g.c3 * e2 ** 3
    elif order != 1:
        raise ValueError(f"order={order!r} is invalid: valid values are 1, 2")
    return h


def zdm_event(p: OscillatorParams, dx: float, dv: float, order: int = 2):
    """Truncated ZDM at Pi1 with the grazing impact it implies: (dx', dv', t1, v-).

    t1 is the local time of the crossing (0 = Pi1) and v- the impact velocity, both to
    the map's order; (dx, dv, None, None) when the smooth flow does not reach the wall.

    order 1 (theory_zdm.md, Eq. (Z7)): with H0 = e1 + e2^2 / (2 alpha),
        v- = sqrt(2 alpha H0),  z -> (z_x, z_v - (1 + r) v-);  error O(delta^2).
    order 2 (Eq. (Z8)): with H = H0 + c3 e2^3, V = sqrt(2 (alpha + k e2) H),
        v- = V + beta V^2 / (3 alpha^2),
        z_x -> z_x + (1 + r) V t1,  z_v -> z_v - (1 + r)(v- + 2 zeta V t1);  error O(delta^3).
    In both, t1 = (e2 - V)/alpha (V = v- at order 1); delta = sqrt(H_max).
    """
    if order not in (1, 2):
        raise ValueError(f"order={order!r} is invalid: valid values are 1, 2")
    g = local_grazing(p)
    e1, e2 = gap_on_pi1(p, dx, dv)
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


def zdm_leading(p: OscillatorParams, dx: float, dv: float):
    """Leading-order ZDM at Pi1 (theory_zdm.md, Eq. (Z7)): a sqrt(H0) velocity jump.

    z -> z if H0 <= 0, else (z_x, z_v - (1 + r) sqrt(2 alpha H0)); see :func:`zdm_event`.
    Error O(delta^2) against the exact ZDM, delta = sqrt(H_max).
    """
    return zdm_event(p, dx, dv, 1)[:2]


def zdm_second(p: OscillatorParams, dx: float, dv: float):
    """Second-order ZDM at Pi1 (theory_zdm.md, Eq. (Z8)); see :func:`zdm_event`.

    Error O(delta^3) against the exact ZDM.
    """
    return zdm_event(p, dx, dv, 2)[:2]


class _LocalGap:
    """Gap, rate and acceleration of the smooth flow through (tau*, z) at local time t."""

    __slots__ = ("p", "z", "a", "w", "dd")

    def __init__(self, p, dx, dv):
        self.p, self.z = p, (dx, dv)
        self.a, self.w, self.dd = p.amplitude, p.omega, p.delta_d

    def __call__(self, t):
        zx, zv = propagate(self.p.zeta, self.z[0], self.z[1], t)
        s = math.sin(0.5 * self.w * t)
        g = zx - self.dd - 2.0 * self.a * s * s
        gd = zv - self.a * self.w * math.sin(self.w * t)
        gdd = -zx - 2.0 * self.p.zeta * zv - self.a * self.w ** 2 * math.cos(self.w * t)
        return g, gd, gdd


def crossing(p: OscillatorParams, dx: float, dv: float):
    """The local grazing event of the smooth flow through (tau*, z), exactly.

    Returns (t_max, H_max, t1, v-): the local time of the maximum of the gap near
    tau*, its value, and, when H_max > 0, the time and velocity of the crossing
    before it (t1 = v- = None otherwise). Local time 0 is Pi1; t1 < 0 means the
    real trajectory has already hit the wall when it reaches Pi1.

    Raises
    ------
    ValueError
        If Newton's method finds no maximum of the gap within a quarter period of Pi1.
    """
    alpha = local_grazing(p).alpha
    return local_crossing(_LocalGap(p, dx, dv), dv / alpha, alpha, p.period,
                          f"z=({dx!r}, {dv!r})")


def local_crossing(gap, t: float, alpha: float, period: float, state: str):
    """(t_max, H_max, t1, v-) of a smooth gap near Pi1, for any model (:func:`crossing`;
    the n-DOF model's is docs/theory_ndof.md section 10).

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


def zdm_exact(p: OscillatorParams, dx: float, dv: float):
    """Exact ZDM: z - (1 + r) v- Phi(-t1) (0, 1)^T with (t1, v-) from :func:`crossing`.

    Local: it accounts for the one grazing event near tau* (theory_zdm.md, Eq. (Z2)).
    """
    _tm, _hm, t1, v = crossing(p, dx, dv)
    if t1 is None:
        return dx, dv
    f11, f12, f21, f22 = transition_matrix(p.zeta, -t1)
    rr = (1.0 + p.r) * v
    return dx - rr * f12, dv - rr * f22


def zdm(p: OscillatorParams, dx: float, dv: float, order=2):
    """The ZDM of the given truncation: 1 (leading), 2 (second) or 'exact'."""
    if order == 1:
        return zdm_leading(p, dx, dv)
    if order == 2:
        return zdm_second(p, dx, dv)
    if order == "exact":
        return zdm_exact(p, dx, dv)
    raise ValueError(f"order={order!r} is invalid: valid values are {ORDERS}")


def zdm_jacobian(p: OscillatorParams, dx: float, dv: float, order=2):
    """Jacobian dD/dz of the ZDM of the given truncation, as (D11, D12, D21, D22).

    * 'exact': Phi(-t1) S Phi(t1), S the saltation matrix at the crossing (the ZDM is
      the impact law conjugated by the smooth flow; det = r^2), theory_zdm.md (Z3);
    * 1 and 2: the derivatives of the formulas (Z7), (Z8).

    The identity where H <= 0 (no impact).
    """
    if order == "exact":
        _tm, _hm, t1, v = crossing(p, dx, dv)
        if t1 is None:
            return 1.0, 0.0, 0.0, 1.0
        r = p.r
        k = (1.0 + r) * (math.cos(p.tau_star + p.omega * t1) - p.d) / v
        sal = (-r, 0.0, k, -r)
        return matmul2(transition_matrix(p.zeta, -t1),
                       matmul2(sal, transition_matrix(p.zeta, t1)))
    g = local_grazing(p)
    e1, e2 = gap_on_pi1(p, dx, dv)
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


def smooth_map(p: OscillatorParams, gains: Gains | None = None):
    """N_g = Phi(T - s) G Phi(s) as a 4-tuple (N11, N12, N21, N22) (Eqs. 29-32).

    :func:`grazing_control.dynamics.maps.maps.period_matrix` (Phi(T) evaluated directly uncontrolled).
    """
    return period_matrix(p, gains)


def normal_form_map(p: OscillatorParams, z, gains: Gains | None = None, order=2):
    """Normal-form Poincare map on Pi1: P(z) = N_g D(z) (theory_zdm.md, section 4).

    Parameters
    ----------
    p : OscillatorParams
    z : (float, float)
        Virtual deviation on Pi1 (smooth flow, the wall ignored).
    gains : Gains, optional
        Controller of Eq. 28 at Pi2, inside N_g.
    order : 1, 2 or 'exact'
        Truncation of the ZDM.

    Returns
    -------
    (float, float)
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
    n11, n12, n21, n22 = smooth_map(p, gains)
    wx, wv = zdm(p, z[0], z[1], order)
    return n11 * wx + n12 * wv, n21 * wx + n22 * wv


def normal_form_jacobian(p: OscillatorParams, z, gains: Gains | None = None, order=2):
    """Jacobian of :func:`normal_form_map`: N_g dD/dz, as (J11, J12, J21, J22)."""
    return matmul2(smooth_map(p, gains), zdm_jacobian(p, z[0], z[1], order))


def exact_return(p: OscillatorParams, dx: float, dv: float, gains: Gains | None = None,
                 *, monodromy: bool = False) -> Segment:
    """Exact Pi1 map of a virtual state: the reference for the normal-form maps.

    If the smooth trajectory through (tau*, z) crosses the wall before tau* (t1 < 0),
    the real trajectory is followed from local time 2 t1 (before the crossing, where
    real and smooth flows agree) with the exact flow and impacts
    (:func:`grazing_control.oscillator.impact.advance`) to Pi2, the controller acts, and the
    flow continues to tau* + T; otherwise this is :func:`grazing_control.dynamics.maps.maps.pi1_map`.
    """
    _tm, _hm, t1, _v = crossing(p, dx, dv)
    if t1 is None or t1 >= 0.0:
        return pi1_map(p, dx, dv, gains, monodromy=monodromy)
    ts = 2.0 * t1
    zs = propagate(p.zeta, dx, dv, ts)
    seg = flow_through_pi2(p, (p.tau_star + p.omega * ts) % (2.0 * math.pi), zs[0], zs[1],
                           p.pi2_offset / p.omega - ts, gains, monodromy=monodromy)
    mono = matmul2(seg.monodromy, transition_matrix(p.zeta, ts)) if monodromy else None
    impacts = [i._replace(dt=i.dt + ts) for i in seg.impacts]
    return Segment(seg.dx, seg.dv, impacts, mono)

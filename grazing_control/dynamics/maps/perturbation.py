"""Perturbation estimates of the near-grazing 1/1 motion and its eigenvalues.

Spec section 7 (study Eqs. 18, 22-26); derived for this model in docs/theory_zdm.md,
sections 5-8. The fast route: closed-form series in the impact velocity delta2 of the
fixed point of the normal-form map P = N_g o D (:mod:`grazing_control.dynamics.maps.zdm`), and of
the characteristic equation of its Jacobian,

    lambda^2 - (chi_m1 / delta2 + chi0 + chi1 delta2 + O(delta2^2)) lambda + psi0 = 0,

with psi0 = r^2 det N_g exact. The accurate route is the exact impact-phase
shooting of :mod:`grazing_control.dynamics.orbits.orbits`; this module is cross-checked against it.

* Fixed point (theory_zdm.md Eqs. (P1)-(P4)): Delta d = kappa1 delta2 + kappa2 delta2^2
  (the analogue of Eq. 18), the virtual gap rate on Pi1 e2 = p1 delta2 + p2 delta2^2,
  its gap e1 = eps2 delta2^2, the crossing time t1 = tau1 delta2 + tau2 delta2^2.
* Non-degenerate (N_g,12 != 0): chi_m1 = -(1 + r) alpha* N_g,12 != 0, one eigenvalue
  ~ chi_m1 / delta2 grows without bound; truncation (Eq. 26): keep chi_m1 and chi0.
* Degenerate (N_g,12 = 0, Eq. 33): chi_m1 = kappa1 = 0, Delta d = kappa2 delta2^2; the
  limit lambda0 solves lambda^2 - chi0 lambda + psi0 = 0 (Eq. 23); the practical
  truncation (Eq. 25) keeps chi1 delta2.
* ``zdm_order=1`` gives the coefficients of the *leading-order* map instead; its chi0,
  psi0 and kappa2 are wrong (theory_zdm.md section 9), which is the point of the
  second-order ZDM.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.orbits.orbits import multipliers
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.zdm import normal_form_jacobian, normal_form_map, smooth_map

__all__ = [
    "SeriesCoefficients",
    "series_coefficients",
    "delta2_from_delta_d",
    "fixed_point_series",
    "trace_series",
    "characteristic_roots",
    "perturbation_multipliers",
    "period_doubling_perturbation",
    "limit_multipliers_perturbation",
    "existence_coefficient_perturbation",
    "admissible_c2_perturbation",
    "normal_form_fixed_point",
    "TRUNCATIONS",
]

#: Truncations of the characteristic equation: 'limit' keeps chi_m1 / delta2 + chi0
#: (Eq. 26; in the degenerate case this is lambda0 of Eq. 23), 'practical' adds
#: chi1 delta2 (Eq. 25).
TRUNCATIONS = ("limit", "practical")


@dataclass(frozen=True)
class SeriesCoefficients:
    """Coefficients of the perturbation series of the 1/1 motion born at grazing.

    delta2 is the impact velocity v- of the 1/1 motion. Attributes (theory_zdm.md):

    n : (N11, N12, N21, N22), the smooth map N_g = Phi(T - s) G Phi(s).
    zdm_order : 1 (leading-order map) or 2 (second-order map).
    alpha : alpha* = d* - cos tau* = -a* (Eq. 3).
    kappa1, kappa2 : Delta d = kappa1 delta2 + kappa2 delta2^2 (P3, analogue of Eq. 18).
    p1, p2, eps2 : virtual state on Pi1, z = (Delta d + eps2 delta2^2, p1 delta2 + p2 delta2^2).
    tau1, tau2 : crossing time t1 = tau1 delta2 + tau2 delta2^2 (P4).
    chi_m1, chi0, chi1 : trace of the Jacobian, chi_m1/delta2 + chi0 + chi1 delta2 (P6).
    psi0 : its determinant (r^2 det N_g for the second-order map, exact).
    """

    n: tuple
    zdm_order: int
    alpha: float
    kappa1: float
    kappa2: float
    p1: float
    p2: float
    eps2: float
    tau1: float
    tau2: float
    chi_m1: float
    chi0: float
    chi1: float
    psi0: float

    @property
    def degenerate(self) -> bool:
        """N_g,12 = 0 up to rounding (Eq. 33): no unbounded eigenvalue."""
        return abs(self.n[1]) <= 1e-12 * max(abs(x) for x in self.n)


def series_coefficients(p: OscillatorParams, gains: Gains | None = None,
                        zdm_order: int = 2) -> SeriesCoefficients:
    """Perturbation coefficients of the 1/1 motion for the map N_g o D (D of zdm_order).

    The expansion is about grazing (Delta d = 0); ``p.delta_d`` is ignored.

    Parameters
    ----------
    p : OscillatorParams
    gains : Gains, optional
        Controller in the loop (inside N_g).
    zdm_order : 1 or 2
        Truncation of the ZDM whose normal-form map is analysed. Only 2 gives the
        correct O(1) coefficients (chi0, psi0) and kappa2.

    Returns
    -------
    SeriesCoefficients
    """
    if zdm_order not in (1, 2):
        raise ValueError(f"zdm_order={zdm_order!r} is invalid: valid values are 1, 2")
    at_grazing = p.delta_d == 0.0 and math.copysign(1.0, p.delta_d) > 0.0
    n = smooth_map(p if at_grazing else p.with_(delta_d=0.0), gains)
    nm = np.array(n).reshape(2, 2)
    r, zeta, w = p.r, p.zeta, p.omega
    rr = 1.0 + r
    al = -p.a_star
    be = -w * math.sin(p.tau_star) + 2.0 * zeta * al
    bmat = np.eye(2) - nm
    # order delta2 (P1): (kappa1, p1) = -(1 + r) (I - N)^{-1} N e2
    kappa1, p1 = -rr * np.linalg.solve(bmat, nm[:, 1])
    eps2 = (1.0 - p1 * p1) / (2.0 * al)
    u = p1 - 1.0
    if zdm_order == 2:
        # order delta2^2 (P2): (X2, p2) = (1 + r)(p1 - 1)/alpha (I - N)^{-1} N (1, -2 zeta)
        x2, p2 = rr * u / al * np.linalg.solve(bmat, nm @ np.array([1.0, -2.0 * zeta]))
    else:
        x2, p2 = 0.0, 0.0
    kappa2 = x2 - eps2
    tau1 = u / al
    tau2 = (p2 / al - u * kappa1 / al ** 2 - 2.0 * zeta / al ** 2 * p1 * u
            + be / (2.0 * al ** 3) * u * u)
    n11, n12, n21, n22 = n
    chi_m1 = -rr * al * n12
    if zdm_order == 2:
        a = np.array([[0.0, 1.0], [-1.0, -2.0 * zeta]])
        c1m = a @ nm - nm @ a
        m1 = c1m[0, 1]
        m2 = 0.5 * (a @ c1m - c1m @ a)[0, 1]
        ws, wc = w * math.sin(p.tau_star), w * w * math.cos(p.tau_star)
        chi0 = -r * (n11 + n22) + rr * (-al * m1 * tau1 - n12 * (kappa1 + ws * tau1))
        chi1 = rr * (-al * (m1 * tau2 + m2 * tau1 * tau1) - m1 * tau1 * (kappa1 + ws * tau1)
                     - n12 * (kappa2 + ws * tau2 + 0.5 * wc * tau1 * tau1))
        psi0 = r * r * (n11 * n22 - n12 * n21)
    else:
        # leading-order map: J = N [[1, 0], [-(1 + r) alpha / V, 1 - (1 + r) e2 / V]]
        chi0 = n11 + n22 * (1.0 - rr * p1) - rr * n12 * kappa1
        chi1 = -rr * (n22 * p2 + n12 * kappa2)
        psi0 = (n11 * n22 - n12 * n21) * (1.0 - rr * p1)
    f = float
    return SeriesCoefficients(tuple(f(x) for x in n), zdm_order, f(al), f(kappa1), f(kappa2),
                              f(p1), f(p2), f(eps2), f(tau1), f(tau2), f(chi_m1), f(chi0),
                              f(chi1), f(psi0))


def delta2_from_delta_d(c: SeriesCoefficients, delta_d: float) -> float:
    """Impact velocity delta2 for a wall offset Delta d: the smallest positive root of
    kappa1 delta2 + kappa2 delta2^2 = Delta d (theory_zdm.md (P3), Eq. 18 analogue).

    Degenerate case (kappa1 = 0): delta2 = sqrt(Delta d / kappa2). Returns nan when
    there is no positive root (no 1/1 motion born at grazing at this Delta d).
    """
    k1, k2 = c.kappa1, c.kappa2
    if delta_d == 0.0:
        return 0.0
    disc = k1 * k1 + 4.0 * k2 * delta_d
    if disc < 0.0:
        return math.nan
    sq = math.sqrt(disc)
    roots = [2.0 * delta_d / (k1 + s * sq) for s in (1.0, -1.0) if k1 + s * sq != 0.0]
    pos = [x for x in roots if x > 0.0]
    return min(pos) if pos else math.nan


def fixed_point_series(c: SeriesCoefficients, delta2: float):
    """(Delta d, z_x, z_v, t1) of the 1/1 fixed point at impact velocity delta2 (P1-P4).

    (z_x, z_v) is the virtual deviation on Pi1 (before the ZDM), t1 the crossing time
    relative to Pi1; all to O(delta2^2) with error O(delta2^3).
    """
    dd = c.kappa1 * delta2 + c.kappa2 * delta2 ** 2
    return (dd, dd + c.eps2 * delta2 ** 2, c.p1 * delta2 + c.p2 * delta2 ** 2,
            c.tau1 * delta2 + c.tau2 * delta2 ** 2)


def trace_series(c: SeriesCoefficients, delta2: float, truncation: str = "practical") -> float:
    """tr J = chi_m1 / delta2 + chi0 (+ chi1 delta2 for 'practical') (P6)."""
    tr = c.chi0 + (c.chi_m1 / delta2 if c.chi_m1 != 0.0 else 0.0)
    if truncation == "practical":
        tr += c.chi1 * delta2
    elif truncation != "limit":
        raise ValueError(f"truncation={truncation!r} is invalid: valid values are {TRUNCATIONS}")
    return tr


def characteristic_roots(c: SeriesCoefficients, delta2: float,
                         truncation: str = "practical") -> np.ndarray:
    """Roots of lambda^2 - tr lambda + psi0 = 0 (Eq. 22 analogue), largest modulus first.

    delta2 = 0 in the degenerate case gives lambda0 (Eq. 23).
    """
    if delta2 == 0.0:
        tr = c.chi0
    else:
        tr = trace_series(c, delta2, truncation)
    return multipliers(np.array([[tr, -c.psi0], [1.0, 0.0]]), c.psi0)


def perturbation_multipliers(p: OscillatorParams, gains: Gains | None = None,
                             truncation: str = "practical", zdm_order: int = 2) -> np.ndarray:
    """Fast estimate of the 1/1 multipliers at ``p.delta_d`` (the perturbation route).

    delta2 from Delta d by (P3), then the truncated characteristic equation. The
    counterpart of ``orbit_11(p, gains).multipliers``. nan if no 1/1 motion is
    predicted at this Delta d.

    Examples
    --------
    >>> from grazing_control.oscillator.params import OscillatorParams
    >>> lam = perturbation_multipliers(OscillatorParams(delta_d=-1e-6))
    >>> round(float(abs(lam[0])), 3)
    24.455
    """
    c = series_coefficients(p, gains, zdm_order)
    d2 = delta2_from_delta_d(c, p.delta_d)
    if not d2 > 0.0:
        return np.array([math.nan, math.nan], dtype=complex)
    return characteristic_roots(c, d2, truncation)


def period_doubling_perturbation(p: OscillatorParams, gains: Gains | None = None,
                                 truncation: str = "limit", zdm_order: int = 2):
    """Delta d and delta2 where a root crosses -1: 1 + tr + psi0 = 0 (theory_zdm.md, 7).

    'limit' (Eq. 26): delta2 = -chi_m1 / (1 + chi0 + psi0); 'practical' solves the
    quadratic with chi1. Returns (Delta d, delta2), nan if none with delta2 > 0.
    """
    c = series_coefficients(p, gains, zdm_order)
    a0 = 1.0 + c.chi0 + c.psi0
    if truncation == "limit":
        cands = [-c.chi_m1 / a0] if a0 != 0.0 else []
    elif truncation == "practical":
        cands = [x.real for x in np.roots([c.chi1, a0, c.chi_m1]) if abs(x.imag) == 0.0]
    else:
        raise ValueError(f"truncation={truncation!r} is invalid: valid values are {TRUNCATIONS}")
    cands = sorted(x for x in cands if x > 0.0)
    if not cands:
        return math.nan, math.nan
    d2 = cands[0]
    return c.kappa1 * d2 + c.kappa2 * d2 * d2, d2


def limit_multipliers_perturbation(p: OscillatorParams, gains: Gains,
                                   zdm_order: int = 2) -> np.ndarray:
    """lambda0 (Eq. 23): roots of lambda^2 - chi0 lambda + psi0 = 0 in the degenerate case.

    Compare :func:`grazing_control.dynamics.design.gains.limit_multipliers` (exact route).
    """
    return characteristic_roots(series_coefficients(p, gains, zdm_order), 0.0)


def existence_coefficient_perturbation(p: OscillatorParams, gains: Gains,
                                       zdm_order: int = 2) -> float:
    """gamma1 from the series, in the units of :func:`grazing_control.dynamics.design.gains.existence_coefficient`.

    Delta d = kappa2 delta2^2 and psi = omega t1 = omega tau1 delta2 give
    Delta d = kappa2 psi^2 / (omega tau1)^2, so gamma1 = -kappa2 / (omega tau1)^2 (Eq. 36).
    """
    c = series_coefficients(p, gains, zdm_order)
    return -c.kappa2 / (p.omega * c.tau1) ** 2


def admissible_c2_perturbation(p: OscillatorParams, lo: float = -4.0, hi: float = 2.0,
                               n: int = 601, zdm_order: int = 2, *, delay: float = 0.0,
                               conditions: str = "combined"):
    """Admissible c2 set from the perturbation formulas (spec section 6).

    For each c2, c1 from the degenerate condition (Eq. 38, for the actuation ``delay``);
    'impacting': max|lambda0| < 1 (lambda0 from chi0, psi0; Eq. 23) and kappa2 < 0 (the
    1/1 motion exists for d < d*, Eq. 36); 'non-impacting': the spectral radius of N_g
    below 1 (the 0/1 motion for d > d*); 'combined' (default): all three. Scan of
    [lo, hi] on n points and the exact route's breakpoints, each end bisected on the
    series' own conditions (:func:`grazing_control.dynamics.design.gains.admissible_intervals`).
    Compare :func:`grazing_control.dynamics.design.gains.admissible_c2`.

    Returns
    -------
    list of (float, float)
        An end at -inf or +inf: still open at |c2| = C2_LIMIT.
    """
    from grazing_control.dynamics.design.gains import CONDITIONS, admissible_intervals, breakpoints, degenerate_c1

    p0 = p.with_(delta_d=0.0)      # the expansion's model, formed once

    def stab(c):
        return float(np.max(np.abs(characteristic_roots(c, 0.0)))) - 1.0

    def exist(c):
        return c.kappa2

    def free(c):
        return float(np.max(np.abs(multipliers(np.array(c.n).reshape(2, 2))))) - 1.0

    funcs = {"impacting": (stab, exist), "non-impacting": (free,),
             "combined": (stab, exist, free)}.get(conditions)
    if funcs is None:
        raise ValueError(f"conditions={conditions!r} is invalid: valid values are {', '.join(CONDITIONS)}")

    def ok(c2):
        # at a pole of the series (I - N_g singular: N11 = 1) the conditions are undefined
        try:
            c = series_coefficients(p0, Gains(degenerate_c1(p, c2, delay), c2, delay),
                                    zdm_order)       # once for the conditions of this c2
            return all(f(c) < 0.0 for f in funcs)
        except (ArithmeticError, np.linalg.LinAlgError):
            return False

    # the series' conditions are the exact route's (theory_delay.md section 4), so they
    # switch at the same breakpoints; the scan of [lo, hi] adds candidates of its own
    cands = breakpoints(p, delay, conditions) + [float(x) for x in np.linspace(lo, hi, n)]
    return admissible_intervals(ok, cands)


def normal_form_fixed_point(p: OscillatorParams, gains: Gains | None = None, order=2,
                            guess=None, tol: float = 1e-14, max_iter: int = 50):
    """Fixed point of the normal-form map N_g o D at ``p.delta_d`` by Newton's method.

    The direct (non-series) route for a given truncation of D; starts from the series
    of the second-order map unless a guess is given. Returns (z, J): the virtual
    deviation on Pi1 and the Jacobian of the map there (2x2 array).
    """
    if guess is None:
        c = series_coefficients(p, gains, 2)
        d2 = delta2_from_delta_d(c, p.delta_d)
        if not d2 > 0.0:
            raise ValueError(f"no 1/1 motion near grazing predicted at delta_d={p.delta_d!r}")
        _dd, _zx, zv, _t1 = fixed_point_series(c, d2)
        guess = (p.delta_d + c.eps2 * d2 * d2, zv)
    z = np.array(guess, dtype=float)
    for _ in range(max_iter):
        pz = np.array(normal_form_map(p, tuple(z), gains, order))
        jac = np.array(normal_form_jacobian(p, tuple(z), gains, order)).reshape(2, 2)
        step = np.linalg.solve(jac - np.eye(2), -(pz - z))
        z = z + step
        if np.max(np.abs(step)) <= tol * np.max(np.abs(z)):
            break
    jac = np.array(normal_form_jacobian(p, tuple(z), gains, order)).reshape(2, 2)
    return (float(z[0]), float(z[1])), jac

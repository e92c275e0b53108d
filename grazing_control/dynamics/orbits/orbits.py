"""Periodic orbits and their Floquet multipliers.

Two routes, each exact (no truncation) and cross-checked against each other:

1. Impact-phase shooting for the 1/1 orbit (docs/theory.md, "The 1/1 branch").
   Take the impact surface x = d as the section. Just before an impact at phase
   theta = tau* + psi with velocity v, the deviation is z- = (q, v - v_p), just after
   it z+ = (q, -r v - v_p), with q = Delta d + 2 a sin^2(psi/2), -v_p = a omega sin psi.
   Over one period the deviation evolves linearly, z- = M(theta) z+, where
   M(theta) = Phi(T - s) G Phi(s) and s = (tau2 - theta mod 2 pi)/omega places the
   controller's action (M = Phi(T) uncontrolled). With B = M - I,
   w = (r M12, 1 + r M22) and u0 = (2 a sin^2(psi/2), a omega sin psi), periodicity
   is the *linear* system

       [B e1, -w] (Delta d, v)^T = -B u0,

   so the whole branch is explicit in the impact phase: psi -> (Delta d, v-).
   The monodromy over one period, from just before the impact, is J = M S with S the
   saltation matrix (spec section 5); its eigenvalues are the Floquet multipliers.

2. Newton shooting on the Pi2 map for any p/n orbit (1/1, 2/2, 1/2, ...): the
   residual is P^n(z) - z, the Jacobian the monodromy (Phi, S, G in time order)
   minus I. This is the generic algorithm of :mod:`.shooting` over the model protocol
   (:mod:`.model`), applied to the 1-DOF model.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.control import Gains, gain_determinant, gain_matrix
from grazing_control.oscillator.flow import matmul2, to_physical, transition_matrix
from grazing_control.oscillator.impact import (Impact, InitialStateError, NonFiniteStateError,
                                               saltation_matrix)
from grazing_control.dynamics.maps.maps import period_matrix, pi2_map
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.orbits.shooting import ShootingFailed, find_periodic, floquet_multipliers
from grazing_control.oscillator.params import OscillatorParams

__all__ = [
    "PeriodicOrbit",
    "OrbitNotFound",
    "impact_period_matrix",
    "wall_offset_at_phase",
    "orbit_11",
    "shoot",
    "multipliers",
    "monodromy_det",
    "find_branch_phase",
    "branch_brackets",
    "BRANCHES",
]

#: Labels of the part of the 1/1 solution curve psi -> (Delta d, v-) an orbit lies on:
#: the arc born at grazing (psi = 0) before its first fold, the same arc past a fold,
#: or an arc with v- > 0 separated from grazing by v- <= 0 (docs/theory.md, section 5).
BRANCHES = ("grazing", "grazing past a fold", "other")

TWO_PI = 2.0 * math.pi
#: Machine epsilon of float64 (the rounding bounds).
_EPS = float(np.finfo(float).eps)


class OrbitNotFound(RuntimeError):
    """No periodic orbit of the requested kind near the given data."""


@dataclass(frozen=True)
class PeriodicOrbit:
    """A periodic orbit with p impacts in n forcing periods.

    Attributes
    ----------
    params, gains : the system it belongs to.
    periods : n.
    pi2 : (x, v) sampled on Pi2 (before the controller acts).
    pi2_deviation : (x - x**, v - v**) at full relative precision.
    impacts : the impacts of one period of the orbit (time since the Pi2 sample).
    monodromy : 2x2 array, Jacobian of P^n at the orbit (Phi, S, G in time order).
    branch : for a 1/1 orbit from :func:`orbit_11`, which part of the 1/1 solution
        curve it lies on (one of :data:`BRANCHES`); '' when not classified (shoot).
    """

    params: OscillatorParams
    gains: Gains | None
    periods: int
    pi2: tuple
    pi2_deviation: tuple
    impacts: tuple
    monodromy: np.ndarray = field(repr=False)
    branch: str = ""

    @property
    def label(self) -> str:
        """Orbit notation p/n (spec section 1)."""
        return f"{len(self.impacts)}/{self.periods}"

    @property
    def multipliers(self) -> np.ndarray:
        """Floquet multipliers, eigenvalues of the monodromy, largest modulus first."""
        sticking = any(i.sticking for i in self.impacts)
        # an impact between a sample and its delayed kick: det is not the product formula
        # (docs/theory_delay.md, (D3))
        delay = 0.0 if self.gains is None else self.gains.delay
        sticking = sticking or any(i.dt % self.params.period < delay for i in self.impacts)
        det = None if sticking else monodromy_det(
            self.params, self.gains, self.periods, len(self.impacts))
        return multipliers(self.monodromy, det)

    @property
    def stable(self) -> bool:
        """All multipliers strictly inside the unit circle."""
        return bool(np.max(np.abs(self.multipliers)) < 1.0)

    @property
    def v_minus(self) -> float:
        """Impact velocity of the first impact (the only one of a 1/1 orbit)."""
        return self.impacts[0].v_minus

    @property
    def impact_phase(self) -> float:
        """Phase in [0, 2 pi) of the first impact."""
        return self.impacts[0].phase


def multipliers(monodromy, det: float | None = None) -> np.ndarray:
    """Eigenvalues of a 2x2 monodromy matrix, sorted by decreasing modulus
    (:func:`grazing_control.dynamics.orbits.shooting.floquet_multipliers`: the cancellation-free
    quadratic formula, ``det`` given exactly where known: det J = e^{-2 zeta n T}
    r^(2 impacts) (1 + c2)^n, products of det Phi, det S and det G)."""
    return floquet_multipliers(monodromy, det)


def monodromy_det(p: OscillatorParams, gains: Gains | None, periods: int, impacts: int) -> float:
    """Exact det of the monodromy: e^{-2 zeta n T} r^(2 m) (det G)^n (spec section 5).

    det G = 1 + c2, or 1 + k^T b_delta with an actuation delay (docs/theory_delay.md).
    """
    g = gain_determinant(gains, p.zeta)
    return math.exp(-2.0 * p.zeta * periods * p.period) * p.r ** (2 * impacts) * g ** periods


def impact_period_matrix(p: OscillatorParams, theta: float, gains: Gains | None = None):
    """M(theta): deviation map over one period from just after an impact at phase theta.

    M = Phi(T - s) G Phi(s), s = ((tau2 - theta) mod 2 pi) / omega (Eqs. 29-32 with the
    section moved to the impact phase); Phi(T) without control. Returns a 4-tuple.
    """
    return period_matrix(p, gains, ((p.tau2 - theta) % TWO_PI) / p.omega)


def wall_offset_at_phase(p: OscillatorParams, psi: float, gains: Gains | None = None):
    """The wall offset Delta d whose 1/1 orbit impacts at phase tau* + psi, with that
    impact's velocity v- and the period matrix M from it: (Delta d, v-, M), M a 4-tuple
    (the 1-DOF closed form; a model file's whole orbit at the phase is
    :func:`.modal_branch.orbit_at_phase`).

    Solves the linear periodicity system of the module docstring; ``p.delta_d`` is
    ignored (it is the unknown). v- <= 0 means the point is not a physical impact.
    With an actuation delay the kick must act before the next impact
    (delay < T - sigma, docs/theory_delay.md section 2); beyond, all values are nan.
    """
    theta = (p.tau_star + psi) % TWO_PI
    if gains is not None and gains.delay != 0.0 and \
            not gains.delay < p.period - ((p.tau2 - theta) % TWO_PI) / p.omega:
        return math.nan, math.nan, (math.nan,) * 4
    return _offset_of(p, psi, impact_period_matrix(p, theta, gains))


def _offset_of(p: OscillatorParams, psi: float, m):
    """:func:`wall_offset_at_phase`'s (Delta d, v-, M) from the period matrix M at the
    impact phase tau* + psi: the periodicity system solved."""
    m11, m12, m21, m22 = m
    a, w, r = p.amplitude, p.omega, p.r
    sh = math.sin(0.5 * psi)
    u1 = 2.0 * a * sh * sh
    u2 = a * w * math.sin(psi)
    b11, b12, b21, b22 = m11 - 1.0, m12, m21, m22 - 1.0
    w1, w2 = r * m12, 1.0 + r * m22
    rhs1 = -(b11 * u1 + b12 * u2)
    rhs2 = -(b21 * u1 + b22 * u2)
    # columns: (b11, b21) for Delta d, (-w1, -w2) for v
    det = -b11 * w2 + w1 * b21
    delta_d = (-rhs1 * w2 + w1 * rhs2) / det
    v = (b11 * rhs2 - b21 * rhs1) / det
    return delta_d, v, (m11, m12, m21, m22)


def _delta_d_rounding(p: OscillatorParams, psi: float, gains: Gains | None = None,
                      point=None, factors=None) -> float:
    """A bound on the rounding error of Delta d(psi) from :func:`wall_offset_at_phase`.

    Delta d = N / det with N = -rhs1 w2 + w1 rhs2, det = -b11 w2 + w1 b21 (the
    periodicity system of docs/theory.md section 5). Each entry of M = Q G P carries an
    absolute error e_M <= 8 eps max(|Q| |G| |P|) (products of O(1) entries summing to a
    possibly tiny M12); to first order Delta d moves by
    sum_ij |dN/dM_ij - Delta d d(det)/dM_ij| e_M / |det|, plus the rounding of the
    products themselves. Near grazing (|psi| ~ 1e-15) M12 is itself at the rounding
    level and Delta d(psi) ~ psi^2 wobbles by tens of percent: a change of direction
    smaller than this bound is not a fold (issue 20, item 4).

    ``point``: :func:`wall_offset_at_phase`'s result at psi when the caller has it (the scan of
    :func:`branch_brackets`), so that it is not solved twice; ``factors``: the point's
    (Phi(T - s), G, Phi(s)) when the caller has them (the scan: :func:`_scan_point`).
    The 2x2 products of absolute values are written out (a scan makes ~500 of these
    bounds per orbit).
    """
    dd, _v, (m11, m12, m21, m22) = wall_offset_at_phase(p, psi, gains) if point is None else point
    if not math.isfinite(dd):
        return math.inf
    if factors is None:
        factors = _scan_point(p, psi, gains)[1]
    (q11, q12, q21, q22), (g11, g12, g21, g22), (p11, p12, p21, p22) = factors
    q11, q12, q21, q22 = abs(q11), abs(q12), abs(q21), abs(q22)
    g11, g12, g21, g22 = abs(g11), abs(g12), abs(g21), abs(g22)
    p11, p12, p21, p22 = abs(p11), abs(p12), abs(p21), abs(p22)
    h11, h12 = q11 * g11 + q12 * g21, q11 * g12 + q12 * g22          # |Q| |G|
    h21, h22 = q21 * g11 + q22 * g21, q21 * g12 + q22 * g22
    eps = _EPS
    e_m = 8.0 * eps * max(h11 * p11 + h12 * p21, h11 * p12 + h12 * p22,
                          h21 * p11 + h22 * p21, h21 * p12 + h22 * p22)
    a, w, r = p.amplitude, p.omega, p.r
    sh = math.sin(0.5 * psi)
    u1, u2 = 2.0 * a * sh * sh, a * w * math.sin(psi)
    b11, b12, b21, b22 = m11 - 1.0, m12, m21, m22 - 1.0
    w1, w2 = r * m12, 1.0 + r * m22
    rhs1, rhs2 = -(b11 * u1 + b12 * u2), -(b21 * u1 + b22 * u2)
    det = -b11 * w2 + w1 * b21
    # (dN/dM_ij, d det/dM_ij) for ij = 11, 12, 21, 22
    partials = ((u1 * w2, -w2), (u2 * w2 + r * rhs2, r * b21), (-w1 * u1, w1),
                (-r * rhs1 - w1 * u2, -r * b11))
    first = e_m * sum(abs(dn - dd * ddet) for dn, ddet in partials)
    products = 4.0 * eps * ((abs(b11 * u1) + abs(b12 * u2)) * abs(w2)
                            + abs(w1) * (abs(b21 * u1) + abs(b22 * u2)))
    return (first + products) / abs(det) + 4.0 * eps * abs(dd)


def _psi_grid(lo_exp=-15.0, n=241):
    mags = np.logspace(lo_exp, math.log10(math.pi * 0.999), n)
    return mags


def _branch_values(p, gains, sign, rounding=False):
    """(psi, Delta d, v-) along the grid of :func:`_psi_grid` on the side ``sign``, with
    Delta d's rounding bound if ``rounding``. The same for every Delta d:
    :func:`wall_offset_at_phase` and :func:`_delta_d_rounding` do not read p.delta_d (it
    is the unknown), so the scan is made once per oscillator (p's other fields), gains and side
    (:func:`_branch_scan`); a sweep over Delta d (the noise covariance's, the mismatch
    bands') solved each orbit's scan anew, 1526 scans in five test modules (issue 30, the
    suite's CPU)."""
    return _branch_scan((p.zeta, p.r, p.omega, p.tau0, p.pi2_offset), gains, sign, rounding)


@functools.lru_cache(maxsize=256)
def _branch_scan(oscillator: tuple, gains, sign: float, rounding: bool) -> tuple:
    """:func:`_branch_values` of the oscillator (zeta, r, omega, tau0, pi2_offset) at
    Delta d = 0 (any other gives the same floats: tests/test_orbits.py)."""
    zeta, r, omega, tau0, pi2_offset = oscillator
    p = OscillatorParams(zeta=zeta, r=r, omega=omega, tau0=tau0, pi2_offset=pi2_offset)
    g = gain_matrix(gains, p.zeta)
    out = []
    for m in _psi_grid():
        psi = sign * m
        point, factors = _scan_point(p, psi, gains, g)
        dd, v, _ = point
        if rounding:
            out.append((psi, dd, v, _delta_d_rounding(p, psi, gains, point, factors)))
        else:
            out.append((psi, dd, v))
    return tuple(out)


def _scan_point(p: OscillatorParams, psi: float, gains, g=None):
    """(:func:`wall_offset_at_phase`, (Phi(T - s), G, Phi(s))) at psi, the same floats
    with each transition matrix formed once for both the point and its rounding bound
    (``g``: gain_matrix(gains, zeta), the same at every point of a scan; None: formed
    here, after the delay is checked)."""
    theta = (p.tau_star + psi) % TWO_PI
    s = ((p.tau2 - theta) % TWO_PI) / p.omega
    if gains is not None and gains.delay != 0.0 and not gains.delay < p.period - s:
        return (math.nan, math.nan, (math.nan,) * 4), None
    if g is None:
        g = gain_matrix(gains, p.zeta)
    q, ph = transition_matrix(p.zeta, p.period - s), transition_matrix(p.zeta, s)
    # period_matrix's product, or Phi(T) itself uncontrolled (impact_period_matrix)
    m = transition_matrix(p.zeta, p.period) if gains is None else matmul2(q, matmul2(g, ph))
    return _offset_of(p, psi, m), (q, g, ph)


def find_branch_phase(p: OscillatorParams, delta_d: float, gains: Gains | None = None) -> float:
    """Impact phase offset psi of the 1/1 orbit born at grazing, for a given Delta d.

    Scans |psi| on a logarithmic grid on both sides of tau*, keeps the brackets of
    Delta d(psi) = delta_d where v- > 0, takes the one nearest to grazing and
    refines it with Brent's method to a few ulps.

    Raises
    ------
    OrbitNotFound
        If no physical (v- > 0) 1/1 orbit on the branch has this Delta d.
    """
    best = None
    for sign in (-1.0, 1.0):
        prev = (0.0, 0.0, 0.0)
        for cur in _branch_values(p, gains, sign):
            f0, f1 = prev[1] - delta_d, cur[1] - delta_d
            if cur[2] > 0.0 and f0 * f1 <= 0.0 and f0 != f1:
                lo, hi = sorted((prev[0], cur[0]))
                if best is None or min(abs(lo), abs(hi)) < min(abs(best[0]), abs(best[1])):
                    best = (lo, hi)
                break
            if cur[2] <= 0.0 and abs(cur[0]) > 1e-3:
                break  # the physical side of the branch is the other one
            prev = cur
    if best is None:
        raise OrbitNotFound(f"no 1/1 orbit born at grazing with delta_d={delta_d!r}")
    g = lambda psi: wall_offset_at_phase(p, psi, gains)[0] - delta_d  # noqa: E731
    if g(best[0]) == 0.0:
        return best[0]
    if g(best[1]) == 0.0:
        return best[1]
    return brentq(g, best[0], best[1], xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)


def branch_brackets(p: OscillatorParams, delta_d: float, gains: Gains | None = None):
    """Every bracket (lo, hi, branch, fold) of Delta d(psi) = delta_d with v- > 0.

    Every 1/1 orbit has an impact phase tau* + psi, psi in (-pi, pi), and at each psi
    the periodicity system gives one (Delta d, v-): the curve psi -> (Delta d, v-) holds
    all 1/1 orbits. Walking |psi| outwards from grazing (psi = 0) on each side on a
    logarithmic grid, the arc with v- > 0 that starts at psi = 0 is the branch born at
    grazing; the brackets on it are labelled 'grazing' before the first fold (turn of
    Delta d(psi)) and 'grazing past a fold' after it (``fold``: the Delta d of the
    first turn, to the grid's resolution); brackets on arcs with v- > 0 reached after a
    stretch of v- <= 0 are 'other'. Sorted in that order, nearest to grazing first.
    A step of Delta d(psi) counts for a turn only where it exceeds the rounding bounds
    of its two ends (:func:`_delta_d_rounding`): near |psi| ~ 1e-15 the computed
    Delta d wobbles by tens of percent, which is no fold.
    """
    found = []
    for sign in (-1.0, 1.0):
        prev = (0.0, 0.0, 0.0, 0.0)
        on_grazing_arc, fold, direction, steps = True, None, 0.0, 0
        for cur in _branch_values(p, gains, sign, rounding=True):
            steps += 1
            if cur[2] <= 0.0:
                if abs(cur[0]) > 1e-3:  # rounding may flip tiny v- near psi = 0
                    on_grazing_arc = False
                prev = cur
                continue
            step = cur[1] - prev[1]
            if on_grazing_arc and fold is None and abs(step) > cur[3] + prev[3]:
                if direction != 0.0 and math.copysign(1.0, step) != direction:
                    fold = prev[1]
                direction = math.copysign(1.0, step)
            f0, f1 = prev[1] - delta_d, cur[1] - delta_d
            if prev[2] >= 0.0 and f0 * f1 <= 0.0 and f0 != f1:
                lo, hi = sorted((prev[0], cur[0]))
                kind = ("grazing" if fold is None else "grazing past a fold") \
                    if on_grazing_arc else "other"
                found.append((lo, hi, kind, fold, steps))
            prev = cur
    order = {k: i for i, k in enumerate(BRANCHES)}
    found.sort(key=lambda b: (order[b[2]], b[4] if b[2] != "grazing" else min(abs(b[0]), abs(b[1]))))
    return [b[:4] for b in found]


def _solve_bracket(p, delta_d, gains, lo, hi):
    g = lambda psi: wall_offset_at_phase(p, psi, gains)[0] - delta_d  # noqa: E731
    if g(lo) == 0.0:
        return lo
    if g(hi) == 0.0:
        return hi
    return brentq(g, lo, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)


def orbit_11(p: OscillatorParams, gains: Gains | None = None, *, check: bool = True,
             branch: str = "any") -> PeriodicOrbit:
    """The 1/1 orbit at ``p.delta_d`` by impact-phase shooting, labelled with its branch.

    The orbit on the branch born at grazing is preferred (before a fold, then past
    one); if there is none, or it fails the physical check, another 1/1 orbit at this
    Delta d is returned, labelled ``branch='other'`` (:func:`branch_brackets`).
    ``branch='grazing'`` accepts only the branch born at grazing (either label).

    Parameters
    ----------
    p : OscillatorParams
        Delta d < 0 for the branch born at grazing.
    gains : Gains, optional
        Controller in the loop (Eq. 28).
    check : bool
        Verify by the exact flow that one period from the Pi2 point has exactly one
        impact and returns to the same point (to 1e-9 relative); else OrbitNotFound.
    """
    if branch not in ("any", "grazing"):
        raise ValueError(f"branch={branch!r} is invalid: valid values are 'any', 'grazing'")
    candidates = [b for b in branch_brackets(p, p.delta_d, gains)
                  if branch == "any" or b[2] != "other"]
    failure = None
    for lo, hi, kind, _fold in candidates:
        psi = _solve_bracket(p, p.delta_d, gains, lo, hi)
        try:
            orbit = _orbit_from_phase(p, psi, gains, check=check, keep_delta_d=True)
        except OrbitNotFound as exc:
            failure = failure or exc
            continue
        return dataclasses.replace(orbit, branch=kind)
    if failure is not None:
        raise failure
    where = "born at grazing" if branch == "grazing" else "(on any branch)"
    raise OrbitNotFound(f"no 1/1 orbit {where} with delta_d={p.delta_d!r}")


def _orbit_from_phase(p, psi, gains, *, check=True, keep_delta_d=False):
    """The 1/1 orbit at impact phase offset psi; Delta d is the branch's unless kept
    (when psi was solved for p.delta_d, the two agree to a few ulps)."""
    dd, v, m = wall_offset_at_phase(p, psi, gains)
    if not v > 0.0 or not math.isfinite(dd):
        raise OrbitNotFound(
            f"the 1/1 solution at delta_d={dd!r} has v- = {v!r}: not an impacting orbit (at "
            "grazing, Delta d = 0, v- = 0 and the multipliers are not defined)")
    pp = p if keep_delta_d or dd == p.delta_d else p.with_(delta_d=dd)
    theta = (pp.tau_star + psi) % TWO_PI
    a, w = pp.amplitude, pp.omega
    q = dd + 2.0 * a * math.sin(0.5 * psi) ** 2
    vp = -a * w * math.sin(psi)
    zplus = (q, -pp.r * v - vp)
    s = ((pp.tau2 - theta) % TWO_PI) / w
    f = transition_matrix(pp.zeta, s)
    dx2 = f[0] * zplus[0] + f[1] * zplus[1]
    dv2 = f[2] * zplus[0] + f[3] * zplus[1]
    # J = M S from just before the impact: similar to the Pi2 map's monodromy, so it has
    # the same multipliers (spec section 5)
    jac = matmul2(m, saltation_matrix(pp, theta, v))
    impact = Impact(((theta - pp.tau2) % TWO_PI) / w, theta, v, -pp.r * v)
    orbit = PeriodicOrbit(pp, gains, 1, to_physical(pp, pp.tau2, dx2, dv2), (dx2, dv2),
                          (impact,), np.array(jac).reshape(2, 2))
    if check:
        try:
            seg = pi2_map(pp, dx2, dv2, gains)
        except (InitialStateError, NonFiniteStateError) as exc:  # beyond the wall, or absurd
            raise OrbitNotFound(f"the branch point at delta_d={dd!r} is not physical: {exc}") from None
        scale = max(abs(dx2), abs(dv2), 1e-300)
        err = max(abs(seg.dx - dx2), abs(seg.dv - dv2))
        gain = 1.0 + float(np.max(np.abs(orbit.multipliers)))  # rounding is amplified
        if len(seg.impacts) != 1 or err > 1e-8 * gain * (scale + 1e-300) + 1e-15 * gain:
            raise OrbitNotFound(
                f"the branch point at delta_d={dd!r} is not a physical 1/1 orbit: "
                f"{len(seg.impacts)} impacts in one period, return error {err:.2e}"
            )
    return orbit


def shoot(p: OscillatorParams, x: float | None = None, v: float | None = None,
          periods: int = 1, gains: Gains | None = None, *, deviation=None,
          tol: float = 1e-14, max_iter: int = 60) -> PeriodicOrbit:
    """Periodic orbit of period n by Newton's method on the Pi2 map.

    The 1-DOF case of :func:`grazing_control.dynamics.orbits.shooting.find_periodic` (the model
    :class:`grazing_control.dynamics.maps.model.OneDOF`); a failure raises OrbitNotFound.

    Parameters
    ----------
    x, v : float
        Initial guess on Pi2 (physical coordinates), or
    deviation : (float, float)
        the guess as (x - x**, v - v**), which keeps full precision near grazing.
    periods : int
        n, the period in forcing periods (>= 1).
    tol : float
        Relative size of the last Newton step at convergence.

    Returns
    -------
    PeriodicOrbit
        Its monodromy is the product of Phi, S and G along the orbit (spec section 5).
    """
    if int(periods) != periods or periods < 1:
        raise ValueError(f"periods={periods!r} is invalid: valid range is an integer >= 1")
    if deviation is None:
        if x is None or v is None:
            raise ValueError("give the guess as x and v, or as deviation=(dx, dv)")
        deviation = (x - p.x_ref, v - p.v_ref)
    try:
        o = find_periodic(OneDOF(p, gains), deviation, periods, tol=tol, max_iter=max_iter)
    except ShootingFailed as exc:
        raise OrbitNotFound(str(exc)) from None
    z = o.state
    return PeriodicOrbit(p, gains, periods, to_physical(p, p.tau2, z[0], z[1]),
                         (float(z[0]), float(z[1])), o.impacts, o.monodromy)

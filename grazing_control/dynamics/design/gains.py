"""Control design: the degenerate-grazing gains and the admissible set of c2.

The 1-DOF closed form, the certified fast path behind the one design entry
(:mod:`.model_design`, issue 32; a model file's family is :mod:`.family`).

Spec section 6 (study Eqs. 33-38), derived for this model in docs/theory.md,
"Degenerate grazing and the design", and for an actuation delay in
docs/theory_delay.md, section 2:

* The 1/1 orbit's monodromy is J = M(theta) S with S21 = (1 + r)(cos theta - d)/v-.
  Its unbounded eigenvalue comes from J11 = -r M11 + M12 S21 ~ M12 / v-. It vanishes
  exactly when M12 = 0 at grazing, i.e. N_g,12 = 0 (Eq. 33). N_g = Phi(T - s) G Phi(s)
  is affine in (c1, c2), so N_g,12 = 0 gives c1 as a function of c2 (Eq. 38):

      c1 = -(Q11 P12 + Q12 (1 + c2) P22) / (Q12 P12),   P = Phi(s), Q = Phi(T - s);

  with a delay delta (G -> G_delta = I + b_delta k^T), N_g,12 = Phi12(T) +
  Phi12(T - s - delta) (c1 P12 + c2 P22) = 0 (theory_delay.md, (D5)).

* lambda0 (Eq. 23) and gamma1 (Eq. 36) in closed form from N = N_g in the degenerate
  case (theory_delay.md, section 4, from the Taylor expansion of the exact branch of
  docs/theory.md section 5; no finite differences):

      tr J0 = -r tr N + (1 + r)(N11 - N22)(1 + r N22)/(N22 - 1),  det J0 = r^2 det N,
      gamma1 = a/2 + a (1 + r)(N22 - N11) / ((N11 - 1)(1 + r N22)),

  Delta d = -gamma1 psi^2 + O(psi^3) along the branch; the controlled 1/1 motion exists
  for d < d* iff gamma1 > 0.
* The non-impacting controlled motion (d > d*, the 0/1 orbit) has the multipliers of
  N_g itself; it is stable iff the spectral radius rho(N_g) < 1.

The admissible c2 set is, by default, where all three hold (the *combined* set):
|lambda0| < 1, gamma1 > 0 (the impacting side, the study's set) and rho(N_g) < 1 (the
non-impacting side). The conditions are evaluated division-free
(:func:`condition_values`, docs/theory_delay.md section 5: each is a polynomial of
degree <= 2 in N_g,11, which is affine in c2), so the set's ends are the roots of those
polynomials, bisected to adjacent floats on the admissibility itself; the search
reaches |c2| = C2_LIMIT, beyond any scan window.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains, gain_determinant
from grazing_control.oscillator.flow import transition_matrix
from grazing_control.dynamics.maps.maps import period_matrix
from grazing_control.dynamics.orbits.orbits import multipliers
from grazing_control.oscillator.params import OscillatorParams

from .degenerate import _Degenerate, degenerate_c1, max_design_delay

__all__ = [
    "degenerate_c1",
    "max_design_delay",
    "limit_monodromy",
    "limit_multipliers",
    "existence_coefficient",
    "free_multipliers",
    "DesignPoint",
    "evaluate_design",
    "CONDITIONS",
    "C2_LIMIT",
    "ConditionValues",
    "condition_values",
    "degenerate_n22",
    "breakpoints",
    "admissible_c2",
    "admissible_intervals",
    "controller_parameters",
    "write_controller_yaml",
]

#: Which conditions define the admissible set: 'combined' (default) = 'impacting'
#: (|lambda0| < 1 and gamma1 > 0, the study's) and 'non-impacting' (rho(N_g) < 1).
CONDITIONS = ("combined", "impacting", "non-impacting")


def limit_monodromy(p: OscillatorParams, gains: Gains) -> np.ndarray:
    """J0 up to similarity: [[tr0, -det0], [1, 0]] (companion form of lambda0's equation).

    Closed form in N = N_g (theory_delay.md, (D8)); the limit of J itself has an entry
    growing like 1/v-, but its trace and determinant converge, and they fix the
    multipliers. det0 = r^2 e^{-2 zeta T} det G exactly.
    """
    n11, _n12, _n21, n22 = period_matrix(p, gains)
    r = p.r
    num = (1.0 + r) * (n11 - n22) * (1.0 + r * n22)
    # N22 = 1: the trace has a pole (no bounded lambda0); inf keeps the multipliers unbounded
    tail = num / (n22 - 1.0) if n22 != 1.0 else math.copysign(math.inf, num or 1.0)
    tr0 = -r * (n11 + n22) + tail
    det0 = r ** 2 * math.exp(-2.0 * p.zeta * p.period) * gain_determinant(gains, p.zeta)
    return np.array([[tr0, -det0], [1.0, 0.0]])


def limit_multipliers(p: OscillatorParams, gains: Gains) -> np.ndarray:
    """lambda0: the 1/1 multipliers in the limit Delta d -> 0- (Eq. 23, exact route)."""
    j0 = limit_monodromy(p, gains)
    return multipliers(j0, det=-j0[0, 1])


def existence_coefficient(p: OscillatorParams, gains: Gains) -> float:
    """gamma1 = -kappa, Delta d(psi) = kappa psi^2 + ... on the 1/1 branch (Eq. 36).

    Positive when the controlled 1/1 motion exists for d < d*. Closed form
    gamma1 = a/2 + a (1 + r)(N22 - N11) / ((N11 - 1)(1 + r N22)) (theory_delay.md, (D9)).
    nan at its pole (N11 = 1 or 1 + r N22 = 0), where its sign is undefined; the
    admissible set uses the division-free :func:`condition_values` instead.
    """
    n11, _n12, _n21, n22 = period_matrix(p, gains)
    a, r = p.amplitude, p.r
    num, den = a * (1.0 + r) * (n22 - n11), (n11 - 1.0) * (1.0 + r * n22)
    if den == 0.0:      # on the pole of (D9), which a root search over c2 can hit exactly
        return 0.5 * a if num == 0.0 else math.copysign(math.inf, num)
    return 0.5 * a + num / den


def free_multipliers(p: OscillatorParams, gains: Gains | None) -> np.ndarray:
    """Multipliers of the non-impacting controlled motion (Delta d > 0): eigenvalues of N_g."""
    n = np.array(period_matrix(p, gains)).reshape(2, 2)
    return multipliers(n, det=math.exp(-2.0 * p.zeta * p.period) * gain_determinant(gains, p.zeta))


@dataclass(frozen=True)
class DesignPoint:
    """The design quantities for one c2 (c1 from the degenerate condition).

    multipliers_limit : lambda0, the 1/1 multipliers as Delta d -> 0- (Eq. 23).
    gamma1 : existence coefficient (Eq. 36), > 0: the 1/1 motion exists for d < d*.
    multipliers_free : eigenvalues of N_g, the non-impacting motion for d > d*.
    delay : the actuation delay the design is for (docs/theory_delay.md).
    """

    c1: float
    c2: float
    multipliers_limit: np.ndarray
    gamma1: float
    multipliers_free: np.ndarray | None = None
    delay: float = 0.0

    @property
    def stable(self) -> bool:
        """|lambda0| < 1: the near-grazing 1/1 motion is stable (Eqs. 34, 35)."""
        return bool(np.max(np.abs(self.multipliers_limit)) < 1.0)

    @property
    def free_stable(self) -> bool:
        """rho(N_g) < 1: the non-impacting controlled motion is stable (d > d*)."""
        return self.multipliers_free is None or bool(np.max(np.abs(self.multipliers_free)) < 1.0)

    @property
    def admissible_impacting(self) -> bool:
        """The study's conditions: stable and gamma1 > 0."""
        return self.stable and self.gamma1 > 0.0

    @property
    def admissible(self) -> bool:
        """The combined set: the impacting conditions and rho(N_g) < 1."""
        return self.admissible_impacting and self.free_stable

    def gains(self) -> Gains:
        return Gains(self.c1, self.c2, self.delay)


def evaluate_design(p: OscillatorParams, c2: float, delay: float = 0.0) -> DesignPoint:
    """c1 from c2 (and the delay), lambda0, gamma1 and the multipliers of N_g."""
    g = Gains(degenerate_c1(p, c2, delay), c2, delay)
    return DesignPoint(g.c1, g.c2, limit_multipliers(p, g), existence_coefficient(p, g),
                       free_multipliers(p, g), g.delay)


@dataclass(frozen=True)
class ConditionValues:
    """The design conditions at one c2 as division-free numbers, each > 0 where it holds.

    Multiplying (D8) and (D9) of docs/theory_delay.md through by their denominators
    with their signs (docs/theory_delay.md, section 5): with N = N_g, q = N22 - 1 and
    P = tr J0 q = -r tr N q + (1 + r)(N11 - N22)(1 + r N22),

    limit : Jury's conditions for lambda0 (Eq. 23), times q^2:
        (1 - det J0, (1 + det J0) q^2 - P q, (1 + det J0) q^2 + P q);
    existence : D (D / 2 + (1 + r)(N22 - N11)), D = (N11 - 1)(1 + r N22), which has the
        sign of gamma1 (Eq. 36) = a (D / 2 + (1 + r)(N22 - N11)) / D;
    free : Jury's conditions for N_g (1 - det N, 1 + det N - tr N, 1 + det N + tr N).

    A pole of (D8) or (D9) is a zero here, where the strict condition fails.
    """

    limit: tuple
    existence: float
    free: tuple

    def holds(self, conditions: str = "combined") -> bool:
        """All conditions of the set ``conditions`` (:data:`CONDITIONS`) hold."""
        groups = _GROUPS.get(conditions)
        if groups is None:
            raise ValueError(f"conditions={conditions!r} is invalid: valid values are "
                             f"{', '.join(CONDITIONS)}")
        return all(v > 0.0 for g in groups for v in self._group(g))

    def _group(self, name):
        return (self.existence,) if name == "existence" else getattr(self, name)


_GROUPS = {"combined": ("limit", "existence", "free"), "impacting": ("limit", "existence"),
           "non-impacting": ("free",)}

#: The outward search for the ends of the admissible c2 set stops at |c2| = C2_LIMIT;
#: an interval still open there is reported with an infinite end ("beyond").
C2_LIMIT = 1e6


def degenerate_n22(p: OscillatorParams, delay: float = 0.0) -> float:
    """N_g,22 of the degenerate design, the same for every c2 (docs/theory_delay.md, 5).

    N_g = Phi(T) + h k^T Phi(s), h = Phi(T - s - delay) e2 (D4): N_g,12 = 0 fixes
    k^T Phi(s) e2 = -Phi12(T) / h12, hence N22 = Phi22(T) - h22 Phi12(T) / h12.
    """
    free = transition_matrix(p.zeta, p.period)
    h = transition_matrix(p.zeta, max_design_delay(p) - delay)
    return free[3] - h[3] * free[1] / h[1]


def _n22_family(p, delay):
    """(q, beta) = (N22 - 1, 1 + r N22) of the degenerate design, constant in c2; each is
    set to exactly 0 when it is 0 within the rounding of N22 (the degenerate family:
    lambda0 unbounded, or gamma1 undefined, for every c2); with the design's c2-free
    matrices (:class:`_Degenerate`): what :func:`_values` takes."""
    design = _Degenerate(p, delay)    # first: its ParameterError names a delay out of range
    free = transition_matrix(p.zeta, p.period)
    h = transition_matrix(p.zeta, max_design_delay(p) - delay)
    n22 = free[3] - h[3] * free[1] / h[1]
    err = 8.0 * np.finfo(float).eps * (abs(free[3]) + abs(h[3] * free[1] / h[1]) + 1.0)
    q = n22 - 1.0
    beta = 1.0 + p.r * n22
    return (0.0 if abs(q) <= err else q), (0.0 if abs(beta) <= p.r * err else beta), design


def condition_values(p: OscillatorParams, c2: float, delay: float = 0.0) -> ConditionValues:
    """The division-free design conditions at c2 (c1 from (D5)): :class:`ConditionValues`.

    N22 and the factors q = N22 - 1, 1 + r N22 come from :func:`degenerate_n22` (the
    same for every c2, so their signs cannot flip by rounding); N11, det and tr from
    N_g = :func:`grazing_control.dynamics.maps.maps.period_matrix`.
    """
    return _values(p, c2, delay, _n22_family(p, delay))


def _values(p, c2, delay, family):
    q, beta, design = family
    _c1, (n11, n12, n21, n22), det_g = design.at(c2)
    r = p.r
    n22c = q + 1.0
    det_n = design.decay * det_g
    tr_n = n11 + n22
    det0 = r * r * det_n
    big_p = -r * (n11 + n22c) * q + (1.0 + r) * (n11 - n22c) * beta
    limit = (1.0 - det0, (1.0 + det0) * q * q - big_p * q, (1.0 + det0) * q * q + big_p * q)
    d = (n11 - 1.0) * beta
    existence = d * (0.5 * d + (1.0 + r) * (n22c - n11))
    free = (1.0 - det_n, 1.0 + det_n - tr_n, 1.0 + det_n + tr_n)
    return ConditionValues(limit, existence, free)


def _c2_of_n11(p, delay):
    """(u0, sigma): N_g,11 = u0 + sigma c2 along the degenerate design (from (D4), (D5):
    N11 = Phi11(T) - P11 Phi12(T) / P12 - c2 h12 det Phi(s) / P12)."""
    s = p.pi2_offset / p.omega
    p11, p12, _p21, _p22 = transition_matrix(p.zeta, s)
    free = transition_matrix(p.zeta, p.period)
    h12 = transition_matrix(p.zeta, max_design_delay(p) - delay)[1]
    return free[0] - p11 * free[1] / p12, -h12 * math.exp(-2.0 * p.zeta * s) / p12


def breakpoints(p: OscillatorParams, delay: float = 0.0, conditions: str = "combined"):
    """The c2 where a condition value of the set may change sign (sorted, |c2| < C2_LIMIT).

    Every value of :class:`ConditionValues` is a polynomial of degree <= 2 in
    u = N_g,11, which is affine in c2 (docs/theory_delay.md, section 5): each value is
    sampled at three u, its roots mapped to c2. Between two consecutive breakpoints
    the admissibility cannot change.
    """
    degenerate_c1(p, 0.0, delay)  # ParameterError where no degenerate design exists
    family = _n22_family(p, delay)
    u0, sigma = _c2_of_n11(p, delay)
    nodes = np.array([-2.0, 0.0, 2.0])
    cs = (nodes - u0) / sigma
    vals = [_values(p, float(c), delay, family) for c in cs]
    out = []
    for group in _GROUPS[conditions]:
        for k in range(len(vals[0]._group(group))):
            y = [v._group(group)[k] for v in vals]
            coef = np.polyfit(nodes, y, 2)
            scale = max(abs(x) for x in y) or 1.0
            coef[np.abs(coef) <= 1e-12 * scale] = 0.0
            coef = np.trim_zeros(coef, "f")
            if len(coef) < 2:
                continue
            for u in np.roots(coef):
                if abs(u.imag) <= 1e-9 * max(1.0, abs(u.real)):
                    c2 = (u.real - u0) / sigma
                    if abs(c2) < C2_LIMIT:
                        out.append(float(c2))
    return sorted(set(out))


def admissible_c2(p: OscillatorParams, lo: float = -4.0, hi: float = 2.0, n: int = 601, *,
                  delay: float = 0.0, conditions: str = "combined"):
    """Intervals of c2 where the degenerate design (for ``delay``) meets ``conditions``.

    'combined' (default): |lambda0| < 1, gamma1 > 0 and rho(N_g) < 1; 'impacting': the
    first two (the study's set); 'non-impacting': rho(N_g) < 1 alone. The conditions
    are read from the division-free :func:`condition_values`. The candidate ends are
    the roots of their polynomials (:func:`breakpoints`) and a scan of [lo, hi] on n
    points; admissibility is constant between consecutive candidates, so each interval
    is found whole, wherever it lies in |c2| < C2_LIMIT, and each end is bisected on
    the admissibility itself to a few ulps (from both sides of the switch).

    Returns
    -------
    list of (float, float)
        Sorted, disjoint. An end at -inf or +inf: the interval is still open at
        c2 = -C2_LIMIT or +C2_LIMIT (the search stops there).
    """
    if conditions not in _GROUPS:
        raise ValueError(f"conditions={conditions!r} is invalid: valid values are {', '.join(CONDITIONS)}")
    degenerate_c1(p, 0.0, delay)  # ParameterError where no degenerate design exists
    family = _n22_family(p, delay)

    def ok(c2):
        return _values(p, c2, delay, family).holds(conditions)

    cands = breakpoints(p, delay, conditions)
    grid = np.linspace(lo, hi, n) if n > 0 else np.array([])
    return admissible_intervals(ok, cands + [float(x) for x in grid])


def admissible_intervals(ok, candidates, limit: float = C2_LIMIT):
    """Intervals of c2 in (-limit, limit) where ``ok(c2)`` holds, given every point where
    it may switch (``candidates``): each gap between consecutive candidates is decided
    at its midpoint, each switch bisected between the midpoints on either side until
    they are adjacent floats (the admissible one is returned). An interval still open
    at +-limit gets an infinite end. ``ok`` must not raise. An "interval" narrower
    than 1e-12 relative is rounding at a pole of the conditions (seen in the series of
    the perturbation route, 30 ulps wide), not a set, and is dropped."""
    pts = sorted({-limit, limit, *(float(c) for c in candidates if -limit < c < limit)})
    mids = [0.5 * (a + b) for a, b in zip(pts, pts[1:])]
    flags = [bool(ok(m)) for m in mids]
    out, start = [], None
    for k, flag in enumerate(flags):
        if flag and start is None:
            start = -math.inf if k == 0 else _switch(ok, mids[k], mids[k - 1])
        if not flag and start is not None:
            end = _switch(ok, mids[k - 1], mids[k])
            if end - start > _SLIVER * max(1.0, abs(end)):
                out.append((start, end))
            start = None
    if start is not None:
        out.append((start, math.inf))
    return out


#: Relative width below which an admissible interval is a rounding artefact.
_SLIVER = 1e-12


def _switch(ok, inside, outside):
    """Bisect between an admissible point and an inadmissible one to adjacent floats."""
    while True:
        mid = 0.5 * (inside + outside)
        if mid in (inside, outside):
            return float(inside)
        if ok(mid):
            inside = mid
        else:
            outside = mid


def controller_parameters(p: OscillatorParams, gains: Gains) -> dict:
    """The controller node's parameters: gains, actuation delay, X**, and the model.

    ``actuation_delay`` (simulation time after the Pi2 sample) is the delay the gains
    were designed for (docs/theory_delay.md); 0 for the study's controller.
    """
    return {
        "c1": float(gains.c1),
        "c2": float(gains.c2),
        "actuation_delay": float(gains.delay),
        "x_ref": float(p.x_ref),
        "v_ref": float(p.v_ref),
        "zeta": float(p.zeta),
        "r": float(p.r),
        "omega": float(p.omega),
        "pi2_offset": float(p.pi2_offset),
    }


def write_controller_yaml(path, p: OscillatorParams, gains: Gains,
                          node_name: str = "**") -> None:
    """Write the ROS 2 parameter file the controller node loads.

    Shape: ``/**: ros__parameters: {c1, c2, actuation_delay, x_ref, v_ref, zeta, r, omega,
    pi2_offset}``: keyed ``/**`` so that it applies under a namespace or a renamed node
    too (a ``/controller_node:`` key would be silently ignored there). Written to a
    temporary file and renamed, so a failure leaves no
    half-written file.
    """
    from grazing_control.support.files import write_yaml_atomic

    doc = {f"/{node_name}": {"ros__parameters": controller_parameters(p, gains)}}
    write_yaml_atomic(path, doc,
                      ["controller gains from `grazing design` (degenerate grazing, Eq. 38)"])

"""Control design: the degenerate-grazing gains and the admissible set of c2.

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
non-impacting side). End points are located by Brent's method on the condition that
changes sign.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.control import Gains, gain_determinant
from grazing_control.oscillator.flow import transition_matrix
from .maps import period_matrix
from .orbits import multipliers
from grazing_control.oscillator.params import OscillatorParams, ParameterError

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
    "admissible_c2",
    "controller_parameters",
    "write_controller_yaml",
]

#: Which conditions define the admissible set: 'combined' (default) = 'impacting'
#: (|lambda0| < 1 and gamma1 > 0, the study's) and 'non-impacting' (rho(N_g) < 1).
CONDITIONS = ("combined", "impacting", "non-impacting")


def max_design_delay(p: OscillatorParams) -> float:
    """T - s: the delay at which the kick reaches the grazing phase tau* (theory_delay.md, 2).

    A degenerate design needs delay < T - s: a kick after the grazing impact cannot
    cancel the singular multiplier.
    """
    return p.period - p.pi2_offset / p.omega


def degenerate_c1(p: OscillatorParams, c2: float, delay: float = 0.0) -> float:
    """c1 that makes N_g,12 = 0 for a given c2 (Eq. 38), with the kick ``delay`` after Pi2.

    delay = 0 is the study's formula; delay > 0 solves (D5) of docs/theory_delay.md,
    0 <= delay < T - s. Raises ParameterError where no c1 exists
    (Phi12(T - s - delay) = 0) or the delay is out of range.
    """
    s = p.pi2_offset / p.omega
    p11, p12, _p21, p22 = transition_matrix(p.zeta, s)
    if delay == 0.0:
        q11, q12, _q21, _q22 = transition_matrix(p.zeta, p.period - s)
        return -(q11 * p12 + q12 * (1.0 + c2) * p22) / (q12 * p12)
    top = max_design_delay(p)
    if not (math.isfinite(delay) and 0.0 < delay < top):
        raise ParameterError(f"delay={delay!r} is invalid: valid range is 0 <= delay < T - s = {top!r} "
                             f"(the kick must act before the grazing phase)")
    n12_free = transition_matrix(p.zeta, p.period)[1]
    h12 = transition_matrix(p.zeta, top - delay)[1]
    c1 = -(n12_free / h12 + c2 * p22) / p12 if h12 != 0.0 else math.inf
    if not math.isfinite(c1):
        raise ParameterError(f"delay={delay!r} is invalid: Phi12(T - s - delay) = {h12!r}, no gain c1 "
                             f"makes N_g,12 = 0 there (delay = T - s - n pi / omega_d)")
    return c1


def limit_monodromy(p: OscillatorParams, gains: Gains) -> np.ndarray:
    """J0 up to similarity: [[tr0, -det0], [1, 0]] (companion form of lambda0's equation).

    Closed form in N = N_g (theory_delay.md, (D8)); the limit of J itself has an entry
    growing like 1/v-, but its trace and determinant converge, and they fix the
    multipliers. det0 = r^2 e^{-2 zeta T} det G exactly.
    """
    n11, _n12, _n21, n22 = period_matrix(p, gains)
    r = p.r
    tr0 = -r * (n11 + n22) + (1.0 + r) * (n11 - n22) * (1.0 + r * n22) / (n22 - 1.0)
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


def _condition_functions(p, delay, conditions):
    """Functions of c2 negative where each condition of ``conditions`` holds."""
    def stab(c2):
        return float(np.max(np.abs(evaluate_design(p, c2, delay).multipliers_limit))) - 1.0

    def exist(c2):
        return -evaluate_design(p, c2, delay).gamma1

    def free(c2):
        return float(np.max(np.abs(evaluate_design(p, c2, delay).multipliers_free))) - 1.0

    if conditions == "impacting":
        return (stab, exist)
    if conditions == "non-impacting":
        return (free,)
    if conditions == "combined":
        return (stab, exist, free)
    raise ValueError(f"conditions={conditions!r} is invalid: valid values are {', '.join(CONDITIONS)}")


def admissible_c2(p: OscillatorParams, lo: float = -4.0, hi: float = 2.0, n: int = 601, *,
                  delay: float = 0.0, conditions: str = "combined"):
    """Intervals of c2 where the degenerate design (for ``delay``) meets ``conditions``.

    'combined' (default): |lambda0| < 1, gamma1 > 0 and rho(N_g) < 1; 'impacting': the
    first two (the study's set); 'non-impacting': rho(N_g) < 1 alone. Scans [lo, hi] on
    n points, then refines each end point with Brent's method on the condition that
    changes sign there to ~1e-13.

    Returns
    -------
    list of (float, float)
    """
    funcs = _condition_functions(p, delay, conditions)
    grid = np.linspace(lo, hi, n)
    ok = [all(f(c2) < 0.0 for f in funcs) for c2 in grid]
    intervals = []
    start = None
    for k, flag in enumerate(ok):
        if flag and start is None:
            start = float(grid[0]) if k == 0 else _edge(grid[k - 1], grid[k], funcs)
        if not flag and start is not None:
            intervals.append((start, _edge(grid[k - 1], grid[k], funcs)))
            start = None
    if start is not None:
        intervals.append((start, float(grid[-1])))
    return intervals


def _edge(a, b, funcs):
    """The end point of an admissible interval between grid points a and b: Brent's
    method on whichever condition changes sign there (the one nearest to a if several)."""
    edges = []
    for f in funcs:
        fa, fb = f(a), f(b)
        if fa * fb < 0.0:
            edges.append(brentq(f, a, b, xtol=1e-13))
    if not edges:
        return float(0.5 * (a + b))
    # the set changes where the first condition to switch does, seen from the inside
    ok_a = all(f(a) < 0.0 for f in funcs)
    return float(min(edges) if ok_a else max(edges))


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
    import os
    import tempfile

    import yaml

    doc = {f"/{node_name}": {"ros__parameters": controller_parameters(p, gains)}}
    path = os.fspath(path)
    if not path.strip():
        raise ValueError(f"path={path!r} is invalid: expected a non-empty file path")
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".yaml.tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write("# controller gains from `grazing design` (degenerate grazing, Eq. 38)\n")
            yaml.safe_dump(doc, fh, sort_keys=False)
        mask = os.umask(0)  # mkstemp creates 0600: give the usual 0666 & ~umask
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise

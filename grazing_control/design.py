"""Control design: the degenerate-grazing gains and the admissible set of c2.

Spec section 6 (study Eqs. 33-38), derived for this model in docs/theory.md,
"Degenerate grazing and the design":

* The 1/1 orbit's monodromy is J = M(theta) S with S21 = (1 + r)(cos theta - d)/v-.
  Its unbounded eigenvalue comes from J11 = -r M11 + M12 S21 ~ M12 / v-. It vanishes
  exactly when M12 = 0 at grazing, i.e. N_g,12 = 0 (Eq. 33). N_g = Phi(T - s) G Phi(s)
  is affine in (c1, c2), so N_g,12 = 0 gives c1 as a function of c2 (Eq. 38):

      c1 = -(Q11 P12 + Q12 (1 + c2) P22) / (Q12 P12),   P = Phi(s), Q = Phi(T - s).

* In the limit Delta d -> 0-, M12(theta) and v-(theta) both vanish linearly in the
  impact phase offset psi, so J tends to a bounded limit J0 with
  trace J0 = -r trace N_g + (1 + r) a* lim(M12 / v-) and det J0 = r^2 e^{-2 zeta T}(1 + c2);
  its eigenvalues are lambda0 (Eq. 23). Stability needs |lambda0| < 1 (Eqs. 34, 35).
* Existence on the impacting side (Eq. 36, gamma1 > 0): along the branch,
  Delta d(psi) = kappa psi^2 + O(psi^3) in the degenerate case; the controlled 1/1
  motion exists for d < d* iff kappa < 0. We report gamma1 = -kappa.

The admissible c2 set is where lambda0 is inside the unit circle and gamma1 > 0; its
end points are located by Brent's method on max|lambda0| - 1 and gamma1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .control import Gains
from .flow import transition_matrix
from .orbits import branch_point, multipliers
from .params import OscillatorParams

__all__ = [
    "degenerate_c1",
    "limit_monodromy",
    "limit_multipliers",
    "existence_coefficient",
    "DesignPoint",
    "evaluate_design",
    "admissible_c2",
    "controller_parameters",
    "write_controller_yaml",
]

#: Phase offset at which limits psi -> 0 are evaluated (symmetric differences cancel
#: the O(psi) term; the O(psi^2) remainder is ~1e-10 relative).
_PSI = 1e-5


def degenerate_c1(p: OscillatorParams, c2: float) -> float:
    """c1 that makes N_g,12 = 0 for a given c2 (Eq. 38)."""
    s = p.pi2_offset / p.omega
    p11, p12, _p21, p22 = transition_matrix(p.zeta, s)
    q11, q12, _q21, _q22 = transition_matrix(p.zeta, p.period - s)
    return -(q11 * p12 + q12 * (1.0 + c2) * p22) / (q12 * p12)


def _ratio_limit(p, gains):
    """lim_{psi->0} M12(theta) / v-(theta) by a symmetric quotient at +-_PSI."""
    vals = []
    for psi in (_PSI, -_PSI):
        _dd, v, m = branch_point(p, psi, gains)
        vals.append(m[1] / v)
    return 0.5 * (vals[0] + vals[1])


def limit_monodromy(p: OscillatorParams, gains: Gains) -> np.ndarray:
    """J0 up to similarity: [[tr0, -det0], [1, 0]] (companion form of lambda0's equation).

    The limit of J itself has an entry growing like 1/v-, but its trace and
    determinant converge, and they fix the multipliers.
    """
    _dd, _v, m0 = branch_point(p, 0.0, gains)
    a_star_r = (1.0 + p.r) * (math.cos(p.tau_star) - p.d_star)
    tr0 = -p.r * (m0[0] + m0[3]) + a_star_r * _ratio_limit(p, gains)
    det0 = p.r ** 2 * math.exp(-2.0 * p.zeta * p.period) * (1.0 + gains.c2)
    return np.array([[tr0, -det0], [1.0, 0.0]])


def limit_multipliers(p: OscillatorParams, gains: Gains) -> np.ndarray:
    """lambda0: the 1/1 multipliers in the limit Delta d -> 0- (Eq. 23, exact route)."""
    j0 = limit_monodromy(p, gains)
    return multipliers(j0, det=-j0[0, 1])


def existence_coefficient(p: OscillatorParams, gains: Gains) -> float:
    """gamma1 = -kappa, Delta d(psi) = kappa psi^2 + ... on the 1/1 branch (Eq. 36).

    Positive when the controlled 1/1 motion exists for d < d*. The symmetric quotient
    (Delta d(psi) + Delta d(-psi)) / (2 psi^2) removes the linear term, which vanishes
    in the degenerate case only up to rounding.
    """
    dp = branch_point(p, _PSI, gains)[0]
    dm = branch_point(p, -_PSI, gains)[0]
    return -(dp + dm) / (2.0 * _PSI * _PSI)


@dataclass(frozen=True)
class DesignPoint:
    """The design quantities for one c2 (c1 from the degenerate condition)."""

    c1: float
    c2: float
    multipliers_limit: np.ndarray
    gamma1: float

    @property
    def stable(self) -> bool:
        return bool(np.max(np.abs(self.multipliers_limit)) < 1.0)

    @property
    def admissible(self) -> bool:
        return self.stable and self.gamma1 > 0.0


def evaluate_design(p: OscillatorParams, c2: float) -> DesignPoint:
    """c1 from c2, the limit multipliers lambda0 and gamma1, for the exact model."""
    g = Gains(degenerate_c1(p, c2), c2)
    return DesignPoint(g.c1, g.c2, limit_multipliers(p, g), existence_coefficient(p, g))


def admissible_c2(p: OscillatorParams, lo: float = -4.0, hi: float = 2.0, n: int = 601):
    """Intervals of c2 where the degenerate design is admissible (stable and gamma1 > 0).

    Scans [lo, hi] on n points, then refines each end point with Brent's method on
    max|lambda0| - 1 or gamma1 (whichever changes sign there) to ~1e-12.

    Returns
    -------
    list of (float, float)
    """
    grid = np.linspace(lo, hi, n)

    def stab(c2):
        return float(np.max(np.abs(evaluate_design(p, c2).multipliers_limit))) - 1.0

    def exist(c2):
        return evaluate_design(p, c2).gamma1

    pts = [evaluate_design(p, c2) for c2 in grid]
    ok = [d.admissible for d in pts]
    intervals = []
    start = None
    for k, flag in enumerate(ok):
        if flag and start is None:
            start = grid[0] if k == 0 else _edge(grid[k - 1], grid[k], stab, exist)
        if not flag and start is not None:
            intervals.append((start, _edge(grid[k - 1], grid[k], stab, exist)))
            start = None
    if start is not None:
        intervals.append((start, grid[-1]))
    return intervals


def _edge(a, b, stab, exist):
    """The end point of an admissible interval between grid points a and b: Brent's
    method on whichever condition changes sign there (stability first)."""
    for f in (stab, exist):
        fa, fb = f(a), f(b)
        if fa * fb < 0.0:
            return brentq(f, a, b, xtol=1e-13)
    return 0.5 * (a + b)


def controller_parameters(p: OscillatorParams, gains: Gains) -> dict:
    """The controller node's parameters: gains, X**, and the model they were made for."""
    return {
        "c1": float(gains.c1),
        "c2": float(gains.c2),
        "x_ref": float(p.x_ref),
        "v_ref": float(p.v_ref),
        "zeta": float(p.zeta),
        "r": float(p.r),
        "omega": float(p.omega),
        "pi2_offset": float(p.pi2_offset),
    }


def write_controller_yaml(path, p: OscillatorParams, gains: Gains,
                          node_name: str = "controller_node") -> None:
    """Write the ROS 2 parameter file the controller node loads.

    Shape: ``/controller_node: ros__parameters: {c1, c2, x_ref, v_ref, zeta, r, omega,
    pi2_offset}``. Written to a temporary file and renamed, so a failure leaves no
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

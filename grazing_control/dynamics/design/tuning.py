"""Choosing c2 inside the admissible set: the least noise gain (issue 15 section 3).

Every c2 of the admissible set (:func:`grazing_control.dynamics.design.gains.admissible_c2`,
with c1 from the degenerate condition, Eq. 38 or (D5) of docs/theory_delay.md) cancels
the singular multiplier; they differ in what they do with measurement noise. The noise
gain (:func:`grazing_control.dynamics.design.noise.noise_gain`: the stationary std of the Pi2
position per unit measurement noise, from the discrete Lyapunov equation of the loop
linearised about the controlled orbit, docs/robustness.md section 3) is

    g(c2) = sqrt(Sigma_xx),  Sigma = J Sigma J^T + (M2 e2)(M2 e2)^T k^T R k,

so it is small where k = (c1(c2), c2) is short and J contracts. Along the design
c1 = alpha + beta c2 (beta = -Phi22(s) / Phi12(s), (D5)), and |k| is least near
c2 = -alpha beta / (1 + beta^2) (0.007 for the study's parameters, where c1 = -0.0071):
a controller that barely acts on the orbit, yet still cancels N_g,12 (the cancellation
needs only the *difference* between c1 and c2 terms, Eq. 38).

:func:`optimize_noise` minimises g over each admissible interval: a grid of ``points``
c2 strictly inside, then Brent's bounded method on the cells around the best grid point
(scipy.optimize.minimize_scalar); where the orbit does not exist or the loop is not
stable at this Delta d the objective is +inf, so the ends where |lambda| reaches 1 are
avoided by the search itself, and an end where the gain stays finite (the non-impacting
condition rho(N_g) = 1, which the impacting loop does not feel) is reached from inside.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgWarning
from scipy.optimize import minimize_scalar

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import ImpactCapError, InitialStateError
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.design.gains import C2_LIMIT, admissible_c2, degenerate_c1
from grazing_control.dynamics.design.noise import noise_gain
from grazing_control.dynamics.orbits.orbits import OrbitNotFound

__all__ = ["STUDY_C2", "NoiseDesign", "design_noise_gain", "optimize_noise"]

#: The study's choice of c2 (Fig. 2), the comparison for every tuned design.
STUDY_C2 = -1.0


@dataclass(frozen=True)
class NoiseDesign:
    """The c2 of least noise gain at ``delta_d`` (and the study's c2 for comparison).

    interval : the admissible interval that holds c2 (an end may be +-inf: beyond
        C2_LIMIT). study_noise_gain : the gain with c2 = STUDY_C2 (inf where that c2
        gives no stable controlled orbit at this delta_d with this delay).
    evaluations : objective evaluations spent.
    """

    c1: float
    c2: float
    delay: float
    delta_d: float
    noise_gain: float
    interval: tuple
    study_noise_gain: float
    evaluations: int

    def gains(self) -> Gains:
        return Gains(self.c1, self.c2, self.delay)


def design_noise_gain(p: OscillatorParams, c2: float, delay: float = 0.0,
                      measurement=None) -> float:
    """The noise gain of the degenerate design c2 (c1 from Eq. 38 / (D5)) at ``p.delta_d``.

    ``measurement``: the covariance of the Pi2 estimate's error per unit sigma^2 (2x2;
    default I, independent noise of equal sigma on x and v). This is the hook for a
    position-only sensor: pass the covariance its estimator reports per unit sigma.
    +inf where no stable controlled 1/1 orbit exists at this Delta d (no stationary
    spread).
    """
    try:
        g = Gains(degenerate_c1(p, c2, delay), c2, delay)
        with warnings.catch_warnings():  # |lambda| -> 1 near an end: Lyapunov ill-conditioned
            warnings.simplefilter("ignore", LinAlgWarning)
            return noise_gain(p, g, measurement)
    except (OrbitNotFound, ImpactCapError, InitialStateError, ValueError, ArithmeticError):
        return math.inf


def optimize_noise(p: OscillatorParams, delay: float = 0.0, *, measurement=None,
                   points: int = 41) -> NoiseDesign:
    """c2 in the admissible set (combined conditions, for ``delay``) of least noise gain
    at ``p.delta_d`` (module docstring). Raises ParameterError where the admissible set
    is empty or no c2 of it gives a stable controlled orbit at this Delta d."""
    if not p.delta_d < 0.0:
        raise ParameterError(f"delta_d={p.delta_d!r} is invalid: the noise gain is that of the "
                             f"controlled 1/1 orbit, valid range is delta_d < 0")
    intervals = admissible_c2(p, delay=delay)
    if not intervals:
        raise ParameterError(f"delay={delay!r}: the admissible c2 set is empty, nothing to optimise")
    count = 0

    def f(c2):
        nonlocal count
        count += 1
        return design_noise_gain(p, float(c2), delay, measurement)

    best = (math.inf, math.nan, None)
    for lo, hi in intervals:
        a, b = max(lo, -C2_LIMIT), min(hi, C2_LIMIT)
        grid = a + (b - a) * (np.arange(points) + 0.5) / points
        vals = [f(c) for c in grid]
        k = int(np.argmin(vals))
        if not math.isfinite(vals[k]):
            continue
        left = grid[k - 1] if k > 0 else a
        right = grid[k + 1] if k < points - 1 else b
        res = minimize_scalar(f, bounds=(left, right), method="bounded",
                              options={"xatol": 1e-10 * max(1.0, abs(grid[k]))})
        for c2, val in ((float(res.x), float(res.fun)), (float(grid[k]), float(vals[k]))):
            if val < best[0]:
                best = (val, c2, (lo, hi))
    gain, c2, interval = best
    if interval is None:
        raise ParameterError(f"delta_d={p.delta_d!r}: no admissible c2 gives a stable controlled "
                             f"1/1 orbit here (delay={delay!r})")
    return NoiseDesign(degenerate_c1(p, c2, delay), c2, delay, p.delta_d, gain, interval,
                       design_noise_gain(p, STUDY_C2, delay, measurement), count)

"""Is the estimator's model the plant's? The windowed innovation test (issue 29 section 2).

Under the right model every period of the model filter's fit has a normalised
innovation squared J_k (the minimised cost of the iterated EKF: the prior term plus the
residuals over sigma^2, which for a linear Gaussian model equals nu^T S^-1 nu of the
innovation nu with S = H P H^T + sigma^2 I, docs/theory_estimation.md (E9)) distributed
chi^2 with n_k degrees of freedom (one per measurement), and the innovations of
different periods are independent. The sum over a sliding window of the last W
periods,

    q = sum J_k  ~  chi^2( sum n_k ),

exceeds its bound b = chi2.isf(alpha, sum n_k) with probability alpha: the false-alarm
rate *per evaluated window*. A wrong model (a stiffness, damping or clearance that is
not the plant's; a sensor bias the filter does not know) adds a deterministic part to
the residuals, so q grows like W times its square over sigma^2 and crosses the bound.

:class:`ConsistencyMonitor` is a pure object: the controller feeds it each section's
(J_k, n_k) (:attr:`grazing_control.dynamics.augmented.AugmentedStreamEstimator.innovation`)
and gets a :class:`Verdict` back, ``ok`` or ``mismatch`` with the statistic and its bound.
A window not yet full is tested with the degrees of freedom it holds (the same alpha),
so a gross mismatch is named in its first period. A section without a fit (the filter
restarted from the arc fit) adds nothing; a fit that failed outright is counted in
:attr:`Verdict.failed` (a failure is not evidence of a wrong model by itself: a reset
by the filter's own chi^2 test comes with its J and is counted).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from scipy.stats import chi2

from grazing_control.oscillator.params import ParameterError

__all__ = ["Verdict", "ConsistencyMonitor", "VERDICTS", "FALSE_ALARM", "WINDOW"]

#: The verdicts, in order of severity.
VERDICTS = ("ok", "mismatch")
#: The default false-alarm rate per evaluated window.
FALSE_ALARM = 1e-3
#: The default window, in periods.
WINDOW = 10


@dataclass(frozen=True)
class Verdict:
    """The test at section ``k``: ``status`` (``ok`` or ``mismatch``), the window's
    ``statistic`` q = sum J, its degrees of freedom ``dof``, the ``bound``
    chi2.isf(alpha, dof), the ``periods`` in the window, and ``failed`` (fits that failed
    in the window)."""

    k: int
    status: str
    statistic: float
    dof: int
    bound: float
    periods: int
    failed: int = 0

    @property
    def ratio(self) -> float:
        """statistic / dof: 1 on average under the right model."""
        return self.statistic / self.dof if self.dof else math.nan


class ConsistencyMonitor:
    """The sliding-window chi^2 test of the innovations (module docstring).

    Parameters
    ----------
    window : int
        Periods in the window (>= 1).
    false_alarm : float
        alpha, the probability that a window fails under the right model, in (0, 0.5).
    """

    def __init__(self, window: int = WINDOW, false_alarm: float = FALSE_ALARM):
        if isinstance(window, bool) or int(window) != window or window < 1:
            raise ParameterError(f"consistency_window={window!r} is invalid: valid range is an "
                                 "integer >= 1 periods")
        false_alarm = float(false_alarm)
        if not (0.0 < false_alarm < 0.5):
            raise ParameterError(f"false_alarm={false_alarm!r} is invalid: valid range is "
                                 "0 < false_alarm < 0.5 per window")
        self.window, self.false_alarm = int(window), false_alarm
        self._terms = deque()          # (k, J, n) of the window, or (k, None, 0): failed
        self._bounds = {}

    def reset(self) -> None:
        self._terms.clear()

    def bound(self, dof: int) -> float:
        """chi2.isf(alpha, dof), cached."""
        if dof not in self._bounds:
            self._bounds[dof] = float(chi2.isf(self.false_alarm, dof))
        return self._bounds[dof]

    def add(self, k: int, statistic: float | None, dof: int = 0) -> Verdict | None:
        """Section k's normalised innovation squared ``statistic`` over ``dof``
        measurements (None: the fit failed); returns the window's verdict, or None while
        the window holds no fitted period."""
        if statistic is not None and not (math.isfinite(statistic) and dof >= 1):
            statistic = None           # a non-finite J: a failed fit
        self._terms.append((int(k), statistic, int(dof) if statistic is not None else 0))
        while self._terms and self._terms[0][0] <= k - self.window:
            self._terms.popleft()
        return self.verdict(k)

    def verdict(self, k: int) -> Verdict | None:
        fitted = [t for t in self._terms if t[1] is not None]
        if not fitted:
            return None
        q = math.fsum(t[1] for t in fitted)
        dof = sum(t[2] for t in fitted)
        bound = self.bound(dof)
        status = "mismatch" if q > bound else "ok"
        return Verdict(int(k), status, q, dof, bound, len(fitted),
                       len(self._terms) - len(fitted))

"""Is the estimator's model the plant's? The windowed innovation tests (issue 29 section 2).

Under the right model every period of the model filter's fit has an innovation nu_k
(the samples less their prediction from the prior) of covariance S_k = H P H^T +
sigma^2 I, and the innovations of different periods are independent (white). Two
statistics over a sliding window of the last W periods (docs/theory_estimation.md
E9, E10):

``nis``
    The normalised innovation squared, J_k = nu^T S^-1 nu: the minimised cost of the
    iterated EKF (the prior term plus the residuals over sigma^2; equal to nu^T S^-1 nu
    for a linear Gaussian model, (E9)), chi^2 with n_k degrees of freedom (one per
    measurement). q = sum J_k ~ chi^2(sum n_k).
``mean``
    The window's mean whitened innovation: eps_k = L_k^-1 nu_k (S_k = L_k L_k^T,
    :func:`grazing_control.dynamics.estimation.augmented.augmented_update`) is N(0, I_n); on a
    periodic orbit the samples sit at the same phases every period, so a wrong model
    leaves the *same* residual pattern mu in each, which adds up in the sum while the
    noise does not: q = |sum eps_k|^2 / W ~ chi^2(n) under the right model, and its
    non-centrality is W |mu|^2 against the nis test's W |mu|^2 spread over W n degrees of
    freedom. Periods with another number of samples than the newest (a lost sample) are
    left out of this sum.

Each is compared with its bound chi2.isf(alpha / 2, dof), so that the window fails under
the right model with probability at most alpha (the false-alarm rate *per evaluated
window*, Bonferroni). A wrong model (a stiffness, damping or clearance that is not the
plant's; a sensor bias the filter does not know) fails them.

:class:`ConsistencyMonitor` is a pure object: the controller feeds it each section's
(J_k, n_k, eps_k) (:attr:`grazing_control.dynamics.estimation.augmented.AugmentedStreamEstimator.innovation`)
and gets a :class:`Verdict` back, ``ok`` or ``mismatch`` with the statistics and their
bounds. A window not yet full is tested with what it holds (the same alpha), so a gross
mismatch is named in its first period. A section without a fit (the filter restarted
from the arc fit) adds nothing; a fit that failed (no convergence, or a reset by the
filter's own chi^2 test) is counted in :attr:`Verdict.failed`, and when half the window
(at least 2) has failed, the verdict is a mismatch named ``resets``: a model so wrong
that the filter keeps restarting has no innovations left to test.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

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
    """The tests at section ``k``: ``status`` (``ok`` or ``mismatch``), ``failing`` (the
    tests that fail: a tuple of ``nis``, ``mean``, ``resets``); the nis test's
    ``statistic`` q = sum J, its degrees of freedom ``dof`` and ``bound``; the mean test's
    ``mean_statistic``, ``mean_dof`` and ``mean_bound`` (NaN, 0 without whitened
    innovations); the ``periods`` in the window and ``failed`` (fits that failed in it)."""

    k: int
    status: str
    statistic: float
    dof: int
    bound: float
    periods: int
    failed: int = 0
    mean_statistic: float = math.nan
    mean_dof: int = 0
    mean_bound: float = math.nan
    failing: tuple = ()

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
        """chi2.isf(alpha / 2, dof), cached (each of the two tests at alpha / 2): scipy's
        chi-squared inverse survival function itself (``chdtri``, what ``chi2.isf``
        calls), bit for bit (tests/test_consistency.py)."""
        if dof not in self._bounds:
            # imported here, and from scipy.special: scipy.stats (2.2-2.8 s of a watchful
            # controller's start on a slow host, against 0.65-0.72 s) loads scipy.optimize
            # and scipy.integrate, which a node does not use (tests/test_node_common.py)
            from scipy.special import chdtri

            self._bounds[dof] = float(chdtri(dof, 0.5 * self.false_alarm))
        return self._bounds[dof]

    def add(self, k: int, statistic: float | None, dof: int = 0,
            whitened=None) -> Verdict | None:
        """Section k's normalised innovation squared ``statistic`` over ``dof``
        measurements and its ``whitened`` innovation (optional; None: the fit failed);
        returns the window's verdict, or None while the window holds no fitted period."""
        if statistic is not None and not (math.isfinite(statistic) and dof >= 1):
            statistic = None           # a non-finite J: a failed fit
        if whitened is not None:
            whitened = np.asarray(whitened, dtype=float)
            if statistic is None or not np.all(np.isfinite(whitened)):
                whitened = None
        self._terms.append((int(k), statistic, int(dof) if statistic is not None else 0,
                            whitened))
        while self._terms and self._terms[0][0] <= k - self.window:
            self._terms.popleft()
        return self.verdict(k)

    def verdict(self, k: int) -> Verdict | None:
        fitted = [t for t in self._terms if t[1] is not None]
        if not fitted:
            if len(self._terms) >= max(2, math.ceil(self.window / 2)):
                return Verdict(int(k), "mismatch", 0.0, 0, math.nan, 0, len(self._terms),
                               failing=("resets",))
            return None
        q = math.fsum(t[1] for t in fitted)
        dof = sum(t[2] for t in fitted)
        bound = self.bound(dof)
        failing = ("nis",) if q > bound else ()
        failed = len(self._terms) - len(fitted)
        if failed >= max(2, math.ceil(self.window / 2)):
            failing += ("resets",)     # the filter fails as often as it fits
        mean_q, mean_dof, mean_bound = math.nan, 0, math.nan
        vectors = [t[3] for t in fitted if t[3] is not None]
        if vectors:
            size = vectors[-1].size
            same = [e for e in vectors if e.size == size]
            mean_q = float(np.sum(np.sum(same, axis=0) ** 2)) / len(same)
            mean_dof, mean_bound = size, self.bound(size)
            if mean_q > mean_bound:
                failing += ("mean",)
        return Verdict(int(k), "mismatch" if failing else "ok", q, dof, bound, len(fitted),
                       failed, mean_q, mean_dof, mean_bound, failing)

"""The relation between a rig's clock and ROS time: offset and drift, estimated.

A driver reads its rig clock and the ROS clock at the same moment and publishes the pair
(docs/driver_contract.md, ``rig/clock``). Over a window of pairs (rig time s_i, ROS time
t_i) the relation is the least-squares line

    t = offset + (1 + drift) s,

fitted about the window's means (s - s_mean is small: no cancellation in the slope at
rig times of 1e5 s). ``drift`` is dimensionless (1e-6: one microsecond per second).
The residuals' standard deviation is the pairs' read jitter; the standard errors of the
line follow from it. :class:`ClockRelation` keeps a sliding window (``window`` pairs)
and refits on each pair (O(window): 200 pairs cost tens of microseconds).
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np

__all__ = ["ClockFit", "fit_clock", "ClockRelation"]


class ClockFit(NamedTuple):
    """ROS time = offset + (1 + drift) * rig time; ``jitter`` the residual std (s),
    ``offset_se`` and ``drift_se`` standard errors, ``n`` pairs, ``span`` (s) of rig time."""

    offset: float
    drift: float
    jitter: float
    offset_se: float
    drift_se: float
    n: int
    span: float

    def ros_time(self, rig_time: float) -> float:
        return self.offset + (1.0 + self.drift) * rig_time

    def rig_time(self, ros_time: float) -> float:
        return (ros_time - self.offset) / (1.0 + self.drift)


def fit_clock(rig, ros) -> ClockFit:
    """The least-squares line through pairs (rig_i, ros_i) (module docstring).

    One pair gives the offset with drift 0 (no slope is known: its standard error is
    inf); two or more pairs at distinct rig times give both.
    """
    s = np.asarray(rig, dtype=float)
    t = np.asarray(ros, dtype=float)
    if s.shape != t.shape or s.ndim != 1 or s.size == 0:
        raise ValueError("fit_clock needs equal, non-empty 1-D arrays of rig and ROS times")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(t))):
        raise ValueError("fit_clock: rig and ROS times must be finite")
    n = s.size
    s0, t0 = s[0], t[0]                     # reference: differences are exact-ish
    ds, dt = s - s0, t - t0
    ms, mt = ds.mean(), dt.mean()
    sxx = float(np.sum((ds - ms) ** 2))
    span = float(s.max() - s.min())
    if n < 2 or sxx == 0.0:
        offset = t0 + mt - (s0 + ms)
        return ClockFit(float(offset), 0.0, 0.0, math.inf, math.inf, n, span)
    slope = float(np.sum((ds - ms) * (dt - mt)) / sxx)
    # t = t0 + mt + slope (s - s0 - ms)  ->  offset = t0 + mt - slope (s0 + ms)
    offset = t0 + mt - slope * (s0 + ms)
    res = dt - mt - slope * (ds - ms)
    dof = n - 2
    jitter = float(math.sqrt(np.sum(res ** 2) / dof)) if dof > 0 else 0.0
    drift_se = jitter / math.sqrt(sxx) if dof > 0 else math.inf
    xbar = s0 + ms
    offset_se = (jitter * math.sqrt(1.0 / n + xbar * xbar / sxx)) if dof > 0 else math.inf
    return ClockFit(float(offset), slope - 1.0, jitter, offset_se, drift_se, n, span)


class ClockRelation:
    """The relation over the last ``window`` pairs, refitted as pairs arrive.

    ``add(rig, ros)`` keeps the pair (a pair whose rig time does not increase is
    refused: False); ``fit`` is the current :class:`ClockFit` or None before the first
    pair.
    """

    def __init__(self, window: int = 200):
        if isinstance(window, bool) or not isinstance(window, int) or window < 2:
            raise ValueError(f"window={window!r} is invalid: valid range is an integer >= 2")
        self.window = window
        self.pairs = deque(maxlen=window)
        self.fit: ClockFit | None = None

    def add(self, rig: float, ros: float) -> bool:
        if not (math.isfinite(rig) and math.isfinite(ros)):
            return False
        if self.pairs and rig <= self.pairs[-1][0]:
            return False
        self.pairs.append((rig, ros))
        s, t = zip(*self.pairs)
        self.fit = fit_clock(s, t)
        return True

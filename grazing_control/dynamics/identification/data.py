"""A recording as arrays, and its cut into free-flight arcs (docs/theory_identification.md).

Between two events (an impact, a controller's correction) the motion is one free-flight
arc, a closed-form function of its start (:func:`.model.free_flight`). An arc after an
impact starts on the wall, x = d, with v+ = -r v- (Eq. 1); an arc after a correction
starts where the previous one ended, with a free velocity (the correction); the first arc
starts free.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Recording", "Arcs", "RecordingError", "cut_arcs", "MIN_SAMPLES"]

#: Fewest samples of the state stream a fit accepts.
MIN_SAMPLES = 20


class RecordingError(ValueError):
    """The recording cannot be used (too short, non-finite, times not increasing...)."""


@dataclass(frozen=True)
class Recording:
    """A recorded motion.

    Attributes
    ----------
    t : (n,) sample times (seconds of the recording, increasing).
    x : (n,) measured positions.
    v : (n,) measured velocities, NaN where not measured (position-only sensor).
    cos_tau, sin_tau : (n,) the forcing's phase reference; sin_tau may be all NaN.
    impact_t : (m,) recorded impact times (empty: none recorded).
    impact_v_minus, impact_v_plus : (m,) recorded impact velocities (NaN: not recorded).
    corrections : (k,) times at which a velocity correction acted.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    cos_tau: np.ndarray
    sin_tau: np.ndarray
    impact_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    impact_v_minus: np.ndarray = field(default_factory=lambda: np.zeros(0))
    impact_v_plus: np.ndarray = field(default_factory=lambda: np.zeros(0))
    corrections: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self):
        n = np.asarray(self.t).size
        for name in ("t", "x", "v", "cos_tau", "sin_tau"):
            a = np.asarray(getattr(self, name), float).ravel()
            if a.size != n:
                raise RecordingError(f"{name} has {a.size} samples, t has {n}")
            object.__setattr__(self, name, a)
        for name in ("impact_t", "impact_v_minus", "impact_v_plus", "corrections"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), float).ravel())
        if n < MIN_SAMPLES:
            raise RecordingError(f"the state stream has {n} samples: need at least "
                                 f"{MIN_SAMPLES}")
        if not (np.all(np.isfinite(self.t)) and np.all(np.isfinite(self.x))
                and np.all(np.isfinite(self.cos_tau))):
            raise RecordingError("the state stream has non-finite times, positions or "
                                 "phase references")
        if not np.all(np.diff(self.t) > 0.0):
            raise RecordingError("the state stream's times are not strictly increasing")
        m = self.impact_t.size
        if self.impact_v_minus.size != m or self.impact_v_plus.size != m:
            raise RecordingError("impact times and velocities differ in number")
        if m and not (np.all(np.isfinite(self.impact_t)) and np.all(np.diff(self.impact_t) > 0)):
            raise RecordingError("the impact times are not finite and strictly increasing")

    @property
    def has_velocity(self) -> bool:
        return bool(np.any(np.isfinite(self.v)))

    def without_samples(self, drop) -> "Recording":
        """The recording less the samples where ``drop`` (a boolean per sample) is true."""
        k = ~np.asarray(drop, bool)
        return Recording(self.t[k], self.x[k], self.v[k], self.cos_tau[k], self.sin_tau[k],
                         self.impact_t, self.impact_v_minus, self.impact_v_plus,
                         self.corrections)

    def near(self, times, tolerance: float) -> np.ndarray:
        """Boolean per sample: within ``tolerance`` of one of ``times``."""
        times = np.sort(np.asarray(times, float))
        if times.size == 0:
            return np.zeros(self.t.size, bool)
        j = np.clip(np.searchsorted(times, self.t), 1, times.size)
        gap = np.minimum(np.abs(self.t - times[j - 1]),
                         np.abs(self.t - times[np.minimum(j, times.size - 1)]))
        return gap <= tolerance

    def window(self, t0: float, t1: float) -> "Recording":
        """The part with t0 <= t < t1 (events included likewise)."""
        s = (self.t >= t0) & (self.t < t1)
        i = (self.impact_t >= t0) & (self.impact_t < t1)
        c = (self.corrections >= t0) & (self.corrections < t1)
        return Recording(self.t[s], self.x[s], self.v[s], self.cos_tau[s], self.sin_tau[s],
                         self.impact_t[i], self.impact_v_minus[i], self.impact_v_plus[i],
                         self.corrections[c])


@dataclass(frozen=True)
class Arcs:
    """The cut: boundary b (b = 1..K-1) starts arc b; arc 0 starts at the first sample.

    Attributes
    ----------
    start : (K,) start times (boundary times; arc 0: t[0]).
    kind : (K,) 0 first arc, 1 after an impact, 2 after a correction.
    time_free : (K,) the boundary's time is a fit parameter.
    lower, upper : (K,) bounds of a free time (the samples around it).
    v_minus, v_plus : (K,) recorded impact velocities (NaN: none).
    sample_arc : (n,) arc of each sample.
    """

    start: np.ndarray
    kind: np.ndarray
    time_free: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    v_minus: np.ndarray
    v_plus: np.ndarray
    sample_arc: np.ndarray

    @property
    def count(self) -> int:
        return int(self.start.size)


def cut_arcs(t, impact_t, corrections, *, impact_v_minus=None, impact_v_plus=None,
             free_times=False, free_corrections=False) -> Arcs:
    """Arcs between the events after the first sample (before the last one).

    ``free_times``, ``free_corrections``: the impact (correction) times are estimates:
    each becomes a fit parameter bounded by the samples around it.
    """
    t = np.asarray(t, float)
    it = np.asarray(impact_t, float)
    vm = np.full(it.size, np.nan) if impact_v_minus is None else np.asarray(impact_v_minus, float)
    vp = np.full(it.size, np.nan) if impact_v_plus is None else np.asarray(impact_v_plus, float)
    ct = np.asarray(corrections, float)
    keep_i = (it > t[0]) & (it < t[-1])
    keep_c = (ct > t[0]) & (ct < t[-1])
    ev_t = np.concatenate([it[keep_i], ct[keep_c]])
    ev_k = np.concatenate([np.ones(keep_i.sum(), int), np.full(keep_c.sum(), 2)])
    ev_vm = np.concatenate([vm[keep_i], np.full(keep_c.sum(), np.nan)])
    ev_vp = np.concatenate([vp[keep_i], np.full(keep_c.sum(), np.nan)])
    order = np.argsort(ev_t, kind="stable")
    start = np.concatenate([[t[0]], ev_t[order]])
    kind = np.concatenate([[0], ev_k[order]])
    v_minus = np.concatenate([[np.nan], ev_vm[order]])
    v_plus = np.concatenate([[np.nan], ev_vp[order]])
    time_free = ((kind == 1) & bool(free_times)) | ((kind == 2) & bool(free_corrections))
    j = np.searchsorted(t, start, side="right")          # first sample after the event
    lower = t[np.maximum(j - 1, 0)]
    upper = t[np.minimum(j, t.size - 1)]
    sample_arc = np.searchsorted(start, t, side="right") - 1
    return Arcs(start, kind, time_free, lower, upper, v_minus, v_plus, sample_arc)

"""Switching the correction on safely: a capture rule and a gain ramp (issue 29 section 5).

Eq. 28 switched on at once from far away answers a large correction: with the least-noise
gains (|k| ~ 1e-2) it is small and the loop captures from 4.5e-2 in one step (issue 29),
but with the study's c2 = -1 the first pulse carries |k| |z - z**| ~ 5e-2, which a rig's
force limit may clip and which lands the state where the linear design says nothing
(docs/theory_capture.md). Two rules, each a pure callable ``switch(k, estimate) ->
factor`` in [0, 1] that scales the section's correction (the controller multiplies
Eq. 28 by it; :func:`grazing_control.dynamics.estimation.stream.simulate_stream` takes it as
``switch``):

:class:`CaptureRule`
    No correction until the estimate is within ``radius`` of the controlled orbit's
    Pi2 state z** (Euclidean in (dx, dv); for a model file's 2n coordinates the
    Euclidean norm of z - z** in (dx_0..dx_{n-1}, dv_0..dv_{n-1})) with a finite
    covariance; from then on the full correction (latched: a noisy excursion after
    capture does not switch it off).
    The default radius is CAPTURE_RADIUS sqrt(|Delta d|), inside the watchdog's
    excursion bound 15 sqrt(|Delta d|) (plant/watchdog.py). While it holds back it keeps
    the closest approach of the estimate (``closest``) and the sections held (``held``);
    :meth:`CaptureRule.news` says once when it has held CAPTURE_PATIENCE sections
    without the estimate coming within the radius (a free motion that does not pass
    near z**, the two-mass beam's case: it is never captured, docs/theory_capture.md).
:class:`GainRamp`
    The factor rises linearly from 1 / N to 1 over the first N sections after
    ``start`` (N = 1: at once).

:func:`free_approach` forecasts it from the model: where the free motion from X** leaves
the radius and how close it comes again after CAPTURE_PATIENCE periods (a line to log
where it does not come back, :meth:`FreeApproach.warning`).

:func:`capture_time` measures a run: the first section from which the plant keeps one
impact per period and stays within ``band`` of z** to the end of the run.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.params import ParameterError

__all__ = ["CAPTURE_RADIUS", "CAPTURE_PATIENCE", "CaptureRule", "GainRamp", "capture_time",
           "FreeApproach", "free_approach"]

#: The capture rule's radius in units of sqrt(|Delta d|) (docs/theory_capture.md).
CAPTURE_RADIUS = 5.0

#: Sections the rule may hold back before it says that the estimate has not come within
#: its radius: about 4x the longest wait measured where the free motion returns near
#: z** (27 periods, the 1-DOF study; 16, the two-mass chain; docs/theory_capture.md).
CAPTURE_PATIENCE = 100


class CaptureRule:
    """Switch on (factor 1, latched) once |z^ - z**| <= ``radius`` (module docstring)."""

    def __init__(self, target, radius: float):
        radius = float(radius)
        if not (math.isfinite(radius) and radius > 0.0):
            raise ParameterError(f"capture_radius={radius!r} is invalid: valid range is a "
                                 "finite capture_radius > 0")
        self.target = np.array(target, dtype=float)
        self.radius = radius
        self.on_at = None
        self.closest = math.inf     # the least |z^ - z**| of an estimate it judged
        self.held = 0               # sections held back (factor 0)
        self.forecast = None        # a line where the model's free motion stays away

    @classmethod
    def for_wall(cls, target, delta_d: float, scale: float = CAPTURE_RADIUS) -> "CaptureRule":
        """The rule with radius ``scale`` sqrt(|Delta d|)."""
        return cls(target, scale * math.sqrt(abs(delta_d)))

    def __call__(self, k: int, estimate) -> float:
        if self.on_at is None:
            z = np.asarray(estimate.z, dtype=float)
            if np.all(np.isfinite(z)) and np.all(np.isfinite(estimate.cov)):
                distance = _distance(z - self.target)
                self.closest = min(self.closest, distance)
                if distance <= self.radius:
                    self.on_at = int(k)
            if self.on_at is None:
                self.held += 1
        return 1.0 if self.on_at is not None else 0.0

    def news(self, k: int, patience: int = CAPTURE_PATIENCE):
        """What the call for section ``k`` changed, as (level, line) for a log, or None:
        ("info", ...) where it switched on at k, ("warning", ...) where it has just held
        ``patience`` sections without the estimate coming within the radius (once)."""
        if self.on_at == k:
            return ("info", f"capture: the estimate is within {self.radius:.4g} of the "
                            f"controlled orbit at section {k}: the correction from here on")
        if self.on_at is None and self.held == patience:
            return ("warning", f"capture: not captured: in {self.held} sections the "
                               f"estimate came no closer than {self.closest:.4g} to the "
                               f"controlled orbit (radius {self.radius:.4g}); the "
                               "correction stays off until it does: a free motion that "
                               "does not pass near the orbit is never captured by the rule "
                               "(docs/theory_capture.md)")
        return None

    def summary(self) -> str:
        """``captured_at=K`` (None: never), and while held back the closest approach."""
        if self.on_at is not None:
            return f"captured_at={self.on_at}"
        return (f"captured_at=None capture_closest={self.closest:.4g} "
                f"capture_radius={self.radius:.4g}")


def _distance(dz: np.ndarray) -> float:
    """|dz|: np.hypot for the 1-DOF (dx, dv) (bit for bit as before), the Euclidean norm
    of a model file's 2n coordinates (docs/theory_capture.md, n DOF)."""
    if dz.shape == (2,):
        return float(np.hypot(*dz))
    return float(np.linalg.norm(dz))


class GainRamp:
    """The factor min(1, (k - start + 1) / sections) from section ``start`` on."""

    def __init__(self, sections: int, start: int = 0):
        if isinstance(sections, bool) or int(sections) != sections or sections < 1:
            raise ParameterError(f"ramp_sections={sections!r} is invalid: valid range is an "
                                 "integer >= 1")
        self.sections, self.start = int(sections), int(start)

    def __call__(self, k: int, estimate=None) -> float:
        if k < self.start:
            return 0.0
        return min(1.0, (k - self.start + 1) / self.sections)


class FreeApproach(NamedTuple):
    """The free motion from ``start`` against the radius about z** (:func:`free_approach`):
    ``left`` the first period it is beyond the radius (None: never in the horizon),
    ``closest`` its least distance to z** over periods ``late`` .. ``periods``."""

    left: int | None
    closest: float
    late: int
    periods: int
    radius: float

    def warning(self) -> str | None:
        """A line for a log where the free motion leaves the radius and does not come
        back within it over periods ``late`` .. ``periods`` (a late switch-on's rule then
        waits in vain), else None."""
        if self.left is None or self.closest <= self.radius:
            return None
        return (f"capture: the model's free motion from X** leaves the radius "
                f"{self.radius:.4g} of the controlled orbit at period {self.left} and comes "
                f"no closer than {self.closest:.4g} in periods {self.late}-{self.periods}: "
                "switched on after it has left, the rule is not expected ever to switch on "
                "(docs/theory_capture.md)")


def free_approach(step, target, radius: float, start=None, late: int = CAPTURE_PATIENCE,
                  periods: int = 3 * CAPTURE_PATIENCE) -> FreeApproach:
    """Iterate the free map ``step(z) -> z`` (deviations from X**) ``periods`` periods
    from ``start`` (None: X**, z = 0, the simulator's start) and measure |z - z**|
    against ``radius`` (:class:`FreeApproach`). The rule's premise is that the free
    motion returns near z** (docs/theory_capture.md); the two-mass beam's does not."""
    target = np.asarray(target, dtype=float)
    z = np.zeros_like(target) if start is None else np.array(start, dtype=float)
    dist = [_distance(z - target)]
    for _ in range(periods):
        z = np.asarray(step(z), dtype=float)
        dist.append(_distance(z - target))
    beyond = [j for j, d in enumerate(dist) if not d <= radius]
    return FreeApproach(beyond[0] if beyond else None, min(dist[late:]), late, periods,
                        float(radius))


def capture_time(truth, impacts_per_period, target, band: float) -> int | None:
    """The first section k from which every later period has one impact and
    |z_j - z**| <= ``band`` (Euclidean) for all j >= k; None if the run ends outside."""
    truth = np.asarray(truth, dtype=float)
    dist = np.hypot(*(truth - np.asarray(target, dtype=float)).T)
    good = (dist <= band) & (np.asarray(impacts_per_period) == 1)
    bad = np.nonzero(~good)[0]
    k = 0 if bad.size == 0 else int(bad[-1]) + 1
    return k if k < truth.shape[0] else None

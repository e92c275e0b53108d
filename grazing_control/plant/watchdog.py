"""The realtime watchdog: when a paced loop is no longer controlling, stop actuating and say why.

A realtime scene can run open loop without any error: every answer misses its deadline
(or the simulator falls so far behind the wall clock that no answer can be on time), the
plant runs uncorrected, and the run still "finishes" (issue 27 §1: ``missed=1500
applied=0``, sample lag p99 75-250 s, reported ok). :class:`Watchdog` watches the loop,
sample by sample, and trips on the first of four conditions (each threshold 0 = off;
sim_node's parameters ``watchdog_*``, :data:`grazing_control.plant.settings.PARAMETERS`):

* **misses**: at least ``misses`` of the last ``window`` samples had no answer in time
  (a scheduled deadline missed, or, acting on arrival, no answer before the next sample
  went out). A miss is counted whether or not control is on: a controller that answers
  zero while it is off still has to answer in time, and a loop that cannot get its
  answers before control starts will not get them after.
* **pace**: over the last ``window`` samples the simulation advanced less than ``pace``
  times the requested rate: (t_k - t_{k-W}) / ((wall_k - wall_{k-W}) time_scale) <
  ``pace``, with wall_k the wall time sample k went out. The loop pins simulation time
  to the wall clock, so a machine that cannot keep up publishes each sample later and
  later and catches up in bursts at the rate it sustains: this ratio is that rate over
  the requested one.
* **lag**: a sample went out more than ``lag`` wall seconds after its simulation time
  (one stall of the process, or the accumulated lag of a slow pace on the wall clock).
  The realtime loop hands in the sample's lag with the longest pause of the plant's
  clock since the previous sample added
  (:meth:`grazing_control.plant.realtime.Realtime.publish_sample`): one stall; pauses
  spread over a run lower the pace instead (a ``time_scale`` 1 scene paused 464 times,
  1.117 s in all, over its 50 periods at idle and tripped on the lag when all its pauses
  counted; loaded, 1574 pauses of at most 43 ms, 1.54 s of them in one 9.4 s period,
  tripped it when a period's pauses counted).
* **excursion**: while the plant is being corrected (the last ``window`` samples each
  had a non-zero correction applied in time: control is on and past its capture
  transient), the Pi2 state is farther from the grazing point X** than ``excursion``
  sqrt(|Delta d|) (:func:`excursion_scale`). Near grazing the impacting 1/1 orbits lie
  at a distance from X** proportional to sqrt(|Delta d|), the square-root singularity of
  the impact map; measured with ``simulate`` and the exact map (samples 50..600 after
  control starts), in units of sqrt(|Delta d|), the same at Delta d = -1e-7, -5e-6 and
  -9e-6: the study's gains (c2 = -1) hold the orbit at 1.83, delay 5 or 6 (with their
  delay-aware c1) at 1.38, c2 = -0.5 at 2.82, -0.1 with delay 3 at 7.2, the rig's
  least-noise design (``grazing design --delta-d -5e-6 --optimize noise --delay 3``) at
  5.47; the rig's measurement noise spreads it by about 2e-5 = 0.01 sqrt(5e-6)
  (docs/nodes.md). The uncontrolled motion at Delta d = -5e-6 reaches 25 (median 6.0,
  samples 200..1500). The default 15 is twice the farthest controlled orbit above and
  inside the chaotic motion's reach: a state beyond it while corrections act means the
  control has lost the orbit (or never held it: a design whose loop is unstable). The
  capture transient is excluded by the window (the rig design's reaches 98 at -1e-7
  within its first 50 samples, 5.47 from then on). Without impacts near grazing
  (Delta d >= 0) or in an n-DOF scene the check is off.

A trip is final (:attr:`Watchdog.tripped`): the loop stops actuating (the safe state of
the rig: no correction acts, :class:`grazing_control.plant.realtime.Realtime`) and ends
the scene, and the node reports the trip's one-line reason (docs/nodes.md, "Watchdog").
The object is pure: it sees sample indices, simulation times and wall times handed in,
never a clock (tests/test_watchdog.py drives it with seeded random miss patterns against
a brute-force count).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

__all__ = ["WatchdogLimits", "Trip", "Watchdog", "excursion_scale", "TRIP_KINDS"]

#: What can trip the watchdog, in the order the checks run at a sample.
TRIP_KINDS = ("lag", "pace", "excursion", "misses")


@dataclass(frozen=True)
class WatchdogLimits:
    """The watchdog's thresholds (0 = that check off); see the module docstring.

    window : int
        Samples (forcing periods) of the sliding window, >= 1.
    misses : int
        Trip at this many samples without an answer in time within the window, >= 0.
    pace : float
        Trip when the simulation advanced less than this fraction of the requested
        time_scale over a full window, 0 <= pace <= 1.
    lag : float
        Trip when a sample goes out more than this many wall seconds late, >= 0.
    excursion : float
        Trip when, while corrections act, |X - X**| > excursion sqrt(|Delta d|)
        (:func:`excursion_scale`), >= 0.
    """

    window: int = 50
    misses: int = 25
    pace: float = 0.5
    lag: float = 1.0
    excursion: float = 15.0


class Trip(NamedTuple):
    """Why and where the watchdog tripped: ``kind`` (one of TRIP_KINDS), sample ``k``,
    its simulation time ``t``, and a one-line ``reason`` with the numbers."""

    kind: str
    k: int
    t: float
    reason: str


def excursion_scale(params) -> float | None:
    """sqrt(|Delta d|), the distance scale of the 1/1 orbits near grazing on Pi2 (module
    docstring); None for Delta d >= 0 (no impacting orbit born at grazing)."""
    dd = float(params.delta_d)
    return math.sqrt(-dd) if dd < 0.0 else None


class Watchdog:
    """The loop's watchdog (module docstring). Feed it every sample as it goes out
    (:meth:`sample`) and the outcome of every sample's answer (:meth:`outcome`); each
    returns the :class:`Trip` when that call tripped it, else None.

    Parameters
    ----------
    limits : WatchdogLimits
    scale : float or None
        sqrt(|Delta d|) of the scene (:func:`excursion_scale`); None: no excursion check.
    """

    def __init__(self, limits: WatchdogLimits, scale: float | None = None):
        self.limits = limits
        self.scale = scale
        self.tripped: Trip | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the window (the scene restarts at t = 0); a trip stays."""
        w = self.limits.window
        self.missed = deque()                 # sample indices of the misses in the window
        self.times = deque(maxlen=w + 1)      # (k, t, wall, time_scale) of the last samples
        self.acting = 0                       # consecutive samples with a correction acting
        self.t = 0.0

    @property
    def misses_in_window(self) -> int:
        """Samples without an answer in time among the last ``window``."""
        return len(self.missed)

    def _trip(self, kind: str, k: int, t: float, reason: str) -> Trip:
        self.tripped = Trip(kind, k, t, reason)
        return self.tripped

    def sample(self, k: int, t: float, wall: float, lag: float, time_scale: float,
               deviation=None):
        """Sample k (simulation time t) went out at wall time ``wall``, ``lag`` wall
        seconds after its simulation time; ``deviation`` its (x - x**, v - v**) (None:
        not checked). Checks lag, pace and excursion."""
        if self.tripped is not None:
            return None
        lim = self.limits
        self.t = t
        if lim.lag and lag > lim.lag:
            return self._trip("lag", k, t, f"sample {k} went out {lag:.3g} s after its "
                              f"simulation time (watchdog_lag {lim.lag:g} s): the simulator "
                              "cannot keep pace with the wall clock")
        if self.times and self.times[-1][3] != time_scale:
            self.times.clear()              # a new time_scale: a new pace window
        self.times.append((k, t, wall, time_scale))
        if lim.pace and len(self.times) == self.times.maxlen:
            k0, t0, wall0, _ = self.times[0]
            dwall = wall - wall0
            if dwall > 0.0:
                pace = (t - t0) / (dwall * time_scale)
                if pace < lim.pace:
                    rate = (k - k0) / dwall
                    return self._trip(
                        "pace", k, t, f"pace {pace:.3g} of time_scale {time_scale:g} over "
                        f"samples {k0}..{k} ({rate:.3g} periods per wall second; "
                        f"watchdog_pace {lim.pace:g}): the simulator cannot keep pace")
        if (lim.excursion and self.scale and deviation is not None
                and self.acting >= lim.window):
            dist = math.hypot(*deviation)
            bound = lim.excursion * self.scale
            if dist > bound:
                return self._trip(
                    "excursion", k, t, f"sample {k}: |X - X**| = {dist:.3g} beyond "
                    f"{lim.excursion:g} sqrt(|Delta d|) = {bound:.3g} (watchdog_excursion) "
                    "while corrections act: the control has lost the orbit")
        return None

    def outcome(self, k: int, missed: bool, acting: bool = False):
        """Sample k's answer: ``missed`` (not in time), else whether a non-zero
        correction acted (``acting``). Checks the misses in the window."""
        if self.tripped is not None:
            return None
        lim = self.limits
        self.acting = self.acting + 1 if (acting and not missed) else 0
        if missed:
            self.missed.append(k)
        while self.missed and self.missed[0] <= k - lim.window:
            self.missed.popleft()
        n = len(self.missed)
        if lim.misses and n >= lim.misses:
            return self._trip("misses", k, self.t, f"{n} of the last {lim.window} samples "
                              f"without an answer in time (watchdog_misses {lim.misses}): "
                              "the loop runs open loop")
        return None

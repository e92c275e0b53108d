"""The actuation engine: sections, deadlines, predictions and the count of what acted.

Any driver of the rig's actuator (docs/driver_contract.md, "The actuation engine") and
the simulator's realtime loop (:class:`grazing_control.plant.realtime.Realtime`) share
this timing logic; it holds no simulator and no clock of its own, and works in whatever
time unit its caller uses (rig seconds for a driver, model time for the simulator):

* **sections**: the caller announces section k (``section(k, key, t, start)``): its
  identity ``key`` (the sample's stamp for the simulator, the section index for a
  driver), its time t_k and the instant its command starts to act, t_k + delay (for a
  pulse of width w centred at the delay: t_k + delay - w/2, the simulator's
  :func:`grazing_control.dynamics.simulation.actuation.pulse_start`); ``start=None`` announces a
  section whose answer acts on arrival (the caller applies it; only the bookkeeping
  below is kept);
* **answers** (``command(key, value, predicted, ...)``): one that arrives before its
  section acted is kept for it; one for a section not yet announced (a stream
  controller may answer before its sample goes out) is kept, for the next two periods
  at most, and attached when the section is announced (``early_until``); one whose
  section already acted is **late**: counted and dropped, never applied late (its
  prediction, if newer than the one held, is kept for the next section); anything else
  (a second answer, one for an older or unknown section) is **ignored** and counted.
  Only the last ``memory`` (2) unanswered sections can be answered;
* **the deadline**: at the section's start (``pop_due(now)`` hands it over once
  ``now`` reaches it) ``act`` decides what acts: the answer (``applied``), or, when none
  arrived (``missed``) or the caller's injected loss dropped it (``lost``), the last
  applied answer's prediction for this section (on_miss = predict; counted as
  ``predicted``) or nothing (on_miss = drop);
* **the prediction** (:class:`Prediction`): each applied answer brings the controller's
  correction for the next section (NaN: none); it stands in for up to PREDICTION_HOLD
  consecutive missing answers (docs/nodes.md, "Scheduled actuation": near the
  controlled orbit, a fixed point of the controlled map on Pi2, the study's Eq. 28,
  the correction is the same at every section, so a miss costs nothing).

A watchdog (:mod:`grazing_control.plant.watchdog`) sits between ``pop_due`` and ``act``:
the caller shows it the section's outcome and, when it trips, acts nothing (the safe
state). :class:`RigSchedule` is a driver's use of it: sections identified by their
rig-clock time from the commands themselves (``rig/force_pulse``), the next section
expected one forcing period on, and the actuator's latency as the lead of each deadline.
"""

from __future__ import annotations

import math
from typing import Hashable, NamedTuple

__all__ = ["PREDICTION_HOLD", "COUNTS", "Prediction", "Section", "Answer", "Act",
           "ActuationSchedule", "RigSchedule", "PulseTrain", "slot"]

#: Consecutive missing answers a prediction stands in for.
PREDICTION_HOLD = 10
#: What the schedule counts: sections that acted with their answer, with a prediction in
#: its place, missed (no answer by the deadline), lost (dropped by the caller), answers
#: late (after their deadline) and ignored (stale, duplicate, foreign).
#: Sections without a deadline (``unarmed``: a stream's pre-roll) are counted apart.
COUNTS = ("applied", "predicted", "missed", "late", "lost", "ignored", "unarmed")


def slot(start: float, period: float, room: float) -> int | None:
    """The section k whose slot [k T, k T + room) holds ``start`` (a command's apply time,
    section 0 at time 0, ``period`` T), or None: before section 0, or between two slots.
    ``room`` is the latest start after its section that leaves a pulse its whole width
    (and the actuator's latency) within the period, T - w - L: a timed command
    (docs/driver_contract.md, "Off the rig's section") is the one of that section."""
    k = math.floor(start / period)
    if k < 0 or not start - k * period < room:
        return None
    return int(k)


class Prediction:
    """The last applied answer's prediction: ``last`` = (k, value) for section k, or None."""

    def __init__(self, hold: int = PREDICTION_HOLD):
        self.hold = hold
        self.last = None

    def remember(self, k: int, predicted: float) -> None:
        """Section k's answer acted: keep its prediction for section k + 1 (NaN: none;
        issue 16 §3)."""
        self.last = (k + 1, predicted) if math.isfinite(predicted) else None

    def remember_late(self, k: int, predicted: float) -> None:
        """Section k's answer came after its deadline: too late for its own section, but
        its prediction is the newest for the next one (unless a newer one is held)."""
        if (self.last is None or self.last[0] <= k) and math.isfinite(predicted):
            self.last = (k + 1, predicted)

    def stand_in(self, k: int) -> float | None:
        """The prediction that stands in for section k's missing answer, or None: the one
        made for a section at most ``hold - 1`` before k (an older one is not used)."""
        pred = self.last
        if pred is not None and 0 <= k - pred[0] < self.hold:
            return pred[1]
        return None


class Section(NamedTuple):
    """Section k: its identity, time and start, and its answer once it arrived."""

    k: int
    key: Hashable          # the identity an answer quotes
    t: float               # section time t_k (the caller's unit)
    start: float | None    # when its command starts to act (None: on arrival)
    sent: object = None    # the caller's record (the realtime loop: wall time it went out)
    width: float = 0.0     # the pulse width (a driver's; the simulator keeps its own)
    value: float | None = None    # the answer, None until it arrives
    predicted: float = math.nan   # the answer's prediction for section k + 1
    received: object = None       # the caller's record of the answer's arrival
    armed: bool = True            # False: no deadline (a pre-roll section; nothing acts)


class Answer(NamedTuple):
    """What :meth:`ActuationSchedule.command` did with an answer: ``outcome`` 'kept'
    (for its section's deadline), 'early' (for a section not yet announced), 'late',
    'unarmed' (its section has no deadline: dropped) or 'ignored'; ``section`` the section
    it answers (kept, late, unarmed), else None."""

    outcome: str
    section: Section | None = None


class Act(NamedTuple):
    """What acts at a section's start: ``value`` (0.0: nothing), ``outcome`` 'applied',
    'missed', 'lost' or 'unarmed' (no deadline: nothing acts), and ``substituted``: a
    prediction acted in the answer's place."""

    section: Section
    value: float
    outcome: str
    substituted: bool = False

    @property
    def code(self) -> int:
        """``rig/applied``'s code (docs/driver_contract.md): 0 answered in time, 1 a
        prediction stood in, 2 nothing acted (3, the safe state, is the caller's)."""
        return 0 if self.outcome == "applied" else 1 if self.substituted else 2


class ActuationSchedule:
    """Sections, their answers and deadlines, and the count of what acted (module
    docstring). ``counts`` may be a dict the caller shares (the realtime loop's
    ``stats``); ``prediction`` a :class:`Prediction` it shares."""

    def __init__(self, memory: int = 2, early: int = 2, prediction: Prediction | None = None,
                 counts: dict | None = None):
        self.memory = memory
        self.early_depth = early
        self.prediction = prediction if prediction is not None else Prediction()
        self.counts = counts if counts is not None else {}
        for name in COUNTS:
            self.counts.setdefault(name, 0)
        self.clear()

    def clear(self) -> None:
        """Forget every section and answer (a new run; the counts and the prediction are
        the caller's to reset)."""
        self.open = {}          # key -> Section announced with a start, not yet acted
        self.unanswered = {}    # key -> Section: the last `memory` announced, unanswered
        self.early = {}         # key -> (value, predicted, received): answers ahead
        self.latest = None      # key of the latest section announced
        self.early_until = -math.inf   # latest section time an early answer may quote

    # --------------------------------------------------------------- sections
    def section(self, k: int, key: Hashable, t: float, start: float | None, sent=None,
                early_until: float = math.inf, width: float = 0.0,
                armed: bool = True) -> Section:
        """Announce section k; an answer kept early is attached (``value`` set).

        ``early_until``: the latest section time an answer arriving before its section
        may quote (the realtime loop: two periods on). ``armed=False``: no deadline
        (module docstring): nothing acts at its start, whatever is answered.
        """
        sec = Section(k, key, t, start, sent, width, armed=armed)
        self.unanswered[key] = sec
        if len(self.unanswered) > self.memory:
            del self.unanswered[next(iter(self.unanswered))]
        if self.latest is None or key > self.latest:    # (a driver may announce an
            self.latest, self.early_until = key, early_until   # expected one later)
        kept = self.early.pop(key, None)
        if kept is not None:
            del self.unanswered[key]
            value, predicted, received = kept
            sec = sec._replace(value=value, predicted=predicted, received=received)
        if start is not None:
            self.open[key] = sec
        return sec

    def retime(self, key: Hashable, start: float) -> Section | None:
        """Section ``key``, open and unanswered, now starting at ``start`` (an answer's
        own start: a rig's command is timed output, docs/driver_contract.md), or None
        (not open or already answered: nothing changed)."""
        if key not in self.open or key not in self.unanswered:
            return None
        sec = self.open[key] = self.unanswered[key] = self.open[key]._replace(start=start)
        return sec

    def drop_late(self, key: Hashable) -> Section | None:
        """The answer of the unanswered section ``key`` came too late for its own start
        (a rig's command after its apply time): counted late, dropped; its section stays
        open for its deadline (a miss there, where the prediction made for it stands in:
        the caller keeps this answer's prediction for the next section once it acted)."""
        sec = self.unanswered.pop(key, None)
        if sec is not None:
            self.counts["late"] += 1
        return sec

    def waiting(self, key: Hashable) -> bool:
        """Whether the section ``key`` is announced and still unanswered."""
        return key in self.unanswered

    def claim(self, key: Hashable) -> Section | None:
        """The unanswered section ``key``, now answered (on arrival), or None."""
        return self.unanswered.pop(key, None)

    def keep_early(self, key: Hashable, t: float, value: float, predicted: float = math.nan,
                   received=None) -> bool:
        """Keep the answer of a section not yet announced (its key after the latest
        section's, its time ``t`` within ``early_until``), the last ``early`` of them:
        it acts as if it had arrived when its section is announced."""
        if self.latest is None or key <= self.latest or key in self.early:
            return False
        if t > self.early_until:
            return False
        self.early[key] = (value, predicted, received)
        if len(self.early) > self.early_depth:
            del self.early[next(iter(self.early))]
        return True

    # ---------------------------------------------------------------- answers
    def command(self, key: Hashable, value: float, predicted: float = math.nan,
                received=None, t: float = math.nan) -> Answer:
        """An answer to the section ``key`` (``t``: its section time, for an early
        answer's horizon): kept, early, late or ignored (module docstring)."""
        sec = self.unanswered.pop(key, None)
        if sec is None:
            if self.keep_early(key, t, value, predicted, received):
                return Answer("early")
            self.counts["ignored"] += 1
            return Answer("ignored")
        if not sec.armed:                 # no deadline there: dropped (counted at act)
            return Answer("unarmed", sec)
        if key not in self.open:          # its section acted already
            self.counts["late"] += 1
            self.prediction.remember_late(sec.k, predicted)
            return Answer("late", sec)
        sec = self.open[key] = sec._replace(value=value, predicted=predicted,
                                            received=received)
        return Answer("kept", sec)

    # -------------------------------------------------------------- deadlines
    def next_start(self) -> float:
        """The earliest start of an open section (inf: none)."""
        return min((s.start for s in self.open.values()), default=math.inf)

    def pop_due(self, now: float) -> Section | None:
        """The open section with the earliest start at or before ``now``, removed (the
        caller acts it with :meth:`act`, or not at all in the safe state), or None."""
        due = None
        for sec in self.open.values():
            if sec.start <= now and (due is None or sec.start < due.start):
                due = sec
        if due is not None:
            del self.open[due.key]
        return due

    def act(self, sec: Section, lost: bool = False, on_miss: str = "predict") -> Act:
        """What acts at section ``sec``'s start: its answer, or (missed, or ``lost``) the
        prediction (``on_miss`` = predict) or nothing; counted. An unarmed section:
        nothing, whatever was answered (``unarmed``)."""
        if not sec.armed:
            self.counts["unarmed"] += 1
            return Act(sec, 0.0, "unarmed")
        if sec.value is not None and not lost:
            self.counts["applied"] += 1
            self.prediction.remember(sec.k, sec.predicted)
            return Act(sec, sec.value, "applied")
        outcome = "missed" if sec.value is None else "lost"
        self.counts[outcome] += 1
        value = self.prediction.stand_in(sec.k) if on_miss == "predict" else None
        if value is None:
            return Act(sec, 0.0, outcome)
        self.counts["predicted"] += 1
        return Act(sec, value, outcome, substituted=True)

    def due(self, now: float, on_miss: str = "predict") -> list:
        """Every section due by ``now``, acted, in the order of their starts."""
        acts = []
        while (sec := self.pop_due(now)) is not None:
            acts.append(self.act(sec, on_miss=on_miss))
        return acts


class RigSchedule(ActuationSchedule):
    """A driver's schedule (docs/driver_contract.md): the commands of ``rig/force_pulse``
    in the rig clock (seconds).

    A command names its section by the section time t_k (``wrench.torque.y``); the
    driver does not compute sections itself. A section's index, its key, counts periods
    from the latest section announced: k = k_ref + round((t_k - t_ref) / period) (without
    a period yet: the next index for a later section time). A command for a section not
    yet known opens it when its start is still ahead by the actuator's ``lead`` (the time
    the hardware needs to take a timed output); one that comes after that is late
    (counted, dropped). Each section that acts announces the next one a ``period`` (the
    forcing period, from ``rig/phase``) on, with the same start offset and width, so that
    a command that never comes is a deadline miss there (the prediction acts), for as
    long as a prediction may stand in (PREDICTION_HOLD sections after the last answer).
    """

    def __init__(self, period: float = math.nan, lead: float = 0.0, **kwargs):
        super().__init__(**kwargs)
        self.period = period
        self.lead = lead

    def clear(self) -> None:
        super().clear()
        self.ref = None              # (k, t_k) of the latest section announced
        self.last_answered = None    # index of the last section answered in time
        self.acted = -math.inf       # index of the latest section acted

    def section(self, k, key, t, start, sent=None, early_until=math.inf, width=0.0):
        self.ref = (k, t)
        return super().section(k, key, t, start, sent, early_until, width)

    def index(self, t: float) -> int | None:
        """The section index of section time ``t`` (class docstring); None for a time
        before the latest section's without a period."""
        if self.ref is None:
            return 0
        k0, t0 = self.ref
        if self.period > 0.0:
            return k0 + round((t - t0) / self.period)
        return k0 if t == t0 else k0 + 1 if t > t0 else None

    def pulse(self, t: float, start: float, force: float, predicted: float, width: float,
              now: float) -> Answer:
        """A command (section time ``t``, ``start``, ``force``, ``predicted``, ``width``)
        received at rig time ``now`` (call :meth:`due` first): kept, late or ignored."""
        k = self.index(t)
        if k is None:
            self.counts["ignored"] += 1
            return Answer("ignored")
        known = k in self.unanswered
        if not known and self.latest is not None and k <= self.latest:
            return self.command(k, force, predicted, received=now)   # stale or duplicate
        if start - self.lead <= now:       # the contract: too late to be scheduled
            self.unanswered.pop(k, None)
            self.counts["late"] += 1
            self.prediction.remember_late(k, predicted)
            return Answer("late")
        if not known:
            self.section(k, k, t, start, width=width)
        elif k in self.open:               # expected: the command's own times rule
            sec = self.open[k]._replace(t=t, start=start, width=width)
            self.open[k] = self.unanswered[k] = sec
        return self.command(k, force, predicted, received=now)

    def due(self, now: float, on_miss: str = "predict") -> list:
        """Every section whose start is within ``lead`` of ``now``, acted; each announces
        the next section one period on (class docstring)."""
        acts = super().due(now + self.lead, on_miss)
        for act in acts:
            sec = act.section
            self.acted = max(self.acted, sec.k)
            if act.outcome == "applied":
                self.last_answered = sec.k
            nxt = sec.k + 1
            if (self.period > 0.0 and self.last_answered is not None
                    and nxt - self.last_answered <= PREDICTION_HOLD
                    and nxt not in self.open and nxt > self.acted):
                self.section(nxt, nxt, sec.t + self.period, sec.start + self.period,
                             width=sec.width)
        return acts


class PulseTrain:
    """The pulses that acted, as a force over time (an effort stream samples it).

    ``add(start, width, force)`` for each act; ``force(t)`` is the sum of the forces of
    the pulses with start <= t < start + width (0 between pulses); pulses that ended
    before ``t`` are forgotten, and counted in ``unsent`` when no ``force`` call fell
    inside them (a stream that stalled for longer than a pulse never carried it).
    """

    def __init__(self):
        self.pulses = []     # [start, end, force, carried]
        self.unsent = 0

    def add(self, start: float, width: float, force: float) -> None:
        if force != 0.0 and width > 0.0:
            self.pulses.append([start, start + width, force, False])

    def force(self, t: float) -> float:
        self.unsent += sum(1 for p in self.pulses if p[1] <= t and not p[3])
        self.pulses = [p for p in self.pulses if p[1] > t]
        total = 0.0
        for p in self.pulses:
            if p[0] <= t:
                p[3] = True
                total += p[2]
        return total

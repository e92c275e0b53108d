"""Realtime: simulation time paced to the wall clock, deadlines, corrections on schedule or on arrival.

Simulation time runs at ``time_scale`` times the wall clock: t = t0 + (wall - wall0)
time_scale. Samples go out when due and the period continues without waiting (its
uncorrected events are integrated when the sample goes out, so that the round trip of
the answer does not include that work). Two ways to act (docs/nodes.md, "Modes"):

* scheduled (``settings.scheduled``): the answer of sample k acts exactly at
  t_k + actuation_delay (+ jitter), the lockstep period bit for bit
  (:meth:`grazing_control.plant.engine.Engine.actuate`, docs/theory_delay.md), if it
  has arrived by then; otherwise the deadline is missed (counted and handed to the
  sink): the last answer's prediction acts in its place (``on_miss`` = predict) or
  nothing (drop), and the answer, when it comes, is dropped as late. The timing is
  the actuation engine's, :class:`grazing_control.plant.schedule.ActuationSchedule`
  (in simulation time, each sample a section keyed by its stamp), the one any rig
  driver uses;
* timed (a rig's command, docs/driver_contract.md, "Off the rig's section"): an answer
  may bring its own start (``answer(..., start=)``, simulation time: the command's apply
  time); its section's deadline moves there, the period is integrated up to it
  (:meth:`~grazing_control.plant.engine.Engine.begin_head` with the start given) and its
  pulse acts there (``Engine.actuate`` with the start given), the same flows as at the
  section's own instant. An answer whose start has passed when it arrives is late
  (counted, dropped). The next section's deadline, which a missing answer's prediction
  keeps, is the last applied answer's start one period on; an answer without a start
  (the rig's own section) acts at t_k + actuation_delay as above, bit for bit;
* on arrival: the correction acts at the simulation time of its arrival, splitting
  the period there (:meth:`~grazing_control.plant.engine.Engine.split`); it must answer
  one of the last two samples, once; an answer after the next sample went out is still
  applied (counted as late).

The node calls :meth:`Realtime.tick` when woken up, arms its timer with
:meth:`Realtime.wake_in`, and hands each answer to :meth:`Realtime.answer`.

Every sample and every answer's outcome (in time, or missed: a scheduled deadline
passed, or on arrival no answer before the next sample went out) is shown to the
:class:`~grazing_control.plant.watchdog.Watchdog`; when it trips, no correction acts any
more (the rig's safe state), the sink is told (``tripped``) and the scene ends.
"""

from __future__ import annotations

import math
import time

from grazing_control.plant.engine import Engine, Event
from grazing_control.plant.loop import Loop
from grazing_control.plant.schedule import ActuationSchedule, Section
from grazing_control.plant.watchdog import Watchdog, excursion_scale

__all__ = ["Realtime", "CLOCK_TICK", "MIN_TICK", "STREAM_TICK", "STALL_PAUSE"]

#: Longest wall time between two wake-ups (each publishes /clock), seconds.
CLOCK_TICK = 5e-3
#: Shortest timer period (an event already due is published at once), seconds.
MIN_TICK = 5e-5
#: Wall seconds the loop lets the events between two samples (the sensor stream, impacts,
#: Pi1) gather before it publishes them, each with its own stamp: a 200-samples-per-period
#: stream at time_scale 1000 (21,000 samples/s) woke the loop once per sample, which this
#: 2-core machine could not keep up with (91 of 106 periods/s). The Pi2 samples and the
#: actuation deadlines are still met on time; a stream sample goes out at most this late
#: (a rig's data acquisition delivers blocks too).
STREAM_TICK = 5e-4
#: Wall seconds a wake-up may come later than the loop asked, or a Pi2 sample go out later
#: than its time, before the plant's clock pauses for the lateness (:meth:`Realtime.resume`,
#: :meth:`Realtime._catch_up`): above how late the loop's samples
#: go out here (p99 0.35-0.47 ms in the T/200 scene under SCHED_FIFO, docs/benchmarks.md,
#: "The plant's clock paused"), well under an answer's budget (3 ms there).
STALL_PAUSE = 1e-3


class Realtime(Loop):
    """The realtime loop over an engine (see the module docstring)."""

    t0 = 0.0           # simulation time at wall time wall0
    wall0 = 0.0
    sample = None      # stamp key of the latest sample
    delay = 0.0        # scheduled: the current sample's delay (actuation_delay + jitter)
    stream_tick = STREAM_TICK   # wall s the stream's events gather (sim_node's stream_block)
    published = 0.0    # simulation time up to which the last wake-up published (progress)
    rel = None         # the current section's start after its sample, given by an answer
    offset = None      # the last applied answer's given start (None: t_k + delay's)
    late_prediction = None   # (k, prediction) of an answer late for its own start
    stall_pause = STALL_PAUSE   # wall s of lateness that pauses the plant (0: never)
    expected = None    # wall time of the wake-up asked for (expect), None: none pending
    began = None       # (wall, thread CPU time) the current wake-up began, None: asleep
    settled = -math.inf   # wall time of the last expect (a wake-up's work measured to it)
    #: the CPU time of the calling thread, seconds (a wake-up's work against its held time)
    cpu_clock = staticmethod(time.thread_time)
    paused = 0.0       # wall s the plant's clock has paused in all
    stall = 0.0        # the longest pause since the last Pi2 sample (the watchdog's lag)
    longest_pause = 0.0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # each sample a section keyed by its stamp (wall time it went out as ``sent``);
        # its answers, early ones included, and (scheduled) its deadline
        self.schedule = ActuationSchedule(prediction=self.prediction, counts=self.stats)
        self.queue = []        # the current period's events not yet published, in time order
        # the excursion check reads the 1-DOF (dx, dv): not an n-DOF model's z
        self._deviation = type(self.engine) is Engine and self.engine.section is None
        self._scaled = None     # the model the watchdog's excursion scale is for
        self.watchdog = Watchdog(self.settings.watchdog)
        self.timed = {}        # key -> start given by an answer kept early (timed)

    @property
    def progress(self) -> float:
        """The simulation time up to which everything due has been published: that of the
        last wake-up (:meth:`tick`), at most CLOCK_TICK of wall time behind a loop that
        keeps pace. A window's pace read from it is not quantised by the forcing period
        as the last sample's time is (ros.diagnostics.SceneWindow: at time_scale 250, a
        period is 37.7 ms of wall time, and a 0.25 s window read 6 or 7 periods, a pace of
        226 or 264, of a loop on pace)."""
        return self.published

    def now(self, wall: float | None = None) -> float:
        """Simulation time at wall time ``wall`` (default: now)."""
        wall = self.clock() if wall is None else wall
        return self.t0 + (wall - self.wall0) * self.settings.time_scale

    def expect(self, wake: float) -> None:
        """The node armed its wake-up ``wake`` wall seconds from now (:meth:`wake_in`, or
        sooner for a driver's sample), at the end of a wake-up: :meth:`resume` measures
        the next one's lateness from it. A wake-up held while it ran -- its wall time
        longer than the CPU time its thread used (:attr:`cpu_clock`) by more than
        ``stall_pause`` -- pauses the plant's clock for the difference, as a late one does
        (:meth:`resume`); its work itself is the plant's own time (a stop of this machine
        is not charged to the thread's CPU time: a busy loop's 4.1 ms gap of wall time
        used 0.04 ms of it, docs/benchmarks.md)."""
        wall = self.clock()
        if self.began is not None and self.stall_pause:
            held = (wall - self.began[0]) - (self.cpu_clock() - self.began[1])
            if held > self.stall_pause:
                self._pause(held)
        self.began, self.settled = None, wall
        self.expected = wall + wake

    def resume(self, wall: float, woke: bool = True) -> float:
        """The loop runs again at wall time ``wall``: woken (``woke``) or taking an answer
        between two wake-ups. Coming more than ``stall_pause`` wall seconds after the
        wake-up it asked for (:meth:`expect`), the simulator was held (the machine ran
        something else, or nothing: a virtual CPU stopped), so the plant did not run:
        its clock pauses for the lateness, wall0 moves on by it, and the simulation time
        at ``wall`` is that of the wake-up asked for. The pause is counted
        (``stats['paused']``, :attr:`paused` in all, :attr:`longest_pause`) and stays in
        the watchdog's lag of the next Pi2 sample when it is the longest since the last
        one (:meth:`publish_sample`), and the pace the watchdog and the diagnostics read
        falls by it. Without it the stall would be charged to the loop: the samples due
        in it go out at once, late, and a deadline in it passes before
        its sample's answer can come (docs/nodes.md, "A stall of the simulator").
        ``stall_pause`` 0: never (the plant's clock is the wall clock). Returns the
        pause, wall seconds (0.0: none)."""
        due = self.expected
        if woke and self.began is None:   # (called again by tick: the wake-up's start kept;
            # an answer taken in this wake-up may have re-armed: measured from there)
            self.began = (max(wall, self.settled), self.cpu_clock())
        if due is None or not self.stall_pause:
            return 0.0
        late = wall - due
        if late <= self.stall_pause:
            if woke:
                self.expected = None
            return 0.0
        self.expected = None
        self._pause(late)
        return late

    def _catch_up(self, sent: float, t: float) -> None:
        """The sample of simulation time ``t`` goes out at wall time ``sent``: more than
        ``stall_pause`` after its time on the plant's clock, the simulator fell behind
        inside a wake-up that began on time (a stop of this machine charged to the
        thread's CPU time, which :meth:`expect` cannot tell from work; a slow spell of the
        whole machine; its own work), and the plant's clock pauses for the sample's lag:
        the sample goes out at its own time, and its deadline keeps its budget. Without
        it such a sample went out 3.4-3.8 ms late with its deadline 3 ms after its time,
        a miss the simulator's (docs/benchmarks.md, "The simulator behind its sample").
        The wake-up's held time is measured from here on (no stall paused twice)."""
        if not self.stall_pause:
            return
        lag = self._lag(sent, t)
        if lag > self.stall_pause:
            self._pause(lag)
            if self.began is not None:
                self.began = (sent, self.cpu_clock())

    def _lag(self, sent: float, t: float) -> float:
        """Wall seconds the event of simulation time ``t`` went out (at ``sent``) after its
        time on the plant's clock (its pauses taken out)."""
        return sent - self.wall0 - (t - self.t0) / self.settings.time_scale

    def _pause(self, seconds: float) -> None:
        """The plant's clock pauses ``seconds`` of wall time (:meth:`resume`,
        :meth:`expect`): counted, told to the sink with the simulation time up to which
        everything had gone out."""
        self.wall0 += seconds
        self.paused += seconds
        self.longest_pause = max(self.longest_pause, seconds)
        self.stall = max(self.stall, seconds)
        self.stats["paused"] = self.stats.get("paused", 0) + 1
        self.sink.paused(self.published, seconds)

    def start(self) -> None:
        """Sample 0 at t = 0, now."""
        self.reset(self.engine.sample())

    def reset(self, ev: Event) -> None:
        """After ``engine.reset()``: t = 0 now, and its sample 0 ``ev`` goes out."""
        self.t0, self.wall0 = 0.0, self.clock()
        self.published = 0.0
        self.expected, self.began, self.stall = None, None, 0.0
        self.finished = False
        self.schedule.clear()
        self.rel = self.offset = self.late_prediction = None
        self.timed = {}
        self.watchdog = Watchdog(self.settings.watchdog)   # a new run: a new watchdog
        self._scaled = None
        # the stream's sample at t = 0 before sample 0, as each section's last stream
        # samples go out before its sample: emitted after it, the t = 0 sample waited in
        # the wake-up's block for the integration of period 0 (1.6 ms at T/200 x1000, on
        # the answer's path of section 0: docs/benchmarks.md, "Section 0")
        for e in self.engine.initial_states():
            self.emit(e)
        self.publish_sample(ev)

    def rebase(self) -> None:
        """Keep the simulation time continuous across a change of time_scale (call it
        before the new settings take effect)."""
        self.t0, self.wall0 = self.now(), self.clock()
        self.stall = 0.0

    def publish_sample(self, ev: Event) -> None:
        """Sample k goes out (as measured), then its uncorrected period is integrated (the
        period's events, 0.6-0.7 ms of CPU at the rig's 150 stream samples: integrated
        first, they made every sample that much late, docs/rig_scene.md); scheduled, only
        up to its actuation instant (Engine.begin_head: the rest is integrated once, with
        the answer, by Engine.actuate; a Hertz period costs ms)."""
        engine = self.engine
        schedule = self.schedule
        if not self.settings.scheduled and schedule.waiting(self.sample):
            # on arrival: the previous sample had no answer before this one (a miss)
            self.trip(self.watchdog.outcome(schedule.unanswered[self.sample].k, missed=True))
            if self.finished:
                return
        sent = self.clock()
        self._catch_up(sent, ev.t)
        self.sample = self.emit(engine.measured(ev))
        start = None                                     # on arrival: no deadline
        if self.settings.scheduled and hasattr(engine, "begin_head"):
            # sample k's actuation instant: its period up to there now, the rest with
            # the answer (Engine.begin_head: each piece integrated once)
            self.delay = engine.actuation_delay()
            given = self.timed.pop(self.sample, None)
            self.timed = {key: s for key, s in self.timed.items() if key > self.sample}
            self.rel = self.offset if given is None else given - ev.t
            if self.rel is None:
                start = ev.t + engine.actuation_start(self.delay)
                self.queue = engine.begin_head(self.delay)
            else:                                        # a start given (timed answers)
                start = ev.t + self.rel
                self.queue = engine.begin_head(self.delay, self.rel)
        else:
            self.queue = engine.begin_period(0.0)
            if self.settings.scheduled:
                self.delay = engine.actuation_delay()
                start = ev.t + engine.actuation_start(self.delay)
        # an answer may come before its sample, for the next two periods at most
        # the stream's pre-roll: the first sections have no deadline (settings.pre_roll)
        sec = schedule.section(engine.k, self.sample, ev.t, start, sent,
                               early_until=ev.t + 2.0 * engine.p.period + 1e-6,
                               armed=start is None or engine.k >= self.settings.pre_roll)
        # pace: how late the sample went out against its simulation time
        lag = self._lag(sent, ev.t)
        self.lags.append(lag)
        if self._deviation and engine.p is not self._scaled:   # the model (Delta d) changed
            self._scaled = engine.p
            self.watchdog.scale = excursion_scale(engine.p)
        # the watchdog's lag is against the wall clock: the longest pause of the plant
        # since the last sample counts there (one stall of the simulator); pauses spread
        # over a run, however many, are the pace's to judge, not the lag's (docs/nodes.md,
        # "A stall of the simulator")
        held, self.stall = self.stall, 0.0
        self.trip(self.watchdog.sample(engine.k, ev.t, sent, lag + held,
                                       self.settings.time_scale,
                                       (engine.dx, engine.dv) if self._deviation else None))
        if self.finished:
            return
        if sec.value is not None:                        # answered before it went out
            dv = sec.value
            self.latencies.append(sec.received - sent)
            self.sink.latency(sec.received - sent)
            if start is not None:                        # acts at its deadline
                return
            self.trip(self.watchdog.outcome(engine.k, missed=False, acting=dv != 0.0))
            if self.finished:
                return
            if engine.correction_lost():
                self.stats["lost"] += 1
            else:
                self.queue = engine.split(ev.t, dv)
                self.stats["applied"] += 1

    def pauses(self) -> str:
        """The plant's pauses (:meth:`resume`) for the summary line, when there were any."""
        if not self.stats.get("paused"):
            return ""
        return (f" paused={self.stats['paused']} paused_ms={self.paused * 1e3:.3f} "
                f"longest_pause_ms={self.longest_pause * 1e3:.3f}")

    def tick(self, wall: float | None = None):
        """A wake-up at wall time ``wall`` (default: now; the node reads it before it takes
        the answers that arrived, so that one arriving in between waits for the next
        wake-up instead of finding its deadline acted): publish what is due; the
        simulation time then, or None when over."""
        if self.finished:
            return None
        wall = self.clock() if wall is None else wall
        self.resume(wall)
        now = self.now(wall)
        self.advance(now)
        self.published = max(self.published, now)
        return None if self.finished else now

    def wake_in(self, now: float) -> float:
        """Wall seconds to the next wake-up after simulation time ``now``, within
        [MIN_TICK, CLOCK_TICK] (at least every CLOCK_TICK for /clock): at the next sample
        or actuation deadline exactly, at the next stream event no sooner than
        ``stream_tick`` (STREAM_TICK unless set) from now."""
        ts = self.settings.time_scale
        exact = min(self.engine.seg.te, self.schedule.next_start())
        due = exact
        if self.queue and self.queue[0].t < exact:
            due = min(exact, max(self.queue[0].t, now + self.stream_tick * ts))
        return min(max((due - now) / ts, MIN_TICK), CLOCK_TICK)

    def advance(self, now: float) -> None:
        """Publish everything due up to simulation time ``now``, actuating on schedule."""
        while not self.finished:
            q = self.queue
            start = self.schedule.next_start()
            due = start <= now
            i = 0
            while i < len(q) and (q[i].t < start if due else q[i].t <= now):
                self.emit(q[i])
                i += 1
            del q[:i]
            if due:
                self._actuate(self.schedule.pop_due(now))
                continue
            if now < self.engine.seg.te:
                self.published = max(self.published, now)
                return
            for ev in q:
                self.emit(ev)
            ev = self.next_sample()
            if ev is None:
                return
            self.publish_sample(ev)

    def answer(self, key: tuple, dv: float, predicted: float = math.nan,
               arrived: float | None = None, start: float | None = None) -> bool:
        """The correction ``dv`` answering the sample stamped ``key`` (with its
        prediction for the next sample, NaN: none), which arrived at wall time
        ``arrived`` (None: now); ``start``: scheduled, the simulation time its pulse
        starts, given (timed, module docstring; None: the section's own instant); True
        when the wake-up must be re-armed (a split or a new start may bring an event
        forward)."""
        if self.settings.scheduled:
            return self._answer_scheduled(key, dv, predicted, arrived, start)
        return self._on_arrival(key, dv)

    def _answer_scheduled(self, key: tuple, dv: float, predicted: float,
                          arrived: float | None = None, start: float | None = None) -> bool:
        """Scheduled actuation: keep the answer of the current sample for its deadline.

        The answer must arrive before the sample's actuation instant t_k + delay in
        simulation time; one that comes later is dropped and counted (its deadline was
        already reported as missed). Its arrival is ``arrived`` (the middleware's
        reception, sim_node.answer_port: the answers are taken at each wake-up, before
        what is due) or, without it, now (this runs); the loop advances to the arrival
        first, so that a deadline due before it is handled first and one due after it
        acts this answer, however late the loop took it. Its latency runs to its arrival.
        A ``start`` given moves its section's deadline there (:meth:`_retime`); True then
        (the wake-up is re-armed).
        """
        if self.finished:
            self.sink.ignored(f"stamp {key}: the scene is not running")
            return False
        wall = self.clock()
        self.resume(wall, woke=False)
        if arrived is not None:
            wall = min(arrived, wall)
        now = self.now(wall)
        self.advance(now)                # a deadline due before its arrival is handled first
        if self.finished:
            return False
        moved = self._retime(key, start, max(now, self.published), predicted)
        if moved is None:                # its start had passed: late
            self.sink.late(f"stamp {key}: its start {start!r} had passed at its arrival "
                           f"(simulation time {max(now, self.published)!r})")
            return False
        answer = self.schedule.command(key, dv, predicted, wall, key[0] + key[1] * 1e-9)
        if answer.outcome == "early" and start is not None:
            self.timed[key] = start
        if answer.outcome in ("early", "unarmed"):
            return moved
        if answer.outcome == "ignored":
            self.sink.ignored(f"stamp {key} answers none of the last two unanswered samples "
                              "(stale, duplicate or foreign)")
            return moved
        latency = wall - answer.section.sent
        self.latencies.append(latency)
        self.sink.latency(latency)
        if answer.outcome == "late":      # counted; its prediction kept if the newest
            self.sink.late(f"stamp {key} arrived {latency * 1e3:.3f} ms after its sample, "
                           "after its actuation time")
        return moved

    def _retime(self, key: tuple, start: float | None, now: float, predicted: float):
        """The current section ``key``, open and unanswered, starts at ``start`` (None:
        its own instant t_k + delay): its deadline moved, its period integrated again up
        to the new start (Engine.begin_head; the events after ``now``, those not yet
        published, replace the queue). True when it moved, False when nothing changed
        (another section, the same start), None when ``start`` is not after ``now``
        (the answer is late: counted, dropped, ActuationSchedule.drop_late)."""
        schedule, engine = self.schedule, self.engine
        sec = schedule.open.get(key)
        if sec is None or not schedule.waiting(key) or sec.k != engine.k:
            return False
        if start is None:                # back to its own instant
            if self.rel is None:
                return False
            start, rel = sec.t + engine.actuation_start(self.delay), None
        elif start == sec.start:
            return False
        else:
            rel = start - sec.t
        if start <= now:                 # its prediction: for the next section, once k acted
            schedule.drop_late(key)
            self.late_prediction = (sec.k, predicted)
            return None
        schedule.retime(key, start)
        self.rel = rel
        head = (engine.begin_head(self.delay) if rel is None else
                engine.begin_head(self.delay, rel))
        self.queue = [ev for ev in head if ev.t > now]
        return True

    def _actuate(self, sec: Section) -> None:
        """Sample k's actuation instant: its answer at t_k + delay; at a deadline miss or
        a lost answer the previous answer's prediction (on_miss = predict) or none
        (ActuationSchedule.act); the watchdog sees the outcome first."""
        if sec.armed:                    # (a pre-roll section has no outcome to judge)
            self.trip(self.watchdog.outcome(sec.k, missed=sec.value is None,
                                            acting=bool(sec.value)))
        if self.finished:
            return                       # the safe state: nothing acts
        lost = sec.value is not None and self.engine.correction_lost()
        act = self.schedule.act(sec, lost=lost, on_miss=self.settings.on_miss)
        if act.outcome == "missed":
            self.sink.miss(sec.k, sec.key, sec.start, self.clock() - sec.sent)
        if act.substituted:
            self.sink.substituted(sec.k, sec.key, act.value)
        rel = self.rel if sec.k == self.engine.k else None
        if act.outcome == "applied":     # the next section expected at the same start
            self.offset = rel
        if self.late_prediction is not None and self.late_prediction[0] == sec.k:
            self.prediction.remember_late(*self.late_prediction)
            self.late_prediction = None
        if rel is None:
            self.queue = self.engine.actuate(act.value, self.delay)
        else:                            # a start given by its answer (timed)
            self.queue = self.engine.actuate(act.value, self.delay, rel)

    def _on_arrival(self, key: tuple, dv: float) -> bool:
        """Apply a correction at the simulation time of its arrival.

        It must answer one of the last two samples, once: the latest (normal) or the
        one before, when the answer comes after the next sample went out (counted as
        late, applied all the same: the next opportunity). Anything else is ignored.
        """
        sec = self.schedule.claim(key)
        if sec is None and not self.finished and self.schedule.keep_early(
                key, key[0] + key[1] * 1e-9, dv, math.nan, self.clock()):
            return False
        if sec is None or self.finished:
            self.sink.ignored(f"stamp {key} answers none of the last two unanswered samples "
                              "(stale, duplicate or foreign)")
            return False
        wall = self.clock()              # the correction acts at this instant's sim time
        self.resume(wall, woke=False)
        now = self.now(wall)
        self.advance(now)
        if self.finished:
            return False
        if key != self.sample:
            self.stats["late"] += 1      # counted as a miss when the next sample went out
        else:
            self.trip(self.watchdog.outcome(self.engine.k, missed=False, acting=dv != 0.0))
            if self.finished:
                return False
        latency = wall - sec.sent
        self.latencies.append(latency)
        self.sink.latency(latency)
        if self.engine.correction_lost():
            self.stats["lost"] += 1
            return False
        self.queue = self.engine.split(now, dv)
        self.stats["applied"] += 1
        return True

"""What the lockstep and realtime loops share: the sink they publish to, their tallies.

A loop (:class:`grazing_control.plant.lockstep.Lockstep`,
:class:`grazing_control.plant.realtime.Realtime`) drives an
:class:`grazing_control.plant.engine.Engine` from the controller's answers and the wall
clock, and hands everything it produces to a :class:`Sink`: sim_node's sink publishes on
the topics of docs/nodes.md, a test's sink records. The loops read the wall clock only
through the ``clock`` they are given (``time.monotonic`` in the node, a fake in tests).
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from grazing_control.plant.engine import Engine, Event
from grazing_control.plant.schedule import PREDICTION_HOLD, Prediction

__all__ = ["Sink", "Loop", "PREDICTION_HOLD"]


class Sink(Protocol):
    """Where a loop's output goes (sim_node: topics and throttled log lines)."""

    def publish(self, ev: Event) -> tuple:
        """Publish ``ev``; return its stamp key (sec, nanosec), which answers quote."""

    def latency(self, seconds: float) -> None:
        """Wall seconds from publishing a sample to receiving (applying) its answer."""

    def miss(self, k: int, key: tuple, t: float, waited: float) -> None:
        """Sample k's answer had not arrived at its actuation time t (scheduled)."""

    def substituted(self, k: int, key: tuple, dv: float) -> None:
        """Sample k's answer was missing (miss, loss, timeout): ``dv``, a prediction,
        acted in its place (on_miss = predict)."""

    def paused(self, t: float, seconds: float) -> None:
        """Realtime: the plant's clock paused ``seconds`` of wall time for a stall of the
        simulator, everything up to simulation time t published before the pause and
        everything after it after (:meth:`.realtime.Realtime.resume`)."""

    def ignored(self, text: str) -> None:
        """An answer that answers no waiting sample."""

    def late(self, text: str) -> None:
        """An answer after its deadline (dropped)."""

    def timeout(self, text: str) -> None:
        """Lockstep: no answer within answer_timeout."""

    def warn(self, text: str) -> None:
        """Anything else worth a warning (new model parameters at a sample)."""

    def tripped(self, trip) -> None:
        """The watchdog tripped (:class:`grazing_control.plant.watchdog.Trip`): the loop
        has stopped actuating and the scene ends (``finish`` follows)."""

    def finish(self) -> None:
        """``max_periods`` periods have run."""


class Loop:
    """The tallies and the end of a run, common to both loops.

    ``stats``: corrections applied, answers late (after the next sample or their
    deadline), corrections lost (injected loss); ``latencies`` (wall seconds per
    answered sample) and ``lags`` (realtime: how late each sample went out against its
    simulation time).
    """

    def __init__(self, engine: Engine, sink: Sink, clock=time.monotonic):
        self.engine = engine
        self.sink = sink
        self.clock = clock
        self.stats = {"applied": 0, "late": 0, "lost": 0, "predicted": 0}
        self.prediction = Prediction()   # the last applied answer's, for the next sample
        self.latencies = []
        self.lags = []
        self.finished = False
        self.watchdog = None       # realtime: the plant.watchdog.Watchdog

    @property
    def settings(self):
        """The engine's current settings (a runtime parameter change replaces them)."""
        return self.engine.settings

    @property
    def progress(self) -> float:
        """The simulation time up to which the run has been published: the last sample's
        (lockstep: the next waits for its answer). The realtime loop refines it to its
        last wake-up (:attr:`Realtime.progress`)."""
        return self.engine.t

    def remember(self, k: int, predicted: float) -> None:
        """Sample k's answer was applied: keep its prediction for sample k + 1 (NaN:
        none; issue 16 §3)."""
        self.prediction.remember(k, predicted)

    def substitute(self, k: int, key: tuple) -> float:
        """Sample k's answer missed its deadline or was lost: with on_miss = predict the
        last applied answer's prediction (counted in ``predicted``), else 0.

        The prediction was made for the sample after that answer's; it stands in for up
        to PREDICTION_HOLD consecutive missing answers: near the controlled orbit (a
        fixed point of the controlled map, the study's Eq. 28 on Pi2) the correction is
        the same at every sample, so a second miss in a row costs nothing either. An
        older prediction is not used (no correction; plant.schedule.Prediction).
        """
        value = self.prediction.stand_in(k) if self.settings.on_miss == "predict" else None
        if value is None:
            return 0.0
        self.stats["predicted"] += 1
        self.sink.substituted(k, key, value)
        return value

    def emit(self, ev: Event) -> tuple:
        """Publish one event (counting impacts); its stamp key."""
        if ev.kind == "impact":
            self.engine.impacts += 1
        return self.sink.publish(ev)

    def next_sample(self):
        """End the period (pending parameters apply); the next sample, or None when done."""
        ev, warning = self.engine.end_period()
        if warning:
            self.sink.warn(warning)
        if self.engine.done:
            self.finish()
            return None
        return ev

    def finish(self) -> None:
        """The run is over (max_periods): no more samples."""
        self.finished = True
        self.sink.finish()

    def trip(self, trip) -> None:
        """The watchdog tripped: the safe state (no correction acts from now on: the
        scene ends here, every later answer is ignored), the sink told, the run over."""
        if trip is None or self.finished:
            return
        self.sink.tripped(trip)
        self.finish()

    def pauses(self) -> str:
        """The summary's words on the plant's pauses (realtime: Realtime.resume)."""
        return ""

    def summary(self, wall: float, counts: dict) -> str:
        """The run in one line: periods, impacts, corrections, then ``counts`` (what the
        node counted: missed, timeouts, ignored, malformed), the rate over ``wall``
        seconds, and the latency and sample lag percentiles in milliseconds."""
        k, stats = self.engine.k, self.stats
        text = (f"summary: periods={k} t={self.engine.t:.9g} impacts={self.engine.impacts} "
                f"applied={stats['applied']} late={stats['late']} "
                f"missed={counts['missed']} lost={stats['lost']} "
                f"predicted={stats['predicted']} "
                + (f"unarmed={stats['unarmed']} " if stats.get("unarmed") else "")
                + "".join(f"{name}={counts[name]} " for name in
                          ("timeouts", "ignored", "malformed"))
                + f"wall={wall:.3f}s rate={k / wall if wall > 0 else 0.0:.1f} periods/s"
                + self.pauses())
        for name, values in (("latency_ms", self.latencies), ("sample_lag_ms", self.lags)):
            if values:
                ms = np.asarray(values) * 1e3
                text += (f" {name} p50={np.percentile(ms, 50):.3f} "
                         f"p99={np.percentile(ms, 99):.3f} max={ms.max():.3f}"
                         + (f" n={ms.size}" if name == "latency_ms" else ""))
        trip = self.watchdog.tripped if self.watchdog is not None else None
        if trip is not None:
            text += f" watchdog={trip.kind} tripped_at={trip.k}"
        return text

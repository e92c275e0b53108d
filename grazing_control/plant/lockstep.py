"""Lockstep: one period per answer, the correction at t_k + actuation_delay (docs/nodes.md).

After publishing sample k the loop waits for the answer stamped with sample k's stamp
(any other is ignored and counted), applies it ``actuation_delay`` (+ the injected
jitter) after the sample, as ``simulate.period_step(..., delay=)`` (docs/theory_delay.md),
and integrates the period; after ``answer_timeout`` wall seconds without it, or when the
injected loss drops it, the last answer's prediction acts instead (``on_miss`` = predict)
or nothing (drop), counted. Deterministic: a lockstep run reproduces
:func:`grazing_control.dynamics.simulation.simulate.simulate` sample for sample, however long the
round trips take.
"""

from __future__ import annotations

import math

from grazing_control.plant.engine import Event
from grazing_control.plant.loop import Loop

__all__ = ["Lockstep"]


class Lockstep(Loop):
    """The lockstep loop over an engine (see the module docstring)."""

    waiting = None       # stamp key of the sample waiting for its answer, or None
    sent = 0.0           # wall time it was published

    def start(self) -> None:
        """Publish sample 0 (and the state stream's sample at t = 0) and wait for its
        answer."""
        self.reset(self.engine.sample())

    def reset(self, ev: Event) -> None:
        """After ``engine.reset()``: run again from its sample 0, ``ev``."""
        self.finished = False
        self.publish_sample(ev)
        for e in self.engine.initial_states():
            self.emit(e)

    def publish_sample(self, ev: Event) -> None:
        """Publish sample k (state before correction, as measured) and wait for its answer."""
        self.waiting = self.emit(self.engine.measured(ev))
        self.sent = self.clock()

    def answer(self, key: tuple, dv: float, predicted: float = math.nan,
               arrived: float | None = None) -> None:
        """The correction ``dv`` answering the sample stamped ``key``, with the
        correction ``predicted`` for the next sample (NaN: none); its arrival is not
        read (the period waits for it: no deadline)."""
        if self.finished or key != self.waiting:
            self.sink.ignored(f"stamp {key} does not answer the waiting sample {self.waiting}")
            return
        self.period(dv, answered=True, predicted=predicted)

    def check_timeout(self) -> None:
        """No answer within answer_timeout wall seconds: the period runs without one."""
        if (not self.finished and self.waiting is not None
                and self.clock() - self.sent > self.settings.answer_timeout):
            self.sink.timeout(f"sample {self.waiting}")
            self.period(0.0)

    def period(self, dv: float, answered: bool = False, predicted: float = math.nan) -> None:
        """Sample k's period with its correction acting at t_k + actuation_delay (+ jitter).

        No answer (timeout) or a lost one: the previous answer's prediction
        (on_miss = predict) or none. The next sample goes out first, so that the
        controller computes its answer while this period's state, crossings and impacts
        are published.
        """
        key, self.waiting = self.waiting, None
        engine = self.engine
        if answered and not engine.correction_lost():
            self.stats["applied"] += 1
            self.remember(engine.k, predicted)
        else:
            self.stats["lost"] += answered
            dv = self.substitute(engine.k, key)
        events = engine.begin_period(dv, engine.actuation_delay())
        ev, warning = engine.end_period()
        if warning:
            self.sink.warn(warning)
        done = engine.done
        if not done:
            self.publish_sample(ev)
        for e in events:
            self.emit(e)
        if done:
            self.finish()

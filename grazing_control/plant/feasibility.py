"""Can this realtime scene keep its budget here? The check before a realtime scene starts.

A realtime scene makes two demands of the machine (docs/nodes.md, "Watchdog and
feasibility"):

* **the answer budget**: a scheduled correction must arrive within the actuation delay
  delta of its sample, delta / time_scale wall seconds (the start of a pulse: delta - w/2;
  :meth:`grazing_control.plant.engine.Engine.actuation_start`); acting on arrival, before
  the next sample, T / time_scale. The controller's round trip is measured before the
  start (sim_node asks the controller's process a few times, ``ROUND_TRIPS``);
* **the simulation rate**: time_scale / T periods per wall second, each with its state
  stream (T / state_period samples), Pi1 crossing, impacts and Pi2 sample. What this
  machine sustains is measured by running the scene's own engine on a copy
  (:func:`sustained_rate`) for ``MEASURE_WALL`` wall seconds, every event handed to the
  node's serialiser.

:func:`check` compares them: **refuse** when the median round trip is at least the
budget (most answers would miss their deadline) or when the measured rate is below the
requested one (the scene would fall further behind the wall clock every period); **warn**
when the largest round trip reaches the budget, or when the rate is below RATE_MARGIN
times the requested one (the measurement is the simulation alone: publishing, the
middleware and the controller share the same CPUs), or when the controller's round trip
could not be measured. Each verdict is one line with the numbers. What is then done
with it is sim_node's ``feasibility`` parameter (refuse: exit status 2, warn, off); the
watchdog (:mod:`grazing_control.plant.watchdog`) covers what changes after the start.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

__all__ = ["Verdict", "answer_budget", "arrival_delay", "requested_rate", "sustained_rate",
           "check",
           "ROUND_TRIPS", "MEASURE_WALL", "RATE_MARGIN"]

#: Round trips to the controller's process measured before the start.
ROUND_TRIPS = 8
#: Wall seconds of the simulation-rate measurement (at most MEASURE_PERIODS periods).
MEASURE_WALL = 0.25
MEASURE_PERIODS = 2000
#: Warn below this multiple of the requested rate: the measurement is the simulation alone,
#: and the node publishing the rig scene (200 stream samples per period) sustained 116
#: periods/s where this measured 321 (ratio 2.8; load average 10 on 2 cores, sim_node at
#: time_scale 1e5 with the watchdog off, issue 27).
RATE_MARGIN = 3.0


class Verdict(NamedTuple):
    """``level``: 'ok', 'warn' or 'refuse'; ``line``: the numbers in one line;
    ``numbers``: the same as a dict (for the node's summary)."""

    level: str
    line: str
    numbers: dict


def arrival_delay(plant, gains, delays, numbers: dict) -> str | None:
    """Acting on arrival, an answer acts its round trip x time_scale (``delays``, model
    time) after its sample: a delay its gains were not designed for. The least delay at
    which each controller's (c1, c2) lose the controlled orbit at the plant's Delta d
    (:func:`grazing_control.dynamics.design.mismatch.delay_margin`), against the
    median and the largest of ``delays``: a warning when the slowest answers act beyond
    it (issue 30: the default realtime scene at x1000 lost its orbit in 4 of 4 runs,
    answers 0.35 time units late at the median, up to 1.5, against a margin of 0.44),
    else None. ``numbers`` gets the delays and the margin. Only a 1-DOF plant."""
    from grazing_control.dynamics.design.mismatch import delay_margin, largest_multiplier
    from grazing_control.oscillator.control import Gains
    from grazing_control.oscillator.params import OscillatorParams

    if not isinstance(plant, OscillatorParams) or not gains or len(delays) == 0:
        return None
    med, top = float(np.median(delays)), float(np.max(delays))
    numbers.update(arrival_delay_median=med, arrival_delay_max=top)
    for name, c1, c2 in gains:
        if largest_multiplier(plant, Gains(c1, c2, top)) < 1.0 \
                and largest_multiplier(plant, Gains(c1, c2, med)) < 1.0:
            continue
        # a delay of a period or more acts in the next period: the scan ends at T
        margin = delay_margin(plant, c1, c2, min(top, plant.period))
        numbers["delay_margin"] = margin
        held = (f"hold the orbit at Delta d = {plant.delta_d:.3g} for delays below "
                f"{margin:.3g}" if margin > 0.0 else
                f"do not hold the orbit at Delta d = {plant.delta_d:.3g} even acting at once")
        return (f"acting on arrival, the answers act {med:.3g} time units after their "
                f"sample at the median and {top:.3g} at the slowest (round trip x "
                f"time_scale), and {name}'s gains (c1={c1:.6g}, c2={c2:.6g}) {held}: "
                "lower time_scale, or schedule the corrections at a delay the gains are "
                "designed for (actuation:=scheduled, grazing design --delay)")
    return None


def answer_budget(settings, period: float) -> float:
    """Wall seconds an answer has: (actuation start) / time_scale when scheduled (delay,
    or delay - w/2 for a pulse of width w), T / time_scale on arrival."""
    if settings.scheduled:
        w = settings.pulse_width
        start = settings.actuation_delay if w == 0.0 else max(
            settings.actuation_delay - 0.5 * w, 0.0)
        return start / settings.time_scale
    return period / settings.time_scale


def requested_rate(settings, period: float) -> tuple:
    """(periods, events) per wall second the scene asks for: time_scale / T periods,
    each with T / state_period stream samples plus its Pi2 sample and Pi1 crossing
    (impacts not counted)."""
    periods = settings.time_scale / period
    per_period = 2.0 + (period / settings.state_period if settings.state_period > 0 else 0.0)
    return periods, periods * per_period


def sustained_rate(engine, emit=None, clock=time.perf_counter, wall: float = MEASURE_WALL,
                   periods: int = MEASURE_PERIODS) -> tuple:
    """(periods, events) per wall second that ``engine`` (a fresh copy of the scene's:
    it is advanced) produces here, each event handed to ``emit`` (the node's
    serialiser; None: not serialised), measured over ``wall`` seconds or ``periods``
    periods, whichever comes first. Uncorrected periods with the scene's actuation split
    (delay or pulse), as the realtime loop integrates them."""
    delay = engine.settings.actuation_delay
    emit = emit or (lambda ev: None)
    n = events = 0
    t0 = clock()
    while True:
        sample = engine.measured(engine.sample())
        emit(sample)
        batch = engine.begin_period(0.0)
        if delay > 0.0:             # the loop integrates the period, then from the actuation
            start = engine.t + engine.actuation_start(delay)
            batch = [ev for ev in batch if ev.t < start] + engine.actuate(0.0, delay)
        for ev in batch:
            emit(ev)
        events += len(batch) + 1
        engine.end_period()
        n += 1
        elapsed = clock() - t0
        if elapsed >= wall or n >= periods:
            break
    return n / elapsed, events / elapsed


def check(settings, period: float, round_trips, sustained: float | None,
          asked: int = 0, waited: float = 0.0, note: str | None = None, *,
          plant=None, gains=()) -> Verdict:
    """The verdict on a realtime scene (module docstring): ``round_trips`` the measured
    wall seconds (empty: no controller was measured), ``sustained`` the measured periods
    per wall second (None: not measured); ``asked`` requests sent to the controller over
    ``waited`` wall seconds (none answered: refused); ``note``: why the round trip was
    not measured (a warning). ``plant`` (1-DOF parameters) and ``gains`` ((controller,
    c1, c2) of this scene's controllers): acting on arrival, the delay the answers act
    at against the one their gains hold the orbit to (:func:`arrival_delay`)."""
    budget = answer_budget(settings, period)
    want, want_events = requested_rate(settings, period)
    numbers = {"budget_ms": budget * 1e3, "requested_periods_per_s": want,
               "requested_events_per_s": want_events}
    refuse, warn = [], []
    rt = np.asarray(list(round_trips), dtype=float)
    if rt.size:
        med, top = float(np.median(rt)), float(rt.max())
        numbers.update(round_trip_median_ms=med * 1e3, round_trip_max_ms=top * 1e3,
                       round_trips=int(rt.size))
        text = (f"the controller's round trip {med * 1e3:.3g} ms (median of {rt.size}, max "
                f"{top * 1e3:.3g} ms) against the answer budget {budget * 1e3:.3g} ms "
                + ("(actuation delay / time_scale)" if settings.scheduled else
                   "(period / time_scale)"))
        if med >= budget:
            refuse.append(text)
        elif top >= budget:
            warn.append(text)
    elif asked:
        refuse.append(f"the controller's process answered none of {asked} requests in "
                      f"{waited:.3g} s (answer budget {budget * 1e3:.3g} ms)")
    if note:
        warn.append(note)
    if rt.size and not settings.scheduled:
        text = arrival_delay(plant, gains, rt * settings.time_scale, numbers)
        if text:
            warn.append(text)
    if sustained is not None and math.isfinite(sustained):
        numbers["sustained_periods_per_s"] = sustained
        text = (f"this machine simulates {sustained:.4g} periods per wall second against the "
                f"{want:.4g} requested (time_scale {settings.time_scale:g}, "
                f"{want_events:.4g} events/s)")
        if sustained < want:
            refuse.append(text)
        elif sustained < RATE_MARGIN * want:
            warn.append(text + f", less than {RATE_MARGIN:g} times")
    if refuse:
        return Verdict("refuse", "infeasible realtime scene: " + "; ".join(refuse + warn),
                       numbers)
    if warn:
        return Verdict("warn", "realtime scene at its limit: " + "; ".join(warn), numbers)
    parts = [f"budget {budget * 1e3:.3g} ms"]
    if rt.size:
        parts.append(f"round trip median {numbers['round_trip_median_ms']:.3g} ms, max "
                     f"{numbers['round_trip_max_ms']:.3g} ms")
    if "sustained_periods_per_s" in numbers:
        parts.append(f"{sustained:.4g} periods/s sustained for {want:.4g} requested")
    return Verdict("ok", "realtime scene feasible: " + ", ".join(parts), numbers)

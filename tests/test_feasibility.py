"""plant.feasibility: the check before a realtime scene starts (issue 27 §1): the answer
budget, the requested rate, the verdicts with their numbers, and the measured rate of
the scene's own engine (no ROS)."""

from __future__ import annotations

import pytest

from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine
from grazing_control.plant.feasibility import (RATE_MARGIN, answer_budget, check,
                                               requested_rate, sustained_rate)
from grazing_control.plant.settings import settings_from_values

P = OscillatorParams(delta_d=-5e-6)
RIG = dict(delta_d=-5e-6, mode="realtime", time_scale=1000.0, state_period=0.0471,
           sensor_noise=1e-4, sensor_velocity=False, pulse_width=0.1, actuation_delay=3.0)


def settings(**kw):
    return settings_from_values({**RIG, **kw})


def test_the_budget_is_the_delay_or_the_period_over_time_scale():
    assert answer_budget(settings(), P.period) == pytest.approx(2.95e-3)   # (3 - 0.05)/1000
    s = settings(pulse_width=0.0)
    assert answer_budget(s, P.period) == pytest.approx(3e-3)
    s = settings(pulse_width=0.0, actuation_delay=0.0, actuation="on_arrival")
    assert answer_budget(s, P.period) == pytest.approx(P.period / 1000.0)


def test_the_requested_rate_counts_the_stream():
    periods, events = requested_rate(settings(), P.period)
    assert periods == pytest.approx(1000.0 / P.period)                    # 106.2
    assert events == pytest.approx(periods * (2.0 + P.period / 0.0471))    # 21,440


@pytest.mark.parametrize("trips, sustained, level, words", [
    ([1e-3] * 8, 1000.0, "ok", "feasible"),
    ([1e-3] * 7 + [4e-3], 1000.0, "warn", "max 4 ms"),
    ([3e-3] * 8, 1000.0, "refuse", "round trip 3 ms (median of 8"),
    ([1e-3] * 8, 150.0, "warn", "150 periods per wall second against the 106.2"),
    ([1e-3] * 8, 100.0, "refuse", "100 periods per wall second against the 106.2"),
    ((), 1000.0, "ok", "feasible"),
])
def test_verdicts_name_their_numbers(trips, sustained, level, words):
    v = check(settings(), P.period, trips, sustained)
    assert v.level == level and words in v.line, v.line
    assert v.numbers["budget_ms"] == pytest.approx(2.95)
    assert "\n" not in v.line


def test_a_controller_that_answers_nothing_is_refused():
    v = check(settings(), P.period, [], None, asked=1, waited=5.0)
    assert v.level == "refuse" and "answered none of 1 requests in 5 s" in v.line


def test_a_round_trip_not_measured_is_a_warning_naming_why():
    v = check(settings(), P.period, [], 1000.0, note="no controller found")
    assert v.level == "warn" and v.line.endswith("no controller found")


def test_the_measured_rate_runs_the_scenes_engine_and_hands_over_every_event():
    s = settings(time_scale=1000.0)
    seen = []
    periods, events = sustained_rate(Engine(s), seen.append, periods=40, wall=60.0)
    # 40 periods: each its Pi2 sample, ~200 stream samples, a Pi1 crossing, impacts
    pi2 = [e for e in seen if e.kind == "pi2"]
    assert len(pi2) == 40 and [e.t for e in pi2] == pytest.approx(
        [k * P.period for k in range(40)])
    assert events / periods == pytest.approx(len(seen) / 40)
    assert sum(e.kind == "state" for e in seen) == pytest.approx(40 * P.period / 0.0471,
                                                                 abs=41)
    assert periods > 0 and RATE_MARGIN >= 1.0


#: The default realtime scene's gains (config/controller.yaml: c2 = -1, c1 degenerate).
DEFAULT_GAINS = [("/controller_node", -1.0206014555435567, -1.0)]


@pytest.mark.parametrize("scale, trips_ms, warned", [
    (1000.0, [0.35] * 7 + [0.85], True),     # the slowest act at 0.85 > 0.441
    (1000.0, [0.3] * 8, False),              # all within the margin
    (100.0, [0.35] * 7 + [0.85], False),     # a tenth of the delay
])
def test_acting_on_arrival_the_answers_delay_is_checked_against_the_gains(
        scale, trips_ms, warned):
    """Acting on arrival, an answer acts its round trip x time_scale after its sample, a
    delay its gains were not designed for: the check warns when the slowest act beyond
    the least delay at which the gains lose the orbit at the plant's Delta d (0.441 for
    the default gains at -5e-6), and names it; a scheduled scene is not concerned (its
    answers act at the designed delay, or miss)."""
    s = settings(pulse_width=0.0, actuation_delay=0.0, actuation="on_arrival",
                 time_scale=scale, state_period=0.0)
    v = check(s, P.period, [t * 1e-3 for t in trips_ms], 1e5, plant=P, gains=DEFAULT_GAINS)
    assert (v.level == "warn") is warned, v.line
    assert v.numbers["arrival_delay_max"] == pytest.approx(max(trips_ms) * 1e-3 * scale)
    if warned:
        assert "delays below 0.441" in v.line and "actuation:=scheduled" in v.line, v.line
        assert v.numbers["delay_margin"] == pytest.approx(0.4413, abs=2e-4)
    scheduled = check(settings(), P.period, [t * 1e-3 for t in trips_ms], 1e5, plant=P,
                      gains=DEFAULT_GAINS)
    assert "arrival_delay_max" not in scheduled.numbers


def test_the_arrival_check_caps_its_scan_at_a_period_and_names_gains_that_never_hold():
    """Round trips of absurd length (a stalled controller: 1e300 time units) scan the
    delays up to a period only, and gains that lose the orbit even acting at once are
    named as such, not with a margin of 0."""
    from grazing_control.plant.feasibility import arrival_delay

    numbers = {}
    line = arrival_delay(P, DEFAULT_GAINS, [0.3, 1e300], numbers)
    assert numbers["delay_margin"] == pytest.approx(0.4413, abs=2e-4) and "below 0.441" in line
    line = arrival_delay(P, [("/c", 1e6, -1e6)], [0.1, 0.2], {})
    assert "do not hold the orbit at Delta d = -5e-06 even acting at once" in line, line
    assert arrival_delay(P, [], [0.3, 9.0], {}) is None

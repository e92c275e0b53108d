"""The actuation engine (plant/schedule.py) as a specification, and against a brute force.

The first tests state the rules of docs/driver_contract.md ("The actuation engine") one
by one on a schedule driven by hand; ``test_random_arrivals_against_a_brute_force``
drives it with thousands of seeded random arrival times and checks every section's
outcome against a few lines that decide, from the whole list of arrivals at once, which
answer acts at each section. The realtime loop that uses it is tests/test_plant_loops.py
(bit for bit against lockstep).
"""

import math

import numpy as np
import pytest

from grazing_control.plant.schedule import (COUNTS, PREDICTION_HOLD, ActuationSchedule,
                                            Prediction, PulseTrain, RigSchedule)

NAN = math.nan
T, D = 1.0, 0.6          # section period and delay of the hand-driven schedule


def announce(s, k, early=True):
    """Section k at t = k T acting at k T + D, early answers up to two periods on."""
    return s.section(k, k, k * T, k * T + D, sent=k * T,
                     early_until=k * T + 2 * T + 1e-6 if early else -math.inf)


def answered_first():
    """A schedule whose section 0 acted with its answer 0.5, predicting 0.25 for 1."""
    s = ActuationSchedule()
    announce(s, 0)
    s.command(0, 0.5, 0.25)
    s.due(D)
    return s


def test_an_answer_in_time_acts_at_its_start_and_brings_its_prediction():
    s = ActuationSchedule()
    announce(s, 0)
    assert s.next_start() == D
    assert s.command(0, 0.5, 0.25, received=0.1).outcome == "kept"
    assert s.pop_due(D - 1e-9) is None            # not yet
    (act,) = s.due(D)
    assert (act.value, act.outcome, act.substituted, act.code) == (0.5, "applied", False, 0)
    assert s.prediction.last == (1, 0.25)
    assert s.next_start() == math.inf and s.due(10.0) == []
    assert s.counts == dict.fromkeys(COUNTS, 0) | {"applied": 1}


def test_a_miss_is_covered_by_the_prediction_for_up_to_the_hold():
    s = answered_first()
    acts = []
    for k in range(1, PREDICTION_HOLD + 3):
        announce(s, k)
        acts += s.due(k * T + D)
    assert [a.value for a in acts] == [0.25] * PREDICTION_HOLD + [0.0, 0.0]
    assert [a.code for a in acts] == [1] * PREDICTION_HOLD + [2, 2]
    assert all(a.outcome == "missed" for a in acts)
    assert (s.counts["missed"], s.counts["predicted"]) == (PREDICTION_HOLD + 2, PREDICTION_HOLD)


def test_on_miss_drop_acts_nothing_and_a_nan_prediction_is_none():
    s = answered_first()
    announce(s, 1)
    (act,) = s.due(T + D, on_miss="drop")
    assert (act.value, act.substituted) == (0.0, False) and s.counts["predicted"] == 0
    announce(s, 2)
    s.command(2, 0.5, NAN)                      # answered, no prediction
    s.due(2 * T + D)
    announce(s, 3)
    assert s.due(3 * T + D)[0].value == 0.0


def test_a_lost_answer_is_counted_and_the_prediction_stands_in():
    s = answered_first()
    announce(s, 1)
    s.command(1, 0.7, 0.3)
    act = s.act(s.pop_due(T + D), lost=True)
    assert (act.value, act.outcome, act.substituted) == (0.25, "lost", True)
    assert s.counts["lost"] == 1 and s.counts["applied"] == 1
    assert s.prediction.last == (1, 0.25)     # a lost answer brings no prediction


def test_a_late_answer_is_dropped_counted_and_its_prediction_serves_the_next_section():
    s = answered_first()
    announce(s, 1)
    assert s.due(T + D)[0].value == 0.25          # missed: predicted
    answer = s.command(1, 0.9, 0.4)               # after its start
    assert answer.outcome == "late" and answer.section.k == 1
    assert s.counts["late"] == 1 and s.prediction.last == (2, 0.4)
    assert s.command(1, 0.9, 0.4).outcome == "ignored"     # once
    announce(s, 2)
    assert s.due(2 * T + D)[0].value == 0.4


def test_a_late_answer_never_replaces_a_newer_prediction():
    p = Prediction()
    p.remember(5, 1.0)                    # for section 6
    p.remember_late(4, 2.0)               # section 4's, for 5: older
    assert p.last == (6, 1.0)
    p.remember_late(6, NAN)               # no prediction: nothing changes
    assert p.last == (6, 1.0)
    p.remember_late(6, 3.0)
    assert p.last == (7, 3.0)
    assert p.stand_in(6) is None and p.stand_in(7) == 3.0
    assert p.stand_in(7 + PREDICTION_HOLD - 1) == 3.0 and p.stand_in(7 + PREDICTION_HOLD) is None


def test_an_unarmed_section_acts_nothing_whatever_is_answered_and_is_no_miss():
    # a stream's pre-roll (settings.pre_roll): no deadline at section 0
    s = ActuationSchedule()
    s.section(0, 0, 0.0, D, sent=0.0, early_until=2 * T, armed=False)
    answer = s.command(0, 0.5, 0.25)                # in time or not: dropped
    assert answer.outcome == "unarmed" and answer.section.k == 0
    (act,) = s.due(D)
    assert (act.value, act.outcome, act.substituted, act.code) == (0.0, "unarmed", False, 2)
    assert s.prediction.last is None                # its prediction stands in for nothing
    assert s.counts == dict.fromkeys(COUNTS, 0) | {"unarmed": 1}
    # unanswered, it is no miss either; a late answer to it is neither late nor ignored
    s.section(1, 1, T, T + D, sent=T, early_until=3 * T, armed=False)
    (act,) = s.due(T + D)
    assert act.outcome == "unarmed" and s.counts["missed"] == 0
    assert s.command(1, 0.5).outcome == "unarmed"   # after its start: not late either
    assert s.counts["late"] == 0 and s.counts["ignored"] == 0
    # the first armed section misses as any other
    announce(s, 2)
    assert s.due(2 * T + D)[0].outcome == "missed" and s.counts["missed"] == 1


def test_duplicates_foreign_and_stale_answers_are_ignored():
    s = ActuationSchedule()
    assert s.command(0, 0.1).outcome == "ignored"          # before any section
    announce(s, 0)
    assert s.command(0, 0.1).outcome == "kept"
    assert s.command(0, 0.2).outcome == "ignored"          # a second answer
    assert s.command(-3, 0.2, t=-3.0).outcome == "ignored"  # foreign (older)
    for k in (1, 2, 3):
        s.due(k * T)
        announce(s, k)
    assert s.command(1, 0.2).outcome == "ignored"          # three sections back
    assert s.command(2, 0.2).outcome == "late"             # the one before: late
    assert s.counts["ignored"] == 4 and s.counts["late"] == 1


def test_an_early_answer_is_kept_for_two_periods_and_acts_when_its_section_comes():
    s = ActuationSchedule()
    announce(s, 0)
    assert s.command(1, 0.3, 0.1, received=0.5, t=1.0).outcome == "early"
    assert s.command(2, 0.4, 0.2, received=0.6, t=2.0).outcome == "early"
    assert s.command(3, 0.5, t=3.0).outcome == "ignored"   # beyond two periods
    assert s.command(1, 0.9, t=1.0).outcome == "ignored"   # kept once
    s.due(D)
    sec = announce(s, 1)
    assert (sec.value, sec.predicted, sec.received) == (0.3, 0.1, 0.5)
    assert s.command(1, 0.9).outcome == "ignored"          # already answered
    assert s.due(T + D)[0].value == 0.3
    assert announce(s, 2).value == 0.4
    assert announce(s, 3, early=False).value is None


def test_on_arrival_sections_keep_the_bookkeeping_only():
    s = ActuationSchedule()
    s.section(0, 0, 0.0, None, sent=0.0, early_until=2.0)
    assert s.next_start() == math.inf and s.waiting(0)
    assert s.claim(0).k == 0 and not s.waiting(0) and s.claim(0) is None


def reference(sections, arrivals, hold=PREDICTION_HOLD):
    """Brute force: what acts at each section, from the whole list of arrivals.

    ``arrivals``: (time, key, value, predicted) sorted by time; sections k = 0..n-1 at
    k T acting at k T + D. An answer is taken when it is the first of its key and
    arrives in [t_k - 2 T, start_k), after the first section went out (before t_k:
    early). After start_k it is late while section k is still remembered: until a later
    section j went out while a section i between them (k < i < j) was waiting (out,
    without an early answer, not answered by t_j); otherwise ignored. Predictions: from
    each applied answer, and from a late one if not older than the one held.
    """
    latest = lambda a: min(math.floor(a / T), sections - 1)   # the section out at a
    answered, taken, late = {}, {}, []     # answered: key -> arrival (early: -inf)

    def remembered(k, now):
        return not any(answered.get(i, math.inf) > j * T
                       for j in range(k + 1, now + 1) for i in range(k + 1, j))

    for a, key, value, pred in arrivals:
        if key in answered or a < 0.0:
            continue
        now = latest(a)
        if a < key * T + D and 0 <= key - now <= 2:
            answered[key] = a if key == now else -math.inf
            taken[key] = (value, pred)
        elif a >= key * T + D and key >= 0 and remembered(key, now):
            answered[key] = a
            late.append((a, key, pred))
    out, last = [], None
    events = sorted([(k * T + D, 0, k, None) for k in range(sections)]
                    + [(a, 1, k, p) for a, k, p in late])
    for _, kind, k, pred in events:
        if kind == 1:
            if math.isfinite(pred) and (last is None or last[0] <= k):
                last = (k + 1, pred)
        elif k in taken:
            out.append((taken[k][0], "applied"))
            last = (k + 1, taken[k][1]) if math.isfinite(taken[k][1]) else None
        elif last is not None and 0 <= k - last[0] < hold:
            out.append((last[1], "predicted"))
        else:
            out.append((0.0, "missed"))
    return out, len(late), len(taken)


def drive(sections, arrivals):
    """The schedule driven as the realtime loop does: in time order, a deadline due
    before an answer at the same instant, a section out before its answers."""
    s = ActuationSchedule()
    out = []
    timeline = sorted([(k * T, 0, k) for k in range(sections)]
                      + [(k * T + D, 1, k) for k in range(sections)]
                      + [(a, 2, i) for i, (a, *_) in enumerate(arrivals)])
    for when, kind, i in timeline:
        if kind == 0:
            announce(s, i)
        elif kind == 1:
            act = s.act(s.pop_due(when))
            out.append((act.value, "predicted" if act.substituted else act.outcome))
        else:
            _, key, value, pred = arrivals[i]
            s.command(key, value, pred, received=when, t=key * T)
    return out, s.counts


@pytest.mark.parametrize("seed", range(6))
def test_random_arrivals_against_a_brute_force(seed):
    """Thousands of answers: most in time, some late, early, duplicated, foreign."""
    rng = np.random.default_rng(seed)
    n = 400
    arrivals = []
    for k in range(n):
        for _ in range(rng.integers(0, 3)):               # 0, 1 or 2 answers
            a = k * T + rng.exponential(0.5) - rng.choice([0.0, 1.5], p=[0.8, 0.2])
            arrivals.append((a, k, float(rng.normal()),
                             float(rng.normal()) if rng.random() < 0.8 else NAN))
        if rng.random() < 0.05:                           # foreign: an unknown key
            arrivals.append((k * T + rng.random(), int(rng.integers(-5, n + 5)), 9.0, NAN))
    arrivals += [(a + 1e-3, key, v, p) for a, key, v, p in arrivals if rng.random() < 0.1]
    arrivals = sorted(a for a in arrivals if (a[0] - D) % T > 1e-9 and a[0] % T > 1e-9)
    want, n_late, n_taken = reference(n, arrivals)
    got, counts = drive(n, arrivals)
    assert got == want
    assert counts["late"] == n_late
    assert counts["applied"] == sum(o == "applied" for _, o in want)
    assert counts["predicted"] == sum(o == "predicted" for _, o in want)
    assert counts["missed"] == n - counts["applied"]
    # every answer is accounted for once: kept (acted, or for a key with no section),
    # late or ignored
    assert n_taken + counts["late"] + counts["ignored"] == len(arrivals)
    # the draw exercises every path
    assert min(counts[c] for c in ("applied", "predicted", "late", "ignored")) > 5
    assert sum(o == "missed" for _, o in want) > 0


# ------------------------------------------------------------------ a driver's schedule
P, LEAD, W = 0.05, 0.001, 0.002      # forcing period, actuator latency, pulse width (s)


def pulse(s, k, now, force=1.0, predicted=NAN, t0=100.0):
    """The command of section k (section time t0 + k P, apply time 5 ms - w/2 later)."""
    t = t0 + k * P
    return s.pulse(t, t + 0.005 - W / 2, force, predicted, W, now)


def test_a_driver_schedule_opens_sections_from_the_commands_and_expects_the_next():
    s = RigSchedule(period=P, lead=LEAD)
    assert pulse(s, 0, now=100.0, force=2.0, predicted=1.5).outcome == "kept"
    assert s.due(100.0 + 0.004 - LEAD - 1e-6) == []       # starts at 100.004
    (act,) = s.due(100.004 - LEAD + 1e-9)                 # handed over `lead` ahead
    assert (act.value, act.section.width) == (2.0, W)
    assert act.section.start == pytest.approx(100.004, abs=1e-12)
    # section 1 is now expected: its command never comes, the prediction acts
    assert s.open[1].start == pytest.approx(100.054)
    (act,) = s.due(100.054)
    assert (act.value, act.code) == (1.5, 1)
    assert s.counts["missed"] == 1 and s.counts["predicted"] == 1
    # a command of section 2 with slightly other times (its own clock reading) rules
    assert pulse(s, 2, now=100.1, force=3.0, t0=100.0 + 1e-7).outcome == "kept"
    assert s.open[2].start == pytest.approx(100.104 + 1e-7, abs=1e-12)
    assert s.due(100.2)[0].value == 3.0


def test_a_driver_schedule_counts_late_duplicate_and_stale_commands():
    s = RigSchedule(period=P, lead=LEAD)
    assert pulse(s, 0, now=100.0035).outcome == "late"    # within the lead of its start
    assert s.counts["late"] == 1 and s.open == {}
    assert pulse(s, 1, now=100.05).outcome == "kept"
    assert pulse(s, 1, now=100.05).outcome == "ignored"   # duplicate
    assert pulse(s, 0, now=100.05).outcome == "ignored"   # stale
    s.due(100.06)
    assert pulse(s, 2, now=100.1035).outcome == "late"    # expected, missed after lead
    assert s.due(100.11)[0].code == 2                      # nothing to stand in
    assert s.counts == {"applied": 1, "predicted": 0, "missed": 1, "late": 2, "lost": 0,
                        "ignored": 2, "unarmed": 0}


def test_a_driver_schedule_stops_expecting_after_the_hold():
    s = RigSchedule(period=P, lead=0.0)
    pulse(s, 0, now=100.0, predicted=0.5)
    acts = s.due(100.0 + 20 * P)
    while (more := s.due(100.0 + 20 * P)):
        acts += more
    assert [a.code for a in acts] == [0] + [1] * PREDICTION_HOLD
    assert s.open == {}


def test_a_driver_schedule_without_a_period_acts_the_commands_it_gets():
    s = RigSchedule(lead=0.0)
    assert pulse(s, 0, now=100.0).outcome == "kept"
    assert pulse(s, 3, now=100.0).outcome == "kept"        # the next section in time
    assert [a.section.k for a in s.due(101.0)] == [0, 1]
    assert s.open == {}                                     # nothing expected
    assert pulse(s, 1, now=101.0).outcome == "ignored"      # before the latest: stale


def test_a_pulse_train_is_each_force_over_its_window_and_zero_between():
    train = PulseTrain()
    train.add(1.0, 0.5, 2.0)
    train.add(1.2, 0.1, -0.5)           # overlapping: the forces add
    train.add(3.0, 0.1, 0.0)            # nothing acts
    assert [train.force(t) for t in (0.99, 1.0, 1.25, 1.3, 1.49, 1.5, 3.05)] == [
        0.0, 2.0, 1.5, 2.0, 2.0, 0.0, 0.0]
    assert train.pulses == [] and train.unsent == 0     # ended pulses are forgotten
    train.add(4.0, 0.002, 1.0)          # a stream that stalls over a whole pulse
    train.add(4.1, 0.002, 1.0)
    assert train.force(4.001) == 1.0 and train.force(4.5) == 0.0
    assert train.unsent == 1


# ------------------------------------------------ a command's own start (timed output)
def test_a_slot_holds_the_starts_that_leave_the_pulse_within_its_period():
    """slot(start, T, room): the section k with k T <= start < k T + room; None before
    section 0 and in the last T - room of a period (docs/driver_contract.md, "Off the
    rig's section")."""
    from grazing_control.plant.schedule import slot

    T, room = 10.0, 9.5
    assert slot(0.0, T, room) == 0 and slot(9.499, T, room) == 0
    assert slot(9.5, T, room) is None and slot(9.999, T, room) is None
    assert slot(10.0, T, room) == 1 and slot(35.2, T, room) == 3
    assert slot(-1e-12, T, room) is None
    assert slot(math.nextafter(T, 0.0), T, room) is None


def test_retime_moves_only_an_open_unanswered_section_and_drop_late_counts_it():
    s = ActuationSchedule()
    s.section(0, "a", 0.0, 5.0)
    assert s.retime("b", 6.0) is None                     # not announced
    sec = s.retime("a", 7.5)
    assert sec.start == 7.5 and s.next_start() == 7.5 and s.waiting("a")
    assert s.command("a", 0.1).outcome == "kept"
    assert s.retime("a", 8.0) is None                     # answered: unchanged
    assert s.open["a"].start == 7.5
    s.section(1, "b", 10.0, 15.0)
    assert s.drop_late("b").k == 1 and s.counts["late"] == 1
    assert s.drop_late("b") is None and s.counts["late"] == 1
    assert s.command("b", 0.2).outcome == "ignored"       # its answer was dropped

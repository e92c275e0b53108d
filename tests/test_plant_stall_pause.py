"""A stall of the simulator pauses the plant's clock (grazing_control.plant.realtime,
``Realtime.resume``; sim_node's ``stall_pause``).

The machine may hold the simulator for milliseconds (this VM: both virtual CPUs stopped
for 4-16 ms a few times a minute, docs/benchmarks.md). Pinned to the wall clock, the
plant then jumps on by the stall when the simulator runs again: the samples due in it go
out at once, late, and a deadline in it passes before its answer can come: a miss that
is the simulator's, not the loop's. With ``stall_pause`` the plant's clock pauses for a
wake-up's lateness beyond it; a controller that is late on its own is still late.

The loop is driven as sim_node drives it, over a clock the test moves: each wake-up is
asked for (``expect``) at most 1 ms ahead (a stream's pace), the controller's answer is
ready 1 ms after its sample, and a stall moves the clock on at a chosen wake-up: the
machine's (both processes held: the pending answers wait as well), or the controller's
alone. The wake-ups' own work takes no wall time and no CPU time here; a wake-up held
while it runs is one whose wall time grows and its thread's CPU time does not.
"""

from __future__ import annotations

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.plant.engine import Engine
from grazing_control.plant.realtime import STALL_PAUSE, Realtime

from test_plant_loops import P, Clock, Recorder, key, law, reference, settings

N, ON, DELAY, C2 = 80, 10, 5.0, -1.0
C1 = degenerate_c1(P, C2, DELAY)
STALL = 8e-3          # longer than the 5 ms from a sample to its deadline at x1000


def run(stalls, pause=STALL_PAUSE, held="machine", late=0.0, n=N, **kw):
    """A scheduled scene of n samples at x1000 (delay 5: 5 ms of wall time), controlled
    from sample ON. ``stalls``: {sample k: seconds} held at the first wake-up after
    sample k went out, beginning half way through the wait (a list: one at each of the
    first wake-ups after it, "machine" only); ``held``: "machine" (the
    simulator and the controller: an answer not ready by the stall's start is ready that
    much later), "running" (the same, but the stall begins in the wake-up that published
    sample k, right after it went out: the simulator held while it runs) or "controller"
    (the simulator wakes on time) or "charged" (the wake-up that publishes sample k
    begins on time and runs that much slowly before the sample goes out, the time
    charged to its thread's CPU time: a stop of this VM charged as system time, or a
    slow spell of the machine). ``late``: every wake-up
    comes this much later than asked (the timer's jitter). Returns (loop, sink)."""
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=DELAY, max_periods=n,
                 state_period=0.0, **kw)
    clock, sink = Clock(), Recorder()
    loop = Realtime(Engine(s), sink, clock)
    loop.stall_pause = pause
    cpu = [0.0]                       # the wake-ups' work takes no time on the test's clock
    loop.cpu_clock = lambda: cpu[0]
    pending, seen, stall, more = [], 0, None, []
    if held == "charged":
        next_sample, slowed, stalls = loop.next_sample, stalls, {}

        def slow_next_sample():
            ev = next_sample()
            slow = ev is not None and slowed.get(round(ev.t / P.period))
            if slow:
                for p in pending:
                    if p[0] > clock.now:
                        p[0] += slow          # the controller slow as well
                clock.now += slow
                cpu[0] += slow
            return ev
        loop.next_sample = slow_next_sample
    loop.start()
    while not loop.finished:
        for ev in sink.samples()[seen:]:
            k = round(ev.t / P.period)
            pending.append([clock.now + 1e-3, key(ev), law(C1, C2, ev) if k >= ON else 0.0])
            stall = stalls.get(k)
            if isinstance(stall, list):
                stall, more = stall[0], stall[1:]
        seen = len(sink.samples())
        if stall and held == "running":
            for p in pending:
                if p[0] > clock.now:
                    p[0] += stall
            clock.now += stall
            stall = None
        wait = min(loop.wake_in(loop.now()), 1e-3)
        loop.expect(wait)
        begins, clock.now = clock.now + wait / 2.0, clock.now + wait + late
        if stall:
            for p in pending:
                if p[0] > begins:
                    p[0] += stall                 # the controller held from ``begins``
            if held == "machine":
                clock.now += stall
            stall = more.pop(0) if more else None
        loop.resume(clock.now)                    # sim_node's wake-up: first the pause,
        for p in [p for p in pending if p[0] <= clock.now]:
            loop.answer(p[1], p[2], arrived=p[0])     # then the answers arrived by now,
            pending.remove(p)
        loop.tick(clock.now)                      # then what is due
    return loop, sink


def samples(sink):
    return np.array([(e.x, e.v) for e in sink.samples()])


def test_without_a_stall_the_scene_is_the_lockstep_loop_bit_for_bit():
    loop, sink = run({})
    np.testing.assert_array_equal(samples(sink), reference(N, C1, C2, ON, DELAY))
    assert not sink.misses and loop.stats.get("paused", 0) == 0 and loop.paused == 0.0


def test_a_stall_of_the_machine_on_the_wall_clock_misses_the_deadlines_in_it():
    """Held 16 ms after sample 47 (a period is 9.4 ms at x1000), the plant publishes
    sample 48 when it runs again, already past 48's deadline as well."""
    stalls = {20: STALL, 21: STALL, 47: 2 * STALL}
    loop, sink = run(stalls, pause=0.0)
    missed = [20, 21, 47, 48]
    assert [m[0] for m in sink.misses] == missed
    np.testing.assert_array_equal(samples(sink), reference(N, C1, C2, ON, DELAY, missed))
    assert loop.stats.get("paused", 0) == 0


@pytest.mark.parametrize("held", ["machine", "running", "charged"])
def test_a_stall_of_the_machine_pauses_the_plant_and_no_deadline_is_missed(held):
    """Held while asleep (its wake-up comes late: Realtime.resume), while it runs (its
    wake-up ends late: Realtime.expect) or slow before a sample with the time charged to
    its CPU time (the sample goes out late: Realtime._catch_up), the plant pauses as
    long."""
    stalls = {20: STALL, 21: STALL, 47: 2 * STALL}
    loop, sink = run(stalls, held=held)
    assert not sink.misses
    np.testing.assert_array_equal(samples(sink), reference(N, C1, C2, ON, DELAY))
    assert loop.stats["paused"] == 3
    # charged: the pause is the sample's whole lag, its usual lateness (the test's wake-up
    # at most 1 ms apart, not at the sample exactly) with the stall
    usual = run({})[0].lags if held == "charged" else [0.0] * N
    pauses = [STALL + usual[20], STALL + usual[21], 2 * STALL + usual[47]]
    assert loop.paused == pytest.approx(sum(pauses), abs=1e-12)
    assert loop.longest_pause == pytest.approx(pauses[-1], abs=1e-12)
    # each pause told to the sink: after sample k went out (charged: before sample k)
    assert [s for _, s in sink.pauses] == pytest.approx(pauses, abs=1e-12)
    assert [t // P.period for t, _ in sink.pauses] == (
        sorted(stalls) if held != "charged" else [k - 1 for k in sorted(stalls)])
    text = loop.summary(1.0, {"missed": 0, "timeouts": 0, "ignored": 0, "malformed": 0})
    assert "missed=0 " in text and (
        f"periods/s paused=3 paused_ms={sum(pauses) * 1e3:.3f} "
        f"longest_pause_ms={pauses[-1] * 1e3:.3f}") in text


def test_a_controller_held_on_its_own_is_late_however_the_plant_pauses():
    stalls = {20: STALL, 33: STALL}
    loop, sink = run(stalls, held="controller")
    assert [m[0] for m in sink.misses] == sorted(stalls)
    np.testing.assert_array_equal(samples(sink), reference(N, C1, C2, ON, DELAY, stalls))
    assert loop.stats.get("paused", 0) == 0


@pytest.mark.parametrize("late", [0.0, 0.3e-3, 0.9e-3])
def test_a_lateness_within_stall_pause_is_the_loops_and_pauses_nothing(late):
    loop, sink = run({}, late=late)
    assert loop.stats.get("paused", 0) == 0 and loop.paused == 0.0
    assert not sink.misses            # 0.9 ms a wake-up: still inside the 5 ms budget


def test_the_pause_is_exactly_the_lateness_beyond_the_asked_wake_up():
    """resume on its own: the simulation time at the late wake-up is the asked one's."""
    clock = Clock()
    loop = Realtime(Engine(settings(mode="realtime", time_scale=1000.0)), Recorder(), clock)
    loop.cpu_clock = lambda: 0.0
    loop.start()
    clock.now += 2e-3
    loop.tick()
    for lateness, paused in ((0.5e-3, 0.0), (0.99 * STALL_PAUSE, 0.0), (7.25e-3, 7.25e-3)):
        asked = loop.now(clock.now + 1e-3)
        loop.expect(1e-3)
        clock.now += 1e-3 + lateness
        assert loop.resume(clock.now) == pytest.approx(paused, abs=1e-12)
        assert loop.now() == pytest.approx(asked + (0.0 if paused else lateness * 1e3),
                                           abs=1e-9)
        loop.tick()
    # an answer between wake-ups, early: nothing paused, the wake-up still expected
    loop.expect(1e-3)
    assert loop.resume(clock.now + 0.5e-3, woke=False) == 0.0 and loop.expected is not None


def test_a_wake_ups_own_work_is_the_plants_time_and_pauses_nothing():
    """Work of 3 ms in one wake-up (the thread's CPU time grows as the wall time): no
    pause; the same 3 ms held (the CPU time still): a pause of 3 ms; 0.5 ms of the 3
    held: within stall_pause, no pause."""
    clock, cpu = Clock(), [0.0]
    loop = Realtime(Engine(settings(mode="realtime", time_scale=1000.0)), Recorder(), clock)
    loop.cpu_clock = lambda: cpu[0]
    loop.start()
    for worked, paused in ((3e-3, 0.0), (0.0, 3e-3), (2.5e-3, 0.0)):
        loop.expect(1e-3)
        clock.now += 1e-3
        loop.tick()
        clock.now += 3e-3                      # the wake-up's wall time
        cpu[0] += worked                       # of which the thread ran this long
        before = loop.paused
        loop.expect(1e-3)
        assert loop.paused - before == pytest.approx(paused, abs=1e-12)
    assert loop.stats["paused"] == 1
    # as sim_node wakes with the answer port: resume, the answers (3 ms of work), then
    # tick, which resumes again: the work is still the wake-up's own (in a wake-up right
    # after a sample: no sample made late by it, below)
    due = loop.wall0 + (loop.engine.seg.te - loop.t0) / 1000.0 + 1e-9   # the next sample's
    loop.expect(due - clock.now)
    clock.now = due
    loop.tick()
    assert loop.lags[-1] == pytest.approx(0.0, abs=1e-8)
    loop.expect(1e-3)
    clock.now += 1e-3
    loop.resume(clock.now)
    clock.now += 3e-3
    cpu[0] += 3e-3
    loop.tick(clock.now - 3e-3)
    loop.expect(1e-3)
    assert loop.stats["paused"] == 1


@pytest.mark.parametrize("worked", [0.5e-3, 0.99e-3, 3e-3, 7e-3])
def test_a_sample_late_from_its_own_wake_up_pauses_the_plant_by_its_lag(worked):
    """The wake-up of sample k begins on time and works ``worked`` before it (the time
    charged to its CPU time, as a stop of this VM can be): beyond stall_pause the plant
    pauses by the sample's lag, which is 0 after it; within it, nothing. The wake-up's
    held time is measured from the sample on (nothing paused twice)."""
    clock, cpu = Clock(), [0.0]
    loop = Realtime(Engine(settings(mode="realtime", time_scale=1000.0)), Recorder(), clock)
    loop.cpu_clock = lambda: cpu[0]
    next_sample = loop.next_sample

    def slow_next_sample():
        clock.now += worked
        cpu[0] += worked
        return next_sample()
    loop.start()
    loop.next_sample = slow_next_sample
    t1 = loop.engine.seg.te
    due = loop.wall0 + (t1 - loop.t0) / 1000.0 + 1e-9   # sample 1's time
    loop.expect(due - clock.now)
    clock.now = woke = due
    loop.tick()
    assert clock.now - woke == pytest.approx(worked, abs=1e-12) and len(loop.lags) == 2
    lag = loop.lags[-1] + loop.paused
    assert lag == pytest.approx(worked, abs=1e-8)
    paused = lag if worked > STALL_PAUSE else 0.0
    assert loop.paused == pytest.approx(paused, abs=1e-12)
    # the simulation time now: the sample's, paused; else on by the lag
    assert loop.now() == pytest.approx(t1 + (lag - paused) * 1e3, abs=1e-8)
    clock.now += 2e-3                      # held 2 ms after the sample
    loop.expect(1e-3)
    assert loop.paused == pytest.approx(paused + 2e-3, abs=1e-12)


def test_a_long_stall_still_trips_the_watchdog_on_the_lag():
    """The pause hides a stall from the deadlines, not from the watchdog: its lag is
    against the wall clock (1.5 s held: tripped on lag at the next sample)."""
    loop, sink = run({30: 1.5}, watchdog_misses=0)
    trip = loop.watchdog.tripped
    assert trip is not None and trip.kind == "lag" and trip.k == 31, trip
    assert loop.stats["paused"] == 1 and loop.paused == pytest.approx(1.5, abs=1e-9)
    assert not sink.misses


def test_short_stalls_spread_over_a_run_never_add_up_to_a_lag():
    """Held 3 ms after every other sample: 0.12 s of pauses in all over 80 samples, at
    pace 0.86, each deadline kept. The lag counts a sample's longest pause since the
    previous one, not the run's pauses: no trip at watchdog_lag 0.1 s, where all of the
    pauses summed would have tripped at sample 67 (a time_scale 1 scene: 464 pauses of
    ~1 ms, 1.117 s, over 50 periods that kept pace). The same 0.12 s in one stall trips
    at once."""
    spread = {k: 3e-3 for k in range(0, N, 2)}
    loop, sink = run(spread, watchdog_misses=0, watchdog_lag=0.1)
    assert loop.watchdog.tripped is None and not sink.misses
    assert loop.paused == pytest.approx(sum(spread.values()), abs=1e-9) and loop.paused > 0.1
    loop, sink = run({40: 0.12}, watchdog_misses=0, watchdog_lag=0.1)
    trip = loop.watchdog.tripped
    assert trip is not None and trip.kind == "lag" and trip.k == 41, trip


def test_many_pauses_in_one_period_are_not_one_stall():
    """Held 30 ms at each of ten wake-ups after sample 40 (0.3 s of pauses within one
    period, as a loaded time_scale 1 scene's 9.4 s periods gather up to 1.5 s of pauses
    of at most 43 ms): no stall beyond watchdog_lag 0.1 s, no trip; each is paused."""
    loop, sink = run({40: [30e-3] * 10}, watchdog_misses=0, watchdog_pace=0.0,
                     watchdog_lag=0.1)
    assert loop.watchdog.tripped is None and not sink.misses
    assert loop.stats["paused"] == 10 and loop.paused == pytest.approx(0.3, abs=1e-9)
    assert loop.longest_pause == pytest.approx(30e-3, abs=1e-12)


@pytest.mark.parametrize("seed", range(12))
def test_the_lag_trips_at_the_first_stall_longer_than_the_limit(seed):
    """Seeded random stalls (2-104 ms, after a random quarter of the samples: 0.8-1.2 s
    of pauses in all, 5 of the 12 seeds without one over 0.1 s), pace and misses off: the
    watchdog trips on the lag at the sample after the first stall longer than
    watchdog_lag 0.1 s (brute force over the pattern), never otherwise; every stall is
    paused exactly."""
    rng = np.random.default_rng(seed)
    ks = sorted(rng.choice(np.arange(1, N - 2), size=N // 4, replace=False))
    stalls = {int(k): float(s) for k, s in zip(ks, rng.uniform(0.002, 0.104, len(ks)))}
    loop, sink = run(stalls, watchdog_misses=0, watchdog_pace=0.0, watchdog_lag=0.1)
    first = next((k for k in ks if stalls[k] > 0.1), None)
    trip = loop.watchdog.tripped
    if first is None:
        assert trip is None
    else:
        assert trip is not None and trip.kind == "lag" and trip.k == first + 1, (trip, first)
        assert f"sample {first + 1} went out {stalls[first]:.3g} s" in trip.reason
    paused = sum(s for k, s in stalls.items() if first is None or k <= first)
    assert loop.paused == pytest.approx(paused, abs=1e-9)


def test_stalls_again_and_again_trip_the_watchdog_on_the_pace():
    """A simulator held 10 ms at every sample (a period is 9.4 ms at x1000) runs at half
    the pace with its plant paused: the watchdog trips on the pace at its first window."""
    loop, sink = run({k: 10e-3 for k in range(N)}, watchdog_misses=0)
    trip = loop.watchdog.tripped
    assert trip is not None and trip.kind == "pace" and trip.k == 50, trip
    assert not sink.misses

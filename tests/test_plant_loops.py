"""The plant's two loops without ROS: lockstep and realtime over a recording sink and a
fake wall clock (grazing_control.plant.lockstep, .realtime, .loop).

The references are the core's: :func:`grazing_control.dynamics.simulation.simulate.simulate` and a
loop of :func:`grazing_control.dynamics.simulation.simulate.period_step` written here, one call per
sample with the delay of docs/theory_delay.md. The realtime loop is driven by a clock the
test advances, so deadlines, misses, late answers and splits happen exactly where the
test puts them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.simulation.simulate import period_step, simulate
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine
from grazing_control.plant.lockstep import Lockstep
from grazing_control.plant.loop import PREDICTION_HOLD
from grazing_control.plant.realtime import CLOCK_TICK, MIN_TICK, STREAM_TICK, Realtime
from grazing_control.plant.settings import settings_from_values
from grazing_control.oscillator.params import ParameterError

P = OscillatorParams(delta_d=-5e-6)


def settings(**kw):
    return settings_from_values({"delta_d": P.delta_d, **kw})


class Recorder:
    """A sink that keeps what a loop publishes, keyed like the node (stamp in ns)."""

    def __init__(self):
        self.events, self.misses, self.latencies = [], [], []
        self.substitutions, self.pauses = [], []
        self.counts = {"ignored": 0, "late": 0, "timeout": 0, "warn": 0}
        self.finished = 0
        self.trips = []
        self._samples = []      # the events' Pi2 samples, kept as they come (a filter of
        #                         every event on each tick of a realtime loop was quadratic)

    def tripped(self, trip):
        self.trips.append(trip)

    def publish(self, ev):
        self.events.append(ev)
        if ev.kind == "pi2":
            self._samples.append(ev)
        return key(ev)

    def samples(self):
        return list(self._samples)

    def latency(self, seconds):
        self.latencies.append(seconds)

    def miss(self, k, key, t, waited):
        self.misses.append((k, key, t, waited))

    def substituted(self, k, key, dv):
        self.substitutions.append((k, key, dv))

    def paused(self, t, seconds):
        self.pauses.append((t, seconds))

    def ignored(self, text):
        self.counts["ignored"] += 1

    def late(self, text):
        self.counts["late"] += 1

    def timeout(self, text):
        self.counts["timeout"] += 1

    def warn(self, text):
        self.counts["warn"] += 1

    def finish(self):
        self.finished += 1


class Clock:
    """A wall clock the test moves."""

    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def key(ev):
    """The stamp (sec, nanosec) of an event, as sim_node's (cdr.stamp_parts)."""
    ns = int(round(ev.t * 1e9))
    return divmod(ns, 1_000_000_000)


def law(c1, c2, ev):
    """Eq. 28 on the published (physical) sample, as controller_node computes it."""
    return c1 * (ev.x - P.x_ref) + c2 * (ev.v - P.v_ref)


def reference(n, c1, c2, on, delay, skip=()):
    """The core, one period_step per sample: the Pi2 samples (physical) and corrections.
    Samples in ``skip`` get no correction (a miss)."""
    dx = dv = 0.0
    out = []
    for k in range(n):
        ev_x, ev_v = P.x_ref + dx, P.v_ref + dv
        out.append((ev_x, ev_v))
        dvc = c1 * (ev_x - P.x_ref) + c2 * (ev_v - P.v_ref) if k >= on and k not in skip \
            else 0.0
        seg = period_step(P, dx, dv, dvc, delay=delay)
        dx, dv = seg.dx, seg.dv
    return np.array(out)


# ==================================================================== lockstep
def test_lockstep_without_corrections_is_simulate_sample_for_sample():
    n = 40
    sink = Recorder()
    loop = Lockstep(Engine(settings(max_periods=n, state_period=0.5)), sink, Clock())
    loop.start()
    while not loop.finished:
        loop.answer(loop.waiting, 0.0)
    got = np.array([(e.x, e.v) for e in sink.samples()])
    np.testing.assert_array_equal(got, simulate(P, n).pi2)
    assert sink.finished == 1 and loop.stats["applied"] == n
    assert sum(e.kind == "pi1" for e in sink.events) == n
    assert sum(e.kind == "impact" for e in sink.events) == loop.engine.impacts == \
        simulate(P, n).impacts_per_period.sum()


@pytest.mark.parametrize("delay", [0.0, 5.0])
def test_lockstep_controlled_is_the_cores_period_loop_bit_for_bit(delay):
    n, on, c2 = 300, 100, -1.0
    c1 = degenerate_c1(P, c2, delay)
    sink = Recorder()
    loop = Lockstep(Engine(settings(max_periods=n, state_period=0.0,
                                    actuation_delay=delay)), sink, Clock())
    loop.start()
    while not loop.finished:
        ev = sink.samples()[-1]
        loop.answer(loop.waiting, law(c1, c2, ev) if loop.engine.k >= on else 0.0)
    got = np.array([(e.x, e.v) for e in sink.samples()])
    np.testing.assert_array_equal(got, reference(n, c1, c2, on, delay))
    if delay == 0.0:
        # and simulate's own loop (its law on the deviation: rounding apart; with a delay
        # simulate does not split its uncontrolled periods, so chaos parts the rounding)
        ref = simulate(P, n, gains=Gains(c1, c2, delay), control_after=on).pi2
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    assert np.ptp(got[-50:, 0]) < 1e-12             # captured on the 1/1 orbit


def test_lockstep_ignores_other_stamps_and_times_out():
    clock = Clock()
    sink = Recorder()
    loop = Lockstep(Engine(settings(answer_timeout=0.5)), sink, clock)
    loop.start()
    first = loop.waiting
    loop.answer((12345, 0), 0.1)                      # foreign
    assert sink.counts["ignored"] == 1 and loop.engine.k == 0
    clock.now += 0.4
    loop.check_timeout()
    assert loop.engine.k == 0                         # not yet
    clock.now += 0.2
    loop.check_timeout()
    assert sink.counts["timeout"] == 1 and loop.engine.k == 1 and loop.stats["applied"] == 0
    loop.answer(first, 0.1)                           # its sample has gone: ignored
    assert sink.counts["ignored"] == 2 and loop.engine.k == 1


def test_lockstep_loss_drops_the_corrections_the_fault_model_draws():
    sink = Recorder()
    s = settings(loss=0.4, seed=5, max_periods=60)
    loop = Lockstep(Engine(s), sink, Clock())
    loop.start()
    while not loop.finished:
        loop.answer(loop.waiting, 1e-3)
    lost = sum(s.faults.draw(k).dropped for k in range(60))
    assert loop.stats["lost"] == lost and loop.stats["applied"] == 60 - lost and 0 < lost < 60


def test_lockstep_reset_starts_again_from_sample_zero():
    sink = Recorder()
    loop = Lockstep(Engine(settings(x0=-0.5, v0=-1.0)), sink, Clock())
    loop.start()
    for _ in range(5):
        loop.answer(loop.waiting, 0.0)
    loop.reset(loop.engine.reset())
    for _ in range(5):
        loop.answer(loop.waiting, 0.0)
    s = sink.samples()
    assert [e.t for e in s[6:]] == [e.t for e in s[:6]]
    assert [(e.x, e.v) for e in s[6:]] == [(e.x, e.v) for e in s[:6]]


# ==================================================================== realtime
def run_realtime(s, n, answer, clock, sink, step=None, acts=None):
    """Drive a realtime loop for n samples: at each wake-up the clock jumps to the next
    due instant (wake_in), and ``answer(loop, sample)`` is called right after each sample
    goes out (it may move the clock and answer or not). ``acts``: a list that receives
    what acted at each section (:func:`record_acts`)."""
    loop = Realtime(Engine(s), sink, clock)
    if acts is not None:
        record_acts(loop, acts)
    loop.start()
    seen = 0
    while not loop.finished:
        samples = sink.samples()
        while seen < len(samples):
            answer(loop, samples[seen])
            seen += 1
        now = loop.now()
        clock.now += loop.wake_in(now) if step is None else step
        loop.tick()
    return loop


def test_realtime_wake_ups_stay_within_the_tick_bounds():
    clock, sink = Clock(), Recorder()
    loop = Realtime(Engine(settings(mode="realtime", time_scale=1000.0)), sink, clock)
    loop.start()
    for _ in range(200):
        w = loop.wake_in(loop.now())
        assert MIN_TICK <= w <= CLOCK_TICK
        clock.now += w
        loop.tick()
    # published in time order, each when due, never early
    ts = [e.t for e in sink.events]
    assert ts == sorted(ts) and ts[-1] <= loop.now()


def test_realtime_scheduled_equals_lockstep_bit_for_bit_and_misses_cost_one_correction():
    n, on, delay, c2 = 200, 60, 5.0, -1.0
    c1 = degenerate_c1(P, c2, delay)
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay,
                 max_periods=n, state_period=0.0)
    skip = {80, 81, 150}
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        k = round(ev.t / P.period)
        if k in skip:
            return                                    # this answer never comes in time
        clock.now += 1e-3                             # 1 ms round trip < 5 ms of delay
        loop.answer(key(ev), law(c1, c2, ev) if k >= on else 0.0)

    loop = run_realtime(s, n, answer, clock, sink)
    got = np.array([(e.x, e.v) for e in sink.samples()])
    np.testing.assert_array_equal(got, reference(n, c1, c2, on, delay, skip))
    assert [m[0] for m in sink.misses] == sorted(skip)
    assert all(m[2] == pytest.approx(m[0] * P.period + delay, abs=1e-9) for m in sink.misses)
    assert loop.stats["applied"] == n - len(skip)
    assert sink.latencies == pytest.approx([1e-3] * (n - len(skip)))


def test_realtime_scheduled_answer_after_its_deadline_is_dropped_as_late():
    delay = 5.0
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=20)
    clock, sink = Clock(), Recorder()
    late = []

    def answer(loop, ev):
        if late:                                     # the late answer of sample 3
            loop.answer(late.pop(), 0.5)
        if round(ev.t / P.period) == 3:
            late.append(key(ev))                      # answered after the next sample
            return
        loop.answer(key(ev), 0.0)

    loop = run_realtime(s, 20, answer, clock, sink)
    assert [m[0] for m in sink.misses] == [3]
    assert sink.counts["late"] == 1 and loop.stats["late"] == 1
    got = np.array([(e.x, e.v) for e in sink.samples()])
    np.testing.assert_array_equal(got, reference(20, 0.0, 0.0, 0, delay))  # 0.5 never acted


def test_a_scheduled_answer_is_judged_by_its_arrival_not_by_when_the_loop_takes_it():
    """The simulator held off its core past a deadline takes the answer that had arrived
    before it (sim_node.answer_port): it acts there, bit for bit the answer in time; one
    that arrived after the deadline is late, however early the loop took it."""
    n, on, delay, c2 = 60, 10, 5.0, -1.0
    c1 = degenerate_c1(P, c2, delay)
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay,
                 max_periods=n, state_period=0.0)
    held, after = {20, 33}, {40}
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        k = round(ev.t / P.period)
        arrived = clock.now + 1e-3                   # 1 ms after the sample (5 ms of delay)
        if k in after:
            arrived = clock.now + (delay + 0.5) / 1000.0   # 0.5 ms after its deadline
        if k in held or k in after:
            clock.now += 8e-3      # off its core for 8 ms: wakes past the deadline, takes
        wall = clock.now           # the answers that arrived by then, then what is due
        loop.answer(key(ev), law(c1, c2, ev) if k >= on else 0.0, arrived=arrived)
        loop.tick(wall)

    loop = run_realtime(s, n, answer, clock, sink)
    got = np.array([(e.x, e.v) for e in sink.samples()])
    np.testing.assert_array_equal(got, reference(n, c1, c2, on, delay, after))
    assert [m[0] for m in sink.misses] == sorted(after)
    assert loop.stats["late"] == 1 and loop.stats["applied"] == n - 1


@pytest.mark.parametrize("pre_roll", [1, 3])
def test_the_pre_roll_sections_have_no_deadline_and_nothing_acts_there(pre_roll):
    # a stream that starts at section 0 (a rig): sections < pre_roll are unarmed
    n, delay, c2 = 40, 5.0, -1.0
    c1 = degenerate_c1(P, c2, delay)
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=n,
                 state_period=0.0, pre_roll=pre_roll)
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        k = round(ev.t / P.period)
        if k == 0:
            clock.now += 8e-3                         # after its deadline (5 ms)
        elif k == 1:
            return                                    # never answered
        else:
            clock.now += 1e-3
        loop.answer(key(ev), law(c1, c2, ev))

    loop = run_realtime(s, n, answer, clock, sink)
    got = np.array([(e.x, e.v) for e in sink.samples()])
    # nothing acted before pre_roll, whatever came; from there on every answer acts, and
    # the first armed section unanswered (pre_roll 1: section 1) is a miss as any other
    skip = set(range(pre_roll)) | {1}
    np.testing.assert_array_equal(got, reference(n, c1, c2, 0, delay, skip))
    assert [m[0] for m in sink.misses] == ([1] if pre_roll == 1 else [])
    assert loop.stats["unarmed"] == pre_roll and loop.stats["late"] == 0
    assert loop.stats["applied"] == n - len(skip) and sink.counts["late"] == 0


def test_the_pre_roll_is_refused_below_zero_in_one_line():
    with pytest.raises(ParameterError, match=r"^pre_roll=-1 is invalid: valid range is "
                                             r"pre_roll >= 0"):
        settings(mode="realtime", actuation_delay=5.0, pre_roll=-1)


def test_realtime_on_arrival_splits_the_period_where_the_answer_arrives():
    s = settings(mode="realtime", time_scale=1000.0, max_periods=3, state_period=0.0)
    clock, sink = Clock(), Recorder()
    dv = 1e-3

    def answer(loop, ev):
        if round(ev.t / P.period) == 0:
            clock.now += 2e-3                         # arrives 2 ms = 2.0 time units later
            loop.answer(key(ev), dv)

    run_realtime(s, 3, answer, clock, sink)
    # the core: the flow to t = 2, the jump there, the flow on (period_step's delay)
    seg = period_step(P, 0.0, 0.0, dv, delay=2.0)
    got = sink.samples()[1]
    assert got.x == pytest.approx(P.x_ref + seg.dx, abs=1e-12)
    assert got.v == pytest.approx(P.v_ref + seg.dv, abs=1e-12)


def test_realtime_lags_are_how_late_each_sample_went_out():
    s = settings(mode="realtime", time_scale=1000.0, max_periods=10)
    clock, sink = Clock(), Recorder()
    loop = run_realtime(s, 10, lambda loop, ev: None, clock, sink, step=1e-3)
    lags = np.array(loop.lags)
    assert lags[0] == 0.0 and np.all(lags >= 0) and np.all(lags < 1e-3 + 1e-12)


def test_rebase_keeps_the_simulation_time_continuous():
    clock, sink = Clock(), Recorder()
    engine = Engine(settings(mode="realtime", time_scale=1000.0))
    loop = Realtime(engine, sink, clock)
    loop.start()
    clock.now += 2e-3
    t = loop.now()
    loop.rebase()
    engine.settings = settings(mode="realtime", time_scale=10.0)
    assert loop.now() == pytest.approx(t, abs=1e-12)
    clock.now += 0.1
    assert loop.now() == pytest.approx(t + 1.0, abs=1e-9)
    assert math.isfinite(loop.wake_in(loop.now()))


# ============================================================ the stream controller
@pytest.mark.parametrize("mode, make, first", [
    ("lockstep", Lockstep, [("pi2", 0.0), ("state", 0.0)]),
    ("realtime", Realtime, [("state", 0.0), ("pi2", 0.0)])])
def test_the_stream_sample_at_t0_goes_out_before_sample_0s_answer_is_awaited(mode, make,
                                                                             first):
    """Realtime: before sample 0, as each section's last stream samples go out before its
    sample (sim_node flushes the wake-up's block before a Pi2 sample)."""
    sink = Recorder()
    loop = make(Engine(settings(state_period=P.period / 200, mode=mode)), sink, Clock())
    loop.start()
    assert [(e.kind, e.t) for e in sink.events] == first
    loop.reset(loop.engine.reset())
    assert [(e.kind, e.t) for e in sink.events[2:]] == first


def test_the_stream_sample_at_t0_does_not_wait_for_period_0s_integration():
    """The t = 0 stream sample is what a stream controller answers section 0 from (with
    an answer lead, docs/nodes.md): emitted after sample 0, it waited in the wake-up's
    block for period 0's integration, 1.6 ms of section 0's 3 ms budget at T/200 x1000
    (docs/benchmarks.md, "Section 0")."""
    clock, sink = Clock(), Recorder()
    engine = Engine(settings(mode="realtime", time_scale=1000.0, max_periods=2,
                             state_period=P.period / 200, actuation_delay=3.0))
    order = []
    for name in ("begin_head", "begin_period"):
        def integrate(*args, _f=getattr(engine, name), **kwargs):
            order.append(("integrate", engine.k))
            return _f(*args, **kwargs)
        setattr(engine, name, integrate)
    published = sink.publish

    def publish(ev):
        order.append((ev.kind, ev.t))
        return published(ev)

    sink.publish = publish
    Realtime(engine, sink, clock).start()
    assert order[:3] == [("state", 0.0), ("pi2", 0.0), ("integrate", 0)]


def test_realtime_answers_that_come_before_their_sample_are_kept():
    """A stream controller may answer sample k before the simulator publishes it (it
    estimates Pi2 from the stream's samples before t_k): the answer acts on schedule."""
    n, delay = 30, 2.0
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=n,
                 state_period=0.0)
    dvs = [1e-4 * ((k % 5) - 2) for k in range(n + 2)]
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        k = round(ev.t / P.period)
        if k == 0:
            loop.answer(key(ev), dvs[0])
        nxt = ev._replace(t=(k + 1) * P.period)       # the next sample, not yet out
        loop.answer(key(nxt), dvs[k + 1])

    loop = run_realtime(s, n, answer, clock, sink)
    dx = dv = 0.0
    ref = []
    for k in range(n):
        ref.append((P.x_ref + dx, P.v_ref + dv))
        seg = period_step(P, dx, dv, dvs[k], delay=delay)
        dx, dv = seg.dx, seg.dv
    np.testing.assert_array_equal([(e.x, e.v) for e in sink.samples()], ref)
    assert not sink.misses and loop.stats["applied"] == n and sink.counts["ignored"] <= 1


# ============================================================= miss-tolerant actuation
def predicting_controller(c1, c2, delay):
    """A controller's answer to a sample (x, v): Eq. 28's Delta v and its prediction for
    the next sample, one exact period of the model with the correction applied."""
    def answer(x, v):
        dvc = c1 * (x - P.x_ref) + c2 * (v - P.v_ref)
        nxt = period_step(P, x - P.x_ref, v - P.v_ref, dvc, delay=delay)
        return dvc, c1 * nxt.dx + c2 * nxt.dv
    return answer


def lossy_lockstep(on_miss, n, on, loss, seed, delay=0.0):
    c2 = -1.0
    c1 = degenerate_c1(P, c2, delay)
    ctl = predicting_controller(c1, c2, delay)
    sink = Recorder()
    loop = Lockstep(Engine(settings(max_periods=n, state_period=0.0, loss=loss, seed=seed,
                                    on_miss=on_miss, actuation_delay=delay)), sink, Clock())
    loop.start()
    while not loop.finished:
        ev = sink.samples()[-1]
        if loop.engine.k >= on:
            loop.answer(loop.waiting, *ctl(ev.x, ev.v))
        else:
            loop.answer(loop.waiting, 0.0, math.nan)
    return np.array([(e.x, e.v) for e in sink.samples()]), loop


@pytest.mark.parametrize("delay", [0.0, 5.0])
def test_a_lost_answer_costs_nothing_with_prediction(delay):
    """Issue 16 §3's acceptance in the engine: Delta d = -5e-6, lockstep, 5 % of the
    answers lost (control from sample 200: captured within about 100 samples). With
    on_miss = predict the Pi2 spread over the last 1000 samples, about the lossless
    run's orbit, stays <= 1e-10; with drop each loss throws the motion off the orbit."""
    n, on, seed = 1600, 200, 7
    spreads, stats = {}, {}
    for on_miss in ("predict", "drop"):
        got, loop = lossy_lockstep(on_miss, n, on, 0.05, seed, delay)
        ref, _ = lossy_lockstep(on_miss, n, on, 0.0, seed, delay)  # the lossless orbit
        orbit = ref[-1, 0]
        spreads[on_miss] = np.std(got[-1000:, 0] - orbit)
        stats[on_miss] = dict(loop.stats)
    print(f"\ndelay {delay}: spread predict {spreads['predict']:.2e}, "
          f"drop {spreads['drop']:.2e}; {stats}")
    faults = settings(loss=0.05, seed=seed).faults
    lost = [k for k in range(n) if faults.draw(k).dropped]
    assert stats["predict"]["lost"] == len(lost) > 50
    # every loss after the first controlled answer (which carried the first prediction)
    assert stats["predict"]["predicted"] == sum(k > on for k in lost)
    assert spreads["predict"] <= 1e-10
    assert spreads["drop"] > 1e-4


def test_realtime_misses_apply_the_previous_answers_prediction():
    """Scheduled realtime: answers that never come in time (misses) are replaced by the
    last applied answer's prediction, for up to PREDICTION_HOLD misses in a row."""
    n, on, delay, c2 = 300, 60, 5.0, -1.0
    c1 = degenerate_c1(P, c2, delay)
    ctl = predicting_controller(c1, c2, delay)
    skip = {200, 230, 231} | set(range(260, 260 + PREDICTION_HOLD + 1))
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=n,
                 state_period=0.0)
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        k = round(ev.t / P.period)
        if k not in skip:
            clock.now += 1e-3
            loop.answer(key(ev), *(ctl(ev.x, ev.v) if k >= on else (0.0, math.nan)))

    loop = run_realtime(s, n, answer, clock, sink)
    assert [m[0] for m in sink.misses] == sorted(skip)
    assert loop.stats["predicted"] == len(skip) - 1       # all but the last of the run
    assert [k for k, _, _ in sink.substitutions] == sorted(skip)[:-1]
    assert all(key_ == key(sink.samples()[k]) for k, key_, _ in sink.substitutions)
    # the core: each miss gets the prediction of the last answer before it
    dx = dv = 0.0
    samples = sink.samples()
    for k, ev in enumerate(samples):
        assert (ev.x, ev.v) == (P.x_ref + dx, P.v_ref + dv), k
        if k < on or k == 260 + PREDICTION_HOLD:
            dvc = 0.0
        elif k in skip:
            last = max(j for j in range(k) if j not in skip)
            dvc = ctl(samples[last].x, samples[last].v)[1]
        else:
            dvc = ctl(ev.x, ev.v)[0]
        seg = period_step(P, dx, dv, dvc, delay=delay)
        dx, dv = seg.dx, seg.dv


def test_realtime_a_late_answers_prediction_serves_the_next_sample():
    """Sample 240's answer comes after its deadline (dropped as late) and 241's never:
    240 gets 239's prediction, 241 gets the late answer's own prediction (made for it)."""
    n, on, delay, c2 = 260, 60, 5.0, -1.0
    c1 = degenerate_c1(P, c2, delay)
    ctl = predicting_controller(c1, c2, delay)
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=n,
                 state_period=0.0)
    clock, sink = Clock(), Recorder()
    held = []

    def answer(loop, ev):
        k = round(ev.t / P.period)
        if k == 241:
            prev = held.pop()
            loop.answer(key(prev), *ctl(prev.x, prev.v))        # 240's, late
            return                                             # 241: never answered
        if k == 240:
            held.append(ev)
            return
        clock.now += 1e-3
        loop.answer(key(ev), *(ctl(ev.x, ev.v) if k >= on else (0.0, math.nan)))

    loop = run_realtime(s, n, answer, clock, sink)
    assert [m[0] for m in sink.misses] == [240, 241] and loop.stats["late"] == 1
    assert loop.stats["predicted"] == 2
    samples = sink.samples()
    dx = dv = 0.0
    for k, ev in enumerate(samples):
        assert (ev.x, ev.v) == (P.x_ref + dx, P.v_ref + dv), k
        if k < on:
            dvc = 0.0
        elif k in (240, 241):
            dvc = ctl(samples[k - 1].x, samples[k - 1].v)[1]
        else:
            dvc = ctl(ev.x, ev.v)[0]
        seg = period_step(P, dx, dv, dvc, delay=delay)
        dx, dv = seg.dx, seg.dv


# ==================================================================== watchdog (issue 27 §1)
RIG = (0.006031909726621269, -0.0060746847760492625, 3.0)   # design --optimize noise --delay 3
NO_WATCHDOG = dict(watchdog_misses=0, watchdog_pace=0.0, watchdog_lag=0.0,
                   watchdog_excursion=0.0)


def late_controller(c1, c2):
    """A controller that answers each sample only when the next one has gone out: 9.4 ms
    after it at time_scale 1000, past the 3 ms budget of delay 3 (a starved process)."""
    held = []

    def answer(loop, ev):
        if held:
            loop.answer(*held.pop())
        held.append((key(ev), law(c1, c2, ev)))
    return answer


def test_open_loop_under_load_trips_the_watchdog_and_nothing_acts_after_it():
    """The rig scene of issue 27 with every answer after its deadline: without the
    watchdog it runs all its periods open loop (missed = n, applied = 0, and nothing
    says so); with the default watchdog it stops at the 25th miss in 50 samples, having
    applied nothing, tells the sink why, and ignores every later answer."""
    c1, c2, delay = RIG
    n = 150
    base = dict(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=n,
                state_period=0.0)
    clock, sink = Clock(), Recorder()
    loop = run_realtime(settings(**base, **NO_WATCHDOG), n, late_controller(c1, c2), clock,
                        sink)
    assert len(sink.misses) == n and loop.stats["applied"] == 0 and not sink.trips
    assert loop.watchdog.tripped is None and "watchdog" not in loop.summary(1.0, {
        "missed": n, "timeouts": 0, "ignored": 0, "malformed": 0})

    clock, sink = Clock(), Recorder()
    loop = run_realtime(settings(**base), n, late_controller(c1, c2), clock, sink)
    trip = loop.watchdog.tripped
    assert sink.trips == [trip] and trip.kind == "misses" and trip.k == 24
    assert "25 of the last 50 samples without an answer in time" in trip.reason
    assert loop.finished and sink.finished == 1
    assert [m[0] for m in sink.misses] == list(range(24))   # the 25th: the trip, not acted
    assert loop.stats["applied"] == 0 and not sink.substitutions
    got = np.array([(e.x, e.v) for e in sink.samples()])
    assert len(got) == 25
    np.testing.assert_array_equal(got, reference(25, 0.0, 0.0, 0, delay))
    # the safe state: an answer after the trip is ignored, the plant does not move
    k, events = loop.engine.k, len(sink.events)
    loop.answer(key(sink.samples()[-1]), 1e-3)
    clock.now += 1.0
    assert loop.tick() is None
    assert loop.engine.k == k and len(sink.events) == events and loop.stats["applied"] == 0
    assert sink.counts["ignored"] == 1
    summary = loop.summary(1.0, {"missed": 24, "timeouts": 0, "ignored": 1, "malformed": 0})
    assert summary.endswith("watchdog=misses tripped_at=24")


def test_on_arrival_an_answer_after_the_next_sample_is_a_miss():
    c1, c2, _ = RIG
    s = settings(mode="realtime", time_scale=1000.0, max_periods=100, state_period=0.0,
                 watchdog_window=10, watchdog_misses=4)
    clock, sink = Clock(), Recorder()
    loop = run_realtime(s, 100, late_controller(c1, c2), clock, sink)
    trip = loop.watchdog.tripped
    # sample k's miss is seen when sample k + 1 goes out; the 4th (sample 3) at sample 4
    assert trip.kind == "misses" and trip.k == 3 and len(sink.samples()) == 4
    assert loop.stats["late"] == 3 and loop.stats["applied"] == 3


class SlowSink(Recorder):
    """Publishing a Pi2 sample costs ``cost`` wall seconds (a machine that cannot keep up)."""

    def __init__(self, clock, cost):
        super().__init__()
        self.clock, self.cost = clock, cost

    def publish(self, ev):
        if ev.kind == "pi2":
            self.clock.now += self.cost
        return super().publish(ev)


def test_a_simulator_that_cannot_keep_pace_trips_on_pace():
    """Each sample costs 20 ms of wall time, a period 9.4 ms at time_scale 1000: the
    loop falls behind at 0.47 of the requested pace; the watchdog trips on the first
    full window (sample 50), before the lag reaches 1 s (0.53 s there). (The misses,
    which a loop publishing its samples in bursts also has, are off here.)"""
    clock = Clock()
    sink = SlowSink(clock, 0.02)
    s = settings(mode="realtime", time_scale=1000.0, max_periods=200, state_period=0.0,
                 watchdog_misses=0)
    loop = run_realtime(s, 200, lambda loop, ev: loop.answer(key(ev), 0.0), clock, sink)
    trip = loop.watchdog.tripped
    assert trip.kind == "pace" and trip.k == 50, trip
    assert f"pace {P.period / 20.0:.3g} of time_scale 1000" in trip.reason
    assert max(loop.lags) < 1.0


def test_a_stall_trips_on_the_lag():
    clock, sink = Clock(), Recorder()
    stalled = []

    def answer(loop, ev):
        loop.answer(key(ev), 0.0)
        if round(ev.t / P.period) == 30 and not stalled:
            stalled.append(True)
            clock.now += 1.5                          # the process did not run for 1.5 s

    s = settings(mode="realtime", time_scale=1000.0, max_periods=200, state_period=0.0,
                 watchdog_misses=0)
    loop = run_realtime(s, 200, answer, clock, sink)
    trip = loop.watchdog.tripped
    # the sample went out 1.5 s late: the plant's clock paused for it (stall_pause), the
    # watchdog's lag against the wall clock kept it
    assert trip.kind == "lag" and trip.k == 31 and loop.lags[-1] + loop.paused > 1.0


def test_a_loop_that_loses_the_orbit_while_correcting_trips_on_the_excursion():
    """Corrections in time but destabilising (c1 = 0, c2 = +0.5: the state is 35 times
    the bound away after 50 samples, ``simulate``): once they have acted for a window
    (samples 1..50; sample 0, at X**, is corrected by 0) the state is beyond 15
    sqrt(|Delta d|) of X**, and the trip names the distance and the bound."""
    delay = 3.0
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=300,
                 state_period=0.0)
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        clock.now += 1e-3
        loop.answer(key(ev), law(0.0, 0.5, ev))

    loop = run_realtime(s, 300, answer, clock, sink)
    trip = loop.watchdog.tripped
    assert trip is not None and trip.kind == "excursion", (trip, loop.engine.k)
    bound = 15.0 * math.sqrt(-P.delta_d)
    last = sink.samples()[-1]
    assert math.hypot(last.x - P.x_ref, last.v - P.v_ref) > bound
    assert trip.k == 51 and f"= {bound:.3g}" in trip.reason
    assert loop.stats["applied"] == 51 and not sink.misses


def test_a_reset_after_a_trip_starts_a_new_run_with_a_new_watchdog():
    """~/reset after a trip: sample 0 again, the trip forgotten by the loop (the node keeps
    it for its exit status), answers in time act again."""
    c1, c2, delay = RIG
    s = settings(mode="realtime", time_scale=1000.0, actuation_delay=delay, max_periods=100,
                 state_period=0.0, watchdog_window=4, watchdog_misses=2)
    clock, sink = Clock(), Recorder()
    loop = run_realtime(s, 100, late_controller(c1, c2), clock, sink)
    assert loop.watchdog.tripped.k == 1 and loop.finished
    loop.reset(loop.engine.reset())
    assert loop.watchdog.tripped is None and not loop.finished
    ev = sink.samples()[-1]
    assert ev.t == 0.0
    clock.now += 1e-3
    loop.answer(key(ev), 1e-4)
    clock.now += 5e-3
    loop.tick()
    assert loop.stats["applied"] == 1 and loop.engine.k == 0


def test_each_pi2_sample_goes_out_before_its_period_is_integrated():
    """The period's integration (0.6-0.7 ms of CPU at a rig's 150 stream samples a
    period) came before the sample went out, so every sample was that much late
    (docs/rig_scene.md, "Where the time went"): the sample is published first."""
    clock, sink = Clock(), Recorder()
    engine = Engine(settings(mode="realtime", time_scale=1000.0, max_periods=5,
                             state_period=P.period / 50))
    order = []
    integrate = engine.begin_period

    def begin_period(*args, **kwargs):
        order.append(("integrate", engine.k))
        return integrate(*args, **kwargs)

    engine.begin_period = begin_period
    loop = Realtime(engine, sink, clock)
    published = sink.publish

    def publish(ev):
        if ev.kind == "pi2":
            order.append(("pi2", engine.k))
        return published(ev)

    sink.publish = publish
    loop.start()
    while not loop.finished:
        clock.now += loop.wake_in(loop.now())
        loop.tick()
    pi2 = [k for what, k in order if what == "pi2"]
    assert len(pi2) == 5
    for k in pi2:
        assert order.index(("pi2", k)) < order.index(("integrate", k))


def test_the_stream_gathers_for_the_loops_stream_tick():
    """sim_node's stream_block: the stream's events of a wake-up gather for stream_tick
    of wall time (a DAQ's block); the Pi2 samples still go out exactly when due."""
    for tick in (STREAM_TICK, 4 * STREAM_TICK):
        clock, sink = Clock(), Recorder()
        s = settings(mode="realtime", time_scale=1000.0, max_periods=4,
                     state_period=P.period / 400)
        loop = Realtime(Engine(s), sink, clock)
        loop.stream_tick = tick
        loop.start()
        waits = []
        while not loop.finished:
            w = loop.wake_in(loop.now())
            waits.append(w)
            clock.now += w
            loop.tick()
        stream = [w for w in waits if w < CLOCK_TICK]
        # between two Pi2 samples the wake-ups come every tick (the last may be shorter)
        assert min(stream) >= MIN_TICK
        assert sorted(stream)[len(stream) // 2] == pytest.approx(tick)
        pi2 = [e.t for e in sink.events if e.kind == "pi2"]
        assert len(pi2) >= 4 and pi2 == pytest.approx([k * P.period for k in range(len(pi2))])


def record_acts(loop, acts):
    """Wrap the loop's ActuationSchedule.act (as sim_node's rig does): ``acts`` receives
    (k, start, value, outcome) of every section that acted."""
    act = loop.schedule.act

    def recorded(sec, lost=False, on_miss="predict"):
        done = act(sec, lost=lost, on_miss=on_miss)
        acts.append((sec.k, sec.start, done.value, done.outcome))
        return done

    loop.schedule.act = recorded

"""The plant's engine without ROS (grazing_control.plant.engine): its periods against the
core's period_step, its events on their grid, its end of run.

tests/test_sim_node.py and tests/test_actuation.py hold the engine's earlier
specifications (reproduces simulate; delayed periods bit for bit on both paths; faults
per sample); these add the sample grid of the state stream, the split against
period_step's delay, and the end of a run.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.dynamics.simulation.simulate import period_step
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

P = OscillatorParams(delta_d=-5e-6)


def settings(**kw):
    return settings_from_values({"delta_d": P.delta_d, **kw})


def test_state_events_lie_on_one_grid_across_periods_and_splits():
    sp = P.period / 7.31                  # no grid point on a sample within 30 periods
    eng = Engine(settings(state_period=sp))
    times = []
    for k in range(30):
        events = eng.begin_period(0.0)
        if k % 3 == 0:                       # a split re-evaluates the rest of the period
            events = [e for e in events if e.t < eng.t + 2.0] + eng.split(eng.t + 2.0, 0.0)
        times += [e.t for e in events if e.kind == "state"]
        eng.end_period()
    j = np.round(np.array(times) / sp)
    np.testing.assert_allclose(times, j * sp, rtol=0, atol=1e-9)
    assert list(j) == list(range(1, len(j) + 1))          # every grid point once
    assert len(times) == math.ceil(30 * P.period / sp) - 1


def test_split_equals_period_step_with_that_delay():
    rng = np.random.default_rng(3)
    for _ in range(40):
        eng = Engine(settings(delta_d=-10 ** rng.uniform(-6, -2)))
        for _ in range(3):
            tc, dvc = rng.uniform(0.0, eng.p.period), rng.normal(0, 0.05)
            ref = period_step(eng.p, eng.dx, eng.dv, dvc, delay=tc)
            eng.begin_period(0.0)
            events = eng.split(eng.t + tc, dvc)
            assert sum(e.kind == "impact" for e in events) == \
                sum(i.dt > tc for i in ref.impacts)
            assert eng.seg.dx_end == pytest.approx(ref.dx, abs=1e-12)
            assert eng.seg.dv_end == pytest.approx(ref.dv, abs=1e-12)
            eng.end_period()


def test_done_after_max_periods_only():
    eng = Engine(settings(max_periods=3))
    flags = []
    for _ in range(3):
        flags.append(eng.done)
        eng.begin_period(0.0)
        eng.end_period()
    assert flags == [False] * 3 and eng.done
    assert not Engine(settings(max_periods=0)).done


def test_reset_returns_sample_zero_and_forgets_the_run():
    eng = Engine(settings(x0=-0.5, v0=-1.0, noise=1e-4, seed=2))
    first = eng.sample()
    for _ in range(4):
        eng.begin_period(0.0)
        eng.end_period()
    again = eng.reset()
    assert (again.t, again.x, again.v) == (first.t, first.x, first.v)
    assert eng.k == 0 and eng.impacts == 0


def test_a_drifting_wall_is_the_cores_plant_at_k_and_restarts_on_reset():
    """delta_d_drift (issue 29): period k runs with Delta d + drift k, each period the
    core's period_step with that model bit for bit (a correction, a delay of 3); the
    drift's ramp starts again at a reset; drift 0 leaves the model untouched."""
    drift = 5e-10
    eng = Engine(settings(delta_d_drift=drift, x0=P.x_ref + 1e-3))
    z = (eng.dx, eng.dv)
    for k in range(6):
        assert eng.p == P.with_(delta_d=P.delta_d + drift * k)
        ref = period_step(P.with_(delta_d=P.delta_d + drift * k), *z, 1e-3 * k, delay=3.0)
        eng.begin_period(1e-3 * k, 3.0)
        assert (eng.seg.dx_end, eng.seg.dv_end) == (ref.dx, ref.dv)
        eng.end_period()
        z = (ref.dx, ref.dv)
    eng.reset()
    assert eng.p == P
    eng.begin_period(0.0)
    eng.end_period()
    assert eng.p == P.with_(delta_d=P.delta_d + drift)
    still = Engine(settings())
    for _ in range(3):
        still.begin_period(0.0)
        still.end_period()
    assert still.p is still.settings.params


# ========================================================== the rig: pulse and sensor
def test_pulse_periods_are_the_cores_pulse_step_bit_for_bit_on_both_paths():
    """A pulse of width w centred at the actuation delay: lockstep (begin_period with the
    delay) and realtime (begin_period(0), then actuate at the deadline) both equal
    dynamics.simulation.actuation.pulse_step(start = delay - w/2) bit for bit, force limit too."""
    from grazing_control.dynamics.simulation.actuation import pulse_step

    rng = np.random.default_rng(21)
    for _ in range(40):
        w, limit = rng.uniform(0.01, 1.0), rng.choice([0.0, 0.05])
        delay = rng.uniform(w / 2, P.period - w / 2 - 1e-9)
        s = settings(delta_d=-10 ** rng.uniform(-6, -2), pulse_width=w, force_limit=limit,
                     actuation_delay=delay, state_period=0.3)
        a, b = Engine(s), Engine(s)
        for _ in range(3):
            dvc = rng.normal(0, 0.05)
            ref = pulse_step(s.params, a.dx, a.dv, dvc, start=delay - w / 2, width=w,
                             force_limit=limit or math.inf)
            ev_a = a.begin_period(dvc, delay)
            ev_b = [e for e in b.begin_period(0.0) if e.t < b.t + delay - w / 2]
            ev_b += b.actuate(dvc, delay)
            assert (a.seg.dx_end, a.seg.dv_end) == (ref.dx, ref.dv)
            assert (b.seg.dx_end, b.seg.dv_end) == (ref.dx, ref.dv)
            assert sum(e.kind == "impact" for e in ev_a) == len(ref.impacts)
            assert [e.kind for e in ev_a] == [e.kind for e in ev_b]
            a.end_period()
            b.end_period()


def test_pulse_width_zero_is_the_kick_and_the_pulse_converges_to_it():
    """w = 0 takes the kick's path (period_step with the delay, bit for bit); the pulse's
    end state approaches the kick's as O(w^2) when centred at the delay
    (docs/theory_pulse.md): halving w divides the difference by about 4."""
    p, delay, dvc = P.with_(delta_d=-1e-2), 4.0, 0.03
    kick = period_step(p, 0.0, 0.0, dvc, delay=delay)
    eng = Engine(settings(delta_d=-1e-2, actuation_delay=delay))
    eng.begin_period(dvc, delay)
    assert (eng.seg.dx_end, eng.seg.dv_end) == (kick.dx, kick.dv)
    errs = []
    for w in (0.4, 0.2, 0.1):
        eng = Engine(settings(delta_d=-1e-2, actuation_delay=delay, pulse_width=w))
        eng.begin_period(dvc, delay)
        errs.append(math.hypot(eng.seg.dx_end - kick.dx, eng.seg.dv_end - kick.dv))
    assert 3.5 < errs[0] / errs[1] < 4.5 and 3.5 < errs[1] / errs[2] < 4.5, errs


def test_states_during_a_pulse_follow_the_flow_under_its_force():
    """The stream's samples inside the pulse are the exact flow under the constant force
    (dynamics.simulation.actuation.flow_with_force from the pulse's start), not the free flow."""
    from grazing_control.dynamics.simulation.actuation import flow_with_force
    from grazing_control.oscillator import kernel
    from grazing_control.oscillator.flow import to_physical

    w, delay, dvc = 2.0, 3.0, 0.05
    s = settings(delta_d=-1e-2, pulse_width=w, actuation_delay=delay, state_period=0.25)
    eng = Engine(s)
    p = eng.p
    events = eng.begin_period(dvc, delay)
    start = delay - w / 2
    inside = [e for e in events if e.kind == "state" and start < e.t < start + w]
    assert len(inside) == 7                            # 2.25, 2.5, ..., 3.75
    h0 = kernel.exact_advance()(p, p.tau2, 0.0, 0.0, start)
    tau_s = (p.tau2 + p.omega * start) % (2 * math.pi)
    for e in inside:
        seg = flow_with_force(p, tau_s, h0.dx, h0.dv, e.t - start, dvc / w)
        x, v = to_physical(p, tau_s + p.omega * (e.t - start), seg.dx, seg.dv)
        assert (e.x, e.v) == pytest.approx((x, v), abs=1e-12)


def test_the_stream_carries_the_sensors_measurement_of_each_grid_sample():
    """oscillator/state sample j is SensorModel.measure of the true state at j*state_period
    (a pure function of (sensor_seed, j)); the noise has the configured std, the bias its
    mean, the quantiser its grid; position only leaves the velocity out (NaN)."""
    from grazing_control.plant.sensor import SensorModel

    sp, sigma, bias, q = P.period / 200, 1e-4, 3e-4, 1e-6
    runs = {}
    for name, kw in (("true", {}), ("noisy", {"sensor_noise": sigma, "sensor_seed": 4,
                                                "sensor_bias": bias}),
                     ("rig", {"sensor_noise": sigma, "sensor_seed": 4, "sensor_bias": bias,
                              "sensor_quantum": q, "sensor_velocity": False})):
        eng = Engine(settings(state_period=sp, **kw))
        states = eng.initial_states()
        for _ in range(40):
            states += [e for e in eng.begin_period(0.0) if e.kind == "state"]
            eng.end_period()
        runs[name] = np.array([(e.t, e.x, e.v) for e in states])
    true, noisy, rig = runs["true"], runs["noisy"], runs["rig"]
    n = len(true)
    assert n == 40 * 200 + 1 and true[0, 0] == 0.0             # t = 0 and every grid point
    np.testing.assert_allclose(true[:, 0], np.arange(n) * sp, rtol=0, atol=1e-9)
    ex, ev = noisy[:, 1] - true[:, 1], noisy[:, 2] - true[:, 2]
    assert abs(ex.mean() - bias) < 4 * sigma / math.sqrt(n)
    assert abs(ex.std() / sigma - 1) < 4 / math.sqrt(2 * n)
    assert abs(ev.mean()) < 4 * sigma / math.sqrt(n) and abs(ev.std() / sigma - 1) < 0.05
    assert abs(np.corrcoef(ex, ev)[0, 1]) < 4 / math.sqrt(n)
    ref = SensorModel(noise=sigma, seed=4, bias=bias).measure(0, true[:, 1], true[:, 2])
    np.testing.assert_array_equal(noisy[:, 1], ref[0])         # sample j's draws
    assert np.all(np.isnan(rig[:, 2]))
    np.testing.assert_allclose(rig[:, 1] / q, np.round(rig[:, 1] / q), rtol=0, atol=1e-6)
    assert np.abs(rig[:, 1] - noisy[:, 1]).max() <= q / 2 + 1e-15

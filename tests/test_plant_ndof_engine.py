"""The n-DOF scene in the plant, without middleware (grazing_control.plant.ndof_engine).

References: the core's NdofMap (the period map the design and shooting use) and its
advance; the engine must repeat NdofMap's iterates bit for bit where it makes the same
calls, publish states between samples that are the core's trajectory, and, driven by the
lockstep and realtime loops with the n-DOF law, take the period-doubled motion near
grazing of config/models/two_mass_scene.yaml to the controlled 1/1 orbit that Newton
shooting finds on NdofMap with the same gains.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.ndof_design import gain_family
from grazing_control.dynamics.maps.ndof_map import NdofMap
from grazing_control.dynamics.orbits.shooting import find_periodic
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.plant.engine import Event
from grazing_control.plant.lockstep import Lockstep
from grazing_control.plant.ndof_engine import NdofEngine, NdofEvent
from grazing_control.plant.ndof_settings import ndof_settings_from_values
from grazing_control.plant.realtime import Realtime
from test_plant_loops import Clock, Recorder

ROOT = Path(__file__).resolve().parents[1]
SCENE = str(ROOT / "config" / "models" / "two_mass_scene.yaml")
CHAIN = str(ROOT / "config" / "models" / "two_mass_chain.yaml")


def settings(path=SCENE, **kw):
    return ndof_settings_from_values(kw, path)


def xv(ev):
    return np.array(ev.x + ev.v)


def test_uncontrolled_samples_are_ndofmap_iterates_bit_for_bit():
    s = settings(CHAIN, delta_d=-1e-3, state_period=0.7)
    eng, P = NdofEngine(s), NdofMap(s.model)
    z = np.zeros(4)
    impacts = 0
    for k in range(60):
        step = P.step(z)
        events = eng.begin_period(0.0)
        ev, warning = eng.end_period()
        assert warning is None and ev.kind == "pi2" and ev.t == (k + 1) * s.model.period
        z = step.state
        assert np.array_equal(eng.z, z), k
        assert [e.t for e in events] == sorted(e.t for e in events)
        imp = [e for e in events if e.kind == "impact"]
        assert [(e.x, e.v) for e in imp] == [(i.v_minus, i.v_plus) for i in step.impacts]
        assert sum(e.kind == "pi1" for e in events) == 1
        impacts += len(imp)
    assert impacts > 20                     # the motion impacts: the check is not vacuous
    # the published sample is the physical state X** + z at the section
    np.testing.assert_array_equal(xv(eng.sample()),
                                  eng.flow.to_physical(eng.flow.tau2, eng.z))


def test_controlled_samples_are_ndofmap_with_gains_bit_for_bit():
    s = settings(delta_d=-1e-4)
    k = gain_family(s.model, 0.1)
    eng, P = NdofEngine(s), NdofMap(s.model, k)
    z = np.zeros(4)
    for _ in range(40):
        eng.begin_period(float(P.gains @ eng.z))   # NdofMap's kick, k^T z
        eng.end_period()
        z = P.step(z).state
        assert np.array_equal(eng.z, z)


def test_states_between_samples_are_the_cores_trajectory():
    """The stream and Pi1 come from the impact list (free flow + velocity jumps): each
    equals advance from the period's start to its time (an independent evaluation)."""
    s = settings(CHAIN, delta_d=-1e-2, state_period=0.37)
    eng = NdofEngine(s)
    checked = 0
    for _ in range(8):
        z0, tau2 = eng.z.copy(), eng.flow.tau2
        events = eng.begin_period(0.0)
        for e in events:
            if e.kind == "impact":
                assert isinstance(e, Event) and e.x > 0 and e.v == pytest.approx(-0.68 * e.x)
                continue
            assert isinstance(e, NdofEvent) and len(e.x) == len(e.v) == 2
            h = e.t - eng.seg.ts
            ref = advance(eng.flow, tau2, z0, h)
            X = eng.flow.to_physical(ref.tau, ref.z)
            np.testing.assert_allclose(xv(e), X, rtol=0, atol=1e-12)
            if e.kind == "pi1":
                assert e.phase == eng.flow.tau_star
            checked += 1
        eng.end_period()
    assert checked > 8 * 20
    grid = [e.t for e in events if e.kind == "state"]
    assert np.allclose(np.array(grid) / 0.37, np.round(np.array(grid) / 0.37), atol=1e-9)


def test_a_delayed_kick_is_the_flow_to_it_the_jump_and_the_flow_on():
    s = settings(actuation_delay=3.0)
    eng = NdofEngine(s)
    m, f = s.model, eng.flow
    for dv in (0.0, 2e-3, -1e-3):
        z0 = eng.z.copy()
        eng.begin_period(dv, 3.0)
        head = advance(f, f.tau2, z0, 3.0)
        zk = head.z.copy()
        zk[m.n + m.i_a] += dv
        tail = advance(f, (f.tau2 + m.omega * 3.0) % (2 * math.pi), zk, m.period - 3.0)
        eng.end_period()
        assert np.array_equal(eng.z, tail.z)
    # realtime's actuate at the deadline repeats the lockstep period bit for bit
    a, b = NdofEngine(s), NdofEngine(s)
    for dv in (1e-3, -2e-3, 0.0):
        a.begin_period(dv, 3.0)
        b.begin_period(0.0)
        b.actuate(dv, 3.0)
        a.end_period(), b.end_period()
        assert np.array_equal(a.z, b.z)


def test_a_split_without_correction_keeps_the_trajectory():
    s = settings(CHAIN, delta_d=-1e-3)
    a, b = NdofEngine(s), NdofEngine(s)
    for _ in range(6):
        a.begin_period(0.0)
        b.begin_period(0.0)
        b.split(b.seg.ts + 1.3, 0.0)
        a.end_period(), b.end_period()
        np.testing.assert_allclose(a.z, b.z, rtol=0, atol=1e-12)


class NdofLaw:
    """Delta v = k^T (X - X**) on the published sample, as controller_node computes it."""

    def __init__(self, s, k, on):
        f = NdofMap(s.model).flow
        self.ref, self.k, self.on = f.particular(f.tau2), k, on

    def __call__(self, ev, count):
        return float(self.k @ (xv(ev) - self.ref)) if count >= self.on else 0.0


def scene_orbit(s, k, z_last):
    """The controlled 1/1 orbit by Newton shooting on NdofMap (the acceptance reference)."""
    P = NdofMap(s.model, k)
    orbit = find_periodic(P, z_last)
    return P.flow.particular(P.flow.tau2) + orbit.state, orbit


def test_lockstep_suppresses_the_period_doubled_motion_near_grazing():
    """config/models/two_mass_scene.yaml at Delta d = -1e-5: period 2 (one impact every
    second period) uncontrolled; with k(mu = 0) switched on at sample 150 the samples
    converge to the controlled 1/1 orbit, one impact per period."""
    n, on = 210, 150
    s = settings(max_periods=n, state_period=0.0)
    k = gain_family(s.model, 0.0)
    law = NdofLaw(s, k, on)
    sink = Recorder()
    loop = Lockstep(NdofEngine(s), sink, Clock())
    loop.start()
    while not loop.finished:
        loop.answer(loop.waiting, law(sink.samples()[-1], loop.engine.k))
    X = np.array([xv(e) for e in sink.samples()])
    assert X.shape == (n, 4)
    # uncontrolled: period 2 (not 1) before the switch-on
    before = X[on - 20:on]
    assert np.max(np.abs(before[2:] - before[:-2])) < 1e-8
    assert np.min(np.max(np.abs(before[1:] - before[:-1]), axis=1)) > 1e-3
    impacts = [e.t // s.model.period for e in sink.events if e.kind == "impact"]
    counts = np.bincount(np.array(impacts, int), minlength=n)
    assert set(counts[on - 20:on]) == {0, 1}
    # controlled: the exact 1/1 orbit, one impact per period
    orbit_X, orbit = scene_orbit(s, k, X[-1] - law.ref)
    assert np.max(np.abs(X[-1] - orbit_X)) < 1e-12
    assert list(counts[-20:-1]) == [1] * 19 and len(orbit.impacts) == 1
    assert np.max(np.abs(np.linalg.eigvals(orbit.monodromy))) < 1.0


def test_realtime_scheduled_is_the_lockstep_run_bit_for_bit():
    n, on, delay = 40, 10, 2.0
    base = dict(max_periods=n, state_period=0.0, actuation_delay=delay)
    k = gain_family(settings().model, 0.0)
    runs = []
    for mode in ("lockstep", "realtime"):
        s = settings(mode=mode, time_scale=1000.0, **base)
        law = NdofLaw(s, k, on)
        sink, clock = Recorder(), Clock()
        loop = (Lockstep if mode == "lockstep" else Realtime)(NdofEngine(s), sink, clock)
        loop.start()
        seen = 0
        while not loop.finished:
            samples = sink.samples()
            if mode == "lockstep":
                loop.answer(loop.waiting, law(samples[-1], loop.engine.k))
                continue
            while seen < len(samples):
                ev = samples[seen]
                loop.answer(divmod(int(round(ev.t * 1e9)), 10**9), law(ev, seen))
                seen += 1
            clock.now += loop.wake_in(loop.now())
            loop.tick()
        assert loop.stats["applied"] == n and loop.stats["late"] == 0
        runs.append(np.array([xv(e) for e in sink.samples()]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_injected_loss_and_jitter_are_the_fault_models_draws():
    """loss drops the corrections FaultModel.draw(k) drops; jitter moves each kick to
    actuation_delay + e_k (FaultModel.actuation_delay), as in 1-DOF."""
    n = 30
    s = settings(max_periods=n, state_period=0.0, actuation_delay=4.0, jitter=0.5,
                 loss=0.3, seed=11)
    sink = Recorder()
    loop = Lockstep(NdofEngine(s), sink, Clock())
    loop.start()
    while not loop.finished:
        loop.answer(loop.waiting, 1e-4)
    lost = [s.faults.draw(k).dropped for k in range(n)]
    assert loop.stats["lost"] == sum(lost) and 0 < sum(lost) < n
    # the reference: the engine's calls by hand, the delays and losses drawn from the model
    eng = NdofEngine(s)
    f, m = eng.flow, s.model
    z = np.zeros(4)
    for k in range(n):
        delay = s.faults.actuation_delay(4.0, k, m.period)
        assert delay != 4.0
        head = advance(f, f.tau2, z, delay)
        zk = head.z.copy()
        zk[m.n + m.i_a] += 0.0 if lost[k] else 1e-4
        z = advance(f, (f.tau2 + m.omega * delay) % (2 * math.pi), zk, m.period - delay).z
    np.testing.assert_array_equal(loop.engine.z, z)      # after the last period


def test_a_delay_aware_design_run_is_the_delayed_ndofmap_sample_for_sample():
    """Issue 32: the lockstep engine with the kick k^T z_k acting ``delay`` after each
    sample (k the delay-aware design, ndof_design.gain_family(..., delay)) is the core's
    NdofMap(model, k, delay) iteration, bit for bit, impacts included."""
    from grazing_control.dynamics.design.ndof_design import evaluate_design

    delay = 1.0
    s = settings(CHAIN, delta_d=-1e-3, actuation_delay=delay)
    design = evaluate_design(s.model, -0.22, delay)
    assert design.admissible
    eng, P = NdofEngine(s), NdofMap(s.model, design.gains, delay)
    z, impacts = np.full(4, 1e-3), 0
    eng.z = z.copy()
    for k in range(60):
        assert np.array_equal(eng.z, z), k
        events = eng.begin_period(float(P.gains @ eng.z), eng.actuation_delay())
        step = P.step(z)
        imp = [e for e in events if e.kind == "impact"]
        assert [(e.x, e.v) for e in imp] == [(i.v_minus, i.v_plus) for i in step.impacts]
        impacts += len(imp)
        eng.end_period()
        z = step.state
    assert impacts >= 50                    # the controlled orbit impacts once a period


@pytest.mark.parametrize("velocity", [True, False])
def test_the_stream_is_the_exact_flow_plus_the_sensors_seeded_noise(velocity):
    """Issue 32: an n-DOF scene's sensor (sensor_noise, sensor_velocity, sensor_seed)
    measures every coordinate: stream sample j's coordinate i is the exact flow at t_j
    (the core's advance from the period's start, an independent route) plus sigma times
    the sensor's draw j n + i (SensorModel.draws; velocity NaN for a position-only
    sensor), however the period is cut by a delayed kick."""
    sigma, h = 1e-4, 4.0 * math.pi / 200
    s = settings(CHAIN, delta_d=-1e-3, state_period=h, sensor_noise=sigma,
                 sensor_velocity=velocity, sensor_seed=7, actuation_delay=1.0)
    assert "sensor noise=0.0001" in s.describe()
    eng = NdofEngine(s)
    f, m = eng.flow, s.model
    draws = s.sensor.draws(0, 2 * 6 * 200 + 2).reshape(-1, 2, 2)   # (j, coordinate, x/v)
    states = eng.initial_states()
    for k in range(5):
        z0 = eng.z.copy()
        evs = eng.begin_period(2e-3 * (-1) ** k, 1.0)
        for e in [e for e in evs if e.kind == "state"]:
            rel = e.t - k * m.period
            if rel <= 1.0:
                ref = advance(f, f.tau2, z0, rel)
            else:
                head = advance(f, f.tau2, z0, 1.0)
                zk = head.z.copy()
                zk[m.n + m.i_a] += 2e-3 * (-1) ** k
                ref = advance(f, (f.tau2 + m.omega) % (2 * math.pi), zk, rel - 1.0)
            X = f.to_physical(ref.tau, ref.z)
            j = round(e.t / h)
            np.testing.assert_allclose(e.x, X[:2] + sigma * draws[j, :, 0], rtol=0,
                                       atol=1e-12)
            if velocity:
                np.testing.assert_allclose(e.v, X[2:] + sigma * draws[j, :, 1], rtol=0,
                                           atol=1e-12)
            else:
                assert all(math.isnan(v) for v in e.v)
            states.append(e)
        eng.end_period()
    # samples 0 .. 999 (the one at 5 T, j h = 20 pi up to rounding, may fall in period 5)
    assert len(states) >= 5 * 200 and states[0].t == 0.0
    # the sample at t = 0 too, and the draws are the 1-DOF sensor's for coordinate 0
    assert states[0].x[0] == pytest.approx(f.particular(f.tau2)[0] + sigma * draws[0, 0, 0],
                                           abs=1e-15)

"""The plant's engine without ROS (grazing_control.plant.engine): its periods against the
core's period_step, its events on their grid, its end of run.

tests/test_sim_node.py and tests/test_actuation.py hold the engine's earlier
specifications (reproduces simulate; delayed periods bit for bit on both paths; faults
per sample); these add the sample grid of the state stream, the split against
period_step's delay, and the end of a run. benchmarks/fold_hashes.py's scenes, run here
against the hashes recorded on main before the fold of issue 32 (:data:`MAIN_HASHES`),
keep every 1-DOF scene bit for bit.

The n-DOF scene runs on the same engine (a model file in the settings, issue 32). Its
references are the core's ModalMap (the period map the design and shooting use) and its
advance: the engine must repeat ModalMap's iterates bit for bit where it makes the same
calls, publish states between samples that are the core's trajectory, and, driven by the
lockstep and realtime loops with the n-DOF law, take the period-doubled motion near
grazing of config/models/two_mass_scene.yaml to the controlled 1/1 orbit that Newton
shooting finds on ModalMap with the same gains.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.family import gain_family
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.shooting import find_periodic
from grazing_control.dynamics.simulation.simulate import period_step
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine, Event, NdofEvent
from grazing_control.plant.lockstep import Lockstep
from grazing_control.plant.realtime import Realtime
from grazing_control.plant.settings import settings_from_values
from test_plant_loops import Clock, Recorder

ROOT = Path(__file__).resolve().parents[1]
SCENE = str(ROOT / "config" / "models" / "two_mass_scene.yaml")
CHAIN = str(ROOT / "config" / "models" / "two_mass_chain.yaml")
STUDY_1DOF = str(ROOT / "config" / "models" / "study_1dof.yaml")

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


def test_a_pulse_at_a_start_given_is_the_cores_pulse_step_and_the_reference_flow():
    """A start given (a rig's command timed off its section, plant.realtime): begin_head
    and actuate with ``start`` are pulse_step(start=) bit for bit, and the motion is an
    independent reference's (tests/reference_actuator.py: DOP853 at rtol 1e-13 of
    x'' + 2 zeta x' + x = cos(tau2 + omega t) + F on the pulse, the impact law at the
    wall) to 1e-10, at starts off t_k + delay - w/2 up to the slot's end T - w."""
    from grazing_control.dynamics.simulation.actuation import pulse_step
    from reference_actuator import lag_reference, pulse_pieces

    w, delay = 0.3, 2.0
    s = settings(delta_d=-1e-2, pulse_width=w, actuation_delay=delay, state_period=0.0)
    p = s.params
    room = p.period - w
    worst, impacts = 0.0, 0
    for start, dvc in ((0.0, 0.04), (0.37, -0.03), (3.1, 0.05), (5.0, 0.2),
                       (math.nextafter(room, 0.0), 0.02)):
        eng = Engine(s)
        eng.dx, eng.dv = 1e-3, -2e-3
        head = eng.begin_head(delay, start)
        assert all(e.t <= start for e in head)
        tail = eng.actuate(dvc, delay, start)
        assert all(e.t >= start for e in tail)
        ref = pulse_step(p, 1e-3, -2e-3, dvc, start=start, width=w)
        assert (eng.seg.dx_end, eng.seg.dv_end) == (ref.dx, ref.dv)
        y, hits, _ = lag_reference(p, p.x_ref + 1e-3, p.v_ref - 2e-3, 0.0,
                                   pulse_pieces(start, w, dvc / w, 0.0), p.period,
                                   max_step=0.01)
        assert len(hits) == len(ref.impacts) == sum(e.kind == "impact" for e in head + tail)
        impacts += len(hits)
        worst = max(worst, abs(y[0] - p.x_ref - ref.dx), abs(y[1] - p.v_ref - ref.dv))
    assert worst < 1e-10, worst
    assert impacts >= 1                 # (5.0, 0.2) pushes the mass onto the wall


def test_an_ndof_pulse_at_a_start_given_is_the_period_of_that_actuation_instant():
    """n-DOF: begin_head and actuate with the start given repeat the period whose own
    actuation instant is that start (begin_period with its delay) bit for bit."""
    s = model_settings(actuation_delay=3.0, pulse_width=0.2)
    a, b = Engine(s), Engine(s)
    for delay, dv in ((3.0, 1e-3), (0.1, -2e-3), (5.5, 0.0)):
        start = a.actuation_start(delay)
        a.begin_period(dv, delay)
        b.begin_head(3.0, start)
        b.actuate(dv, 3.0, start)
        a.end_period(), b.end_period()
        assert np.array_equal(a.z, b.z)


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


# ------------------------------------------------------------ bit for bit across the fold
#: `.venv/bin/python benchmarks/fold_hashes.py` on main 5b8ea17, before the fold of the
#: plant (issue 32): the 1-DOF engine's events over its seeded scenes and the n-DOF
#: engine's (then plant.ndof_engine) over a two-mass scene.
MAIN_HASHES = {
    "stream_noise_faults_delay": "0c48afdcf138acbf240df75915ae942c30dce2e7d8203af8f117cffd5d89591c",
    "pulse": "77800b363f1502c13b025c2d65d870e469ae581ad8371dccbee6e0260618e533",
    "actuator": "81b74bf196186e8daa8c08fdf6df56cf20e0716fab1d156d845a50b6a1f061a3",
    "contact_friction": "540176ee5ae0f328a85a91842039e1ae19134ed64653dc4403dfc95bf4ddf431",
    "drift": "17733624c4723988188119b490efe72bce78e790e034232827a091aa21e4ea34",
    "on_arrival": "42dc44f719a9ff612c12660cfeacd1b124820570d8e9c709c679bef4c18b9c4e",
    "pending": "8be224f838afda9a0afd0bd432386020dc719d57d94067eabc8b20326645a425",
    # the n-DOF scene's hash since the compiled n-DOF search (issue 32, ebf72ed): its pure
    # twin's gap evaluator is set up in plain floats, term by term (the compiled one's
    # order), not by NumPy's reductions; against the events of a688280, 9915 of 16524
    # differ, the first by one ulp in x at an impact, at most 4.6e-11 relative after the
    # scene's own growth (main before the fold: 819ffd684e9a...). Since the compiled n-DOF
    # advance (issue 32, h-ndof-advance): Phi(h) and the products of the flow with impacts
    # in a fixed order of real operations (ndof/flow.py transition, matvec), not BLAS's;
    # against 26c69b67450a..., 14084 of 16524 events differ, the first by one ulp in v at
    # a sample (t = 21.1), at most 2.8e-11 relative after the scene's growth
    "ndof_two_mass": "ddedf5eadcde2ffa4993698ebc20d2aed4ae226ce61c66e85e53dbe3618b8c95",
}


def test_the_folded_engine_repeats_mains_events_bit_for_bit():
    """Every scene of benchmarks/fold_hashes.py (stream, sensor, noise, loss, jitter, delay,
    pulse, actuator, compliant stop with friction, drift, pending change, on arrival, and
    the n-DOF scene) hashes as it did on main before the fold."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import fold_hashes
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    got = {name: fold_hashes.run(name, values) for name, values in fold_hashes.SCENES.items()}
    got["ndof_two_mass"] = fold_hashes.run_ndof(fold_hashes.NDOF_SCENE)
    assert got == MAIN_HASHES


# ------------------------------------------------------------------- the n-DOF scene
def model_settings(path=SCENE, **kw):
    return settings_from_values(kw, path)


def xv(ev):
    return np.array(ev.x + ev.v)


def test_uncontrolled_samples_are_ndofmap_iterates_bit_for_bit():
    s = model_settings(CHAIN, delta_d=-1e-3, state_period=0.7)
    eng, P = Engine(s), ModalMap(s.model)
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
                                  eng.section.flow.to_physical(eng.section.flow.tau2, eng.z))


def test_controlled_samples_are_ndofmap_with_gains_bit_for_bit():
    s = model_settings(delta_d=-1e-4)
    k = gain_family(s.model, 0.1)
    eng, P = Engine(s), ModalMap(s.model, k)
    z = np.zeros(4)
    for _ in range(40):
        eng.begin_period(float(P.gains @ eng.z))   # ModalMap's kick, k^T z
        eng.end_period()
        z = P.step(z).state
        assert np.array_equal(eng.z, z)


def test_an_n_dof_drifting_wall_is_ndofmap_at_the_drifted_delta_d_bit_for_bit():
    """delta_d_drift in an n-DOF scene (issue 32): period k runs with Delta d + drift k,
    each period ModalMap of the model at that Delta d (with the gains and a delay of 1)
    bit for bit, the wall moved far enough to change the impacts; the ramp starts again
    at a reset; the flow's decomposition is kept (the same eigenvalues object). The
    realtime path (begin_head, then actuate at the deadline) gives the same states."""
    drift, delay = -1e-4, 1.0          # from 1e-3 (out of reach) to -2.9e-3 (impacting)
    s = model_settings(CHAIN, delta_d=1e-3, delta_d_drift=drift, actuation_delay=delay)
    k = gain_family(s.model, 0.1)
    eng, rt, z, impacts = Engine(s), Engine(s), np.zeros(4), []
    flow0 = eng.section.flow
    for j in range(40):
        model = dataclasses.replace(s.model, delta_d=s.model.delta_d + drift * j)
        assert eng.section.model.delta_d == model.delta_d and eng.p is eng.section
        assert eng.section.flow.model is eng.section.model
        assert eng.section.flow.eigenvalues is flow0.eigenvalues
        step = ModalMap(model, k, delay).step(z)
        eng.begin_period(float(k @ eng.z), delay)
        eng.end_period()
        rt.begin_head(delay)
        rt.actuate(float(k @ rt.z), delay)
        rt.end_period()
        z = step.state
        impacts.append(len(step.impacts))
        assert np.array_equal(eng.z, z) and np.array_equal(rt.z, z), j
    assert impacts[0] == 0 and sum(impacts) > 10, impacts     # the wall came into reach
    eng.reset()
    assert eng.section.flow is flow0 and eng.k == 0
    eng.begin_period(0.0)
    eng.end_period()
    assert eng.section.model.delta_d == s.model.delta_d + drift


def test_a_start_state_starts_ndofmap_iterates_bit_for_bit():
    """Issue 32: an n-DOF scene from a physical start X0 (state0, 2n values) starts at
    z = X0 - X_p(tau2) and repeats ModalMap's iterates from there, controlled, bit for
    bit; a reset goes back to it."""
    f = ModalMap(model_settings(CHAIN, delta_d=-1e-3).model).flow
    X0 = f.particular(f.tau2) + np.array([-0.05, 0.02, 0.01, -0.03])
    s = model_settings(CHAIN, delta_d=-1e-3, state0=X0.tolist())
    assert s.state0 == tuple(X0.tolist())
    k = gain_family(s.model, 0.1)
    eng, P = Engine(s), ModalMap(s.model, k)
    z = f.to_deviation(f.tau2, X0)
    assert np.array_equal(eng.z, z) and abs(np.max(np.abs(z)) - 0.05) < 1e-15
    np.testing.assert_allclose(xv(eng.sample()), X0, rtol=0, atol=1e-15)
    impacts = 0
    for _ in range(40):
        eng.begin_period(float(P.gains @ eng.z))   # ModalMap's kick, k^T z
        eng.end_period()
        step = P.step(z)
        z = step.state
        impacts += len(step.impacts)
        assert np.array_equal(eng.z, z)
    assert impacts > 10
    eng.reset()
    assert eng.k == 0 and np.array_equal(eng.z, f.to_deviation(f.tau2, X0))


def test_the_velocity_noise_at_pi2_is_the_one_dof_draws_on_the_actuated_velocity():
    """Issue 32: ``noise`` in an n-DOF scene is the 1-DOF definition (a Gaussian velocity
    kick at every Pi2 sample, one draw of the generator seeded with ``seed``), on the
    actuated coordinate's velocity: ModalMap's iterates with that kick, bit for bit; for
    n = 1 through the model file the 1-DOF scene's draws, bit for bit."""
    sigma, seed = 1e-3, 5
    s = model_settings(CHAIN, delta_d=-1e-3, noise=sigma, seed=seed)
    eng, P = Engine(s), ModalMap(s.model)
    rng = np.random.default_rng(seed)
    z = eng.section.kicked(np.zeros(4), rng.normal(0.0, sigma))
    assert np.array_equal(eng.z, z) and z[3] != 0.0 and not z[:3].any()   # i_a = 1
    for _ in range(30):
        eng.begin_period(0.0)
        eng.end_period()
        z = eng.section.kicked(P.step(z).state, rng.normal(0.0, sigma))
        assert np.array_equal(eng.z, z)
    eng.reset()                                 # the generator is seeded again
    assert np.array_equal(eng.z, eng.section.kicked(np.zeros(4),
                                                     np.random.default_rng(seed).normal(
                                                         0.0, sigma)))
    # n = 1: the model file's draws are the 1-DOF scene's (the states differ: two flows)
    one = Engine(model_settings(STUDY_1DOF, noise=sigma, seed=seed))
    study = Engine(settings_from_values({"noise": sigma, "seed": seed, "delta_d": -5e-6}))
    rng = np.random.default_rng(seed)
    w = rng.normal(0.0, sigma)
    assert one.z[1] == study.dv == w and one.z[0] == study.dx == 0.0
    for _ in range(20):
        one.begin_period(0.0)
        study.begin_period(0.0)
        z_end, dv_end = one.seg.z_end, study.seg.dv_end
        one.end_period()
        study.end_period()
        w = rng.normal(0.0, sigma)
        assert one.z[1] == z_end[1] + w and study.dv == dv_end + w


def test_the_measurement_noise_is_a_seeded_draw_per_coordinate():
    """Issue 32: ``measurement_noise`` on every coordinate of the published n-DOF sample k,
    a pure function of (seed, k) (FaultModel.coordinate_noise): coordinate 0's draws are
    the 1-DOF FaultModel.draw(k)'s, so n = 1 through the model file is the 1-DOF scene's
    bit for bit; the others are further draws, independent, of std sigma."""
    sigma, seed = 2e-4, 9
    s = model_settings(CHAIN, delta_d=-1e-3, measurement_noise=sigma, seed=seed)
    eng = Engine(s)
    noise = []
    for k in range(300):
        ev = eng.sample()
        m = eng.measured(ev)
        nx, nv = s.faults.coordinate_noise(k, 2)
        assert m.x == tuple(float(a) for a in np.array(ev.x) + nx), k
        assert m.v == tuple(float(a) for a in np.array(ev.v) + nv), k
        d = s.faults.draw(k)
        assert (nx[0], nv[0]) == (d.noise_x, d.noise_v)
        assert eng.sample() == ev           # the true state is untouched
        noise.append(np.concatenate([nx, nv]))
        eng.begin_period(0.0)
        eng.end_period()
    noise = np.array(noise)
    std = noise.std(axis=0) / sigma
    assert np.all((0.85 < std) & (std < 1.15)), std
    corr = np.corrcoef(noise.T) - np.eye(4)
    assert np.max(np.abs(corr)) < 0.2, corr
    # the same (seed, k): the same draws, from another engine, after a reset
    again = Engine(s)
    assert again.measured(again.sample()) == Engine(s).measured(Engine(s).sample())
    # n = 1: the 1-DOF scene's measured sample's offsets
    one = Engine(model_settings(STUDY_1DOF, measurement_noise=sigma, seed=seed))
    study = Engine(settings_from_values({"measurement_noise": sigma, "seed": seed,
                                         "delta_d": -5e-6}))
    for k in range(5):
        a, b = one.sample(), study.sample()
        ma, mb = one.measured(a), study.measured(b)
        d = s.faults.draw(k)
        assert (ma.x[0], ma.v[0]) == (a.x[0] + d.noise_x, a.v[0] + d.noise_v)
        assert (mb.x, mb.v) == (b.x + d.noise_x, b.v + d.noise_v)
        for e in (one, study):
            e.begin_period(0.0)
            e.end_period()


def test_states_between_samples_are_the_cores_trajectory():
    """The stream and Pi1 come from the impact list (free flow + velocity jumps): each
    equals advance from the period's start to its time (an independent evaluation)."""
    s = model_settings(CHAIN, delta_d=-1e-2, state_period=0.37)
    eng = Engine(s)
    checked = 0
    for _ in range(8):
        z0, tau2 = eng.z.copy(), eng.section.flow.tau2
        events = eng.begin_period(0.0)
        for e in events:
            if e.kind == "impact":
                assert isinstance(e, Event) and e.x > 0 and e.v == pytest.approx(-0.68 * e.x)
                continue
            assert isinstance(e, NdofEvent) and len(e.x) == len(e.v) == 2
            h = e.t - eng.seg.ts
            ref = advance(eng.section.flow, tau2, z0, h)
            X = eng.section.flow.to_physical(ref.tau, ref.z)
            np.testing.assert_allclose(xv(e), X, rtol=0, atol=1e-12)
            if e.kind == "pi1":
                assert e.phase == eng.section.flow.tau_star
            checked += 1
        eng.end_period()
    assert checked > 8 * 20
    grid = [e.t for e in events if e.kind == "state"]
    assert np.allclose(np.array(grid) / 0.37, np.round(np.array(grid) / 0.37), atol=1e-9)


def test_a_delayed_kick_is_the_flow_to_it_the_jump_and_the_flow_on():
    s = model_settings(actuation_delay=3.0)
    eng = Engine(s)
    m, f = s.model, eng.section.flow
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
    a, b = Engine(s), Engine(s)
    for dv in (1e-3, -2e-3, 0.0):
        a.begin_period(dv, 3.0)
        b.begin_period(0.0)
        b.actuate(dv, 3.0)
        a.end_period(), b.end_period()
        assert np.array_equal(a.z, b.z)


def test_a_split_without_correction_keeps_the_trajectory():
    s = model_settings(CHAIN, delta_d=-1e-3)
    a, b = Engine(s), Engine(s)
    for _ in range(6):
        a.begin_period(0.0)
        b.begin_period(0.0)
        b.split(b.seg.ts + 1.3, 0.0)
        a.end_period(), b.end_period()
        np.testing.assert_allclose(a.z, b.z, rtol=0, atol=1e-12)


class NdofLaw:
    """Delta v = k^T (X - X**) on the published sample, as controller_node computes it."""

    def __init__(self, s, k, on):
        f = ModalMap(s.model).flow
        self.ref, self.k, self.on = f.particular(f.tau2), k, on

    def __call__(self, ev, count):
        return float(self.k @ (xv(ev) - self.ref)) if count >= self.on else 0.0


def scene_orbit(s, k, z_last):
    """The controlled 1/1 orbit by Newton shooting on ModalMap (the acceptance reference)."""
    P = ModalMap(s.model, k)
    orbit = find_periodic(P, z_last)
    return P.flow.particular(P.flow.tau2) + orbit.state, orbit


def test_lockstep_suppresses_the_period_doubled_motion_near_grazing():
    """config/models/two_mass_scene.yaml at Delta d = -1e-5: period 2 (one impact every
    second period) uncontrolled; with k(mu = 0) switched on at sample 150 the samples
    converge to the controlled 1/1 orbit, one impact per period."""
    n, on = 210, 150
    s = model_settings(max_periods=n, state_period=0.0)
    k = gain_family(s.model, 0.0)
    law = NdofLaw(s, k, on)
    sink = Recorder()
    loop = Lockstep(Engine(s), sink, Clock())
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
    k = gain_family(model_settings().model, 0.0)
    runs = []
    for mode in ("lockstep", "realtime"):
        s = model_settings(mode=mode, time_scale=1000.0, **base)
        law = NdofLaw(s, k, on)
        sink, clock = Recorder(), Clock()
        loop = (Lockstep if mode == "lockstep" else Realtime)(Engine(s), sink, clock)
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
    s = model_settings(max_periods=n, state_period=0.0, actuation_delay=4.0, jitter=0.5,
                 loss=0.3, seed=11)
    sink = Recorder()
    loop = Lockstep(Engine(s), sink, Clock())
    loop.start()
    while not loop.finished:
        loop.answer(loop.waiting, 1e-4)
    lost = [s.faults.draw(k).dropped for k in range(n)]
    assert loop.stats["lost"] == sum(lost) and 0 < sum(lost) < n
    # the reference: the engine's calls by hand, the delays and losses drawn from the model
    eng = Engine(s)
    f, m = eng.section.flow, s.model
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
    sample (k the delay-aware design, family.gain_family(..., delay)) is the core's
    ModalMap(model, k, delay) iteration, bit for bit, impacts included."""
    from grazing_control.dynamics.design.family import evaluate_design

    delay = 1.0
    s = model_settings(CHAIN, delta_d=-1e-3, actuation_delay=delay)
    design = evaluate_design(s.model, -0.22, delay)
    assert design.admissible
    eng, P = Engine(s), ModalMap(s.model, design.gains, delay)
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
    s = model_settings(CHAIN, delta_d=-1e-3, state_period=h, sensor_noise=sigma,
                 sensor_velocity=velocity, sensor_seed=7, actuation_delay=1.0)
    assert "sensor noise=0.0001" in s.describe()
    eng = Engine(s)
    f, m = eng.section.flow, s.model
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


def test_a_pulsed_run_is_ndofmap_with_the_width_bit_for_bit_on_both_paths():
    """Issue 32: with ``pulse_width`` the correction k^T z_k is the force pulse
    F = m_a k^T z_k / w centred ``actuation_delay`` after the sample
    (docs/theory_ndof.md section 15): the lockstep period (begin_period) and the realtime
    one (begin_head, then actuate at the deadline) are ModalMap(model, k, delay, width)'s
    iterates bit for bit, impacts included; the stream's states during the pulse are the
    flow under its force (advance_with_force from the pulse's start, independent of the
    engine's evaluation from the impact list)."""
    from grazing_control.dynamics.design.family import pulse_design
    from grazing_control.oscillator.ndof.forced import advance_with_force

    delay, width = 1.0, 1.0
    s = model_settings(CHAIN, delta_d=-1e-3, actuation_delay=delay, pulse_width=width,
                       state_period=0.05)
    design = pulse_design(s.model, -0.22, delay, width)
    assert design.admissible
    a, b = Engine(s), Engine(s)
    P = ModalMap(s.model, design.gains, delay, width)
    f = a.section.flow
    z, impacts, during = np.full(4, 1e-3), 0, 0
    a.z, b.z = z.copy(), z.copy()
    for k in range(40):
        dv = float(P.gains @ z)
        events = a.begin_period(dv, a.actuation_delay())
        b.begin_head(delay)
        b.actuate(dv, delay)
        step = P.step(z)
        imp = [e for e in events if e.kind == "impact"]
        assert [(e.x, e.v) for e in imp] == [(i.v_minus, i.v_plus) for i in step.impacts]
        impacts += len(imp)
        start = a.actuation_start(delay)
        t0 = a.t
        force = a.section.pulse_force(dv, width)
        head = advance(f, f.tau2, z, start)
        for e in events:
            if e.kind == "state" and t0 + start < e.t <= t0 + start + width:
                ref = advance_with_force(f, (f.tau2 + s.model.omega * start) % (2 * math.pi),
                                         head.z, e.t - t0 - start, force)
                X = f.to_physical(ref.tau, ref.z)
                np.testing.assert_allclose(xv(e), X, rtol=0, atol=1e-12)
                during += 1
        a.end_period(), b.end_period()
        z = step.state
        assert np.array_equal(a.z, z) and np.array_equal(b.z, z), k
    assert impacts >= 35 and during >= 40 * 19     # impacts once a period; 20 states a pulse
    assert abs(force) > 1e-6                       # the pulse pushes: not vacuous


def test_a_sticking_period_of_the_wall_coordinate_is_the_cores():
    """Issue 32 (docs/theory_ndof.md section 16): a 2-DOF scene whose wall coordinate
    sits at rest on the wall pushed into it (tests/models/two_mass_chain_w08.yaml at
    Delta d = -3): the engine's period is the core's advance (a sticking impact with its
    release, then flights and impacts), the stream's states while stuck hold x_w = d at
    rest and equal advance from the period's start, and the run goes on after it (the
    scene refused this motion before issue 32's section 16)."""
    s = model_settings(str(ROOT / "tests" / "models" / "two_mass_chain_w08.yaml"),
                       delta_d=-3.0, state_period=0.3)
    eng = Engine(s)
    f, m = eng.section.flow, s.model
    n, w = m.n, m.i_w
    z = np.zeros(2 * n)
    z[w], z[n + w] = f.on_wall(f.tau2)
    assert f.wall_acceleration(f.tau2, z) > 0.5         # pushed into the wall
    eng.z = z.copy()
    ref = advance(f, f.tau2, z, m.period)
    events = eng.begin_period(0.0)
    (stick,) = eng.seg.impacts
    assert stick.sticking and 1.0 < stick.release < m.period
    assert [(e.x, e.v) for e in events if e.kind == "impact"] == [
        (i.v_minus, i.v_plus) for i in ref.impacts]
    stuck = free = 0
    for e in events:
        if e.kind == "impact":
            continue
        h = e.t - eng.seg.ts
        X = f.to_physical(*(lambda r: (r.tau, r.z))(advance(f, f.tau2, z, h)))
        np.testing.assert_allclose(xv(e), X, rtol=0, atol=1e-12)
        if h < stick.release:
            assert e.x[w] == pytest.approx(f.d_star + m.delta_d, abs=1e-12) and abs(e.v[w]) < 1e-12
            stuck += 1
        else:
            free += e.x[w] < f.d_star + m.delta_d - 1e-6      # released: off the wall
    assert stuck >= 10 and free >= 5
    eng.end_period()
    np.testing.assert_array_equal(eng.z, ref.z)
    impacts = 0
    for _ in range(3):                                   # and the scene goes on, impacting
        impacts += sum(e.kind == "impact" for e in eng.begin_period(0.0))
        eng.end_period()
    assert impacts >= 6


@pytest.mark.parametrize("tau_a, latency", [(1.5, 0.2), (0.0, 0.2)])
def test_through_the_actuator_a_run_is_actuated_steps_iterates_bit_for_bit(tau_a, latency):
    """Issue 32 (docs/theory_ndof.md section 15): with ``actuator_bandwidth`` 1 / tau_a
    and ``actuator_latency`` L the command m_a k^T z / w on [start + L, start + L + w]
    reaches x1 through the lag, the force a state carried from sample to sample: the
    lockstep periods and the realtime ones (begin_head, actuate) are
    modal_map.actuated_step's iterates bit for bit, force included (tau_a = 0: the pulse
    L later); the stream's states are lag_advance from each piece's start (1e-12)."""
    from grazing_control.dynamics.design.family import pulse_design
    from grazing_control.dynamics.maps.modal_map import actuated_step
    from grazing_control.oscillator.ndof.forced import lag_advance

    delay, width = 1.0, 1.0
    bw = 0.0 if tau_a == 0.0 else 1.0 / tau_a
    s = model_settings(CHAIN, delta_d=-1e-3, actuation_delay=delay, pulse_width=width,
                       actuator_bandwidth=bw, actuator_latency=latency, state_period=0.1)
    k = pulse_design(s.model, -0.22, delay, width).gains
    a, b = Engine(s), Engine(s)
    f = a.section.flow
    z, force, impacts, checked = np.full(4, 1e-3), 0.0, 0, 0
    a.z, b.z = z.copy(), z.copy()
    start = a.actuation_start(delay)
    for n in range(25):
        dv = float(k @ z)
        events = a.begin_period(dv, delay)
        b.begin_head(delay)
        b.actuate(dv, delay)
        z1, force1, imps = actuated_step(f, z, force, dv, start=start, width=width,
                                         time_constant=tau_a, latency=latency)
        got = [(e.x, e.v) for e in events if e.kind == "impact"]
        assert got == [(i.v_minus, i.v_plus) for i in imps], n
        impacts += len(got)
        if tau_a:                   # the states of the piece under the commanded force
            on, off, t0 = start + latency, start + latency + width, a.t
            first = lag_advance(f, f.tau2, z, on, 0.0, force, tau_a)
            u = a.section.pulse_force(dv, width)
            tau_on = (f.tau2 + s.model.omega * on) % (2 * math.pi)
            for e in events:
                if e.kind == "state" and t0 + on < e.t <= t0 + off:
                    ref = lag_advance(f, tau_on, first.z, e.t - t0 - on, u,
                                      first.force - u, tau_a)
                    np.testing.assert_allclose(xv(e), f.to_physical(ref.tau, ref.z),
                                               rtol=0, atol=1e-12)
                    checked += 1
        a.end_period(), b.end_period()
        z, force = z1, force1
        assert np.array_equal(a.z, z) and np.array_equal(b.z, z), n
        assert a.force == force == b.force
    assert impacts >= 20 and (checked >= 25 * 9 or not tau_a)
    assert tau_a == 0.0 or abs(force) > 1e-8        # the force carries over the sample

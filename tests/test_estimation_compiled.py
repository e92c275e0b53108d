"""The compiled model filter (issue 30) against the core's: the same numbers bit for bit.

``trajectory(..., kernel=True)`` runs the kernel's exact flow and the evaluation at the
samples of dynamics/estimation/compiled_flow.py; a StreamEstimator uses it by default
where numba is installed. Nothing may change but the time: here every output of
:func:`trajectory` over seeded cases with impacts, pulses (impacts inside them too) and
the wall's sensitivity, and every answer of a controller replaying a recorded scene's
whole stream (estimate, covariance, correction, prediction), compared with ``==``.
(Speed is measured in benchmarks/bench_stream_estimator.py, not here.)
"""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from grazing_control.dynamics.estimation.compiled_flow import event_offsets  # noqa: E402
from grazing_control.dynamics.estimation.motion import trajectory  # noqa: E402
from grazing_control.dynamics.estimation.stream import (StreamEstimator,  # noqa: E402
                                                        predict_section, simulate_stream)
from grazing_control.dynamics.design.tuning import optimize_noise  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.plant.sensor import SensorModel  # noqa: E402

P = OscillatorParams(delta_d=-5e-6)


def _same(a, b):
    """Equal bit for bit (NaN where NaN), through nested tuples, lists and arrays."""
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def test_event_offsets_is_numpys_search():
    rng = np.random.default_rng(3)
    for _ in range(200):
        times = np.sort(rng.uniform(0.0, 9.0, rng.integers(1, 6)))
        times[0] = 0.0
        s = np.concatenate([rng.uniform(-1.0, 10.0, 50), times, [math.nan]])
        idx, hh = event_offsets(times, s)
        ref = np.clip(np.searchsorted(times, s, side="left") - 1, 0, times.size - 1)
        assert np.array_equal(idx, ref)
        assert _same(hh, s - times[ref])


@pytest.mark.parametrize("width", [0.0, 0.1, 0.5])
def test_trajectory_compiled_is_the_core_bit_for_bit(width):
    rng = np.random.default_rng(11)
    s = np.arange(1, 200) * P.period / 200
    impacts = 0
    for _ in range(150):
        z = tuple(rng.normal(0.0, 3e-2, 2))
        dv = float(rng.normal(0.0, 5e-3))
        delay = float(rng.uniform(0.0, 6.0))
        for wall in (False, True):
            kw = dict(width=width, force_limit=0.05 if width == 0.5 else math.inf, wall=wall)
            try:
                ref = trajectory(P, z, s, dv, delay, **kw)
            except ValueError:          # sticking: raised alike
                with pytest.raises(ValueError):
                    trajectory(P, z, s, dv, delay, kernel=True, **kw)
                continue
            new = trajectory(P, z, s, dv, delay, kernel=True, **kw)
            assert _same(new[:4], ref[:4]) and _same(new[5:], ref[5:])
            assert new[4] == ref[4]
            impacts += len(ref[4])
    assert impacts > 100                # the cases cross the wall


@pytest.mark.parametrize("kernel", [False, True])
def test_the_prediction_is_the_trajectorys_end_bit_for_bit(kernel):
    """predict_section takes the end alone (trajectory_end, issue 30: the controller's
    prediction on the realtime answer's path): the same numbers as trajectory's ``end``,
    and the same refusal where the motion sticks, kick and pulse, clipped or not."""
    rng = np.random.default_rng(5)
    impacts = 0
    for _ in range(150):
        z = tuple(rng.normal(0.0, 3e-2, 2))
        dv = float(rng.normal(0.0, 5e-3))
        delay = float(rng.uniform(0.0, 6.0))
        for width, limit in ((0.0, math.inf), (0.1, math.inf), (0.5, 0.05)):
            kw = dict(width=width, force_limit=limit, kernel=kernel)
            try:
                ref = trajectory(P, z, np.empty(0), dv, delay, **kw)
            except ValueError:          # sticking: raised alike
                with pytest.raises(ValueError):
                    predict_section(P, z, dv, delay, **kw)
                continue
            assert _same(predict_section(P, z, dv, delay, **kw), ref[2])
            impacts += len(ref[4])
    assert impacts > 100                # the cases cross the wall


@pytest.mark.parametrize("scene", ["rig", "t200"])
def test_replayed_stream_same_answers(scene):
    """A controller's answers over a recorded closed-loop stream (the rig scene's 2 ms
    pulse and answer lead, or the T/200 stream's pulse 0.1; uncontrolled, then
    controlled), the core's and the compiled filter's, equal bit for bit."""
    if scene == "rig":
        from grazing_control.plant.rig import load_rig
        from grazing_control.ros.rig_boundary import controller_values

        rig = load_rig("config/rigs/acceptance.yaml")
        p, d = rig.params(), rig.dimensionless()
        v = controller_values(rig, 0.03276358910091768)
        g, rate = Gains(v["c1"], v["c2"], v["actuation_delay"]), 150
        kw = dict(sigma=d["sensor_noise"], sample_period=p.period / rate,
                  lead=v["answer_lead"], pulse_width=d["pulse_width"],
                  force_limit=d["force_limit"])
    else:
        p, rate = P, 200
        n = optimize_noise(p, 3.0)
        g = Gains(n.c1, n.c2, 3.0)
        kw = dict(sigma=1e-4, sample_period=p.period / rate, pulse_width=0.1)
    samples = []

    class Recording(StreamEstimator):     # the samples of both paths, in order
        def add_sample(self, t, x, v=math.nan):
            samples.append((t, x, v))
            return super().add_sample(t, x, v)

        def add_plain(self, t, x, v):
            samples.extend(zip(t, x, v))
            super().add_plain(t, x, v)

    simulate_stream(p, g, SensorModel(noise=kw["sigma"], velocity=False, seed=5).measure,
                    120, rate, sigma=kw["sigma"], control_after=40,
                    stream_estimator=Recording(p, kernel=False, **kw),
                    pulse_width=kw["pulse_width"], force_limit=kw.get("force_limit", math.inf))

    def answers(compiled):
        est = StreamEstimator(p, kernel=compiled, **kw)
        out = []
        for t, x, v in samples:
            for k, _tk, e in est.add_sample(t, x, v):
                dv = g.c1 * e.z[0] + g.c2 * e.z[1] if k >= 40 else 0.0
                pred = predict_section(p, e.z, dv, g.delay, width=est.pulse[0],
                                       force_limit=est.pulse[1], kernel=compiled)
                est.set_correction(k, dv, g.delay)
                out.append((k, e.source, e.z, e.cov, dv, pred))
        return out, est.resets

    core, new = answers(False), answers(True)
    assert len(core[0]) == 121 and sum(a[1] == "model" for a in core[0]) > 100
    assert _same([a[2:] for a in new[0]], [a[2:] for a in core[0]])
    assert [a[:2] for a in new[0]] == [a[:2] for a in core[0]] and new[1] == core[1]


def _two_mass_model():
    from grazing_control.plant.rig import load_rig

    return load_rig("config/rigs/two_mass_beam.yaml")


@pytest.mark.parametrize("width, limit", [(0.0, math.inf), (0.12649110640673517, 4.0),
                                          (0.5, 0.05)])
def test_n_dof_trajectory_compiled_is_the_core_bit_for_bit(width, limit):
    """The n-DOF model filter's motion (issue 32): the evaluation at the samples of
    dynamics/estimation/compiled_modal_flow.py against motion.modal_trajectory's NumPy, every output
    (samples, Jacobians, end, monodromy, impacts) equal, over seeded starts with impacts,
    kicks, pulses and clipped pulses (the rig's 2 ms pulse at its 20 N limit)."""
    model = _two_mass_model().model()
    s = np.arange(1, 493) * (model.period / 500)
    rng = np.random.default_rng(17)
    impacts = 0
    for _ in range(60):
        z = rng.normal(0.0, 3e-2, 4)
        dv = float(rng.normal(0.0, 5e-3))
        delay = float(rng.uniform(0.0, 6.0))
        try:
            ref = trajectory(model, z, s, dv, delay, width=width, force_limit=limit)
        except ValueError:              # sticking: raised alike
            with pytest.raises(ValueError):
                trajectory(model, z, s, dv, delay, width=width, force_limit=limit,
                           kernel=True)
            continue
        new = trajectory(model, z, s, dv, delay, width=width, force_limit=limit, kernel=True)
        assert _same(new[:4], ref[:4]) and new[4] == ref[4]
        impacts += len(ref[4])
    assert impacts > 20                 # the cases cross the wall


def test_n_dof_replayed_stream_same_answers():
    """The two-mass rig's controller over a closed-loop stream of its measured mass (the
    engine with the rig's sensor and 2 ms pulse, 2 uncontrolled and 10 controlled
    periods): the estimates, covariances, corrections and predictions of the core's and
    the compiled model filter, equal bit for bit."""
    from grazing_control.plant.engine import Engine
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros.controller_values import (model_controller_from_values,
                                                       pulse_from_values)
    from grazing_control.ros.rig_boundary import controller_values, sim_values

    rig = _two_mass_model()
    v = controller_values(rig, math.nan)
    ndof = model_controller_from_values(v, "two_mass_beam.yaml", v["gains"], rig.model())
    model, k, delay = ndof.model, np.asarray(ndof.gains), v["actuation_delay"]
    pulse = pulse_from_values({**v, "actuator_latency": 0.0}, model.omega, delay)
    kw = dict(sigma=v["sensor_noise"], sample_period=v["state_period"],
              lead=v["answer_lead"], pulse_width=pulse[0], force_limit=pulse[1],
              coordinate=v["sensor_coordinate"])
    sv = {key: val for key, val in sim_values(rig).items()
          if key not in ("time_scale", "pre_roll")}
    eng = Engine(settings_from_values({**sv, "sensor_seed": 5}, "two_mass_beam.yaml", model))
    c, samples = kw["coordinate"], []
    est = StreamEstimator(model, kernel=False, **kw)
    due = []
    for ev in eng.initial_states():
        samples.append((ev.t, ev.x[c]))
        due += est.add_sample(ev.t, ev.x[c])
    for j in range(12):
        due += est.flush(j)
        (e,) = [d[2] for d in due if d[0] == j]
        dv = float(k @ np.asarray(e.z)) if j >= 2 else 0.0
        est.set_correction(j, dv, delay)
        due = []
        for ev in eng.begin_period(dv, delay):
            if ev.kind == "state":
                samples.append((ev.t, ev.x[c]))
                due += est.add_sample(ev.t, ev.x[c])
        eng.end_period()

    def answers(compiled):
        est = StreamEstimator(model, kernel=compiled, **kw)
        out = []
        for t, x in samples:
            for j, _tk, e in est.add_sample(t, x):
                z = np.asarray(e.z)
                dv = float(k @ z) if j >= 2 else 0.0
                pred = ndof.predict(ndof.x_ref + z[:2], ndof.v_ref + z[2:], dv, delay, pulse,
                                    est.section_force(est.next_k - 1))
                est.set_correction(j, dv, delay)
                out.append((j, e.source, e.z, e.cov, dv, pred))
        return out, est.resets

    core, new = answers(False), answers(True)
    assert len(core[0]) >= 12 and sum(a[1] == "model" for a in core[0]) >= 10
    assert _same([a[2:] for a in new[0]], [a[2:] for a in core[0]])
    assert [a[:2] for a in new[0]] == [a[:2] for a in core[0]] and new[1] == core[1]

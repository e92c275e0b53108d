"""The controller's compute per section on a sensor stream, in-process (issue 30).

What controller_node does with each stream sample (``add_stream_sample``, no middleware):
:meth:`StreamEstimator.add_sample`, and for each section it makes due Eq. 28 on the
estimate, the prediction of the next correction (:func:`predict_section`, with the force
the earlier corrections left, as ``_predict``) and :meth:`StreamEstimator.set_correction`.
The stream is a scene's, recorded once by the closed loop of the core
(:func:`simulate_stream`: the exact plant with the pulse, the sensor's seeded noise),
then replayed sample by sample into a fresh estimator per path, the paths interleaved in
one process (``--rounds`` alternations, the percentiles over all of them):

* ``core``: the model filter and the prediction in the pure-Python core and NumPy
  (``kernel=False``: the code of main before issue 30's change);
* ``kernel``: compiled (``kernel=True``, what a StreamEstimator uses by default where
  numba is installed: the kernel's exact flow and the evaluation at the samples of
  dynamics/estimation/compiled_flow.py).

Scenes (``--scene``): ``rig``, the acceptance rig of issue 28 (config/rigs/acceptance.yaml:
150 samples a period, position only, 2 ms pulse, the answer 4 ms before the section's
last sample, the controller's gains at c2 = 0.03276); ``t200``, the realtime stream of
bench_stream_blocks.py (T/200, sigma 1e-4, pulse 0.1 at delay 3, the least-noise gains for
delay 3); ``masses``, the two-mass rig of issue 32 (config/rigs/two_mass_beam.yaml: the
n-DOF model filter on mass 1 at 500 samples a period with the 4 ms answer lead, its
gains, ``ModelController.predict`` with the 2 ms pulse; ``--noise-um`` another sensor
noise; the compiled path there is the evaluation at the samples of
dynamics/estimation/compiled_modal_flow.py and the n-DOF event search, flow with impacts
and period's events of oscillator/kernel/compiled_modal.py; the core path runs the pure
ones with GRAZING_KERNEL=python). ``--paths core``
runs one path alone (with ``PYTHONPATH=/work/main``: main's). Printed per path: the time of a section's answer (the add_sample that makes it
due through the prediction), the time of a sample that makes none due (p50/p99/max, µs),
their ratio core/kernel, and whether the two paths gave the same estimates, covariances,
corrections and predictions bit for bit (they must: the kernel's flow is the core's,
tests/test_kernel.py and tests/test_estimation_compiled.py).

    .venv/bin/python benchmarks/bench_stream_estimator.py [--scene rig|t200]
        [--periods 400] [--enable-after 100] [--rounds 3]

Results in docs/benchmarks.md ("The controller's compute per section").
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from grazing_control.dynamics.estimation.stream import (StreamEstimator,  # noqa: E402
                                                        predict_section, simulate_stream,
                                                        warm_up)
from grazing_control.oscillator import kernel  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.plant.sensor import SensorModel  # noqa: E402

RIG_C2 = 0.03276358910091768


def rig_scene():
    """(p, gains, rate, estimator keywords) of the acceptance rig's controller."""
    from grazing_control.plant.rig import load_rig
    from grazing_control.ros.rig_boundary import controller_values

    rig = load_rig(ROOT / "config" / "rigs" / "acceptance.yaml")
    p, d = rig.params(), rig.dimensionless()
    v = controller_values(rig, RIG_C2)
    rate = round(p.period / d["state_period"])
    kw = dict(estimator="model", sigma=d["sensor_noise"], impact_source="stream",
              sample_period=p.period / rate, lead=v["answer_lead"],
              pulse_width=d["pulse_width"], force_limit=d["force_limit"] or math.inf)
    return p, Gains(v["c1"], v["c2"], v["actuation_delay"]), rate, kw


def t200_scene():
    """(p, gains, rate, estimator keywords) of bench_stream_blocks.py's stream."""
    from grazing_control.dynamics.design.tuning import optimize_noise
    from grazing_control.oscillator.params import OscillatorParams

    p = OscillatorParams(delta_d=-5e-6)
    rate = 200
    g = optimize_noise(p, 3.0)
    kw = dict(estimator="model", sigma=1e-4, impact_source="stream",
              sample_period=p.period / rate, pulse_width=0.1)
    return p, Gains(g.c1, g.c2, 3.0), rate, kw


def masses_scene(noise=None):
    """(model, ModelController, pulse, rate, estimator keywords) of the two-mass rig's
    controller (config/rigs/two_mass_beam.yaml, issue 32): controller_node's own
    construction (rig_boundary.controller_values, model_controller_from_values,
    pulse_from_values, model_stream_from_values), the sensor noise ``noise`` (m) where
    given."""
    from grazing_control.plant.rig import load_rig
    from grazing_control.ros.controller_values import (model_controller_from_values,
                                                       pulse_from_values)
    from grazing_control.ros.rig_boundary import controller_values

    rig = load_rig(ROOT / "config" / "rigs" / "two_mass_beam.yaml")
    v = controller_values(rig, math.nan)
    if noise is not None:
        v["sensor_noise"] = noise / rig.scales.length
    ndof = model_controller_from_values(v, "two_mass_beam.yaml", v["gains"], rig.model())
    pulse = pulse_from_values({**v, "actuator_latency": 0.0}, ndof.model.omega,
                              v["actuation_delay"])
    rate = round(ndof.model.period / v["state_period"])
    kw = dict(estimator="model", sigma=v["sensor_noise"], impact_source="stream",
              sample_period=v["state_period"], lead=v["answer_lead"], pulse_width=pulse[0],
              force_limit=pulse[1], coordinate=v["sensor_coordinate"])
    return rig, ndof, pulse, rate, v, kw


def record_masses(rig, ndof, v, kw, periods, enable_after, seed=7):
    """The two-mass rig's stream [(t, x~, v~)] of its measured coordinate in the closed
    loop in one process (studies.near_grazing.scene.stream_loop's calls: sim_node's
    engine with the rig's sensor and pulse, the estimator, k^T z^ from
    ``enable_after``)."""
    from grazing_control.plant.engine import Engine
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros.rig_boundary import sim_values

    sv = {key: val for key, val in sim_values(rig).items()
          if key not in ("time_scale", "pre_roll")}
    sv.update(sensor_noise=kw["sigma"], sensor_seed=seed)
    eng = Engine(settings_from_values(sv, "two_mass_beam.yaml", ndof.model))
    est = StreamEstimator(ndof.model, **kw)
    c, k, delay = kw["coordinate"], np.asarray(ndof.gains), v["actuation_delay"]
    samples, due = [], []

    def add(ev):
        samples.append((ev.t, ev.x[c], math.nan))
        return est.add_sample(ev.t, ev.x[c])

    for ev in eng.initial_states():
        due += add(ev)
    for j in range(periods):
        due += est.flush(j)
        (e,) = [d[2] for d in due if d[0] == j]
        dv = float(k @ np.asarray(e.z)) if j >= enable_after else 0.0
        est.set_correction(j, dv, delay)
        due = []
        for ev in eng.begin_period(dv, delay):
            if ev.kind == "state":
                due += add(ev)
        eng.end_period()
    return samples


def replay_masses(ndof, pulse, v, kw, samples, enable_after, compiled):
    """:func:`replay` of the n-DOF controller: controller_node's work on each sample with
    a rig of n masses (the estimate, k^T z^, the prediction ``ModelController.predict``
    with the pulse and the force left at the section, set_correction)."""
    est = StreamEstimator(ndof.model, kernel=compiled, **kw)
    n, k, delay = ndof.model.n, np.asarray(ndof.gains), v["actuation_delay"]
    clock, cpu = time.perf_counter, time.thread_time
    section_t, section_cpu, sample_t, answers = [], [], [], []
    for t, x, vv in samples:
        c0 = cpu()
        t0 = clock()
        due = est.add_sample(t, x, vv)
        for j, _tk, e in due:
            z = np.asarray(e.z)
            dv = float(k @ z) if j >= enable_after else 0.0
            force0 = est.section_force(est.next_k - 1)
            xn, vn = ndof.predict(ndof.x_ref + z[:n], ndof.v_ref + z[n:], dv, delay, pulse,
                                  force0)
            est.set_correction(j, dv, delay)
            answers.append((j, e.z, e.cov.tobytes(), dv, xn.tobytes(), vn.tobytes()))
        (section_t if due else sample_t).append(clock() - t0)
        if due:
            section_cpu.append(cpu() - c0)
    return np.array(section_t), np.array(section_cpu), np.array(sample_t), answers


@contextlib.contextmanager
def search_path(compiled):
    """The n-DOF event search of the path: the compiled one (oscillator/kernel/
    compiled_modal.py, loaded by kernel.warm_up_modal) for ``compiled``, else the pure
    one (GRAZING_KERNEL=python for the replay; the same floats)."""
    before = os.environ.get(kernel.ENV)
    if not compiled:
        os.environ[kernel.ENV] = "python"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(kernel.ENV, None)
        else:
            os.environ[kernel.ENV] = before


def record(p, gains, rate, kw, periods, enable_after, seed=7):
    """The stream's samples [(t, x~, v~)] of the closed loop in the core."""
    samples = []

    class Recording(StreamEstimator):     # the samples of both paths, in order
        def add_sample(self, t, x, v=math.nan):
            samples.append((t, x, v))
            return super().add_sample(t, x, v)

        def add_plain(self, t, x, v):
            samples.extend(zip(t, x, v))
            super().add_plain(t, x, v)

    est = Recording(p, **kw)
    simulate_stream(p, gains, SensorModel(noise=kw["sigma"], velocity=False, seed=seed).measure,
                    periods, rate, sigma=kw["sigma"], control_after=enable_after,
                    stream_estimator=est, pulse_width=kw["pulse_width"],
                    force_limit=kw.get("force_limit", math.inf))
    return samples


def replay(p, gains, kw, samples, enable_after, compiled):
    """The controller's work on each sample (module docstring): (section times s,
    the sections' CPU times s, other samples' times s, answers [(k, z, cov, dv,
    predicted)]). The CPU time (this thread's) leaves out the time the thread waited
    for a core: on a loaded machine the wall time's tail is mostly that."""
    est = StreamEstimator(p, kernel=compiled, **kw)
    clock, cpu = time.perf_counter, time.thread_time
    section_t, section_cpu, sample_t, answers = [], [], [], []
    for t, x, v in samples:
        c0 = cpu()
        t0 = clock()
        due = est.add_sample(t, x, v)
        for k, _tk, e in due:
            dv = gains.c1 * e.z[0] + gains.c2 * e.z[1] if k >= enable_after else 0.0
            force0 = est.section_force(est.next_k - 1)
            pred = predict_section(p, e.z, dv, gains.delay, width=est.pulse[0],
                                   force_limit=est.pulse[1], actuator=est.actuator,
                                   force0=force0, kernel=est.kernel)
            est.set_correction(k, dv, gains.delay)
            answers.append((k, e.z, e.cov.tobytes(), dv, pred))
        (section_t if due else sample_t).append(clock() - t0)
        if due:
            section_cpu.append(cpu() - c0)
    return np.array(section_t), np.array(section_cpu), np.array(sample_t), answers


def _q(a, scale=1e6):
    a = np.asarray(a) * scale
    return f"p50 {np.percentile(a, 50):7.1f} p99 {np.percentile(a, 99):7.1f} max {a.max():7.1f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=("rig", "t200", "masses"), default="rig")
    ap.add_argument("--noise-um", type=float, default=None,
                    help="masses: the sensor's noise (µm; default the rig file's 2 µm)")
    ap.add_argument("--paths", default="core,kernel",
                    help="the paths to run, of core,kernel (one alone: no comparison)")
    ap.add_argument("--periods", type=int, default=400)
    ap.add_argument("--enable-after", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=3, help="alternations of the paths")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    kernel.warm_up()
    warm_up()
    warm = time.perf_counter() - t0
    if args.scene == "masses":
        noise = None if args.noise_um is None else args.noise_um * 1e-6
        rig, ndof, pulse, rate, v, kw = masses_scene(noise)
        samples = record_masses(rig, ndof, v, kw, args.periods, args.enable_after)
        kernel.warm_up_modal()

        def run(compiled):
            with search_path(compiled):
                return replay_masses(ndof, pulse, v, kw, samples, args.enable_after, compiled)
    else:
        p, gains, rate, kw = (rig_scene if args.scene == "rig" else t200_scene)()
        samples = record(p, gains, rate, kw, args.periods, args.enable_after)

        def run(compiled):
            return replay(p, gains, kw, samples, args.enable_after, compiled)
    print(f"scene {args.scene}: {rate} samples a period, {args.periods} periods "
          f"({len(samples)} samples), control from {args.enable_after}; kernel loaded in "
          f"{warm:.2f} s; {os.cpu_count()} CPUs, load %.2f %.2f %.2f" % os.getloadavg())
    paths = {name: compiled for name, compiled in (("core", False), ("kernel", True))
             if name in args.paths.split(",")}
    times = {name: ([], [], []) for name in paths}
    answers = {}
    for _ in range(args.rounds):
        for name, compiled in paths.items():
            sec, sec_cpu, smp, ans = run(compiled)
            times[name][0].append(sec)
            times[name][1].append(sec_cpu)
            times[name][2].append(smp)
            answers.setdefault(name, ans)
            if ans != answers[name]:
                print(f"{name}: a replay differs from the first: not deterministic")
                return 1
    med = {}
    for name, (sec, sec_cpu, smp) in times.items():
        sec, sec_cpu, smp = (np.concatenate(a) for a in (sec, sec_cpu, smp))
        med[name] = np.percentile(sec, 50), np.percentile(sec_cpu, 50)
        print(f"{name:6s} section answer ({sec.size} = {args.rounds} x {sec.size // args.rounds}) "
              f"µs wall {_q(sec)}, CPU {_q(sec_cpu)}; other sample µs wall {_q(smp)}")
    if len(paths) < 2:
        print("load at the end %.2f %.2f %.2f" % os.getloadavg())
        return 0
    print(f"ratio core/kernel at the section's p50: wall "
          f"{med['core'][0] / med['kernel'][0]:.1f}x, CPU {med['core'][1] / med['kernel'][1]:.1f}x")
    same = answers["core"] == answers["kernel"]
    n = len(answers["core"])
    print(f"answers ({n} sections: estimate, covariance, correction, prediction) "
          f"bit-identical: {same}")
    print("load at the end %.2f %.2f %.2f" % os.getloadavg())
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

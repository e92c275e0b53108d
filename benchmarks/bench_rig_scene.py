"""Issue 28's acceptance scene: a simulated rig in SI at physical speed (time_scale 1).

`grazing run --rig config/rigs/acceptance.yaml` (docs/rig_scene.md): sim_node simulates
the rig file's rig and speaks the driver contract (rig/sensor at 2 kHz with 2 um noise
and 0.5 ms latency, position only; rig/phase; rig/clock with a drifting rig clock);
controller_node estimates each Pi2 section from rig/sensor with the model estimator and
answers with rig/force_pulse (2 ms pulses, 5 ms budget), the gains designed for the
budget's delay. The first ``--enable-after`` periods are uncontrolled (chaotic near
grazing), then the control is switched on.

Printed, against the design (the core: dynamics/design/noise.py, dynamics/estimation/section_state.py):

* uncontrolled: the largest Lyapunov exponent of the rig's model at its Delta d (exact
  core, 20000 periods), and in the scene the Pi2 position's range and the share of
  periods with one impact;
* controlled: the periods to capture (|x - x*| below 5 predicted spreads for 50 periods
  in a row), then over the held periods (at least 600): the Pi2 spread (RMS about the
  exact orbit of the pulse loop, dynamics.simulation.actuation.pulse_orbit, and the std), the
  design's predicted spread (the noise gain, position only, model estimator at the
  sensor's samples per period, times the sensor noise in model units: what `grazing
  design --delta-d D --delay B --sensor-rate N --c2 C2` prints) and their ratio, the
  share of periods with one impact, the deadline misses (the simulator's count) and the
  controller's clock relation and sensor latency (its summary line).

    .venv/bin/python benchmarks/bench_rig_scene.py [--rig config/rigs/acceptance.yaml]
        [--periods 900] [--enable-after 200] [--c2 C2] [--engine-cost]

A rig file of n masses (config/rigs/two_mass_beam.yaml, issue 32) runs that rig's scene
instead (``--slow``, ``--watchdog-misses``, ``--noise-um``): the controller's summary, who
was late (rig_timing), the deadline misses and impacts per controlled period; with
``--core-noise UM ...`` only its closed loop in one process at each sensor noise (the
noise it tolerates, docs/rig.md).

``--engine-cost``: the simulator's CPU for one period and for its stream's states on
the rig file's stop, and for the scheduled realtime loop's engine calls of a period
(stream included), no nodes (a compliant stop's cost, docs/rig_scene.md).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from grazing_control.dynamics.simulation.actuation import pulse_orbit
from grazing_control.dynamics.estimation.section_state import estimate_covariance
from grazing_control.dynamics.simulation.lyapunov import lyapunov_exact
from grazing_control.dynamics.design.tuning import design_noise_gain
from grazing_control.oscillator.control import Gains
from grazing_control.plant.rig import load_rig
from grazing_control.recordings.scenes import load
from grazing_control.ros import launcher
from grazing_control.ros.rig_boundary import answer_lead, controller_values

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def design(rig, c2, lead=None):
    """(gains, predicted spread, samples per period) of the rig's design: the estimate
    as the rig's controller makes it (answering ``lead``, model time, before the
    section's last sample: default its answer_lead), as `grazing rig` predicts it."""
    p, d = rig.params(), rig.dimensionless()
    values = controller_values(rig, c2)
    g = Gains(values["c1"], values["c2"], values["actuation_delay"])
    rate = round(p.period / d["state_period"])
    r = estimate_covariance(p, g, rate, estimator="model",
                            lead=values["answer_lead"] if lead is None else lead)
    gain = design_noise_gain(p, g.c2, g.delay, measurement=r)
    return g, gain * d["sensor_noise"], rate


def compliant_orbit(rig, g, z, periods=3000):
    """The controlled 1/1 orbit of the pulse loop on the rig's compliant stop (issue 31):
    the stop's pulse map (plant.contact_plant.ContactPlant.pulse_step, the simulator's
    flow) with Eq. 28's correction iterated from the rigid pulse orbit's deviation ``z``
    until a step moves it by less than 1e-14 (its multiplier is below 1 where the design
    holds). Returns (Pi2 x, last step, contacts in its last period), or None (no
    convergence in ``periods``)."""
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros.rig_boundary import sim_values

    s = settings_from_values({**sim_values(rig), "mode": "realtime"})
    p, w = s.params, s.pulse_width
    start = pulse_start(p.period, g.delay, w)
    dx, dv = z
    for _ in range(periods):
        nx, nv, contacts = s.contact.pulse_step(p, dx, dv, g.c1 * dx + g.c2 * dv, start, w,
                                                s.force_limit or math.inf)
        step = math.hypot(nx - dx, nv - dv)
        dx, dv = nx, nv
        if step < 1e-14:
            return p.x_ref + dx, step, len(contacts)
    return None


def engine_cost(rig, periods=20):
    """The simulator's CPU per period for the rig file (no nodes): one period of the
    plant from X** (the wall's exact flow or the stop's, plant.contact_plant) and the
    stream's states of one period at the sensor's rate, as sim_node's engine makes them
    (ms of process time, mean over ``periods``)."""
    from grazing_control.dynamics.simulation.simulate import states_between
    from grazing_control.oscillator import kernel
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros.rig_boundary import sim_values

    s = settings_from_values({**sim_values(rig), "mode": "realtime"})
    p = s.params
    rel = np.arange(1, round(p.period / s.state_period)) * s.state_period
    advance = kernel.exact_advance() if s.contact is None else s.contact.advance
    advance(p, p.tau2, 0.0, 0.0, p.period)       # compiled at its first call (the wall)
    t0 = time.process_time()
    for _ in range(periods):
        seg = advance(p, p.tau2, 0.0, 0.0, p.period)
    t1 = time.process_time()
    for _ in range(periods):
        if s.contact is None:
            states_between(p, p.tau2, 0.0, 0.0, seg.impacts, rel)
        else:
            s.contact.states_between(p, p.tau2, 0.0, 0.0, rel)
    t2 = time.process_time()
    print(f"engine ({rig.stop.type}): one period {1e3 * (t1 - t0) / periods:.2f} ms, "
          f"{len(rel)} stream states {1e3 * (t2 - t1) / periods:.2f} ms of CPU "
          f"(the period is {1e3 * p.period / rig.omega_n:.1f} ms at physical speed)")
    # the scheduled realtime loop's engine calls of one period, stream included: the
    # period to the actuation start at the sample (Engine.begin_head; an engine without
    # it, before 2026-11-28: the whole uncorrected period), the rest at the actuation
    from grazing_control.plant.engine import Engine

    eng = Engine(s)
    head = getattr(eng, "begin_head", None)
    t0 = time.process_time()
    for _ in range(periods):
        delay = eng.actuation_delay()
        if head is not None:
            head(delay)
        else:
            eng.begin_period(0.0)
        eng.actuate(0.0, delay)
        eng.end_period()
    t1 = time.process_time()
    print(f"scheduled realtime loop, one period with its stream ("
          f"{'begin_head' if head else 'begin_period'} + actuate): "
          f"{1e3 * (t1 - t0) / periods:.2f} ms of CPU")


def core(rig, c2, forces, periods, enable_after, seed=7):
    """The acceptance in the core, for the rig with each force amplitude F0 (N) and the
    same Delta d: the closed loop on the sensor stream (dynamics.estimation.stream.simulate_stream:
    the exact plant, the rig's sensor at the nearest integer samples per period, the
    model estimator answering answer_lead before the section's last sample, the pulse
    at the budget's delay in the plant and the model), uncontrolled for ``enable_after``
    periods, then controlled; the noise in model units is the sensor's 2 um / l, l = F0/k."""
    from dataclasses import replace

    from grazing_control.dynamics.simulation.actuation import pulse_orbit
    from grazing_control.dynamics.estimation.stream import StreamEstimator, simulate_stream
    from grazing_control.plant.sensor import SensorModel
    from grazing_control.ros.rig_boundary import answer_lead

    dd = rig.params().delta_d
    for f0 in forces:
        r = replace(rig, amplitude=f0)
        r = replace(r, gap=(r.params().d_star + dd) * r.scales.length)
        p, d = r.params(), r.dimensionless()
        g, predicted, rate = design(r, c2)
        sigma = d["sensor_noise"]
        w, limit = d["pulse_width"], d["force_limit"] or math.inf
        est = StreamEstimator(p, "model", sigma, "stream", p.period / rate,
                              lead=answer_lead(r), pulse_width=w, force_limit=limit)
        run = simulate_stream(p, g, SensorModel(noise=sigma, velocity=False, seed=seed).measure,
                              enable_after + periods, rate, sigma=sigma,
                              control_after=enable_after, stream_estimator=est,
                              pulse_width=w, force_limit=limit)
        z = pulse_orbit(p, g, w, force_limit=limit).pi2_deviation
        x = run.truth[:, 0]
        err = np.abs(x - z[0])
        cap = next((k for k in range(enable_after, len(x) - 50)
                    if np.all(err[k:k + 50] < 5.0 * predicted)), None)
        if cap is None:
            print(f"core F0 = {f0:g} N: sigma {sigma:.3g}, not captured")
            continue
        held = slice(cap, len(x))
        rms = float(np.sqrt(np.mean((x[held] - z[0]) ** 2)))
        one = float(np.mean(run.impacts_per_period[held] == 1))
        unc = float(np.mean(run.impacts_per_period[:enable_after] == 1))
        print(f"core F0 = {f0:g} N: l = {r.scales.length * 1e3:.4g} mm, sigma {sigma:.3g} "
              f"({sigma / abs(dd):.3g} |Delta d|); uncontrolled one impact in "
              f"{100 * unc:.0f} %; captured after {cap - enable_after} periods; held "
              f"{len(x) - cap}: spread {rms:.3g}, predicted {predicted:.3g}, ratio "
              f"{rms / predicted:.3f}; one impact in {100 * one:.1f} %; model resets "
              f"{run.resets}")


def masses_core(rig, path, noises_um, periods: int, enable_after: int, settle: int = 5,
                seeds=(7, 8, 9)) -> None:
    """A rig of n masses in one process (no nodes, no deadlines: the calls the nodes make,
    as studies.near_grazing.scene.stream_loop): sim_node's engine on the rig's model with
    its sensor (rate, noise ``noises_um`` in µm) and 2 ms pulse, the controller's stream
    estimator on sensor.masses[0] (its answer lead) and its gains k^T z^ from
    ``enable_after``. Per noise: sigma / |Delta d| (model units), the share of the held
    periods (from enable_after + settle) with one impact, the Pi2 position of the
    impacting mass (its deviation z_w from X_p: mean and std, model units), the filter's resets."""
    from grazing_control.dynamics.estimation.stream import StreamEstimator
    from grazing_control.plant.engine import Engine
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros.rig_boundary import sim_values

    model = rig.model()
    v = controller_values(rig, math.nan)
    k, delay, c = np.asarray(v["gains"]), v["actuation_delay"], v["sensor_coordinate"]
    w = model.i_w
    for um in noises_um:
        sigma = um * 1e-6 / rig.scales.length
        ones, held, xs, resets = 0, 0, [], 0
        for seed in seeds:
            sv = {key: val for key, val in sim_values(rig).items()
                  if key not in ("time_scale", "pre_roll")}
            sv.update(sensor_noise=sigma, sensor_seed=seed)
            eng = Engine(settings_from_values(sv, str(path), model))
            est = StreamEstimator(model, "model", sigma, "stream", v["state_period"],
                                  lead=v["answer_lead"], pulse_width=v["pulse_width"],
                                  force_limit=v["force_limit"], coordinate=c)
            due = []
            for ev in eng.initial_states():
                due += est.add_sample(ev.t, ev.x[c])
            for j in range(periods):
                due += est.flush(j)
                (e,) = [d[2] for d in due if d[0] == j]
                if j >= enable_after + settle:
                    xs.append(float(eng.z[w]))
                dv = float(k @ np.asarray(e.z)) if j >= enable_after else 0.0
                est.set_correction(j, dv, delay)
                events = eng.begin_period(dv, delay)
                if j >= enable_after + settle:
                    held += 1
                    ones += sum(ev.kind == "impact" for ev in events) == 1
                due = [d for ev in events if ev.kind == "state"
                       for d in est.add_sample(ev.t, ev.x[c])]
                eng.end_period()
            resets += est.resets
        x = np.asarray(xs)
        print(f"noise {um:g} um: sigma {sigma:.3g} = {sigma / abs(model.delta_d):.3g} |Delta d|;"
              f" one impact in {ones} of {held} held periods ({100 * ones / held:.1f} %); "
              f"Pi2 deviation of x_{w} mean {x.mean():+.3g} std {x.std():.3g}; resets {resets} "
              f"({len(seeds)} seeds x {periods} periods, control from {enable_after})")


def masses_scene(args, rig) -> int:
    """A rig of n masses through the nodes (docs/rig_scene.md, "A rig of n masses"): the
    scene at 1/``--slow`` of physical speed with the file's sensor (its noise
    ``--noise-um`` where given), the controller's summary, who was late section by section
    (rig_timing), and over the controlled periods: the deadline misses (rig/applied: in
    time, prediction, nothing, safe) and the impacts per period of the impacting mass."""
    import yaml

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_rig_"))
    out.mkdir(parents=True, exist_ok=True)
    path = Path(args.rig)
    if args.noise_um is not None:
        doc = yaml.safe_load(path.read_text())
        doc["sensor"]["noise"] = f"{args.noise_um!r} um"
        path = out / "rig.yaml"
        path.write_text(yaml.safe_dump(doc))
        rig = load_rig(path)
    print(f"rig {args.rig}: {rig.n} masses, sensor {rig.sensor.rate:g} Hz, noise "
          f"{rig.sensor.noise * 1e6:g} um, {args.periods} periods at 1/{args.slow:g} of "
          f"physical speed, control from {args.enable_after}; load %.2f %.2f %.2f"
          % __import__("os").getloadavg())
    t0 = time.time()
    res = launcher.run(None, None, str(out / "bag"), args.periods, rig=str(path),
                       enable_after=args.enable_after,
                       timeout=args.periods * 0.3 * args.slow + 120, log_dir=str(out / "logs"),
                       sim_overrides=dict(
                           {} if args.slow == 1.0 else {"time_scale": rig.omega_n / args.slow},
                           **({} if args.watchdog_misses is None else
                              {"watchdog_misses": args.watchdog_misses})))
    print(f"scene: {res} ({time.time() - t0:.0f} s); load at the end %.2f %.2f %.2f"
          % __import__("os").getloadavg())
    for name in ("sim_node", "controller_node"):
        log = Path(res.logs.get(name, ""))
        if log.is_file():
            lines = [ln for ln in log.read_text(errors="replace").splitlines()
                     if "summary:" in ln]
            if lines:
                print(f"{name}: {lines[-1].split('summary: ', 1)[1]}")
    from rig_timing import report, section_timing     # benchmarks/rig_timing.py

    try:
        print("\n".join(report(section_timing(out / "bag", answer_lead(rig) / rig.omega_n,
                                               1.0 / rig.sensor.rate))))
    except (OSError, StopIteration, ValueError) as exc:
        print(f"no timing from the bag: {exc}")
    from test_rig_scene import _messages, _seconds   # tests/: the bag's messages

    m = _messages(out / "bag", ("/rig/applied", "/rig/phase", "/oscillator/impact"))
    start = _seconds(m["/rig/phase"][0][1].header.stamp)
    period = 1.0 / rig.frequency
    status = {round((msg.wrench.torque.y - start) / period): int(msg.wrench.force.z)
              for _, msg in m["/rig/applied"]}
    counts = np.zeros(args.periods, dtype=int)
    for _, msg in m["/oscillator/impact"]:
        k = int(_seconds(msg.header.stamp) // (2.0 * math.pi / rig.model().omega))
        if 0 <= k < args.periods:
            counts[k] += 1
    ctrl = [k for k in sorted(status) if args.enable_after <= k < args.periods]
    late = [k for k in ctrl if status[k] != 0]
    held = counts[args.enable_after:]
    print(f"controlled sections {len(ctrl)}: deadline misses {len(late)} "
          f"(rig/applied in time, predicted, nothing, safe: "
          f"{[sum(status[k] == c for k in ctrl) for c in range(4)]}); sections missed "
          f"{late[:20]}")
    print(f"impacts per controlled period: one in {int(np.sum(held == 1))} of {held.size}, "
          f"counts {np.bincount(held).tolist()}")
    return 0 if res.ok else 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default=str(ROOT / "config" / "rigs" / "acceptance.yaml"))
    ap.add_argument("--periods", type=int, default=900)
    ap.add_argument("--engine-cost", action="store_true",
                    help="only the simulator's CPU per period and per stream (no nodes)")
    ap.add_argument("--enable-after", type=int, default=200)
    ap.add_argument("--c2", type=float, default=math.nan,
                    help="the design's c2 (default: the c2 of least noise gain)")
    ap.add_argument("--out", default=None, help="keep the bag and logs here")
    ap.add_argument("--core", type=float, nargs="*", default=None, metavar="F0",
                    help="only the core's closed loop (no nodes), for the rig with each of "
                         "these force amplitudes in N and its Delta d (default F0s: 20 50 "
                         "200 1000)")
    ap.add_argument("--slow", type=float, default=1.0,
                    help="run at 1/SLOW of physical speed (time_scale = omega_n / SLOW): the "
                         "controller's budget in wall time SLOW times the rig's (default 1: "
                         "physical speed, the acceptance)")
    ap.add_argument("--answer-lead", type=float, default=None, metavar="SECONDS",
                    help="the controller's answer_lead in rig seconds (default: the rig "
                         "controller's, (budget - w/2)/2)")
    ap.add_argument("--watchdog-misses", type=int, default=None,
                    help="sim_node's watchdog_misses (default: its own, 25 of 50; 0: off, "
                         "to measure a scene that misses)")
    ap.add_argument("--stream-block", type=float, default=None, metavar="SECONDS",
                    help="sim_node's stream_block (default: its own, 0.5 ms)")
    ap.add_argument("--thread-priority", type=int, default=None, metavar="P",
                    help="sim_node's and controller_node's thread_priority (SCHED_FIFO 1..99; "
                         "default: their own, 0 = off)")
    ap.add_argument("--recorder-batch-window", type=float, default=None, metavar="SECONDS",
                    help="recorder_node's batch_window (default: its own, 1 ms)")
    ap.add_argument("--noise-um", type=float, default=None,
                    help="a rig of n masses: the sensor's noise in µm (default the file's)")
    ap.add_argument("--core-noise", type=float, nargs="*", default=None, metavar="UM",
                    help="a rig of n masses: only the closed loop in one process (no nodes) "
                         "at each sensor noise in µm (default 0.2 0.5 1 2)")
    ap.add_argument("--settle", type=int, default=5,
                    help="--core-noise: periods after the switch-on left out (default 5)")
    args = ap.parse_args(argv)
    rig = load_rig(args.rig)
    if rig.n > 1 and args.core_noise is not None:
        masses_core(rig, args.rig, args.core_noise or (0.2, 0.5, 1.0, 2.0), args.periods,
                    args.enable_after, args.settle)
        return 0
    if rig.n > 1:
        return masses_scene(args, rig)
    if args.engine_cost:
        engine_cost(rig)
        return 0
    p, d = rig.params(), rig.dimensionless()
    g, predicted, rate = design(rig, args.c2, None if args.answer_lead is None
                                else args.answer_lead * rig.omega_n)
    lyap = lyapunov_exact(p, (0.0, 0.0), 20000, 1000, None, None)
    print(f"rig {args.rig}: Delta d = {p.delta_d:.3g}, omega = {p.omega:.8g}, l = "
          f"{rig.scales.length * 1e3:.4g} mm, sensor noise {d['sensor_noise']:.3g} (model "
          f"units), {p.period / d['state_period']:.1f} samples per period, delay "
          f"{g.delay:.4g}, pulse {d['pulse_width']:.4g}")
    print(f"design: c2 = {g.c2:.6g}, c1 = {g.c1:.6g}; predicted Pi2 spread {predicted:.4g} "
          f"(noise gain, position only, model estimator at {rate} samples per period)")
    print(f"uncontrolled rigid model: largest Lyapunov exponent {lyap.exponents[0]:.3f} per period "
          f"({'chaotic' if lyap.exponents[0] > 0 else 'not chaotic'}), "
          f"{lyap.impacts_per_period:.3f} impacts per period")
    if args.core is not None:
        core(rig, args.c2, args.core or (20.0, 50.0, 200.0, 1000.0), args.periods - args.enable_after,
             args.enable_after)
        return 0
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_rig_"))
    t0 = time.time()
    res = launcher.run(None, None, str(out / "bag"), args.periods, rig=args.rig,
                       enable_after=args.enable_after, timeout=args.periods * 0.1 * args.slow + 120,
                       controller_overrides=dict(
                           {"rig_c2": g.c2},
                           **({} if args.thread_priority is None else
                              {"thread_priority": args.thread_priority}),
                           **({} if args.answer_lead is None else
                              {"answer_lead": args.answer_lead * rig.omega_n})),
                       log_dir=str(out / "logs"),
                       recorder_overrides=(None if args.recorder_batch_window is None else
                                           {"batch_window": args.recorder_batch_window}),
                       sim_overrides=dict(
                           {} if args.slow == 1.0 else {"time_scale": rig.omega_n / args.slow},
                           **({} if args.watchdog_misses is None else
                              {"watchdog_misses": args.watchdog_misses}),
                           **({} if args.stream_block is None else
                              {"stream_block": args.stream_block}),
                           **({} if args.thread_priority is None else
                              {"thread_priority": args.thread_priority})))
    wall = time.time() - t0
    print(f"scene: {res} ({wall:.0f} s)")
    for name in ("sim_node", "controller_node", "recorder_node"):
        log = Path(res.logs.get(name, ""))
        if log.is_file():
            text = log.read_text(errors="replace").splitlines()
            lines = [ln for ln in text if "summary:" in ln]
            if lines:
                print(f"{name}: {lines[-1].split('summary: ', 1)[1]}")
            for ln in (ln for ln in text if "cpu_s=" in ln):   # GRAZING_GC_PAUSES=1
                print(f"{name}: {ln.split(']: ', 1)[-1]}")
    from rig_timing import report, section_timing     # benchmarks/rig_timing.py

    lead = (answer_lead(rig) / rig.omega_n if args.answer_lead is None else args.answer_lead)
    try:
        print("\n".join(report(section_timing(out / "bag", lead, 1.0 / rig.sensor.rate))))
    except (OSError, StopIteration, ValueError) as exc:
        print(f"no timing from the bag: {exc}")
    try:
        sd = load(out / "bag").scenes[0]
    except (OSError, ValueError) as exc:
        print(f"no scene to measure: {exc}")
        return 1
    t, x = sd.scene.t, sd.scene.pi2[:, 0]
    edges = np.append(t, t[-1] + p.period)
    counts = np.histogram(sd.scene.impacts[:, 0], edges)[0]
    k0 = args.enable_after
    unc = slice(0, min(k0, len(t)))
    print(f"uncontrolled ({unc.stop} periods): Pi2 x in [{x[unc].min():.4g}, "
          f"{x[unc].max():.4g}], one impact in {100 * np.mean(counts[unc] == 1):.1f} % "
          f"(impacts per period {np.bincount(counts[unc]).tolist()})")
    orbit = pulse_orbit(p, g, d["pulse_width"],
                        force_limit=d["force_limit"] if d["force_limit"] > 0 else math.inf)
    x_orbit = orbit.pi2[0]
    if rig.stop.type != "rigid":      # the orbit on the rig's own stop, not the wall's
        found = compliant_orbit(rig, g, orbit.pi2_deviation)
        if found is None:
            print(f"stop {rig.stop.type}: no controlled 1/1 orbit of the pulse loop (3000 "
                  "periods)")
            return 1
        x_orbit = found[0]
        print(f"stop {rig.stop.type} {rig.contact_values()}: the pulse loop's orbit Pi2 x "
              f"{x_orbit:.9g} ({x_orbit - orbit.pi2[0]:+.3g} from the rigid one, "
              f"{found[2]} contact(s) a period)")
    err = np.abs(x - x_orbit)
    band = 5.0 * predicted
    captured = next((k for k in range(k0, len(x) - 50) if np.all(err[k:k + 50] < band)), None)
    if captured is None:
        print("controlled: not captured")
        return 1
    held = slice(captured, len(x))
    n = len(x) - captured
    rms = float(np.sqrt(np.mean((x[held] - x_orbit) ** 2)))
    std = float(np.std(x[held]))
    from grazing_control.dynamics.orbits import one_one

    kick = p.x_ref + one_one.orbit(p, g).state[0]
    print(f"  mean Pi2 x over the held periods: {np.mean(x[held]) - x_orbit:+.3g} from the "
          f"pulse loop's orbit, {np.mean(x[held]) - kick:+.3g} from the kick's (the "
          "controller's estimator and prediction integrate the pulse since 2026-11-28)")
    print(f"controlled: captured {captured - k0} periods after the switch; held {n} periods: "
          f"Pi2 spread RMS about the pulse orbit {rms:.4g}, std {std:.4g}, predicted "
          f"{predicted:.4g}: ratio {rms / predicted:.3f} (std {std / predicted:.3f}); one "
          f"impact in {100 * np.mean(counts[held] == 1):.2f} %; deadline misses "
          f"{sd.deadline_misses} in the whole scene, "
          f"{int(np.count_nonzero(np.isin(sd.missed_stamp_ns, sd.stamp_ns[held])))} "
          "while held")
    return 0 if res.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())

"""The issue-32 acceptance scene, measured: a 2-DOF chain through the nodes with a
position-only sensor, the stream estimator and a delay-aware design, against the design's
predicted spread (docs/ndof_scene.md).

Three numbers per coordinate of the Pi2 deviation about the controlled orbit z*:

* **predicted**: sigma sqrt(diag Sigma), Sigma the stationary covariance of the loop
  linearised about z* on the exact n-DOF map (with the pulse, and through the
  actuator's lag the map of (z, F)), driven by the model filter's error covariance on
  the orbit (dynamics/design/noise.py: filter_covariance;
  dynamics/design/noise.py: predicted_spread, docs/theory_ndof.md section 17):
  the prediction `grazing design --model M ... --delta-d D` prints;
* **core**: the seeded closed loop in one process (studies.near_grazing.scene.stream_loop: the
  engine with the sensor, the StreamEstimator over the model, k^T z^ acting ``delay``
  after each section), over ``--seeds`` seeds;
* **nodes**: sim_node + controller_node (+ recorder) through ``grazing run``'s launcher,
  lockstep or realtime, analysed from the bag (recordings.scenes.load): captured, impacts
  per period, spread, deadline misses.

The spreads are taken over the periods from ``--on`` + ``--settle`` to the end.

    .venv/bin/python benchmarks/ndof_stream_scene.py --periods 400
    .venv/bin/python benchmarks/ndof_stream_scene.py --mode realtime --time-scale 20

With ``--pulse-width W`` the correction is the force pulse of that width centred at the
delay, in the design, the plant, the filter and the prediction (the rig scene,
benchmarks/ndof_rig_scene.py); with ``--actuator-bandwidth B`` (1 / tau_a) and
``--actuator-latency L`` that pulse through the first-order actuator, everywhere.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from grazing_control.dynamics.design.family import (pulse_design,  # noqa: E402
                                                       write_gain_yaml)
from grazing_control.dynamics.design.noise import (controlled_orbit,  # noqa: E402
                                                   filter_covariance, predicted_spread)
from grazing_control.dynamics.maps.modal_map import ModalMap  # noqa: E402
from grazing_control.dynamics.simulation.actuator import Actuator  # noqa: E402
from grazing_control.oscillator.ndof import load_model  # noqa: E402
from grazing_control.studies.near_grazing.scene import stream_loop  # noqa: E402


def core_loop(model_file, model, gains, a, seed: int):
    """The seeded closed loop in one process (studies.near_grazing.scene.stream_loop): (Pi2
    deviations z_k, impacts per period, estimator resets, seconds per period, the
    estimates' errors, the corrections)."""
    t0 = time.perf_counter()
    run = stream_loop(model_file, gains, delta_d=model.delta_d, delay=a.delay,
                      sigma=a.sigma, rate=a.rate, coordinate=a.coordinate,
                      periods=a.periods, control_after=a.on, seed=seed,
                      width=a.pulse_width, actuator=_actuator(a))
    return (run.truth, run.impacts_per_period, run.resets,
            (time.perf_counter() - t0) / a.periods, run.estimate - run.truth,
            run.corrections)


def _actuator(a):
    """The first-order actuator of --actuator-bandwidth / --actuator-latency (None: the
    ideal pulse)."""
    if not (a.actuator_bandwidth or a.actuator_latency):
        return None
    return Actuator(1.0 / a.actuator_bandwidth if a.actuator_bandwidth else 0.0,
                    a.actuator_latency)


def node_scene(model_file, model, design, a, tmp: Path, seed: int | None = None):
    """The scene through the nodes, its sensor seeded by ``seed`` (default ``--seed``):
    (Pi2 deviations, impacts per period, deadline misses, answered, wall seconds); the
    bag in ``tmp / "bag"``. The gain file carries the design's actuation (delay, pulse
    width), which the launcher gives the simulator too."""
    from grazing_control.recordings.scenes import load
    from grazing_control.ros import launcher
    from test_closed_loop import NO_WATCHDOG, new_domain

    gains = tmp / "gains.yaml"
    write_gain_yaml(gains, model, design, model_file)
    sim = {"state_period": model.period / a.rate, "sensor_noise": a.sigma,
           "sensor_velocity": False, "sensor_seed": a.seed if seed is None else seed}
    if a.mode == "realtime":
        sim.update(time_scale=a.time_scale, **NO_WATCHDOG)
    t0 = time.perf_counter()
    res = launcher.run(None, gains, tmp / "bag", a.periods, delta_d=model.delta_d,
                       enable_after=a.on, mode=a.mode, domain_id=new_domain(),
                       timeout=a.timeout, log_dir=tmp / "logs", sim_overrides=sim,
                       controller_overrides={"pi2_source": "stream", "estimator": "model",
                                             "sensor_coordinate": a.coordinate})
    wall = time.perf_counter() - t0
    if not res.ok:
        raise SystemExit(f"the scene failed: {res}\n"
                         + Path(res.logs["sim_node"]).read_text()[-3000:])
    sd = load(tmp / "bag").scenes[0]
    flow = ModalMap(model).flow
    z = sd.scene.pi2 - flow.particular(flow.tau2)
    return (z, np.asarray(sd.scene.impacts_per_period), sd.deadline_misses,
            int(np.sum(sd.answered)), wall)


def spread(z, orbit, a):
    """std and mean of z_k - z* per coordinate over [on + settle, end)."""
    d = z[a.on + a.settle:] - orbit
    return d.std(axis=0), d.mean(axis=0)


def main(argv=None):
    """Run the measurement; returns its numbers (the dict ``--out`` writes)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(ROOT / "config" / "models" / "two_mass_chain.yaml"))
    ap.add_argument("--delta-d", type=float, default=-1e-3)
    ap.add_argument("--mu", type=float, default=-0.22)
    ap.add_argument("--delay", type=float, default=1.0)
    ap.add_argument("--pulse-width", type=float, default=0.0,
                    help="the correction as a force pulse of this width centred --delay "
                    "after the sample (0: the kick; docs/theory_ndof.md section 15)")
    ap.add_argument("--actuator-bandwidth", type=float, default=0.0,
                    help="the pulse through a first-order actuator of bandwidth 1 / tau_a "
                    "(0: ideal; needs --pulse-width)")
    ap.add_argument("--actuator-latency", type=float, default=0.0,
                    help="the actuator's latency (needs --pulse-width)")
    ap.add_argument("--sigma", type=float, default=1e-4)
    ap.add_argument("--rate", type=int, default=200)
    ap.add_argument("--coordinate", type=int, default=0)
    ap.add_argument("--periods", type=int, default=400)
    ap.add_argument("--on", type=int, default=10)
    ap.add_argument("--settle", type=int, default=60)
    ap.add_argument("--seed", type=int, default=7, help="the node scene's sensor seed")
    ap.add_argument("--node-seeds", type=int, default=1,
                    help="node scenes, sensor seeds --seed, --seed + 1, ...")
    ap.add_argument("--keep-bags", default="", help="keep each node scene's bag under "
                    "this directory (bag_<seed>)")
    ap.add_argument("--seeds", type=int, default=4, help="seeds of the core loop")
    ap.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    ap.add_argument("--time-scale", type=float, default=20.0)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--core-only", action="store_true")
    ap.add_argument("--out", default="")
    a = ap.parse_args(argv)

    model = dataclasses.replace(load_model(a.model), delta_d=a.delta_d)
    act = _actuator(a)
    design = pulse_design(model, a.mu, a.delay, a.pulse_width,
                          *((act.time_constant, act.latency) if act else ()))
    n2 = 2 * model.n
    # the controlled orbit (z*, and F* through the lag) by Newton on the exact loop
    # (noise.controlled_orbit, from the 1/1 branch of the ideal pulse or the kick)
    full = controlled_orbit(model, design.gains, design.delay)
    orbit = full[:n2]
    # the samples the controller fits: before t_k in lockstep, up to t_k in realtime
    # (answer_after_section; filter_covariance's section_sample)
    R = filter_covariance(model, design.gains, orbit, a.rate, a.coordinate, a.delay,
                               width=a.pulse_width, section_sample=a.mode == "realtime"
                               and not a.core_only, actuator=act,
                               force0=float(full[n2]) if full.size > n2 else 0.0)
    spread_ = predicted_spread(model, design.gains, design.delay, measurement=R, orbit=full)
    predicted = a.sigma * spread_.std[:n2]
    out = {"model": a.model, "delta_d": a.delta_d, "mu": a.mu, "delay": a.delay,
           "pulse_width": a.pulse_width, "actuator_bandwidth": a.actuator_bandwidth,
           "actuator_latency": a.actuator_latency,
           "correction_std_predicted": a.sigma * spread_.correction_std,
           "admissible": bool(design.admissible), "gains": design.gains.tolist(),
           "orbit": orbit.tolist(), "predicted_std": predicted.tolist(),
           "filter_std_predicted": (a.sigma * np.sqrt(np.diag(R))).tolist()}
    print(f"design mu={a.mu} delay={a.delay} pulse_width={a.pulse_width} "
          f"actuator bandwidth={a.actuator_bandwidth} latency={a.actuator_latency} "
          f"admissible={design.admissible} "
          f"k={np.round(design.gains, 6).tolist()}")
    print(f"controlled orbit z* = {np.round(orbit, 9).tolist()}")
    print(f"predicted std     {np.array2string(predicted, precision=4)}")
    ratios, secs = [], []
    for seed in range(a.seeds):
        z, counts, resets, per, errors, dvs = core_loop(a.model, model, design.gains, a, seed)
        dv_ratio = dvs[a.on + a.settle:].std() / (a.sigma * spread_.correction_std)
        std, mean = spread(z, orbit, a)
        filt = errors[a.on + a.settle:].std(axis=0)
        ratios.append(std / predicted)
        secs.append(per)
        print(f"core seed {seed}: std {np.array2string(std, precision=4)} ratio "
              f"{np.array2string(std / predicted, precision=3)} impacts/period (last "
              f"{a.periods - a.on - a.settle}) {sorted(set(counts[a.on + a.settle:].tolist()))}"
              f" resets {resets}; corrections' std / predicted {dv_ratio:.3f}; filter error std {np.array2string(filt, precision=3)} "
              f"(predicted {np.array2string(a.sigma * np.sqrt(np.diag(R)), precision=3)})")
    if a.seeds:
        ratios = np.array(ratios)
        out["core"] = {"ratio_mean": ratios.mean(axis=0).tolist(),
                       "ratio_min": ratios.min().item(), "ratio_max": ratios.max().item(),
                       "seconds_per_period": float(np.mean(secs))}
        print(f"core: spread/predicted mean {np.array2string(ratios.mean(axis=0), precision=3)}"
              f" (all seeds {ratios.min():.3f} .. {ratios.max():.3f}); "
              f"{np.mean(secs) * 1e3:.1f} ms per period")
    if not a.core_only:
        out["nodes"] = []
        for seed in range(a.seed, a.seed + a.node_seeds):
            with tempfile.TemporaryDirectory() as tmp:
                z, counts, misses, answered, wall = node_scene(a.model, model, design, a,
                                                               Path(tmp), seed)
                if a.keep_bags:
                    import shutil
                    Path(a.keep_bags).mkdir(parents=True, exist_ok=True)
                    shutil.copytree(Path(tmp) / "bag", Path(a.keep_bags) / f"bag_{seed}",
                                    dirs_exist_ok=True)
            std, mean = spread(z, orbit, a)
            tail = counts[a.on + a.settle:]
            last = float(np.max(np.abs(z[-1] - orbit)))
            out["nodes"].append({
                "seed": seed, "mode": a.mode, "time_scale": a.time_scale
                if a.mode == "realtime" else None, "std": std.tolist(),
                "ratio": (std / predicted).tolist(), "mean": mean.tolist(),
                "impacts_per_period": sorted(set(tail.tolist())), "deadline_misses": misses,
                "answered": answered, "final_distance": last, "wall_s": wall})
            print(f"nodes seed {seed} ({a.mode}"
                  f"{'' if a.mode == 'lockstep' else f', time scale {a.time_scale}'}"
                  f"): std {np.array2string(std, precision=4)} ratio "
                  f"{np.array2string(std / predicted, precision=3)}; impacts per period "
                  f"{sorted(set(tail.tolist()))}; |z_final - z*| {last:.2e}; deadline misses "
                  f"{misses}; answered {answered}; {wall:.0f} s wall")
    if a.out:
        Path(a.out).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()

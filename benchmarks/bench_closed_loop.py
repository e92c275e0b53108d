"""Closed loop across processes: lockstep throughput and realtime correction latency.

Lockstep: sim_node and controller_node as two processes (grazing_control.launcher.run),
every period controlled (enable_after = 0), Delta d = -5e-6 from X**; the rate is the
sim node's own count, periods / wall seconds from its first sample to its last period
(process start-up and discovery excluded), next to the in-process core
``simulate(p, N, gains, control_after=0)`` as the baseline. Rows: without and with
oscillator/state (state_period 0 and 1.0), and with the recorder in a third process.

Realtime: sim_node paced at ``--scale`` simulation seconds per wall second, the
controller answering every sample; the latency of a sample is the wall time from
publishing it to applying its correction in the simulator (see sim_node's docstring),
over ``--samples`` samples; p50/p99/max from the sim node's summary.

QoS: every topic reliable and volatile; publishers keep last 100000, subscriptions keep
last 1000 (grazing_control.nodes.common.PUBLISHER_QOS, DATA_QOS); RMW rmw_fastrtps_cpp
(default, shared-memory transport between processes on one host); one
SingleThreadedExecutor per node.

Run: ``python benchmarks/bench_closed_loop.py`` (about 2 minutes; ``--quick`` for a
short check). Each run uses its own ROS_DOMAIN_ID.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grazing_control import launcher  # noqa: E402
from grazing_control.control import Gains  # noqa: E402
from grazing_control.design import degenerate_c1  # noqa: E402
from grazing_control.params import OscillatorParams  # noqa: E402
from grazing_control.simulate import simulate  # noqa: E402

STUDY = ROOT / "config" / "study.yaml"
CONTROLLER = ROOT / "config" / "controller.yaml"


def summary(log: Path) -> dict:
    """The sim node's summary line: key=value pairs; latency/sample_lag as (p50, p99, max)."""
    m = re.search(r"summary: (.*)", log.read_text())
    if not m:
        raise RuntimeError(f"no summary in {log}:\n{log.read_text()}")
    text = m.group(1)
    out = dict(re.findall(r"(\w+)=([^\s]+)", text))
    for name in ("latency", "sample_lag"):
        q = re.search(name + r"_ms p50=(\S+) p99=(\S+) max=(\S+)", text)
        if q:
            out[name] = tuple(float(v) for v in q.groups())
    return out


def scene(periods, sim_overrides, controller_overrides, bag=None):
    """One launcher run; returns the sim node's summary."""
    with tempfile.TemporaryDirectory(prefix="bench_closed_loop_") as tmp:
        res = launcher.run(STUDY, CONTROLLER, None if bag is None else Path(tmp) / "bag",
                           periods, domain_id=random.SystemRandom().randrange(101, 232),
                           timeout=600, sim_overrides=sim_overrides,
                           controller_overrides=controller_overrides, log_dir=tmp)
        if not res.ok:
            raise RuntimeError(f"run failed: {res}\n{Path(res.logs['sim_node']).read_text()}")
        return summary(Path(res.logs["sim_node"]))


def core_rate(periods) -> float:
    p = OscillatorParams(delta_d=-5e-6)
    gains = Gains(degenerate_c1(p, -1.0), -1.0)
    t = time.perf_counter()
    simulate(p, periods, gains=gains, control_after=0)
    return periods / (time.perf_counter() - t)


def lockstep(periods, repeat):
    rows = []
    configs = [("lockstep, no state", {"state_period": 0.0}, None),
               ("lockstep, state every 1.0", {"state_period": 1.0}, None),
               ("lockstep, state 1.0 + recorder", {"state_period": 1.0}, "bag")]
    for name, over, bag in configs:
        rates, base = [], []
        for _ in range(repeat):
            base.append(core_rate(periods))
            s = scene(periods, {"delta_d": -5e-6, **over}, {"enable_after": 0}, bag)
            assert int(s["periods"]) == periods and s["timeouts"] == "0", s
            rates.append(float(s["rate"]))
        rows.append((name, statistics.median(rates), max(rates), statistics.median(base)))
    print(f"\nlockstep closed loop, {periods} controlled periods per run, median and best "
          f"of {repeat}")
    print(f"{'configuration':34s} {'periods/s':>10s} {'best':>8s} {'core/s':>8s} "
          f"{'ratio':>6s} {'goal':>6s}")
    print("-" * 78)
    for name, med, best, base in rows:
        print(f"{name:34s} {med:10.0f} {best:8.0f} {base:8.0f} {med / base:6.2f} "
              f"{'ok' if med >= 1000 else 'MISS':>6s}")
    return rows


def realtime(samples, scale):
    T = OscillatorParams().period
    s = scene(samples, {"mode": "realtime", "time_scale": scale, "state_period": 0.0,
                        "delta_d": -5e-6}, {"enable_after": 0})
    print(f"\nrealtime, time_scale {scale:g} (a sample every {T / scale * 1e3:.2f} ms wall), "
          f"{samples} samples, state off")
    lat, lag = s["latency"], s["sample_lag"]
    print(f"{'':18s} {'p50 ms':>8s} {'p99 ms':>8s} {'max ms':>8s}")
    print("-" * 46)
    print(f"{'latency':18s} {lat[0]:8.3f} {lat[1]:8.3f} {lat[2]:8.3f}   "
          f"goal p99 < 2 ms: {'ok' if lat[1] < 2.0 else 'MISS'}")
    print(f"{'sample lag':18s} {lag[0]:8.3f} {lag[1]:8.3f} {lag[2]:8.3f}   "
          "(sample published after its simulation time)")
    print(f"applied {s['applied']} of {samples} corrections, {s['late']} of them after the "
          "next sample (late)")
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--periods", type=int, default=5000, help="lockstep periods per run")
    ap.add_argument("--repeat", type=int, default=3, help="lockstep runs per configuration")
    ap.add_argument("--samples", type=int, default=10000, help="realtime samples")
    ap.add_argument("--scale", type=float, default=2000.0, help="realtime time_scale")
    ap.add_argument("--quick", action="store_true", help="1000 periods, 1 run, 1000 samples")
    args = ap.parse_args(argv)
    if args.quick:
        args.periods, args.repeat, args.samples = 1000, 1, 1000
    print(f"closed-loop benchmark: python {platform.python_version()}, "
          f"RMW {os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (default)')}, "
          f"{os.cpu_count()} CPUs; QoS reliable, volatile, publishers keep last 100000, "
          "subscriptions keep last 1000")
    lockstep(args.periods, args.repeat)
    realtime(args.samples, args.scale)


if __name__ == "__main__":
    main()

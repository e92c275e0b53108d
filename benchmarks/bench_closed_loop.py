"""Closed loop across processes: lockstep throughput, realtime latency and pace (issue 8 §4).

Everything runs through :func:`grazing_control.ros.launcher.run` (sim_node, controller_node and,
where stated, recorder_node as separate processes; Fast DDS, reliable volatile QoS), each
scene on its own ROS_DOMAIN_ID, and side by side in one run of this script:

1. **Lockstep throughput**: every period controlled (enable_after 0, Delta d = -5e-6);
   rows without state messages, with a state message every 1.0 of simulation time, and
   the same with the recorder (its default batch_window of 1 ms, and 0: a take per
   wake-up), for both executors (rclpy's SingleThreadedExecutor and
   rclpy.experimental.EventsExecutor, in both nodes). The rate is the simulator's own
   count (periods / wall seconds from its first sample to its last period); the baseline
   is the in-process core ``simulate(p, N, gains, control_after=0)``, timed in this
   process next to each run. The CPU seconds each process spent per period (user +
   system, from /proc, sampled while the scene runs) say where the time goes. With
   ``--composed`` each row runs again right after as a composed scene (the three nodes
   in one process, ``grazing run --compose``: grazing_control/ros/composed.py), its rate
   over the row above printed as ``x sep``.
2. **Latency**: realtime at ``--scale`` with apply-on-arrival (``actuation:=on_arrival``,
   so the correction is applied when it arrives), state off, every sample answered;
   latency = wall time from publishing a sample to applying its correction; p50/p99/max
   from the simulator's summary, with no extra load and with both cores busy (two
   ``yes > /dev/null``), for both executors.
3. **Pace**: realtime with the recorder on and state every 1.0, default executor, time
   scales doubling from 250; the simulator keeps pace while the sample lag (how late a
   sample goes out against its simulation time) has p99 < 10 % of a period of wall time.

Run: ``.venv/bin/python benchmarks/bench_closed_loop.py`` (about 4 minutes; ``--quick``
for a short check). Results and the machine's state in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grazing_control.ros import launcher  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate  # noqa: E402

STUDY = ROOT / "config" / "study.yaml"
CONTROLLER = ROOT / "config" / "controller.yaml"
EXECUTORS = ("single_threaded", "events")
NODES = {launcher.SIM_MODULE: "sim", launcher.CONTROLLER_MODULE: "controller",
         launcher.RECORDER_MODULE: "recorder", launcher.COMPOSED_MODULE: "composed"}
TICK = os.sysconf("SC_CLK_TCK")


def summary(log: Path) -> dict:
    """The sim node's summary line: key=value pairs; latency/sample_lag as (p50, p99, max)."""
    m = re.search(r"\[sim_node\]: summary: (.*)", log.read_text())
    if not m:
        raise RuntimeError(f"no summary in {log}:\n{log.read_text()}")
    text = m.group(1)
    out = dict(re.findall(r"(\w+)=([^\s]+)", text))
    for name in ("latency", "sample_lag"):
        q = re.search(name + r"_ms p50=(\S+) p99=(\S+) max=(\S+)", text)
        if q:
            out[name] = tuple(float(v) for v in q.groups())
    return out


class CpuMeter:
    """CPU seconds (user + system) of this process's node children, sampled from /proc
    every 20 ms: ``series[node]`` is a list of (Unix time, CPU seconds)."""

    def __init__(self):
        self.series = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        me = str(os.getpid())
        while not self._stop.is_set():
            for pid in os.listdir("/proc"):
                if not pid.isdigit():
                    continue
                try:
                    stat = Path(f"/proc/{pid}/stat").read_text()
                    fields = stat.rsplit(")", 1)[1].split()
                    if fields[1] != me:
                        continue
                    cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                except OSError:
                    continue
                name = next((NODES[c.decode()] for c in cmd if c.decode() in NODES), None)
                if name:
                    self.series.setdefault(name, []).append(
                        (time.time(), (int(fields[11]) + int(fields[12])) / TICK))
            self._stop.wait(0.02)

    def during(self, start: float, end: float) -> dict:
        """CPU seconds of each node between two Unix times (to the sampling interval)."""

        def at(series, t):
            before = [c for s, c in series if s <= t]
            return before[-1] if before else series[0][1]
        return {name: at(ser, end) - at(ser, start) for name, ser in self.series.items()}

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def scene(periods, sim_overrides, controller_overrides, bag=False, recorder_overrides=None,
          meter=True, compose=False):
    """One launcher run; returns (the sim node's summary, CPU seconds per node, or {}
    without ``meter``: the meter's thread wakes every 20 ms to read /proc, and on two
    cores that shows in a realtime run's latency tail, so the realtime rows run without)."""
    with tempfile.TemporaryDirectory(prefix="bench_closed_loop_") as tmp, \
            (CpuMeter() if meter else contextlib.nullcontext()) as cpu:
        res = launcher.run(STUDY, CONTROLLER, Path(tmp) / "bag" if bag else None,
                           periods, timeout=600, sim_overrides=sim_overrides,
                           controller_overrides=controller_overrides,
                           recorder_overrides=recorder_overrides, log_dir=tmp,
                           compose=compose)
        if not res.ok:
            raise RuntimeError(f"run failed: {res}\n{Path(res.logs['sim_node']).read_text()}")
        log = Path(res.logs["sim_node"]).read_text()
        s = summary(Path(res.logs["sim_node"]))
    # the scene: from the first sample to the summary line (its log stamp, Unix time)
    end = float(re.search(r"\[(\d+\.\d+)\] \[sim_node\]: summary", log).group(1))
    return s, (cpu.during(end - float(s["wall"].rstrip("s")), end) if cpu else {})


@contextlib.contextmanager
def busy_cores(n):
    """n processes ``yes > /dev/null`` for the duration (both cores busy on a 2-CPU VM)."""
    procs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def core_rate(periods) -> float:
    p = OscillatorParams(delta_d=-5e-6)
    gains = Gains(degenerate_c1(p, -1.0), -1.0)
    t = time.perf_counter()
    simulate(p, periods, gains=gains, control_after=0)
    return periods / (time.perf_counter() - t)


def executors(ex):
    return {"executor": ex}, {"executor": ex}


def lockstep(periods, repeat, composed=False):
    """The lockstep rows; with ``composed`` each row also as a composed scene (the nodes
    in one process, ``grazing run --compose``), right after it, and the ratio."""
    configs = [("no state", {"state_period": 0.0}, False, None),
               ("state every 1.0", {"state_period": 1.0}, False, None),
               ("state 1.0 + recorder", {"state_period": 1.0}, True, None),
               ("  recorder window 0", {"state_period": 1.0}, True, {"batch_window": 0.0})]
    rows = []
    for name, over, bag, rec in configs:
        for ex in EXECUTORS:
            for compose in ((False, True) if composed else (False,)):
                rates, base, cpus = [], [], []
                for _ in range(repeat):
                    base.append(core_rate(min(periods, 2000)))
                    sim, ctl = executors(ex)
                    s, cpu = scene(periods, {"delta_d": -5e-6, **over, **sim},
                                   {"enable_after": 0, **ctl}, bag, rec, compose=compose)
                    assert int(s["periods"]) == periods and s["timeouts"] == "0", s
                    rates.append(float(s["rate"]))
                    cpus.append(cpu)
                cpu = {k: statistics.median(c.get(k, 0.0) for c in cpus) * 1e3 / periods
                       for k in ("sim", "controller", "recorder", "composed")}
                rows.append((name, ex, compose, statistics.median(rates), max(rates),
                             statistics.median(base), cpu))
    print(f"\nlockstep closed loop, {periods} controlled periods per run, median and best "
          f"of {repeat}; CPU ms per period of each process (median); 'x sep': the composed "
          "scene's rate over the separate processes' of the row above")
    print(f"{'configuration':22s} {'executor':16s} {'nodes':9s} {'periods/s':>9s} {'best':>6s} "
          f"{'core/s':>7s} {'ratio':>6s} {'sim':>6s} {'ctl':>6s} {'rec':>6s} {'1 proc':>6s} "
          f"{'x sep':>6s}")
    print("-" * 118)
    last = None
    for name, ex, compose, med, best, base, cpu in rows:
        vs = f"{med / last:6.2f}" if compose and last else ""
        print(f"{name:22s} {ex:16s} {'composed' if compose else 'processes':9s} {med:9.0f} "
              f"{best:6.0f} {base:7.0f} {med / base:6.3f} {cpu['sim']:6.3f} "
              f"{cpu['controller']:6.3f} {cpu['recorder']:6.3f} {cpu['composed']:6.3f} {vs}")
        last = med if not compose else last
    return rows


def latency(samples, scale):
    T = OscillatorParams().period
    rows = []
    for load in (0, 2):
        for ex in EXECUTORS:
            sim, ctl = executors(ex)
            with busy_cores(load):
                s, _ = scene(samples, {"mode": "realtime", "time_scale": scale,
                                       "state_period": 0.0, "delta_d": -5e-6,
                                       "actuation": "on_arrival", "watchdog_excursion": 0.0,
                                       "watchdog_misses": 0,
                                       **sim},
                             {"enable_after": 0, **ctl}, meter=False)
            rows.append((load, ex, s))
    print(f"\nrealtime latency, time_scale {scale:g} (a sample every {T / scale * 1e3:.2f} ms "
          f"wall), {samples} samples, state off, apply on arrival")
    print(f"{'load':16s} {'executor':16s} {'p50 ms':>7s} {'p99 ms':>7s} {'max ms':>7s} "
          f"{'lag p99':>8s} {'late':>5s}  goal p99 <= 1 ms")
    print("-" * 86)
    for load, ex, s in rows:
        lat, lag = s["latency"], s["sample_lag"]
        print(f"{('no extra load' if not load else f'+{load} x yes'):16s} {ex:16s} "
              f"{lat[0]:7.3f} {lat[1]:7.3f} {lat[2]:7.3f} {lag[1]:8.3f} {s['late']:>5s}  "
              f"{'ok' if lat[1] <= 1.0 else 'MISS'}")
    return rows


def pace(samples_wall, executor, scales):
    T = OscillatorParams().period
    rows = []
    for scale in scales:
        n = max(50, int(samples_wall * scale / T))
        sim, ctl = executors(executor)
        s, _ = scene(n, {"mode": "realtime", "time_scale": scale, "state_period": 1.0,
                         "delta_d": -5e-6, "actuation": "on_arrival",
                         "watchdog_excursion": 0.0, "watchdog_misses": 0, **sim},
                     {"enable_after": 0, **ctl}, bag=True, meter=False)
        budget = 0.1 * T / scale * 1e3
        rows.append((scale, n, s, budget))
    print(f"\nrealtime pace with the recorder on, state every 1.0, executor {executor}: keeps "
          "pace while the sample lag p99 < 10 % of a period")
    print(f"{'time_scale':>10s} {'period ms':>9s} {'samples':>7s} {'lag p50':>8s} "
          f"{'lag p99':>8s} {'lag max':>8s} {'10% T':>6s} {'latency p99':>11s} pace")
    print("-" * 86)
    best = None
    for scale, n, s, budget in rows:
        lag = s["sample_lag"]
        ok = lag[1] < budget
        best = scale if ok and (best is None or scale > best) else best
        print(f"{scale:10g} {T / scale * 1e3:9.3f} {n:7d} {lag[0]:8.3f} {lag[1]:8.3f} "
              f"{lag[2]:8.3f} {budget:6.3f} {s['latency'][1]:11.3f} {'ok' if ok else 'no'}")
    print(f"highest time_scale keeping pace: {best if best is not None else 'none'}")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--periods", type=int, default=3000, help="lockstep periods per run")
    ap.add_argument("--repeat", type=int, default=2, help="lockstep runs per configuration")
    ap.add_argument("--samples", type=int, default=2000, help="realtime latency samples")
    ap.add_argument("--scale", type=float, default=1000.0, help="latency: time_scale")
    ap.add_argument("--pace-seconds", type=float, default=4.0,
                    help="pace: wall seconds per time scale")
    ap.add_argument("--scales", default="250,500,1000,2000,4000,8000",
                    help="pace: time scales to try")
    ap.add_argument("--executor", choices=EXECUTORS, default="events",
                    help="pace: the executor of both nodes")
    ap.add_argument("--quick", action="store_true",
                    help="1000 periods, 1 run, 500 samples, 2 s per scale")
    ap.add_argument("--composed", action="store_true",
                    help="lockstep: each row also composed (grazing run --compose), side by side")
    ap.add_argument("--only", choices=("lockstep", "latency", "pace"), action="append",
                    help="run only these parts (repeatable)")
    args = ap.parse_args(argv)
    if args.quick:
        args.periods, args.repeat, args.samples, args.pace_seconds = 1000, 1, 500, 2.0
    parts = args.only or ("lockstep", "latency", "pace")
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[:3]
    print(f"closed-loop benchmark: python {platform.python_version()}, "
          f"RMW {os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (default)')}, "
          f"{os.cpu_count()} CPUs, load average {' '.join(load)} at the start; QoS reliable, "
          "volatile, publishers keep last 100000, subscriptions keep last 1000 (the "
          "controller's inputs 100000)")
    if "lockstep" in parts:
        lockstep(args.periods, args.repeat, args.composed)
    if "latency" in parts:
        latency(args.samples, args.scale)
    if "pace" in parts:
        pace(args.pace_seconds, args.executor, [float(s) for s in args.scales.split(",")])
    with open("/proc/loadavg") as fh:
        print(f"\nload average at the end: {' '.join(fh.read().split()[:3])}")


if __name__ == "__main__":
    main()

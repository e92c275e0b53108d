"""The realtime loop's latency tail, with and without real-time scheduling, idle and loaded.

Issue 16 §3. A realtime scene (``grazing run --mode realtime``, time_scale 1000: a period
is 9.4 ms of wall time) at Delta d = -5e-6 with scheduled actuation (the correction acts
``--delay`` simulation-time units after its Pi2 sample, i.e. ``--delay`` ms of wall time
at time_scale 1000; gains of ``grazing design --c2 -1 --delay D``), ``--periods`` periods,
control on from sample 0, a recorder on the scene's topics. Four runs side by side in one
process:

* ``idle``: the machine as it is;
* ``idle + rt``: the nodes' real-time options (sim_node and controller_node
  ``thread_priority`` 50 (SCHED_FIFO), ``lock_memory``; docs/nodes.md);
* ``2 x yes``: two ``yes > /dev/null`` processes running throughout (one per core here);
* ``2 x yes + rt``: both.

From each bag (``oscillator/latency``: wall seconds from publishing a sample to receiving
its correction; ``oscillator/deadline_miss``): p50, p99, p99.9, max of the latency (ms),
the answers later than ``--budget`` ms per 10,000 periods, the simulator's deadline
misses per 10,000 periods, and the corrections it applied by prediction (on_miss predict,
docs/nodes.md), plus the Pi2 distance to the controlled orbit at the end. The ratio
printed is the p99.9 without the options over the p99.9 with them.

Run: ``.venv/bin/python benchmarks/bench_latency.py [--periods 30000] [--delay 3.0]``
(about 4 x periods x 9.4 ms of wall time); bags in benchmarks/out/latency/.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grazing_control.dynamics.design.gains import degenerate_c1, write_controller_yaml  # noqa: E402
from grazing_control.dynamics.orbits import one_one  # noqa: E402
from grazing_control.dynamics.design.tuning import optimize_noise  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.recordings import reader  # noqa: E402

OUT = ROOT / "benchmarks" / "out" / "latency"
DD = -5e-6
RT = ("thread_priority:=50", "lock_memory:=true")


def run(name, periods, delay, controller, rt):
    bag, logs = OUT / f"{name}_bag", OUT / f"{name}_logs"
    shutil.rmtree(bag, ignore_errors=True)
    cmd = [sys.executable, "-m", "grazing_control.cli", "run", "--mode", "realtime",
           "--periods", str(periods), "--delta-d", repr(DD), "--enable-after", "0",
           "--controller-params", str(controller), "--bag", str(bag), "--log-dir",
           str(logs), "--timeout", str(60 + periods * 0.02),
           "--sim-param", "time_scale:=1000.0", "--sim-param", "state_period:=1.0"]
    for opt in (RT if rt else ()):
        cmd += ["--sim-param", opt, "--controller-param", opt]
    t0 = time.monotonic()
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.monotonic() - t0
    if done.returncode != 0:
        print(done.stdout[-2000:], done.stderr[-2000:])
    sim_log = (logs / "sim_node.log").read_text()
    warnings = sorted(set(re.findall(r"(thread_priority=\d+ not applied[^\n]*|lock_memory"
                                     r"[^\n]*not applied[^\n]*)", sim_log)))
    summary = re.search(r"summary: (.*)", sim_log)
    raw = reader.read_raw(bag)
    lat = reader.decode_float64(raw, "/oscillator/latency")
    lat_ms = lat["data"][lat["ok"]] * 1e3
    misses = raw.count("/oscillator/deadline_miss")
    pi2 = reader.decode_joint_state(raw, "/oscillator/pi2")
    return {"name": name, "wall": wall, "status": done.returncode, "lat": lat_ms,
            "misses": misses, "final": np.array([pi2["x"][-1], pi2["v"][-1]]),
            "summary": summary.group(1) if summary else "", "warnings": warnings}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=30000)
    ap.add_argument("--delay", type=float, default=3.0,
                    help="actuation delay, simulation time (= ms at time_scale 1000)")
    ap.add_argument("--budget", type=float, default=3.0, help="latency budget, ms")
    ap.add_argument("--only", nargs="*", default=None,
                    help="run only these configurations (idle, idle+rt, yes, yes+rt)")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    p = OscillatorParams(delta_d=DD)
    c2 = optimize_noise(p, args.delay).c2     # the study's c2 = -1 has no orbit at delay 3
    gains = Gains(degenerate_c1(p, c2, args.delay), c2, args.delay)
    controller = write_controller_yaml(OUT / "controller.yaml", p, gains) or OUT / "controller.yaml"
    orbit = one_one.orbit(p, gains, branch="grazing").physical
    configs = [("idle", False, False), ("idle+rt", False, True), ("yes", True, False),
               ("yes+rt", True, True)]
    results = []
    for name, loaded, rt in configs:
        if args.only and name not in args.only:
            continue
        loads = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in
                 range(2 if loaded else 0)]
        try:
            res = run(name, args.periods, args.delay, controller, rt)
        finally:
            for q in loads:
                q.kill()
                q.wait()
        res["distance"] = float(np.max(np.abs(res["final"] - orbit)))
        results.append(res)
        print(f"{name}: {res['wall']:.0f} s, status {res['status']}", flush=True)
    print(f"\n{args.periods} realtime periods each, time_scale 1000 (9.4 ms per period), "
          f"delay {args.delay} ms, budget {args.budget} ms")
    print("| run | p50 ms | p99 ms | p99.9 ms | max ms | > budget per 10k | deadline misses "
          "per 10k | final distance to the orbit |")
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        a = r["lat"]
        n = max(len(a), 1)
        q = np.percentile(a, [50, 99, 99.9]) if len(a) else [np.nan] * 3
        print(f"| {r['name']} | {q[0]:.3f} | {q[1]:.3f} | {q[2]:.3f} | "
              f"{a.max() if len(a) else np.nan:.3f} | "
              f"{1e4 * np.count_nonzero(a > args.budget) / n:.1f} | "
              f"{1e4 * r['misses'] / args.periods:.1f} | {r['distance']:.1e} |")
    for r in results:
        print(f"{r['name']}: {r['summary']}")
        for w in r["warnings"]:
            print(f"  {w}")
    by = {r["name"]: r for r in results}
    for base in ("idle", "yes"):
        if base in by and base + "+rt" in by and len(by[base]["lat"]) and \
                len(by[base + "+rt"]["lat"]):
            a, b = (np.percentile(by[k]["lat"], 99.9) for k in (base, base + "+rt"))
            print(f"ratio p99.9 {base} / {base}+rt = {a / b:.2f}")


if __name__ == "__main__":
    main()

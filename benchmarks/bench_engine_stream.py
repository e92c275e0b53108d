"""The simulator's work per period of the T/200 scene, without the middleware (issue 30).

In a realtime T/200 scene at x1000 the simulator node spends most of its CPU in the
plant's engine: each period the head to the actuation (``Engine.begin_head``), the pulse
and the rest of the period (``Engine.actuate``), the step to the next sample
(``end_period``), each measuring its stream samples through the sensor (noise 1e-4,
position only). This runs those calls as ``plant.realtime.Realtime`` makes them, for the
scene of ``bench_stream_blocks`` (Delta d = -5e-6, state_period T/200, pulse width 0.1,
actuation delay 3, a correction of ~1e-5 each period), in-process, and reads the thread's
CPU time per period (after 50 periods of warm-up). Each arm runs in a fresh interpreter of its checkout (this one, and
``--baseline DIR``: a git worktree of an older commit), alternating ``--reps`` times; the
arms' events must be the same (a hash of every event's fields, printed).

Printed: ms of CPU a period (median of the runs) per arm, and this / base.

Run: ``.venv/bin/python benchmarks/bench_engine_stream.py --baseline /tmp/base``.
Results in docs/benchmarks.md, "A block in one step".
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: One arm, run with a checkout as the working directory; argv: periods. Prints JSON.
ARM = r"""
import hashlib, json, math, os, sys, time
sys.path.insert(0, os.getcwd())
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

periods = int(sys.argv[1])
p = OscillatorParams(delta_d=-5e-6)
s = settings_from_values({"delta_d": p.delta_d, "state_period": p.period / 200,
                          "sensor_noise": 1e-4, "sensor_velocity": False,
                          "pulse_width": 0.1, "actuation_delay": 3.0})
eng = Engine(s)
events, cpu = [], 0.0
for k in range(periods + 50):       # the first 50: compiled code loaded, caches warm
    c0 = time.thread_time()
    got = eng.begin_head(3.0) + eng.actuate(1e-5 * math.sin(k), 3.0)
    eng.end_period()
    cpu += (time.thread_time() - c0) if k >= 50 else 0.0
    events += got
digest = hashlib.sha256(repr([tuple(e) for e in events]).encode())
print(json.dumps({"ms": 1e3 * cpu / periods, "hash": digest.hexdigest()[:16]}))
"""


def arm(root: Path, periods: int) -> dict:
    out = subprocess.run([sys.executable, "-c", ARM, str(periods)], cwd=root,
                         capture_output=True, text=True, env={"OPENBLAS_NUM_THREADS": "1",
                                                              "PATH": "/usr/bin:/bin"})
    if out.returncode != 0:
        raise SystemExit(f"{root}: exit {out.returncode}: {out.stderr.strip()[-600:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=2000)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--baseline", type=Path, default=None)
    args = ap.parse_args(argv)
    roots = {"this": ROOT} | ({"base": args.baseline.resolve()} if args.baseline else {})
    runs = {name: [] for name in roots}
    for rep in range(args.reps):
        for name in (list(roots) if rep % 2 == 0 else list(roots)[::-1]):
            runs[name].append(arm(roots[name], args.periods))
    print(f"\n{args.periods} periods of the T/200 scene's engine, {args.reps} runs an arm")
    med = {}
    for name, rs in runs.items():
        med[name] = statistics.median(r["ms"] for r in rs)
        print(f"{name:5s} {med[name]:.3f} ms of CPU a period (runs: "
              f"{', '.join(format(r['ms'], '.3f') for r in rs)}); events {rs[0]['hash']}")
    if "base" in roots:
        same = {r["hash"] for rs in runs.values() for r in rs}
        print(f"this / base: {med['this'] / med['base']:.3f}; the same events: "
              f"{len(same) == 1}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Lockstep with the state stream and the recorder, this checkout against a baseline, side
by side (issue 30's ">= 2000 periods/s, measured side by side in one run").

The row "state 1.0 + recorder, events" of ``bench_closed_loop.py --composed``: every period
controlled (enable_after 0, Delta d = -5e-6), a state message every 1.0 of simulation time
(about 9.4 a period), the recorder on (its default batch_window), both nodes on the
EventsExecutor; composed (``grazing run --compose``) and, with ``--processes``, also as
three processes; with ``--stream-message block`` the stream in blocks (one a period in
lockstep). Each scene runs in a fresh interpreter with the checkout as its working
directory and first on sys.path (the launcher puts that checkout on the nodes'
PYTHONPATH), this checkout and ``--baseline DIR`` (a git worktree of the old commit)
alternating, so that both see the same load. The rate is the simulator's own count
(periods / wall seconds from its first sample to its last period); the load average is
printed before each scene.

Run: ``.venv/bin/python benchmarks/bench_lockstep_recorder.py --baseline /tmp/base --reps 3``.
Results in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: One scene, run in the checkout's directory: prints {"rate": periods/s, "summary": line}.
SCENE = r"""
import json, re, sys, tempfile
from pathlib import Path
sys.path.insert(0, ".")
from grazing_control.ros import launcher
periods, compose, message = int(sys.argv[1]), sys.argv[2] == "1", sys.argv[3]
with tempfile.TemporaryDirectory(prefix="bench_lockstep_") as tmp:
    res = launcher.run(Path("config/study.yaml"), Path("config/controller.yaml"),
                       Path(tmp) / "bag", periods,
                       timeout=600,
                       sim_overrides={"delta_d": -5e-6, "state_period": 1.0,
                                      "executor": "events", "stream_message": message},
                       controller_overrides={"enable_after": 0, "executor": "events"},
                       log_dir=tmp, compose=compose)
    line = re.search(r"summary: .*", Path(res.logs["sim_node"]).read_text()).group(0)
assert res.ok and f"periods={periods} " in line and "timeouts=0 " in line, line
print(json.dumps({"rate": float(re.search(r"rate=([\d.]+)", line).group(1)), "summary": line}))
"""


def scene(root: Path, periods: int, compose: bool, message: str = "sample") -> float:
    out = subprocess.run([sys.executable, "-c", SCENE, str(periods), "1" if compose else "0",
                          message], cwd=root, capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"scene in {root} failed:\n{out.stdout[-3000:]}{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])["rate"]


def load() -> str:
    with open("/proc/loadavg") as fh:
        return fh.read().split()[0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", type=Path, default=None, help="the old checkout")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--periods", type=int, default=3000)
    ap.add_argument("--processes", action="store_true",
                    help="also the three processes (not composed)")
    ap.add_argument("--stream-message", choices=("sample", "block"), default="sample",
                    help="the state stream one message a sample (default), or a block a "
                         "wake-up (sim_node's stream_message; a lockstep wake-up is a period)")
    args = ap.parse_args(argv)
    sides = {"this": ROOT} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    kinds = (True, False) if args.processes else (True,)
    rates, loads = {}, []
    for rep in range(args.reps):
        for compose in kinds:
            for name, root in sides.items():
                loads.append(float(load()))
                r = scene(root, args.periods, compose, args.stream_message)
                rates.setdefault((name, compose), []).append(r)
                print(f"rep {rep} {name:8s} {'composed' if compose else 'processes':9s} "
                      f"load {loads[-1]:5.2f}  {r:7.1f} periods/s", flush=True)
    print(f"\n{args.periods} periods, state every 1.0 ({args.stream_message}) + recorder, "
          f"events; load "
          f"{min(loads):.2f}-{max(loads):.2f}")
    for (name, compose), rs in rates.items():
        print(f"{name:8s} {'composed' if compose else 'processes':9s} median "
              f"{statistics.median(rs):7.1f}  best {max(rs):7.1f}  all "
              f"{' '.join(f'{r:.0f}' for r in rs)}")


if __name__ == "__main__":
    main()

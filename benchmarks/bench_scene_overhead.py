"""Where a scene's wall time goes: ``grazing run`` of a 1300-period lockstep scene (issue 30).

Runs ``python -m grazing_control.cli run --periods 1300 --bag B --log-dir L --json`` N times
for this checkout and, side by side in the same run (alternating, so both see the same
load), for a baseline checkout (``--baseline DIR``: a git worktree of the old commit; its
interpreter is this one, its code its own: the command runs with DIR as the working
directory, and the launcher puts DIR on the nodes' PYTHONPATH). Each scene's timeline
comes from the wall clock of this script (start, exit of the command) and the nodes'
log lines (ROS's epoch time stamps):

- ``up``: the command started -> the last node's first log line (process spawn, imports,
  rclpy init, the node constructed; the launcher's own start-up included);
- ``handshake``: -> the simulator's "start conditions met" (discovery, matching, the
  recorder's ready, the settle delays, the kernel's warm-up);
- ``simulating``: the simulator's own ``wall=`` (first sample to last period);
- ``end``: the simulator's summary -> the recorder's "closed" line (the published records,
  the acknowledgements, the bag closed);
- ``exit``: -> the command returned (process exits, the launcher's own end);
- ``overhead`` = wall - simulating (issue 30's acceptance: <= 1.5 s).

With ``--composed`` the same scene composed (``grazing run --compose``: the three nodes in
one process, grazing_control/ros/composed.py) runs too, alternating with the others.

Run: ``.venv/bin/python benchmarks/bench_scene_overhead.py --reps 3 --baseline /tmp/base``
(about 15 s a scene on an idle machine). Results in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAMP = re.compile(r"\[(\w+)\] \[(\d+\.\d+)\] \[(\w+)\]: (.*)")
PHASES = ("up", "handshake", "simulating", "end", "exit", "wall", "overhead")


def log_events(log_dir: Path) -> dict:
    """(node, first|start|summary|closed) -> epoch seconds, and the simulating seconds."""
    ev = {}
    for log in log_dir.glob("*.log"):
        for line in log.read_text(errors="replace").splitlines():
            m = STAMP.match(line)
            if not m:
                continue
            t, node, text = float(m.group(2)), m.group(3), m.group(4)
            ev.setdefault((node, "first"), t)
            if text.startswith("start conditions met"):
                ev[(node, "start")] = t
            elif text.startswith("summary:"):
                ev[(node, "summary")] = t
                w = re.search(r"wall=([\d.]+)s", text)
                if w and node == "sim_node":
                    ev["simulating"] = float(w.group(1))
            elif text.startswith("closed "):
                ev[(node, "closed")] = t
    return ev


def one_scene(root: Path, periods: int, extra=()) -> dict:
    """One ``grazing run`` of ``root``'s code; its phases in seconds."""
    with tempfile.TemporaryDirectory(prefix="scene_overhead_") as tmp:
        tmp = Path(tmp)
        cmd = [sys.executable, "-m", "grazing_control.cli", "run", "--periods", str(periods),
               "--bag", str(tmp / "bag"), "--log-dir", str(tmp / "logs"), "--json", *extra]
        env = dict(os.environ, PYTHONPATH=str(root))
        t0 = time.time()
        proc = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
        t1 = time.time()
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n"
                               f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
        ev = log_events(tmp / "logs")
    up = max(v for k, v in ev.items() if isinstance(k, tuple) and k[1] == "first")
    start = ev[("sim_node", "start")]
    summary = ev[("sim_node", "summary")]
    closed = ev[("recorder_node", "closed")]
    wall = t1 - t0
    return {"up": up - t0, "handshake": start - up, "simulating": ev["simulating"],
            "end": closed - summary, "exit": t1 - closed, "wall": wall,
            "overhead": wall - ev["simulating"]}


def load() -> str:
    return "load %.2f %.2f %.2f" % os.getloadavg()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3, help="scenes per checkout (default 3)")
    ap.add_argument("--periods", type=int, default=1300)
    ap.add_argument("--baseline", type=Path, default=None,
                    help="a checkout of the old code to run side by side (default: none)")
    ap.add_argument("--composed", action="store_true",
                    help="also this checkout's scene composed (grazing run --compose: the "
                         "nodes in one process), side by side")
    ap.add_argument("--only-composed", action="store_true",
                    help="run every checkout's scene composed (this one's and the "
                         "baseline's: a change to the composed scene against the old one)")
    args = ap.parse_args(argv)
    both = ("--compose",) if args.only_composed else ()
    runs = {"this": (ROOT, both)} | ({"composed": (ROOT, ("--compose",))}
                                     if args.composed and not both else {}) \
        | ({"baseline": (args.baseline.resolve(), both)} if args.baseline else {})
    for name, (root, extra) in runs.items():   # a fresh checkout compiles numba's cache once
        one_scene(root, 20, extra)
    rows = {name: [] for name in runs}
    for rep in range(args.reps):
        for name, (root, extra) in runs.items():
            before = load()
            r = one_scene(root, args.periods, extra)
            rows[name].append(r)
            print(f"{name:8s} rep {rep}: " + " ".join(f"{k}={r[k]:.2f}" for k in PHASES)
                  + f"  ({before})", flush=True)
    print(f"\nmedians over {args.reps} scenes of {args.periods} periods (seconds):")
    print(f"{'':10s}" + "".join(f"{k:>11s}" for k in PHASES))
    for name, rs in rows.items():
        print(f"{name:10s}" + "".join(f"{statistics.median(r[k] for r in rs):11.2f}"
                                      for k in PHASES))
    med = {name: {k: statistics.median(r[k] for r in rs) for k in PHASES}
           for name, rs in rows.items()}
    for name in med:
        if name != "this":
            print(f"{name} / this: wall {med[name]['wall'] / med['this']['wall']:.2f}, "
                  f"overhead {med[name]['overhead'] / med['this']['overhead']:.2f}")
    print(load())
    return 0


if __name__ == "__main__":
    sys.exit(main())

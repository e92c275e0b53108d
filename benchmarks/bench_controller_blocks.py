"""The stream controller's CPU per message, without the middleware's noise (issue 30).

The T/200 scene's answers come from ``controller_node._on_state_block``: each stream
block's samples taken in order, and in the block that makes a section due, the section's
estimate and its answer. Timed in a live scene, that callback's CPU time mixes the
controller's own work with what this shared machine does to it (docs/benchmarks.md,
"What the misses left are made of"). Here one realtime scene of ``bench_stream_blocks``
(T/200 at x1000 in blocks, a block per wake-up; sigma 1e-4, position only, the
least-noise gains for delay 3, control from ``--enable-after``) is recorded once; then a ``ControllerNode`` of each
checkout, created in-process with the parameters of that scene's controller (the model
filter, ``answer_lead`` ``--answer-lead``), is handed every recorded block as its
subscription would hand it (the serialized message), and each call's thread CPU time is
read (``time.thread_time``). Its publishers publish to no reader.

Printed per arm: the blocks that answered a section and the others, p50 / p99 / max in
ms, and the ratio of the medians against the baseline (``--baseline DIR``, a git worktree
of an older commit: its node in a fresh interpreter there, the two alternating ``--reps``
times).

Run: ``.venv/bin/python benchmarks/bench_controller_blocks.py --baseline /tmp/base``.
Results in docs/benchmarks.md, "Section 0".
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: One arm: run with a checkout as the working directory; argv: bag, parameters (JSON).
#: Prints the block times as JSON.
ARM = r"""
import json, os, sys, time
sys.path.insert(0, os.getcwd())
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from grazing_control.recordings import reader
from grazing_control.ros.controller_node import ControllerNode

bag, values = sys.argv[1], json.loads(sys.argv[2])
rclpy.init(args=["--ros-args", "--log-level", "warn"])
node = ControllerNode(parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
raw = reader.read_raw(bag, ["/oscillator/state_block"])
cols = reader.serialized(raw, "/oscillator/state_block")
section, other = [], []
for i in np.flatnonzero(cols["ok"]).tolist():
    before = node.answered
    c0 = time.thread_time()
    node._on_state_block(cols["data"][i])
    (section if node.answered != before else other).append((time.thread_time() - c0) * 1e3)
node.destroy_node()
rclpy.shutdown()
print(json.dumps({"section": section, "other": other}))
"""


def record(tmp: Path, periods: int, enable_after: int) -> tuple:
    """(bag, the controller's parameters) of one realtime T/200 scene at x1000
    (``bench_stream_blocks.scene``, variant block: a block per wake-up, as the
    controller takes them live)."""
    sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]
    import bench_stream_blocks as b
    import yaml
    from grazing_control.oscillator.params import OscillatorParams

    controller = b.design(tmp)
    r = b.scene("block", controller, periods, enable_after, 1000.0, tmp)
    if "failed" in r or not r.get("ok"):
        raise SystemExit(f"the recording scene failed: {r}")
    p = OscillatorParams(delta_d=b.DD)
    values = next(iter(yaml.safe_load(controller.read_text()).values()))["ros__parameters"]
    values.update(pi2_source="stream", estimator="model", stream_message="block",
                  enable_after=enable_after, state_period=p.period / b.RATE,
                  sensor_noise=b.SIGMA, delta_d=b.DD)
    return tmp / "bag", values


def arm(root: Path, bag: Path, values: dict) -> dict:
    from grazing_control.ros.launcher import claim_domain

    domain, lock = claim_domain()        # a domain of its own, held while the arm runs
    try:
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", ROS_DOMAIN_ID=str(domain))
        out = subprocess.run([sys.executable, "-c", ARM, str(bag), json.dumps(values)],
                             cwd=root, capture_output=True, text=True, env=env)
    finally:
        lock.close()
    if out.returncode != 0:
        raise SystemExit(f"{root}: exit {out.returncode}: {out.stderr.strip()[-600:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _row(name: str, times: list) -> str:
    q = statistics.quantiles(times, n=100)
    return (f"{name:14s} {len(times):7d} {statistics.median(times):8.3f} {q[98]:8.3f} "
            f"{max(times):8.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=1500)
    ap.add_argument("--enable-after", type=int, default=300)
    ap.add_argument("--answer-lead", type=float, default=2.95)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--baseline", type=Path, default=None)
    args = ap.parse_args(argv)
    roots = {"this": ROOT} | ({"base": args.baseline.resolve()} if args.baseline else {})
    with tempfile.TemporaryDirectory(prefix="controller_blocks_") as tmp:
        bag, values = record(Path(tmp), args.periods, args.enable_after)
        values["answer_lead"] = args.answer_lead
        runs = {name: [] for name in roots}
        for rep in range(args.reps):
            for name in (list(roots) if rep % 2 == 0 else list(roots)[::-1]):
                runs[name].append(arm(roots[name], bag, values))
    print(f"\n{args.periods} periods of the T/200 stream (a realtime recording), answer_lead "
          f"{args.answer_lead:g}, {args.reps} runs an arm; CPU ms a block")
    print(f"{'arm, blocks':14s} {'calls':>7s} {'p50':>8s} {'p99':>8s} {'max':>8s}")
    med = {}
    for name, rs in runs.items():
        for kind in ("section", "other"):
            times = [t for r in rs for t in r[kind]]
            med[name, kind] = statistics.median(times)
            print(_row(f"{name} {kind}", times))
    if "base" in roots:
        for kind in ("section", "other"):
            print(f"{kind} blocks, this / base (medians): "
                  f"{med['this', kind] / med['base', kind]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

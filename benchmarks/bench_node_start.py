"""CPU a node process costs from start to stop: spawned, or forked from the node zygote
(grazing_control/ros/node_zygote.py; issue 30, the suite's CPU).

For each node (controller_node with config/controller.yaml, sim_node with
config/study.yaml and no controller, recorder_node writing a bag), alternately spawned
(``launcher.start_node`` as ``grazing run`` does) and forked (the same call with the
zygote enabled, as the test suite has it): start the node, wait for its first log line
(its constructor has run), stop it (SIGTERM, as ``stop_nodes``), and read the CPU it used
(``RUSAGE_CHILDREN``, user + system). The zygote's own start is paid once per owner and
is printed apart. Prints the medians and their ratio.

Run: ``.venv/bin/python benchmarks/bench_node_start.py --reps 6``. Results in
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

from grazing_control.ros import launcher, node_zygote


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def one_node(name: str, tmp: Path, i: int) -> float:
    module = launcher.MODULES[name]
    files = {"controller_node": [launcher.CONFIG_DIR / "controller.yaml"],
             "sim_node": [launcher.CONFIG_DIR / "study.yaml"]}.get(name, [])
    over = {"output": str(tmp / f"bag{i}")} if name == "recorder_node" else {}
    log = tmp / f"{name}{i}.log"
    c0 = children_cpu()
    proc = launcher.start_node(module, files, over, domain_id=launcher.MAX_DOMAIN_ID, log=log)
    end = time.monotonic() + 120
    while "[INFO]" not in log.read_text(errors="replace"):
        if proc.poll() is not None or time.monotonic() > end:
            raise RuntimeError(f"{name} did not log:\n{log.read_text()}")
        time.sleep(0.01)
    launcher.stop_nodes([proc])
    if proc.returncode != 0:
        raise RuntimeError(f"{name} ended {proc.returncode}:\n{log.read_text()}")
    return children_cpu() - c0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=6, help="nodes of each kind each way")
    args = ap.parse_args(argv)
    print("load %.2f %.2f %.2f" % os.getloadavg())
    c0, t0 = children_cpu(), time.monotonic()
    node_zygote.enable()
    if node_zygote.owner_zygote(launcher.node_env(), launcher.MODULES.values()) is None:
        print("the zygote did not start", file=sys.stderr)
        return 1
    print(f"zygote start: {children_cpu() - c0:.2f} CPU-s so far (its imports are counted "
          f"when it exits), {time.monotonic() - t0:.2f} s wall")
    with tempfile.TemporaryDirectory(prefix="bench_node_start_") as tmp:
        for name in ("controller_node", "sim_node", "recorder_node"):
            got = {False: [], True: []}
            for i in range(2 * args.reps):
                forked = i % 2 == 1
                node_zygote._enabled = forked
                got[forked].append(one_node(name, Path(tmp), i))
            s, f = statistics.median(got[False]), statistics.median(got[True])
            print(f"{name:16s} CPU-s a node: spawned {s:.3f} (min {min(got[False]):.3f}), "
                  f"forked {f:.3f} (min {min(got[True]):.3f}); ratio {s / f:.2f}")
    print("load %.2f %.2f %.2f" % os.getloadavg())
    return 0


if __name__ == "__main__":
    sys.exit(main())

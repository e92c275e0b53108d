"""The live view's cost to the loop: the same scenes with and without live_node (issue 19 §1).

Every scene runs through :func:`grazing_control.ros.launcher.run` (sim_node and
controller_node as separate processes, Fast DDS, a ROS_DOMAIN_ID of its own), side by side
in one run of this script, one scene of each case per round and the order reversed
every other round, so that a drift of the machine's load favours no case:

1. **Lockstep rate**: ``--periods`` controlled periods (enable_after 0, Delta d = -5e-6),
   a state message every 1.0 of simulation time, default executor; the rate is the
   simulator's own count (periods / wall seconds from its first sample to its last).
2. **Realtime latency tail**: time_scale ``--scale``, ``--samples`` samples, state every
   1.0, ``actuation:=on_arrival``; latency p50/p99/max and the sample lag p99 from the
   simulator's summary.

Cases: without a view; live_node with its default parameters (as ``grazing run --live
PORT`` starts it; priority idle) on the scene's domain and no client; the same with a
Foxglove WebSocket client (tests/foxglove_client.py) in this process subscribed to
every channel before the scene starts (the frames it received are printed, so that
the view was really attached). The ratios printed are each case / without (medians).

Run: ``.venv/bin/python benchmarks/bench_live.py`` (about 8 minutes; ``--quick``).
Results in docs/benchmarks.md, "Live view".
"""

from __future__ import annotations

import argparse
import os
import platform
import socket
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from bench_closed_loop import CONTROLLER, STUDY, summary  # noqa: E402
from foxglove_client import FoxgloveClient  # noqa: E402
from grazing_control.ros import launcher  # noqa: E402


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


CASES = ((None, "without live view"), ("idle", "live view, no client"),
         ("client", "live view + client"))


def scene(periods, sim_overrides, live):
    """One launcher run; returns (the simulator's summary, frames the client received).

    ``live``: None (no view), "idle" (live_node and no client) or "client" (live_node and
    a subscribed client). With a view: live_node (its defaults, as ``grazing run --live`` starts it) on the
    scene's domain and the client subscribed before the scene starts, so that the rows
    compare the loop's steady state with the view attached, not the view's start-up.
    """
    domain, lock = launcher.claim_domain()
    proc = client = None
    try:
        with tempfile.TemporaryDirectory(prefix="bench_live_") as tmp:
            if live:
                port = free_port()
                proc = launcher.start_node(launcher.LIVE_MODULE, (), {"port": port},
                                           domain_id=domain, log=Path(tmp) / "live.log")
                client = FoxgloveClient(port, timeout=60)   # the view is up
                if live == "idle":
                    client.close()
                    client = None
            res = launcher.run(STUDY, CONTROLLER, None, periods, domain_id=domain,
                               timeout=600, sim_overrides={"delta_d": -5e-6, **sim_overrides},
                               controller_overrides={"enable_after": 0}, log_dir=tmp)
            if not res.ok:
                raise RuntimeError(f"run failed: {res}\n"
                                   f"{Path(res.logs['sim_node']).read_text()}")
            result = summary(Path(res.logs["sim_node"]))
            frames = 0
            if client is not None:
                client.wait_for(lambda c: False, 0.5)
                frames = client.frames
    finally:
        if client is not None:
            client.close()
        launcher.stop_nodes([proc])
        lock.close()
    return result, frames


def paired(repeat, periods, over):
    """``repeat`` rounds of one scene per case, the order reversed every other round;
    {case: [(summary, frames), ...]}."""
    runs = {case: [] for case, _ in CASES}
    for r in range(repeat):
        for case, _ in (CASES if r % 2 == 0 else CASES[::-1]):
            runs[case].append(scene(periods, over, case))
    return runs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--periods", type=int, default=3000, help="lockstep periods per run")
    ap.add_argument("--samples", type=int, default=2000, help="realtime samples per run")
    ap.add_argument("--scale", type=float, default=1000.0, help="realtime time_scale")
    ap.add_argument("--repeat", type=int, default=3, help="rounds (a run of each case)")
    ap.add_argument("--quick", action="store_true", help="1000 periods, 500 samples, 1 round")
    ap.add_argument("--only", choices=("lockstep", "realtime"), default=None,
                    help="run only one of the two parts")
    args = ap.parse_args(argv)
    if args.quick:
        args.periods, args.samples, args.repeat = 1000, 500, 1
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[:3]
    print(f"live view benchmark: python {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"load average {' '.join(load)} at the start; {args.repeat} round(s), "
          "order reversed every other round")

    if args.only != "realtime":
        lockstep(args)
    if args.only != "lockstep":
        realtime(args)
    with open("/proc/loadavg") as fh:
        print(f"\nload average at the end: {' '.join(fh.read().split()[:3])}")


def lockstep(args):
    lock = paired(args.repeat, args.periods, {"state_period": 1.0})
    rate = {k: [float(s["rate"]) for s, _ in v] for k, v in lock.items()}
    print(f"\nlockstep, {args.periods} controlled periods, state every 1.0")
    print(f"{'':22s} {'periods/s median':>16s} {'runs':>24s} {'frames to client':>17s}")
    for live, name in CASES:
        runs = " ".join(f"{r:.0f}" for r in rate[live])
        frames = statistics.median(f for _, f in lock[live])
        print(f"{name:22s} {statistics.median(rate[live]):16.0f} {runs:>24s} {frames:17.0f}")
    for live, name in CASES[1:]:
        print(f"ratio {name} / without (median rate): "
              f"{statistics.median(rate[live]) / statistics.median(rate[None]):.3f}")



def realtime(args):
    rt = paired(args.repeat, args.samples, {"mode": "realtime", "time_scale": args.scale,
                                            "state_period": 1.0, "actuation": "on_arrival"})
    print(f"\nrealtime, time_scale {args.scale:g}, {args.samples} samples, state every 1.0, "
          "apply on arrival; latency ms (median over runs of each quantile)")
    print(f"{'':22s} {'p50':>7s} {'p99':>7s} {'max':>7s} {'lag p99':>8s} {'late':>5s} "
          f"{'frames':>7s}")
    med = {}
    for live, name in CASES:
        lat = [s["latency"] for s, _ in rt[live]]
        med[live] = [statistics.median(q[i] for q in lat) for i in range(3)]
        lag = statistics.median(s["sample_lag"][1] for s, _ in rt[live])
        late = statistics.median(int(s["late"]) for s, _ in rt[live])
        frames = statistics.median(f for _, f in rt[live])
        print(f"{name:22s} {med[live][0]:7.3f} {med[live][1]:7.3f} {med[live][2]:7.3f} "
              f"{lag:8.3f} {late:5.0f} {frames:7.0f}")
    for live, name in CASES[1:]:
        print(f"ratio {name} / without: p50 {med[live][0] / med[None][0]:.3f}, "
              f"p99 {med[live][1] / med[None][1]:.3f}")


if __name__ == "__main__":
    main()

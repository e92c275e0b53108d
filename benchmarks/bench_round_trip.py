"""The middleware's floor: a bare rclpy round trip next to the realtime answer latency (issue 30).

Two processes and nothing else: *ping* publishes a Pi2-sized sample (packed
sensor_msgs/JointState, the bytes sim_node sends on ``oscillator/pi2``) every T/scale of
wall time from a timer, *pong* answers each in its subscription callback with the packed
TwistStamped a controller sends (``controller/velocity_correction``, stamp = the sample's);
ping takes the wall time from publishing a sample to its answer's callback. The floor's
quantiles leave out, as the simulator's do, the answers that came after the next two
samples went out (the simulator ignores such an answer: it answers none of the last two
unanswered samples, and it is not in its latency); their count and the quantiles of all
are printed beside. The same as
the nodes: raw (serialized) publish and take, publishers keep last 100000 and
subscriptions keep last 1000, reliable, volatile (:data:`grazing_control.ros.common.
PUBLISHER_QOS`, ``DATA_QOS``), no QoS-event callbacks, the executor of the scene
(``--executor``, default ``events``), the heap frozen before spinning, and the launcher's
environment (:func:`grazing_control.ros.launcher.node_env`: the Fast DDS profile
``grazing_control/ros/fastdds_profile.xml``, one BLAS thread). No controller law, no
simulation, no recorder: what is left of the realtime scene's latency is the middleware's.

With ``--composed`` the same scene also runs composed (``grazing run --compose``: both
nodes in one process, the answer delivered in the process; the floor stays the two
processes' round trip, what the middleware allows between processes).

In the same run, alternating with it (both see the same load), the realtime scene of
``benchmarks/bench_closed_loop.py`` part 2: sim_node and controller_node through the
launcher at ``--scale`` with ``actuation:=on_arrival`` (latency = a sample published ->
its correction applied), state off, every sample answered, the watchdog's excursion and misses off
(a correction applied on arrival acts later than designed: at x1000 the orbit was lost
at sample 51 and the scene ended; the latency is what is measured, not the control). Printed: p50/p99/max of each
and the scene's over the floor's (issue 30's acceptance: the scene's p99 <= 1.0 ms and
<= 1.5x the floor's p99).

Run: ``.venv/bin/python benchmarks/bench_round_trip.py --reps 3`` (about 1 min a rep on
an idle machine). Results in docs/benchmarks.md ("The middleware's floor").
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

#: Wall seconds the ping waits for its peer's match before it gives up.
MATCH_TIMEOUT = 30.0
#: Wall seconds between the match and the first sample (the scenes' settle, 0.2 s).
SETTLE = 0.2
#: Wall seconds the ping waits for the last answers after the last sample.
DRAIN = 5.0


def quantiles_ms(values) -> tuple:
    """(p50, p99, max) of wall seconds, in ms (the simulator's summary: nearest rank)."""
    v = sorted(values)
    rank = lambda q: v[min(len(v) - 1, max(0, math.ceil(q * len(v)) - 1))]  # noqa: E731
    return rank(0.5) * 1e3, rank(0.99) * 1e3, v[-1] * 1e3


def _node(name: str, executor_kind: str):
    """rclpy initialised, a node, its executor (as run_node builds them)."""
    import rclpy
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    from grazing_control.ros.common import make_executor

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node(name)
    executor = make_executor(executor_kind)
    executor.add_node(node)
    return node, executor


def _endpoints(node):
    from geometry_msgs.msg import TwistStamped
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    from sensor_msgs.msg import JointState

    from grazing_control.ros.common import DATA_QOS, PUBLISHER_QOS

    no_pub_events = PublisherEventCallbacks(use_default_callbacks=False)
    no_sub_events = SubscriptionEventCallbacks(use_default_callbacks=False)
    return (JointState, TwistStamped, PUBLISHER_QOS, DATA_QOS, no_pub_events, no_sub_events)


def _prioritise(priority: int) -> None:
    """SCHED_FIFO at ``priority`` for this process and every thread it has (the
    middleware's too), as the nodes' ``thread_priority`` does (ros/scheduling.py); 0: off.
    The floor gets what the scene gets, so that their ratio stays a fair one."""
    if priority:
        from grazing_control.ros.scheduling import apply_scheduling

        done = apply_scheduling(priority)
        if done.warnings:
            raise SystemExit("; ".join(done.warnings))


def pong(executor_kind: str, priority: int = 0) -> int:
    """Answer every sample on ``oscillator/pi2`` with a TwistStamped of its stamp (read
    as the controller reads it, :func:`cdr.read_sample`), until the ping's last sample
    (stamp sec :data:`DONE_SEC`)."""
    from grazing_control.ros import cdr
    from grazing_control.ros.common import freeze_heap

    node, executor = _node("round_trip_pong", executor_kind)
    js, tw, pub_qos, sub_qos, no_pub, no_sub = _endpoints(node)
    pub = node.create_publisher(tw, "controller/velocity_correction", pub_qos,
                                event_callbacks=no_pub)
    state = {"done": False}

    def on_sample(data: bytes) -> None:
        sec, nanosec, _x, _v = cdr.read_sample(data)
        pub.publish(cdr.twist_stamped(sec, nanosec, 0.0))
        if sec == DONE_SEC:
            state["done"] = True

    node.create_subscription(js, "oscillator/pi2", on_sample, sub_qos, raw=True,
                             event_callbacks=no_sub)
    _prioritise(priority)
    freeze_heap()
    t_end = time.monotonic() + MATCH_TIMEOUT * 10
    while not state["done"] and time.monotonic() < t_end:
        executor.spin_once(timeout_sec=0.05)
    time.sleep(0.2)          # the last answer acknowledged (50 ms heartbeat)
    os._exit(0)


#: The stamp's seconds of the sample that ends the pong.
DONE_SEC = 2**31 - 1


def ping(executor_kind: str, samples: int, interval: float, priority: int = 0) -> int:
    """Publish ``samples`` samples, one every ``interval`` wall s; print the round trips
    (wall seconds, in sample order) as one JSON line."""
    from grazing_control.ros import cdr
    from grazing_control.ros.common import freeze_heap

    node, executor = _node("round_trip_ping", executor_kind)
    js, tw, pub_qos, sub_qos, no_pub, no_sub = _endpoints(node)
    pub = node.create_publisher(js, "oscillator/pi2", pub_qos, event_callbacks=no_pub)
    sent, trips = {}, {}

    def on_answer(data: bytes) -> None:
        now = time.perf_counter()
        answer = cdr.read_twist_stamped(data)
        if answer is not None and answer[0] in sent:
            trips[answer[0]] = now - sent[answer[0]]

    sub = node.create_subscription(tw, "controller/velocity_correction", on_answer, sub_qos,
                                   raw=True, event_callbacks=no_sub)
    t_end = time.monotonic() + MATCH_TIMEOUT
    while (pub.get_subscription_count() < 1 or sub.get_publisher_count() < 1) \
            and time.monotonic() < t_end:
        executor.spin_once(timeout_sec=0.02)
    if pub.get_subscription_count() < 1:
        print(json.dumps({"error": "no pong matched"}))
        os._exit(1)
    _prioritise(priority)
    t_settle = time.monotonic() + SETTLE
    while time.monotonic() < t_settle:
        executor.spin_once(timeout_sec=0.02)
    freeze_heap()
    state = {"k": 0}

    def on_tick() -> None:
        k = state["k"]
        if k >= samples:
            return
        state["k"] = k + 1
        data = cdr.joint_state(k, 0, 1e-3 * k, -0.5, 0.25)
        sent[k] = time.perf_counter()
        pub.publish(data)

    node.create_timer(interval, on_tick)
    t_end = None
    while True:
        executor.spin_once(timeout_sec=0.05)
        if state["k"] >= samples:
            t_end = t_end or time.monotonic() + DRAIN
            if len(trips) >= samples or time.monotonic() > t_end:
                break
    pub.publish(cdr.joint_state(DONE_SEC, 0, 0.0, 0.0, 0.0))
    t_wait = time.monotonic() + 0.5
    while time.monotonic() < t_wait:
        executor.spin_once(timeout_sec=0.05)
    print(json.dumps({"trips": [trips.get(k) for k in range(samples)]}), flush=True)
    os._exit(0)


def floor(executor_kind: str, samples: int, interval: float, priority: int = 0,
          budget: float = math.inf) -> dict:
    """One bare round trip run (two processes, a domain of their own): p50/p99/max ms, the
    answers lost, and the round trips longer than ``budget`` wall s (``over``)."""
    from grazing_control.ros import launcher

    domain, lock = launcher.claim_domain()     # held until both processes are done
    env = launcher.node_env(domain)
    me = [sys.executable, str(Path(__file__).resolve()), "--executor", executor_kind,
          "--priority", str(priority)]
    pong_proc = subprocess.Popen(me + ["--role", "pong"], env=env, stdout=subprocess.DEVNULL)
    try:
        out = subprocess.run(me + ["--role", "ping", "--samples", str(samples),
                                   "--interval", repr(interval)],
                             env=env, capture_output=True, text=True, timeout=300)
    finally:
        try:
            pong_proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pong_proc.kill()
            pong_proc.wait()
        lock.close()
    line = (out.stdout.strip().splitlines() or ["{}"])[-1]
    res = json.loads(line)
    if "trips" not in res:
        raise RuntimeError(f"ping failed: {out.stdout[-500:]} {out.stderr[-1500:]}")
    trips = [t for t in res["trips"] if t is not None]
    # as the simulator counts: an answer that comes after the next two samples went out
    # answers none of the last two unanswered samples; it is ignored, not in its latency
    counted = [t for t in trips if t <= 2 * interval]
    return {"latency": quantiles_ms(counted), "all": quantiles_ms(trips),
            "beyond": len(trips) - len(counted), "lost": samples - len(trips),
            "over": sum(t > budget for t in trips)}


def scene(executor_kind: str, samples: int, scale: float, compose: bool = False,
          priority: int = 0) -> dict:
    """The realtime scene of bench_closed_loop part 2 (sim_node + controller_node; with
    ``compose`` in one process, grazing run --compose)."""
    import bench_closed_loop

    s, _ = bench_closed_loop.scene(
        samples, {"mode": "realtime", "time_scale": scale, "state_period": 0.0,
                  "delta_d": -5e-6, "actuation": "on_arrival", "executor": executor_kind,
                  "watchdog_excursion": 0.0, "watchdog_misses": 0, "thread_priority": priority},
        {"enable_after": 0, "executor": executor_kind, "thread_priority": priority},
        meter=False, compose=compose)
    return {"latency": s["latency"], "late": s.get("late", "?"), "missed": s.get("missed", "?"),
            "ignored": s.get("ignored", "?")}


def load() -> str:
    return "%.2f %.2f %.2f" % os.getloadavg()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3, help="floor + scene pairs (default 3)")
    ap.add_argument("--samples", type=int, default=2000, help="samples per run (default 2000)")
    ap.add_argument("--scale", type=float, default=1000.0, help="time_scale (default 1000)")
    ap.add_argument("--executor", choices=("single_threaded", "events"), default="events")
    ap.add_argument("--composed", action="store_true",
                    help="also the scene composed (grazing run --compose), in each rep")
    ap.add_argument("--priority", type=int, default=0,
                    help="SCHED_FIFO priority 1..99 of the floor's two processes and of both "
                         "nodes (their thread_priority); 0: off (default)")
    ap.add_argument("--budget", type=float, default=None,
                    help="also count the floor's round trips longer than this many ms (a "
                         "section's answer budget: T/200 x1000's is 2.95); with --floor-only "
                         "the floor alone is run")
    ap.add_argument("--floor-only", action="store_true",
                    help="run the floor alone, --reps times (no scene)")
    ap.add_argument("--role", choices=("ping", "pong"), help=argparse.SUPPRESS)
    ap.add_argument("--interval", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.role == "pong":
        return pong(args.executor, args.priority)
    from grazing_control.oscillator.params import OscillatorParams

    interval = OscillatorParams().period / args.scale
    if args.role == "ping":
        return ping(args.executor, args.samples, args.interval or interval, args.priority)
    print(f"round trip floor vs realtime x{args.scale:g}: a sample every {interval * 1e3:.3f} "
          f"ms wall, {args.samples} samples, executor {args.executor}, priority "
          f"{args.priority or 'off'}, {os.cpu_count()} CPUs, "
          f"load {load()}")
    budget = math.inf if args.budget is None else args.budget * 1e-3
    if args.floor_only:
        over = 0
        for rep in range(args.reps):
            before = load()
            f = floor(args.executor, args.samples, interval, args.priority, budget)
            over += f["over"]
            fa = f["all"]
            print(f"rep {rep} (load {before}): floor p50/p99/max {fa[0]:.3f}/{fa[1]:.3f}/"
                  f"{fa[2]:.3f} ms, lost {f['lost']}, longer than {args.budget} ms: "
                  f"{f['over']} of {args.samples}", flush=True)
        print(f"floor alone: {over} of {args.reps * args.samples} round trips longer than "
              f"{args.budget} ms; load at the end {load()}")
        return 0
    rows = []
    for rep in range(args.reps):
        before = load()
        f = floor(args.executor, args.samples, interval, args.priority, budget)
        s = scene(args.executor, args.samples, args.scale, priority=args.priority)
        c = scene(args.executor, args.samples, args.scale, True, args.priority) \
            if args.composed else None
        rows.append((f, s) + ((c,) if c else ()))
        fl = f["latency"]
        for name, one in (("scene", s), ("composed", c)):
            if one is None:
                continue
            sl = one["latency"]
            fa = f["all"]
            print(f"rep {rep} (load {before}): floor p50/p99/max {fl[0]:.3f}/{fl[1]:.3f}/"
                  f"{fl[2]:.3f} ms ({f['beyond']} beyond 2 intervals left out; all: "
                  f"{fa[0]:.3f}/{fa[1]:.3f}/{fa[2]:.3f}; lost {f['lost']}); {name} "
                  f"{sl[0]:.3f}/{sl[1]:.3f}/{sl[2]:.3f} ms (late {one['late']}, ignored "
                  f"{one['ignored']}); ratio {sl[0] / fl[0]:.2f}/{sl[1] / fl[1]:.2f}/"
                  f"{sl[2] / fl[2]:.2f}"
                  + (f"; floor longer than {args.budget} ms: {f['over']}"
                     if args.budget is not None else ""), flush=True)
    med = lambda i, which: statistics.median(r[which]["latency"][i] for r in rows)  # noqa
    print(f"\nmedians over {args.reps} pairs (ms)       p50     p99     max")
    print(f"bare rclpy round trip (floor)   {med(0, 0):7.3f} {med(1, 0):7.3f} {med(2, 0):7.3f}")
    print(f"realtime scene (sim+controller) {med(0, 1):7.3f} {med(1, 1):7.3f} {med(2, 1):7.3f}")
    print(f"scene / floor                   {med(0, 1) / med(0, 0):7.2f} "
          f"{med(1, 1) / med(1, 0):7.2f} {med(2, 1) / med(2, 0):7.2f}")
    if args.composed:
        print(f"composed scene (one process)    {med(0, 2):7.3f} {med(1, 2):7.3f} "
              f"{med(2, 2):7.3f}")
        print(f"composed / floor                {med(0, 2) / med(0, 0):7.2f} "
              f"{med(1, 2) / med(1, 0):7.2f} {med(2, 2) / med(2, 0):7.2f}")
    print(f"acceptance: scene p99 <= 1.0 ms: {'ok' if med(1, 1) <= 1.0 else 'MISS'}; "
          f"<= 1.5x floor p99: {'ok' if med(1, 1) <= 1.5 * med(1, 0) else 'MISS'}")
    print(f"load at the end {load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

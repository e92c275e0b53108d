"""Benchmark of the recorder between messages: its CPU at a scene's pace, not at its limit.

A realtime scene at physical speed (``time_scale`` 1) sends the recorder a few hundred
messages a second: ``/clock`` at ~150 Hz, the state, the plant's pause events on
``grazing/parameters``. Measured on such a scene the recorder took 45 % of a core
(docs/benchmarks.md, "The recorder between messages"). This script publishes the same
kind of stream at a fixed pace (``/clock`` and ``oscillator/state`` in a 3:1 mix,
``--rate`` messages per second for ``--seconds``) to two recorder processes in turn,
the baseline checkout's (``--baseline``, e.g. ``git worktree add --detach /tmp/base
<rev>``) and this tree's, each recording the two topics only, and reads each one's CPU
time (``/proc/PID/stat``, user + system) over the paced window, start-up and close left
out. Every bag is read back: "lost" must be 0. Printed: the CPU per second of each, per
message, and the ratio baseline / this.

Run: ``python benchmarks/bench_recorder_pace.py --baseline /tmp/base [--rate 200]
[--seconds 10] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402

from grazing_control.ros.common import LATCHED_QOS, READY_TOPIC  # noqa: E402
from grazing_control.ros.recording import read_messages  # noqa: E402

TOPICS = ("/clock", "/oscillator/state")
CLK_TCK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def run_recorder(root: Path, rate: float, seconds: float, workdir: Path, domain: int):
    """(CPU seconds over the paced window, messages published, messages lost) of the
    recorder of checkout ``root``."""
    bag = workdir / f"bag_{root.name}_{time.monotonic_ns()}"
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONPATH=str(root))
    topics = "[" + ",".join(f"'{t}'" for t in TOPICS) + "]"
    recorder = subprocess.Popen(
        [sys.executable, "-m", "grazing_control.ros.recorder_node", "--ros-args",
         "-p", f"output:={bag}", "-p", f"topics:={topics}"],
        cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("bench_pace", context=context)
    try:
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                         reliability=ReliabilityPolicy.RELIABLE)
        clock = node.create_publisher(Clock, "/clock", qos)
        state = node.create_publisher(JointState, "/oscillator/state", qos)
        ready = []
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        node.create_subscription(Bool, READY_TOPIC, lambda m: ready.append(m.data),
                                 LATCHED_QOS)
        deadline = time.monotonic() + 60.0
        while not any(ready):
            if recorder.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"recorder not ready: {recorder.communicate()[0]}")
            executor.spin_once(timeout_sec=0.05)
        time.sleep(0.5)                                   # its start-up work done
        n = int(rate * seconds)
        cpu0, wall0 = cpu_seconds(recorder.pid), time.monotonic()
        for k in range(n):
            due = wall0 + k / rate
            pause = due - time.monotonic()
            if pause > 0.0:
                time.sleep(pause)
            if k % 4 == 3:
                msg = JointState(name=["mass"], position=[1e-3 * k], velocity=[0.5])
                msg.header.stamp.sec = k
                state.publish(msg)
            else:
                msg = Clock()
                msg.clock.sec = k
                clock.publish(msg)
        time.sleep(max(0.0, wall0 + seconds - time.monotonic()))
        cpu = cpu_seconds(recorder.pid) - cpu0
        recorder.send_signal(signal.SIGTERM)
        output, _ = recorder.communicate(timeout=60)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    if recorder.returncode != 0:
        raise RuntimeError(f"recorder exited with {recorder.returncode}:\n{output}")
    lost = n - sum(1 for _ in read_messages(bag))
    return cpu, n, lost


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", type=Path, required=True,
                        help="the baseline checkout (git worktree add --detach DIR REV)")
    parser.add_argument("--rate", type=float, default=200.0,
                        help="messages per second, /clock and the state 3:1 (default 200)")
    parser.add_argument("--seconds", type=float, default=10.0,
                        help="the paced window, seconds (default 10)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs of each, alternating (default 3)")
    args = parser.parse_args(argv)
    domain = 150 + os.getpid() % 50
    print(f"recorder at a pace: {args.rate:g} messages/s for {args.seconds:g} s, "
          f"baseline {args.baseline} against {REPO}, {args.repeat} runs each, alternating")
    cpu = {"baseline": [], "this": []}
    with tempfile.TemporaryDirectory(prefix="bench_recorder_pace_") as work:
        for _ in range(args.repeat):
            for label, root in (("baseline", args.baseline), ("this", REPO)):
                used, n, lost = run_recorder(root.resolve(), args.rate, args.seconds,
                                             Path(work), domain)
                cpu[label].append(used)
                print(f"  {label:<8} CPU {used:6.2f} s ({100 * used / args.seconds:5.1f} % "
                      f"of a core, {1e3 * used / n:.3f} ms a message), {n} messages, "
                      f"lost {lost}")
                if lost:
                    raise SystemExit(f"{label}: {lost} messages lost")
    base, this = (sum(cpu[k]) / len(cpu[k]) for k in ("baseline", "this"))
    print(f"mean CPU over the window: baseline {base:.2f} s, this {this:.2f} s, "
          f"ratio {base / this:.2f}")


if __name__ == "__main__":
    main()

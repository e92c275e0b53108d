"""Publishing the simulator's JointState: rclpy message vs packed CDR bytes, side by side.

One publisher in this process (reliable, keep last 100000, as the simulator's), one
reader in a subprocess (reliable, keep all, raw: the recorder's way), on a domain of its
own. For each way of publishing, ``--messages`` messages in bursts of 200 (2 ms apart),
and the publisher's CPU time per message (time.process_time: conversion, serialization
and Fast DDS's synchronous write to the reader):

* ``message``: ``publish(JointState)``, the header stamp and the three one-element
  arrays set on a reused message (what sim_node did before issue 8 §4's change);
* ``serialize``: ``rclpy.serialization.serialize_message`` of that message, published
  as bytes;
* ``cdr``: :func:`grazing_control.ros.cdr.joint_state` (struct.pack), published as
  bytes (what sim_node does now);
* ``pack only``: the cdr packing alone.

Best of ``--repeat`` rounds; the ratio is message / cdr. The reader reports how many it
received (all of them: nothing is lost).

Run: ``.venv/bin/python benchmarks/bench_publish.py [--messages 20000]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

READER = """
import rclpy, sys
from rclpy.experimental import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
rclpy.init()
node = rclpy.create_node("bench_publish_reader")
count = [0]
qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=0, reliability=ReliabilityPolicy.RELIABLE)
node.create_subscription(JointState, "bench/js", lambda m: count.__setitem__(0, count[0] + 1),
                         qos, raw=True)
ex = EventsExecutor()
ex.add_node(node)
print("ready", flush=True)
expected = int(sys.argv[1])
while count[0] < expected:
    ex.spin_once(timeout_sec=0.5)
print(count[0], flush=True)
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--messages", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    from grazing_control.ros.launcher import claim_domain

    domain, _lock = claim_domain()       # a domain of its own, held until the process ends
    os.environ["ROS_DOMAIN_ID"] = str(domain)

    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from grazing_control.ros import cdr

    kinds = ("message", "serialize", "cdr", "pack only")
    total = args.messages * args.repeat * (len(kinds) - 1)
    reader = subprocess.Popen([sys.executable, "-c", READER, str(total)],
                              stdout=subprocess.PIPE, text=True)
    assert reader.stdout.readline().strip() == "ready"
    rclpy.init()
    node = rclpy.create_node("bench_publish_writer")
    pub = node.create_publisher(JointState, "bench/js", QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=100000, reliability=ReliabilityPolicy.RELIABLE))
    end = time.monotonic() + 20
    while pub.get_subscription_count() < 1 and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(0.5)  # both ends of the match
    msg = JointState(name=["mass"])

    def burst(kind):
        t0 = time.process_time()
        for i in range(args.messages):
            x = i * 1e-3
            if kind in ("message", "serialize"):
                msg.header.stamp = Time(sec=i, nanosec=5)
                msg.position = [x]
                msg.velocity = [x]
                msg.effort = [x]
                pub.publish(msg if kind == "message" else serialize_message(msg))
            elif kind == "cdr":
                pub.publish(cdr.joint_state(i, 5, x, x, x))
            else:
                cdr.joint_state(i, 5, x, x, x)
            if i % 200 == 199:
                time.sleep(0.002)
        return (time.process_time() - t0) / args.messages * 1e6

    best = {k: min(burst(k) for _ in range(args.repeat)) for k in kinds}
    received = int(reader.communicate(timeout=120)[0].split()[-1])
    node.destroy_node()
    rclpy.try_shutdown()
    print(f"publishing sensor_msgs/JointState to one reader in another process (Fast DDS, "
          f"reliable), {args.messages} messages per round, best of {args.repeat}; publisher "
          "CPU microseconds per message")
    for k in kinds:
        print(f"  {k:10s} {best[k]:7.2f} us")
    print(f"  ratio message / cdr: {best['message'] / best['cdr']:.2f}x; "
          f"reader received {received} of {total}")


if __name__ == "__main__":
    main()

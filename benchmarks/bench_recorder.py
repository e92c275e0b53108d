"""Benchmark of the recorder: messages per second written with no loss.

Two measurements, side by side:

* ``BagWriter`` in-process (the baseline): pre-serialized messages of the six
  project topics, round robin, written with :class:`BagWriter` and closed;
  nothing else. This is the ceiling of the recording layer itself.
* ``recorder_node`` over Fast DDS: the recorder runs as its own process; this
  process publishes the same mix of message objects as fast as ``rclpy``
  allows, with reliable QoS and a history deep enough to hold them all, waits
  until every message is acknowledged, then sends SIGTERM. The rate is
  messages / (first publish -> recorder exited, bag closed), so it includes
  the drain and the close. The bag is then read back and every message
  counted: "lost" must be 0.

Run: ``python benchmarks/bench_recorder.py [--messages 60000] [--repeat 3]``
(PYTHONPATH must reach the repository root, as it does in the project venv).
"""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import rclpy  # noqa: E402
from geometry_msgs.msg import TwistStamped, Vector3Stamped  # noqa: E402
from mcap_ros2._dynamic import serialize_dynamic  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.duration import Duration  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from grazing_control.ros.recording.topics import DEFAULT_TOPICS  # noqa: E402
from grazing_control.ros.recording import BagWriter, message_definition, read_messages

CLASSES = {
    "sensor_msgs/msg/JointState": JointState,
    "geometry_msgs/msg/Vector3Stamped": Vector3Stamped,
    "geometry_msgs/msg/TwistStamped": TwistStamped,
    "rosgraph_msgs/msg/Clock": Clock,
}


def make_message(msg_type, i):
    """A message like the simulator's: one joint, stamped."""
    msg = CLASSES[msg_type]()
    if msg_type == "rosgraph_msgs/msg/Clock":
        msg.clock.sec = i
        return msg
    msg.header.stamp.sec = i
    if msg_type == "sensor_msgs/msg/JointState":
        msg.name, msg.position, msg.velocity, msg.effort = ["mass"], [1e-3 * i], [0.5], [1.0]
    elif msg_type == "geometry_msgs/msg/Vector3Stamped":
        msg.vector.x, msg.vector.y, msg.vector.z = -0.1, 0.08, 1.0
    else:
        msg.twist.linear.x = 1e-6 * i
    return msg


def message_mix(n):
    """(relative topic, type, index) of `n` messages, round robin over the topics."""
    topics = list(DEFAULT_TOPICS.items())
    return [(*topics[k % len(topics)], k // len(topics)) for k in range(n)]


def bench_bagwriter(n, compression, workdir):
    """Messages per second of BagWriter.write + close, in-process."""
    encoders = {t: serialize_dynamic(t, message_definition(t))[t] for t in CLASSES}
    data = [("/" + name.lstrip("/"), t, encoders[t](make_message(t, i)))
            for name, t, i in message_mix(n)]
    bag_dir = Path(workdir) / f"writer_{compression}"
    start = time.perf_counter()
    with BagWriter(bag_dir, compression=compression) as bag:
        for name, t in DEFAULT_TOPICS.items():
            bag.add_topic("/" + name.lstrip("/"), t)
        for k, (topic, _, payload) in enumerate(data):
            bag.write(topic, payload, 1_000_000 + k)
    elapsed = time.perf_counter() - start
    size = bag.path.stat().st_size
    shutil.rmtree(bag_dir)
    return n / elapsed, size


# recorder_node with BagWriter.write made a no-op: what the node costs without
# recording (subscription, executor, take), to show where the time goes.
_NO_WRITE = ("import sys, grazing_control.ros.recording as r; "
             "r.BagWriter.write = lambda *a, **k: None; "
             "from grazing_control.ros.recorder_node import main; sys.exit(main())")


def bench_node(n, compression, workdir, domain, write=True):
    """Messages per second through recorder_node, and messages lost.

    With ``write=False`` the node runs with a no-op ``BagWriter.write``
    (nothing is recorded; "lost" is then meaningless and returned as 0).
    """
    bag_dir = Path(workdir) / f"node_{compression}_{domain}"
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    program = ["-m", "grazing_control.ros.recorder_node"] if write else ["-c", _NO_WRITE]
    recorder = subprocess.Popen(
        [sys.executable, *program, "--ros-args",
         "-p", f"output:={bag_dir}", "-p", f"compression:={compression}"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("bench_publisher", context=context)
    try:
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=n,
                         reliability=ReliabilityPolicy.RELIABLE)
        pubs = {name: node.create_publisher(CLASSES[t], name, qos)
                for name, t in DEFAULT_TOPICS.items()}
        while any(p.get_subscription_count() < 1 for p in pubs.values()):
            if recorder.poll() is not None:
                raise RuntimeError(recorder.communicate()[0])
            time.sleep(0.02)
        msgs = [(pubs[name], make_message(t, i)) for name, t, i in message_mix(n)]
        start = time.perf_counter()
        for pub, msg in msgs:
            pub.publish(msg)
        published = time.perf_counter()
        for pub in pubs.values():
            if not pub.wait_for_all_acked(Duration(seconds=60)):
                raise RuntimeError("messages not acknowledged within 60 s")
        recorder.send_signal(signal.SIGTERM)
        output, _ = recorder.communicate(timeout=120)
        done = time.perf_counter()
    finally:
        if recorder.poll() is None:
            recorder.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    if recorder.returncode != 0:
        raise RuntimeError(f"recorder exited with {recorder.returncode}:\n{output}")
    lost = n - sum(1 for _ in read_messages(bag_dir)) if write else 0
    shutil.rmtree(bag_dir)
    return n / (done - start), n / (published - start), lost


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--messages", type=int, default=60_000,
                        help="messages per run, spread over the six topics (default 60000)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per case; best is kept")
    parser.add_argument("--compression", nargs="+", default=["zstd", "lz4", "none"])
    args = parser.parse_args(argv)

    n = args.messages
    print(f"recorder benchmark: {n} messages per run (6 topics, round robin), "
          f"best of {args.repeat}; python {sys.version.split()[0]}, "
          f"RMW {os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (default)')}, "
          f"{os.cpu_count()} CPUs")
    header = (f"{'compression':<12}{'BagWriter msg/s':>17}{'node msg/s':>12}{'node/writer':>13}"
              f"{'lost':>6}{'publish msg/s':>15}{'bytes/msg':>11}")
    print(header)
    print("-" * len(header))
    domain = 200 + os.getpid() % 30
    with tempfile.TemporaryDirectory(prefix="bench_recorder_") as workdir:
        for compression in args.compression:
            writer = max(bench_bagwriter(n, compression, workdir) for _ in range(args.repeat))
            runs = [bench_node(n, compression, workdir, domain) for _ in range(args.repeat)]
            node_rate, pub_rate, _ = max(runs)
            lost = max(r[2] for r in runs)
            print(f"{compression:<12}{writer[0]:>17,.0f}{node_rate:>12,.0f}"
                  f"{node_rate / writer[0]:>13.3f}{lost:>6d}{pub_rate:>15,.0f}"
                  f"{writer[1] / n:>11.1f}")
        idle = max(bench_node(n, "none", workdir, domain, write=False)
                   for _ in range(args.repeat))
        print(f"{'(no write)':<12}{'':>17}{idle[0]:>12,.0f}{'':>13}{'':>6}{idle[1]:>15,.0f}")
    print("node msg/s: first publish -> recorder exited with the bag closed (drain and close\n"
          "included); lost: published minus read back, worst run; (no write): the same node\n"
          "with BagWriter.write a no-op, i.e. the cost of subscribing alone.")


if __name__ == "__main__":
    main()

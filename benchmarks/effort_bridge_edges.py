"""effort_bridge's edges: the first and last sample of each pulse against its ROS-time window.

The scene of tests/test_rig_drivers.py (clock pairs with offset 1.6e9 s and drift 2e-4,
the forcing at 5 Hz) with 10 pulses of 60 ms, at the default control_rate 1000 Hz; prints
how far after its window's start each pulse's first sample went out (its source
timestamp) and how far from its window's end its last one, in ms, and the bridge's
summary (docs/driver_contract.md, "ros2_control: effort_bridge").

    .venv/bin/python benchmarks/effort_bridge_edges.py
"""
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_rig_drivers as T  # noqa: E402
from std_msgs.msg import Float64MultiArray
from sensor_msgs.msg import TimeReference
from geometry_msgs.msg import Vector3Stamped
from grazing_control.ros.common import stamp_from_seconds

domain = T.new_domain()
peer = T.Peer(domain, {"forward_effort_controller/commands": Float64MultiArray})
clock = peer.node.create_publisher(TimeReference, "rig/clock", T.KEEP_ALL)
phase = peer.node.create_publisher(Vector3Stamped, "rig/phase", T.KEEP_ALL)
rig_of = lambda ros: (ros - T.OFFSET) / (1.0 + T.DRIFT)
ros_of = lambda rig: T.OFFSET + (1.0 + T.DRIFT) * rig
def pair():
    m = TimeReference(); ros = time.time()
    m.header.stamp = stamp_from_seconds(ros); m.time_ref = stamp_from_seconds(rig_of(ros)); clock.publish(m)
    p = Vector3Stamped(); p.header.stamp = m.time_ref; p.vector.x = 5.0; phase.publish(p)
peer.node.create_timer(0.02, pair)
proc = T.start([T.exe("effort_bridge"), "--ros-args"], domain)
peer.wait_for(lambda: clock.get_subscription_count() > 0 and peer.pulses.get_subscription_count() > 0 and len(peer.get("forward_effort_controller/commands")) > 50)
time.sleep(0.3)
now = rig_of(time.time()); t0 = now + 0.4; w = 0.06
starts = [t0 + 0.005 + 0.2 * i for i in range(10)]
for i, s in enumerate(starts):
    peer.pulses.publish(T.pulse(s - 0.005, s, 1.0 + i, math.nan, w))
end = ros_of(starts[-1] + w)
peer.wait_for(lambda: any(src > end + 0.05 for _, src, _ in peer.get("forward_effort_controller/commands")), 60)
out = T.stop(proc); peer.close()
stream = [(src, m.data[0]) for _, src, m in peer.get("forward_effort_controller/commands")]
first = []; last = []
for i, s in enumerate(starts):
    on = [src for src, f in stream if f == 1.0 + i]
    first.append((min(on) - ros_of(s)) * 1e3); last.append((max(on) - ros_of(s + w)) * 1e3)
print("first sample after window start (ms):", " ".join(f"{x:.3f}" for x in first))
print("last sample vs window end (ms):", " ".join(f"{x:.3f}" for x in last))
print(T.summary(out))

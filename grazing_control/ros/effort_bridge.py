"""effort_bridge: scheduled force pulses as an effort stream for a rig behind ros2_control.

A rig driven by ros2_control takes its command as a stream: a
forward_command_controller with one effort joint subscribes
``forward_effort_controller/commands`` (std_msgs/Float64MultiArray) and writes
``data[0]`` to the joint at its own update rate. This node turns the contract's
``rig/force_pulse`` (docs/driver_contract.md) into that stream: every 1/``control_rate``
seconds it publishes ``data = [F]`` (N), the force of the pulse acting at that instant
and 0 otherwise.

The pulses are timed in the rig clock; the stream in ROS time (the system clock). The
node relates the two through ``rig/clock`` (sensor_msgs/TimeReference pairs: a least
squares line over the last ``clock_window`` pairs, offset and drift estimated,
:class:`grazing_control.dynamics.estimation.clock_relation.ClockRelation`): at each tick the ROS time
now is mapped to rig time, and the actuation engine
(:class:`grazing_control.plant.schedule.RigSchedule`, the one every driver uses) decides
what acts: the command at its apply time, the prediction in place of a missing one
(``on_miss``), a command that arrives after its apply time minus ``actuator_latency`` is
late (counted, never sent late). The forcing period (a section per period, for the
prediction) comes from ``rig/phase``. Until the first clock pair the stream is 0 and a
command cannot be timed (dropped, counted as ``unclocked``). A pulse's edges fall on the
stream's ticks: within one control period plus the relation's uncertainty of their
ROS-time instants while the timer keeps its rate; a tick is never early, and a pulse
that a stalled timer stepped over entirely is counted (``unsent``).

A malformed message (bytes that are no such message, non-finite fields, a width <= 0)
is counted and logged, never fatal. The summary at exit counts what acted.

Parameters (read-only): ``control_rate`` (Hz, 1000; 1..100000), ``actuator_latency``
(s, 0; 0..1), ``on_miss`` (``predict`` | ``drop``), ``clock_window`` (pairs, 200;
2..100000).
"""

from __future__ import annotations

import math

from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import TimeReference
from std_msgs.msg import Float64MultiArray

from .common import (DATA_QOS, PUBLISHER_QOS, StartupError, Throttled, check_ranges,
                     deserialize, float_descriptor, int_descriptor, run_node, seconds_from_stamp,
                     string_descriptor)
from .rig_driver import ON_MISS, read_pulse
from grazing_control.dynamics.estimation.clock_relation import ClockRelation
from grazing_control.plant.schedule import COUNTS, PulseTrain, RigSchedule

__all__ = ["EffortBridge", "main", "COMMANDS_TOPIC"]

COMMANDS_TOPIC = "forward_effort_controller/commands"


class EffortBridge(Node):
    """rig/force_pulse + rig/clock -> forward_effort_controller/commands (module docstring)."""

    def __init__(self, **kwargs):
        super().__init__("effort_bridge", **kwargs)
        rate = self.declare_parameter("control_rate", 1000.0, float_descriptor(
            "effort samples per second (Hz)", 1.0, 1e5, read_only=True)).value
        latency = self.declare_parameter("actuator_latency", 0.0, float_descriptor(
            "seconds a command must arrive before its apply time", 0.0, 1.0,
            read_only=True)).value
        self.on_miss = self.declare_parameter("on_miss", "predict", string_descriptor(
            "what acts when a command misses its deadline", read_only=True,
            choices=ON_MISS)).value
        window = self.declare_parameter("clock_window", 200, int_descriptor(
            "rig/clock pairs of the clock relation's fit", 2, 100_000, read_only=True)).value
        if self.on_miss not in ON_MISS:
            raise StartupError(f"on_miss={self.on_miss!r} is invalid: valid values are "
                               + ", ".join(ON_MISS))
        check_ranges(self)           # exactly the described ranges (docs/nodes.md)
        self.schedule = RigSchedule(lead=latency)
        self.train = PulseTrain()
        self.relation = ClockRelation(window)
        self.malformed = Throttled(self.get_logger(), "malformed message")
        self.unclocked = Throttled(self.get_logger(),
                                   "force pulse before any rig/clock pair (dropped)")
        self.late = Throttled(self.get_logger(), "late force pulse (dropped)")
        self.sent = 0
        self.pub = self.create_publisher(Float64MultiArray, COMMANDS_TOPIC, PUBLISHER_QOS)
        self.create_subscription(WrenchStamped, "rig/force_pulse", self.on_pulse, DATA_QOS,
                                 raw=True)
        self.create_subscription(TimeReference, "rig/clock", self.on_clock, DATA_QOS,
                                 raw=True)
        self.create_subscription(Vector3Stamped, "rig/phase", self.on_phase, DATA_QOS,
                                 raw=True)
        self.create_timer(1.0 / rate, self.tick)

    def ros_now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def rig_now(self) -> float | None:
        """The rig clock now through the relation, or None before the first pair."""
        fit = self.relation.fit
        return None if fit is None else fit.rig_time(self.ros_now())

    def tick(self) -> None:
        """One sample of the stream: what acts at this instant."""
        now = self.rig_now()
        force = 0.0
        if now is not None:
            for act in self.schedule.due(now, self.on_miss):
                self.train.add(act.section.start, act.section.width, act.value)
            force = self.train.force(now)
        msg = Float64MultiArray()
        msg.data = [float(force)]
        self.pub.publish(msg)
        self.sent += 1

    def on_pulse(self, data: bytes) -> None:
        fields = read_pulse(data, self.malformed)
        if fields is None:
            return
        now = self.rig_now()
        if now is None:
            self.unclocked(f"section t={fields[0]:.6f} s")
            return
        for act in self.schedule.due(now, self.on_miss):   # what is due acts first
            self.train.add(act.section.start, act.section.width, act.value)
        t, start, force, predicted, width = fields
        if self.schedule.pulse(t, start, force, predicted, width, now).outcome == "late":
            self.late(f"section t={t:.6f} s: apply time {start:.6f} s, received at "
                      f"{now:.6f} s (rig clock)")

    def on_clock(self, data: bytes) -> None:
        msg = deserialize(data, TimeReference, self.malformed)
        if msg is None:
            return
        rig, ros = seconds_from_stamp(msg.time_ref), seconds_from_stamp(msg.header.stamp)
        if not self.relation.add(rig, ros):
            self.malformed(f"rig/clock: pair (rig {rig!r}, ROS {ros!r}) does not advance")

    def on_phase(self, data: bytes) -> None:
        msg = deserialize(data, Vector3Stamped, self.malformed)
        if msg is None:
            return
        f = msg.vector.x
        if not (math.isfinite(f) and f > 0.0):
            self.malformed(f"rig/phase: frequency vector.x={f!r} is invalid: valid range "
                           "is > 0 Hz")
            return
        self.schedule.period = 1.0 / f

    def summary(self) -> str:
        fit = self.relation.fit
        counts = {name: self.schedule.counts[name] for name in COUNTS}
        text = ("summary: " + " ".join(f"{k}={v}" for k, v in counts.items())
                + f" unclocked={self.unclocked.count} malformed={self.malformed.count}"
                + f" unsent={self.train.unsent} sent={self.sent}")
        if fit is not None:
            text += (f" clock_offset={fit.offset:.9f}s clock_drift={fit.drift:.3e}"
                     f" clock_jitter={fit.jitter:.3e}s pairs={fit.n}")
        return text

    def on_exit(self) -> None:
        self.get_logger().info(self.summary())


def main(args=None) -> int:
    return run_node(EffortBridge, args, "effort_bridge")


if __name__ == "__main__":
    raise SystemExit(main())

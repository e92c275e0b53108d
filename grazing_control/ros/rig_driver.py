"""The base of a rig driver: the driver contract's topics around four hooks a lab fills in.

A driver owns the rig's hardware and speaks docs/driver_contract.md. This node does the
contract's part: it publishes ``rig/sensor`` (sensor_msgs/JointState, metres, stamped in
the rig clock), ``rig/phase`` (geometry_msgs/Vector3Stamped: the forcing frequency in Hz
and its phase at a rig-clock instant, once per forcing period), ``rig/clock``
(sensor_msgs/TimeReference: a ROS-time / rig-time pair read together, ``clock_rate``
times a second), takes ``rig/force_pulse`` (geometry_msgs/WrenchStamped) through the
actuation engine in the rig clock
(:class:`grazing_control.plant.schedule.RigSchedule`: deadline at the apply time minus
the actuator's latency, the prediction in place of a missing command, late ones counted
and dropped) and publishes what acted on ``rig/applied``, one per section. A subclass
overrides the hooks:

``rig_time()``
    the rig clock now, in seconds (the DAQ's sample clock, the microcontroller's timer);
``read_sensor()``
    the samples measured since the last call: (t, x, v) with t in the rig clock, x in
    metres (+ towards the stop), v in m/s or None for a position-only sensor; for a rig
    of n masses x (and v) a sequence over the measured masses, in the order of
    ``joint_names`` (set it to rig_boundary.joint_names(rig): ``mass<i>``, the rig
    file's ``sensor.masses``; ``["mass"]`` by default);
``phase_reference()``
    (t_ref, f, phi): the forcing's phase phi (rad) at rig time t_ref and its frequency
    f (Hz) (a signal generator's sync output);
``write_pulse(start, width, force)``
    a timed output: ``force`` newtons from rig time ``start`` for ``width`` seconds
    (the DAQ's scheduled write; called ``actuator_latency`` before the start).

Every ``poll_period`` wall seconds the node reads the sensor block, publishes it, the
phase reference when due (once per forcing period) and the clock pair when due, and
hands every section due to ``write_pulse``. A malformed command (bytes that are no
WrenchStamped, a non-finite field, a width <= 0) is counted and logged, never fatal. The
summary at exit counts what acted (``applied``, ``predicted``, ``missed``, ``late``,
``ignored``) and the malformed commands. drivers/template_driver.py is the template a
lab copies; ``rig_mock`` (mock hardware replaying a bag) is another driver on this base.

Parameters (read-only): ``poll_period`` (s, 0.002; 1e-4..1), ``clock_rate`` (Hz, 20;
10..1000), ``actuator_latency`` (s, 0; 0..1), ``on_miss`` (``predict`` | ``drop``).
"""

from __future__ import annotations

import math

from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState, TimeReference

from .common import (DATA_QOS, PUBLISHER_QOS, StartupError, Throttled, check_ranges,
                     deserialize, float_descriptor, seconds_from_stamp, stamp_from_seconds,
                     string_descriptor)
from grazing_control.plant.schedule import COUNTS, RigSchedule

__all__ = ["RigDriver", "pulse_fields", "read_pulse", "applied_message", "ON_MISS", "TOPICS"]

#: The contract's topics (relative names) and types.
TOPICS = {
    "rig/sensor": JointState,
    "rig/phase": Vector3Stamped,
    "rig/clock": TimeReference,
    "rig/applied": WrenchStamped,
    "rig/force_pulse": WrenchStamped,
}
ON_MISS = ("predict", "drop")
#: rig/applied's code for the safe state (docs/driver_contract.md)
SAFE_STATE = 3


def pulse_fields(msg) -> tuple:
    """(section time t_k, start, force, predicted, width) of a ``rig/force_pulse``
    message, or a one-line problem (str) when it cannot be a command."""
    start = seconds_from_stamp(msg.header.stamp)
    force, predicted = msg.wrench.force.x, msg.wrench.force.y
    width, t = msg.wrench.torque.x, msg.wrench.torque.y
    for name, value in (("header.stamp", start), ("wrench.force.x", force),
                        ("wrench.torque.x", width), ("wrench.torque.y", t)):
        if not math.isfinite(value):
            return f"{name}={value!r} is not finite"
    if not width > 0.0:
        return f"wrench.torque.x (pulse width)={width!r} is invalid: valid range is > 0 s"
    if math.isinf(predicted):
        return f"wrench.force.y (prediction)={predicted!r} is invalid: finite or NaN"
    return t, start, force, predicted, width


def read_pulse(data: bytes, malformed: Throttled):
    """The fields of a serialized ``rig/force_pulse`` (:func:`pulse_fields`), or None when
    it is malformed (counted and logged by ``malformed``: never fatal)."""
    msg = deserialize(data, WrenchStamped, malformed)
    if msg is None:
        return None
    fields = pulse_fields(msg)
    if isinstance(fields, str):
        malformed(f"rig/force_pulse: {fields}")
        return None
    return fields


def applied_message(start: float, t: float, width: float, force: float, predicted: float,
                    code: int) -> WrenchStamped:
    """``rig/applied``: as ``rig/force_pulse``, with ``wrench.force.z`` = the code."""
    msg = WrenchStamped()
    msg.header.stamp = stamp_from_seconds(max(start, 0.0))
    msg.wrench.force.x, msg.wrench.force.y = float(force), float(predicted)
    msg.wrench.force.z = float(code)
    msg.wrench.torque.x, msg.wrench.torque.y = float(width), float(t)
    return msg


class RigDriver(Node):
    """The contract's node around the hooks (module docstring); subclass and override."""

    def __init__(self, name: str = "rig_driver", **kwargs):
        super().__init__(name, **kwargs)
        self.poll_period = self.declare_parameter(
            "poll_period", 0.002, float_descriptor(
                "wall seconds between two reads of the sensor block (and deadline checks)",
                1e-4, 1.0, read_only=True)).value
        self.clock_rate = self.declare_parameter(
            "clock_rate", 20.0, float_descriptor(
                "rig/clock pairs per second (the contract: at least 10)", 10.0, 1000.0,
                read_only=True)).value
        latency = self.declare_parameter(
            "actuator_latency", 0.0, float_descriptor(
                "seconds the actuator needs before a timed pulse starts: a command must "
                "arrive that long before its apply time", 0.0, 1.0, read_only=True)).value
        self.on_miss = self.declare_parameter(
            "on_miss", "predict", string_descriptor(
                "what acts when a command misses its deadline", read_only=True,
                choices=ON_MISS)).value
        if self.on_miss not in ON_MISS:
            raise StartupError(f"on_miss={self.on_miss!r} is invalid: valid values are "
                               + ", ".join(ON_MISS))
        self.schedule = RigSchedule(lead=latency)
        self.malformed = Throttled(self.get_logger(), "malformed force pulse")
        self.late = Throttled(self.get_logger(), "late force pulse (dropped)")
        self.sensor_pub = self.create_publisher(JointState, "rig/sensor", PUBLISHER_QOS)
        self.phase_pub = self.create_publisher(Vector3Stamped, "rig/phase", PUBLISHER_QOS)
        self.clock_pub = self.create_publisher(TimeReference, "rig/clock", PUBLISHER_QOS)
        self.applied_pub = self.create_publisher(WrenchStamped, "rig/applied", PUBLISHER_QOS)
        self.create_subscription(WrenchStamped, "rig/force_pulse", self.on_pulse, DATA_QOS,
                                 raw=True)
        self.published = dict.fromkeys(("sensor", "phase", "clock", "applied"), 0)
        self.next_phase = -math.inf      # rig time of the next phase reference
        self.next_clock = -math.inf      # rig time of the next clock pair
        self.safe_state = False          # a subclass's watchdog: nothing acts any more
        self.joint_names = ["mass"]      # rig/sensor's names (rig_boundary.joint_names)
        self.timer = None

    def start(self) -> None:
        """Start the poll (a subclass calls it once its hardware is ready, after
        declaring its own parameters: their ranges are held exactly from here)."""
        check_ranges(self)
        self.timer = self.create_timer(self.poll_period, self.poll)

    # ------------------------------------------------------------------ hooks
    def rig_time(self) -> float:
        """The rig clock now (s)."""
        raise NotImplementedError

    def read_sensor(self):
        """The samples since the last call: iterable of (t_rig, x_m, v_mps or None)."""
        raise NotImplementedError

    def phase_reference(self):
        """(t_ref, f_hz, phi_rad): the forcing's phase at rig time t_ref, or None."""
        raise NotImplementedError

    def write_pulse(self, start: float, width: float, force: float) -> None:
        """Apply ``force`` N from rig time ``start`` for ``width`` s (a timed output)."""
        raise NotImplementedError

    # ------------------------------------------------------------------- work
    def poll(self) -> None:
        """Publish the sensor block, the phase and clock when due; act what is due."""
        for t, x, v in self.read_sensor():
            self.publish_sample(t, x, v)
        now = self.rig_time()
        if now >= self.next_phase:
            ref = self.phase_reference()
            if ref is not None:
                self.publish_phase(*ref)
                self.next_phase = now + 1.0 / ref[1]
        if now >= self.next_clock:
            self.publish_clock()
            self.next_clock = now + 1.0 / self.clock_rate
        self.act(now)

    def publish_sample(self, t: float, x, v) -> None:
        """One measurement: x (m) and v (m/s or None) a number for one measured mass, a
        sequence over ``joint_names`` for several."""
        msg = JointState()
        msg.header.stamp = stamp_from_seconds(t)
        msg.name = list(self.joint_names)
        msg.position = [float(a) for a in x] if hasattr(x, "__len__") else [float(x)]
        msg.velocity = [] if v is None else \
            [float(a) for a in v] if hasattr(v, "__len__") else [float(v)]
        self.sensor_pub.publish(msg)
        self.published["sensor"] += 1

    def publish_phase(self, t_ref: float, f: float, phi: float) -> None:
        msg = Vector3Stamped()
        msg.header.stamp = stamp_from_seconds(t_ref)
        msg.vector.x, msg.vector.y = float(f), float(phi) % (2.0 * math.pi)
        self.phase_pub.publish(msg)
        self.schedule.period = 1.0 / f      # a section per forcing period
        self.published["phase"] += 1

    def publish_clock(self) -> None:
        """A pair read together: ROS time (header.stamp) and the rig clock (time_ref)."""
        msg = TimeReference()
        rig = self.rig_time()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.time_ref = stamp_from_seconds(rig)
        msg.source = self.get_name()
        self.clock_pub.publish(msg)
        self.published["clock"] += 1

    def act(self, now: float) -> None:
        """Every section due by rig time ``now`` (within the actuator's latency):
        written and published on rig/applied."""
        for act in self.schedule.due(now, self.on_miss):
            sec = act.section
            code = act.code
            if self.safe_state:
                code = SAFE_STATE
            elif act.value != 0.0:
                self.write_pulse(sec.start, sec.width, act.value)
            self.applied_pub.publish(applied_message(
                sec.start, sec.t, sec.width, act.value if code != SAFE_STATE else 0.0,
                sec.predicted, code))
            self.published["applied"] += 1

    def on_pulse(self, data: bytes) -> None:
        """A command: checked (malformed: counted), then into the schedule."""
        fields = read_pulse(data, self.malformed)
        if fields is None:
            return
        now = self.rig_time()
        self.act(now)                   # a deadline already due is handled first
        t, start, force, predicted, width = fields
        answer = self.schedule.pulse(t, start, force, predicted, width, now)
        if answer.outcome == "late":
            self.late(f"section t={t:.6f} s: apply time {start:.6f} s, received at "
                      f"{now:.6f} s (actuator latency {self.schedule.lead} s)")

    def counts(self) -> dict:
        """What acted and what came: the schedule's counts and the malformed commands."""
        return {name: self.schedule.counts[name] for name in COUNTS} | {
            "malformed": self.malformed.count}

    def summary(self) -> str:
        return "summary: " + " ".join(f"{k}={v}" for k, v in self.counts().items()) + \
            " " + " ".join(f"{k}_msgs={v}" for k, v in self.published.items())

    def on_exit(self) -> None:
        self.get_logger().info(self.summary())

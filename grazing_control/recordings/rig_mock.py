"""rig_mock: mock hardware, a driver that replays a recorded rig and echoes the commands.

ros2_control's mock_components idea for the driver contract (docs/driver_contract.md):
the node replays the ``rig/sensor``, ``rig/phase`` and ``rig/clock`` streams of a bag
(MCAP, read by :func:`grazing_control.recordings.reader.read_raw`), and answers
``rig/force_pulse`` as any driver does (:class:`grazing_control.ros.rig_driver.RigDriver`:
the actuation engine in the rig clock, one ``rig/applied`` per section) without hardware
behind it: nothing is written, the commands are echoed on ``rig/applied``. It records
nothing itself (a recorder does). Run beside a controller, it gives that controller the
recorded scene again, so that its commands can be compared with the recorded ones.

The replay is deterministic: the messages go out in the recorded order (log time, then
file order), every one of them (reliable, keep last 100000 on each publisher), the
sensor and phase messages byte for byte as recorded (their stamps are the recorded
rig-clock stamps), the clock pairs with their recorded rig time (``time_ref``) and the
ROS time at which the replay made them due (``header.stamp``: the pair states the
relation of the replayed rig clock to this run's ROS time, whenever the poll came to
it; the recorded ROS stamps belong to another run). Pacing: message i goes out when the replay position, the
recording's ROS time log_0 + (wall - wall_0) x ``time_scale``, reaches its log time (the
recorder's receive time: the recorded blocks and latencies are kept); the mock's rig
clock is the recorded relation (a least-squares line through the bag's clock pairs)
at that position.

Parameters (read-only; besides RigDriver's poll_period, clock_rate, actuator_latency,
on_miss): ``bag`` (the bag directory or .mcap file, required), ``time_scale`` (1.0;
recorded seconds per wall second, 1e-3..1e6), ``bag_namespace`` (the recorded topics'
namespace, "" for /rig/...), ``linger`` (s, 1.0: how long the node stays after the last
message, for the last commands; then it exits 0), ``wait_for_subscribers`` (1: the
replay starts 0.2 s after each replayed topic has that many subscribers, so that nothing
is lost to a late match; 0: at once). A bag without rig/clock pairs or rig
messages is refused in one line (exit status 2).

``compare`` (the bag's recorded commands, e.g. ``rig/force_pulse``; "" none): replay and
compare (docs/driver_contract.md, "Mock hardware"). The recorded ``rig/applied`` (what the
hardware did, which the controller's estimator integrates) is replayed on ``rig/applied``
at its recorded place among the samples, this run's echo goes to ``rig/echo``, and each
``rig/force_pulse`` received is compared with the recorded one of its section
(:class:`CommandComparison`: every field, floats as float64 bytes); the summary counts
identical / differing / missing / extra commands and the node exits 1 naming the first
difference (:mod:`grazing_control.recordings.rig_replay` runs it beside a controller).
"""

from __future__ import annotations

import struct
import time

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.duration import Duration
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import TimeReference

from grazing_control.dynamics.estimation.clock_relation import fit_clock
from grazing_control.ros.common import (PUBLISHER_QOS, StartupError, float_descriptor,
                                        int_descriptor, run_node, spin, string_descriptor)
from grazing_control.ros.rig_driver import RigDriver

from .reader import (BagReadError, decode_stamped, decode_time_reference,
                     decode_vector3_stamped, read_raw)

__all__ = ["RigMock", "CommandComparison", "command_fields", "load_commands", "load_replay",
           "main"]

_NS = 1_000_000_000
#: Wall seconds between the subscribers' match and the first message (both ends of each
#: match up, as sim_node's start: docs/nodes.md, "Start, end, summary").
MATCH_SETTLE = 0.2
#: The replayed topics (relative to ``bag_namespace``).
REPLAYED = {"sensor": "rig/sensor", "phase": "rig/phase", "clock": "rig/clock"}


def _message_bytes(pool, rec: int) -> bytes:
    """The CDR bytes of the message record at pool offset ``rec`` (MCAP Message:
    opcode, length, channel, sequence, log time, publish time, data)."""
    (length,) = struct.unpack_from("<Q", pool, rec + 1)
    return pool[rec + 31:rec + 9 + length].tobytes()


def _topic(namespace: str, name: str) -> str:
    """The recorded topic of the contract's relative ``name`` under ``namespace``."""
    prefix = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    return prefix + name.strip("/")


def load_replay(bag, namespace: str = "", applied: bool = False) -> tuple:
    """(messages, relation) of a bag's rig streams: messages as (log_ns, kind, bytes,
    value) in the recorded order (kind 'sensor' | 'phase' | 'clock', with ``applied``
    also 'applied': the recorded rig/applied, what the hardware did; value: the phase's
    frequency in Hz, the clock pair's rig time in ns); relation the
    :class:`~grazing_control.dynamics.estimation.clock_relation.ClockFit` of the recorded pairs.
    StartupError (one line) when the bag cannot be replayed."""
    kinds = dict(REPLAYED, **({"applied": "rig/applied"} if applied else {}))
    topics = {kind: _topic(namespace, name) for kind, name in kinds.items()}
    try:
        raw = read_raw(bag, topics.values())
    except (BagReadError, OSError) as exc:
        raise StartupError(f"bag={bag!r}: {exc}") from None
    rows = []
    for kind, topic in topics.items():
        if kind == "clock":
            cols = decode_time_reference(raw, topic)
            values = cols["time_ref"]
        elif kind == "phase":
            cols = decode_vector3_stamped(raw, topic)
            values = cols["vx"]
        else:                                   # sensor, applied: replayed as they are
            body, _, _ = decode_stamped(raw, topic)
            cols = {"ok": body.ok, "log_time": body.log_time}
            values = np.zeros(len(body.ok))
        offsets = raw.offsets(topic)
        for i in np.flatnonzero(cols["ok"]):
            value = int(values[i]) if kind == "clock" else float(values[i])
            rows.append((int(cols["log_time"][i]), int(offsets[i]), kind, value))
    if not any(r[2] == "sensor" for r in rows):
        raise StartupError(f"bag={bag!r}: no {topics['sensor']} messages to replay")
    if applied and not any(r[2] == "applied" for r in rows):
        raise StartupError(f"bag={bag!r}: no {topics['applied']} messages (compare needs "
                           "what acted: the controller's estimator integrates it)")
    pairs = [r for r in rows if r[2] == "clock"]
    if len(pairs) < 2:
        raise StartupError(f"bag={bag!r}: {len(pairs)} {topics['clock']} pairs (need 2 or "
                           "more: the mock's rig clock is the recorded relation)")
    clock = decode_time_reference(raw, topics["clock"])
    ok = clock["ok"]
    relation = fit_clock(clock["time_ref"][ok] / _NS, clock["stamp"][ok] / _NS)
    rows.sort(key=lambda r: (r[0], r[1]))         # log time, then file order
    messages = [(log, kind, _message_bytes(raw.pool, rec), value)
                for log, rec, kind, value in rows]
    return messages, relation


def command_fields(msg: WrenchStamped) -> tuple:
    """What a ``rig/force_pulse`` says, in the order :data:`COMMAND_FIELDS` names it."""
    w = msg.wrench
    return (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id,
            w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z)


#: The fields of :func:`command_fields` (the comparison names the first that differs).
COMMAND_FIELDS = ("header.stamp.sec", "header.stamp.nanosec", "header.frame_id",
                  "force.x (F, N)", "force.y (predicted F, N)", "force.z", "torque.x (width, s)",
                  "torque.y (section time t_k, s)", "torque.z")


def _bits(value) -> bytes:
    """The bytes a field is compared by: a float as its float64 (NaN by its bits)."""
    return struct.pack("<d", value) if isinstance(value, float) else repr(value).encode()


def section_key(fields: tuple) -> bytes:
    """A command's identity: its section time t_k (torque.y) as float64 bytes."""
    return _bits(fields[7])


def load_commands(bag, topic: str) -> dict:
    """The recorded commands of ``topic``: {section_key: fields} (the first per section),
    in the recorded order. StartupError (one line) when there are none."""
    try:
        raw = read_raw(bag, [topic])
    except (BagReadError, OSError) as exc:
        raise StartupError(f"bag={bag!r}: {exc}") from None
    body, _, _ = decode_stamped(raw, topic)
    order = sorted((int(body.log_time[i]), int(rec)) for i, rec in
                   enumerate(raw.offsets(topic)) if body.ok[i])
    out = {}
    for _, rec in order:
        fields = command_fields(deserialize_message(_message_bytes(raw.pool, rec),
                                                    WrenchStamped))
        out.setdefault(section_key(fields), fields)
    if not out:
        raise StartupError(f"compare={topic!r} is invalid: bag={bag!r} has no {topic} "
                           "messages to compare with")
    return out


class CommandComparison:
    """This run's commands against the recorded ones, section by section, bit for bit
    (every field of :func:`command_fields`, floats as float64 bytes): ``identical``,
    ``differing``, ``missing`` (recorded, never sent here), ``extra`` (sent here, not
    recorded); ``first`` names the first difference (None: none yet)."""

    def __init__(self, recorded: dict):
        self.recorded = recorded
        self.seen = {}
        self.identical = self.differing = self.extra = 0
        self.first = None

    def command(self, fields: tuple) -> None:
        key = section_key(fields)
        if key in self.seen:
            return                        # a second command for a section: the first counts
        self.seen[key] = fields
        want = self.recorded.get(key)
        if want is None:
            self.extra += 1
            self.first = self.first or f"section t_k={fields[7]!r} s: not recorded"
            return
        diff = [i for i, (a, b) in enumerate(zip(want, fields)) if _bits(a) != _bits(b)]
        if not diff:
            self.identical += 1
            return
        self.differing += 1
        i = diff[0]
        self.first = self.first or (f"section t_k={fields[7]!r} s: {COMMAND_FIELDS[i]} "
                                    f"recorded {want[i]!r} replayed {fields[i]!r}")

    @property
    def missing(self) -> int:
        return sum(1 for key in self.recorded if key not in self.seen)

    def verdict(self) -> str | None:
        """None when every recorded command came again, identical; else the first
        difference (one line)."""
        if self.first is not None:
            return self.first
        if self.missing:
            key = next(k for k in self.recorded if k not in self.seen)
            return f"section t_k={self.recorded[key][7]!r} s: recorded, not sent in the replay"
        return None

    def counts(self) -> dict:
        return {"identical": self.identical, "differing": self.differing,
                "missing": self.missing, "extra": self.extra}


class RigMock(RigDriver):
    """The replaying driver (module docstring)."""

    def __init__(self, **kwargs):
        super().__init__("rig_mock", **kwargs)
        bag = self.declare_parameter("bag", "", string_descriptor(
            "the bag (directory or .mcap) whose rig streams are replayed",
            read_only=True)).value
        self.time_scale = self.declare_parameter("time_scale", 1.0, float_descriptor(
            "recorded seconds per wall second", 1e-3, 1e6, read_only=True)).value
        namespace = self.declare_parameter("bag_namespace", "", string_descriptor(
            "namespace of the recorded rig topics ('' for /rig/...)", read_only=True)).value
        self.linger = self.declare_parameter("linger", 1.0, float_descriptor(
            "wall seconds the node stays after the last message", 0.0, 3600.0,
            read_only=True)).value
        self.subscribers = self.declare_parameter("wait_for_subscribers", 1, int_descriptor(
            "the replay starts once each replayed topic has this many subscribers "
            "(0: at once)", 0, 1000, read_only=True)).value
        compare = self.declare_parameter("compare", "", string_descriptor(
            "the bag's recorded commands (e.g. rig/force_pulse, relative to bag_namespace): "
            "replay the recorded rig/applied (the echo goes to rig/echo) and compare each "
            "command with the recorded one of its section bit for bit; exit 1 on a "
            "difference ('': no comparison, the commands are echoed on rig/applied)",
            read_only=True)).value
        if not bag:
            raise StartupError("bag='' is invalid: give the bag to replay (-p bag:=PATH)")
        self.messages, self.recorded = load_replay(bag, namespace, applied=bool(compare))
        self.comparison = None
        if compare:
            self.comparison = CommandComparison(load_commands(bag, _topic(namespace,
                                                                          compare)))
            # what acted is the recorded rig/applied (the controller's estimator integrates
            # it); this run's echo of the commands goes to a topic of its own
            self.recorded_applied = self.applied_pub
            self.published["recorded_applied"] = 0
            self.applied_pub = self.create_publisher(WrenchStamped, "rig/echo",
                                                     PUBLISHER_QOS)
        self.next = 0
        self.log0 = self.messages[0][0] / _NS
        self.wall0 = None
        self.matched = None               # wall time the subscribers were all there
        self.ended = None                 # wall time the last message went out
        self.finished = False
        self.exit_code = 0
        self.start()

    def position(self) -> float:
        """The replay position: the recording's ROS time now (s); its first message's
        log time until the replay starts."""
        if self.wall0 is None:
            return self.log0
        return self.log0 + (time.monotonic() - self.wall0) * self.time_scale

    def rig_time(self) -> float:
        return self.recorded.rig_time(self.position())

    def due_stamp(self, log_ns: int):
        """The ROS time at which the replay position reached ``log_ns`` (when the
        message was due), not when the poll came to it: a clock pair stamped when a
        loaded machine's poll ran late paired the recorded rig time with a later ROS
        time (a fit of the pairs read drift -0.395 where the replay at time_scale 2
        gives -0.5)."""
        late = time.monotonic() - (self.wall0 + (log_ns / _NS - self.log0) / self.time_scale)
        return (self.get_clock().now()
                - Duration(nanoseconds=int(round(max(late, 0.0) * _NS)))).to_msg()

    def poll(self) -> None:
        """Publish every recorded message due by now, in order; act what is due."""
        if self.wall0 is None:
            pubs = (self.sensor_pub, self.phase_pub, self.clock_pub)
            if self.comparison is not None:
                pubs += (self.recorded_applied,)
            if any(p.get_subscription_count() < self.subscribers for p in pubs):
                return                    # nobody would get the first messages yet
            if self.matched is None:
                self.matched = time.monotonic()
            if time.monotonic() - self.matched < MATCH_SETTLE:
                return                    # both ends of each match up
            self.wall0 = time.monotonic()    # the replay starts
        pos_ns = self.position() * _NS
        msgs = self.messages
        while self.next < len(msgs) and msgs[self.next][0] <= pos_ns:
            log_ns, kind, data, value = msgs[self.next]
            self.next += 1
            if kind == "sensor":
                self.sensor_pub.publish(data)
                self.published["sensor"] += 1
            elif kind == "applied":
                self.recorded_applied.publish(data)
                self.published["recorded_applied"] += 1
            elif kind == "phase":
                self.phase_pub.publish(data)
                if value > 0.0:
                    self.schedule.period = 1.0 / value
                self.published["phase"] += 1
            else:
                msg = TimeReference()
                msg.header.stamp = self.due_stamp(log_ns)
                msg.time_ref.sec, msg.time_ref.nanosec = divmod(value, _NS)
                msg.source = self.get_name()
                self.clock_pub.publish(msg)
                self.published["clock"] += 1
        self.act(self.rig_time())
        if self.next == len(msgs):
            now = time.monotonic()
            self.ended = self.ended or now
            if now - self.ended >= self.linger:
                self.finished = True

    # the recorded streams replace the hooks of a live rig
    def read_sensor(self):
        return ()

    def phase_reference(self):
        return None

    def write_pulse(self, start: float, width: float, force: float) -> None:
        """Mock hardware: nothing to drive; rig/applied (with compare rig/echo) is the
        echo."""

    def on_pulse(self, data: bytes) -> None:
        """A command: compared with the recorded one of its section (compare), then to
        the engine as any driver's."""
        if self.comparison is not None:
            try:
                msg = deserialize_message(data, WrenchStamped)
            except Exception:             # malformed: the driver's path counts it
                msg = None
            if msg is not None:
                self.comparison.command(command_fields(msg))
        super().on_pulse(data)

    def summary(self) -> str:
        text = super().summary()
        if self.comparison is not None:
            text += " " + " ".join(f"{k}={v}" for k, v in self.comparison.counts().items())
        return text

    def on_exit(self) -> None:
        """The summary; with compare the verdict: exit 1 naming the first difference."""
        super().on_exit()
        if self.comparison is None:
            return
        verdict = self.comparison.verdict()
        if verdict is None:
            self.get_logger().info(f"compare: all {self.comparison.identical} commands "
                                   "identical bit for bit")
        else:
            self.get_logger().error(f"compare: {verdict}")
            self.exit_code = 1

    def spin_until(self, executor) -> None:
        """Spin until the replay and its linger are over, then let every reader take
        what was published."""
        spin(executor, done=lambda: self.finished)
        pubs = (self.sensor_pub, self.phase_pub, self.clock_pub, self.applied_pub)
        if self.comparison is not None:
            pubs += (self.recorded_applied,)
        for pub in pubs:
            pub.wait_for_all_acked(Duration(seconds=2.0))


def main(args=None) -> int:
    return run_node(RigMock, args, "rig_mock")


if __name__ == "__main__":
    raise SystemExit(main())

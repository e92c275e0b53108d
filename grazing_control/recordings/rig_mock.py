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
ROS time at which this node publishes them (``header.stamp``: the pair states the
relation of the replayed rig clock to this run's ROS time; the recorded ROS stamps
belong to another run). Pacing: message i goes out when the replay position, the
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
"""

from __future__ import annotations

import struct
import time

import numpy as np
from rclpy.duration import Duration
from sensor_msgs.msg import TimeReference

from grazing_control.dynamics.clock_relation import fit_clock
from grazing_control.ros.common import (StartupError, float_descriptor, int_descriptor,
                                        run_node, spin, string_descriptor)
from grazing_control.ros.rig_driver import RigDriver

from .reader import (BagReadError, decode_stamped, decode_time_reference,
                     decode_vector3_stamped, read_raw)

__all__ = ["RigMock", "load_replay", "main"]

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


def load_replay(bag, namespace: str = "") -> tuple:
    """(messages, relation) of a bag's rig streams: messages as (log_ns, kind, bytes,
    value) in the recorded order (kind 'sensor' | 'phase' | 'clock'; value: the phase's
    frequency in Hz, the clock pair's rig time in ns); relation the
    :class:`~grazing_control.dynamics.clock_relation.ClockFit` of the recorded pairs.
    StartupError (one line) when the bag cannot be replayed."""
    prefix = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    topics = {kind: prefix + name for kind, name in REPLAYED.items()}
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
        else:
            body, _, _ = decode_stamped(raw, topic)
            cols = {"ok": body.ok, "log_time": body.log_time}
            values = np.zeros(len(body.ok))
        offsets = raw.offsets(topic)
        for i in np.flatnonzero(cols["ok"]):
            value = int(values[i]) if kind == "clock" else float(values[i])
            rows.append((int(cols["log_time"][i]), int(offsets[i]), kind, value))
    if not any(r[2] == "sensor" for r in rows):
        raise StartupError(f"bag={bag!r}: no {topics['sensor']} messages to replay")
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
        if not bag:
            raise StartupError("bag='' is invalid: give the bag to replay (-p bag:=PATH)")
        self.messages, self.recorded = load_replay(bag, namespace)
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

    def poll(self) -> None:
        """Publish every recorded message due by now, in order; act what is due."""
        if self.wall0 is None:
            pubs = (self.sensor_pub, self.phase_pub, self.clock_pub)
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
            _, kind, data, value = msgs[self.next]
            self.next += 1
            if kind == "sensor":
                self.sensor_pub.publish(data)
                self.published["sensor"] += 1
            elif kind == "phase":
                self.phase_pub.publish(data)
                if value > 0.0:
                    self.schedule.period = 1.0 / value
                self.published["phase"] += 1
            else:
                msg = TimeReference()
                msg.header.stamp = self.get_clock().now().to_msg()
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
        """Mock hardware: nothing to drive; rig/applied is the echo."""

    def spin_until(self, executor) -> None:
        """Spin until the replay and its linger are over, then let every reader take
        what was published."""
        spin(executor, done=lambda: self.finished)
        for pub in (self.sensor_pub, self.phase_pub, self.clock_pub, self.applied_pub):
            pub.wait_for_all_acked(Duration(seconds=2.0))


def main(args=None) -> int:
    return run_node(RigMock, args, "rig_mock")


if __name__ == "__main__":
    raise SystemExit(main())

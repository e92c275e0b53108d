"""live_node: a live view of a running scene for Foxglove and Lichtblick (issue 19 section 1).

The node subscribes to the scene's topics as serialized CDR bytes (``raw=True``: nothing
is deserialized) and forwards each message, unchanged, to a WebSocket server of the
Foxglove SDK (PyPI ``foxglove-sdk``), which Foxglove and Lichtblick open as a live data
source ("Open connection" → "Foxglove WebSocket", ``ws://HOST:PORT``). Each topic is one
channel: topic = the fully qualified ROS name, ``encoding`` ``cdr``, ``schemaEncoding``
``ros2msg``, ``schemaName`` ``pkg/msg/Type`` and ``schema`` the ``.msg`` definition with
its nested types, exactly as rosbag2 stores it in an MCAP bag
(:func:`grazing_control.ros.recording.message_definition`). A message's timestamp is its
reception time (ns since the Unix epoch), and the shipped layout (config/live_layout.json,
docs/live.md) plots against it: it is the one time every topic has (``oscillator/latency``
is a std_msgs/Float64 without a header), and in realtime it is the simulation time divided
by ``time_scale``. The header stamp is the simulation time (docs/nodes.md, "Units and
time"): a Raw Messages panel shows it.

What it forwards by default (names relative to the node's namespace; docs/nodes.md):

``oscillator/pi2``, ``oscillator/pi1`` (sensor_msgs/msg/JointState)
    the Pi2 samples (before the correction) and the Pi1 crossings.
``oscillator/state`` (sensor_msgs/msg/JointState)
    the sensor stream: position [x~], velocity [v~], effort [cos tau, sin tau].
``oscillator/impact`` (geometry_msgs/msg/Vector3Stamped)
    vector = (v-, v+, phase tau) at each impact.
``controller/velocity_correction`` (geometry_msgs/msg/TwistStamped)
    twist.linear.x = Delta v, stamped with the sample it answers.
``oscillator/deadline_miss`` (geometry_msgs/msg/Vector3Stamped), ``oscillator/latency``
(std_msgs/msg/Float64)
    realtime: the samples whose correction missed its actuation time; wall seconds from
    a sample to its correction.
``controller/estimate`` (sensor_msgs/msg/JointState)
    stream mode: the controller's Pi2 estimate [x^], [v^], effort [var x, cov, var v].

Never slowing the loop
----------------------
The subscriptions are best effort, volatile, keep last ``depth``: a reliable publisher
does not wait for this reader's acknowledgements (a best-effort reader matches a
reliable writer without joining its flow control), and when the node lags, the oldest
queued messages are overwritten. Towards the browser the SDK keeps at most ``backlog``
messages per client and drops the oldest. Every thread of the node runs at SCHED_IDLE
(``priority``): the scene's nodes get the CPU first. The simulator does not wait for
this node (it is not a recorder: ``recorder/ready`` is not its business), so a scene
started before the view loses only what the view would have shown. A message is forwarded as
bytes without being decoded, so a malformed message cannot make the node fail: the
viewer reports what it cannot decode.

Parameters (all read-only)
--------------------------
``port`` (integer, 8765; range 0..65535)
    TCP port of the WebSocket server; 0 lets the system choose one (logged).
    A port in use is refused in one line (exit status 2).
``host`` (string, ``127.0.0.1``)
    Address to listen on; ``0.0.0.0`` serves other machines too.
``topics`` (string array)
    Entries ``"name"`` for the topics above (and the recorder's, e.g. ``/clock``) or
    ``"name pkg/msg/Type"`` (:func:`grazing_control.ros.recording.topics.parse_topics`).
``depth`` (integer, 10; range 1..10000)
    Keep-last depth of each subscription.
``backlog`` (integer, 1024; range 1..1000000)
    Messages queued per WebSocket client before the oldest is dropped.
``priority`` (string, ``idle``)
    CPU priority of the node's threads: ``idle`` (SCHED_IDLE), ``low`` (nice 19),
    ``normal`` (:func:`lower_priority`).

Run: ``ros2 run grazing_control live_node --ros-args -p port:=8765``, or
``grazing run --live 8765`` (the launcher starts it beside the scene).
"""

from __future__ import annotations

import os
import sys
import time

from rcl_interfaces.msg import ParameterType
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .common import StartupError, int_descriptor, run_node, string_descriptor
from .recording.topics import message_class, parse_topics
from .recording import message_definition
from grazing_control.oscillator.params import ParameterError

__all__ = ["LIVE_TOPICS", "LiveNode", "live_qos", "channel_schema", "main"]

#: The topics forwarded by default (relative names) and their types.
LIVE_TOPICS = {
    "oscillator/pi2": "sensor_msgs/msg/JointState",
    "oscillator/pi1": "sensor_msgs/msg/JointState",
    "oscillator/state": "sensor_msgs/msg/JointState",
    "oscillator/impact": "geometry_msgs/msg/Vector3Stamped",
    "controller/velocity_correction": "geometry_msgs/msg/TwistStamped",
    "oscillator/deadline_miss": "geometry_msgs/msg/Vector3Stamped",
    "oscillator/latency": "std_msgs/msg/Float64",
    "controller/estimate": "sensor_msgs/msg/JointState",
}

DEFAULT_PORT = 8765
MAX_PORT = 65535
DEFAULT_DEPTH = 10
MAX_DEPTH = 10_000
DEFAULT_BACKLOG = 1024
MAX_BACKLOG = 1_000_000
#: CPU priorities of the view (parameter ``priority``), lowest first.
PRIORITIES = ("idle", "low", "normal")

# Most messages of one topic forwarded in one callback (keeps topics interleaved).
_BATCH = 64


def live_qos(depth: int = DEFAULT_DEPTH) -> QoSProfile:
    """Best effort, volatile, keep last ``depth``: a reader the scene never waits for.

    DDS request/offer rule: a best-effort reader matches a reliable writer, and the
    writer does not hold its history for it (docs/live.md, "Never slowing the loop").
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


def channel_schema(msg_type: str):
    """The Foxglove channel schema of a ROS 2 message type: ``(name, encoding, data)``.

    Name ``pkg/msg/Type``, encoding ``ros2msg`` and the rosbag2 message definition
    (:func:`~grazing_control.ros.recording.message_definition`): what Foxglove's
    ``ros2msg`` parser reads, the same as the schema of the recorder's bags.
    """
    package, *_, name = msg_type.split("/")
    return f"{package}/msg/{name}", "ros2msg", message_definition(msg_type).encode()


def lower_priority(priority: str) -> None:
    """Lower the CPU priority of every thread of this process (and so of those they
    start: the middleware's and the WebSocket server's).

    ``idle``: Linux SCHED_IDLE, below every nice level: the view runs on what the
    scene's nodes leave (nice 19 where SCHED_IDLE is refused); ``low``: nice 19;
    ``normal``: unchanged.
    """
    if priority == "normal":
        return
    try:
        threads = [int(tid) for tid in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        try:
            if priority == "idle" and hasattr(os, "SCHED_IDLE"):
                os.sched_setscheduler(tid, os.SCHED_IDLE, os.sched_param(0))
            else:
                os.setpriority(os.PRIO_PROCESS, tid, 19)
        except OSError:
            try:
                os.setpriority(os.PRIO_PROCESS, tid, 19)
            except OSError:
                pass        # a thread that ended meanwhile


class LiveNode(Node):
    """Forwards the scene's serialized messages to a Foxglove WebSocket server.

    Raises
    ------
    ParameterError, StartupError
        A bad parameter, or a port that cannot be bound (named in one line); nothing
        is left running then.
    """

    def __init__(self, **kwargs):
        super().__init__("live_node", **kwargs)
        self._declare_parameters()
        port, host, topics, depth, backlog, priority = self._read_parameters()
        lower_priority(priority)     # the middleware's threads and the server's (below)
        import foxglove

        self._context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name="grazing_control", host=host, port=port, context=self._context,
                message_backlog_size=backlog)
        except (RuntimeError, OSError, OverflowError) as exc:
            text = " ".join(str(exc).split())
            if "in use" in text:
                raise StartupError(f"port={port} is in use on {host}: stop the other server "
                                   "or choose another port (-p port:=N, 0: any free port)"
                                   ) from None
            raise StartupError(f"port={port} on host={host!r} cannot be served: {text}"
                               ) from None
        self.forwarded = {}
        self._channels = {}
        self._subs = {}
        qos = live_qos(depth)
        for name, kind in topics.items():
            topic = self.resolve_topic_name(name)
            schema_name, encoding, data = channel_schema(kind)
            self._channels[topic] = foxglove.Channel(
                topic, schema=foxglove.Schema(name=schema_name, encoding=encoding, data=data),
                message_encoding="cdr", context=self._context)
            self.forwarded[topic] = 0
            self._subs[topic] = self.create_subscription(
                message_class(kind), name,
                lambda data, info, topic=topic: self._on_message(topic, data, info),
                qos, raw=True)
        self.get_logger().info(
            f"live view on ws://{host}:{self.server.port} ({len(topics)} topics; open it in "
            "Foxglove or Lichtblick: Open connection > Foxglove WebSocket)")

    def _declare_parameters(self):
        self.declare_parameter("port", DEFAULT_PORT, int_descriptor(
            f"TCP port of the Foxglove WebSocket server, 0..{MAX_PORT} (0: any free port)",
            0, MAX_PORT, read_only=True))
        self.declare_parameter("host", "127.0.0.1", string_descriptor(
            "address the server listens on (0.0.0.0: every interface)", read_only=True))
        self.declare_parameter("topics", [f"{n} {t}" for n, t in LIVE_TOPICS.items()],
                               _read_only_strings("'name' or 'name pkg/msg/Type' per topic"))
        self.declare_parameter("depth", DEFAULT_DEPTH, int_descriptor(
            f"keep-last depth of each best-effort subscription, 1..{MAX_DEPTH}",
            1, MAX_DEPTH, read_only=True))
        self.declare_parameter("backlog", DEFAULT_BACKLOG, int_descriptor(
            f"messages queued per WebSocket client before the oldest is dropped, "
            f"1..{MAX_BACKLOG}", 1, MAX_BACKLOG, read_only=True))
        self.declare_parameter("priority", "idle", string_descriptor(
            "CPU priority of the view: idle (SCHED_IDLE: runs when the scene's nodes "
            "leave a core free), low (nice 19) or normal", read_only=True,
            choices=PRIORITIES))

    def _read_parameters(self):
        values = {}
        for name, lo, hi in (("port", 0, MAX_PORT), ("depth", 1, MAX_DEPTH),
                             ("backlog", 1, MAX_BACKLOG)):
            value = self.get_parameter(name).value
            if not lo <= value <= hi:       # the descriptor's range, for a direct caller
                raise ParameterError(f"{name}={value!r} is invalid: valid range is "
                                     f"{lo}..{hi}")
            values[name] = value
        priority = self.get_parameter("priority").value
        if priority not in PRIORITIES:
            raise ParameterError(f"priority={priority!r} is invalid: valid values are "
                                 f"{', '.join(PRIORITIES)}")
        host = self.get_parameter("host").value
        if not host:
            raise ParameterError("host='' is invalid: give an address, e.g. 127.0.0.1")
        try:
            entries = self.get_parameter("topics").value
        except ParameterUninitializedException:      # -p topics:=[] has no type
            entries = []
        topics = parse_topics(entries)
        for kind in topics.values():
            try:
                message_class(kind)
                message_definition(kind)
            except (ImportError, AttributeError, LookupError, ValueError):
                raise ParameterError(f"topics: message type {kind!r} is not installed "
                                     "(no Python module or no .msg file)") from None
        return (values["port"], host, topics, values["depth"], values["backlog"],
                priority)

    def _on_message(self, topic, data, info):
        """Forward a message, then those already queued behind it (one wake-up, a batch)."""
        self._forward(topic, data, info)
        sub = self._subs[topic]
        for _ in range(_BATCH):
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, True)
            if taken is None:
                return
            self._forward(topic, *taken)

    def _forward(self, topic, data, info):
        """The CDR bytes as received, logged at their reception time (ns)."""
        log_time = info.get("received_timestamp") or time.time_ns()
        self._channels[topic].log(bytes(data), log_time=log_time)
        self.forwarded[topic] += 1

    def on_exit(self) -> None:
        """Stop the server; log what was forwarded per topic."""
        self.server.stop()
        counts = ", ".join(f"{t} {n}" for t, n in self.forwarded.items() if n)
        self.get_logger().info(f"live view stopped: forwarded {counts or 'nothing'}")


def _read_only_strings(description):
    from rcl_interfaces.msg import ParameterDescriptor

    return ParameterDescriptor(description=description, read_only=True,
                               type=ParameterType.PARAMETER_STRING_ARRAY)


def main(args=None) -> int:
    """Run the live view until SIGINT/SIGTERM (:func:`~grazing_control.ros.common.run_node`)."""
    return run_node(LiveNode, args, "live_node")


if __name__ == "__main__":
    sys.exit(main())

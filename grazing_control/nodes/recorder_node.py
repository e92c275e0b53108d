"""recorder_node: records the oscillator's topics to a rosbag2-style MCAP bag.

What it records by default (names relative to the node's namespace):

``oscillator/state`` (sensor_msgs/msg/JointState)
    position x, velocity v, effort cos(tau); stamp = simulation time.
``oscillator/impact`` (geometry_msgs/msg/Vector3Stamped)
    vector = (v-, v+, phase tau) at each impact; stamp = impact time.
``oscillator/pi1``, ``oscillator/pi2`` (sensor_msgs/msg/JointState)
    state at each crossing of Pi1 and Pi2; stamp = crossing time.
``controller/velocity_correction`` (geometry_msgs/msg/TwistStamped)
    twist.linear.x = Delta v; stamp = stamp of the Pi2 sample it answers.
``/clock`` (rosgraph_msgs/msg/Clock)
    simulation time.

Each message is stored as the serialized CDR bytes the middleware delivered
(a ``raw=True`` subscription): nothing is deserialized on the way. The bag
(:mod:`grazing_control.recording`) is ``<output>/<output name>_0.mcap`` plus
``<output>/metadata.yaml``; ``ros2 bag info``, ``ros2 bag play`` and Foxglove
open it.

Times of a recorded message:

* ``log_time``: receive time. Without ``use_sim_time``, the middleware's
  reception timestamp (wall clock, ns since the Unix epoch); with
  ``use_sim_time:=true``, the node's ROS clock (``/clock``) when the message
  is taken, which is 0 before the first ``/clock`` message.
* ``publish_time``: the publisher's source timestamp (wall clock).

QoS: every topic is subscribed reliable, keep-all, volatile, so that nothing
published by a reliable publisher is dropped. A best-effort publisher is not
matched (a warning names the topic). The publishers' offered QoS profiles
(read at the first message of a topic) are stored in ``offered_qos_profiles``.

Parameters (all read-only):

``output`` (string, required)
    Bag directory; created, and must not exist or be empty.
``topics`` (string array)
    Entries ``"name"`` for the topics above, or ``"name pkg/msg/Type"``.
``compression`` (string, ``zstd``)
    Chunk compression: ``zstd``, ``lz4`` or ``none``.
``chunk_size`` (integer, bytes, 262144)
    Uncompressed chunk size; a crash loses at most the chunk being filled.

On SIGINT or SIGTERM the node stops spinning, takes every message already
received by the middleware, finishes the MCAP file, writes ``metadata.yaml``
and logs the message count per topic; it exits with status 0. A bad parameter
is logged in one line and the process exits with status 2.

Run: ``ros2 run grazing_control recorder_node --ros-args -p output:=bags/run1``
(or ``python -m grazing_control.nodes.recorder_node --ros-args ...``).
"""

import importlib
import signal
import sys
import threading
import time

import rclpy
import rclpy.logging
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile,
                       ReliabilityPolicy)
from rclpy.signals import SignalHandlerOptions

from grazing_control.params import ParameterError
from grazing_control.recording import (COMPRESSIONS, DEFAULT_CHUNK_SIZE,
                                       BagWriter, message_definition,
                                       qos_profile_dict)

__all__ = ["DEFAULT_TOPICS", "EXTRA_TOPICS", "PARAMETER_TOPIC", "RECORDER_QOS", "RecorderNode",
           "main", "parse_topics"]

#: Topics recorded by default (relative names) and their types.
DEFAULT_TOPICS = {
    "oscillator/state": "sensor_msgs/msg/JointState",
    "oscillator/impact": "geometry_msgs/msg/Vector3Stamped",
    "oscillator/pi1": "sensor_msgs/msg/JointState",
    "oscillator/pi2": "sensor_msgs/msg/JointState",
    "controller/velocity_correction": "geometry_msgs/msg/TwistStamped",
    "/clock": "rosgraph_msgs/msg/Clock",
}

#: The nodes' parameter record (grazing_control.bagtools.record), recorded by default too,
#: subscribed transient local so that a record published before the match is received.
PARAMETER_TOPIC = ("grazing/parameters", "std_msgs/msg/String")
#: Also recorded by default: what the analysis of a realtime run reads (docs/analysis.md).
EXTRA_TOPICS = {PARAMETER_TOPIC[0]: PARAMETER_TOPIC[1],
                "oscillator/latency": "std_msgs/msg/Float64"}

#: Subscription QoS: reliable and keep-all, so a lockstep run loses nothing.
RECORDER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    depth=0,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

#: Subscription QoS of PARAMETER_TOPIC: reliable, transient local (matches the latched
#: publishers of the nodes, and volatile ones).
PARAMETER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    depth=0,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# Most messages of one topic taken in one callback (keeps topics interleaved
# and the reaction to a signal prompt).
_BATCH = 256


def parse_topics(entries):
    """Topics to record from the ``topics`` parameter.

    Parameters
    ----------
    entries : sequence of str
        ``"name"`` (a topic of :data:`DEFAULT_TOPICS`, with or without its
        leading ``/``) or ``"name pkg/msg/Type"``.

    Returns
    -------
    dict
        Topic name (as given) to message type.

    Raises
    ------
    ParameterError
        For an empty list, a malformed entry or an unknown topic without type.
    """
    known = {name.lstrip("/"): (name, kind)
             for name, kind in (*DEFAULT_TOPICS.items(), *EXTRA_TOPICS.items())}
    topics = {}
    for entry in entries:
        words = entry.split()
        if len(words) == 2:
            name, kind = words
        elif len(words) == 1 and words[0].lstrip("/") in known:
            name, kind = known[words[0].lstrip("/")]
        else:
            raise ParameterError(
                f"topics entry {entry!r} is invalid: give 'name pkg/msg/Type' or one of "
                f"{', '.join(DEFAULT_TOPICS)}")
        topics[name] = kind
    if not topics:
        raise ParameterError("topics=[] is invalid: give at least one topic")
    return topics


def qos_to_dict(qos):
    """rosbag2 mapping (:func:`~grazing_control.recording.qos_profile_dict`) of a QoSProfile."""
    return qos_profile_dict(
        history=qos.history.name.lower(),
        depth=qos.depth,
        reliability=qos.reliability.name.lower(),
        durability=qos.durability.name.lower(),
        deadline_ns=qos.deadline.nanoseconds,
        lifespan_ns=qos.lifespan.nanoseconds,
        liveliness=qos.liveliness.name.lower(),
        liveliness_lease_duration_ns=qos.liveliness_lease_duration.nanoseconds,
        avoid_ros_namespace_conventions=qos.avoid_ros_namespace_conventions,
    )


def _message_class(msg_type):
    """Python class of ``pkg/msg/Type`` (or ``pkg/Type``)."""
    parts = msg_type.split("/")
    package, name = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{package}.msg"), name)


class RecorderNode(Node):
    """Subscribes to the topics and writes their serialized messages to a bag.

    Parameters
    ----------
    **kwargs
        Passed to :class:`rclpy.node.Node` (e.g. ``parameter_overrides``).

    Raises
    ------
    ParameterError
        If a parameter is invalid; nothing is created then.
    """

    def __init__(self, **kwargs):
        super().__init__("recorder_node", **kwargs)
        self._declare_parameters()
        output, topics, compression, chunk_size = self._read_parameters()
        self._sim_time = self.get_parameter("use_sim_time").value
        self.bag = BagWriter(
            output, compression=compression, chunk_size=chunk_size,
            custom_data={"log_time": "ros_clock" if self._sim_time else "received_timestamp"})
        self.bag.open()
        self.received = 0
        self._types = {}            # fully qualified topic -> message type
        self._subs = {}             # fully qualified topic -> Subscription
        for name, kind in topics.items():
            self._subscribe(name, kind)
        self.get_logger().info(
            f"recording {', '.join(self._types)} to {self.bag.bag_dir} "
            f"({compression}, log_time = {'ROS clock' if self._sim_time else 'receive time'})")

    def _declare_parameters(self):
        def read_only(description, kind):
            return ParameterDescriptor(description=description, type=kind, read_only=True)

        self.declare_parameter("output", "", read_only(
            "bag directory (created; must not exist or be empty)",
            ParameterType.PARAMETER_STRING))
        self.declare_parameter("topics", [f"{n} {t}" for n, t in (*DEFAULT_TOPICS.items(),
                                                                  *EXTRA_TOPICS.items())],
                               read_only("'name' or 'name pkg/msg/Type' per topic",
                                         ParameterType.PARAMETER_STRING_ARRAY))
        self.declare_parameter("compression", "zstd", read_only(
            f"chunk compression: {', '.join(COMPRESSIONS)}", ParameterType.PARAMETER_STRING))
        self.declare_parameter("chunk_size", DEFAULT_CHUNK_SIZE, read_only(
            "uncompressed chunk size, bytes", ParameterType.PARAMETER_INTEGER))

    def _read_parameters(self):
        output = self.get_parameter("output").value
        if not output:
            raise ParameterError("output='' is invalid: give the bag directory, "
                                 "e.g. --ros-args -p output:=bags/run1")
        compression = self.get_parameter("compression").value
        if compression not in COMPRESSIONS:
            raise ParameterError(f"compression={compression!r} is invalid: valid values "
                                 f"are {', '.join(COMPRESSIONS)}")
        chunk_size = self.get_parameter("chunk_size").value
        if chunk_size <= 0:
            raise ParameterError(f"chunk_size={chunk_size} is invalid: valid range is > 0")
        topics = parse_topics(self.get_parameter("topics").value)
        for kind in topics.values():
            try:
                _message_class(kind)
                message_definition(kind)
            except (ImportError, AttributeError, LookupError, ValueError):
                raise ParameterError(f"topics: message type {kind!r} is not installed "
                                     "(no Python module or no .msg file)") from None
        return output, topics, compression, chunk_size

    def _subscribe(self, name, kind):
        topic = self.resolve_topic_name(name)            # fully qualified
        events = SubscriptionEventCallbacks(
            incompatible_qos=lambda event: self._on_incompatible_qos(topic, event))
        self._types[topic] = kind
        self._subs[topic] = self.create_subscription(
            _message_class(kind), name,
            lambda data, info: self._on_message(topic, data, info),
            PARAMETER_QOS if name.lstrip("/") == PARAMETER_TOPIC[0] else RECORDER_QOS,
            raw=True, event_callbacks=events)

    def _on_message(self, topic, data, info):
        """Record a message, then the ones already queued behind it."""
        self._record(topic, data, info)
        self._take_queued(topic, _BATCH)

    def _take_queued(self, topic, limit):
        """Take and record up to `limit` messages queued on `topic`; return how many.

        The executor hands over one message per wait, and building the wait
        set costs several times more than recording; taking the queued
        messages here, with the call the executor itself makes, lets the
        recorder keep up with a lockstep simulation.
        """
        sub = self._subs[topic]
        for n in range(limit):
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, True)
            if taken is None:
                return n
            self._record(topic, *taken)
        return limit

    def _record(self, topic, data, info):
        """Write one serialized message as received."""
        if not self.bag.has_topic(topic):
            self.bag.add_topic(topic, self._types[topic], self._offered_qos(topic))
        if self._sim_time:
            log_time = self.get_clock().now().nanoseconds
        else:
            log_time = info.get("received_timestamp") or time.time_ns()
        sequence = info.get("publication_sequence_number") or 0
        self.bag.write(topic, data, log_time, info.get("source_timestamp") or log_time,
                       sequence if sequence < 2**63 else 0)
        self.received += 1

    def _offered_qos(self, topic):
        """QoS profiles offered by the topic's publishers (ours if none is known)."""
        publishers = self.get_publishers_info_by_topic(topic)
        return [qos_to_dict(p.qos_profile) for p in publishers] or [qos_to_dict(RECORDER_QOS)]

    def _on_incompatible_qos(self, topic, event):
        self.get_logger().warning(
            f"{topic}: a publisher's QoS is incompatible with the recorder's "
            f"(reliable, keep-all; policy {event.last_policy_kind}): its messages are "
            "not recorded")

    def drain(self):
        """Record every message the middleware has already received.

        Returns
        -------
        int
            Number of messages taken.
        """
        total = 0
        while True:
            taken = sum(self._take_queued(topic, _BATCH) for topic in self._subs)
            if taken == 0:
                return total
            total += taken

    def close(self):
        """Finish the bag (summary, metadata.yaml) and log the counts per topic."""
        for topic, kind in self._types.items():
            if not self.bag.has_topic(topic):          # listed, with no message
                self.bag.add_topic(topic, kind, [qos_to_dict(RECORDER_QOS)])
        info = self.bag.close()
        if info:
            counts = ", ".join(f"{name} {n}" for name, n in self.bag.message_counts.items())
            self.get_logger().info(
                f"closed {self.bag.path}: {info['message_count']} messages ({counts})")


def _stop_on_signals(stop):
    """SIGINT and SIGTERM set `stop` (the spin loop then ends and the bag closes)."""
    def handler(signum, frame):
        stop.set()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, handler)


def main(args=None):
    """Run the recorder until SIGINT/SIGTERM; return the exit status."""
    # Our own handlers: rclpy's would shut the context down before the drain.
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    status = 0
    node = None
    try:
        _stop_on_signals(stop)
        node = RecorderNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
        node.drain()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ParameterError, OSError) as exc:       # bad parameter, bag not creatable
        rclpy.logging.get_logger("recorder_node").error(str(exc))
        status = 2
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)    # a second Ctrl-C must not cut the close
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())

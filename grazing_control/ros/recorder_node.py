"""recorder_node: records the oscillator's topics to a rosbag2-style MCAP bag.

What it records by default (names relative to the node's namespace):

``oscillator/state`` (sensor_msgs/msg/JointState)
    position x, velocity v, effort cos(tau); stamp = simulation time.
``oscillator/state_block`` (std_msgs/msg/Float64MultiArray)
    the same stream in blocks (sim_node's ``stream_message:=block``): a row per sample,
    (stamp sec, nanosec, x, v, cos tau, sin tau), with n masses x0 .. x{n-1},
    v0 .. v{n-1} (grazing_control.ros.stream_block).
``oscillator/impact`` (geometry_msgs/msg/Vector3Stamped)
    vector = (v-, v+, phase tau) at each impact; stamp = impact time.
``oscillator/pi1``, ``oscillator/pi2`` (sensor_msgs/msg/JointState)
    state at each crossing of Pi1 and Pi2; stamp = crossing time.
``controller/velocity_correction`` (geometry_msgs/msg/TwistStamped)
    twist.linear.x = Delta v, twist.linear.y = the predicted next Delta v (NaN: none);
    stamp = stamp of the Pi2 sample it answers.
``controller/estimate`` (sensor_msgs/msg/JointState)
    stream mode: the controller's Pi2 estimate, position [x^], velocity [v^], effort
    [var x, cov xv, var v]; stamp = the section time.
``controller/model_watch`` (sensor_msgs/msg/JointState)
    stream mode with the model watch on (issue 29): per section the bias and Delta d
    estimates with their standard errors and the consistency verdict, named values
    (grazing_control.ros.model_watch.WATCH_FIELDS); stamp = the section time.
``controller/model_switch`` (sensor_msgs/msg/JointState)
    re-identification in the loop (issue 29): one row per decision, a switch to a
    refitted model or a refusal with its reason, named values
    (grazing_control.ros.reidentify.SWITCH_FIELDS); stamp = the section it was decided at.
``/clock`` (rosgraph_msgs/msg/Clock)
    simulation time.
``oscillator/deadline_miss`` (geometry_msgs/msg/Vector3Stamped)
    realtime, scheduled actuation: a sample whose correction missed its actuation
    time (docs/nodes.md, "Scheduled actuation").
``grazing/parameters``, ``grazing/published`` (std_msgs/msg/String)
    the nodes' parameter records, and their published records: what each published,
    sent when it stops (below).

Each message is stored as the serialized CDR bytes the middleware delivered
(a ``raw=True`` subscription): nothing is deserialized on the way. The bag
(:mod:`grazing_control.ros.recording`) is ``<output>/<output name>_0.mcap`` plus
``<output>/metadata.yaml``; ``ros2 bag info``, ``ros2 bag play`` and Foxglove
open it.

Times of a recorded message:

* ``log_time``: receive time. Without ``use_sim_time``, the middleware's
  reception timestamp (wall clock, ns since the Unix epoch); with
  ``use_sim_time:=true``, the node's ROS clock (``/clock``) when the message
  is taken, which is 0 before the first ``/clock`` message.
* ``publish_time``: the publisher's source timestamp (wall clock).

QoS: like ``ros2 bag record``, the recorder subscribes to a topic once it has a
publisher, with a QoS adapted to the publishers' offers (:func:`adapted_qos`, rosbag2's
rule): reliable only if every publisher is reliable (else best effort, which matches
them all), transient local only if every publisher is (then it also gets what they
sent before it started), keep-all history. The offered profiles are stored in the
channel metadata ``offered_qos_profiles``. A publisher that appears later with an
incompatible QoS is reported (a warning names the topic and the policy).

Readiness and completeness: once every topic has a subscription matched to at least
one publisher, the recorder publishes ``True`` on ``recorder/ready`` (std_msgs/Bool,
reliable, transient local); the simulator waits for it (``wait_for_recorder``) before
the scene starts. At close, each topic is checked with the publisher's sequence numbers
(``publication_sequence_number``, 1 for its first message): messages published before
the match or lost on the way are reported as ``missed`` in a warning, and with
``require_complete:=true`` the exit status is 1. A topic on which two publishers both
sent cannot be checked (their sequences interleave) and is named in a warning; a silent
second publisher does not stop the check.

The tail (issue 27): each node of the package publishes, when it stops, how many
messages it published per topic (``grazing/published``, grazing_control/ros/published.py).
Once stopped, the recorder keeps taking messages until every node that sent a parameter
record has sent that record and every count is recorded (``close_timeout`` seconds at
most); what is still missing counts as missed, and a node that never sent its record
leaves its tail unchecked (incomplete too, with ``require_complete``). Once a node's
counts are all recorded, its name goes out on ``recorder/complete`` (std_msgs/String,
latched, a JSON list of node names): the controller waits for it before it exits. The
closed record
in ``metadata.yaml`` carries ``recorder_status``, ``recorder_received`` and
``recorder_missed`` ("topic n, ..."), which ``grazing run`` reports.

Diagnostics: one ``diagnostic_msgs/DiagnosticArray`` per second on ``/diagnostics``,
status ``recorder_node: recording`` with the messages received, written, dropped (after
a failed write) and missed; WARN on a miss, ERROR after a failed write.

QoS: the package's own topics (those above and ``grazing/parameters``,
``oscillator/latency``) are subscribed reliably whatever else is offered: a best-effort
publisher on them (a bystander) is not matched and is named in a warning, so it cannot
make the scene's record lossy. Other topics follow ros2 bag's rule (reliable only if every
publisher is, transient local only if every publisher is); ``adapt_qos:=true`` applies
that rule to every topic (a rig whose driver publishes best effort).

Parameters (all read-only):

``output`` (string, required)
    Bag directory; created, and must not exist or be empty.
``topics`` (string array)
    Entries ``"name"`` for the topics above, or ``"name pkg/msg/Type"``.
``compression`` (string, ``zstd``)
    Chunk compression: ``zstd``, ``lz4`` or ``none``.
``chunk_size`` (integer, bytes, 262144)
    Uncompressed chunk size; a crash loses at most the chunk being filled.
``require_complete`` (bool, false)
    Exit with status 1 when messages were missed (see above).
``adapt_qos`` (bool, false)
    ros2 bag's QoS rule for the package's own topics too (see QoS above).
``close_timeout`` (double, seconds, 5.0; range [0, 60])
    Once stopped, how long to wait for the messages the nodes said they published.
``batch_window`` (double, seconds, 0.001; range [0, 0.1])
    After each wake-up the recorder waits this long and then takes every message
    queued on every topic: one wake-up records a batch instead of one message, which
    is most of the recorder's CPU and of its contention with the simulator on a small
    machine (docs/benchmarks.md, "Batching and packed messages"). Messages wait in the
    middleware's keep-all queues meanwhile; ``log_time`` is the reception time and is
    not moved, except with ``use_sim_time`` (the clock when taken: up to the window
    later; 0 takes each message as it arrives).

On SIGINT or SIGTERM the node stops spinning, takes every message already
received by the middleware and what the nodes said they published (up to
``close_timeout``), finishes the MCAP file, writes ``metadata.yaml``
and logs the message count per topic; it exits with status 0. A bad parameter
or argument is logged in one line and the process exits with status 2. A write
that fails (disk full, file too large) stops the recording with one error line and
exit status 2; the file keeps every chunk written before, and
``grazing bag reindex`` makes it a complete bag again.

Run: ``ros2 run grazing_control recorder_node --ros-args -p output:=bags/run1``
(or ``python -m grazing_control.ros.recorder_node --ros-args ...``).
"""

import json
import math
import signal
import sys
import time
from collections import defaultdict

import rclpy
import rclpy.logging
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from std_msgs.msg import Bool, String

from .common import (LATCHED_QOS, READY_TOPIC, SIGNAL_POLL, StartupError, _startup_message,
                     fast_exit_process, float_descriptor, init_ros, int_descriptor,
                     settle_heap, string_descriptor)
from .node_arguments import check_overrides, usage
from .diagnostics import OK, ERROR, WARN, Updater
from .message_wait import wait_for_messages
from .published import COMPLETE_TOPIC
from .rig_boundary import RIG_TOPICS
from grazing_control.oscillator.params import ParameterError
from grazing_control.support.signals import SignalStop
from .recording import COMPRESSIONS, DEFAULT_CHUNK_SIZE, BagWriter, message_definition
from .recording import record as records
from .recording.topics import (DEFAULT_TOPICS, EXTRA_TOPICS, PARAMETER_TOPIC, PUBLISHED_TOPIC,
                               RECORDER_QOS, adapted_qos, is_own, message_class,
                               parse_topics, qos_to_dict)

__all__ = ["DEFAULT_TOPICS", "EXTRA_TOPICS", "PARAMETER_TOPIC", "PUBLISHED_TOPIC",
           "READY_TOPIC", "RECORDER_QOS",
           "RecorderNode", "adapted_qos", "main", "parse_topics"]

# Most messages of one topic taken in one callback (keeps topics interleaved
# and the reaction to a signal prompt).
_BATCH = 256

#: Default ``batch_window``: after a wake-up the recorder waits this long, then takes
#: every message queued on every topic (docs/nodes.md, "Wire format and batching").
DEFAULT_BATCH_WINDOW = 0.001
MAX_BATCH_WINDOW = 0.1
#: While messages flow (a batch took some), the recorder's executor runs its timers and
#: services at most every this many wall seconds (record_until); the batches take the
#: messages in between.
SPIN_EVERY = 0.02
#: Default ``close_timeout``: wall seconds the recorder waits, once stopped, for what the
#: nodes said they published (ros2 launch sends SIGTERM 5 s after SIGINT, SIGKILL 5 s
#: later; the launcher stops the recorder only after the controller has exited).
DEFAULT_CLOSE_TIMEOUT = 5.0
MAX_CLOSE_TIMEOUT = 60.0
#: Wall seconds the recorder waits, after closing, for its confirmation and last status
#: to be acknowledged by their readers.
CONFIRM_ACK_TIMEOUT = 1.0

#: Wall seconds between two /diagnostics messages of the recorder.
DIAGNOSTICS_PERIOD = 1.0

class RecorderNode(Node):
    """Subscribes to the topics and writes their serialized messages to a bag.

    Parameters
    ----------
    arguments : NodeArguments, optional
        The parsed command line (:func:`~grazing_control.ros.common.init_ros`): an
        unknown ``-p`` name is refused before the bag is created.
    **kwargs
        Passed to :class:`rclpy.node.Node` (e.g. ``parameter_overrides``).

    Raises
    ------
    ParameterError
        If a parameter is invalid; nothing is created then.
    """

    def __init__(self, arguments=None, **kwargs):
        super().__init__("recorder_node", **kwargs)
        self._declare_parameters()
        if arguments is not None:      # refuse unknown -p names before creating anything
            check_overrides(self, arguments)
        output, topics, compression, chunk_size = self._read_parameters()
        self._sim_time = self.get_parameter("use_sim_time").value
        self.set_descriptor("use_sim_time", ParameterDescriptor(
            type=ParameterType.PARAMETER_BOOL, description="log time from /clock instead "
            "of the receive time (rclpy's parameter)", additional_constraints="set at "
            "start only: the bag states one time base"))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.require_complete = self.get_parameter("require_complete").value
        self.bag = BagWriter(
            output, compression=compression, chunk_size=chunk_size,
            custom_data={"log_time": "ros_clock" if self._sim_time else "received_timestamp"})
        self.bag.open()
        self.received = 0           # messages written to the bag
        self.dropped = 0            # messages taken after a failed write (not written)
        self.failed = None          # the OSError that stopped the recording
        self._published = {}        # node -> {topic: count} of its published record
        self._confirmed = set()     # nodes told (recorder/complete) that all is recorded
        self._nodes = set()         # nodes that sent a parameter record (and owe a published one)
        self._types = {}            # fully qualified topic -> message type
        self._subs = {}             # fully qualified topic -> Subscription
        self._offered = {}          # fully qualified topic -> offered QoS dicts
        self._names = {}            # fully qualified topic -> name as given
        self._first_seq = {}        # topic -> first publication sequence number
        self._last_seq = {}         # topic -> last publication sequence number
        self._gaps = defaultdict(int)   # topic -> messages skipped inside the sequence
        self._interleaved = set()   # topics on which several publishers send
        self._reliable = {}         # topic -> its subscription is reliable
        self._adapt_all = bool(self.get_parameter("adapt_qos").value)
        for name, kind in topics.items():
            topic = self.resolve_topic_name(name)            # fully qualified
            self._types[topic] = kind
            self._names[topic] = name
        self._record_topics = {self.resolve_topic_name(PARAMETER_TOPIC[0]): "parameters",
                               self.resolve_topic_name(PUBLISHED_TOPIC[0]): "published"}
        self._ready = False
        self._pub_ready = self.create_publisher(Bool, READY_TOPIC, LATCHED_QOS)
        self._pub_complete = self.create_publisher(String, COMPLETE_TOPIC, LATCHED_QOS)
        self.diagnostics = Updater(self, DIAGNOSTICS_PERIOD)   # hardware id: its namespace
        self.diagnostics.add("recording", self._diagnose)
        self._pub_ready.publish(Bool(data=False))
        # a steady clock: with use_sim_time a ROS-time timer would wait for /clock
        self._watch_timer = self.create_timer(0.05, self._watch,
                                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._watch()
        self.get_logger().info(
            f"recording {', '.join(self._types)} to {self.bag.bag_dir} "
            f"({compression}, log_time = {'ROS clock' if self._sim_time else 'receive time'})")

    def _on_set_parameters(self, params):
        """Refuse a change of ``use_sim_time`` (every other parameter is read-only): the
        bag states one time base for its log times (custom_data ``log_time``, chosen at
        start), and a third party's switch would mix two in one bag unseen (issue 27).
        Logged, and refused naming the parameter."""
        from rcl_interfaces.msg import SetParametersResult

        if not any(p.name == "use_sim_time" and p.value != self._sim_time for p in params):
            return SetParametersResult(successful=True)
        reason = (f"use_sim_time={str(not self._sim_time).lower()} is invalid while "
                  f"recording: valid is {str(self._sim_time).lower()} (the bag's log_time "
                  "is the time base chosen at start; restart the recorder to change it)")
        self.get_logger().warning(f"parameter change refused: {reason}")
        return SetParametersResult(successful=False, reason=reason)

    def _watch(self):
        """Subscribe to each topic once it has publishers; say when all are matched.

        "Matched" counts the publishers the subscription matched: a best-effort bystander
        on one of the package's (reliably recorded) topics does not make it ready.
        """
        for topic, kind in self._types.items():
            if topic not in self._subs:
                publishers = self.get_publishers_info_by_topic(topic)
                if publishers:
                    self._subscribe(topic, kind, publishers)

        if self._ready:
            return
        if len(self._subs) == len(self._types) and all(
                sub.get_publisher_count() > 0 for sub in self._subs.values()):
            self._ready = True
            self._pub_ready.publish(Bool(data=True))
            self.get_logger().info("every topic is matched: ready")
            # every topic subscribed: nothing left to watch (each run of it cost the
            # recorder an executor spin, 1-2 ms of CPU, 20 times a second)
            self._watch_timer.cancel()

    def watch_due(self) -> float:
        """Seconds until the topic watch (:meth:`_watch`) is due (<= 0: due now;
        SIGNAL_POLL once it has stopped: a cancelled timer has no next call)."""
        due = self._watch_timer.time_until_next_call()
        return SIGNAL_POLL if due is None else due * 1e-9

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
        self.declare_parameter("rig_topics", False, read_only(
            "also record the driver contract's topics (rig/sensor, rig/phase, rig/clock, "
            "rig/force_pulse, rig/applied, grazing/rig: docs/driver_contract.md); grazing "
            "run --rig sets it", ParameterType.PARAMETER_BOOL))
        self.declare_parameter("compression", "zstd", string_descriptor(
            f"chunk compression: {', '.join(COMPRESSIONS)}", True, COMPRESSIONS))
        self.declare_parameter("chunk_size", DEFAULT_CHUNK_SIZE, int_descriptor(
            "uncompressed chunk size, bytes, > 0", 1, None, read_only=True))
        self.declare_parameter("require_complete", False, read_only(
            "exit with status 1 when messages were missed", ParameterType.PARAMETER_BOOL))
        self.declare_parameter("adapt_qos", False, read_only(
            "subscribe to the package's own topics with ros2 bag's adapted QoS too (default: "
            "reliable, a best-effort publisher is left out)", ParameterType.PARAMETER_BOOL))
        self.declare_parameter("close_timeout", DEFAULT_CLOSE_TIMEOUT, float_descriptor(
            f"wall seconds the recorder waits, once stopped, for the messages the nodes said "
            f"they published (grazing/published), in [0, {MAX_CLOSE_TIMEOUT:g}]",
            0.0, MAX_CLOSE_TIMEOUT, read_only=True))
        self.declare_parameter("batch_window", DEFAULT_BATCH_WINDOW, float_descriptor(
            f"seconds the recorder lets messages gather after each wake-up before taking "
            f"all of them, in [0, {MAX_BATCH_WINDOW:g}] (0: take each one as it arrives)",
            0.0, MAX_BATCH_WINDOW, read_only=True))

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
        window = self.get_parameter("batch_window").value
        if not 0.0 <= window <= MAX_BATCH_WINDOW:
            raise ParameterError(f"batch_window={window!r} is invalid: valid range is "
                                 f"[0, {MAX_BATCH_WINDOW:g}] seconds")
        wait = self.get_parameter("close_timeout").value
        if not 0.0 <= wait <= MAX_CLOSE_TIMEOUT:
            raise ParameterError(f"close_timeout={wait!r} is invalid: valid range is "
                                 f"[0, {MAX_CLOSE_TIMEOUT:g}] seconds")
        try:
            entries = self.get_parameter("topics").value
        except ParameterUninitializedException:      # -p topics:=[] has no type
            entries = []
        topics = parse_topics(entries)
        if self.get_parameter("rig_topics").value:      # a rig scene (issue 28)
            topics.update({k: v for k, v in RIG_TOPICS.items() if k not in topics})
        for kind in topics.values():
            try:
                message_class(kind)
                message_definition(kind)
            except (ImportError, AttributeError, LookupError, ValueError):
                raise ParameterError(f"topics: message type {kind!r} is not installed "
                                     "(no Python module or no .msg file)") from None
        return output, topics, compression, chunk_size

    def _subscribe(self, topic, kind, publishers):
        """Subscribe to ``topic`` with the QoS adapted to its ``publishers``."""
        own = is_own(self._names[topic]) and not self._adapt_all
        qos, warnings = adapted_qos([p.qos_profile for p in publishers], own=own)
        for text in warnings:
            self.get_logger().warning(f"{topic}: {text}")
        self._reliable[topic] = qos.reliability == ReliabilityPolicy.RELIABLE
        self._offered[topic] = [qos_to_dict(p.qos_profile) for p in publishers
                                if not own or not self._reliable[topic]
                                or p.qos_profile.reliability == ReliabilityPolicy.RELIABLE]
        events = SubscriptionEventCallbacks(
            incompatible_qos=lambda event: self._on_incompatible_qos(topic, event))
        self._subs[topic] = self.create_subscription(
            message_class(kind), self._names[topic],
            lambda data, info: self._on_message(topic, data, info),
            qos, raw=True, event_callbacks=events)

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
        handle, kind, record = sub.handle, sub.msg_type, self._record
        with handle:            # held for the batch, not entered once a message
            for n in range(limit):
                taken = handle.take_message(kind, True)
                if taken is None:
                    return n
                record(topic, *taken)
        return limit

    def _record(self, topic, data, info):
        """Write one serialized message as received (nothing after a failed write)."""
        if self.failed is not None:
            self.dropped += 1
            return
        if self._sim_time:
            log_time = self.get_clock().now().nanoseconds
        else:
            log_time = info.get("received_timestamp") or time.time_ns()
        sequence = info.get("publication_sequence_number") or 0
        sequence = sequence if sequence < 2**63 else 0
        try:
            if not self.bag.has_topic(topic):
                self.bag.add_topic(topic, self._types[topic],
                                   self._offered.get(topic) or [qos_to_dict(RECORDER_QOS)])
            self.bag.write(topic, data, log_time, info.get("source_timestamp") or log_time,
                           sequence)
        except OSError as exc:
            self.failed = exc
            self.get_logger().error(
                f"writing {self.bag.path} failed: {exc.strerror or exc}: recording stopped; "
                "the file keeps every chunk written before (grazing bag reindex "
                f"{self.bag.bag_dir} makes it a complete bag)")
            return
        self.received += 1
        self._track_sequence(topic, sequence)
        if topic in self._record_topics:
            self._read_record(self._record_topics[topic], data)

    def _read_record(self, kind, data):
        """Note a node's parameter record (it owes a published record at its end) or its
        published record (the counts the tail is checked against)."""
        from rclpy.serialization import deserialize_message
        from std_msgs.msg import String

        try:
            text = deserialize_message(data, String).data
            if kind == "parameters":
                self._nodes.add(records.decode(text)[0])
            else:
                node, counts = records.decode_published(text)
                self._published[node] = counts
        except Exception:        # a foreign or malformed message: recorded, not used
            return

    def _track_sequence(self, topic, sequence):
        if not sequence:
            return
        if topic not in self._first_seq:
            self._first_seq[topic] = sequence
        else:
            last = self._last_seq[topic]
            if sequence <= last:            # a second publisher that sends: interleaved
                self._interleaved.add(topic)
            elif sequence > last + 1:
                self._gaps[topic] += sequence - last - 1
        self._last_seq[topic] = sequence

    def missed(self):
        """{topic: messages missed} from the publisher's sequence numbers.

        Messages published before the recorder matched the publisher (the first one
        recorded has sequence number n > 1: n - 1 missed), lost in between (gaps), or
        after the last one recorded: the tail, from the count the publishing node said
        in its published record (:meth:`tails`). A topic on which two publishers both
        send interleaves their sequences and cannot be checked (a silent second
        publisher, e.g. a passive bystander, does not prevent the check).
        """
        out = {}
        for topic, first in self._first_seq.items():
            if topic in self._interleaved:
                continue
            n = first - 1 + self._gaps[topic]
            if n:
                out[topic] = n
        for topic, n in self.tails().items():
            out[topic] = out.get(topic, 0) + n
        return out

    def tails(self):
        """{topic: messages published after the last one recorded}: the nodes' published
        records (:mod:`grazing_control.ros.published`) against the last sequence number
        received (0: none). Only topics this recorder records, with one publisher."""
        out = {}
        for counts in self._published.values():
            for topic, count in counts.items():
                if topic not in self._types or topic in self._interleaved:
                    continue
                n = count - self._last_seq.get(topic, 0)
                if n > 0:
                    out[topic] = out.get(topic, 0) + n
        return out

    def confirm(self):
        """Say on ``recorder/complete`` which nodes' published records are recorded in
        full (their counts reached), so that they stop waiting and exit."""
        done = {node for node, counts in self._published.items()
                if node not in self._confirmed and all(
                    self._last_seq.get(t, 0) >= n for t, n in counts.items()
                    if t in self._types and t not in self._interleaved)}
        if done:
            self._confirmed |= done
            self._pub_complete.publish(String(data=json.dumps(sorted(self._confirmed))))

    def unannounced(self):
        """Nodes that sent a parameter record but no published record (yet): the tails
        of their topics cannot be checked."""
        return sorted(self._nodes - set(self._published))

    def settle(self, executor, timeout: float) -> None:
        """Once stopped: take messages until every node's published record has come and
        every count in it is recorded, ``timeout`` wall seconds at most (issue 27: a
        recorder behind a loaded scene still had the last corrections to take)."""
        end = time.monotonic() + timeout
        self.drain()
        self.confirm()
        while (self.failed is None and (self.tails() or self.unannounced())
               and time.monotonic() < end and rclpy.ok()):
            executor.spin_once(timeout_sec=0.02)
            self.drain()
            self.confirm()

    def _diagnose(self, stat):
        """The recorder's /diagnostics task: messages received, written, dropped (after a
        failed write), missed so far (sequence gaps; the tail once the nodes have said
        what they published)."""
        missed = sum(self.missed().values())
        stat.summary(OK, "recording" if self._ready else "waiting for every topic's publisher")
        stat.add("received", self.received + self.dropped)
        stat.add("written", self.received)
        stat.add("dropped", self.dropped)
        stat.add("missed", missed)
        stat.add("topics matched", f"{len(self._subs)}/{len(self._types)}")
        stat.add("bag", str(self.bag.bag_dir))
        if missed:
            stat.merge_summary(WARN, f"{missed} messages missed (published, not received)")
        if self.failed is not None:
            stat.merge_summary(ERROR, f"writing the bag failed: "
                                      f"{self.failed.strerror or self.failed}; "
                                      f"{self.dropped} messages dropped")
        return stat

    def _on_incompatible_qos(self, topic, event):
        self.get_logger().warning(
            f"{topic}: a publisher's QoS is incompatible with the recorder's subscription "
            f"(policy {event.last_policy_kind}): its messages are not recorded")

    def drain(self):
        """Record every message the middleware has already received.

        Returns
        -------
        int
            Number of messages taken.
        """
        total = 0
        while self.failed is None:
            taken = sum(self._take_queued(topic, _BATCH) for topic in self._subs)
            if taken == 0:
                return total
            total += taken
        return total

    def close(self):
        """Finish the bag (summary, metadata.yaml) and log the counts per topic.

        Returns the exit status: 0, 1 if messages were missed and ``require_complete``,
        2 if a write failed (then the file is only closed, not finished).
        """
        log = self.get_logger()
        if self.failed is not None:
            self.bag.abandon()
            return 2
        for topic, kind in self._types.items():
            if not self.bag.has_topic(topic):          # listed, with no message
                self.bag.add_topic(topic, kind, self._offered.get(topic)
                                   or [qos_to_dict(RECORDER_QOS)])
        missed = self.missed()
        unannounced = self.unannounced()
        # a node that never said what it published (killed, or its record lost with it)
        # leaves the tail of its topics unchecked: not complete either
        status = 1 if (missed or unannounced) and self.require_complete else 0
        # The closed record: metadata.yaml, written last and atomically, carries the
        # status, so the launcher reads success from the bag itself, not from how fast
        # the process ends afterwards (issue 21 section 6), and what was missed, so that
        # it can name the loss (issue 27).
        self.bag.custom_data["recorder_status"] = str(status)
        self.bag.custom_data["recorder_received"] = str(self.received)
        if missed or unannounced:
            self.bag.custom_data["recorder_missed"] = ", ".join(
                [f"{t} {n}" for t, n in sorted(missed.items())]
                + [f"{node}'s tail (no published record)" for node in unannounced])
        try:            # the last status, with the final counts
            self.diagnostics.update()
        except Exception:
            pass
        try:
            info = self.bag.close()
        except OSError as exc:
            self.bag.abandon()
            log.error(f"finishing {self.bag.path} failed: {exc.strerror or exc} (grazing bag "
                      f"reindex {self.bag.bag_dir} recovers the chunks written)")
            return 2
        if info:
            counts = ", ".join(f"{name} {n}" for name, n in self.bag.message_counts.items())
            log.info(f"closed {self.bag.path}: {info['message_count']} messages ({counts})")
        # the confirmation (recorder/complete) and the last status reach their readers
        # before this node leaves the graph (a reader that had not taken them lost them
        # with the participant: a controller then waited its whole ACK_TIMEOUT)
        for pub in (self._pub_complete, self.diagnostics.publisher):
            try:
                pub.wait_for_all_acked(Duration(seconds=CONFIRM_ACK_TIMEOUT))
            except Exception:           # noqa: BLE001 - leaving must not fail
                pass
        # the parameter and published records have one publisher per node by design
        # (depth 1, latched): not a loss check's business, and not worth a warning
        unchecked = sorted(t for t in self._interleaved
                           if t not in self._record_topics)
        if unchecked:
            self.get_logger().warning(
                f"not checked for losses: {', '.join(unchecked)} (several "
                "publishers sent on it: their sequence numbers interleave)")
        if unannounced:
            log.warning(f"no published record (grazing/published) from "
                        f"{', '.join(unannounced)}: the tail of its topics is not checked")
        if missed:
            text = ", ".join(f"{t} {n}" for t, n in missed.items())
            log.warning(f"missed: {text} (published before the recorder matched the "
                        "publisher, lost, or published after the recording stopped)")
        return status

def record_until(node, executor, stop) -> None:
    """Record until ``stop`` (a threading.Event) is set, then take what the nodes' published
    records still name (:meth:`RecorderNode.settle`): the recorder's loop, in its own
    process (:func:`main`) or in a thread of a composed scene (ros/composed.py)."""
    window = node.get_parameter("batch_window").value
    flowing = False       # the last batch took messages: the next one is gathering
    spun = -math.inf
    while not stop.is_set() and rclpy.ok() and node.failed is None:
        now = time.monotonic()
        if window <= 0.0 or not node._subs:
            if not flowing or now - spun >= SPIN_EVERY:
                # an idle one waits here (and notices a stop); while messages flow, the
                # executor's wait set (rclpy builds it in Python over every
                # subscription, timer and service: the recorder's largest cost per
                # wake-up, issue 30) only every SPIN_EVERY s, for the timers and services
                executor.spin_once(timeout_sec=0.0 if flowing else SIGNAL_POLL)
                spun = now
        else:
            # the executor (timers, services, QoS events) every SIGNAL_POLL s and when
            # the topic watch is due; in between the batches take the messages, and an
            # idle recorder waits on its subscriptions alone (ros/message_wait.py:
            # woken through the executor once a message, it burnt 45 % of a core at
            # ~200 messages/s, docs/benchmarks.md, "The recorder between messages")
            due = node.watch_due()
            if due <= 0.0 or now - spun >= SIGNAL_POLL:
                executor.spin_once(timeout_sec=0.0)
                spun = now
                due = node.watch_due()
            if not flowing:
                wait_for_messages(node._subs.values(), node.context,
                                  min(spun + SIGNAL_POLL - time.monotonic(), due))
        if window > 0.0:    # let a batch gather, then take all of it in one go
            stop.wait(window)
            flowing = node.drain() > 0
        if len(node._published) > len(node._confirmed):
            node.confirm()
    node.settle(executor, node.get_parameter("close_timeout").value)


def _stop_on_signals(stop):
    """SIGINT and SIGTERM set `stop` (the spin loop then ends and the bag closes)."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, stop.set)

def main(args=None):
    """Run the recorder until SIGINT/SIGTERM; return the exit status."""
    args = list(sys.argv if args is None else args)
    # Our own handlers, from the start: rclpy's would shut the context down before the
    # drain, and a signal while starting must end the process quietly.
    stop = SignalStop()
    _stop_on_signals(stop)
    status = 0
    node = executor = pauses = None
    try:
        arguments = init_ros(args, "recorder_node")
        if arguments is None:
            sys.stdout.write(usage(RecorderNode, "recorder_node"))
            return 0
        if stop.is_set():
            return 0
        node = RecorderNode(arguments)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        pauses = settle_heap()
        record_until(node, executor, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (StartupError, ParameterError, ParameterException, OSError) as exc:
        # bad parameter or argument, bag not creatable
        rclpy.logging.get_logger("recorder_node").error(_startup_message(exc))
        status = 2
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)    # a second Ctrl-C must not cut the close
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if node is not None:
            status = node.close() or status
        if pauses is not None:
            rclpy.logging.get_logger("recorder_node").info(pauses.summary())
    # The bag is closed and its summary logged: leave the graph and end the process.
    # Tearing the interpreter down (GC of every history) took up to 30 s under CPU
    # starvation, past the launcher's grace (issue 21: a complete bag, then SIGKILL).
    fast_exit_process(status, node, executor)

if __name__ == "__main__":
    sys.exit(main())

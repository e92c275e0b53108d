"""What the recorder records and how it subscribes: the package's topics (recorded by
default) and their types, a ``topics`` parameter read into names and types, and the QoS
adapted to what the publishers offer (rosbag2's rule; the package's own topics reliable).
docs/recording.md, "Topics"."""

from __future__ import annotations

import importlib

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from grazing_control.oscillator.params import ParameterError

from ..rig_boundary import RIG_TOPICS
from . import qos_profile_dict
from . import record as records

#: Topics recorded by default (relative names) and their types.
DEFAULT_TOPICS = {
    "oscillator/state": "sensor_msgs/msg/JointState",
    "oscillator/impact": "geometry_msgs/msg/Vector3Stamped",
    "oscillator/pi1": "sensor_msgs/msg/JointState",
    "oscillator/pi2": "sensor_msgs/msg/JointState",
    "controller/velocity_correction": "geometry_msgs/msg/TwistStamped",
    "/clock": "rosgraph_msgs/msg/Clock",
    "oscillator/deadline_miss": "geometry_msgs/msg/Vector3Stamped",
    "oscillator/substituted": "geometry_msgs/msg/TwistStamped",
}

#: The nodes' parameter record (grazing_control.ros.recording.record), recorded by default too;
#: its publishers are transient local, so the adapted subscription is too and a record
#: published before the match is received.
PARAMETER_TOPIC = ("grazing/parameters", "std_msgs/msg/String")
#: The nodes' published record (what each published, sent when it stops: issue 27),
#: recorded by default; the recorder checks the tail of every topic against it.
PUBLISHED_TOPIC = (records.PUBLISHED_TOPIC, "std_msgs/msg/String")
#: Also recorded by default: what the analysis of a realtime run reads (docs/analysis.md).
EXTRA_TOPICS = {PARAMETER_TOPIC[0]: PARAMETER_TOPIC[1],
                PUBLISHED_TOPIC[0]: PUBLISHED_TOPIC[1],
                "oscillator/latency": "std_msgs/msg/Float64",
                "controller/estimate": "sensor_msgs/msg/JointState",
                "controller/model_watch": "sensor_msgs/msg/JointState",
                "controller/model_switch": "sensor_msgs/msg/JointState",
                "controller/enabled": "std_msgs/msg/Bool",
                "oscillator/state_block": "std_msgs/msg/Float64MultiArray"}

#: Subscription QoS before adaptation: reliable and keep-all, so a lockstep run loses
#: nothing (used for a topic's metadata when it never had a publisher).
RECORDER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    depth=0,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

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

def adapted_qos(offered, own: bool = False):
    """The subscription QoS for publishers offering ``offered`` (rosbag2's rule).

    rosbag2_transport ``Rosbag2QoS::adapt_request_to_offers``: reliable only if every
    publisher is reliable, else best effort (which matches both kinds); transient local
    only if every publisher is, else volatile. History (keep all here) does not affect
    compatibility; deadline and liveliness stay at their defaults, compatible with any
    offer. Returns ``(qos, warnings)``: a warning for each mixed policy.

    ``own``: the topic is one of the package's (its nodes publish it reliably). Then the
    subscription is reliable whatever is offered: a best-effort publisher (a bystander,
    or a rig's driver: record it with ``adapt_qos:=true``) is left out with a warning, so
    a passive bystander cannot turn the scene's record lossy (issue 21).
    """
    offered = list(offered)
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=0,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    warnings = []
    if not offered:
        return qos, warnings
    reliable = sum(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    if own:
        if reliable < len(offered):
            warnings.append(f"{len(offered) - reliable} best-effort publisher(s) not recorded "
                            "(the package's own topics are recorded reliably; "
                            "adapt_qos:=true records them best effort, as ros2 bag does)")
        offered = [q for q in offered if q.reliability == ReliabilityPolicy.RELIABLE]
        if not offered:
            return qos, warnings
        reliable = len(offered)
    latched = sum(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    if reliable < len(offered):
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
        if reliable:
            warnings.append("some, but not all, publishers are reliable: subscribed best "
                            "effort (messages of the reliable ones may be dropped)")
    if latched == len(offered):
        qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    elif latched:
        warnings.append("some, but not all, publishers are transient local: subscribed "
                        "volatile (their earlier messages are not retrieved)")
    return qos, warnings

def is_own(topic: str) -> bool:
    """Whether ``topic`` (as configured, relative or absolute) is one of the package's."""
    return topic.lstrip("/") in _OWN


_OWN = {name.lstrip("/") for name in (*DEFAULT_TOPICS, *EXTRA_TOPICS, *RIG_TOPICS)}


def qos_to_dict(qos):
    """rosbag2 mapping (:func:`~grazing_control.ros.recording.qos_profile_dict`) of a QoSProfile."""
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

def message_class(msg_type):
    """Python class of ``pkg/msg/Type`` (or ``pkg/Type``)."""
    parts = msg_type.split("/")
    package, name = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{package}.msg"), name)

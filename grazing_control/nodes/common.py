"""Small helpers shared by the node adapters: QoS, stamps, descriptors, throttled logs, main.

Nothing here knows the model; the nodes (:mod:`sim_node.sim_node`,
:mod:`grazing_control.nodes.controller_node`) adapt the core to ROS with these.

QoS (docs/nodes.md, "QoS")
--------------------------
Every data topic (Pi2 samples, corrections, impacts, section crossings, state, /clock,
latency) is reliable and volatile. Publishers use :data:`PUBLISHER_QOS`, keep last
100000: a reliable writer keeps each message until every reader has acknowledged it or
it falls out of this history, so the depth is the backlog a reader may accumulate without
loss. In lockstep the simulator is paced only by the controller and publishes the
state, crossings and impacts of a 1200-period scene (about 25,000 messages) in about a
second, faster than a recorder takes them; the history holds them until it does (the
memory is used only while a reader lags). The nodes' own subscriptions use
:data:`DATA_QOS` (reliable, keep last 1000): they need only the newest samples.
:data:`LATCHED_QOS` (reliable, transient local, depth 1) is for ``oscillator/done``, so
that a late subscriber still learns that the scene has finished.
"""

from __future__ import annotations

import math
import re
import signal
import time

import rclpy
import rclpy.logging
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    "DATA_QOS",
    "PUBLISHER_QOS",
    "LATCHED_QOS",
    "publish_parameter_record",
    "StartupError",
    "Throttled",
    "bool_descriptor",
    "float_descriptor",
    "int_descriptor",
    "run_node",
    "spin",
    "seconds_from_stamp",
    "stamp_from_seconds",
    "stamp_key",
    "string_descriptor",
]

#: Reliable, volatile, keep last 1000: the nodes' subscriptions (see the module docstring).
DATA_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)

#: Reliable, volatile, keep last 100000: every data publisher (a lagging reader loses nothing).
PUBLISHER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100_000,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)

#: Reliable, transient local, depth 1: ``oscillator/done``.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

_NS = 1_000_000_000


class StartupError(RuntimeError):
    """A node cannot start (invalid parameter): logged in one line, exit status 2."""


# --------------------------------------------------------------------------- stamps
def stamp_from_seconds(t: float) -> Time:
    """builtin_interfaces/Time for a simulation time t >= 0 in seconds (rounded to 1 ns)."""
    ns = int(round(t * 1e9))
    return Time(sec=ns // _NS, nanosec=ns % _NS)


def stamp_key(stamp) -> tuple:
    """(sec, nanosec) of a stamp: the exact identity of a sample."""
    return (stamp.sec, stamp.nanosec)


def seconds_from_stamp(stamp) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return stamp.sec + stamp.nanosec * 1e-9


# ----------------------------------------------------------------------- descriptors
def float_descriptor(description: str, lo: float | None = None, hi: float | None = None,
                     read_only: bool = False) -> ParameterDescriptor:
    """A double parameter; with ``lo``/``hi`` a FloatingPointRange (closed, ends included)."""
    d = ParameterDescriptor(type=ParameterType.PARAMETER_DOUBLE, description=description,
                            read_only=read_only)
    if lo is not None or hi is not None:
        d.floating_point_range = [FloatingPointRange(
            from_value=-math.inf if lo is None else float(lo),
            to_value=math.inf if hi is None else float(hi), step=0.0)]
    return d


def int_descriptor(description: str, lo: int | None = None, hi: int | None = None,
                   read_only: bool = False) -> ParameterDescriptor:
    """An integer parameter; with ``lo``/``hi`` an IntegerRange (ends included)."""
    d = ParameterDescriptor(type=ParameterType.PARAMETER_INTEGER, description=description,
                            read_only=read_only)
    if lo is not None or hi is not None:
        d.integer_range = [IntegerRange(from_value=-2**63 if lo is None else int(lo),
                                        to_value=2**63 - 1 if hi is None else int(hi), step=1)]
    return d


def string_descriptor(description: str, read_only: bool = False,
                      choices=None) -> ParameterDescriptor:
    """A string parameter; ``choices`` is stated in additional_constraints."""
    d = ParameterDescriptor(type=ParameterType.PARAMETER_STRING, description=description,
                            read_only=read_only)
    if choices:
        d.additional_constraints = "one of: " + ", ".join(choices)
    return d


def bool_descriptor(description: str, read_only: bool = False) -> ParameterDescriptor:
    """A boolean parameter."""
    return ParameterDescriptor(type=ParameterType.PARAMETER_BOOL, description=description,
                               read_only=read_only)


# ------------------------------------------------------------------ throttled logging
class Throttled:
    """Count events of one kind and log at most one line per ``interval`` wall seconds.

    >>> bad = Throttled(node.get_logger(), "malformed correction")   # doctest: +SKIP
    >>> bad("NaN dv")   # counts, logs "malformed correction (1 so far): NaN dv"
    """

    def __init__(self, logger, what: str, interval: float = 2.0):
        self.logger = logger
        self.what = what
        self.interval = interval
        self.count = 0
        self._last = -math.inf

    def __call__(self, detail: str) -> None:
        self.count += 1
        now = time.monotonic()
        if now - self._last >= self.interval:
            self._last = now
            self.logger.warning(f"{self.what} ({self.count} so far): {detail}")


# ------------------------------------------------------------------------------ main
_TYPE_RE = re.compile(r"Trying to set parameter '(?P<name>[^']*)' to '(?P<value>.*)' of type "
                      r"'(?P<got>\w+)', expecting type '(?P<want>\w+)'")
_VALUE_RE = re.compile(r"Invalid parameter value \((?P<value>.*?)\) for parameter\. "
                       r"Reason: (?P<reason>.*): (?P<name>[\w./]+)$")


def _startup_message(exc: BaseException) -> str:
    """One line for a refused parameter: ``name=value is invalid: reason``."""
    text = " ".join(str(exc).split())
    m = _TYPE_RE.search(text)
    if m:
        hint = " (write a double with a decimal point, e.g. 1.0)" if m["want"] == "DOUBLE" else ""
        return (f"{m['name']}={m['value']} is invalid: expected type {m['want']}, "
                f"got {m['got']}{hint}")
    m = _VALUE_RE.search(text)
    if m:
        return f"{m['name']}={m['value']} is invalid: {m['reason']}"
    return text or type(exc).__name__


#: Longest wall time an idle executor waits before noticing a signal (seconds).
SIGNAL_POLL = 0.2


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def spin(executor, done=None) -> None:
    """Spin until ``done()`` is true (or forever), waking at least every SIGNAL_POLL s."""
    while rclpy.ok() and not (done is not None and done()):
        executor.spin_once(timeout_sec=SIGNAL_POLL)


def run_node(factory, args=None, name: str = "node") -> int:
    """The main of every node: init, build, spin, and a clean exit.

    ``factory()`` builds the node; its optional ``spin_until(executor)`` method spins
    (a node that finishes by itself returns from it), otherwise :func:`spin` spins until
    shutdown. A :class:`StartupError` or a parameter exception while building is logged
    in one line and gives exit status 2. SIGINT (Ctrl-C) and SIGTERM end the spin
    without a traceback: rclpy's own signal handlers are not installed, so the context
    stays valid while the node's ``on_exit()`` logs its summary (to /rosout too); a
    second signal during that cleanup is ignored. Returns the exit status, which is the
    value of ``node.exit_code`` if the node has one.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    node = None
    code = 0
    try:
        node = factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        if hasattr(node, "spin_until"):
            node.spin_until(executor)
        else:
            spin(executor)
    except (StartupError, ParameterException) as exc:
        rclpy.logging.get_logger(name).error(_startup_message(exc))
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # a second Ctrl-C (terminal and launcher both signal) must not break the cleanup
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if node is not None:
            if hasattr(node, "on_exit"):
                node.on_exit()
            code = code or int(getattr(node, "exit_code", 0))
            node.destroy_node()
        rclpy.try_shutdown()
    return code


# ------------------------------------------------------------------ parameter record
def publish_parameter_record(node):
    """Publish the node's parameters on ``grazing/parameters``, now and after each change.

    One std_msgs/String (JSON of :func:`grazing_control.bagtools.record.encode`) on a
    reliable, transient-local, depth-1 publisher, so that a recording describes itself
    (docs/analysis.md, "Parameter record"). Returns the publisher.
    """
    from std_msgs.msg import String

    from grazing_control.bagtools.record import TOPIC, encode

    pub = node.create_publisher(String, TOPIC, LATCHED_QOS)

    def publish(_changed=None):
        values = {name: p.value for name, p in node.get_parameters_by_prefix("").items()}
        pub.publish(String(data=encode(node.get_fully_qualified_name(), values)))

    node.add_post_set_parameters_callback(publish)
    publish()
    return pub

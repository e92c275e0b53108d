"""Small helpers shared by the node adapters: QoS, stamps, descriptors, throttled logs, main.

Nothing here knows the model; the nodes (:mod:`sim_node.sim_node`,
:mod:`grazing_control.ros.controller_node`) adapt the core to ROS with these.

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
that a late subscriber still learns that the scene has finished. A reader of a latched
topic with several writers (the parameter records) uses :data:`RECORDS_QOS` (depth
1000): a reader's depth counts every writer's samples together.
"""

from __future__ import annotations

import gc
import math
import os
import re
import signal
import sys
import threading
import time
import warnings

import rclpy
import rclpy.logging
from rclpy._rclpy_pybind11 import RCLError
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .cdr import stamp_parts

__all__ = [
    "DATA_QOS",
    "INPUT_QOS",
    "EXECUTORS",
    "executor_kind",
    "make_executor",
    "freeze_heap",
    "SafePoints",
    "settle_heap",
    "GcPauses",
    "deserialize",
    "PUBLISHER_QOS",
    "READY_TOPIC",
    "REPLAY_QOS",
    "LATCHED_QOS",
    "RECORDS_QOS",
    "EVENT_QOS",
    "publish_parameter_record",
    "fast_exit_process",
    "leave_graph",
    "StartupError",
    "Throttled",
    "bool_descriptor",
    "check_ranges",
    "range_problem",
    "refuse_out_of_range",
    "init_ros",
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

#: Reliable, volatile, keep last 100000: a subscription that must take every message, the
#: controller's inputs (Pi2 samples, the sensor stream, impacts, misses): a reader's
#: history of 1000 (:data:`DATA_QOS`) dropped its oldest unread samples without a word
#: when the controller lagged 1000 behind (a replay at twice the recorded rate on a
#: loaded host: 109 of 1300 samples never answered, none counted). A lagging controller
#: now answers them late, where lateness is counted (stale_after, the deadlines).
INPUT_QOS = PUBLISHER_QOS

#: Reliable, transient local, keep last 100000: the controller's corrections. A reader
#: that matches the writer late (the recorder: the simulator can check its own writers'
#: matches before the scene starts, not the controller's) still gets every answer
#: published before, from the writer's history; volatile readers (the simulator) are
#: compatible and get no replay.
REPLAY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100_000,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: Reliable, transient local, depth 1: ``oscillator/done``.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: Reliable, transient local, keep last 1000: a reader of a latched topic that several
#: nodes publish (the parameter records, ``grazing/parameters``). A reader's depth bounds
#: the samples of *all* writers together (the topic has no key): at depth 1, the record
#: of the simulator itself, arriving after its controller's and before the executor took
#: it, replaced the controller's, and the simulator waited its whole start_timeout for a
#: record it had received (issue 27, docs/nodes.md "Start handshake").
RECORDS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: The simulator's event records on grazing/parameters (the watchdog's trip, the
#: feasibility verdict): reliable, transient local, deep enough for every event of a run.
EVENT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=16,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: Latched topic (std_msgs/Bool) on which recorder_node says it has matched a publisher
#: on every topic it records; sim_node waits for it with ``wait_for_recorder``.
READY_TOPIC = "recorder/ready"


class StartupError(RuntimeError):
    """A node cannot start (invalid parameter): logged in one line, exit status 2."""


# --------------------------------------------------------------------------- stamps
def stamp_from_seconds(t: float) -> Time:
    """builtin_interfaces/Time for a simulation time t >= 0 in seconds (rounded to 1 ns,
    :func:`grazing_control.ros.cdr.stamp_parts`)."""
    sec, nanosec = stamp_parts(t)
    return Time(sec=sec, nanosec=nanosec)


def stamp_key(stamp) -> tuple:
    """(sec, nanosec) of a stamp: the exact identity of a sample."""
    return (stamp.sec, stamp.nanosec)


def seconds_from_stamp(stamp) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return stamp.sec + stamp.nanosec * 1e-9


# ----------------------------------------------------------------------- descriptors
def float_descriptor(description: str, lo: float | None = None, hi: float | None = None,
                     read_only: bool = False, constraints: str = "") -> ParameterDescriptor:
    """A double parameter; with ``lo``/``hi`` a FloatingPointRange (closed, ends included:
    an open end is the next double, ``math.nextafter``); ``constraints``: what a range
    cannot say (additional_constraints, shown by ``ros2 param describe``)."""
    d = ParameterDescriptor(type=ParameterType.PARAMETER_DOUBLE, description=description,
                            read_only=read_only, additional_constraints=constraints)
    if lo is not None or hi is not None:
        d.floating_point_range = [FloatingPointRange(
            from_value=-math.inf if lo is None else float(lo),
            to_value=math.inf if hi is None else float(hi), step=0.0)]
    return d


def int_descriptor(description: str, lo: int | None = None, hi: int | None = None,
                   read_only: bool = False, constraints: str = "") -> ParameterDescriptor:
    """An integer parameter; with ``lo``/``hi`` an IntegerRange (ends included)."""
    d = ParameterDescriptor(type=ParameterType.PARAMETER_INTEGER, description=description,
                            read_only=read_only, additional_constraints=constraints)
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


def bool_descriptor(description: str, read_only: bool = False,
                    constraints: str = "") -> ParameterDescriptor:
    """A boolean parameter."""
    return ParameterDescriptor(type=ParameterType.PARAMETER_BOOL, description=description,
                               read_only=read_only, additional_constraints=constraints)


def range_problem(node, name: str, value) -> str | None:
    """Why ``value`` lies outside the range the node describes for ``name``, or None.

    rclpy accepts a double within a relative 1e-6 of an end of its FloatingPointRange
    (``Node.PARAM_REL_TOL``): diagnostics_period 3600.0000000000005 passed though
    described as at most 3600 (issue 27). The nodes hold each range exactly, so that
    ``ros2 param describe`` states what they accept.
    """
    if not isinstance(value, float) or not node.has_parameter(name):
        return None
    ranges = node.describe_parameter(name).floating_point_range
    if not ranges:
        return None
    lo = min(ranges[0].from_value, ranges[0].to_value)
    hi = max(ranges[0].from_value, ranges[0].to_value)
    if lo <= value <= hi:
        return None
    return f"{name}={value!r} is invalid: valid range is [{lo!r}, {hi!r}]"


def check_ranges(node) -> None:
    """StartupError naming the first declared double outside its described range."""
    for name in node.list_parameters([], 0).names:
        try:
            value = node.get_parameter(name).value
        except ParameterUninitializedException:     # declared by type, no value yet
            continue
        problem = range_problem(node, name, value)
        if problem:
            raise StartupError(problem)


def refuse_out_of_range(node, params):
    """The refusal of a set-parameters request with a double outside its described
    range (:func:`range_problem`), else None."""
    from rcl_interfaces.msg import SetParametersResult

    for p in params:
        problem = range_problem(node, p.name, p.value)
        if problem:
            return SetParametersResult(successful=False, reason=problem)
    return None


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


def deserialize(data: bytes, kind, malformed: Throttled):
    """A message of type ``kind`` from serialized ``data`` with rclpy's deserializer, or
    None (counted and logged by ``malformed``) when the bytes decode to no such message:
    a node must not fail on what arrives (the fast path of :mod:`.cdr` comes first)."""
    from rclpy.serialization import deserialize_message

    try:
        return deserialize_message(data, kind)
    except Exception as exc:  # noqa: BLE001 - rclpy raises several types for bad bytes
        malformed(f"{len(data)} bytes that are no {kind.__name__} ({exc})")
        return None


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
        hint = {"DOUBLE": " (write a double with a decimal point, e.g. 1.0)",
                "STRING": " (quote a value that YAML reads as another type: "
                          "-p \"name:='123'\")",
                "STRING_ARRAY": " (write a list of strings: -p \"name:=['a', 'b']\")",
                "INTEGER": " (write an integer, e.g. 262144)"}.get(m["want"], "")
        return (f"{m['name']}={m['value']} is invalid: expected type {m['want']}, "
                f"got {m['got']}{hint}")
    m = _VALUE_RE.search(text)
    if m:
        return f"{m['name']}={m['value']} is invalid: {m['reason']}"
    return text or type(exc).__name__


#: The executors a node can spin in (its read-only parameter ``executor``):
#: ``single_threaded`` (rclpy.executors.SingleThreadedExecutor) and ``events``
#: (rclpy.experimental.EventsExecutor: the wait and dispatch in C++; the default of
#: sim_node and controller_node, measured faster in docs/benchmarks.md). A node without
#: an ``executor_kind`` attribute gets the SingleThreadedExecutor.
EXECUTORS = ("single_threaded", "events")


def executor_kind(node) -> str:
    """The node's ``executor`` parameter, one of :data:`EXECUTORS` (StartupError)."""
    kind = node.get_parameter("executor").value
    if kind not in EXECUTORS:
        raise StartupError(f"executor={kind!r} is invalid: valid values are "
                           f"{', '.join(EXECUTORS)}")
    return kind


def make_executor(kind: str = "single_threaded"):
    """A new executor of the given kind (:data:`EXECUTORS`)."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    if kind != "single_threaded":
        raise StartupError(f"executor={kind!r} is invalid: valid values are "
                           f"{', '.join(EXECUTORS)}")
    return SingleThreadedExecutor()


#: Longest wall time an idle executor waits before noticing a signal (seconds): part of
#: every scene's end (issue 30: 0.2 s, 0.1 s of it on average), 20 idle wake-ups a second.
SIGNAL_POLL = 0.05


class _Signals:
    """What the signal handler knows: whether a stop was asked, whether we spin."""

    stop = False
    spinning = False


def _interrupt(signum, frame):
    """SIGINT/SIGTERM: while the node spins, only ask :func:`spin` to stop.

    Raising KeyboardInterrupt from the handler lands in whatever Python code runs next:
    inside a timer's or a subscription's callback the EventsExecutor logs it as
    ``[FATAL] Exception in 'timers' callback`` with a stack (every realtime scene stopped
    by Ctrl-C or --timeout), and an executor that catches it can lose the signal (2 of 12
    scripted SIGINTs, issue 19). Outside the spin (starting up) it still raises, which
    ends the start at once.
    """
    _Signals.stop = True
    if not _Signals.spinning:
        raise KeyboardInterrupt


def spin(executor, done=None) -> None:
    """Spin until ``done()`` is true (or forever), waking at least every SIGNAL_POLL s.

    A SIGINT/SIGTERM (:func:`_interrupt`) ends it between two callbacks, as a
    KeyboardInterrupt raised here, in our code, never inside a callback.
    """
    _Signals.spinning = True
    try:
        while rclpy.ok() and not _Signals.stop and not (done is not None and done()):
            executor.spin_once(timeout_sec=SIGNAL_POLL)
    finally:
        _Signals.spinning = False
    if _Signals.stop:
        raise KeyboardInterrupt


def init_ros(args, name: str):
    """Check the arguments, then ``rclpy.init`` them; StartupError with one line if bad.

    Returns the :class:`NodeArguments`, or None when ``--help`` was asked (the caller
    prints its usage and exits 0).
    """
    from .node_arguments import parse_node_arguments

    arguments = parse_node_arguments(args)
    if arguments.help:
        return None
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:   # rcl: RCLError, UnknownROSArgsError (not exported)
        text = re.sub(r", at \S+:\d+", "", " ".join(str(exc).split()))
        raise StartupError(f"invalid ROS arguments: {text}") from None
    return arguments


#: Environment switches of :func:`settle_heap`: ``GRAZING_GC=keep`` leaves Python's cyclic
#: collector as it is (to measure against), ``GRAZING_GC_PAUSES=1`` logs the collector's
#: pauses per generation at the node's exit (:class:`GcPauses`).
GC_ENV, GC_PAUSES_ENV = "GRAZING_GC", "GRAZING_GC_PAUSES"


class GcPauses:
    """The cyclic collector's pauses in this process, per generation (gc.callbacks), and
    the process's CPU time, from the node's start of spinning to its exit."""

    def __init__(self):
        self.count, self.total, self.max = [0, 0, 0], [0.0] * 3, [0.0] * 3
        self._start = 0.0
        self.cpu0 = time.process_time()
        gc.callbacks.append(self)

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._start = time.perf_counter()
            return
        dt, g = time.perf_counter() - self._start, info["generation"]
        self.count[g] += 1
        self.total[g] += dt
        self.max[g] = max(self.max[g], dt)

    def summary(self) -> str:
        return (f"cpu_s={time.process_time() - self.cpu0:.2f} gc pauses: " + " ".join(
            f"gen{g} n={self.count[g]} total_ms={self.total[g] * 1e3:.1f} "
            f"max_ms={self.max[g] * 1e3:.2f}" for g in range(3)))


def freeze_heap() -> None:
    """Collect, then freeze every object alive now out of the cyclic collector's reach
    (gc.freeze): what start-up made (imports, rclpy, numpy, the scene's models: ~10^5
    objects that live as long as the process) is no longer walked by each full
    collection while the scene runs (docs/rig_scene.md, "Where the time went").
    ``GRAZING_GC=keep`` leaves the collector as it is (to measure against)."""
    if os.environ.get(GC_ENV) != "keep":
        gc.collect()
        gc.freeze()


#: :class:`SafePoints`: the automatic collector's trigger raised to this many net
#: allocations, a fallback for a stretch without a safe point (CPython's default 700).
SAFE_POINT_FALLBACK = 100_000


class SafePoints:
    """The cyclic collector's collections moved to safe points of a node's choosing
    (issue 30: at T/200 x1000 the stream controller's young collections, ~0.1 ms each and
    ~1.2 ms every tenth, fell inside 23 of 1000 section estimates and made the answer
    latency's tail, docs/benchmarks.md "Where the stream's answer went").

    Made, the automatic trigger waits for :data:`SAFE_POINT_FALLBACK` allocations; each
    call (a safe point: the node's answer is out) runs the collection the default
    thresholds (700, 10, 10) would have asked for by now: the youngest generation past
    700 allocations, the older ones each tenth time, as CPython's own policy (gen 2 also
    without its long-lived-objects ratio: after :func:`freeze_heap` it walks only what
    the scene made). Nothing collected is kept longer than a safe point's spacing.
    ``GRAZING_GC=keep`` leaves the collector as it is (to measure against): then a call
    does nothing. :meth:`close` puts the thresholds back once the last of the process's
    SafePoints is closed, in whatever order they close (two controllers in one process:
    the second one read the raised trigger as the default, and closed last, left it
    raised for good)."""

    #: SafePoints of this process not closed yet, and the thresholds before the first.
    _open = 0
    _before = None

    def __init__(self):
        self.active = os.environ.get(GC_ENV) != "keep"
        if not self.active:
            self.thresholds = gc.get_threshold()
            return
        if SafePoints._open == 0:
            SafePoints._before = gc.get_threshold()
        SafePoints._open += 1
        self.thresholds = SafePoints._before
        gc.set_threshold(SAFE_POINT_FALLBACK, *self.thresholds[1:])

    def __call__(self) -> None:
        if not self.active:
            return
        c0, c1, c2 = gc.get_count()
        t0, t1, t2 = self.thresholds
        if c0 <= t0:
            return
        gc.collect(2 if c2 > t2 else 1 if c1 > t1 else 0)      # CPython's choice

    def close(self) -> None:
        """The automatic trigger as it was once no SafePoints of the process is left open
        (a node destroyed in a process that goes on: the collector's thresholds are the
        process's)."""
        if self.active:
            self.active = False
            SafePoints._open -= 1
            if SafePoints._open == 0:
                gc.set_threshold(*self.thresholds)


def settle_heap():
    """Before a node spins: :func:`freeze_heap`; returns the :class:`GcPauses` recorder
    when ``GRAZING_GC_PAUSES`` is set, else None."""
    freeze_heap()
    return GcPauses() if os.environ.get(GC_PAUSES_ENV) else None


def run_node(factory, args=None, name: str = "node", fast_exit: bool = True) -> int:
    """The main of every node: init, build, spin, and a clean exit.

    The command line is checked first (:func:`init_ros`): ``--help`` prints the usage and
    returns 0; a malformed argument or parameter file is one line and exit status 2.
    ``factory()`` builds the node; its optional ``spin_until(executor)`` method spins
    (a node that finishes by itself returns from it), otherwise :func:`spin` spins until
    shutdown. A :class:`StartupError`, a ParameterError or a parameter exception while
    building, or an unknown ``-p`` name (:func:`check_overrides`), is logged in one line
    and gives exit status 2. SIGINT (Ctrl-C) and SIGTERM end the spin
    without a traceback, also while starting: rclpy's own signal handlers are not
    installed, so the context stays valid while the node's ``on_exit()`` logs its summary
    (to /rosout too); a second signal during that cleanup is ignored. Returns the exit
    status, which is the value of ``node.exit_code`` if the node has one. With
    ``fast_exit`` (a node's process: its entry point) the process ends right after the
    summary with ``os._exit`` instead of tearing everything down.
    """
    from .node_arguments import check_overrides, usage

    from grazing_control.oscillator.params import ParameterError

    args = list(sys.argv if args is None else args)
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    node = executor = pauses = None
    code = 0
    try:
        arguments = init_ros(args, name)
        if arguments is None:
            sys.stdout.write(usage(factory, name))
            return 0
        try:
            with warnings.catch_warnings():   # rclpy's own noise after a failed creation
                warnings.filterwarnings("ignore", message="Failed to fini rosout publisher")
                node = factory()
        except RCLError as exc:       # e.g. SROS2 asked of a Fast DDS without security
            text = re.sub(r",? at \S+:\d+", "", " ".join(str(exc).split()))
            raise StartupError(f"the node cannot be created: {text}") from None
        try:
            check_overrides(node, arguments)
        except StartupError:
            node.on_exit = lambda: None      # it never ran: no summary
            raise
        executor = make_executor(getattr(node, "executor_kind", "single_threaded"))
        executor.add_node(node)
        pauses = settle_heap()
        if hasattr(node, "spin_until"):
            node.spin_until(executor)
        else:
            spin(executor)
    except (StartupError, ParameterException, ParameterError) as exc:
        # the node is ending: a stop signal now (a launcher stopping the scene because
        # another node refused to start) must not end the report in a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
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
        if pauses is not None:
            rclpy.logging.get_logger(name).info(pauses.summary())
    # Reached when nothing escaped. The summary is logged and every reliable reader has
    # acknowledged (the nodes' spin_until / on_exit): leave the graph, then end the
    # process without tearing the interpreter down (issue 21: that took up to 30 s under
    # CPU starvation, past the launcher's grace).
    if fast_exit:
        fast_exit_process(code, node, executor)
    if node is not None:
        node.destroy_node()
    rclpy.try_shutdown()
    return code


#: Wall seconds an exiting node waits for its node and DDS participant to be destroyed
#: (:func:`leave_graph`) before it ends the process all the same.
LEAVE_TIMEOUT = 3.0


def leave_graph(node, executor=None, timeout: float = LEAVE_TIMEOUT) -> bool:
    """Destroy ``node`` (or each node of a list: a composed scene's), shut its context
    down and destroy it, so that the peers see it leave at once and nothing of its DDS
    participant is left on the machine.

    Destroying the nodes announces their endpoints' removal, and destroying the context
    deletes its DDS participant, which announces its own. A process that ends through
    ``os._exit`` without it stays in every peer's graph until its participant's lease
    runs out (Fast DDS: 20 s): a controller then counted the exited simulator's
    publisher and a restarted one's, called the scene "not isolated" and exited 1
    (issue 27 §2). And its shared-memory segment stayed in /dev/shm for good: every
    simulator and controller left one (549 KB; 13,000 of them, 6.8 GB of this machine's
    memory, after two days of test suites, issue 30). Runs in a daemon thread, waited
    for ``timeout`` s at most, so that a starved machine still ends the process in time
    (the caller exits either way). Returns whether the teardown finished.
    """
    nodes = list(node) if isinstance(node, (list, tuple)) else [node]

    def teardown():
        try:
            for one in nodes:
                if executor is not None:
                    executor.remove_node(one)
                one.destroy_node()
            context = nodes[0].context
            rclpy.try_shutdown(context=context)
            if executor is not None:
                executor.shutdown(timeout_sec=0.0)
            context.destroy()
        except Exception:  # noqa: BLE001 - leaving anyway: the lease ends what is left
            pass

    worker = threading.Thread(target=teardown, name="leave_graph", daemon=True)
    worker.start()
    worker.join(timeout)
    return not worker.is_alive()


def fast_exit_process(code: int, node=None, executor=None) -> None:
    """End a node's process with status ``code``: leave the graph (:func:`leave_graph`),
    flush the output, ``os._exit``."""
    if node is not None:
        leave_graph(node, executor)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


# ------------------------------------------------------------- parameters at runtime
LIVE_CHANGES_DOC = ("allow parameter changes while the scene runs (each is logged and, "
                    "through the parameter record, recorded); false: read-only once the "
                    "scene has started")


def refuse_while_running(node, params, running: bool):
    """The refusal of a set-parameters request while the scene runs (issue 21 §3), else
    None. Anyone on the domain can call a node's parameter services: a scene's gains and
    model change only when the node was started with ``live_changes:=true``."""
    from rcl_interfaces.msg import SetParametersResult

    if not running or node.get_parameter("live_changes").value:
        return None
    names = ", ".join(p.name for p in params)
    node.get_logger().warning(f"parameter change refused while the scene runs: {names}")
    return SetParametersResult(successful=False, reason=(
        f"{names}: read-only while the scene runs (start the node with live_changes:=true "
        "to allow changes; each is logged and recorded)"))


def log_parameter_changes(node, params) -> None:
    """Log each accepted change, old -> new (the parameter record also records it)."""
    for p in params:
        old = node.get_parameter(p.name).value if node.has_parameter(p.name) else None
        node.get_logger().warning(f"parameter changed: {p.name} {old!r} -> {p.value!r}")


# ------------------------------------------------------------------ parameter record
def publish_parameter_record(node):
    """Publish the node's parameters on ``grazing/parameters``, now and after each change.

    One std_msgs/String (JSON of :func:`grazing_control.ros.recording.record.encode`) on a
    reliable, transient-local, depth-1 publisher, so that a recording describes itself
    (docs/analysis.md, "Parameter record"). Returns the publisher.
    """
    from std_msgs.msg import String

    from grazing_control.ros.recording.record import TOPIC, encode

    pub = node.create_publisher(String, TOPIC, LATCHED_QOS)

    def publish(_changed=None):
        values = {name: p.value for name, p in node.get_parameters_by_prefix("").items()}
        pub.publish(String(data=encode(node.get_fully_qualified_name(), values)))

    node.add_post_set_parameters_callback(publish)
    publish()
    return pub

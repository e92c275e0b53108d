"""sim_node: the impact oscillator of the plant layer, as a ROS 2 node (the adapter only).

The simulation is :mod:`grazing_control.plant` (no ROS): :mod:`~grazing_control.plant.settings`
(the parameter table and its validation), :mod:`~grazing_control.plant.engine` (samples and
periods of the exact flow, as :func:`grazing_control.dynamics.simulation.simulate.simulate`),
:mod:`~grazing_control.plant.lockstep` and :mod:`~grazing_control.plant.realtime` (the
two loops: one period per answer, or paced to the wall clock with deadlines), and
:mod:`~grazing_control.plant.faults` (injected loss, measurement noise, jitter). This
file declares the parameters from :data:`grazing_control.plant.settings.PARAMETERS`,
turns answers into loop calls and the loops' output into messages (packed CDR,
:mod:`grazing_control.ros.cdr`). A lockstep run reproduces ``simulate`` of the same
scene sample for sample (docs/nodes.md).

Topics (docs/nodes.md has every field, unit and QoS): publishes ``oscillator/state`` (the
rig's sensor stream; with ``stream_message`` block ``oscillator/state_block`` instead, a
block per loop call: :mod:`grazing_control.ros.stream_block`), ``oscillator/pi1``, ``/pi2`` (the ground truth), ``/impact``,
``/latency``, ``/deadline_miss``, ``/substituted`` (the prediction that acted for a
missing answer), ``/done``, ``/clock``; stamps are simulation time; ``grazing/parameters``
carries its parameter record and its events (the watchdog's trip, the feasibility
verdict: :mod:`grazing_control.ros.recording.record`). Subscribes
``controller/velocity_correction`` (linear.x = Delta v, linear.y = the predicted next
one, stamp = the Pi2 sample answered). Service ``~/reset``: back to t = 0.

With ``model_file`` (an n-DOF model YAML, docs/ndof_model.md; issue 17) the node simulates
that oscillator (:mod:`grazing_control.plant.ndof_engine`) and publishes every coordinate:
``oscillator/state``, ``/pi1``, ``/pi2`` as JointState with n joints ``mass0`` ..
(docs/nodes.md, "n-DOF scenes").

Run: ``ros2 run grazing_control sim_node --ros-args --params-file config/study.yaml`` or
``python -m sim_node.sim_node --ros-args ...``.
"""

from __future__ import annotations

import math
import threading
import time

from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray, String
from std_srvs.srv import Trigger

from grazing_control.oscillator import kernel
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.feasibility import ROUND_TRIPS, check, sustained_rate
from grazing_control.plant.lockstep import Lockstep
from grazing_control.plant.loop import Loop
from grazing_control.plant.ndof_engine import NdofEngine
from grazing_control.plant.ndof_settings import (UNSUPPORTED, load_model_file,
                                                 ndof_settings_from_values)
from grazing_control.plant.realtime import CLOCK_TICK, MIN_TICK, STREAM_TICK, Realtime
from grazing_control.plant.rig import load_rig
from grazing_control.plant.settings import (PARAMETERS, SETTING_KEYS, Parameter,
                                            check_live_change, described_range,
                                            settings_from_values)
from grazing_control.ros import cdr, stream_block
from grazing_control.ros.diagnostics import ERROR, WARN, SceneWindow, Updater
from grazing_control.ros.published import (ACK_TIMEOUT, Counted, PublishedRecord,
                                          close_publishers)
from grazing_control.ros.recording.record import TOPIC as RECORD_TOPIC
from grazing_control.ros.recording.record import encode_event
from grazing_control.ros.common import (DATA_QOS, EVENT_QOS, EXECUTORS, LATCHED_QOS,
                                        LIVE_CHANGES_DOC, PUBLISHER_QOS, READY_TOPIC,
                                        StartupError, bool_descriptor, check_ranges,
                                        deserialize, executor_kind, float_descriptor,
                                        freeze_heap,
                                        int_descriptor, log_parameter_changes,
                                        publish_parameter_record, refuse_out_of_range,
                                        refuse_while_running, run_node, spin, stamp_key,
                                        string_descriptor)
from grazing_control.ros.rig_boundary import check_rig_values, sim_values
from grazing_control.ros.scene import SCENE_PARAMETER_DOC, SceneGuard
from grazing_control.ros.scheduling import apply_node_scheduling

from sim_node.answer_port import AnswerPort
from sim_node.messages import Outputs, read_answer
from sim_node.probe import RoundTrips, controller_name
from sim_node.rig_io import SimulatedRig

__all__ = ["SimNode", "main"]

#: Wall seconds between two checks for another simulator or controller on the topics.
ISOLATION_CHECK = 0.25
#: The wait at exit for the readers' acknowledgements (published.ACK_TIMEOUT, 10 s, after
#: the scene) when stopped by a signal before the end (the launcher's grace is 15 s).
INTERRUPTED_ACK_TIMEOUT = 2.0
#: Realtime: /clock goes out at a wake-up at most every this many wall seconds (and at
#: least every CLOCK_TICK of the loop); one per wake-up was one message per stream sample.
CLOCK_EVERY = 1e-3
#: Wall seconds the round trips to the controller before a realtime start may take.
PROBE_TIMEOUT = 5.0
#: No default QoS-event handlers on the data publishers: each one is one more entity in
#: every executor wait (measured: about 10 % of the lockstep rate).
_NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)

#: An n-DOF scene (issue 17): declared first, its model gives delta_d's default.
MODEL_FILE = Parameter("model_file", "string", "", "path of an n-DOF model YAML file "
                       "(docs/ndof_model.md): simulate it and publish every coordinate "
                       "(JointState with n joints); '' = the study's 1-DOF oscillator",
                       read_only=True)

#: A simulated rig in SI (issue 28, sim_node/rig_io.py): declared first, its rig file
#: gives the simulation's defaults (plant.rig.Rig.dimensionless).
RIG_FILE = Parameter("rig_file", "string", "", "path of a rig file (docs/rig.md): simulate "
                     "that rig at physical speed and speak the driver contract in SI "
                     "(docs/driver_contract.md: rig/sensor, rig/phase, rig/clock, "
                     "rig/applied, grazing/rig; answers on rig/force_pulse); '' = the "
                     "dimensionless scene", read_only=True)
#: The simulated rig's clock against ROS time (rig_boundary.SimulatedClock).
RIG_CLOCK = (
    Parameter("clock_start", "double", 1000.0, "rig_file: the rig clock's reading (s) when "
              "the scene starts (snapped to the next Pi2 section): a DAQ that has been "
              "running, so its clock is offset from ROS time", 0.0, 1e9, read_only=True),
    Parameter("clock_drift", "double", 5e-5, "rig_file: the rig clock's drift against ROS "
              "time (ROS s per rig s, less 1; 5e-5: 50 ppm): the default time_scale is "
              "omega_n / (1 + clock_drift)", -0.01, 0.01, read_only=True),
    Parameter("clock_rate", "double", 20.0, "rig_file: rig/clock messages per wall second, "
              "10..1000", 10.0, 1000.0, read_only=True),
)

#: The node's own parameters (how it starts and spins), after the simulation's.
NODE_PARAMETERS = (
    MODEL_FILE,
    RIG_FILE,
    *RIG_CLOCK,
    Parameter("executor", "string", "events", "rclpy executor: single_threaded "
              "(SingleThreadedExecutor) or events (rclpy.experimental EventsExecutor)",
              choices=EXECUTORS, read_only=True),
    Parameter("stream_block", "double", STREAM_TICK, "realtime: wall seconds the stream's "
              "samples (oscillator/state, rig/sensor) gather before one wake-up publishes "
              "them, each with its own stamp: a DAQ's block (5e-5..5e-3)", MIN_TICK,
              CLOCK_TICK, read_only=True),
    Parameter("stream_message", "string", "sample", "the state stream's messages: sample (one "
              "JointState per sample on oscillator/state) or block (the samples of a wake-up "
              "in one Float64MultiArray on oscillator/state_block, as a DAQ driver "
              "publishes; ros/stream_block.py; 1-DOF only)", choices=stream_block.MESSAGES,
              read_only=True),
    Parameter("exit_when_done", "bool", False, "exit (status 0) once max_periods have run",
              read_only=True),
    Parameter("wait_for_controller", "bool", True, "start only when a controller is matched "
              "on oscillator/pi2 and controller/velocity_correction", read_only=True),
    Parameter("wait_for_subscribers", "integer", 0, "start only when every data topic has "
              "this many other subscribers (a recorder: 1)", 0, 100, read_only=True),
    Parameter("wait_for_recorder", "bool", False, "start only when recorder_node says it has "
              f"matched every topic ({READY_TOPIC}); grazing run sets it when it records",
              read_only=True),
    Parameter("scene", "string", "", SCENE_PARAMETER_DOC, read_only=True),
    Parameter("live_changes", "bool", False, LIVE_CHANGES_DOC, read_only=True),
    Parameter("history_depth", "integer", 100_000, "keep-last depth of each data publisher: "
              "the backlog a reliable reader may fall behind without loss, and the bound of "
              "the memory a slow reader can hold (about 1 kB per unacknowledged message per "
              "topic; docs/nodes.md, QoS)", 100, 1_000_000, read_only=True),
    Parameter("diagnostics_period", "double", 1.0, "wall seconds between /diagnostics "
              "messages (grazing_control.ros.diagnostics); 0 = none", 0.0, 3600.0,
              read_only=True),
    Parameter("diag_misses_warn", "integer", 1, "/diagnostics WARN from this many missed, "
              "timed-out or lost corrections in one diagnostics period (0 = off)", 0),
    Parameter("diag_misses_error", "integer", 10, "/diagnostics ERROR from this many (0 = off)",
              0),
    Parameter("diag_latency_warn", "double", 0.005, "/diagnostics WARN from this latency "
              "p99 over one period, wall seconds (realtime; 0 = off)", 0.0),
    Parameter("diag_latency_error", "double", 0.05, "/diagnostics ERROR from this latency "
              "p99, wall seconds (0 = off)", 0.0),
    Parameter("diag_pace_warn", "double", 0.9, "/diagnostics WARN when realtime runs slower "
              "than this fraction of time_scale (0 = off)", 0.0, 1.0),
    Parameter("verdict_file", "string", "", "write how the scene ended (exit status, "
              "reason, summary, watchdog trip, feasibility verdict) as one JSON object to "
              "this file at exit; grazing run reads it ('' = none)", read_only=True),
    Parameter("start_timeout", "double", 30.0, "wall seconds to wait for the above, then "
              "start anyway (with a warning)", 0.0, read_only=True),
    Parameter("thread_priority", "integer", 0, "real-time scheduling: SCHED_FIFO priority "
              "1..99 of the process, 0 = off (a warning where not permitted)", 0, 99,
              read_only=True),
    Parameter("cpu_affinity", "string", "", "real-time scheduling: CPUs to run on, e.g. "
              "'2' or '0,2-3'; '' = any", read_only=True),
    Parameter("lock_memory", "bool", False, "real-time scheduling: lock the process's memory "
              "(mlockall; a warning where not permitted)", read_only=True),
)


#: The simulator is the source of /clock: it never follows it (issue 27: a third party's
#: use_sim_time:=true froze a realtime scene, its timers waiting for its own /clock).
SIM_TIME_REFUSED = ("use_sim_time=true is invalid for sim_node: valid is false only (the "
                    "simulator publishes /clock; on simulation time its own timers would "
                    "wait for it)")


def check_rig_scene(rig_file: str, rig_values: dict, values: dict) -> None:
    """A rig scene's parameters are the rig file's, time_scale (a faster scene) and
    pre_roll excepted (rig_boundary.check_rig_values); its mode is realtime (the rig's clock runs)."""
    if not rig_values:
        return
    check_rig_values(rig_file, rig_values, values, free=("time_scale", "pre_roll"))
    if values["mode"] != "realtime":
        raise ParameterError(f"mode={values['mode']!r} is invalid with rig_file={rig_file}: "
                             "valid is realtime (a rig's clock runs)")


def descriptor(p: Parameter, declared: dict | None = None):
    """The ROS descriptor of one parameter of the table (type, range, choices, read-only);
    ``declared``: the values declared before it, which bound some ranges
    (:func:`grazing_control.plant.settings.described_range`)."""
    if p.kind == "double":
        lo, hi = described_range(p, declared or {})
        return float_descriptor(p.doc, lo, hi, p.read_only, p.constraints)
    if p.kind == "integer":
        return int_descriptor(p.doc, p.lo, p.hi, p.read_only, p.constraints)
    if p.kind == "string":
        return string_descriptor(p.doc, p.read_only, p.choices)
    return bool_descriptor(p.doc, p.read_only)


class SimNode(Node):
    """The simulator node (module docstring: topics; docs/nodes.md: modes, parameters)."""

    def __init__(self, **kwargs):
        super().__init__("sim_node", **kwargs)
        self.model_file = self.declare_parameter(MODEL_FILE.name, MODEL_FILE.default,
                                                  descriptor(MODEL_FILE)).value
        self.model = None            # the n-DOF model file's model (issue 17), or None
        if self.model_file:
            try:
                self.model = load_model_file(self.model_file)
            except ParameterError as exc:
                raise StartupError(str(exc)) from None
        self.rig, rig_values = self._declare_rig()
        declared = {}
        for p in PARAMETERS + NODE_PARAMETERS:
            if p is MODEL_FILE or p is RIG_FILE or p in RIG_CLOCK:
                continue
            default = p.default     # with a model file, delta_d defaults to the file's
            if p.name == "delta_d" and self.model is not None:
                default = self.model.delta_d
            default = rig_values.get(p.name, default)     # with a rig file, the rig's
            declared[p.name] = self.declare_parameter(
                p.name, default, self._descriptor(p, declared)).value
        self.set_descriptor("use_sim_time", bool_descriptor(
            "follow /clock (rclpy's parameter)", constraints="false only: sim_node "
            "publishes /clock"))
        if self.get_parameter("use_sim_time").value:
            raise StartupError(SIM_TIME_REFUSED)
        check_ranges(self)
        why = stream_block.check_message(self.get_parameter("stream_message").value)
        if why is not None:
            raise StartupError(why)
        if self.model is not None and self.get_parameter("stream_message").value == "block":
            raise StartupError(f"stream_message='block' is invalid with model_file="
                               f"{self.model_file!r}: valid value there is 'sample' (the "
                               "stream's blocks carry a 1-DOF state)")
        try:
            check_rig_scene(self.rig_file, rig_values, self._values())
            self.settings = self._validate(self._values())
            apply_node_scheduling(self)
        except (ParameterError, ValueError) as exc:
            raise StartupError(str(exc)) from None
        self.engine = (Engine if self.model is None else NdofEngine)(self.settings)
        self.exit_when_done = self.get_parameter("exit_when_done").value
        self._strays = set()          # (topic, node) of bystander publishers, logged once
        self.exit_code = 0
        self.exit_now = False

        qos = QoSProfile(history=PUBLISHER_QOS.history, reliability=PUBLISHER_QOS.reliability,
                         durability=PUBLISHER_QOS.durability,
                         depth=self.get_parameter("history_depth").value)

        def publisher(kind, topic):     # counted: the published record at exit (issue 27)
            return Counted(self.create_publisher(kind, topic, qos, event_callbacks=_NO_EVENTS))

        (self.pub_state, self.pub_impact, self.pub_pi1, self.pub_pi2, self.pub_clock,
         self.pub_latency, self.pub_miss) = (publisher(kind, topic) for kind, topic in (
             (JointState, "oscillator/state"), (Vector3Stamped, "oscillator/impact"),
             (JointState, "oscillator/pi1"), (JointState, "oscillator/pi2"), (Clock, "/clock"),
             (Float64, "oscillator/latency"), (Vector3Stamped, "oscillator/deadline_miss")))
        self.pub_substituted = publisher(TwistStamped, "oscillator/substituted")
        # the stream in blocks (issue 30): created in both modes, as the recorder records it
        self.pub_state_block = publisher(Float64MultiArray, stream_block.TOPIC)
        self.pub_done = self.create_publisher(Bool, "oscillator/done", LATCHED_QOS)
        self.driver = None            # the simulated rig's side of the contract (rig_file)
        if self.rig is not None:
            self.driver = SimulatedRig(self, self.rig, publisher,
                                    self.get_parameter("clock_start").value,
                                    self.get_parameter("clock_rate").value)
        self.published = PublishedRecord(self, (
            self.pub_state, self.pub_impact, self.pub_pi1, self.pub_pi2, self.pub_clock,
            self.pub_latency, self.pub_miss, self.pub_substituted, self.pub_state_block)
            + (self.driver.publishers if self.driver else ()))
        # the answers: the correction, or a rig's scheduled force pulse (docs/driver_contract.md);
        # scheduled realtime takes them at each wake-up, judged by their arrival (answer_port)
        kind, topic, callback = ((TwistStamped, "controller/velocity_correction",
                                  self._on_correction) if self.driver is None else
                                 (WrenchStamped, "rig/force_pulse", self._on_force_pulse))
        events = SubscriptionEventCallbacks(use_default_callbacks=False)
        self.port = None
        if self.settings.mode == "realtime" and self.settings.scheduled:
            self.port = self.sub_correction = AnswerPort(self, kind, topic, DATA_QOS, events)
        else:
            self.sub_correction = self.create_subscription(kind, topic, callback, DATA_QOS,
                                                           raw=True, event_callbacks=events)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._recorder_ready = False
        if self.get_parameter("wait_for_recorder").value:
            self.create_subscription(Bool, READY_TOPIC, self._on_recorder_ready, LATCHED_QOS)
        self.pub_parameters = publish_parameter_record(self)   # grazing/parameters
        # the scene's events on the same topic (record.encode_event): watchdog, feasibility
        self.pub_events = self.create_publisher(String, RECORD_TOPIC, EVENT_QOS)
        self.trip = None              # the watchdog's Trip, once tripped
        self.feasibility = None       # the check before a realtime start (Verdict)
        self.reason = None            # why the scene failed, in one line
        self._probe = False           # False: not started; None: no controller; RoundTrips
        self._probe_start = 0.0
        # compile, or load numba's cache (0.5-0.8 s), while the peers are discovered and
        # the start conditions settle, not in the first period (issue 30)
        self._warming = None
        if kernel.use_kernel():
            self._warming = threading.Thread(target=kernel.warm_up, name="kernel_warm_up",
                                             daemon=True)
            self._warming.start()
        self._summary = None          # the summary line logged when the scene ended
        self.scene = SceneGuard(self, self.get_parameter("scene").value)
        self._start_timer = self.create_timer(0.02, self._try_start)
        self._isolation_timer = self.create_timer(ISOLATION_CHECK, self._check_isolation)
        self._tick_timer = None
        self.out = Outputs(self)
        self.diagnostics = Updater(self, self.get_parameter("diagnostics_period").value)
        self._window = SceneWindow()
        self.diagnostics.add("scene", self._diagnose)
        self.executor_kind = executor_kind(self)
        self.loop = None              # the Lockstep or Realtime loop, once started
        self._finished = False        # refused to start, or failed
        self._created = time.monotonic()
        self._wall_start = None
        self._ready_since = None
        self._clock_wall = -math.inf   # wall time of the last /clock (realtime)
        self.get_logger().info(f"{self.settings.describe()} executor={self.executor_kind}")

    def _declare_rig(self):
        """Declare rig_file and the rig clock's parameters; (the Rig or None, the
        simulation's values the rig file sets: rig_boundary.sim_values)."""
        self.rig_file = self.declare_parameter(RIG_FILE.name, RIG_FILE.default,
                                               descriptor(RIG_FILE)).value
        for p in RIG_CLOCK:
            self.declare_parameter(p.name, p.default, descriptor(p))
        if not self.rig_file:
            return None, {}
        if self.model is not None:
            raise StartupError(f"rig_file={self.rig_file} is invalid with model_file: a rig "
                               "file describes a 1-DOF rig; give one of them")
        try:
            rig = load_rig(self.rig_file)
        except ParameterError as exc:
            raise StartupError(str(exc)) from None
        try:
            return rig, sim_values(rig, self.get_parameter("clock_drift").value)
        except ParameterError as exc:
            raise StartupError(f"{self.rig_file}: {exc}") from None

    def _descriptor(self, p: Parameter, declared: dict):
        """:func:`descriptor`; in an n-DOF scene with the model's forcing frequency (its
        times are bounded by its period), and a parameter it does not build states that
        only its default is valid (plant.ndof_settings.UNSUPPORTED; the range stays, so
        that a refusal says why: "zeta=0.02 is invalid with model_file=...")."""
        if self.model is None:
            return descriptor(p, declared)
        d = descriptor(p, {**declared, "omega": self.model.omega})
        if p.name in UNSUPPORTED:
            d.additional_constraints = (f"only its default {p.default!r} with model_file "
                                        f"({UNSUPPORTED[p.name]})")
        return d

    def _values(self) -> dict:
        return {k: self.get_parameter(k).value for k in SETTING_KEYS}

    def _validate(self, values: dict):
        """The settings of ``values``: the 1-DOF scene's, or with ``model_file`` the
        n-DOF scene's (plant.ndof_settings); ParameterError naming a bad value."""
        if self.model is None:
            return settings_from_values(values)
        return ndof_settings_from_values(values, self.model_file, self.model)

    @property
    def running(self) -> bool:
        """Started and neither done nor failed."""
        return self.loop is not None and not self.loop.finished and not self._finished

    # ------------------------------------------------------------------ start
    def _on_recorder_ready(self, msg: Bool) -> None:
        self._recorder_ready = bool(msg.data)

    def _intruders(self) -> list:
        """Other simulators or controllers on this scene's topics.

        A simulator or a controller of this package publishes its parameter record
        (``grazing/parameters``): only publishers whose node does count. Any other
        publisher on the scene's topics (a stray ``ros2 topic pub --once``) is a bystander:
        logged once, its messages counted as ignored (or malformed) like any input that
        answers no waiting sample, and the scene goes on (issue 19 §4).
        """
        found = []
        nodes = {(i.node_namespace, i.node_name) for i in
                 self.get_publishers_info_by_topic(self.resolve_topic_name(RECORD_TOPIC))}
        for topic, what, own in ((self.pub_pi2.topic_name, "another simulator", 1),
                                 (self.sub_correction.topic_name, "more than one controller",
                                  0)):
            infos = self.get_publishers_info_by_topic(topic)
            ours = [i for i in infos if (i.node_namespace, i.node_name) in nodes]
            if len(ours) > 1:
                found.append(f"{len(ours) - own} other publisher(s) of this package on "
                             f"{topic} ({what})" if own else
                             f"{len(ours)} controllers publish on {topic} ({what})")
            if self.loop is None:        # a controller's record may not be discovered yet
                continue
            strays = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos
                            if (i.node_namespace, i.node_name) not in nodes
                            and i.node_name != self.get_name())
            for name in strays:
                if (topic, name) not in self._strays:
                    self._strays.add((topic, name))
                    self.get_logger().warning(
                        f"a publisher that is not a node of this package on {topic}: "
                        f"{name} (a bystander: its messages are counted, the scene goes on)")
        return found + self.scene.intruders()

    def _check_isolation(self) -> None:
        """Refuse to start, or stop, when another scene shares this one's topics.

        Two simulators (or two controllers) on the same topics corrupt each other's
        samples, answers and recordings: the scene is stopped with an error (exit status
        1) instead of reporting success. Checked every ISOLATION_CHECK wall seconds.
        """
        if self._finished or (self.loop is not None and self.loop.finished):
            return
        found = self._intruders()
        why = self.scene.delay_mismatch(self.settings.actuation_delay)
        if why is None and found:
            why = (f"{'; '.join(found)}: the scene is not isolated (another scene on this "
                   "ROS_DOMAIN_ID and namespace?)")
        if why is not None:
            if self.loop is None:
                self.reason = f"not starting: {why}"
                self.get_logger().error(f"not starting: {why}")
                self.exit_code = 1
                self._finished = True
                self.exit_now = True
                self.destroy_timer(self._start_timer)
            else:
                self._fail(RuntimeError(why))
            return
        if (self.loop is not None and self._recorder_ready
                and self.get_parameter("wait_for_recorder").value
                and self.count_publishers(self.resolve_topic_name(READY_TOPIC)) == 0):
            # the recorder that matched every topic before the start has left the graph
            self._fail(RuntimeError("the recorder (recorder/ready) has gone: the scene's "
                                    "recording is lost (recorder_node killed?)"))

    def _missing(self) -> list:
        """What the start still waits for, one phrase per missing peer ([]: ready).

        The conditions (docs/nodes.md, "Start handshake"): with ``wait_for_recorder`` the
        recorder's ``recorder/ready``; with ``wait_for_controller`` a controller
        subscribed to the samples (Pi2 or the stream) and publishing corrections and,
        with a scene token, the parameter record of a controller of this scene; with
        ``wait_for_subscribers`` n, n subscribers (besides the controller) on every data
        topic of this scene. A scene that refuses to start (another scene's node, a
        controller designed for another delay) is :meth:`_check_isolation`'s.
        """
        refused = self._intruders() + [why for why in (
            self.scene.delay_mismatch(self.settings.actuation_delay),) if why]
        if refused:                          # _check_isolation refuses to start
            return refused
        missing = []
        if self.get_parameter("wait_for_recorder").value and not self._recorder_ready:
            missing.append(f"the recorder's True on {self.resolve_topic_name(READY_TOPIC)} "
                           "(recorder_node not running, or not matched to every topic yet)")
        n = self.get_parameter("wait_for_subscribers").value
        if self.get_parameter("wait_for_controller").value:
            samples = max(self.pub_pi2.get_subscription_count(),    # a controller reads
                          self.pub_state.get_subscription_count(),  # Pi2 or the stream
                          self.pub_state_block.get_subscription_count())
            if self.driver is not None:         # a rig's controller: the SI stream, phase
                samples = min(self.driver.pub_sensor.get_subscription_count(),
                              self.driver.pub_phase.get_subscription_count())
            if samples < n + 1:
                topics = (f"{self.pub_pi2.topic_name} or {self.pub_state.topic_name}"
                          if self.driver is None else
                          f"{self.driver.pub_sensor.topic_name} and "
                          f"{self.driver.pub_phase.topic_name}")
                missing.append(f"the controller{f' and {n} recorder(s)' if n else ''} "
                               f"subscribed to {topics} ({samples} subscriber(s) of {n + 1})")
            if self.sub_correction.get_publisher_count() < 1:
                missing.append(f"a controller publishing {self.sub_correction.topic_name}")
            why = self.scene.missing_controller()
            if why is not None:
                missing.append(why)
        if n > 0:
            pubs = [self.pub_impact, self.pub_pi1, self.pub_pi2, self.pub_clock]
            if self.settings.state_period > 0.0:
                pubs.append(self.pub_state if self.out.block is None else self.pub_state_block)
            if self.settings.mode == "realtime":     # the latency of every sample is recorded
                pubs.append(self.pub_latency)
            if self.driver is not None:
                pubs.extend(self.driver.publishers)
            for pub in pubs:
                have = pub.get_subscription_count()
                if have < n:
                    missing.append(f"a subscriber of {pub.topic_name} ({have} of {n})")
            topic = self.sub_correction.topic_name
            have = self.count_subscribers(topic)
            if have < n + 1:
                missing.append(f"a recorder subscribed to {topic} ({have} subscriber(s) of "
                               f"{n + 1}, this node's own included)")
        return missing

    def _try_start(self) -> None:
        waited = time.monotonic() - self._created
        loading = self._warming is not None and self._warming.is_alive()   # the kernel
        missing = self._missing()
        if missing:
            self._ready_since = None
            if waited < self.get_parameter("start_timeout").value or loading:
                return
            self.get_logger().warning(
                f"starting after start_timeout={waited:.1f} s without: {'; '.join(missing)}")
        elif self._ready_since is None:
            self._ready_since = time.monotonic()   # let both ends of every match settle
            return
        elif time.monotonic() - self._ready_since < 0.2:
            return
        if loading:
            return
        if self._warming is not None:
            self._warming = None
            kernel.warm_up()            # at once when loaded; raises what the load raised
        if not self._feasible():
            return
        if not missing:
            self.get_logger().info(f"start conditions met after {waited:.1f} s: starting")
        self.destroy_timer(self._start_timer)
        freeze_heap()       # what start-up made (the warmed kernel, the scene): out of reach
        self._wall_start = time.monotonic()
        if self.settings.mode == "lockstep":
            self.loop = Lockstep(self.engine, self.out)
            self.create_timer(min(0.25, self.settings.answer_timeout / 4.0),
                              lambda: self._guard(self.loop.check_timeout))
            self._guard(self.loop.start)
        else:
            self.loop = Realtime(self.engine, self.out)
            self.loop.stream_tick = self.get_parameter("stream_block").value
            self._tick_timer = self.create_timer(MIN_TICK, self._on_tick)
            self._guard(self.loop.start)
            if self.driver is not None:
                self.driver.started()

    def _feasible(self) -> bool:
        """Realtime: the check before the start (plant.feasibility); True when the scene
        may start now, False while the round trips are measured or when it is refused.

        The controller's round trips (sim_node.probe) while nothing of the scene is
        published, then the simulation rate of a copy of the engine with every event
        serialised; the verdict is logged, published as an event record, and with
        ``feasibility`` refuse an infeasible scene ends here with exit status 2."""
        s = self.settings
        if s.mode != "realtime" or s.feasibility == "off" or self.feasibility is not None:
            return True
        if self._probe is False:     # the controller of this package answering, if any
            nodes = {(i.node_namespace, i.node_name) for i in
                     self.get_publishers_info_by_topic(self.resolve_topic_name(RECORD_TOPIC))}
            target = controller_name(self, self.sub_correction.topic_name, nodes)
            self._probe = (RoundTrips(self, target, ROUND_TRIPS, PROBE_TIMEOUT)
                           if target else None)
            self._probe_start = time.monotonic()
        probe = self._probe
        if probe is not None and not probe.poll():
            return False
        period = self.engine.p.period
        sustained, _ = sustained_rate(type(self.engine)(s), self.out.serialise)
        waited = time.monotonic() - self._probe_start
        note = None
        if probe is None:
            note = "no controller of this package found: its round trip is not measured"
        elif not probe.asked:
            note = (f"the controller's get_parameters service did not appear in "
                    f"{waited:.3g} s: its round trip is not measured")
        verdict = check(s, period, probe.times if probe else (), sustained,
                        probe.asked if probe else 0, waited, note)
        self.feasibility = verdict
        self._event("feasibility", level=verdict.level, line=verdict.line, **verdict.numbers)
        log = self.get_logger()
        if verdict.level == "refuse" and s.feasibility == "refuse":
            self.reason = verdict.line
            log.error(f"not starting: {verdict.line} (feasibility:=warn starts anyway)")
            self.exit_code = 2
            self._finished = True
            self.exit_now = True
            self.destroy_timer(self._start_timer)
            return False
        (log.info if verdict.level == "ok" else log.warning)(verdict.line)
        return True

    def _event(self, event: str, **fields) -> None:
        """Publish one event record on grazing/parameters (recorded with the scene)."""
        self.pub_events.publish(String(data=encode_event(
            self.get_fully_qualified_name(), event, **fields)))

    def on_trip(self, trip) -> None:
        """The watchdog tripped (the loop has stopped actuating; the scene ends next):
        an error naming the reason, exit status 1, an event record, /diagnostics now."""
        self.trip = trip
        if self.driver is not None:       # rig/applied: the safe state at its section
            self.driver.tripped(trip.k)
        self.reason = f"watchdog ({trip.kind}): {trip.reason}"
        self.exit_code = 1
        self.get_logger().error(
            f"watchdog tripped at sample {trip.k} (t={trip.t:.9g}): {trip.reason}; no "
            "correction acts from now on (safe state) and the scene ends")
        self._event("watchdog", kind=trip.kind, k=trip.k, t=trip.t, reason=trip.reason)
        self.diagnostics.force_update()

    # ---------------------------------------------------------------- answers, time
    def _on_correction(self, data: bytes, arrived: float | None = None) -> None:
        """A correction as received (serialized): the controller's layout is read directly
        (:func:`read_answer`), any other TwistStamped through rclpy; ``arrived``: when the
        middleware received it (scheduled realtime, :mod:`sim_node.answer_port`)."""
        answer = read_answer(data)
        if answer is None:
            msg = deserialize(data, TwistStamped, self.out.malformed)
            if msg is None:
                return
            answer = (stamp_key(msg.header.stamp), msg.twist.linear.x, msg.twist.linear.y)
        key, dv, predicted = answer
        if not math.isfinite(dv):
            self.out.malformed(f"dv={dv!r} for stamp {key}")
            return
        if not self.running:
            self.out.ignored(f"stamp {key}: the scene is not running")
            return
        if (self._guard(self.loop.answer, key, dv, predicted, arrived)
                and self._tick_timer is not None):
            self._arm(self.loop.now())       # a split may have brought an event forward

    def _on_force_pulse(self, data: bytes, arrived: float | None = None) -> None:
        """A rig/force_pulse (rig_file): the answer of its section, as a correction."""
        answer = self.driver.answer(data)
        if answer is None:
            return
        if not self.running:
            self.out.ignored(f"stamp {answer[0]}: the scene is not running")
            return
        rearm = self._guard(self.loop.answer, *answer, arrived)
        if rearm and self._tick_timer is not None:
            self._arm(self.loop.now())

    def take_answers(self) -> None:
        """Scheduled realtime: the answers waiting at the port, each judged at its arrival."""
        take = self._on_correction if self.driver is None else self._on_force_pulse
        for data, arrived in self.port.take():
            take(data, arrived)

    def stop_answers(self) -> None:
        """No more answers taken (the scene is over): the subscription's end announced."""
        if self.port is not None:
            self.port.destroy()
        else:
            self.destroy_subscription(self.sub_correction)

    def _on_tick(self) -> None:
        """Realtime wake-up: the answers that arrived, then what is due, /clock, and sleep
        until the next event."""
        if not self.running:
            return
        wall = None
        if self.port is not None:       # what arrived by now, then what is due by now
            wall = self.loop.clock()
            self.take_answers()
            if not self.running:
                return
        now = self._guard(self.loop.tick, wall)
        if self.driver is not None and now is not None:
            self.driver.flush(now)
        if now is not None and self.running:
            wall = time.monotonic()
            if wall - self._clock_wall >= CLOCK_EVERY:     # /clock at most every 1 ms
                self._clock_wall = wall
                self.pub_clock.publish(cdr.clock(*cdr.stamp_parts(now)))
            self._arm(now)

    def _arm(self, now: float) -> None:
        wake = self.loop.wake_in(now)
        if self.driver is not None:     # a sensor sample whose latency ends sooner
            wake = min(wake, self.driver.wake_in(now))
        self._tick_timer.timer_period_ns = int(wake * 1e9)
        self._tick_timer.reset()

    def _guard(self, call, *args):
        """Run a loop call; a refusal of the core (impact cap, state beyond the wall)
        stops the scene with exit status 1 instead of crashing the node."""
        if not self.running:
            return None
        try:
            return call(*args)
        except Exception as exc:
            self._fail(exc)
            return None
        finally:
            self.out.end_of_wake_up()     # the stream's block, with stream_message block

    # ------------------------------------------------------------ end, failure
    def finish(self) -> None:
        """max_periods have run: oscillator/done, the summary, exit if asked."""
        self.pub_done.publish(Bool(data=True))
        self._summary = self.summary()      # the wall time of the scene, not of the exit
        self.get_logger().info(self._summary)
        if self.exit_when_done:
            self.exit_now = True

    def _fail(self, exc: Exception) -> None:
        self.reason = self.reason or f"simulation stopped at t={self.engine.t:.9g}: {exc}"
        self.get_logger().error(f"simulation stopped at t={self.engine.t:.9g}: {exc}")
        self.exit_code = 1
        self._finished = True
        self.exit_now = True

    def _diagnose(self, stat):
        """The scene's diagnostics task (ros.diagnostics.SceneWindow), thresholds read now
        (they may change while the scene runs)."""
        out = self.out
        counts = {"missed": out.misses.count, "timeouts": out.timeout.count,
                  "ignored": out.ignored.count, "malformed": out.malformed.count}
        th = {k: self.get_parameter(f"diag_{k}").value for k in
              ("misses_warn", "misses_error", "latency_warn", "latency_error", "pace_warn")}
        stat = self._window.status(stat, self.loop, counts, time.monotonic(), th,
                                   self.settings.mode == "realtime", self.settings.time_scale)
        if self.feasibility is not None:
            stat.add("feasibility", self.feasibility.level)
        if self.trip is not None:
            stat.add("watchdog", self.trip.kind)
            stat.merge_summary(ERROR, f"watchdog tripped at sample {self.trip.k}: "
                                      f"{self.trip.reason}; not actuating")
        elif self.feasibility is not None and self.feasibility.level == "refuse":
            # refused: the node ends with status 2; started anyway (feasibility:=warn): a
            # warning, as asked, until the watchdog says what it cost
            warned = self.get_parameter("feasibility").value == "warn"
            stat.merge_summary(WARN if warned else ERROR, self.feasibility.line)
        return stat

    def summary(self) -> str:
        """One line: periods, impacts, corrections, ignored input, rate, latency."""
        wall = time.monotonic() - self._wall_start if self._wall_start else 0.0
        out = self.out
        counts = {"missed": out.misses.count, "timeouts": out.timeout.count,
                  "ignored": out.ignored.count, "malformed": out.malformed.count}
        text = (self.loop or Loop(self.engine, out)).summary(wall, counts)
        return text + (self.driver.summary() if self.driver is not None else "")

    def spin_until(self, executor) -> None:
        """Spin until shutdown, or until done when exit_when_done.

        After the scene: stop listening for corrections (the subscription's end is
        announced, so the controller does not wait for this reader's acknowledgements
        once it has gone), publish the published record (:mod:`grazing_control.ros.
        published`) and wait (ACK_TIMEOUT s at most in all) until every reliable reader
        has acknowledged every message: a reader that lagged behind (a recorder) gets the
        rest from the publishers' history, not from a dead process.
        """
        spin(executor, lambda: self.exit_now)
        if self.exit_now:
            self.stop_answers()
            close_publishers(self.published, ACK_TIMEOUT, also=(self.pub_done,))

    def on_exit(self) -> None:
        """Log the summary when stopped before the end (Ctrl-C), say what was published
        (a recorder checks the bag's tail with it) and write ``verdict_file``."""
        if self.loop is None or not self.loop.finished:
            self.get_logger().info(self.summary() + " (interrupted)")
        if not self.published.sent:
            close_publishers(self.published, INTERRUPTED_ACK_TIMEOUT)
        path = self.get_parameter("verdict_file").value
        if path:
            write_verdict(path, self.verdict())

    def verdict(self) -> dict:
        """How the scene ended, for ``verdict_file`` (grazing run's JSON)."""
        trip, fe = self.trip, self.feasibility
        return {"node": self.get_fully_qualified_name(), "status": self.exit_code,
                "finished": bool(self.loop is not None and self.loop.finished),
                "reason": self.reason, "summary": self._summary or self.summary(),
                "watchdog": None if trip is None else trip._asdict(),
                "feasibility": None if fe is None else {"level": fe.level, "line": fe.line,
                                                        **fe.numbers}}

    # ----------------------------------------------------------- services, params
    def _on_reset(self, request, response):
        ev = self.engine.reset()
        response.success = True
        response.message = "reset to the initial state, sample 0 at t=0"
        self.get_logger().info(response.message)
        if self.loop is not None:
            self._finished = False
            self.loop.finished = False
            self._guard(self.loop.reset, ev)
        return response

    def _on_set_parameters(self, params) -> SetParametersResult:
        refused = refuse_out_of_range(self, params)
        if refused is not None:
            return refused
        if any(p.name == "use_sim_time" and p.value for p in params):
            self.get_logger().warning(f"parameter change refused: {SIM_TIME_REFUSED}")
            return SetParametersResult(successful=False, reason=SIM_TIME_REFUSED)
        if all(p.name.startswith("diag_") for p in params):
            log_parameter_changes(self, params)      # /diagnostics thresholds: any time
            return SetParametersResult(successful=True)
        refused = refuse_while_running(self, params, self.loop is not None)
        if refused is not None:
            return refused
        values = self._values()
        values.update({p.name: p.value for p in params if p.name in values})
        try:
            new = self._validate(values)
            if self.loop is not None:        # running: the change's consequences too
                check_live_change(self.settings, new, self.engine.k)
                if self.model is not None and new.model.delta_d != self.settings.model.delta_d:
                    raise ParameterError(
                        f"delta_d={new.model.delta_d!r} is invalid while an n-DOF scene runs: "
                        "a live change of the n-DOF model is not built (valid: "
                        f"{self.settings.model.delta_d!r}; set it before the start)")
        except ParameterError as exc:
            self.get_logger().warning(f"parameter change refused: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        old = self.settings
        if self.model is not None:
            if self.loop is None and new.model.delta_d != old.model.delta_d:
                self.engine = NdofEngine(new)    # not started yet: the new wall from t = 0
        elif new.params != old.params:
            self.engine.pending = new.params     # whole, at the next Pi2 sample
        if isinstance(self.loop, Realtime) and new.time_scale != old.time_scale:
            self.loop.rebase()
        self.settings = new
        self.engine.settings = new
        log_parameter_changes(self, params)
        return SetParametersResult(successful=True)


def write_verdict(path: str, verdict: dict) -> None:
    """Write ``verdict`` as one JSON object to ``path`` (whole or not at all: a file next
    to it renamed over it); an error is one line on stderr, never a crash at exit."""
    import json
    import os
    import sys

    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(verdict, f, default=str)
        os.replace(tmp, path)
    except OSError as exc:
        print(f"sim_node: verdict_file={path!r}: {exc.strerror or exc}", file=sys.stderr)


def main(args=None) -> int:
    """Entry point of the ``sim_node`` executable; returns the exit status."""
    return run_node(SimNode, args, "sim_node")


if __name__ == "__main__":
    raise SystemExit(main())

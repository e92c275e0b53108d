"""sim_node's parameters: the node's own (after the simulation's table,
:data:`grazing_control.plant.settings.PARAMETERS`), their ROS descriptors, and the
declaration with a model file (issue 17) or a rig file (issue 28) setting defaults."""

from __future__ import annotations

from rcl_interfaces.msg import ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.parameter import Parameter as RosParameter

from grazing_control.oscillator.ndof.flow import grazing_clearance
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.realtime import CLOCK_TICK, MIN_TICK, STALL_PAUSE, STREAM_TICK, Realtime
from grazing_control.plant.rig import load_rig
from grazing_control.plant.settings import (NOT_WITH_MODEL_FILE, PARAMETERS, SETTING_KEYS,
                                            Parameter, check_live_change, described_range,
                                            load_model_file, settings_from_values)
from grazing_control.ros import stream_block
from grazing_control.ros.common import (EXECUTORS, LIVE_CHANGES_DOC, READY_TOPIC,
                                        StartupError, bool_descriptor, check_ranges,
                                        float_descriptor, int_descriptor,
                                        log_parameter_changes, refuse_out_of_range,
                                        refuse_while_running, string_descriptor)
from grazing_control.ros.rig_boundary import check_rig_values, sim_values
from grazing_control.ros.scene import SCENE_PARAMETER_DOC
from grazing_control.ros.scheduling import apply_node_scheduling

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
    Parameter("stall_pause", "double", STALL_PAUSE, "realtime: a wake-up of the simulator "
              "this many wall seconds later than it asked for, or a Pi2 sample going out "
              "this much after its time, pauses the plant's clock for the lateness (the "
              "machine held or slowed the simulator: its stall is not charged to the "
              "loop's deadlines; counted, paused= in the summary); 0 = never, the plant's "
              "clock is the wall clock; 0..1. Not with rig_file: a rig's clock runs on "
              "against ROS time", 0.0, 1.0, read_only=True),
    Parameter("stream_message", "string", "sample", "the state stream's messages: sample (one "
              "JointState per sample on oscillator/state) or block (the samples of a wake-up "
              "in one Float64MultiArray on oscillator/state_block, as a DAQ driver "
              "publishes, a row of n positions and n velocities per sample with n masses; "
              "ros/stream_block.py)", choices=stream_block.MESSAGES,
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
              "reason, summary, watchdog trip, feasibility verdict, the missed deadlines, "
              "the longest pause) as one JSON object to this file at exit; grazing run "
              "reads it ('' = none)", read_only=True),
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
    if p.kind == "double_array":
        return ParameterDescriptor(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                   description=p.doc, read_only=p.read_only,
                                   additional_constraints=p.constraints)
    return bool_descriptor(p.doc, p.read_only)


def declare_rig(node):
    """Declare rig_file and the rig clock's parameters; (the Rig or None, the
    simulation's values the rig file sets: rig_boundary.sim_values)."""
    node.rig_file = node.declare_parameter(RIG_FILE.name, RIG_FILE.default,
                                           descriptor(RIG_FILE)).value
    for p in RIG_CLOCK:
        node.declare_parameter(p.name, p.default, descriptor(p))
    if not node.rig_file:
        return None, {}
    if node.model is not None:
        raise StartupError(f"rig_file={node.rig_file} is invalid with model_file: each "
                           "gives the model; give one of them")
    try:
        rig = load_rig(node.rig_file)
    except ParameterError as exc:
        raise StartupError(str(exc)) from None
    try:
        return rig, sim_values(rig, node.get_parameter("clock_drift").value)
    except ParameterError as exc:
        raise StartupError(f"{node.rig_file}: {exc}") from None

def node_descriptor(node, p: Parameter, declared: dict):
    """:func:`descriptor`; in an n-DOF scene with the model's forcing frequency (its
    times are bounded by its period; delta_d_drift by its d*), and a parameter it does
    not build states that only its default is valid (plant.settings.NOT_WITH_MODEL_FILE; the range stays, so
    that a refusal says why: "zeta=0.02 is invalid with model_file=...")."""
    if node.model is None:
        return descriptor(p, declared)
    if p.name == "delta_d_drift":      # |drift| <= d* of the model's wall coordinate
        try:
            d_star = grazing_clearance(node.model)
        except (ValueError, ArithmeticError):     # no d* (resonance): the model is refused
            return descriptor(p)
        return float_descriptor(p.doc, -d_star, d_star, p.read_only, p.constraints)
    d = descriptor(p, {**declared, "omega": node.model.omega})
    if p.name in NOT_WITH_MODEL_FILE:
        d.additional_constraints = (f"only its default {p.default!r} with model_file "
                                    f"({NOT_WITH_MODEL_FILE[p.name]})")
    return d

def values_of(node) -> dict:
    """The simulation's parameters as declared now (plant.settings.SETTING_KEYS)."""
    return {k: node.get_parameter(k).value for k in SETTING_KEYS}

def validate(node, values: dict):
    """The settings of ``values`` (plant.settings.settings_from_values): the 1-DOF
    scene's, or with ``model_file`` the n-DOF scene's; ParameterError naming a bad value."""
    # a rig of n masses is the n-DOF scene of its model (rig_boundary.sim_values)
    source = node.model_file or (node.rig_file if node.model is not None else "")
    return settings_from_values(values, source, node.model)


def declare(node) -> None:
    """Declare every parameter of ``node`` and validate them: ``node.model_file`` /
    ``node.model`` (an n-DOF scene), ``node.rig_file`` / ``node.rig`` (a rig scene),
    ``node.settings``; a StartupError naming the bad value (the node refuses to start)."""
    node.model_file = node.declare_parameter(MODEL_FILE.name, MODEL_FILE.default,
                                             descriptor(MODEL_FILE)).value
    node.model = None            # the n-DOF model file's model (issue 17), or None
    if node.model_file:
        try:
            node.model = load_model_file(node.model_file)
        except ParameterError as exc:
            raise StartupError(str(exc)) from None
    node.rig, rig_values = declare_rig(node)
    if node.rig is not None and node.rig.n > 1:
        node.model = node.rig.model()      # the n-DOF scene of the rig's model
    declared = {}
    for p in PARAMETERS + NODE_PARAMETERS:
        if p is MODEL_FILE or p is RIG_FILE or p in RIG_CLOCK:
            continue
        default = p.default     # with a model file, delta_d defaults to the file's
        if p.name == "delta_d" and node.model is not None:
            default = node.model.delta_d
        default = rig_values.get(p.name, default)     # with a rig file, the rig's
        if p.kind == "double_array":      # declared by type: an empty list has none
            declared[p.name] = _declare_array(node, p, node_descriptor(node, p, declared))
            continue
        declared[p.name] = node.declare_parameter(
            p.name, default, node_descriptor(node, p, declared)).value
    node.set_descriptor("use_sim_time", bool_descriptor(
        "follow /clock (rclpy's parameter)", constraints="false only: sim_node "
        "publishes /clock"))
    if node.get_parameter("use_sim_time").value:
        raise StartupError(SIM_TIME_REFUSED)
    check_ranges(node)
    why = stream_block.check_message(node.get_parameter("stream_message").value)
    if why is not None:
        raise StartupError(why)
    try:
        check_rig_scene(node.rig_file, rig_values, values_of(node))
        node.settings = validate(node, values_of(node))
        apply_node_scheduling(node)
    except (ParameterError, ValueError) as exc:
        raise StartupError(str(exc)) from None


def _declare_array(node, p: Parameter, d) -> list:
    """Declare a double-array parameter of the table (``state0``): by type, then, where
    no override gave it a value, the empty list (so that a get over every name answers,
    as controller_node's ``gains``)."""
    value = node.declare_parameter(p.name, RosParameter.Type.DOUBLE_ARRAY, d).value
    if value is None:
        node.set_parameters([RosParameter(p.name, RosParameter.Type.DOUBLE_ARRAY, [])])
        value = []
    return list(value)


def on_set_parameters(node, params) -> SetParametersResult:
    """A parameter change (docs/nodes.md, "Live changes"): refused in one line where it is
    out of range, read-only while the scene runs, or invalid with the running scene; else
    taken whole (a model change at the next Pi2 sample)."""
    refused = refuse_out_of_range(node, params)
    if refused is not None:
        return refused
    if any(p.name == "use_sim_time" and p.value for p in params):
        node.get_logger().warning(f"parameter change refused: {SIM_TIME_REFUSED}")
        return SetParametersResult(successful=False, reason=SIM_TIME_REFUSED)
    if all(p.name.startswith("diag_") for p in params):
        log_parameter_changes(node, params)      # /diagnostics thresholds: any time
        return SetParametersResult(successful=True)
    refused = refuse_while_running(node, params, node.loop is not None)
    if refused is not None:
        return refused
    values = values_of(node)
    values.update({p.name: p.value for p in params if p.name in values})
    try:
        new = validate(node, values)
        if node.loop is not None:        # running: the change's consequences too
            check_live_change(node.settings, new, node.engine.k)
    except ParameterError as exc:
        node.get_logger().warning(f"parameter change refused: {exc}")
        return SetParametersResult(successful=False, reason=str(exc))
    old = node.settings
    if node.model is not None:
        if node.loop is None and new.model.delta_d != old.model.delta_d:
            node.engine = Engine(new)    # not started yet: the new wall from t = 0
    elif new.params != old.params:
        node.engine.pending = new.params     # whole, at the next Pi2 sample
    if isinstance(node.loop, Realtime) and new.time_scale != old.time_scale:
        node.loop.rebase()
    node.settings = new
    node.engine.settings = new
    log_parameter_changes(node, params)
    return SetParametersResult(successful=True)

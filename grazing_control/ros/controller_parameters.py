"""controller_node's parameters: their declaration, each with its ROS descriptor (the
range described is exactly the range the ``*_from_values`` functions of
:mod:`grazing_control.ros.controller_values` accept, issue 27), a rig file's values as the
defaults (issue 28), and the ``gains`` array of an n-DOF scene.

c1, c2 (gains, from the YAML of ``grazing design --out``), x_ref, v_ref (NaN: X** computed
from zeta, r, omega, pi2_offset), enable_after, saturation, stale_after, actuation_delay
(the delay the gains were designed for, 0 <= delay < T; the simulator applies it, the
controller validates and reports it: docs/nodes.md, "Scheduled actuation"), executor;
delta_d (the plant's model, NaN: none), pi2_source, estimator, impact_source,
sensor_noise, state_period, model_noise (stream mode); model_file and gains (an n-DOF
scene, issue 17: Delta v = k^T (X - X**), :mod:`grazing_control.ros.controller_values`; n, i_a,
mu: the design file's section data, checked against the model; with pi2_source stream the
model filter over the n-DOF map reads coordinate sensor_coordinate, issue 32); the model
watch, re-identification, pulse, actuator, capture, rig and scheduling parameters.
"""

from __future__ import annotations

import math

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter

from grazing_control.dynamics.design.capture import CAPTURE_RADIUS
from grazing_control.dynamics.estimation.section_state import ESTIMATORS
from grazing_control.dynamics.estimation.stream import IMPACT_SOURCES
from grazing_control.oscillator.params import OscillatorParams, ParameterError, study_omega
from grazing_control.plant.settings import ABOVE_0, FINITE, MAX_BANDWIDTH, below

from . import stream_block
from .common import (EXECUTORS, LIVE_CHANGES_DOC, StartupError, bool_descriptor,
                     float_descriptor, int_descriptor, string_descriptor)
from .controller_values import GAIN_LIMIT, PI2_SOURCES, below_period, model_omega
from .model_watch import WATCH_DEFAULTS
from .reidentify import declare_reidentify
from .rig_boundary import controller_values
from .scene import SCENE_PARAMETER_DOC

def declare_parameters(node) -> None:
    """Declare every parameter of the controller ``node`` (the rig file's first: with one,
    its values are the defaults), each described with exactly the range that the
    ``*_from_values`` functions accept (issue 27: open bounds as the next double); sets
    ``node.rig``, ``node.rig_values`` and ``node.model_file``. StartupError for a bad
    value that cannot wait for the node's checks."""
    ref = OscillatorParams()
    node.rig, node.rig_values = declare_rig(node)

    def d(name, default, desc):     # with a rig file, the rig's values are the defaults
        return node.declare_parameter(name, node.rig_values.get(name, default), desc)

    node.model_file = d("model_file", "", string_descriptor(
        "path of an n-DOF model YAML file (docs/ndof_model.md): answer its Pi2 samples "
        "(JointState with n joints) with Delta v = k^T (X - X**), k = gains; '' = the "
        "1-DOF law", True)).value
    # each range is exactly what law_from_values & co. accept (issue 27): open bounds
    # as the next double (plant.settings.ABOVE_0, below), "finite" as FINITE
    d("c1", 0.0, float_descriptor("gain c1 on x - x** (Eq. 28)", -GAIN_LIMIT, GAIN_LIMIT))
    d("c2", 0.0, float_descriptor("gain c2 on v - v** (Eq. 28)", -GAIN_LIMIT, GAIN_LIMIT))
    d("x_ref", math.nan, float_descriptor("x** on Pi2; NaN: from the model parameters",
                                          constraints="finite, or NaN"))
    d("v_ref", math.nan, float_descriptor("v** on Pi2; NaN: from the model parameters",
                                          constraints="finite, or NaN"))
    d("zeta", ref.zeta, float_descriptor("damping ratio (for X**), 0 < zeta < 1", ABOVE_0,
                                         below(1.0)))
    d("r", ref.r, float_descriptor("coefficient of restitution (recorded with the gains), "
                                   "0 < r < 1", ABOVE_0, below(1.0)))
    omega = d("omega", study_omega(), float_descriptor(
        "forcing frequency (for X**), > 0", ABOVE_0, FINITE,
        constraints="actuation_delay < T = 2 pi / omega")).value
    d("pi2_offset", ref.pi2_offset, float_descriptor(
        "phase of Pi2 after Pi1 (for X**), 0 < pi2_offset < 2 pi", ABOVE_0,
        below(2.0 * math.pi)))
    d("enable_after", 1000, int_descriptor(
        "first controlled sample (from 0); -1: only through ~/enable", -1))
    d("saturation", math.inf, float_descriptor("limit on |Delta v|, > 0 (inf: none)",
                                               ABOVE_0, math.inf))
    d("stale_after", math.inf, float_descriptor(
        "max age of a sample in simulation seconds (with use_sim_time), > 0 (inf: none)",
        ABOVE_0, math.inf))
    d("actuation_delay", 0.0, float_descriptor(
        "simulation time from a sample to its correction that the gains were designed "
        "for (applied by sim_node), 0 <= actuation_delay < T", 0.0,
        below_period(model_omega(node.model_file, omega)), read_only=True,
        constraints="actuation_delay < T = 2 pi / omega (with model_file: the model's "
        "omega)"))
    d("delta_d", math.nan, float_descriptor(
        "the plant's Delta d (the model of the estimator and of the predicted next "
        "correction); NaN: no model", read_only=True, constraints="finite, or NaN"))
    d("pi2_source", "sample", string_descriptor(
        "sample: the simulator's Pi2 samples (oscillator/pi2); stream: estimated from "
        "the sensor stream (oscillator/state)", True, PI2_SOURCES))
    d("estimator", "model", string_descriptor(
        "stream mode: nearest (last sample), arc (free-flow fit since the last impact),"
        " model (exact-map filter across periods)", True, ESTIMATORS))
    d("impact_source", "stream", string_descriptor(
        "stream mode: impacts from oscillator/impact (topic) or detected in the stream",
        True, IMPACT_SOURCES))
    d("sensor_noise", 1e-4, float_descriptor(
        "std of the stream's noise (> 0 for arc and model)", 0.0, FINITE,
        read_only=True))
    d("state_period", 0.0, float_descriptor(
        "simulation time between stream samples; 0: from the stamps", 0.0, FINITE,
        read_only=True))
    d("stream_message", "sample", string_descriptor(
        "stream mode: the stream's messages, sample (oscillator/state) or block "
        "(oscillator/state_block, ros/stream_block.py); the launcher passes the "
        "simulator's", True, stream_block.MESSAGES))
    why = stream_block.check_message(node.get_parameter("stream_message").value)
    if why is not None:
        raise StartupError(why)
    d("model_noise", 1e-2, float_descriptor(
        "model filter's process noise per period, in units of sensor_noise", 0.0, FINITE,
        read_only=True))
    d("estimate_bias", False, bool_descriptor(
        "stream mode, estimator model: estimate a constant sensor position bias (the "
        "augmented filter, issue 29; published on controller/model_watch)", True,
        constraints="true only with pi2_source stream and estimator model"))
    d("track_delta_d", False, bool_descriptor(
        "stream mode, estimator model: track Delta d as a random walk of std "
        "wall_noise per period (the augmented filter)", True,
        constraints="true only with pi2_source stream and estimator model"))
    d("bias_std", WATCH_DEFAULTS["bias_std"], float_descriptor(
        "augmented filter: prior std of the sensor bias, > 0", ABOVE_0, FINITE,
        read_only=True))
    d("wall_std", WATCH_DEFAULTS["wall_std"], float_descriptor(
        "augmented filter: prior std of Delta d about delta_d, > 0", ABOVE_0, FINITE,
        read_only=True))
    d("wall_noise", WATCH_DEFAULTS["wall_noise"], float_descriptor(
        "augmented filter: Delta d's random walk std per period, >= 0", 0.0, FINITE,
        read_only=True))
    # the test's window is described as [0, 0] where no test can run (the sample
    # source, or another estimator): a range end is always accepted (issue 27)
    watched = (node.get_parameter("pi2_source").value == "stream"
               and node.get_parameter("estimator").value == "model")
    d("consistency_window", 0, int_descriptor(
        "stream mode, estimator model: periods of the innovation consistency test's "
        "window (docs/theory_estimation.md E9-E10; verdict on /diagnostics and "
        "controller/model_watch); 0: no test", 0, None if watched else 0,
        read_only=True,
        constraints="> 0 only with pi2_source stream and estimator model"))
    d("false_alarm", WATCH_DEFAULTS["false_alarm"], float_descriptor(
        "consistency test: false-alarm rate per window, 0 < false_alarm < 0.5", ABOVE_0,
        below(0.5), read_only=True))
    d("capture", False, bool_descriptor(
        "stream mode: the capture rule (issue 29, docs/theory_capture.md): once control "
        "is on, no correction until the estimate is within capture_radius of the "
        "controlled orbit's Pi2 state, then Eq. 28 (latched)", True,
        constraints="true only with pi2_source stream and a model (delta_d; with "
                    "model_file its finite delta_d)"))
    d("capture_radius", 0.0, float_descriptor(
        "capture rule: the distance (Euclidean in (x, v) on Pi2; with model_file in the "
        "2n coordinates X - X**), >= 0; 0: "
        f"{CAPTURE_RADIUS:g} sqrt(|delta_d|)", 0.0, FINITE, read_only=True))
    declare_reidentify(d)
    d("scene", "", string_descriptor(SCENE_PARAMETER_DOC, True))
    d("live_changes", False, bool_descriptor(LIVE_CHANGES_DOC, True))
    d("diagnostics_period", 1.0, float_descriptor(
        "wall seconds between /diagnostics messages (grazing_control.ros.diagnostics); "
        "0 = none", 0.0, 3600.0, read_only=True))
    d("answer_after_section", False, bool_descriptor(
        "stream mode: answer section k with its sample at t_k (realtime: the simulator "
        "publishes it before its Pi2 sample), not with the last before it (lockstep)",
        read_only=True))
    d("answer_lead", 0.0, float_descriptor(
        "stream mode: answer a section this much simulation time before its last "
        "sample (those samples are not used); 0: with its last sample", 0.0, FINITE,
        read_only=True, constraints="answer_lead < T = 2 pi / omega"))
    width = d("pulse_width", 0.0, float_descriptor(
        "how sim_node acts (its pulse_width): a force pulse of this width centred at the "
        "actuation time, modelled by the estimator and the prediction; 0: a velocity "
        "kick", 0.0, below(2.0 * math.pi / omega), read_only=True,
        constraints="pulse_width < T = 2 pi / omega; with "
        "rig_file the rig's")).value
    d("force_limit", 0.0, float_descriptor(
        "sim_node's force_limit on the pulse's force, modelled; 0: none", 0.0, FINITE,
        read_only=True, constraints="with rig_file the rig's"))
    # the actuator acts on a pulse: without one (pulse_width 0) its parameters are
    # described as [0, 0], as consistency_window without a test (a range end is
    # always accepted, tests/test_node_parameters.py)
    pulsed = width > 0.0
    d("actuator_bandwidth", 0.0, float_descriptor(
        "sim_node's first-order actuator (issue 29): bandwidth 1 / tau_a in radians per "
        "simulation time unit, integrated exactly by the estimator and the prediction; "
        "0: ideal", 0.0, MAX_BANDWIDTH if pulsed else 0.0, read_only=True,
        constraints="> 0 only with pulse_width > 0; with rig_file the rig's"))
    d("actuator_latency", 0.0, float_descriptor(
        "the actuator's latency from the command to the force, simulation time; 0: none",
        0.0, FINITE if pulsed else 0.0, read_only=True,
        constraints="> 0 only with pulse_width > 0; "
        "actuation_delay + pulse_width / 2 + actuator_latency < T"))
    d("executor", "events", string_descriptor(
        "rclpy executor: single_threaded or events (rclpy.experimental EventsExecutor)",
        True, EXECUTORS))
    d("gains", Parameter.Type.DOUBLE_ARRAY, ParameterDescriptor(
        type=ParameterType.PARAMETER_DOUBLE_ARRAY, description=(
            "with model_file: the 2n gains k on (x_0..x_{n-1}, v_0..v_{n-1}) - X** "
            "(grazing design --model FILE --out); unused without (empty)")))
    if not node.model_file and gains_of(node) is None:
        # a value, so that a get over every name answers (ros2 param dump, get): an
        # unset parameter made rclpy's GetParameters return nothing at all (issue 27)
        node.set_parameters([Parameter("gains", Parameter.Type.DOUBLE_ARRAY, [])])
    d("n", -1, int_descriptor("with model_file: the degrees of freedom the gains were "
                              "designed for (checked against the model; -1: not given)",
                              -1, read_only=True))
    d("i_a", -1, int_descriptor("with model_file: the actuated coordinate the gains were "
                                "designed for (checked; -1: not given)", -1,
                                read_only=True))
    d("mu", math.nan, float_descriptor("with model_file: the design's mu (w^T N = mu w^T; "
                                       "recorded, not used)", read_only=True))
    d("sensor_coordinate", 0, int_descriptor(
        "with model_file and pi2_source stream: the coordinate whose position (and "
        "velocity where carried) the model filter reads, 0 <= sensor_coordinate < n",
        0, read_only=True))


def declare_rig(node):
    """Declare rig_file, rig_c2 and clock_window; (the Rig or None, the parameters
    its file sets: rig_boundary.controller_values, the design for its budget)."""
    from grazing_control.plant.rig import load_rig

    path = node.declare_parameter("rig_file", "", string_descriptor(
        "path of a rig file (docs/rig.md): speak the driver contract in SI "
        "(docs/driver_contract.md: reads rig/sensor, rig/phase, rig/clock, rig/applied;"
        " answers on rig/force_pulse and, dimensionless, on "
        "controller/velocity_correction), the model, sensor and gains from the rig; "
        "'' = the dimensionless scene", True)).value
    c2 = node.declare_parameter("rig_c2", math.nan, float_descriptor(
        "rig_file: the design's c2 (c1 from the degenerate condition for the budget's "
        "delay); NaN: the c2 of least noise gain", read_only=True,
        constraints=f"|rig_c2| <= {GAIN_LIMIT:g}, or NaN")).value
    if not (math.isnan(c2) or abs(c2) <= GAIN_LIMIT):
        raise StartupError(f"rig_c2={c2!r} is invalid: valid range is |rig_c2| <= "
                           f"{GAIN_LIMIT:g}, or NaN for the c2 of least noise gain")
    mu = node.declare_parameter("rig_mu", math.nan, float_descriptor(
        "rig_file of n >= 2 masses: the n-DOF design's mu (grazing design --rig FILE --mu); "
        "NaN: the middle of the widest admissible interval", read_only=True,
        constraints="finite, or NaN")).value
    if math.isinf(mu):
        raise StartupError(f"rig_mu={mu!r} is invalid: valid range is a finite mu, or NaN "
                           "for the middle of the widest admissible interval")
    node.declare_parameter("clock_window", 200, int_descriptor(
        "rig_file: rig/clock pairs of the clock relation's sliding window", 2, 100_000,
        read_only=True))
    node.rig_file = path
    if not path:
        return None, {}
    try:
        rig = load_rig(path)
        return rig, controller_values(rig, c2, mu)
    except (ParameterError, ValueError, ArithmeticError) as exc:
        raise StartupError(f"rig_file={path}: {exc}") from None


def gains_of(node):
    """The ``gains`` parameter, None when not given."""
    try:
        return node.get_parameter("gains").value
    except ParameterUninitializedException:
        return None

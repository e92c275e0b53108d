"""controller_node: the discrete grazing controller on section Pi2 (spec section 4, Eq. 28).

Each Pi2 sample (x, v) is answered with the velocity correction

    Delta v = c1 (x - x**) + c2 (v - v**)

computed by :func:`grazing_control.oscillator.control.correction`, limited to |Delta v| <=
``saturation``, and published stamped with the sample's own stamp, so that the
simulator can tell which sample it answers.

Topics
------
subscribes ``oscillator/pi2`` (sensor_msgs/JointState): position [x], velocity [v] at Pi2.
publishes ``controller/velocity_correction`` (geometry_msgs/TwistStamped):
twist.linear.x = Delta v (nondimensional velocity), twist.linear.y = the correction
predicted for the NEXT sample (one exact period of the model from this sample with this
correction applied after ``actuation_delay``, then Eq. 28; 0 when the next sample is not
controlled; NaN without a model, i.e. ``delta_d`` NaN: issue 16 section 3),
header.stamp = the sample's stamp;
reliable, transient local, keep last 100000 (``REPLAY_QOS``): a recorder that matches
late still gets every answer (the subscription is reliable, volatile, keep last 1000).
Both as packed bytes (:mod:`grazing_control.ros.cdr`, docs/nodes.md "Wire format"):
the simulator's sample layout is read directly, any other JointState through rclpy;
bytes that decode to no JointState are counted as malformed.

Stream mode (``pi2_source`` stream)
-----------------------------------
The controller does not subscribe ``oscillator/pi2``: it estimates each section's state
from ``oscillator/state`` (JointState, stamp = sample time, position [x~], velocity [v~]
or empty for a position-only sensor, effort [cos tau, sin tau] or [cos tau]; the section
times are t_k = k T, the simulator's origin) with ``estimator`` nearest, arc or model
(:mod:`grazing_control.dynamics.estimation.section_state`, docs/theory_estimation.md), the impacts
taken from ``oscillator/impact`` (``impact_source`` topic) or detected in the stream.
With ``stream_message`` block the same samples come in blocks on
``oscillator/state_block`` (:mod:`grazing_control.ros.stream_block`; an n-DOF scene's
rows carry its n positions and velocities), taken row by row.
Section k is estimated and answered (stamped t_k) as soon as its last sample arrived:
the newest sample's t + ``state_period`` > t_k (0: the gap between the last two stamps),
or late, with the first sample after t_k when that one was lost. Each estimate is
published on ``controller/estimate`` (JointState: position [x^], velocity [v^], effort
[var x, cov xv, var v] per the noise model; stamp t_k; transient local like the
answers). The model needs the plant's ``delta_d`` and the sensor's ``sensor_noise``
(the launcher passes the simulator's); ``model_noise`` is the model filter's process
noise per period in units of ``sensor_noise``. With ``estimate_bias``, ``track_delta_d``
or ``consistency_window`` (issue 29, :mod:`grazing_control.ros.model_watch`) the
augmented filter estimates a sensor bias and a drifting Delta d, a consistency monitor
tests its innovations, and each section's row goes on ``controller/model_watch``; a
mismatch verdict is an ERROR on /diagnostics naming the test, statistic and bound.
With ``reidentify`` (on a mismatch verdict) or on a call of ``~/reidentify``
(std_srvs/Trigger) the model is refitted on the last ``reidentify_periods`` periods in a
worker thread and, where the design is admissible for it (``design_conditions``), the
estimator, Eq. 28 and X** switch to it at the next section
(:mod:`grazing_control.ros.reidentify`); each decision goes on ``controller/model_switch``.

Switching on
------------
The controller acts from the ``enable_after``-th sample on (counted from 0: with
enable_after = 1000 samples 0..999 are uncontrolled, as the study and
``simulate(..., control_after=1000)``); -1 means only through ``~/enable``
(std_srvs/SetBool), which switches it on or off at any time. While off it still answers
every sample, with Delta v = 0, so that a lockstep simulator never waits for an answer
that will not come.

Stale, duplicate and malformed samples
--------------------------------------
* Every sample is answered once: a sample whose stamp equals one of the last
  ``RECENT`` answered stamps is a duplicate and not answered (counted as stale). A
  sample older than the newest one is still answered (counted as out of order): the
  controller cannot tell a stray message from the simulator's stream, so it does not
  let one decide; the simulator applies only the answer to the sample it is waiting for
  (lockstep) or to one of its last two samples (realtime), so a stray sample with a
  future stamp neither switches control off nor starves the simulator. A sample at
  t = 0 (stamp 0) after others means the simulator was reset (``~/reset``): the sample
  count restarts and ``enable_after`` counts again from there, unless the next sample
  continues the old stream (a stamp newer than the newest before it): then that t = 0
  sample was a stray and the count goes on.
* With ``use_sim_time`` true the node's clock follows ``/clock``; a sample older than
  ``stale_after`` seconds of simulation time on arrival (clock now - stamp) is stale and
  not answered. Without simulation time the check is skipped (stamps are simulation
  time, the node's clock would be wall time).
* NaN/inf or missing position/velocity: ignored, counted, logged (throttled).
* A correction that is not finite (overflow, e.g. x = v = 1e308 with saturation = inf)
  is never published: counted (``nonfinite``) and logged; the simulator then applies no
  correction to that sample.
* More than one publisher of ``oscillator/pi2`` (two simulators: two scenes on one
  domain and namespace) is an error: the node logs it and exits with status 1, so the
  scene fails instead of losing answers to the other scene's colliding stamps. Checked
  every ``ISOLATION_CHECK`` s of wall time and whenever a sample is refused as a
  duplicate. (Each simulator checks for another simulator or controller too, but sees
  only what its own participant has discovered; the controller hears both.)

Parameters: :mod:`grazing_control.ros.controller_parameters` (the table is in docs/nodes.md). Run: ``ros2 run grazing_control controller_node --ros-args --params-file
config/controller.yaml`` or ``python -m grazing_control.ros.controller_node ...``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import JointState, TimeReference
from std_msgs.msg import Bool, Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.oscillator.params import ParameterError

from . import cdr, stream_block
from .common import (DATA_QOS, INPUT_QOS, LATCHED_QOS, REPLAY_QOS, SafePoints, StartupError,
                     Throttled, check_ranges, deserialize, executor_kind,
                     log_parameter_changes, publish_parameter_record, refuse_out_of_range,
                     refuse_while_running, run_node, spin, stamp_key)
from .controller_parameters import declare_parameters, gains_of
from .controller_values import (ControlLaw, actuation_delay_from_values, capture_from_values,
                                degeneracy_warning, law_from_values, model_capture_from_values,
                                model_controller_from_values, model_from_values,
                                model_stream_from_values, predicted_correction,
                                pulse_from_values, stream_from_values, unseen_rebound,
                                warm_up_kernel)
from .controller_status import diagnose
from .diagnostics import Updater
from .matching import MatchReport
from .model_watch import (WATCH_FIELDS, WATCH_KEYS, WATCH_TOPIC, describe_verdict,
                          watch_from_values, watch_row)
from .message_wait import take_queued
from .published import (ACK_TIMEOUT, COMPLETE_TOPIC, Counted, PublishedRecord,
                        RecorderConfirmation, close_publishers)
from .reidentify import REID_KEYS, SWITCH_TOPIC, ReidentifySide
from .rig_boundary import check_rig_values
from .rig_control import RigSide
from .scene_nodes import ACTUATION_KEYS as PULSE_KEYS  # how a correction acts
from .scheduling import apply_node_scheduling, declare_scheduling, raise_node_priority
from .stream_intake import PHASE_TOLERANCE, phase_error, plain_rows, take_run

#: Wall seconds between two checks that only one simulator publishes the samples.
ISOLATION_CHECK = 0.25

__all__ = ["ControllerNode", "main"]

_KEYS = ("c1", "c2", "x_ref", "v_ref", "zeta", "r", "omega", "pi2_offset", "n", "i_a",
         "enable_after", "saturation", "stale_after", "actuation_delay", "delta_d",
         "pi2_source", "estimator", "impact_source", "sensor_noise", "state_period",
         "model_noise", "answer_after_section", "answer_lead", "capture",
         "capture_radius", "sensor_coordinate") + WATCH_KEYS + REID_KEYS


class ControllerNode(Node):
    """The controller node (module docstring: topics, switching, stale samples)."""

    def __init__(self, **kwargs):
        super().__init__("controller_node", **kwargs)
        declare_parameters(self)   # ros/controller_parameters.py: rig, model file, every parameter
        declare_scheduling(self)
        check_ranges(self)
        self.executor_kind = executor_kind(self)
        try:
            apply_node_scheduling(self)
            check_rig_values(self.rig_file, self.rig_values,
                             {**self._values(), "gains": list(gains_of(self) or []),
                              "mu": self.get_parameter("mu").value}, free=("answer_lead",))
        except (ValueError, ParameterError) as exc:
            raise StartupError(str(exc)) from None
        self.ndof = None         # an n-DOF scene's controller (issue 17), or None
        # a rig of n masses is the n-DOF scene of its model (rig_boundary.controller_values)
        self.rig_model = (self.rig.model() if self.rig is not None and self.rig.n > 1
                          else None)
        # how a correction acts in the plant: a rig's force pulse (its estimator and
        # prediction integrate it, dynamics.estimation.motion.trajectory), else the kick
        self.pulse = (0.0, math.inf, None)
        # (a rig file's are the defaults: rig_boundary.controller_values; its actuator's
        # latency is in the budget)
        pulse = {k: self.get_parameter(k).value for k in PULSE_KEYS}
        try:
            if self.model_file or self.rig_model is not None:
                self.law = self._ndof_law(self._values(), gains_of(self))
                self.actuation_delay = actuation_delay_from_values(
                    {**self._values(), "omega": self.ndof.model.omega})
                self.pulse = pulse_from_values(pulse, self.ndof.model.omega,
                                               self.actuation_delay)
                self.model = self.capture = None
                self.stream = model_stream_from_values(self._values(), self.ndof, self.pulse)
                self.capture = model_capture_from_values(self._values(), self.ndof,
                                                         self.actuation_delay, self.pulse)
                if self.capture is not None and self.capture.forecast:
                    self.get_logger().warning(self.capture.forecast)
                if self.stream is not None:     # the section times and the phase check
                    self.model = self.ndof.model
            else:
                self.law = law_from_values(self._values())
                self.actuation_delay = actuation_delay_from_values(self._values())
                self.pulse = pulse_from_values(pulse, self._values()["omega"],
                                               self.actuation_delay)
                self.model = model_from_values(self._values())
                self.stream = stream_from_values(self._values(), self.model, self.pulse)
                self.capture = capture_from_values(self._values(), self.model,
                                                   self.actuation_delay)
            warm_up_kernel(self.model, self.stream)     # the compiled filter, the prediction
            # stream mode: the cyclic collector runs after a section's answer, not inside
            # its estimate (issue 30; common.SafePoints)
            self.collect = SafePoints() if self.stream is not None else None
            self._early = set()      # stamps answered before their estimate
            if self.stream is not None:
                self.stream.before_estimate = self._answer_before_estimate
        except ParameterError as exc:
            raise StartupError(str(exc)) from None
        self.stale_after = float(self.get_parameter("stale_after").value)
        # what its ends have matched, for the start handshake (ros/matching.py): made
        # before the data endpoints, so whoever discovers those has discovered it
        self.matched = MatchReport(self)
        # no default QoS-event handlers: each is one more entity in every executor wait
        self.pub = Counted(self.create_publisher(
            TwistStamped, "controller/velocity_correction", REPLAY_QOS,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
        quiet = SubscriptionEventCallbacks(use_default_callbacks=False)
        # created in both modes (published in stream mode only): the recorder records it by
        # default and says it is ready once every recorded topic has its publisher
        self.pub_estimate = Counted(self.create_publisher(
            JointState, "controller/estimate", REPLAY_QOS,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
        # the augmented filter's estimates and the consistency verdict (issue 29), made
        # in every mode like controller/estimate (recorded by default)
        self.pub_watch = Counted(self.create_publisher(
            JointState, WATCH_TOPIC, REPLAY_QOS,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
        # the re-identification's decisions (issue 29 section 3), made in every mode
        self.pub_switch = Counted(self.create_publisher(
            JointState, SWITCH_TOPIC, REPLAY_QOS,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
        self.watching = isinstance(self.stream, AugmentedStreamEstimator)
        self.monitor = (watch_from_values(self._values())[1] if self.watching else None)
        self.verdict = None             # the monitor's latest verdict
        self.mismatches = 0             # sections whose verdict was a mismatch
        self.first_mismatch = None      # the first section with a mismatch verdict
        self.diag_mismatches = 0
        try:        # re-identification in the loop (ros/reidentify.py), or None
            self.reid = ReidentifySide.from_node(self, self._values())
        except ParameterError as exc:
            raise StartupError(str(exc)) from None
        self.rig_side = None     # the driver contract's side (rig_file), or None
        self.sub_impacts = None  # stream mode's impact topic (impact_source topic), or None
        reads = []               # the other subscriptions (all: self.inputs, below)
        if self.rig is not None:
            self.rig_side = RigSide(self, self.rig, self.get_parameter("clock_window").value)
            self.pub_force = Counted(self.create_publisher(
                WrenchStamped, "rig/force_pulse", REPLAY_QOS,
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False)))
            self.sub_samples = self.create_subscription(
                JointState, "rig/sensor", self.rig_side.on_sensor, INPUT_QOS, raw=True,
                event_callbacks=quiet)
            reads = [self.create_subscription(
                Vector3Stamped, "rig/phase", self.rig_side.on_phase, DATA_QOS,
                event_callbacks=quiet), self.create_subscription(
                TimeReference, "rig/clock", self.rig_side.on_clock, DATA_QOS,
                event_callbacks=quiet), self.create_subscription(
                WrenchStamped, "rig/applied", self.rig_side.on_applied, INPUT_QOS,
                event_callbacks=quiet)]
        elif self.stream is None:
            self.sub_samples = self.create_subscription(
                JointState, "oscillator/pi2", self._on_sample, INPUT_QOS, raw=True,
                event_callbacks=quiet)
        else:       # stream mode never listens to the simulator's exact samples
            self.sub_samples = (self.create_subscription(    # in blocks (issue 30)
                Float64MultiArray, stream_block.TOPIC, self._on_state_block, INPUT_QOS,
                raw=True, event_callbacks=quiet)
                if self.get_parameter("stream_message").value == "block" else
                self.create_subscription(JointState, "oscillator/state", self._on_state,
                                         INPUT_QOS, raw=True, event_callbacks=quiet))
            if self.stream.impact_source == "topic":
                self.sub_impacts = self.create_subscription(
                    Vector3Stamped, "oscillator/impact", self._on_impact, INPUT_QOS,
                    event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
            # what acted where an answer came too late: nothing (oscillator/deadline_miss)
            # or the prediction substituted for it (oscillator/substituted); the model
            # filter must integrate the kick that acted, not the one it answered
            reads = [self.create_subscription(
                Vector3Stamped, "oscillator/deadline_miss", self._on_miss, INPUT_QOS,
                event_callbacks=quiet), self.create_subscription(
                TwistStamped, "oscillator/substituted", self._on_substituted, INPUT_QOS,
                raw=True, event_callbacks=quiet)]
        # the start handshake's report (ros/matching.py): every topic read, the answers
        # (a rig's force pulse)
        self.inputs = [self.sub_samples] + ([self.sub_impacts] if self.sub_impacts else []) + reads
        self.matched.watch(self.inputs, self.pub_force if self.rig_side else self.pub)
        self.exit_code, self.exit_now = 0, False
        self._next_check = 0.0
        self.pub_enabled = Counted(self.create_publisher(Bool, "controller/enabled",
                                                         LATCHED_QOS))
        self.published = PublishedRecord(self, (self.pub, self.pub_estimate, self.pub_enabled,
                                                self.pub_watch, self.pub_switch)
                                         + ((self.pub_force,) if self.rig_side else ()))
        self.recorder = RecorderConfirmation(self)
        self.create_service(SetBool, "~/enable", self._on_enable)
        self.create_service(Trigger, "~/reidentify", self._on_reidentify)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.pub_parameters = publish_parameter_record(self)   # grazing/parameters
        log = self.get_logger()
        self.malformed = Throttled(log, "malformed sample ignored")
        self.stale = Throttled(log, "stale sample not answered")
        self.nonfinite = Throttled(log, "non-finite correction not published")
        self.phase_mismatch = Throttled(log, "stream phase reference off")
        self.mismatch_log = Throttled(log, "consistency test failed")
        self.answered = 0
        self.warned_unseen = False       # the answer lead's unseen rebound, said once
        self.prediction = math.nan       # the last answer's predicted next correction
        self.diagnostics = Updater(self, self.get_parameter("diagnostics_period").value)
        self.diagnostics.add("controller", self._diagnose)
        self.diag_last = (0, 0, None)   # answered, refused, ROS time (sim time)
        if math.isfinite(self.stale_after) and not self.get_parameter("use_sim_time").value:
            log.warning("stale_after is ignored without use_sim_time (stamps are simulation "
                        "time)")
        raise_node_priority(self)   # its start-up done: SCHED_FIFO from here (scheduling.py)
        self._warn_gains()
        if self.ndof is not None:
            log.info(f"model_file={self.model_file or self.rig_file} n={self.ndof.model.n} "
                     f"i_a={self.ndof.model.i_a} gains={self.ndof.gains.tolist()!r} "
                     f"X**={self.law.x_ref.tolist() + self.law.v_ref.tolist()!r} "
                     f"enable_after={self.law.enable_after} "
                     f"actuation_delay={self.actuation_delay!r} "
                     f"predicts={str(self.ndof.predicts).lower()} executor={self.executor_kind}"
                     + ("" if self.stream is None else
                        f" pi2_source=stream estimator=model sensor_coordinate="
                        f"{self.stream.coordinate} sensor_noise={self.stream.sigma!r}"))
            return
        source = "sample" if self.stream is None else (
            f"stream estimator={self.stream.estimator} impact_source="
            f"{self.stream.impact_source} sensor_noise={self.stream.sigma!r}")
        log.info(f"c1={self.law.gains.c1!r} c2={self.law.gains.c2!r} x_ref={self.law.x_ref!r} "
                 f"v_ref={self.law.v_ref!r} enable_after={self.law.enable_after} "
                 f"actuation_delay={self.actuation_delay!r} executor={self.executor_kind} "
                 f"pi2_source={source}")

    def _warn_gains(self) -> None:
        """Warn when the gains were not given or are both zero (the controller then
        answers every sample with Delta v = 0): typically a parameter file keyed for
        another node name, which rcl ignores silently; or when c1 is not Eq. 38's gain of
        c2 at the actuation delay (controller_values.degeneracy_warning)."""
        given, warn = getattr(self, "_parameter_overrides", {}), self.get_logger().warning
        if self.ndof is not None:
            if not np.any(self.ndof.gains):
                warn("gains are all 0: every correction is 0, the controller does not control")
            return
        missing = [k for k in ("c1", "c2") if k not in given]
        if missing and self.rig is None:        # a rig file's design gives them
            warn(f"{' and '.join(missing)} not given to {self.get_fully_qualified_name()} "
                 "(no -p and no parameter-file entry that applies to this node name): "
                 "default 0.0 used")
        if self.law.gains.c1 == 0.0 and self.law.gains.c2 == 0.0:
            warn("c1 = c2 = 0: every correction is 0, the controller does not control")
        elif self.rig is None and (text := degeneracy_warning(self._values(), self.pulse)):
            warn(text)

    def _values(self) -> dict:
        return {k: self.get_parameter(k).value for k in _KEYS}

    def _ndof_law(self, values: dict, gains) -> ControlLaw:
        """The law k^T (X - X**) of a model file's ``values`` and ``gains``
        (controller_values.model_controller_from_values); sets :attr:`ndof`. The switches
        (enable_after, saturation, stale_after) are validated as the 1-DOF law's."""
        ndof = model_controller_from_values(values, self.model_file or self.rig_file, gains,
                                            self.rig_model)
        base = law_from_values({**values, "c1": 0.0, "c2": 0.0, "x_ref": 0.0, "v_ref": 0.0})
        self.ndof = ndof
        return ControlLaw(ndof.gains, ndof.x_ref, ndof.v_ref, base.enable_after,
                          base.saturation)

    def _ndof_sample(self, data: bytes):
        """(key, x, v) of an n-DOF Pi2 sample (a JointState with n positions and n
        velocities), else None (counted as malformed)."""
        msg = deserialize(data, JointState, self.malformed)
        if msg is None:
            return None
        key = stamp_key(msg.header.stamp)
        n = self.ndof.model.n
        if len(msg.position) != n or len(msg.velocity) != n:
            self.malformed(f"stamp {key}: {len(msg.position)} positions and "
                           f"{len(msg.velocity)} velocities, expected {n} of each (the "
                           f"{n}-DOF model of {self.model_file})")
            return None
        return key, np.array(msg.position, dtype=float), np.array(msg.velocity, dtype=float)

    def _on_sample(self, data: bytes) -> None:
        """A Pi2 sample as received (serialized): the simulator's layout is read directly
        (:func:`cdr.read_sample`), any other JointState through rclpy's deserializer; an
        n-DOF scene's samples (n joints) through rclpy's."""
        if self.ndof is not None:
            sample = self._ndof_sample(data)
            if sample is None:
                return
            key, x, v = sample
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
                self.malformed(f"stamp {key}: x={x.tolist()!r} v={v.tolist()!r}")
                return
            if self._stale(key):
                return
            self._answer(key, x, v)
            return
        sample = cdr.read_sample(data)
        if sample is None:
            msg = deserialize(data, JointState, self.malformed)
            if msg is None:
                return
            key = stamp_key(msg.header.stamp)
            if len(msg.position) < 1 or len(msg.velocity) < 1:
                self.malformed(f"stamp {key}: missing position/velocity")
                return
            sample = key + (msg.position[0], msg.velocity[0])
        sec, ns, x, v = sample
        key = (sec, ns)
        if not (math.isfinite(x) and math.isfinite(v)):
            self.malformed(f"stamp {key}: x={x!r} v={v!r}")
            return
        if self._stale(key):
            return
        self._answer(key, x, v)

    def _stale(self, key: tuple) -> bool:
        """Whether the sample stamped ``key`` is older than ``stale_after`` (with
        use_sim_time; counted and logged)."""
        if math.isfinite(self.stale_after) and self._use_sim_time():
            age = self.get_clock().now().nanoseconds * 1e-9 - (key[0] + key[1] * 1e-9)
            if age > self.stale_after:
                self.stale(f"stamp {key} is {age:.6g} s old")
                return True
        return False

    def _answer(self, key: tuple, x: float, v: float, factor: float = 1.0,
                rig_time: float | None = None):
        """Answer the Pi2 state (x, v) stamped ``key``: the correction and, with a model,
        the one predicted for the next sample (twist.linear.y, NaN: none); ``factor`` 0
        (the capture rule holding back) answers 0 and predicts 0. ``rig_time``: the
        section's model time with a rig file, whose force pulse goes out first (it has
        the deadline; rig_control.RigSide.answered). Returns the correction published,
        or None."""
        dv = self.law.answer(key, x, v)
        if factor != 1.0 and dv is not None:
            dv = dv * factor if factor else 0.0
        if dv is None:
            self.stale(f"stamp {key} was already answered")
            self._check_isolation()
            return None
        if not math.isfinite(dv):
            self.nonfinite(f"stamp {key}: x={x!r} v={v!r} gives Delta v={dv!r}: not published")
            return None
        self.prediction = self._predict(x, v, dv) if factor == 1.0 else 0.0
        if rig_time is not None:
            self.rig_side.answered(rig_time, dv, self.prediction)
        self.pub.publish(cdr.twist_stamped(*key, dv, self.prediction))
        self.answered += 1
        return dv

    def _answer_before_estimate(self, k: int) -> None:
        """Section k falls due (before its estimate): while the control is off for it and
        the next, its answer (0, predicting 0) does not wait for the estimate (issue 30:
        at T/200 x1000 the first sections missed their deadline behind the arc fit)."""
        tk = k * self.stream.p.period          # the stamp the estimate will have
        key = cdr.stamp_parts(tk)
        if key == (0, 0) or not self.law.off_for_two():
            return
        # factor 0: the answer 0 and the prediction 0, whatever the (unknown) state
        self._answer(key, math.nan, math.nan, 0.0, tk if self.rig_side is not None else None)
        self._early.add(key)

    def _answered_early(self, key: tuple) -> bool:
        early = key in self._early
        if self._early:     # older ones too (an estimate that failed never came back)
            self._early = {k for k in self._early if k > key}
        return early

    def _predict(self, x: float, v: float, dv: float) -> float:
        """The correction of the next sample (:func:`predicted_correction`)."""
        return predicted_correction(self.law, self.model, self.ndof, self.stream, self.pulse,
                                    self.actuation_delay, x, v, dv)

    def _on_state(self, data: bytes) -> None:
        """A stream sample as received: read directly (:func:`cdr.read_state`), else
        through rclpy; the sections it completes are estimated, published on
        controller/estimate and answered. An n-DOF stream sample (n joints) through
        rclpy: coordinate ``sensor_coordinate``'s position and velocity (NaN: none)."""
        if self.ndof is not None:
            msg = deserialize(data, JointState, self.malformed)
            if msg is None:
                return
            n, c = self.ndof.model.n, self.stream.coordinate
            if len(msg.position) != n or len(msg.velocity) not in (0, n):
                self.malformed(f"stamp {stamp_key(msg.header.stamp)}: {len(msg.position)} "
                               f"positions and {len(msg.velocity)} velocities, expected {n} "
                               f"(and {n} or no velocities)")
                return
            v = msg.velocity[c] if len(msg.velocity) else math.nan
            self._take_sample(stamp_key(msg.header.stamp) + (msg.position[c], v,
                                                             tuple(msg.effort)))
            return
        sample = cdr.read_state(data)
        if sample is None:
            msg = deserialize(data, JointState, self.malformed)
            if msg is None:
                return
            if len(msg.position) < 1:
                self.malformed(f"stamp {stamp_key(msg.header.stamp)}: no position")
                return
            v = msg.velocity[0] if len(msg.velocity) else math.nan
            sample = stamp_key(msg.header.stamp) + (msg.position[0], v, tuple(msg.effort))
        self._take_sample(sample)

    def _on_state_block(self, data: bytes) -> None:
        """A block of stream samples (ros/stream_block.py), row after row as :meth:`_on_state`
        takes one (n-DOF: coordinate ``sensor_coordinate``); another n is malformed."""
        rows = stream_block.read(data)
        n = 1 if self.ndof is None else self.ndof.model.n
        if rows is None or rows.masses != n:
            self.malformed(f"a message on {self.sub_samples.topic_name} that is not a "
                           f"stream block of rows of n={n} (ros/stream_block.py)")
            return
        c, i, end = (0 if self.ndof is None else self.stream.coordinate), 0, rows.count
        while i < end:          # the runs between sections in one step (ros/stream_intake.py)
            i += take_run(self.stream, self.reid,
                          *plain_rows(rows, c, self._tau2(), self.model.omega, i))
            if i < end:             # a section due, a row that fails a check: by itself
                self._take_sample(stream_block.samples(rows, c, i, i + 1)[0])
                i += 1

    def _take_sample(self, sample: tuple) -> None:
        """(sec, nanosec, x, v, effort) of one stream sample: checked, then estimated."""
        sec, ns, x, v, effort = sample
        if not math.isfinite(x) or math.isinf(v):
            self.malformed(f"stamp {(sec, ns)}: x={x!r} v={v!r}")
            return
        t = sec + ns * 1e-9
        self._check_phase(t, effort)
        self.add_stream_sample(t, x, v)

    def add_stream_sample(self, t: float, x: float, v: float) -> None:
        """A stream sample (model time and units): the sections it completes are
        estimated, answered (with a rig file first as the force pulse,
        rig_control.RigSide.answered) and published on controller/estimate."""
        if self.reid is not None:
            self.reid.sample(t, x, v)
        try:
            due = self.stream.add_sample(t, x, v)
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            self.malformed(f"stamp {cdr.stamp_parts(t)}: the estimator failed: {exc}")
            return
        if due and self.stream.unseen_impacts and not self.warned_unseen:
            self.warned_unseen = True
            self.get_logger().warning(unseen_rebound(self.stream.lead))
        for k, tk, est in due:
            key = cdr.stamp_parts(tk)
            if self.ndof is not None:
                self._answer_ndof_estimate(k, tk, key, est)
                continue
            p = self.model      # a switch at the section before moves it (ros/reidentify.py)
            xh, vh = p.x_ref + est.z[0], p.v_ref + est.z[1]
            c = est.cov
            estimate = cdr.estimate_state(*key, xh, vh, float(c[0, 0]), float(c[0, 1]),
                                          float(c[1, 1]))
            if not (math.isfinite(xh) and math.isfinite(vh)):
                self.pub_estimate.publish(estimate)
                self.malformed(f"section {k}: no estimate (no sample before it)")
                continue
            if self.watching:
                self._watch(k, key)
            if self.reid is not None:       # a finished refit is applied here, at Pi2
                self.reid.at_section(k, key, est)
            # the answer before the estimate's message (issue 30: in the rig scene publishing
            # the estimate first put the force pulse 0.37 ms later, docs/benchmarks.md)
            dv = 0.0 if self._answered_early(key) else self._answer(
                key, xh, vh, self._capture_factor(k, est),
                tk if self.rig_side is not None else None)
            self.pub_estimate.publish(estimate)
            self.stream.set_correction(k, 0.0 if dv is None else dv, self.actuation_delay)
            if self.reid is not None:
                self.reid.answered(k, 0.0 if dv is None else dv)
        if due:
            self.collect()          # the answers are out: a safe point for the collector

    def _answer_ndof_estimate(self, k: int, tk: float, key: tuple, est) -> None:
        """Section k (model time ``tk``) of an n-DOF stream: the answer k^T (X^ - X**)
        (with a rig file of n masses first as the force pulse), then (as in 1-DOF)
        the estimate X^ = X** + z^ on controller/estimate (JointState, n joints:
        positions, velocities, effort the 2n variances); with the model watch its row first."""
        if self.watching:
            self._watch(k, key)
        ndof = self.ndof
        X = np.concatenate([ndof.x_ref, ndof.v_ref]) + np.asarray(est.z, dtype=float)
        n = ndof.model.n
        if self.reid is not None:       # a finished refit is applied here, at Pi2
            self.reid.at_section(k, key, est)
        dv = 0.0 if self._answered_early(key) else self._answer(
            key, X[:n], X[n:], self._capture_factor(k, est),
            tk if self.rig_side is not None else None)
        msg = JointState(name=[f"mass{i}" for i in range(n)],
                         position=X[:n].tolist(), velocity=X[n:].tolist(),
                         effort=np.diag(est.cov).tolist())
        msg.header.stamp.sec, msg.header.stamp.nanosec = key
        self.pub_estimate.publish(msg)
        self.stream.set_correction(k, 0.0 if dv is None else dv, self.actuation_delay)
        if self.reid is not None:
            self.reid.answered(k, 0.0 if dv is None else dv)

    def _capture_factor(self, k: int, est) -> float:
        """1, or 0 while the capture rule holds the correction back (only once the
        control is on: the rule latches on the first controlled section within its
        radius; logged, and a warning once it has held back CAPTURE_PATIENCE sections)."""
        if self.capture is None or not self.law.enabled:
            return 1.0
        factor = self.capture(k, est)
        news = self.capture.news(k)
        if news is not None:
            getattr(self.get_logger(), news[0])(news[1])
        return factor

    def _watch(self, k: int, key: tuple) -> None:
        """Section k of the augmented filter: its innovation to the consistency monitor
        (a mismatch logged, throttled, and counted for /diagnostics), and the row of
        controller/model_watch (ros/model_watch.py)."""
        innovation = self.stream.innovations.pop(k, None)
        if self.monitor is not None and innovation is not None:
            verdict = self.monitor.add(*innovation)
            if verdict is not None:
                self.verdict = verdict
                if verdict.status == "mismatch":
                    self.mismatches += 1
                    if self.first_mismatch is None:
                        self.first_mismatch = k
                    self.mismatch_log(describe_verdict(verdict))
        msg = JointState(name=list(WATCH_FIELDS), position=watch_row(self.stream, self.verdict))
        msg.header.stamp.sec, msg.header.stamp.nanosec = key
        self.pub_watch.publish(msg)

    def _check_phase(self, t: float, effort) -> None:
        """The shaker's phase reference (effort [cos tau, sin tau] or [cos tau]) against the
        phase the sections assume, tau2 + omega t: a rig whose reference disagrees by more
        than 1e-6 is counted and logged (``phase_mismatch``); the estimate goes on."""
        err = phase_error(effort, self._tau2() + self.model.omega * t)
        if not err <= PHASE_TOLERANCE:
            self.phase_mismatch(f"t={t!r}: the stream's phase reference {tuple(effort[:2])} "
                                f"differs by {err:.3g} from tau2 + omega t (sections at "
                                "t_k = k T)")

    def _tau2(self) -> float:
        return self.model.tau2 if self.ndof is None else self.ndof.flow.tau2

    def _section(self, sec: int, nanosec: int) -> int | None:
        """The section index k of a sample stamp t_k = k T (None if it is not one)."""
        t = sec + nanosec * 1e-9
        k = round(t / self.model.period) if self.model is not None else -1
        return k if k >= 0 and abs(t - k * self.model.period) < 1e-6 else None

    def _on_miss(self, msg) -> None:
        """The simulator missed section k's deadline: no answer of ours acted there."""
        k = self._section(msg.header.stamp.sec, msg.header.stamp.nanosec)
        if k is not None:
            self.stream.acted(k, 0.0, self.actuation_delay)
            if self.reid is not None:
                self.reid.acted(k, 0.0)

    def _on_substituted(self, data: bytes) -> None:
        """The prediction that acted at section k in place of our late answer."""
        answer = cdr.read_twist_stamped(data)
        if answer is None or not math.isfinite(answer[2]):
            return
        k = self._section(answer[0], answer[1])
        if k is not None:
            self.stream.acted(k, answer[2], self.actuation_delay)
            if self.reid is not None:
                self.reid.acted(k, answer[2])

    def _on_impact(self, msg) -> None:
        """An impact from the rig's impact sensor (impact_source topic): its time (also
        to the re-identification's record: the refit's impact times)."""
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self.stream.add_impact(t)
        if self.reid is not None:
            self.reid.record.add_impact(t)

    def _check_isolation(self) -> None:
        """Stop with status 1 when more than one simulator publishes the samples."""
        n = self.sub_samples.get_publisher_count()
        if n > 1 and not self.exit_now:
            self.get_logger().error(
                f"{n} publishers on {self.sub_samples.topic_name} (more than one simulator):"
                " the scene is not isolated (another scene on this ROS_DOMAIN_ID and "
                "namespace?)")
            self.exit_code = 1
            self.exit_now = True

    def spin_until(self, executor) -> None:
        """Spin until shutdown, or until the isolation check stops the node.

        The check runs here, between the executor's waits, rather than in a timer: a
        SIGTERM is delivered in whatever Python callback runs next, and in a timer's
        the EventsExecutor logs it as a fatal exception.
        """
        spin(executor, self.between_waits)

    def between_waits(self) -> bool:
        """What runs between two of the executor's waits (here and in a composed
        scene's loop, ros/composed.py): the report of the matches when due
        (ros/matching.py), the isolation check every ISOLATION_CHECK s; True once the
        node must stop."""
        now = time.monotonic()
        self.matched.poll(now)
        if now >= self._next_check:
            self._next_check = now + ISOLATION_CHECK
            self._check_isolation()
        return self.exit_now

    def _use_sim_time(self) -> bool:
        return self.get_clock().ros_time_is_active

    def _on_enable(self, request, response):
        """~/enable: the explicit path to switch the control on or off during a scene;
        logged and published on controller/enabled (recorded: the analysis reports it)."""
        self.law.forced = bool(request.data)
        response.success = True
        response.message = f"controller {'on' if request.data else 'off'} at sample " \
                           f"{self.law.count}"
        self.get_logger().warning(f"~/enable: {response.message}")
        self.pub_enabled.publish(Bool(data=bool(request.data)))
        return response

    def _on_reidentify(self, request, response):
        """~/reidentify (std_srvs/Trigger): start a refit of the last reidentify_periods
        periods (ros/reidentify.py); refused (success false, the reason in the message)
        without the stream's model estimator, while a fit runs, or on too short a
        window. The result is applied at the next Pi2 section."""
        response.success, response.message = (self.reid.request() if self.reid else (
            False, "re-identification needs pi2_source=stream and estimator=model"))
        return response

    def _on_set_parameters(self, params) -> SetParametersResult:
        refused = (refuse_out_of_range(self, params)
                   or refuse_while_running(self, params, self.answered > 0))
        if refused is not None:
            return refused
        values = self._values()
        values.update({p.name: p.value for p in params if p.name in values})
        try:
            if self.ndof is None:
                new = law_from_values(values)
                actuation_delay_from_values(values)     # omega: T must stay > the delay
            else:
                gains = next((p.value for p in params if p.name == "gains"), gains_of(self))
                new = self._ndof_law(values, gains)     # sets self.ndof when valid
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.law.configure(new.gains, new.x_ref, new.v_ref, new.enable_after, new.saturation)
        self.stale_after = float(values["stale_after"])
        log_parameter_changes(self, params)
        return SetParametersResult(successful=True)

    def _diagnose(self, stat):
        """The controller's /diagnostics task (:func:`controller_status.diagnose`)."""
        return diagnose(self, stat)

    def destroy_node(self) -> None:
        """The collector's thresholds back (common.SafePoints), then rclpy's teardown."""
        if getattr(self, "collect", None) is not None:
            self.collect.close()
        super().destroy_node()

    def on_exit(self) -> None:
        """Take what has arrived (message_wait.take_queued), say what was published
        (grazing/published) and log what was answered and ignored, once a recorder has
        confirmed that it holds every message (ACK_TIMEOUT s at most: it may lag on a
        loaded machine, issue 27), or else once the readers acknowledged them (1 s)."""
        take_queued(self.executor, self.inputs, self.context, 1.0)
        if self.count_publishers(self.resolve_topic_name(COMPLETE_TOPIC)) > 0:
            close_publishers(self.published, ACK_TIMEOUT, recorder=self.recorder)
        else:       # the only reader is the simulator, which has gone: no warning
            close_publishers(self.published, 1.0, warn=False)
        self.get_logger().info(
            f"summary: answered={self.answered} controlled_from_sample="
            f"{self.law.enable_after} malformed={self.malformed.count} "
            f"stale={self.stale.count} out_of_order={self.law.out_of_order} "
            f"nonfinite={self.nonfinite.count}"
            + ("" if self.stream is None else
               f" phase_mismatch={self.phase_mismatch.count} stream_ignored="
               f"{self.stream.ignored} model_resets={self.stream.resets}")
            + ("" if not self.watching else
               f" mismatch_sections={self.mismatches} first_mismatch={self.first_mismatch}"
               f" bias={self.stream.bias!r} delta_d={self.stream.delta_d!r}")
            + ("" if self.capture is None else f" {self.capture.summary()}")
            + ("" if self.reid is None else self.reid.summary())
            + ("" if self.rig_side is None else self.rig_side.summary()))


def main(args=None) -> int:
    """Entry point of the ``controller_node`` executable; returns the exit status."""
    return run_node(ControllerNode, args, "controller_node")


if __name__ == "__main__":
    raise SystemExit(main())

"""sim_node: the impact oscillator of the plant layer, as a ROS 2 node (the adapter only).

The simulation is :mod:`grazing_control.plant` (no ROS): :mod:`~grazing_control.plant.settings`
(the parameter table and its validation), :mod:`~grazing_control.plant.engine` (samples and
periods of the exact flow, as :func:`grazing_control.dynamics.simulation.simulate.simulate`),
:mod:`~grazing_control.plant.lockstep` and :mod:`~grazing_control.plant.realtime` (the
two loops: one period per answer, or paced to the wall clock with deadlines), and
:mod:`~grazing_control.plant.faults` (injected loss, measurement noise, jitter). This
file turns answers into loop calls and the loops' output into messages (packed CDR,
:mod:`grazing_control.ros.cdr`); beside it :mod:`sim_node.parameters` (the parameters,
declared from :data:`grazing_control.plant.settings.PARAMETERS`, and live changes),
:mod:`sim_node.start` (the start handshake, isolation, feasibility), :mod:`sim_node.report`
(summary, /diagnostics, verdict), :mod:`sim_node.answer_port` (scheduled answers by their
arrival), :mod:`sim_node.messages` and :mod:`sim_node.rig_io` (the simulated rig's side of
the driver contract). A lockstep run reproduces ``simulate`` of the same scene sample for
sample (docs/nodes.md).

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
that oscillator (the same :mod:`grazing_control.plant.engine` over the model, issue 32)
and publishes every coordinate:
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
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray, String
from std_srvs.srv import Trigger

from grazing_control.oscillator import kernel
from grazing_control.plant.engine import Engine
from grazing_control.plant.lockstep import Lockstep
from grazing_control.plant.realtime import MIN_TICK, Realtime
from grazing_control.ros import cdr, stream_block
from grazing_control.ros.common import (DATA_QOS, EVENT_QOS, LATCHED_QOS, PUBLISHER_QOS,
                                        READY_TOPIC, deserialize, executor_kind,
                                        freeze_heap, publish_parameter_record, run_node,
                                        spin, stamp_key)
from grazing_control.ros.diagnostics import SceneWindow, Updater
from grazing_control.ros.matching import MATCHED_TOPIC, parse_report
from grazing_control.ros.published import (ACK_TIMEOUT, Counted, PublishedRecord,
                                          close_publishers)
from grazing_control.ros.recording.record import TOPIC as RECORD_TOPIC
from grazing_control.ros.recording.record import encode_event
from grazing_control.ros.scene import SceneGuard

from sim_node import report, start
from sim_node.answer_port import AnswerPort
from sim_node.messages import Outputs, read_answer
from sim_node.parameters import declare, on_set_parameters
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
#: No default QoS-event handlers on the data publishers: each one is one more entity in
#: every executor wait (measured: about 10 % of the lockstep rate).
_NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)


class SimNode(Node):
    """The simulator node (module docstring: topics; docs/nodes.md: modes, parameters)."""

    def __init__(self, **kwargs):
        super().__init__("sim_node", **kwargs)
        declare(self)      # the parameters (sim_node/parameters.py): model, rig, settings
        self.engine = Engine(self.settings)
        self.exit_when_done = self.get_parameter("exit_when_done").value
        self.strays = set()          # (topic, node) of bystander publishers, logged once
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
        self.add_on_set_parameters_callback(lambda params: on_set_parameters(self, params))
        self.controller_matched = None  # the controller's report (ros/matching.py), or None
        if self.get_parameter("wait_for_controller").value:
            self.create_subscription(String, MATCHED_TOPIC, self._on_controller_matched,
                                     LATCHED_QOS)
        self.recorder_ready = False
        if self.get_parameter("wait_for_recorder").value:
            self.create_subscription(Bool, READY_TOPIC, self._on_recorder_ready, LATCHED_QOS)
        self.pub_parameters = publish_parameter_record(self)   # grazing/parameters
        # the scene's events on the same topic (record.encode_event): watchdog, feasibility
        self.pub_events = self.create_publisher(String, RECORD_TOPIC, EVENT_QOS)
        self.trip = None              # the watchdog's Trip, once tripped
        self.feasibility = None       # the check before a realtime start (Verdict)
        self.reason = None            # why the scene failed, in one line
        self.probe = False           # False: not started; None: no controller; RoundTrips
        self.probe_start = 0.0
        # compile, or load numba's cache (0.5-0.8 s), while the peers are discovered and
        # the start conditions settle, not in the first period (issue 30)
        self.warming = None
        if kernel.use_kernel():
            self.warming = threading.Thread(target=kernel.warm_up, name="kernel_warm_up",
                                             daemon=True)
            self.warming.start()
        self.summary_line = None          # the summary line logged when the scene ended
        self.scene = SceneGuard(self, self.get_parameter("scene").value)
        self.start_timer = self.create_timer(0.02, self._try_start)
        self._isolation_timer = self.create_timer(ISOLATION_CHECK,
                                                  lambda: start.check_isolation(self))
        self._tick_timer = None
        self.out = Outputs(self)
        self.diagnostics = Updater(self, self.get_parameter("diagnostics_period").value)
        self.window = SceneWindow()
        self.diagnostics.add("scene", lambda stat: report.diagnose(self, stat))
        self.executor_kind = executor_kind(self)
        self.loop = None              # the Lockstep or Realtime loop, once started
        self.refused = False        # refused to start, or failed
        self.created = time.monotonic()       # the start's wait counts from here
        self.wall_start = None
        self.ready_since = None               # since when the start conditions hold
        self._clock_wall = -math.inf   # wall time of the last /clock (realtime)
        self.get_logger().info(f"{self.settings.describe()} executor={self.executor_kind}")

    @property
    def running(self) -> bool:
        """Started and neither done nor failed."""
        return self.loop is not None and not self.loop.finished and not self.refused

    # ------------------------------------------------------------------ start
    def _on_controller_matched(self, msg: String) -> None:
        report = parse_report(msg.data)
        if report is not None:
            self.controller_matched = report

    def _on_recorder_ready(self, msg: Bool) -> None:
        self.recorder_ready = bool(msg.data)

    def _try_start(self) -> None:
        if self.loop is not None:
            # an expiry of the start timer queued before it was destroyed (the events
            # executor delivers it): the scene started twice, its t = 0 samples twice
            return
        if not start.due(self):
            return
        self.destroy_timer(self.start_timer)
        freeze_heap()       # what start-up made (the warmed kernel, the scene): out of reach
        self.wall_start = time.monotonic()
        if self.settings.mode == "lockstep":
            self.loop = Lockstep(self.engine, self.out)
            self.create_timer(min(0.25, self.settings.answer_timeout / 4.0),
                              lambda: self._guard(self.loop.check_timeout))
            self._guard(self.loop.start)
        else:
            self.loop = Realtime(self.engine, self.out)
            self.loop.stream_tick = self.get_parameter("stream_block").value
            # a rig's clock runs on against ROS time (rig_io): its stalls are the loop's
            self.loop.stall_pause = (self.get_parameter("stall_pause").value
                                     if self.driver is None else 0.0)
            self._tick_timer = self.create_timer(MIN_TICK, self._on_tick)
            self._guard(self.loop.start)
            if self.driver is not None:
                self.driver.started()

    def event(self, event: str, **fields) -> None:
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
        self.event("watchdog", kind=trip.kind, k=trip.k, t=trip.t, reason=trip.reason)
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
        key, dv, predicted, start = answer
        rearm = self._guard(self.loop.answer, key, dv, predicted, arrived, start)
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
            self.loop.resume(wall)       # a stall of this process: the plant paused first
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
        self.loop.expect(wake)

    def _guard(self, call, *args):
        """Run a loop call; a refusal of the core (impact cap, state beyond the wall)
        stops the scene with exit status 1 instead of crashing the node."""
        if not self.running:
            return None
        try:
            return call(*args)
        except Exception as exc:
            self.fail(exc)
            return None
        finally:
            self.out.end_of_wake_up()     # the stream's block, with stream_message block

    # ------------------------------------------------------------ end, failure
    def finish(self) -> None:
        """max_periods have run: oscillator/done, the summary, exit if asked."""
        self.pub_done.publish(Bool(data=True))
        self.summary_line = report.summary(self)      # the wall time of the scene, not of the exit
        self.get_logger().info(self.summary_line)
        if self.exit_when_done:
            self.exit_now = True

    def fail(self, exc: Exception) -> None:
        self.reason = self.reason or f"simulation stopped at t={self.engine.t:.9g}: {exc}"
        self.get_logger().error(f"simulation stopped at t={self.engine.t:.9g}: {exc}")
        self.exit_code = 1
        self.refused = True
        self.exit_now = True

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
            # kept for the verdict: computed there, after the wait for acknowledgements
            # below, its wall time (and pace) took that wait in
            self.summary_line = report.summary(self) + " (interrupted)"
            self.get_logger().info(self.summary_line)
        if not self.published.sent:
            close_publishers(self.published, INTERRUPTED_ACK_TIMEOUT)
        path = self.get_parameter("verdict_file").value
        if path:
            report.write_verdict(path, report.verdict(self))

    # ----------------------------------------------------------- services, params
    def _on_reset(self, request, response):
        ev = self.engine.reset()
        response.success = True
        response.message = "reset to the initial state, sample 0 at t=0"
        self.get_logger().info(response.message)
        if self.loop is not None:
            self.refused = False
            self.loop.finished = False
            self._guard(self.loop.reset, ev)
        return response


def main(args=None) -> int:
    """Entry point of the ``sim_node`` executable; returns the exit status."""
    return run_node(SimNode, args, "sim_node")


if __name__ == "__main__":
    raise SystemExit(main())

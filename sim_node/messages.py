"""sim_node's messages: the plant loops' output as messages and log lines, answers read.

:class:`Outputs` is the :class:`grazing_control.plant.loop.Sink` of the node: each
:class:`grazing_control.plant.engine.Event` goes out as packed CDR
(:mod:`grazing_control.ros.cdr`) on its topic (docs/nodes.md, "Topics"); what the loops
count (ignored, malformed, late answers, timeouts, deadline misses) is logged at most
once per two seconds per kind (:class:`grazing_control.ros.common.Throttled`).
:func:`read_answer` reads a controller's answer (Delta v and its prediction for the next
sample, issue 16 §3).
"""

from __future__ import annotations

import math

from rclpy.duration import Duration

from grazing_control.plant.engine import Event, NdofEvent
from grazing_control.ros import cdr, stream_block
from grazing_control.ros.common import Throttled

__all__ = ["Outputs", "read_answer", "joint_names", "ndof_joint_state"]

#: Lockstep: wall seconds to wait for every reader to acknowledge a substitution.
ACKED_WAIT = 5.0


def joint_names(n: int) -> list:
    """The joint names of an n-DOF scene's JointState messages: mass0 .. mass{n-1}."""
    return [f"mass{i}" for i in range(n)]


def ndof_joint_state(ev: NdofEvent, names: list):
    """sensor_msgs/JointState of an n-DOF state (issue 17): stamp = ev.t, one joint per
    coordinate (``names``), position [x_0 .. x_{n-1}], velocity [v_0 .. v_{n-1}], effort
    [cos tau] (Pi1, Pi2) or [cos tau, sin tau] (the state stream), as the 1-DOF messages;
    a position-only sensor's stream sample has no velocity."""
    from sensor_msgs.msg import JointState

    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = cdr.stamp_parts(ev.t)
    msg.name = names
    msg.position = [float(x) for x in ev.x]
    # a position-only sensor's stream (NaN velocities): no velocity, as the 1-DOF stream
    msg.velocity = ([] if ev.kind == "state" and all(math.isnan(v) for v in ev.v)
                    else [float(v) for v in ev.v])
    msg.effort = ([math.cos(ev.phase), math.sin(ev.phase)] if ev.kind == "state"
                  else [math.cos(ev.phase)])
    return msg

def read_answer(data: bytes):
    """(stamp key, Delta v = twist.linear.x, the Delta v predicted for the next sample =
    twist.linear.y, NaN for none) of a TwistStamped in the controller's layout
    (:func:`cdr.read_twist_stamped`), else None (issue 16 §3)."""
    answer = cdr.read_twist_stamped(data)
    if answer is None:
        return None
    sec, nanosec, dv, predicted = answer
    return (sec, nanosec), dv, predicted


#: The verdict file lists the first this many missed deadlines (sample, actuation time).
MISSES_KEPT = 100


class Outputs:
    """The loops' sink (:class:`grazing_control.plant.loop.Sink`): topics and log lines."""

    def __init__(self, node):
        self.node = node
        log = node.get_logger()
        self.ignored = Throttled(log, "correction ignored")
        self.malformed = Throttled(log, "malformed correction ignored")
        self.timeout = Throttled(log, "no correction within answer_timeout, none applied")
        self.misses = Throttled(log, "deadline missed: no correction at the actuation time, "
                                     "none applied")
        self.late = Throttled(log, "answer after its deadline dropped")
        # for the verdict file: which deadlines were missed (the log is throttled), and
        # the longest pause of the plant's clock with its simulation time
        self.missed: list[dict] = []
        self.longest_pause: dict | None = None
        self.warn = log.warning
        self._names = None         # joint names of n-DOF messages (mass0 ..)
        # stream_message block: the wake-up's stream samples, one message at its end
        self.block = (stream_block.Block()
                      if node.get_parameter("stream_message").value == "block" else None)

    def publish(self, ev: Event) -> tuple:
        """Publish an event as packed CDR; its stamp as (sec, nanosec)."""
        n = self.node
        sec, ns = stamp = cdr.stamp_parts(ev.t)
        if isinstance(ev, NdofEvent):
            return self._publish_ndof(ev, stamp)
        if n.driver is not None:              # a simulated rig: the contract's topics too
            n.driver.event(ev)
        if ev.kind == "impact":
            n.pub_impact.publish(cdr.vector3_stamped(sec, ns, ev.x, ev.v, ev.phase))
            return stamp
        if ev.kind == "state":                 # the rig's sensor stream
            v = ev.v if n.settings.sensor.velocity else None
            if self.block is not None:         # out at the wake-up's end
                self.block.add(sec, ns, (ev.x,), None if v is None else (v,),
                               math.cos(ev.phase), math.sin(ev.phase))
                return stamp
            n.pub_state.publish(cdr.stream_sample(sec, ns, ev.x, v, math.cos(ev.phase),
                                                  math.sin(ev.phase)))
            return stamp
        data = cdr.joint_state(sec, ns, ev.x, ev.v, math.cos(ev.phase))
        if ev.kind == "pi1":
            n.pub_pi1.publish(data)
        elif ev.kind == "pi2":
            if n.settings.mode == "lockstep":
                n.pub_clock.publish(cdr.clock(sec, ns))
            # the section's last samples before the section (issue 30: held to the end of
            # the wake-up, they waited for the period's integration that follows the
            # sample, ~0.6 ms of the answer's budget at T/200 x1000)
            self.end_of_wake_up()
            n.pub_pi2.publish(data)
        return stamp

    def _publish_ndof(self, ev: NdofEvent, stamp: tuple) -> tuple:
        """An n-DOF state (state stream, Pi1, Pi2) as a JointState with n joints; with
        stream_message block a stream sample as a row of n positions and n velocities
        (NaN: the JointState's empty velocity) of the wake-up's block."""
        n = self.node
        if n.driver is not None:              # a simulated rig of n masses: rig/sensor ..
            n.driver.event(ev)
        if ev.kind == "state" and self.block is not None:     # out at the wake-up's end
            self.block.add(*stamp, ev.x, ev.v, math.cos(ev.phase), math.sin(ev.phase))
            return stamp
        if self._names is None or len(self._names) != len(ev.x):
            self._names = joint_names(len(ev.x))
        msg = ndof_joint_state(ev, self._names)
        if ev.kind == "state":
            n.pub_state.publish(msg)
        elif ev.kind == "pi1":
            n.pub_pi1.publish(msg)
        elif ev.kind == "pi2":
            if n.settings.mode == "lockstep":
                n.pub_clock.publish(cdr.clock(*stamp))
            self.end_of_wake_up()              # the section's last samples first
            n.pub_pi2.publish(msg)
        return stamp

    def end_of_wake_up(self) -> None:
        """After each loop call (sim_node's _guard), and before each Pi2 sample: the
        stream samples gathered, as one block on oscillator/state_block (stream_message
        block; none gathered: nothing)."""
        if self.block is not None and len(self.block):
            self.node.pub_state_block.publish(self.block.take())

    def latency(self, seconds: float) -> None:
        self.node.pub_latency.publish(cdr.float64(seconds))

    def miss(self, k: int, key: tuple, t: float, waited: float) -> None:
        self.misses(f"sample {k} (stamp {key}), actuation at t={t:.9g}, "
                    f"{waited * 1e3:.3f} ms after the sample went out")
        if len(self.missed) < MISSES_KEPT:
            self.missed.append({"k": k, "t": t, "waited_ms": waited * 1e3})
        self.node.pub_miss.publish(cdr.vector3_stamped(*key, float(k), t, waited))

    def substituted(self, k: int, key: tuple, dv: float) -> None:
        pub = self.node.pub_substituted
        pub.publish(cdr.twist_stamped(*key, dv))
        if self.node.settings.mode == "lockstep":
            # The period's stream follows on another topic, and topics keep no order
            # between them at a reader: a stream controller took the substitution after
            # the sample that made the next section due (its estimate then used the
            # answer, not what acted: in 1 of about 10 of test_stream_replay's scenes with
            # three at once, 2026-11-29). Lockstep waits until every reader has it; realtime
            # cannot wait, and a late substitution there is what a rig would see too.
            pub.wait_for_all_acked(Duration(seconds=ACKED_WAIT))

    def paused(self, t: float, seconds: float) -> None:
        """A pause of the plant's clock (Realtime.resume): an event record (recorded with
        the scene: the analysis keeps its sample lag on the paused clock); counted in the
        summary line and on /diagnostics, not logged one by one; the longest is kept for
        the verdict file."""
        if self.longest_pause is None or seconds > self.longest_pause["seconds"]:
            self.longest_pause = {"t": t, "seconds": seconds}
        self.node.event("paused", t=t, seconds=seconds)

    def tripped(self, trip) -> None:
        self.node.on_trip(trip)

    def serialise(self, ev: Event) -> None:
        """What :meth:`publish` makes of ``ev`` without publishing it (the feasibility
        check's rate measurement, plant.feasibility.sustained_rate)."""
        sec, ns = cdr.stamp_parts(ev.t)
        if isinstance(ev, NdofEvent):
            if self._names is None or len(self._names) != len(ev.x):
                self._names = joint_names(len(ev.x))
            ndof_joint_state(ev, self._names)
        elif ev.kind == "impact":
            cdr.vector3_stamped(sec, ns, ev.x, ev.v, ev.phase)
        elif ev.kind == "state":
            cdr.stream_sample(sec, ns, ev.x, ev.v if self.node.settings.sensor.velocity
                              else None, math.cos(ev.phase), math.sin(ev.phase))
        else:
            cdr.joint_state(sec, ns, ev.x, ev.v, math.cos(ev.phase))

    def finish(self) -> None:
        self.node.finish()

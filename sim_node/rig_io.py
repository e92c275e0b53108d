"""sim_node as a driver of the rig contract (docs/driver_contract.md): the simulated rig.

With ``rig_file`` the simulator is one backend of the contract: besides its
dimensionless topics (the ground truth, which analyze and the recorder read) it
publishes what a rig's driver publishes, in SI and in the rig's own clock
(:class:`grazing_control.ros.rig_boundary.SimulatedClock`):

* ``rig/sensor`` (sensor_msgs/JointState): each sample of the sensor stream in metres
  (and m/s where the sensor measures velocity), stamped with the rig time it was taken,
  published no earlier than that time + the sensor's latency
  (:class:`~grazing_control.ros.rig_boundary.DelayLine`);
* ``rig/phase`` (geometry_msgs/Vector3Stamped): at each Pi2 section, the forcing
  frequency (Hz) and its phase (rad) at that rig time;
* ``rig/clock`` (sensor_msgs/TimeReference): ROS time against the rig clock, read
  together, ``clock_rate`` times a second;
* ``grazing/rig`` (std_msgs/String, transient local, depth 1): the rig file's YAML
  (:func:`grazing_control.plant.rig.rig_to_dict`);
* ``rig/applied`` (geometry_msgs/WrenchStamped): what acted at each section, at its
  actuation instant.

It takes ``rig/force_pulse`` (geometry_msgs/WrenchStamped) as the answer of its section:
the force F over the width w is the correction Delta v~ = F w / (m omega_n l) of the
section t_k (torque.y, rig clock), with force.y the prediction, handed to the loop's
``answer`` like a ``controller/velocity_correction``. A command whose section and apply
time are the rig's own (within 1e-6 of a period) acts at the rig's actuation instant, as
the loop's own sections do; any other is timed output (docs/driver_contract.md, "Off the
rig's section"): it is the command of the section whose slot [t_k, t_k + T - w - L] (model
time; L the actuator's latency) holds its apply time, and its pulse starts there.
"""

from __future__ import annotations

import math
import time

import yaml
from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from sensor_msgs.msg import JointState, TimeReference
from std_msgs.msg import String

from grazing_control.plant.rig import rig_to_dict
from grazing_control.plant.schedule import slot
from grazing_control.ros import cdr
from grazing_control.ros.common import LATCHED_QOS, stamp_from_seconds
from grazing_control.ros.rig_driver import applied_message, read_pulse
from grazing_control.ros.rig_boundary import (APPLIED_SAFE, DelayLine, Pacer, SimulatedClock,
                                              correction_of, force_of, joint_names,
                                              sensor_positions)

__all__ = ["SimulatedRig", "CLOCK_READ"]

#: Longest wall time (s) between the two wall-clock reads around a ROS clock read of a
#: rig/clock pair: beyond, the process was preempted in between and the pair is skipped.
CLOCK_READ = 5e-5

#: Reads of a rig/clock pair tried in one call before it is left for the next.
READ_TRIES = 5


class SimulatedRig:
    """The simulated rig's side of the contract for one :class:`~sim_node.sim_node.SimNode`
    (module docstring). ``publisher(kind, topic)`` makes the node's counted publishers."""

    def __init__(self, node, rig, publisher, clock_start: float, clock_rate: float):
        self.node, self.rig = node, rig
        s = node.settings
        self.clock = SimulatedClock(rig, clock_start, s.time_scale)
        self.latency = DelayLine(rig.sensor.latency * rig.omega_n)
        self.velocity = rig.sensor.velocity
        self.pub_sensor = publisher(JointState, "rig/sensor")
        self.pub_phase = publisher(Vector3Stamped, "rig/phase")
        self.pub_clock = publisher(TimeReference, "rig/clock")
        self.pub_applied = publisher(WrenchStamped, "rig/applied")
        self.pub_rig = node.create_publisher(String, "grazing/rig", LATCHED_QOS)
        self.pub_rig.publish(String(data=yaml.safe_dump(rig_to_dict(rig), sort_keys=False)))
        self.applied = [0, 0, 0, 0]  # counts per rig/applied status
        self.timed = {}              # key -> (model start, rig start) of timed commands
        self.name = node.get_fully_qualified_name()
        self._pairs = Pacer(1.0 / clock_rate)      # rig/clock, asked by timer and loop
        self._clock_timer = node.create_timer(self._pairs.period, self.publish_clock)

    @property
    def publishers(self) -> tuple:
        return self.pub_sensor, self.pub_phase, self.pub_clock, self.pub_applied

    # --------------------------------------------------------------- the loop's events
    def read_clocks(self):
        """(ROS time, model time) read at one moment: the wall clock read on both sides of
        the ROS clock, the model time at their midpoint; None when the two reads lie more
        than CLOCK_READ apart (the process was preempted: the pair would be off)."""
        loop, clock = self.node.loop, self.node.get_clock()
        before = loop.clock()
        ros = clock.now()
        after = loop.clock()
        if after - before > CLOCK_READ:
            return None
        return ros, loop.now(0.5 * (before + after))

    def started(self) -> None:
        """The loop has started: the relation of the rig clock to ROS time, and what its
        actuation engine acts is also said on rig/applied (ActuationSchedule.act, called
        by the loop at each section's start, is wrapped)."""
        schedule = self.node.loop.schedule
        engine_act = schedule.act

        def act(sec, lost=False, on_miss="predict"):
            done = engine_act(sec, lost=lost, on_miss=on_miss)
            self.act(done)
            return done

        schedule.act = act
        read = None
        while read is None:
            read = self.read_clocks()
        ros, t = read
        self.clock.started(ros.nanoseconds * 1e-9, t)
        self.node.get_logger().info(
            f"simulated rig clock: ROS time = {self.clock.offset:.9f} s + (1 + "
            f"{self.clock.drift:.6g}) x rig time; the scene starts at rig time "
            f"{self.clock.start:.9f} s; the rig's clock runs on through a stall of the "
            "simulator, as a rig's does (stall_pause does not apply)")

    def event(self, ev) -> None:
        """A published event of the loop: a stream sample into the latency's delay line,
        a Pi2 sample as the phase reference of its section."""
        if ev.kind == "state":
            self.latency.push(ev.t, (ev.t, ev.x, ev.v))
        elif ev.kind == "pi2":
            s = self.clock.rig_time(ev.t)
            msg = Vector3Stamped()
            msg.header.stamp = stamp_from_seconds(s)
            msg.vector.x = float(self.rig.frequency)
            msg.vector.y = float(self.clock.phase(s))
            self.pub_phase.publish(msg)

    def flush(self, now: float) -> None:
        """Publish the stream samples whose latency has passed at model time ``now``
        (and the rig/clock pair when one is due)."""
        self.publish_clock()
        l, vs = self.rig.scales.length, self.rig.scales.velocity
        if self.rig.n > 1:
            self._flush_masses(now)
            return
        for t, x, v in self.latency.due(now):
            sec, ns = cdr.stamp_parts(self.clock.rig_time(t))
            self.pub_sensor.publish(cdr.rig_sample(sec, ns, float(x) * l,
                                                   float(v) * vs if self.velocity else None))

    def _flush_masses(self, now: float) -> None:
        """:meth:`flush` of a rig of n masses: one JointState per sample with the measured
        masses (rig_boundary.joint_names: mass<i> in sensor.masses order), positions in
        metres (rig_boundary.sensor_positions), velocities in m/s where the sensor
        measures them (packed: cdr.rig_sample_masses)."""
        names, vs = joint_names(self.rig), self.rig.scales.velocity
        for t, x, v in self.latency.due(now):
            sec, ns = cdr.stamp_parts(self.clock.rig_time(t))
            self.pub_sensor.publish(cdr.rig_sample_masses(
                sec, ns, names, sensor_positions(self.rig, x),
                [float(v[i]) * vs for i in self.rig.measured] if self.velocity else None))

    def wake_in(self, now: float) -> float:
        """Wall seconds until the next held sample is due (inf: none), no sooner than the
        loop's ``stream_tick``, as its own stream (a DAQ's block): each wake-up costs, and at
        one per sample the simulator's events queued up under load (the answers of a
        recorded scene reached it seconds late, 792 of 900 ignored)."""
        due = (self.latency.next_time() - now) / self.node.settings.time_scale
        return max(due, self.node.loop.stream_tick)

    def publish_clock(self) -> None:
        """rig/clock: ROS time and the rig clock, read together (while the scene runs),
        ``clock_rate`` times a wall second (:class:`Pacer`): asked by its timer and by
        every wake-up of the loop (:meth:`flush`). Paced, not one per call: a timer fired
        in bursts after a stall (an overloaded scene's bag held 91,322 pairs where 20 Hz
        gives about 1,350); and asked from the loop too, since the timer alone gave 55
        pairs over a 7.2 s scene on a loaded CI host, where the contract wants 10 a
        second. A read preempted between its clocks is tried again (READ_TRIES), then
        left due for the next call."""
        node = self.node
        if not node.running:
            return
        wall = time.monotonic()
        if not self._pairs.due(wall):
            return
        for _ in range(READ_TRIES):
            read = self.read_clocks()
            if read is not None:
                break
        else:
            return                      # preempted at every try: due at the next call
        self._pairs.done(wall)
        ros, t = read
        rig = self.clock.rig_time(t)
        msg = TimeReference()
        msg.header.stamp = ros.to_msg()
        msg.time_ref = stamp_from_seconds(rig)
        msg.source = self.name
        self.pub_clock.publish(msg)

    # ------------------------------------------------------------------ answers
    def answer(self, data: bytes):
        """(stamp key, Delta v~, predicted Delta v~, start) of a serialized
        rig/force_pulse (:func:`grazing_control.ros.rig_driver.read_pulse`), or None
        (counted as malformed) when it is malformed or its apply time lies in no slot of
        this rig (:meth:`slot`). ``start``: None for a command of the rig's own section
        and instant, else the model time its pulse starts (the loop's timed answer)."""
        fields = read_pulse(data, self.node.out.malformed)
        if fields is None:
            return None
        t_k, apply, f, fy, w = fields
        engine = self.node.engine
        period = engine.p.period
        t, s = self.clock.model_time(t_k), self.clock.model_time(apply)
        k = round(t / period)
        own = engine.actuation_start(self.node.settings.actuation_delay)
        tol = 1e-6 * period
        start = None
        if k < 0 or abs(t - k * period) > tol or abs(s - k * period - own) > tol:
            k = self.slot(s)
            if k is None:
                self.node.out.malformed(
                    f"rig/force_pulse apply time={apply!r} s (model time {s!r}) of section "
                    f"{t_k!r} s lies in no slot of this rig (a pulse starts in "
                    f"[t_k, t_k + {self.room():.6g}) of a section t_k = k {period!r}, k >= 0)")
                return None
            start = s
            self.timed.setdefault(cdr.stamp_parts(k * period), (s, apply))
            if len(self.timed) > 8:
                del self.timed[next(iter(self.timed))]
        return (cdr.stamp_parts(k * period), correction_of(self.rig, f, w),
                correction_of(self.rig, fy, w), start)

    def room(self) -> float:
        """The latest start of a pulse after its section (model time): T - w - L, so
        that the pulse (through the actuator's latency L) ends within the period."""
        s = self.node.settings
        return self.node.engine.p.period - s.pulse_width - s.actuator.latency

    def slot(self, s: float) -> int | None:
        """The section whose slot holds model time ``s`` (a command's apply time;
        :func:`grazing_control.plant.schedule.slot`), or None."""
        return slot(s, self.node.engine.p.period, self.room())

    def act(self, act) -> None:
        """What acted at a section (the actuation engine's
        :class:`~grazing_control.plant.schedule.Act`): rig/applied."""
        sec = act.section
        timed = self.timed.pop(sec.key, None)
        rig_start = timed[1] if timed is not None and timed[0] == sec.start else None
        self.publish_applied(float(act.code), act.value, sec.start, sec.t, rig_start)

    def tripped(self, k: int) -> None:
        """The watchdog tripped at section k: nothing acts there (the safe state)."""
        period = self.node.engine.p.period
        t = k * period
        self.publish_applied(APPLIED_SAFE, 0.0,
                             t + self.node.engine.actuation_start(self.node.loop.delay), t)

    def publish_applied(self, status: float, dv: float, start: float, t_k: float,
                        rig_start: float | None = None) -> None:
        """rig/applied (:func:`grazing_control.ros.rig_driver.applied_message`): the
        force that acted (N, clipped to the force limit) from the pulse's start
        ``start`` of the section at ``t_k`` (model times); ``rig_start``: the start in
        the rig clock, given (a timed command's own apply time, exactly as sent)."""
        self.applied[int(status)] += 1
        force = force_of(self.rig, dv)
        limit = self.rig.actuator.force_limit
        if limit > 0.0:
            force = max(-limit, min(limit, force))
        self.pub_applied.publish(applied_message(
            self.clock.rig_time(start) if rig_start is None else rig_start,
            self.clock.rig_time(t_k),
            self.rig.actuator.pulse_width, force, math.nan, int(status)))

    def summary(self) -> str:
        a = self.applied
        return (f" rig_applied in_time={a[0]} predicted={a[1]} nothing={a[2]} safe={a[3]} "
                f"clock_offset={self.clock.offset:.9f} clock_drift={self.clock.drift:.12g}")

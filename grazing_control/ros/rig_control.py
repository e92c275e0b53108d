"""controller_node's side of the driver contract (docs/driver_contract.md), with a rig file.

The controller reads the rig's ``rig/sensor`` (SI, rig clock) and ``rig/phase`` (the
forcing's phase reference), converts each sample to the model's units and time
(:class:`grazing_control.ros.rig_boundary.Sections`: the sections are where the rig's
forcing phase equals tau2) and feeds the node's stream estimator with it; each section's
answer goes out as the dimensionless ``controller/velocity_correction`` (analyze and
replay read it) and as the scheduled ``rig/force_pulse`` (force F = m Delta v / w in N,
apply time t_k + budget - w / 2 and section time t_k in the rig clock, the predicted next
force in force.y). ``rig/clock`` gives the clock relation (offset and drift of the rig
clock against ROS time, :class:`grazing_control.dynamics.estimation.clock_relation.ClockRelation`);
with it each sample's arrival latency (ROS time of its arrival less the ROS time of its
stamp) is measured. ``rig/applied`` tells the estimator what acted where a prediction
stood in or nothing acted (its model must integrate the kick that acted). The commands
are a function of the stamps and values of these inputs, never of their arrival time
(the answer_lead is a stretch of stamps), so that a replay through mock hardware
(:mod:`grazing_control.recordings.rig_replay`) gives them again bit for bit:

* no sample is lost to a lagging controller (rig/sensor and rig/applied are read with
  :data:`common.INPUT_QOS`, keep last 100000: 50 s at 2 kHz; with keep last 1000 a
  controller half a second behind lost whole periods);
* the estimate of section k + 1 integrates what acted at section k: once the driver has
  sent a first rig/applied (it reports each section, docs/driver_contract.md), a sample
  that would make section k + 1 due is held until section k's rig/applied has come
  (:meth:`RigSide._sample`; it normally comes most of a period earlier, and nothing
  waits; a later section's rig/applied ends the wait: that one was skipped); held
  samples are fed in order. A driver that stays silent is waited for only up to the
  samples of HOLD_PERIODS more periods (stamps, not a clock: ``applied_waited_out``
  counts it), and a rig/applied after the estimate that needed it is counted
  (``applied_after_use``).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from sensor_msgs.msg import JointState

from grazing_control.dynamics.estimation.clock_relation import ClockRelation
from . import cdr
from .common import deserialize, seconds_from_stamp, stamp_from_seconds, stamp_key
from .diagnostics import WARN
from .rig_boundary import (APPLIED_IN_TIME, APPLIED_PREDICTED, Sections, correction_of,
                           force_of, joint_names, model_positions)

__all__ = ["RigSide", "PENDING_SAMPLES", "LATENCIES"]

#: Sensor samples kept until the first phase reference fixes the sections.
PENDING_SAMPLES = 4096
#: How long a sample waits for the previous section's rig/applied: until the samples of
#: this many periods after its section have come (the simulated rig at load 10 sent one
#: 2.2 periods after the samples it followed; a driver that stays silent costs that).
HOLD_PERIODS = 4
#: Sections whose rig/applied is remembered.
REPORTED = 64
#: Arrival latencies kept for the percentiles (/diagnostics, the exit summary).
LATENCIES = 100_000


class RigSide:
    """The contract's topics for one controller node (module docstring)."""

    def __init__(self, node, rig, clock_window: int):
        self.node, self.rig = node, rig
        self.sections = Sections(rig)
        self.clock = ClockRelation(clock_window)
        self.length, self.velocity = rig.scales.length, rig.scales.velocity
        self.pending = deque(maxlen=PENDING_SAMPLES)
        self.latencies = deque(maxlen=LATENCIES)
        self.phase_mismatch = 0
        self.pulses = 0
        self.applied = [0, 0, 0, 0]
        self.applied_after_use = 0       # rig/applied after the estimate that needed it
        self.reported = deque(maxlen=REPORTED)   # sections whose rig/applied came
        self.held = deque()              # (t, x~, v~) held for a section's rig/applied
        self.acts = deque(maxlen=REPORTED)   # (k, dv): what acted, not told the estimator yet
        self.applied_waited_out = 0      # sections estimated without it (silent driver)
        self.names = tuple(joint_names(rig))   # rig/sensor's names (n masses)
        self.joint = None                # the read mass's entry in them (set at first use)

    # ---------------------------------------------------------------- driver -> us
    def on_phase(self, msg) -> None:
        ok = self.sections.reference(seconds_from_stamp(msg.header.stamp), msg.vector.x,
                                     msg.vector.y)
        if not ok:
            self.phase_mismatch += 1
            self.node.phase_mismatch(
                f"rig/phase at {seconds_from_stamp(msg.header.stamp)!r} s: f={msg.vector.x!r} "
                f"Hz, phase {msg.vector.y!r} rad disagree with the rig file's forcing "
                f"({self.rig.frequency!r} Hz) and the sections fixed by the first reference")
        while self.pending and self.sections.origin is not None:
            self._sample(*self.pending.popleft())

    def on_clock(self, msg) -> None:
        self.clock.add(seconds_from_stamp(msg.time_ref), seconds_from_stamp(msg.header.stamp))

    def on_sensor(self, data: bytes) -> None:
        """A rig/sensor sample as received (serialized: read directly, cdr.read_state,
        else through rclpy; SI, rig clock): its arrival latency, then to the estimator in
        the model's units (held until the first phase reference)."""
        arrival = self.node.get_clock().now().nanoseconds * 1e-9
        sample = self._masses_sample(data) if self.rig.n > 1 else cdr.read_state(data)
        if sample is None and self.rig.n > 1:
            return
        if sample is None:
            msg = deserialize(data, JointState, self.node.malformed)
            if msg is None:
                return
            if len(msg.position) < 1:
                self.node.malformed(f"rig/sensor at {stamp_key(msg.header.stamp)}: no position")
                return
            v = msg.velocity[0] if len(msg.velocity) else math.nan
            sample = stamp_key(msg.header.stamp) + (msg.position[0], v, ())
        sec, ns, x, v, _effort = sample
        s = sec + ns * 1e-9
        if not math.isfinite(x) or math.isinf(v):
            self.node.malformed(f"rig/sensor at {s!r} s: x={x!r} v={v!r}")
            return
        fit = self.clock.fit
        if fit is not None and fit.n >= 2:
            self.latencies.append(arrival - fit.ros_time(s))
        if self.sections.origin is None:
            self.pending.append((s, x, v))
            return
        self._sample(s, x, v)

    def _masses_sample(self, data: bytes):
        """(sec, nanosec, x, v, ()) of a rig/sensor message of a rig of n masses: the
        position (m) and velocity (m/s, NaN: none) of the mass the stream estimator reads
        (its ``sensor_coordinate``, a measured mass); None (counted as malformed, with
        rig_boundary.model_positions' line) for a message whose names are not the rig's
        measured masses or whose position count differs. Read directly
        (:func:`cdr.read_joints`), else through rclpy. At 2 kHz: the names compared
        once as a tuple, the read mass's entry found once (the other positions are not
        converted: the estimator does not read them)."""
        fields = cdr.read_joints(data)
        if fields is None:
            msg = deserialize(data, JointState, self.node.malformed)
            if msg is None:
                return None
            fields = stamp_key(msg.header.stamp) + (msg.name, msg.position, msg.velocity)
        sec, ns, names, positions, velocities = fields
        if tuple(names) != self.names or len(positions) != len(self.names):
            try:
                model_positions(self.rig, names, positions)   # raises its one line
            except ValueError as exc:
                self.node.malformed(f"rig/sensor at {(sec, ns)}: {exc}")
            return None
        j = self.joint
        if j is None:
            j = self.joint = self.rig.measured.index(self.node.stream.coordinate)
        v = velocities[j] if len(velocities) == len(names) else math.nan
        return sec, ns, positions[j], v, ()

    def _sample(self, s: float, x: float, v: float) -> None:
        """A sample to the estimator in the model's units, held while it would make a
        section due before the previous section's rig/applied came (module docstring)."""
        self.held.append((self.sections.model_time(s), x / self.length, v / self.velocity))
        self._release()

    def _waits(self, t: float) -> bool:
        """Whether a sample at model time t must wait for a rig/applied: the driver
        reports sections, t would make section k due (t + h + lead >= t_k, a sample
        period early to be safe: holding one more is harmless), and neither section
        k - 1's rig/applied nor a later section's (k - 1 was skipped) has come. For at
        most the samples of HOLD_PERIODS periods after t_k (then counted)."""
        stream = self.node.stream
        k = stream.next_k
        if not self.reported or k is None or k < 1:
            return False
        period, h = self.node.model.period, stream.sample_period
        if t + 2.0 * h + stream.lead < k * period:
            return False
        if (k - 1) in self.reported or max(self.reported) >= k:
            return False
        if self.held[-1][0] > (k + HOLD_PERIODS) * period:
            self.applied_waited_out += 1
            self.reported.append(k - 1)   # wait no longer for it
            return False
        return True

    def _release(self) -> None:
        """Feed the held samples, in order, up to one that must wait; before each, what
        acted at the sections already answered (:meth:`_flush_acts`)."""
        while self.held and not self._waits(self.held[0][0]):
            self._flush_acts()
            self.node.add_stream_sample(*self.held.popleft())

    def _flush_acts(self) -> None:
        """Tell the estimator what acted at each section it has answered (k < next_k),
        in section order: always after its own answer to that section, never one that
        is still ahead (a rig/applied that came early, while the controller lagged,
        would make the estimator forget older corrections before their last use)."""
        stream = self.node.stream
        while self.acts and stream.next_k is not None and self.acts[0][0] < stream.next_k:
            k, dv = self.acts.popleft()
            stream.acted(k, dv, self.node.actuation_delay)

    def on_applied(self, msg) -> None:
        """What acted at a section (rig/applied): where a prediction stood in (1) the
        estimator integrates its force, where nothing acted (2, 3) none."""
        status = msg.wrench.force.z
        if status not in (0.0, 1.0, 2.0, 3.0) or self.sections.origin is None:
            return
        self.applied[int(status)] += 1
        t = self.sections.model_time(msg.wrench.torque.y)
        period = self.node.model.period
        k = round(t / period)
        if k < 0 or abs(t - k * period) > 1e-6 * period:
            return
        if status != APPLIED_IN_TIME:
            self._acted(k, status, msg)
        if k not in self.reported:
            self.reported.append(k)
        self._release()

    def _acted(self, k: int, status: float, msg) -> None:
        """What acted at section k where it was not our answer in time."""
        stream = self.node.stream
        if stream.next_k is not None and k + 1 < stream.next_k:
            self.applied_after_use += 1  # section k + 1 was estimated with the answer
        dv = 0.0
        if status == APPLIED_PREDICTED and msg.wrench.torque.x > 0.0:
            dv = correction_of(self.rig, msg.wrench.force.x, msg.wrench.torque.x)
        self.acts.append((k, dv))        # told the estimator in _flush_acts

    # ---------------------------------------------------------------- us -> driver
    def answered(self, t: float, dv: float, predicted: float) -> None:
        """Section k at model time ``t`` answered with ``dv`` (its ``predicted`` next):
        rig/force_pulse."""
        t_k = self.sections.rig_time(t)
        stamp = stamp_from_seconds(self.sections.apply_time(t_k))
        force = (float(force_of(self.rig, dv)),
                 float(force_of(self.rig, predicted)) if math.isfinite(predicted) else math.nan,
                 0.0)
        torque = (float(self.rig.actuator.pulse_width), float(t_k), 0.0)
        self.node.pub_force.publish(cdr.wrench_stamped(stamp.sec, stamp.nanosec, force, torque))
        self.pulses += 1

    # ---------------------------------------------------------------- reporting
    def numbers(self) -> dict:
        """The clock relation and the sensor samples' arrival latency (s)."""
        fit = self.clock.fit
        out = {"clock_offset": math.nan, "clock_drift": math.nan, "clock_jitter": math.nan,
               "clock_pairs": 0}
        if fit is not None:
            out.update(clock_offset=fit.offset, clock_drift=fit.drift,
                       clock_jitter=fit.jitter, clock_pairs=fit.n)
        if self.latencies:
            lat = np.asarray(self.latencies)
            out.update(sensor_latency_p50=float(np.percentile(lat, 50)),
                       sensor_latency_p99=float(np.percentile(lat, 99)),
                       sensor_latency_max=float(lat.max()))
        return out

    def diagnose(self, stat) -> None:
        for key, value in self.numbers().items():
            stat.add(key, f"{value:.9g}" if isinstance(value, float) else str(value))
        stat.add("force_pulses", self.pulses)
        stat.add("phase_mismatch", self.phase_mismatch)
        if self.clock.fit is None:
            stat.merge_summary(WARN, "no rig/clock pair yet: the clock relation is unknown")

    def summary(self) -> str:
        n = self.numbers()
        text = (f" force_pulses={self.pulses} rig_applied={','.join(map(str, self.applied))}"
                f" applied_after_use={self.applied_after_use}"
                f" applied_waited_out={self.applied_waited_out}"
                f" clock_offset={n['clock_offset']:.9f} clock_drift={n['clock_drift']:.12g}"
                f" clock_jitter={n['clock_jitter']:.3g} clock_pairs={n['clock_pairs']}")
        if "sensor_latency_p50" in n:
            text += (f" sensor_latency_ms p50={n['sensor_latency_p50'] * 1e3:.3f} "
                     f"p99={n['sensor_latency_p99'] * 1e3:.3f} "
                     f"max={n['sensor_latency_max'] * 1e3:.3f}")
        return text

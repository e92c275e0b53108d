"""sim_node: the impact oscillator integrated with the exact flow, as a ROS 2 node.

The integration is :func:`grazing_control.dynamics.fidelity.period_step` (by default the exact
:func:`grazing_control.dynamics.simulate.period_step`), one call per forcing
period from one Pi2 sample to the next, exactly as :func:`grazing_control.dynamics.simulate.simulate`
does; everything published between two samples (state, Pi1 crossing, impacts) is
evaluated from the closed form by :func:`grazing_control.dynamics.simulate.states_between`
without altering the trajectory. A lockstep run therefore reproduces ``simulate`` of
the same scene sample for sample (docs/nodes.md).

Simulation time: t = 0 at the first Pi2 sample, sample k at t = k T (T = 2 pi / omega);
the forcing phase at a Pi2 sample is tau2 = tau* + pi2_offset (spec section 3), so
``tau0`` does not change the sampled dynamics (it is accepted and validated with the
model parameters).

Topics (all reliable, volatile, keep last 1000, except ``oscillator/done``)
---------------------------------------------------------------------------
``oscillator/state`` (sensor_msgs/JointState)
    name ["mass"], position [x], velocity [v], effort [cos tau], every
    ``state_period`` of simulation time (nondimensional units; t in seconds of stamp).
``oscillator/impact`` (geometry_msgs/Vector3Stamped)
    vector.x = v-, vector.y = v+ (= -r v-), vector.z = phase in [0, 2 pi); stamp = impact time.
``oscillator/pi1``, ``oscillator/pi2`` (sensor_msgs/JointState)
    state at each crossing of Pi1 (phase tau*) and Pi2 (phase tau2), stamped with the
    crossing time; a Pi2 sample is the state before the correction.
``oscillator/latency`` (std_msgs/Float64)
    realtime mode: wall seconds from publishing a sample to receiving its correction
    (on arrival: the instant it is applied).
``oscillator/deadline_miss`` (geometry_msgs/Vector3Stamped)
    realtime, scheduled actuation: one per sample whose correction had not arrived at its
    actuation time; stamp = the sample's stamp, vector.x = k, vector.y = the actuation
    time t_k + delay missed, vector.z = wall seconds from publishing the sample to the miss.
``oscillator/done`` (std_msgs/Bool, transient local)
    true once ``max_periods`` periods have run.
``/clock`` (rosgraph_msgs/Clock)
    simulation time: at every Pi2 sample (lockstep), at every wake-up of the realtime
    loop (at least every 5 ms of wall time).

Subscribed: ``controller/velocity_correction`` (geometry_msgs/TwistStamped), twist.linear.x
= Delta v, header.stamp = the stamp of the Pi2 sample it answers. Service: ``~/reset``
(std_srvs/Trigger): back to the initial state at t = 0.

Modes
-----
``lockstep``: after publishing sample k the node waits for the correction stamped with
sample k's stamp (others are ignored and counted), applies it ``actuation_delay`` (+ the
injected jitter) after the sample, as ``simulate.period_step(..., delay=)``, and
integrates the period; after ``answer_timeout`` wall seconds without it, no correction is
applied (counted, logged). Deterministic, as fast as the round trip allows. The loop is
driven by the correction's subscription callback (no thread, no polling): the callback
integrates the period, publishes the next sample, then the period's state, crossings and
impacts (so the controller computes while they go out).

``realtime``: simulation time runs at ``time_scale`` times the wall clock (a timer wakes
up when the next event is due, and at least every 5 ms for /clock); samples are published
on time and the period continues without waiting. With scheduled actuation
(``actuation_delay`` > 0, docs/nodes.md "Scheduled actuation") the correction of sample k
acts exactly at t_k + actuation_delay (+ jitter) if it has arrived by then, as in lockstep
(:meth:`Engine.actuate`); an answer that has not arrived is a deadline miss: no correction
(counted, logged, published on ``oscillator/deadline_miss``), and the answer, when it
comes, is dropped. With ``actuation:=on_arrival`` (the default when actuation_delay = 0)
a correction is applied when it arrives, as an instantaneous velocity change
at the state of that instant: the period is then split there (the exact flow is
evaluated up to the arrival, Delta v is added, and the flow continues to the next
sample), so the correction acts a latency after Pi2, not on it. It must answer one of
the last two samples, once; an answer that comes after the next sample went out is
still applied (counted as late). The latency (wall time from publishing the sample to
applying its correction) is published on ``oscillator/latency`` and summarised at exit
with how late the samples went out against their simulation time (``sample_lag_ms``).

Injected faults (``loss``, ``measurement_noise``, ``jitter`` with ``seed``): the
:class:`grazing_control.plant.faults.FaultModel` of sample k, a pure function of (seed, k), as
in the core's fault simulation: the published sample carries the measurement noise, the
correction is dropped (counted as ``lost``) or acts at the jittered delay.

Run: ``ros2 run grazing_control sim_node --ros-args --params-file config/study.yaml`` or
``python -m sim_node.sim_node --ros-args ...``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
from geometry_msgs.msg import TwistStamped, Vector3Stamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64
from std_srvs.srv import Trigger

from grazing_control.oscillator import kernel
from grazing_control.plant.faults import FaultModel
from grazing_control.ros import cdr
from grazing_control.ros.common import (DATA_QOS, EXECUTORS, LATCHED_QOS, PUBLISHER_QOS,
                                        deserialize, READY_TOPIC, StartupError, Throttled,
                                        bool_descriptor, float_descriptor, int_descriptor,
                                        publish_parameter_record, run_node, spin, stamp_key,
                                        string_descriptor)
from grazing_control.oscillator.params import OscillatorParams, ParameterError, study_omega
from grazing_control.dynamics.fidelity import FIDELITIES, period_step
from grazing_control.dynamics.simulate import states_between

__all__ = ["SimSettings", "settings_from_values", "Event", "Engine", "SimNode", "main"]

TWO_PI = 2.0 * math.pi
MODES = ("lockstep", "realtime")
#: When a realtime correction acts: at t_k + actuation_delay (scheduled), when it arrives
#: (on_arrival, the original behaviour), or auto: scheduled if actuation_delay > 0 or
#: jitter > 0, else on_arrival. Lockstep always acts at t_k + actuation_delay.
ACTUATIONS = ("auto", "scheduled", "on_arrival")
MODEL_KEYS = ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset")
#: Realtime: longest wall time between two wake-ups (each publishes /clock), seconds.
CLOCK_TICK = 5e-3
#: Realtime: shortest timer period (an event already due is published at once), seconds.
MIN_TICK = 5e-5
#: Wall seconds between two checks for another simulator or controller on the topics.
ISOLATION_CHECK = 0.25
#: Wall seconds to wait at exit for every reader to acknowledge every message.
ACK_TIMEOUT = 10.0


# ============================================================== settings (no ROS)
@dataclass(frozen=True)
class SimSettings:
    """The sim node's validated parameters (see :func:`settings_from_values`)."""

    params: OscillatorParams
    x0: float
    v0: float
    mode: str
    time_scale: float
    state_period: float
    answer_timeout: float
    max_periods: int
    fidelity: str
    noise: float
    seed: int
    actuation_delay: float = 0.0
    actuation: str = "auto"
    loss: float = 0.0
    measurement_noise: float = 0.0
    jitter: float = 0.0

    @property
    def scheduled(self) -> bool:
        """Realtime corrections act at t_k + actuation_delay (else on arrival)."""
        if self.actuation == "auto":
            return self.actuation_delay > 0.0 or self.jitter > 0.0
        return self.actuation == "scheduled"

    @cached_property
    def faults(self) -> FaultModel:
        """The injected faults (loss, measurement noise, jitter) with the node's seed."""
        return FaultModel(self.loss, self.measurement_noise, self.jitter, self.seed)


def _finite(name, value, ok, valid):
    value = float(value)
    if not (math.isfinite(value) and ok(value)):
        raise ParameterError(f"{name}={value!r} is invalid: valid range is {valid}")
    return value


def settings_from_values(values: dict) -> SimSettings:
    """Validate the sim node's parameter values; raise ParameterError naming the bad one.

    The model parameters go through :class:`OscillatorParams` (its message names the
    parameter and its range); the initial state must be finite or NaN (= X**) and not
    beyond the wall (x0 <= d).
    """
    p = OscillatorParams(**{k: values[k] for k in MODEL_KEYS})
    mode = str(values["mode"])
    if mode not in MODES:
        raise ParameterError(f"mode={mode!r} is invalid: valid values are {', '.join(MODES)}")
    fidelity = str(values["fidelity"])
    if fidelity not in FIDELITIES:
        raise ParameterError(
            f"fidelity={fidelity!r} is invalid: valid values are {', '.join(FIDELITIES)}")
    if fidelity != "exact" and mode == "realtime":
        raise ParameterError(
            f"fidelity={fidelity!r} is invalid in realtime mode: valid there is 'exact' only "
            "(corrections land inside a period, which only the exact flow can split)")
    x0, v0 = float(values["x0"]), float(values["v0"])
    for name, value in (("x0", x0), ("v0", v0)):
        if math.isinf(value):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite real "
                                 "number, or NaN for the grazing point X**")
    if not math.isnan(x0) and x0 > p.d:
        raise ParameterError(f"x0={x0!r} is invalid: valid range is x0 <= d = {p.d!r} "
                             "(the state must not be beyond the wall)")
    max_periods = int(values["max_periods"])
    if max_periods < 0:
        raise ParameterError(f"max_periods={max_periods} is invalid: valid range is >= 0 "
                             "(0 = unbounded)")
    seed = int(values["seed"])
    if seed < 0:
        raise ParameterError(f"seed={seed} is invalid: valid range is seed >= 0")
    actuation = _actuation_values(values, p, mode, fidelity)
    return SimSettings(
        params=p, x0=x0, v0=v0, mode=mode,
        time_scale=_finite("time_scale", values["time_scale"], lambda v: v > 0.0,
                           "a finite time_scale > 0"),
        state_period=_finite("state_period", values["state_period"], lambda v: v >= 0.0,
                             "a finite state_period >= 0 (0 disables oscillator/state)"),
        answer_timeout=_finite("answer_timeout", values["answer_timeout"],
                               lambda v: v > 0.0, "a finite answer_timeout > 0"),
        max_periods=max_periods, fidelity=fidelity,
        noise=_finite("noise", values["noise"], lambda v: v >= 0.0, "a finite noise >= 0"),
        seed=seed, **actuation)


def _actuation_values(values: dict, p: OscillatorParams, mode: str, fidelity: str) -> dict:
    """Validate actuation_delay, actuation and the injected faults (docs/nodes.md)."""
    out = {
        "actuation_delay": _finite(
            "actuation_delay", values.get("actuation_delay", 0.0),
            lambda v: 0.0 <= v < p.period,
            f"0 <= actuation_delay < T = {p.period!r} (simulation time)"),
        "loss": _finite("loss", values.get("loss", 0.0), lambda v: 0.0 <= v <= 1.0,
                        "0 <= loss <= 1"),
        "measurement_noise": _finite("measurement_noise", values.get("measurement_noise", 0.0),
                                     lambda v: v >= 0.0, "a finite measurement_noise >= 0"),
        "jitter": _finite("jitter", values.get("jitter", 0.0), lambda v: v >= 0.0,
                          "a finite jitter >= 0 (simulation time)"),
    }
    actuation = str(values.get("actuation", "auto"))
    if actuation not in ACTUATIONS:
        raise ParameterError(f"actuation={actuation!r} is invalid: valid values are "
                             f"{', '.join(ACTUATIONS)}")
    out["actuation"] = actuation
    split = out["actuation_delay"] > 0.0 or out["jitter"] > 0.0
    if split and fidelity != "exact":
        raise ParameterError(
            f"fidelity={fidelity!r} is invalid with actuation_delay or jitter > 0: valid "
            "there is 'exact' only (the correction splits the period)")
    if mode == "realtime" and actuation == "on_arrival" and out["jitter"] > 0.0:
        raise ParameterError(f"jitter={out['jitter']!r} is invalid with actuation=on_arrival: "
                             "valid there is 0 (the actuation time is the arrival)")
    if mode == "realtime" and actuation == "scheduled" and not split:
        raise ParameterError(
            "actuation_delay=0.0 is invalid with actuation=scheduled in realtime mode: valid "
            f"range is 0 < actuation_delay < T = {p.period!r} (no answer can arrive at its "
            "own sample's instant); use actuation:=on_arrival to apply on arrival")
    return out


def initial_deviation(p: OscillatorParams, x0: float, v0: float) -> tuple:
    """(x0 - x**, v0 - v**) with NaN meaning the grazing point's coordinate: as simulate()."""
    x = p.x_ref if math.isnan(x0) else x0
    v = p.v_ref if math.isnan(v0) else v0
    return x - p.x_ref, v - p.v_ref


# ================================================================= engine (no ROS)
class Event(NamedTuple):
    """Something to publish at simulation time t.

    kind 'state' or 'pi1': (x, v) physical; kind 'impact': x = v-, v = v+;
    kind 'pi2': the sample (x, v) before correction. ``phase`` is the forcing phase.
    """

    t: float
    kind: str
    x: float
    v: float
    phase: float


class _Deadline(NamedTuple):
    """Realtime, scheduled: sample k's actuation instant and its answer once it arrives."""

    t: float          # actuation time t_k + delay (simulation time)
    delay: float      # delay after the sample (actuation_delay + jitter)
    key: tuple        # the sample's stamp key
    k: int            # sample index
    sent: float       # wall time the sample was published
    dv: float | None  # the answer, None until it arrives


class _Segment(NamedTuple):
    ts: float      # start time
    tau: float     # forcing phase at the start
    dx: float      # deviation at the start, after any correction
    dv: float
    te: float      # end time (the next Pi2 sample)
    dx_end: float
    dv_end: float


class Engine:
    """The simulated oscillator between ROS and the core: samples, periods, splits.

    The state is carried as the deviation (dx, dv) from the non-impacting motion at the
    current Pi2 sample k (time t_k). :meth:`begin_period` integrates the period with a
    correction by one :func:`period_step` call; :meth:`split` (realtime) re-evaluates the
    current period from its start to a time inside it and applies a correction there;
    :meth:`end_period` moves to the next sample, where pending model parameters take
    effect and the velocity noise is added.
    """

    def __init__(self, settings: SimSettings):
        self.settings = settings
        self.p = settings.params
        self.advance = kernel.exact_advance()   # the exact flow, compiled when available
        self.pending = None
        self.rng = np.random.default_rng(settings.seed)
        self.impacts = 0
        self._drawn = None
        self.reset()

    # ---------------------------------------------------------------- samples
    def reset(self) -> Event:
        """Back to the initial state, sample 0 at t = 0 (pending parameters apply now)."""
        if self.pending is not None:
            self.p, self.pending = self.pending, None
        s = self.settings
        self.rng = np.random.default_rng(s.seed)
        self.k = 0
        self.k_base, self.t_base = 0, 0.0
        self.dx, self.dv = initial_deviation(self.p, s.x0, s.v0)
        self.impacts = 0
        self.seg = None
        return self._sample()

    @property
    def t(self) -> float:
        """Time of the current sample, t_k = k T (re-based when T changes)."""
        return self.t_base + (self.k - self.k_base) * self.p.period

    def _sample(self) -> Event:
        if self.settings.noise > 0.0:
            self.dv += float(self.rng.normal(0.0, self.settings.noise))
        p = self.p
        return Event(self.t, "pi2", p.x_ref + self.dx, p.v_ref + self.dv, p.tau2)

    def sample(self) -> Event:
        """The current sample (without drawing noise again)."""
        p = self.p
        return Event(self.t, "pi2", p.x_ref + self.dx, p.v_ref + self.dv, p.tau2)

    # ------------------------------------------------------------- faults (per sample k)
    def _draw(self):
        """The faults of sample k (FaultModel.draw, a pure function of (seed, k))."""
        faults = self.settings.faults
        if self._drawn is None or self._drawn[0] != (faults, self.k):
            self._drawn = ((faults, self.k), faults.draw(self.k))
        return self._drawn[1]

    def measured(self, ev: Event) -> Event:
        """Sample k as the controller sees it: (x, v) + the measurement noise of draw(k)."""
        if self.settings.measurement_noise == 0.0:
            return ev
        f = self._draw()
        return ev._replace(x=ev.x + f.noise_x, v=ev.v + f.noise_v)

    def correction_lost(self) -> bool:
        """Whether sample k's correction is dropped by the injected loss."""
        return self.settings.loss > 0.0 and self._draw().dropped

    def actuation_delay(self) -> float:
        """Delay of sample k's correction after the sample: actuation_delay + jitter e_k,
        clipped to [0, T) (FaultModel.actuation_delay)."""
        s = self.settings
        if s.jitter == 0.0:
            return s.actuation_delay
        return s.faults.actuation_delay(s.actuation_delay, self.k, self.p.period)

    # ---------------------------------------------------------------- periods
    def begin_period(self, dv_correction: float, delay: float = 0.0) -> list:
        """Integrate the period from the current sample with ``dv_correction`` at ``delay``.

        delay = 0: one :func:`period_step` call, as :func:`simulate` makes. delay > 0:
        the flow to t_k + delay, the correction there, the flow to t_k+1 (:meth:`actuate`),
        the same two calls as ``simulate.period_step(..., delay=delay)``. Returns the events
        of (t_k, t_k+1) in time order (state, Pi1, impacts), the next sample excluded.
        """
        p = self.p
        t0 = self.t
        if delay > 0.0:
            head = self.advance(p, p.tau2, self.dx, self.dv, delay)
            events = self._events(_Segment(t0, p.tau2, self.dx, self.dv, t0 + delay,
                                           head.dx, head.dv), head.impacts)
            return events + self._actuate(head, dv_correction, delay)
        seg = period_step(p, self.dx, self.dv, dv_correction, self.settings.fidelity)
        t1 = self.t_base + (self.k + 1 - self.k_base) * p.period
        self.seg = _Segment(t0, p.tau2, self.dx, self.dv + dv_correction, t1, seg.dx, seg.dv)
        return self._events(self.seg, seg.impacts)

    def actuate(self, dv_correction: float, delay: float) -> list:
        """Apply ``dv_correction`` exactly ``delay`` after the current sample (scheduled).

        The period is re-integrated as ``simulate.period_step(p, dx, dv, dv_correction,
        delay=delay)`` does it (the free flow with impacts to t_k + delay, the velocity
        jump, the flow on to t_k+1), so a realtime period equals the lockstep one bit for
        bit. Returns the events of (t_k + delay, t_k+1).
        """
        head = self.advance(self.p, self.p.tau2, self.dx, self.dv, delay)
        return self._actuate(head, dv_correction, delay)

    def _actuate(self, head, dv_correction: float, delay: float) -> list:
        p = self.p
        tau = (p.tau2 + p.omega * delay) % TWO_PI
        dv = head.dv + dv_correction
        tail = self.advance(p, tau, head.dx, dv, p.period - delay)
        t1 = self.t_base + (self.k + 1 - self.k_base) * p.period
        self.seg = _Segment(self.t + delay, tau, head.dx, dv, t1, tail.dx, tail.dv)
        return self._events(self.seg, tail.impacts)

    def split(self, tc: float, dv_correction: float) -> list:
        """Apply ``dv_correction`` at time tc inside the current period (realtime).

        The exact flow is re-evaluated from the period's start to tc (same closed form as
        the events already published), the velocity jumps there, and the flow continues
        to the next sample. Returns the events of (tc, t_k+1).
        """
        s, p = self.seg, self.p
        tc = min(max(tc, s.ts), s.te)
        head = self.advance(p, s.tau, s.dx, s.dv, tc - s.ts)
        tau_c = (s.tau + p.omega * (tc - s.ts)) % TWO_PI
        dv_c = head.dv + dv_correction
        tail = self.advance(p, tau_c, head.dx, dv_c, s.te - tc)
        self.seg = _Segment(tc, tau_c, head.dx, dv_c, s.te, tail.dx, tail.dv)
        return self._events(self.seg, tail.impacts)

    def end_period(self) -> tuple:
        """Move to the next sample: returns (sample event, warning or None).

        Pending model parameters take effect here, never within a period: the physical
        state (x, v) at the sample is kept and re-expressed as a deviation of the new
        model on its own Pi2 (if it lies beyond the new wall it is put on the wall).
        """
        s = self.seg
        self.dx, self.dv = s.dx_end, s.dv_end
        self.k += 1
        self.seg = None
        warning = None
        if self.pending is not None:
            warning = self._apply_pending()
        return self._sample(), warning

    def _apply_pending(self):
        old, new = self.p, self.pending
        t = self.t
        self.p, self.pending = new, None
        self.k_base, self.t_base = self.k, t
        if (old.x_ref, old.v_ref) == (new.x_ref, new.v_ref):
            x = None
        else:
            x, v = old.x_ref + self.dx, old.v_ref + self.dv
            self.dx, self.dv = x - new.x_ref, v - new.v_ref
        if new.x_ref + self.dx > new.d:
            self.dx = new.d - new.x_ref
            self.dv = min(self.dv + new.v_ref, 0.0) - new.v_ref
            return (f"the state at t={t:.6g} lies beyond the new wall d={new.d!r}: "
                    "placed on the wall")
        return None

    def _events(self, s: _Segment, impacts) -> list:
        p = self.p
        events = []
        for i in impacts:
            events.append(Event(s.ts + i.dt, "impact", i.v_minus, i.v_plus, i.phase % TWO_PI))
        rel, kinds = [], []
        sp = self.settings.state_period
        if sp > 0.0:
            j = math.floor(s.ts / sp) + 1
            while j * sp < s.te:
                rel.append(j * sp - s.ts)
                kinds.append("state")
                j += 1
        d1 = ((p.tau_star - s.tau) % TWO_PI) / p.omega
        if 0.0 < d1 < s.te - s.ts:
            rel.append(d1)
            kinds.append("pi1")
        if rel:
            order = np.argsort(rel, kind="stable")
            rel = [rel[i] for i in order]
            kinds = [kinds[i] for i in order]
            xv = states_between(p, s.tau, s.dx, s.dv, impacts, rel)
            for h, kind, (x, v) in zip(rel, kinds, xv):
                phase = p.tau_star if kind == "pi1" else (s.tau + p.omega * h) % TWO_PI
                events.append(Event(s.ts + h, kind, float(x), float(v), phase))
        events.sort(key=lambda e: e.t)
        return events


# ======================================================================= the node
#: No default QoS-event handlers on the data publishers: each one is one more entity in
#: every executor wait (measured: about 10 % of the lockstep rate).
_NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)


def _declare(node: Node) -> None:
    d = node.declare_parameter
    ref = OscillatorParams()
    d("zeta", ref.zeta, float_descriptor("damping ratio zeta, 0 < zeta < 1", 0.0, 1.0))
    d("r", ref.r, float_descriptor("coefficient of restitution r, 0 < r < 1", 0.0, 1.0))
    d("omega", study_omega(), float_descriptor("forcing frequency omega > 0 (nondimensional)",
                                               0.0))
    d("delta_d", 0.0, float_descriptor("wall clearance Delta d = d - d* (< 0: impacting side)"))
    d("tau0", 0.0, float_descriptor("forcing phase tau0 (reduced mod 2 pi; the sampled "
                                    "dynamics start on Pi2 and do not depend on it)"))
    d("pi2_offset", ref.pi2_offset, float_descriptor(
        "phase of Pi2 after Pi1, 0 < pi2_offset < 2 pi (study: pi/2)", 0.0, TWO_PI))
    d("x0", math.nan, float_descriptor("initial position on Pi2; NaN = x** (grazing point)"))
    d("v0", math.nan, float_descriptor("initial velocity on Pi2; NaN = v** (grazing point)"))
    d("mode", "lockstep", string_descriptor("lockstep (wait for each correction) or realtime "
                                            "(paced to the wall clock)", True, MODES))
    d("time_scale", 1.0, float_descriptor("realtime: simulation seconds per wall second, > 0",
                                          0.0))
    d("state_period", 1.0, float_descriptor("simulation time between oscillator/state "
                                            "messages; 0 disables them", 0.0))
    d("answer_timeout", 1.0, float_descriptor("lockstep: wall seconds to wait for the "
                                              "correction of a sample, then apply none", 0.0))
    d("max_periods", 0, int_descriptor("forcing periods to simulate; 0 = unbounded", 0))
    d("fidelity", "exact", string_descriptor("model fidelity: exact (closed-form flow), zdm2 / "
                                             "zdm1 (normal-form maps), ode (solve_ivp, "
                                             "comparison); lockstep only for all but exact",
                                             False, FIDELITIES))
    d("noise", 0.0, float_descriptor("std of Gaussian velocity noise added at each Pi2 sample",
                                     0.0))
    d("seed", 0, int_descriptor("seed of the noise generator, >= 0 (applied at start and "
                                "reset)", 0))
    d("actuation_delay", 0.0, float_descriptor(
        "simulation time from a Pi2 sample to its correction, 0 <= actuation_delay < T "
        "(the controller YAML's actuation_delay)", 0.0, read_only=True))
    d("actuation", "auto", string_descriptor(
        "realtime: scheduled (act at t_k + actuation_delay; a later answer is a deadline "
        "miss), on_arrival (act when the answer arrives), auto (scheduled if "
        "actuation_delay or jitter > 0)", True, ACTUATIONS))
    d("loss", 0.0, float_descriptor("injected fault: probability that a correction is "
                                    "dropped, 0..1 (FaultModel, seed)", 0.0, 1.0, True))
    d("measurement_noise", 0.0, float_descriptor(
        "injected fault: std of Gaussian noise on the x and v of the published Pi2 sample "
        "(FaultModel, seed)", 0.0, read_only=True))
    d("jitter", 0.0, float_descriptor(
        "injected fault: std of the actuation time around actuation_delay, simulation time "
        "(FaultModel, seed)", 0.0, read_only=True))
    d("executor", "events", string_descriptor(
        "rclpy executor: single_threaded (SingleThreadedExecutor) or events "
        "(rclpy.experimental EventsExecutor)", True, EXECUTORS))
    d("exit_when_done", False, bool_descriptor("exit (status 0) once max_periods have run",
                                               True))
    d("wait_for_controller", True, bool_descriptor(
        "start only when a controller is matched on oscillator/pi2 and "
        "controller/velocity_correction", True))
    d("wait_for_subscribers", 0, int_descriptor(
        "start only when every data topic has this many other subscribers (a recorder: 1)",
        0, 100, True))
    d("wait_for_recorder", False, bool_descriptor(
        "start only when recorder_node says it has matched every topic "
        f"({READY_TOPIC}); grazing run sets it when it records", True))
    d("start_timeout", 30.0, float_descriptor(
        "wall seconds to wait for the above, then start anyway (with a warning)", 0.0,
        read_only=True))


_SETTING_KEYS = MODEL_KEYS + ("x0", "v0", "mode", "time_scale", "state_period",
                              "answer_timeout", "max_periods", "fidelity", "noise", "seed",
                              "actuation_delay", "actuation", "loss", "measurement_noise",
                              "jitter")


class SimNode(Node):
    """The simulator node (module docstring: topics, modes, parameters)."""

    def __init__(self, **kwargs):
        super().__init__("sim_node", **kwargs)
        _declare(self)
        values = {k: self.get_parameter(k).value for k in _SETTING_KEYS}
        try:
            self.settings = settings_from_values(values)
        except ParameterError as exc:
            raise StartupError(str(exc)) from None
        self.engine = Engine(self.settings)
        self.exit_when_done = self.get_parameter("exit_when_done").value
        self.exit_code = 0
        self.exit_now = False

        def publisher(kind, topic):
            return self.create_publisher(kind, topic, PUBLISHER_QOS, event_callbacks=_NO_EVENTS)

        self.pub_state = publisher(JointState, "oscillator/state")
        self.pub_impact = publisher(Vector3Stamped, "oscillator/impact")
        self.pub_pi1 = publisher(JointState, "oscillator/pi1")
        self.pub_pi2 = publisher(JointState, "oscillator/pi2")
        self.pub_clock = publisher(Clock, "/clock")
        self.pub_latency = publisher(Float64, "oscillator/latency")
        self.pub_miss = publisher(Vector3Stamped, "oscillator/deadline_miss")
        self.pub_done = self.create_publisher(Bool, "oscillator/done", LATCHED_QOS)
        self.sub_correction = self.create_subscription(
            TwistStamped, "controller/velocity_correction", self._on_correction, DATA_QOS,
            raw=True, event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._recorder_ready = False
        if self.get_parameter("wait_for_recorder").value:
            self.create_subscription(Bool, READY_TOPIC, self._on_recorder_ready, LATCHED_QOS)
        self.pub_parameters = publish_parameter_record(self)   # grazing/parameters
        self._start_timer = self.create_timer(0.02, self._try_start)
        self._isolation_timer = self.create_timer(ISOLATION_CHECK, self._check_isolation)
        self._tick_timer = None
        self._watchdog = None

        log = self.get_logger()
        self.ignored = Throttled(log, "correction ignored")
        self.malformed = Throttled(log, "malformed correction ignored")
        self.timeouts = Throttled(log, "no correction within answer_timeout, none applied")
        self.misses = Throttled(log, "deadline missed: no correction at the actuation time, "
                                     "none applied")
        self.late_answers = Throttled(log, "answer after its deadline dropped")
        self.executor_kind = self.get_parameter("executor").value
        self.stats = {"applied": 0, "late": 0, "lost": 0}
        self.latencies = []
        self.lags = []
        self._started = False
        self._finished = False
        self._created = time.monotonic()
        self._wall_start = None
        self._waiting = None
        s = self.settings
        log.info(
            f"mode={s.mode} delta_d={s.params.delta_d!r} "
            f"max_periods={s.max_periods} state_period={s.state_period} "
            f"actuation={'scheduled' if s.scheduled else 'on_arrival'} "
            f"actuation_delay={s.actuation_delay!r} executor={self.executor_kind}"
            + (f" faults loss={s.loss!r} measurement_noise={s.measurement_noise!r} "
               f"jitter={s.jitter!r} seed={s.seed}" if s.faults.active else ""))

    # ------------------------------------------------------------------ start
    def _on_recorder_ready(self, msg: Bool) -> None:
        self._recorder_ready = bool(msg.data)

    def _intruders(self) -> list:
        """Other simulators or controllers on this scene's topics (publisher counts)."""
        found = []
        n = self.count_publishers(self.pub_pi2.topic_name)
        if n > 1:
            found.append(f"{n - 1} other publisher(s) on {self.pub_pi2.topic_name} "
                         "(another simulator)")
        n = self.count_publishers(self.sub_correction.topic_name)
        if n > 1:
            found.append(f"{n} publishers on {self.sub_correction.topic_name} "
                         "(more than one controller)")
        return found

    def _check_isolation(self) -> None:
        """Refuse to start, or stop, when another scene shares this one's topics.

        Two simulators (or two controllers) on the same topics corrupt each other's
        samples, answers and recordings: the scene is stopped with an error (exit status
        1) instead of reporting success. Checked every ISOLATION_CHECK wall seconds.
        """
        if self._finished:
            return
        found = self._intruders()
        if found:
            what = "; ".join(found)
            if not self._started:
                self.get_logger().error(f"not starting: {what}: the scene is not isolated "
                                        "(another scene on this ROS_DOMAIN_ID and namespace?)")
                self.exit_code = 1
                self._finished = True
                self.exit_now = True
                self.destroy_timer(self._start_timer)
            else:
                self._fail(RuntimeError(f"{what}: the scene is not isolated (another scene "
                                        "on this ROS_DOMAIN_ID and namespace?)"))

    def _ready(self) -> bool:
        if self.get_parameter("wait_for_recorder").value and not self._recorder_ready:
            return False
        if self._intruders():
            return False                   # _check_isolation refuses
        n = self.get_parameter("wait_for_subscribers").value
        controller = self.get_parameter("wait_for_controller").value
        if controller and (self.pub_pi2.get_subscription_count() < n + 1
                           or self.sub_correction.get_publisher_count() < 1):
            return False
        if n > 0:
            pubs = [self.pub_impact, self.pub_pi1, self.pub_pi2, self.pub_clock]
            if self.settings.state_period > 0.0:
                pubs.append(self.pub_state)
            if self.settings.mode == "realtime":     # the latency of every sample is recorded
                pubs.append(self.pub_latency)
            if any(pub.get_subscription_count() < n for pub in pubs):
                return False
            if self.count_subscribers("controller/velocity_correction") < n + 1:
                return False
        return True

    def _try_start(self) -> None:
        waited = time.monotonic() - self._created
        if not self._ready():
            if waited < self.get_parameter("start_timeout").value:
                return
            self.get_logger().warning(
                f"starting after start_timeout={waited:.1f} s without the expected "
                "controller/subscribers")
        elif self._ready_since is None:
            self._ready_since = time.monotonic()   # let both ends of every match settle
            return
        elif time.monotonic() - self._ready_since < 0.2:
            return
        self.destroy_timer(self._start_timer)
        if kernel.use_kernel():   # compile, or load numba's cache, now: not in the first period
            kernel.warm_up()
        self._started = True
        self._wall_start = time.monotonic()
        if self.settings.mode == "lockstep":
            self._watchdog = self.create_timer(
                min(0.25, self.settings.answer_timeout / 4.0), self._on_watchdog)
            self._publish_sample(self.engine.sample())
        else:
            self._rt_start()

    _ready_since = None

    # ----------------------------------------------------------------- lockstep
    def _publish_sample(self, ev: Event) -> None:
        """Publish sample k (state before correction, as measured) and wait for its answer."""
        self._waiting = self._publish(self.engine.measured(ev))
        self._sent = time.monotonic()

    def _on_correction(self, data: bytes) -> None:
        """A correction as received (serialized): the controller's layout is read directly
        (:func:`cdr.read_twist_stamped`), any other TwistStamped through rclpy."""
        answer = cdr.read_twist_stamped(data)
        if answer is None:
            msg = deserialize(data, TwistStamped, self.malformed)
            if msg is None:
                return
            answer = stamp_key(msg.header.stamp) + (msg.twist.linear.x,)
        key, dv = answer[:2], answer[2]
        if not math.isfinite(dv):
            self.malformed(f"dv={dv!r} for stamp {key}")
            return
        if self.settings.mode == "lockstep":
            if not self._started or self._finished or key != self._waiting:
                self.ignored(f"stamp {key} does not answer the waiting sample {self._waiting}")
                return
            self._lockstep_period(dv, answered=True)
        elif self.settings.scheduled:
            self._rt_answer(key, dv)
        else:
            self._rt_correction(key, dv)

    def _on_watchdog(self) -> None:
        if (self._started and not self._finished and self._waiting is not None
                and time.monotonic() - self._sent > self.settings.answer_timeout):
            self.timeouts(f"sample {self._waiting}")
            self._lockstep_period(0.0)

    def _lockstep_period(self, dv: float, answered: bool = False) -> None:
        """Sample k's period with its correction acting at t_k + actuation_delay (+ jitter)."""
        self._waiting = None
        if answered:
            if self.engine.correction_lost():
                self.stats["lost"] += 1
                dv = 0.0
            else:
                self.stats["applied"] += 1
        try:
            events = self.engine.begin_period(dv, self.engine.actuation_delay())
        except Exception as exc:  # the core refused (impact cap, state beyond the wall)
            self._fail(exc)
            return
        # the next sample goes out first, so that the controller computes its answer
        # while this period's state, crossings and impacts are published
        ev, warning = self.engine.end_period()
        if warning:
            self.get_logger().warning(warning)
        done = 0 < self.settings.max_periods <= self.engine.k
        if not done:
            self._publish_sample(ev)
        for e in events:
            self._publish(e)
        if done:
            self._finish()

    def _next_sample(self):
        """End the period (pending parameters apply); the next sample, or None when done."""
        ev, warning = self.engine.end_period()
        if warning:
            self.get_logger().warning(warning)
        if 0 < self.settings.max_periods <= self.engine.k:
            self._finish()
            return None
        return ev

    # ----------------------------------------------------------------- realtime
    def _now(self, wall: float | None = None) -> float:
        wall = time.monotonic() if wall is None else wall
        return self._rt_t0 + (wall - self._rt_wall0) * self.settings.time_scale

    def _rt_start(self) -> None:
        self._rt_t0, self._rt_wall0 = 0.0, time.monotonic()
        self._rt_sample = None
        self._rt_pending = {}
        self._rt_queue = []
        self._rt_deadline = None
        self._rt_publish_sample(self.engine.sample())
        self._tick_timer = self.create_timer(MIN_TICK, self._rt_tick)

    def _rt_publish_sample(self, ev: Event) -> None:
        # the uncorrected period is integrated first, so that the round trip of the
        # correction does not include it
        self._rt_queue = self.engine.begin_period(0.0)
        sent = time.monotonic()
        self._rt_sample = self._publish(self.engine.measured(ev))
        self._rt_pending[self._rt_sample] = sent
        if len(self._rt_pending) > 2:                    # keep the last two samples
            del self._rt_pending[next(iter(self._rt_pending))]
        if self.settings.scheduled:                      # sample k's actuation instant
            delay = self.engine.actuation_delay()
            self._rt_deadline = _Deadline(ev.t + delay, delay, self._rt_sample,
                                          self.engine.k, sent, None)
        # pace: how late the sample went out against its simulation time
        self.lags.append(sent - self._rt_wall0
                         - (ev.t - self._rt_t0) / self.settings.time_scale)

    def _rt_tick(self) -> None:
        if self._finished:
            return
        now = self._now()
        try:
            self._rt_advance(now)
        except Exception as exc:
            self._fail(exc)
            return
        if not self._finished:
            self.pub_clock.publish(cdr.clock(*cdr.stamp_parts(now)))
            self._rt_schedule(now)

    def _rt_schedule(self, now: float) -> None:
        """Wake up when the next event is due, and at least every CLOCK_TICK for /clock."""
        due = self._rt_queue[0].t if self._rt_queue else self.engine.seg.te
        if self._rt_deadline is not None:
            due = min(due, self._rt_deadline.t)
        delay = min(max((due - now) / self.settings.time_scale, MIN_TICK), CLOCK_TICK)
        self._tick_timer.timer_period_ns = int(delay * 1e9)
        self._tick_timer.reset()

    def _rt_advance(self, now: float) -> None:
        """Publish everything due up to simulation time ``now``, actuating on schedule."""
        while True:
            q = self._rt_queue
            dl = self._rt_deadline
            due = dl is not None and dl.t <= now
            i = 0
            while i < len(q) and (q[i].t < dl.t if due else q[i].t <= now):
                self._publish(q[i], clock=False)
                i += 1
            del q[:i]
            if due:
                self._rt_actuate(dl)
                continue
            if now < self.engine.seg.te:
                return
            for ev in q:
                self._publish(ev, clock=False)
            ev = self._next_sample()
            if ev is None:
                return
            self._rt_publish_sample(ev)

    def _rt_answer(self, key: tuple, dv: float) -> None:
        """Scheduled actuation: keep the answer of the current sample for its deadline.

        The answer must arrive (this callback runs) before the sample's actuation instant
        t_k + delay in simulation time; one that comes later is dropped and counted (its
        deadline was already reported as missed).
        """
        if not self._started or self._finished:
            self.ignored(f"stamp {key}: the scene is not running")
            return
        wall = time.monotonic()
        self._rt_advance(self._now(wall))     # a deadline already due is handled first
        if self._finished:
            return
        dl = self._rt_deadline
        sent = self._rt_pending.pop(key, None)
        if sent is None:
            self.ignored(f"stamp {key} answers none of the last two unanswered samples "
                         "(stale, duplicate or foreign)")
            return
        latency = wall - sent
        self.latencies.append(latency)
        self.pub_latency.publish(cdr.float64(latency))
        if dl is None or dl.key != key:
            self.stats["late"] += 1
            self.late_answers(f"stamp {key} arrived {latency * 1e3:.3f} ms after its sample, "
                              "after its actuation time")
            return
        self._rt_deadline = dl._replace(dv=dv)

    def _rt_actuate(self, dl) -> None:
        """Sample k's actuation instant: its answer, or 0 (a deadline miss), at t_k + delay."""
        self._rt_deadline = None
        dv = dl.dv
        if dv is None:
            dv = 0.0
            waited = time.monotonic() - dl.sent
            self.misses(f"sample {dl.k} (stamp {dl.key}), actuation at t={dl.t:.9g}, "
                        f"{waited * 1e3:.3f} ms after the sample went out")
            self.pub_miss.publish(cdr.vector3_stamped(*dl.key, float(dl.k), dl.t, waited))
        elif self.engine.correction_lost():
            self.stats["lost"] += 1
            dv = 0.0
        else:
            self.stats["applied"] += 1
        self._rt_queue = self.engine.actuate(dv, dl.delay)

    def _rt_correction(self, key: tuple, dv: float) -> None:
        """Apply a correction at the simulation time of its arrival.

        It must answer one of the last two samples, once: the latest (normal) or the
        one before, when the answer comes after the next sample went out (counted as
        late, applied all the same: the next opportunity). Anything else is ignored.
        """
        sent = self._rt_pending.pop(key, None) if self._started else None
        if sent is None or self._finished:
            self.ignored(f"stamp {key} answers none of the last two unanswered samples "
                         "(stale, duplicate or foreign)")
            return
        wall = time.monotonic()          # the correction acts at this instant's sim time
        now = self._now(wall)
        self._rt_advance(now)
        if self._finished:
            return
        if key != self._rt_sample:
            self.stats["late"] += 1
        latency = wall - sent
        self.latencies.append(latency)
        self.pub_latency.publish(cdr.float64(latency))
        if self.engine.correction_lost():
            self.stats["lost"] += 1
            return
        self._rt_queue = self.engine.split(now, dv)
        self.stats["applied"] += 1
        self._rt_schedule(now)           # the split may have brought an event forward

    # ---------------------------------------------------------------- publishing
    def _publish(self, ev: Event, clock: bool = True) -> tuple:
        """Publish an event (as packed CDR, :mod:`grazing_control.ros.cdr`); returns
        its stamp as (sec, nanosec)."""
        sec, ns = stamp = cdr.stamp_parts(ev.t)
        if ev.kind == "impact":
            self.engine.impacts += 1
            self.pub_impact.publish(cdr.vector3_stamped(sec, ns, ev.x, ev.v, ev.phase))
            return stamp
        data = cdr.joint_state(sec, ns, ev.x, ev.v, math.cos(ev.phase))
        if ev.kind == "pi1":
            self.pub_pi1.publish(data)
        elif ev.kind == "pi2":
            if clock and self.settings.mode == "lockstep":
                self.pub_clock.publish(cdr.clock(sec, ns))
            self.pub_pi2.publish(data)
        else:
            self.pub_state.publish(data)
        return stamp

    # ------------------------------------------------------------ end, failure
    def _finish(self) -> None:
        self._finished = True
        self.pub_done.publish(Bool(data=True))
        self.get_logger().info(self.summary())
        if self.exit_when_done:
            self.exit_now = True

    def _fail(self, exc: Exception) -> None:
        self.get_logger().error(f"simulation stopped at t={self.engine.t:.9g}: {exc}")
        self.exit_code = 1
        self._finished = True
        self.exit_now = True

    def summary(self) -> str:
        """One line: periods, impacts, corrections, ignored input, rate, latency."""
        wall = time.monotonic() - self._wall_start if self._wall_start else 0.0
        k = self.engine.k
        text = (f"summary: periods={k} t={self.engine.t:.9g} impacts={self.engine.impacts} "
                f"applied={self.stats['applied']} late={self.stats['late']} "
                f"missed={self.misses.count} lost={self.stats['lost']} "
                f"timeouts={self.timeouts.count} "
                f"ignored={self.ignored.count} malformed={self.malformed.count} "
                f"wall={wall:.3f}s rate={k / wall if wall > 0 else 0.0:.1f} periods/s")
        if self.latencies:
            lat = np.asarray(self.latencies) * 1e3
            text += (f" latency_ms p50={np.percentile(lat, 50):.3f} "
                     f"p99={np.percentile(lat, 99):.3f} max={lat.max():.3f} n={lat.size}")
        if self.lags:
            lag = np.asarray(self.lags) * 1e3
            text += (f" sample_lag_ms p50={np.percentile(lag, 50):.3f} "
                     f"p99={np.percentile(lag, 99):.3f} max={lag.max():.3f}")
        return text

    def spin_until(self, executor) -> None:
        """Spin until shutdown, or until done when exit_when_done.

        Before returning after the scene, wait (ACK_TIMEOUT s at most in all) until every
        reliable reader has acknowledged every message: a reader that lagged behind
        (a recorder) gets the rest from the publishers' history, not from a dead process.
        """
        spin(executor, lambda: self.exit_now)
        if self.exit_now:
            end = time.monotonic() + ACK_TIMEOUT
            for pub in (self.pub_pi2, self.pub_state, self.pub_impact, self.pub_pi1,
                        self.pub_clock, self.pub_latency, self.pub_miss, self.pub_done):
                left = max(0.0, end - time.monotonic())
                if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                    self.get_logger().warning(
                        f"{pub.topic_name}: not every message acknowledged at exit")

    def on_exit(self) -> None:
        """Log the summary when stopped before the end (Ctrl-C)."""
        if not self._finished:
            self.get_logger().info(self.summary() + " (interrupted)")

    # ----------------------------------------------------------- services, params
    def _on_reset(self, request, response):
        ev = self.engine.reset()
        response.success = True
        response.message = "reset to the initial state, sample 0 at t=0"
        self.get_logger().info(response.message)
        if not self._started:
            return response
        self._finished = False
        if self.settings.mode == "lockstep":
            self._publish_sample(ev)
        else:
            self._rt_t0, self._rt_wall0 = 0.0, time.monotonic()
            self._rt_pending.clear()
            self._rt_deadline = None
            self._rt_publish_sample(ev)
        return response

    def _on_set_parameters(self, params) -> SetParametersResult:
        values = {k: self.get_parameter(k).value for k in _SETTING_KEYS}
        values.update({p.name: p.value for p in params if p.name in values})
        try:
            new = settings_from_values(values)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        old = self.settings
        if new.params != old.params:
            self.engine.pending = new.params     # whole, at the next Pi2 sample
        if self.settings.mode == "realtime" and self._started and new.time_scale != old.time_scale:
            self._rt_t0, self._rt_wall0 = self._now(), time.monotonic()
        self.settings = new
        self.engine.settings = new
        return SetParametersResult(successful=True)


def main(args=None) -> int:
    """Entry point of the ``sim_node`` executable; returns the exit status."""
    return run_node(SimNode, args, "sim_node")


if __name__ == "__main__":
    raise SystemExit(main())

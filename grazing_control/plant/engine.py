"""The simulated oscillator, sample by sample: periods, corrections, splits, published events.

:class:`Engine` carries the state as the deviation (dx, dv) from the non-impacting motion
at the current Pi2 sample k (t_k = k T, spec section 3) and integrates each period with
the core's exact flow: one :func:`grazing_control.dynamics.simulation.fidelity.period_step` call per
period (as :func:`grazing_control.dynamics.simulation.simulate.simulate` makes them), or, with a
correction delayed by s, the flow to t_k + s, the velocity jump, the flow to t_k+1 (as
``simulate.period_step(..., delay=s)``, docs/theory_delay.md). Everything published
between two samples (state, Pi1 crossing, impacts) is evaluated from the closed form by
:func:`grazing_control.dynamics.simulation.simulate.states_between` without altering the trajectory,
so a run of the engine reproduces ``simulate`` of the same scene sample for sample.
With a compliant stop (settings.contact, :mod:`grazing_control.plant.contact_plant`) the
flow of every piece (a period, the pieces of a delayed or split period, a force pulse)
and the states between samples are that stop's flow instead
(:meth:`~grazing_control.plant.contact_plant.ContactPlant.advance`, the exact flow's
signature), its contacts published as impacts (v- at entry, v+ at exit); a pulse's
constant force is the same shift of the stop as of the wall (docs/theory_contact.md §16).

With a first-order actuator (``actuator_bandwidth`` or ``actuator_latency`` > 0, issue
29 section 4) the force on the mass is a third state carried from sample to sample
(:attr:`Engine.force`): each period is the exact flow under a piecewise exponential
force, :func:`grazing_control.dynamics.simulation.actuator.lag_flow` per piece between the
command's switches (:meth:`Engine._lag_period`, docs/theory_pulse.md section 5); with a
compliant stop the stop's flow under that force
(:meth:`~grazing_control.plant.contact_plant.ContactPlant.lag_flow`, docs/theory_contact.md
§21).

An n-DOF scene (``settings.model``, a model file of docs/ndof_model.md; issues 17, 32)
runs on the same engine: the sample bookkeeping, the faults, the delay and the split on
arrival, the stream's grid and the Pi1 crossing are the ones above, and what differs --
the state z in R^{2n} (the deviation from the periodic response at Pi2), the flow of a
piece, the kick on the actuated velocity or the force pulse carrying it (``pulse_width``:
F = m_a Delta v / w on the actuated coordinate, centred ``actuation_delay`` after the
sample as in 1-DOF; docs/theory_ndof.md section 15; through the first-order actuator
the legs of :func:`~grazing_control.dynamics.maps.modal_map.actuated_step`, the force
carried in :attr:`Engine.force`), the physical state of the n coordinates, the
states between samples and the sensor's draws per coordinate -- is the model's
(:class:`grazing_control.oscillator.ndof.section.NdofSection`, :attr:`Engine.section`):
its start is ``state0`` (X** when empty), its drifting wall (``delta_d_drift``) the
model's Delta d moved at each sample as the 1-DOF one, its velocity noise at Pi2 the
kick of one draw per sample on the actuated velocity, its measurement noise a draw per
coordinate (:meth:`grazing_control.plant.faults.FaultModel.coordinate_noise`).
Its events are :class:`NdofEvent` (tuples of the n coordinates) for the state stream,
Pi1 and Pi2, and :class:`Event` for an impact (x = v-, v = v+ of the wall coordinate).
A lockstep n-DOF run repeats :class:`grazing_control.dynamics.maps.modal_map.ModalMap`'s
iterates bit for bit (with a pulse, ``ModalMap(width=)``'s: the calls of
:func:`~grazing_control.dynamics.maps.modal_map.pulse_step`); a sticking motion of the
wall coordinate is the core's (``advance`` returns its sticking impacts; the states
between samples while stuck are ``advance`` from the piece's start); the 1-DOF path is the kernel's closed form, unchanged
(benchmarks/fold_hashes.py).

No ROS: sim_node publishes the :class:`Event` values this returns.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.simulation.actuation import flow_with_force, pulse_force, pulse_start
from grazing_control.dynamics.simulation.actuator import command_period, lag_flow, lag_states
from grazing_control.dynamics.simulation.fidelity import period_step
from grazing_control.dynamics.simulation.simulate import states_between
from grazing_control.oscillator import kernel
from grazing_control.oscillator.ndof.section import NdofSection, measure_coordinates
from grazing_control.plant.settings import SimSettings, initial_deviation

__all__ = ["Event", "NdofEvent", "Segment", "Span", "Engine"]

TWO_PI = 2.0 * math.pi


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


class NdofEvent(NamedTuple):
    """A state of an n-DOF scene to publish at simulation time t: kind 'state', 'pi1' or
    'pi2' (the sample before its correction); ``x``, ``v`` the physical positions and
    velocities of the n coordinates; ``phase`` the forcing phase."""

    t: float
    kind: str
    x: tuple
    v: tuple
    phase: float


class Span(NamedTuple):
    """One stretch of an n-DOF period after its last correction: from (ts, tau, z) to te."""

    ts: float          # start time
    tau: float         # forcing phase at the start
    z: np.ndarray      # deviation at the start, after any correction
    te: float          # end time (the next Pi2 sample)
    z_end: np.ndarray  # deviation at te
    impacts: tuple     # the model's impacts of the stretch (dt from ts)
    force: float = 0.0  # a pulse's constant force on the stretch (0: free flight)
    lag: tuple | None = None  # through the actuator: (command, transient, tau_a)


class _Rest(NamedTuple):
    """An n-DOF head of length 0 (a pulse starting at the sample): z, no impacts."""

    z: np.ndarray
    impacts: tuple


class Segment(NamedTuple):
    """One stretch of a period after its last correction: from (ts, tau, dx, dv) to te."""

    ts: float      # start time
    tau: float     # forcing phase at the start
    dx: float      # deviation at the start, after any correction
    dv: float
    te: float      # end time (the next Pi2 sample)
    dx_end: float
    dv_end: float
    force: float = 0.0   # a pulse's constant force on the segment (0: free flight)


class Engine:
    """The simulated oscillator between ROS and the core: samples, periods, splits.

    The state is carried as the deviation (dx, dv) from the non-impacting motion at the
    current Pi2 sample k (time t_k). :meth:`begin_period` integrates the period with a
    correction by one :func:`period_step` call; :meth:`split` (realtime) re-evaluates the
    current period from its start to a time inside it and applies a correction there;
    :meth:`end_period` moves to the next sample, where pending model parameters take
    effect and the velocity noise is added. In an n-DOF scene (module docstring) the
    state is ``z`` and the model's pieces are :attr:`section`'s.
    """

    def __init__(self, settings: SimSettings):
        self.settings = settings
        # the n-DOF model's pieces (oscillator.ndof.section), None for the 1-DOF closed form
        model = getattr(settings, "model", None)
        self.section = None if model is None else NdofSection(model)
        self.p = settings.params if self.section is None else self.section
        # the drifting wall (delta_d_drift, issue 29): the model in force when the drift
        # (re)started and that sample's index; self.p's Delta d moves from it
        self.drift = getattr(settings, "delta_d_drift", 0.0)
        self._drift_from = (self.p, 0)
        # the exact flow of each piece: the wall's (compiled when available) or the
        # compliant stop's, with the same signature (plant.contact_plant)
        contact = getattr(settings, "contact", None)
        self.advance = kernel.exact_advance() if contact is None else contact.advance
        self.pending = None
        self.rng = np.random.default_rng(settings.seed)
        self.impacts = 0
        self._drawn = None
        self.force = 0.0          # the actuator's force at the current sample
        self._force_end = 0.0     # ... at the end of the period integrated
        self._head = None         # begin_head's flow to the actuation start
        self.reset()

    # ---------------------------------------------------------------- samples
    def reset(self) -> Event:
        """Back to the initial state, sample 0 at t = 0 (pending parameters apply now)."""
        if self.pending is not None:
            self.p, self.pending = self.pending, None
        elif self.drift:
            self.p = self._drift_from[0]
        self._drift_from = (self.p, 0)
        if self.section is not None:
            self.section = self.p
        s = self.settings
        self.rng = np.random.default_rng(s.seed)
        self.k = 0
        self.k_base, self.t_base = 0, 0.0
        if self.section is not None:
            self.z = self.section.start(s.state0)
            self.impacts = 0
            self.seg = None
            self._head = None
            self.force = self._force_end = 0.0
            return self._model_sample()
        self.dx, self.dv = initial_deviation(self.p, s.x0, s.v0)
        self.impacts = 0
        self.seg = None
        self._head = None
        self.force = self._force_end = 0.0
        return self._sample()

    @property
    def done(self) -> bool:
        """Whether ``max_periods`` periods have run (never when max_periods = 0)."""
        return 0 < self.settings.max_periods <= self.k

    @property
    def t(self) -> float:
        """Time of the current sample, t_k = k T (re-based when T changes)."""
        return self.t_base + (self.k - self.k_base) * self.p.period

    def _sample(self) -> Event:
        if self.settings.noise > 0.0:
            self.dv += float(self.rng.normal(0.0, self.settings.noise))
        p = self.p
        return Event(self.t, "pi2", p.x_ref + self.dx, p.v_ref + self.dv, p.tau2)

    def _model_sample(self) -> NdofEvent:
        """:meth:`_sample` of an n-DOF scene: the velocity noise at Pi2 is a kick on the
        actuated velocity (NdofSection.kicked), one draw of the seeded generator per
        sample as the 1-DOF scene's dv (n = 1: the same draws)."""
        if self.settings.noise > 0.0:
            self.z = self.section.kicked(self.z, float(self.rng.normal(0.0,
                                                                       self.settings.noise)))
        return self.sample()

    def sample(self) -> Event:
        """The current sample (without drawing noise again)."""
        if self.section is not None:
            return self._state(self.t, "pi2", self.p.tau2, self.z)
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
        if self.section is not None:    # every coordinate (FaultModel.coordinate_noise)
            nx, nv = self.settings.faults.coordinate_noise(self.k, self.section.n)
            return ev._replace(x=tuple(float(a + b) for a, b in zip(ev.x, nx)),
                               v=tuple(float(a + b) for a, b in zip(ev.v, nv)))
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
        the same two calls as ``simulate.period_step(..., delay=delay)``; with a pulse
        width w > 0 the flow to its start, the pulse, the flow on, as
        ``dynamics.simulation.actuation.pulse_step``. Returns the events of (t_k, t_k+1] in time
        order (state, Pi1, impacts), the next sample excluded.
        """
        if self.section is not None:
            if self.lagged:
                return self._model_lag_period(dv_correction, self.actuation_start(delay))
            return self._model_period(dv_correction, delay)
        if self.lagged:
            return self._lag_period(dv_correction, self.actuation_start(delay))
        p = self.p
        t0 = self.t
        if delay > 0.0:
            start = self.actuation_start(delay)
            events = self.begin_head(delay)
            return events + self._actuate(self._head[4], dv_correction, start)
        t1 = self.t_base + (self.k + 1 - self.k_base) * p.period
        states = None
        if self.settings.contact is not None:   # a compliant stop (plant.contact_plant)
            # ContactPlant.period_step's flow, its states in the same integration
            seg, states = self._free_piece(p.tau2, self.dx, self.dv + dv_correction,
                                           p.period, t0, t1)
        else:
            seg = period_step(p, self.dx, self.dv, dv_correction, self.settings.fidelity)
        self.seg = Segment(t0, p.tau2, self.dx, self.dv + dv_correction, t1, seg.dx, seg.dv)
        return self._events(self.seg, seg.impacts, states)

    def begin_head(self, delay: float, start: float | None = None) -> list:
        """Sample k's period up to the start of its correction ``delay`` after it
        (scheduled realtime: the correction is not known yet, and what follows its start
        is integrated by :meth:`actuate` once it is). The head is kept for
        :meth:`actuate` (the flow is never integrated twice: with a Hertz stop a period
        costs ms, docs/rig_scene.md); returns the events of (t_k, t_k + start]. Through
        the first-order actuator the whole uncorrected period (:meth:`actuate`
        re-integrates it with the command). ``start``: the correction's start after the
        sample, given (a rig's command timed off the rig's own section, plant.realtime;
        within [0, T - w]) instead of :meth:`actuation_start` of ``delay``."""
        if self.lagged:
            return self.begin_period(0.0)
        p = self.p
        t0 = self.t
        start = self.actuation_start(delay) if start is None else start
        if self.section is not None:
            head = (self.section.advance(p.tau2, self.z, start) if start > 0.0 else
                    _Rest(self.z, ()))
            self._head = (self.k, start, self.z, head)
            self.seg = Span(t0, p.tau2, self.z, (self.k + 1) * p.period, None, ())
            return self._model_events(Span(t0, p.tau2, self.z, t0 + start, head.z,
                                           head.impacts))
        head, states = self._free_piece(p.tau2, self.dx, self.dv, start, t0, t0 + start)
        self._head = (self.k, start, self.dx, self.dv, head)
        t1 = self.t_base + (self.k + 1 - self.k_base) * p.period
        # the period runs to t1; its end is known once actuate() has run
        self.seg = Segment(t0, p.tau2, self.dx, self.dv, t1, math.nan, math.nan)
        return self._events(Segment(t0, p.tau2, self.dx, self.dv, t0 + start, head.dx,
                                    head.dv), head.impacts, states)

    def actuation_start(self, delay: float) -> float:
        """When the correction of a sample acting ``delay`` after it starts to act: at
        ``delay`` (the velocity jump), or, for a force pulse of width w, at delay - w/2
        (centred at the actuation time, docs/theory_pulse.md), kept within [0, T - w)."""
        return pulse_start(self.p.period, delay, self.settings.pulse_width)

    def actuate(self, dv_correction: float, delay: float, start: float | None = None) -> list:
        """Apply ``dv_correction`` exactly ``delay`` after the current sample (scheduled).

        The period is re-integrated as ``simulate.period_step(p, dx, dv, dv_correction,
        delay=delay)`` does it (the free flow with impacts to t_k + delay, the velocity
        jump, the flow on to t_k+1), or as ``pulse_step`` for a pulse, so a realtime period
        equals the lockstep one bit for bit. Returns the events from the actuation's start
        to t_k+1. ``start`` (as :meth:`begin_head`'s): the pulse's start after the sample,
        given instead of :meth:`actuation_start` of ``delay``; the same flows from there.
        """
        start = self.actuation_start(delay) if start is None else start
        if self.section is not None and self.lagged:
            t = self.t + start
            return [ev for ev in self._model_lag_period(dv_correction, start) if ev.t >= t]
        if self.section is not None:
            kept = self._head
            if kept is not None and kept[:2] == (self.k, start) and kept[2] is self.z:
                head = kept[3]                  # begin_head's flow to the start
            else:
                head = (self.section.advance(self.p.tau2, self.z, start) if start > 0.0
                        else _Rest(self.z, ()))
            self._head = None
            return self._model_actuate(head.z, dv_correction, start)
        if self.lagged:
            t = self.t + start
            return [ev for ev in self._lag_period(dv_correction, start) if ev.t >= t]
        kept = self._head
        if kept is not None and kept[:4] == (self.k, start, self.dx, self.dv):
            head = kept[4]                  # begin_head's flow to the start
        else:
            head = self.advance(self.p, self.p.tau2, self.dx, self.dv, start)
        return self._actuate(head, dv_correction, start)

    @property
    def lagged(self) -> bool:
        """Whether a first-order actuator (bandwidth or latency) stands between the
        command and the force (settings.actuator not ideal)."""
        return not self.settings.actuator.ideal

    def _lag_period(self, dv_correction: float, start: float) -> list:
        """The period from the current sample with the command of ``dv_correction`` at
        ``start`` through the actuator (module docstring): a pulse F = Delta v / w on
        [start, start + w] (w = 0: an impulse Delta v) reaches the lag L later; on each
        piece between the switches the force is F_inf + C e^{-h / tau_a} and the motion
        :func:`lag_flow`'s. The force at the next sample is kept for :meth:`end_period`.
        Returns the period's events (state, Pi1, impacts) in time order."""
        p, s = self.p, self.settings
        t0 = self.t
        t1 = self.t_base + (self.k + 1 - self.k_base) * p.period
        contact = getattr(s, "contact", None)
        events = []
        if contact is None:
            def flow(*a):
                return lag_flow(p, *a)
        else:   # the compliant stop's flow under the force (contact_plant)
            def flow(*a):
                return contact.lag_flow(p, *a)

        def publish(h, end, tau, dx, dv, u, c, piece):
            if contact is None:
                states = (lambda rel: lag_states(p, piece, rel))
            else:
                states = (lambda rel: contact.lag_states(p, tau, dx, dv, u, c,
                                                         s.actuator.time_constant, rel))
            te = t1 if end == p.period else t0 + end
            events.extend(self._events(Segment(t0 + h, tau, dx, dv, te, piece.dx, piece.dv),
                                       piece.impacts, states))

        dx, dv, f, _ = command_period(p, self.dx, self.dv, self.force, dv_correction, start,
                                      s.pulse_width, s.actuator, s.force_limit or math.inf,
                                      flow, publish)
        self.seg = Segment(t0, p.tau2, self.dx, self.dv, t1, dx, dv)
        self._force_end = f
        return events

    def _actuate(self, head, dv_correction: float, start: float) -> list:
        p = self.p
        t, w = self.t, self.settings.pulse_width
        t1 = self.t_base + (self.k + 1 - self.k_base) * p.period
        tau = (p.tau2 + p.omega * start) % TWO_PI
        self._head = None
        if w == 0.0:                                    # the kick of Eq. 28
            dv = head.dv + dv_correction
            tail, states = self._free_piece(tau, head.dx, dv, p.period - start, t + start, t1)
            self.seg = Segment(t + start, tau, head.dx, dv, t1, tail.dx, tail.dv)
            return self._events(self.seg, tail.impacts, states)
        # a force pulse on [start, start + w]: the exact flow under a constant force
        limit = self.settings.force_limit or math.inf
        force = pulse_force(dv_correction, w, limit)
        mid = flow_with_force(p, tau, head.dx, head.dv, w, force, self.advance)
        events = self._events(Segment(t + start, tau, head.dx, head.dv, t + start + w,
                                      mid.dx, mid.dv, force), mid.impacts)
        tau = (p.tau2 + p.omega * (start + w)) % TWO_PI
        tail, states = self._free_piece(tau, mid.dx, mid.dv, p.period - start - w,
                                        t + start + w, t1)
        self.seg = Segment(t + start + w, tau, mid.dx, mid.dv, t1, tail.dx, tail.dv)
        return events + self._events(self.seg, tail.impacts, states)

    def split(self, tc: float, dv_correction: float) -> list:
        """Apply ``dv_correction`` at time tc inside the current period (realtime).

        The exact flow is re-evaluated from the period's start to tc (same closed form as
        the events already published), the velocity jumps there, and the flow continues
        to the next sample. Returns the events of (tc, t_k+1).
        """
        if self.lagged:
            raise RuntimeError("a correction on arrival through the actuator: refused by "
                               "the settings (actuation on_arrival with an actuator)")
        if self.section is not None:
            return self._model_split(tc, dv_correction)
        s, p = self.seg, self.p
        tc = min(max(tc, s.ts), s.te)
        head = self.advance(p, s.tau, s.dx, s.dv, tc - s.ts)
        tau_c = (s.tau + p.omega * (tc - s.ts)) % TWO_PI
        dv_c = head.dv + dv_correction
        tail, states = self._free_piece(tau_c, head.dx, dv_c, s.te - tc, tc, s.te)
        self.seg = Segment(tc, tau_c, head.dx, dv_c, s.te, tail.dx, tail.dv)
        return self._events(self.seg, tail.impacts, states)

    def end_period(self) -> tuple:
        """Move to the next sample: returns (sample event, warning or None).

        Pending model parameters take effect here, never within a period: the physical
        state (x, v) at the sample is kept and re-expressed as a deviation of the new
        model on its own Pi2 (if it lies beyond the new wall it is put on the wall).
        """
        s = self.seg
        if self.section is not None:
            self.z = s.z_end
            self.force = self._force_end
            self.k += 1
            self.seg = None
            if self.drift:
                self._drift_wall()
            return self._model_sample(), None
        self.dx, self.dv = s.dx_end, s.dv_end
        self.force = self._force_end
        self.k += 1
        self.seg = None
        warning = None
        if self.pending is not None:
            warning = self._apply_pending()
            self._drift_from = (self.p, self.k)
        elif self.drift:
            self._drift_wall()
        return self._sample(), warning

    def _drift_wall(self) -> None:
        """The wall of sample k's period under the linear drift: Delta d in force at
        sample k0 plus delta_d_drift * (k - k0), as ``plant_at(k)`` of
        dynamics.estimation.stream.simulate_stream; X** (which does not depend on Delta d) and the
        deviation stay (a state beyond the moved wall is left to the flow: the drift
        per period is far below the distance to the wall on Pi2). In an n-DOF scene the
        model's Delta d moves (:meth:`NdofSection.with_delta_d`): z, the deviation from
        the periodic response, stays."""
        base, k0 = self._drift_from
        if self.section is not None:
            self.p = self.section = base.with_delta_d(base.model.delta_d
                                                      + self.drift * (self.k - k0))
            return
        self.p = base.with_(delta_d=base.delta_d + self.drift * (self.k - k0))

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

    def initial_states(self) -> list:
        """The state stream's sample at t = 0 (grid index 0; none when state_period = 0):
        published with sample 0, before its answer is awaited, so that a controller
        estimating Pi2 from the stream has it."""
        if self.settings.state_period <= 0.0 or self.t != 0.0:
            return []
        p = self.p
        if self.section is not None:
            return self._measured(0, [self._state(0.0, "state", p.tau2, self.z)])
        xm, vm = self.settings.sensor.measure(0, [p.x_ref + self.dx], [p.v_ref + self.dv])
        return [Event(0.0, "state", float(xm[0]), float(vm[0]), p.tau2)]

    def _published_times(self, ts: float, te: float, tau: float):
        """The times (from ts, sorted) at which a segment [ts, te] starting at phase
        ``tau`` publishes a state: the stream's grid j * state_period in (ts, te] and the
        Pi1 crossing; (rel, kinds, the first grid index j0)."""
        p = self.p
        rel, kinds = [], []
        sp = self.settings.state_period
        j0 = None
        if sp > 0.0:
            j = math.floor(ts / sp)
            while j * sp <= te:
                if j * sp > ts:
                    j0 = j if j0 is None else j0
                    rel.append(j * sp - ts)
                    kinds.append("state")
                j += 1
        d1 = ((p.tau_star - tau) % TWO_PI) / p.omega
        if 0.0 < d1 < te - ts:
            rel.append(d1)
            kinds.append("pi1")
        if rel:
            order = sorted(range(len(rel)), key=rel.__getitem__)    # stable, as argsort's
            rel = [rel[i] for i in order]
            kinds = [kinds[i] for i in order]
        return rel, kinds, j0

    def _free_piece(self, tau: float, dx: float, dv: float, duration: float, ts: float,
                    te: float):
        """The exact flow of a piece without force (from (dx, dv) at phase ``tau`` for
        ``duration``, published over [ts, te]): (segment, states for :meth:`_events`).
        With a compliant stop its published states come from the same integration
        (ContactPlant.advance_with_states: a Hertz contact is integrated once, not again
        for the stream, docs/rig_scene.md); the wall's are its closed form (None)."""
        contact = self.settings.contact
        if contact is None:
            return self.advance(self.p, tau, dx, dv, duration), None
        rel = self._published_times(ts, te, tau)[0]
        seg, xv = contact.advance_with_states(self.p, tau, dx, dv, duration, rel)
        return seg, (lambda _rel: xv)

    def _events(self, s: Segment, impacts, states=None) -> list:
        """The events of segment ``s``: its impacts, the state stream's samples on the
        grid j * state_period in (ts, te] as the sensor measures them (plant.sensor,
        draws of sample j), and the Pi1 crossing; in time order. Under a pulse's force F
        the states are the flow of the oscillator with clearance Delta d - F shifted by
        F (dynamics.simulation.actuation.flow_with_force); through the actuator ``states`` (times
        since the segment's start -> physical (x, v)) evaluates them."""
        p = self.p
        events = []
        for i in impacts:
            events.append(Event(s.ts + i.dt, "impact", i.v_minus, i.v_plus, i.phase % TWO_PI))
        rel, kinds, j0 = self._published_times(s.ts, s.te, s.tau)
        if rel:
            if states is not None:
                xv = states(rel)
            else:   # under a pulse's force F: the stop moved by -F, x shifted by F
                q = p if s.force == 0.0 else p.with_(delta_d=p.delta_d - s.force)
                contact = self.settings.contact
                xv = (states_between(q, s.tau, s.dx - s.force, s.dv, impacts, rel)
                      if contact is None else
                      contact.states_between(q, s.tau, s.dx - s.force, s.dv, rel))
                xv[:, 0] += s.force
            states = [i for i, kind in enumerate(kinds) if kind == "state"]
            if states:
                xm, vm = self.settings.sensor.measure(j0, xv[states, 0], xv[states, 1])
                xv[states, 0], xv[states, 1] = xm, vm
            ts, tau, omega, tau_star = s.ts, s.tau, p.omega, p.tau_star
            for h, kind, (x, v) in zip(rel, kinds, xv.tolist()):    # Python floats, exact
                phase = tau_star if kind == "pi1" else (tau + omega * h) % TWO_PI
                events.append(Event(ts + h, kind, x, v, phase))
        if impacts:             # the rest come in time order (rel is sorted)
            events.sort(key=lambda e: e.t)
        return events

    # ------------------------------------------------- the n-DOF model's pieces
    def _state(self, t: float, kind: str, tau: float, z) -> NdofEvent:
        x, v = self.section.physical(tau, z)
        return NdofEvent(t, kind, x, v, tau)

    def _model_period(self, dv_correction: float, delay: float) -> list:
        """:meth:`begin_period` of an n-DOF scene: the kick and one piece, or the flow to
        t_k + delay, the kick there, the flow to t_k+1 (module docstring)."""
        sec, t0 = self.section, self.t
        if delay > 0.0:
            start = self.actuation_start(delay)
            if start > 0.0:
                head = sec.advance(sec.tau2, self.z, start)
                events = self._model_events(Span(t0, sec.tau2, self.z, t0 + start, head.z,
                                                 head.impacts))
                return events + self._model_actuate(head.z, dv_correction, start)
            return self._model_actuate(self.z, dv_correction, start)   # a pulse from t_k
        z = sec.kicked(self.z, dv_correction)
        piece = sec.advance(sec.tau2, z, sec.period)
        self.seg = Span(t0, sec.tau2, z, (self.k + 1) * sec.period, piece.z, piece.impacts)
        return self._model_events(self.seg)

    def _model_lag_period(self, dv_correction: float, start: float) -> list:
        """The n-DOF period through the first-order actuator (module docstring): the
        command m_a Delta v / w (clipped) on [start + L, start + L + w], the force from
        :attr:`force` at the sample, the legs of
        :func:`grazing_control.dynamics.maps.modal_map.actuated_step` (its calls, so a
        lockstep run is its iterates bit for bit); tau_a = 0 (latency only) is the pulse
        at start + L. The force at the next sample is kept for :meth:`end_period`."""
        sec, s = self.section, self.settings
        act, w = s.actuator, s.pulse_width
        if act.time_constant == 0.0:
            self._force_end = 0.0
            head_events, z_head = self._model_head(start + act.latency)
            return head_events + self._model_actuate(z_head, dv_correction,
                                                     start + act.latency)
        command = sec.pulse_force(dv_correction, w, s.force_limit or math.inf)
        on, off = start + act.latency, start + act.latency + w
        t0, end_t = self.t, (self.k + 1) * sec.period
        z, f, t, events = self.z, float(self.force), 0.0, []
        for end, u in ((on, 0.0), (off, command), (sec.period, 0.0)):
            if end > t:
                tau = (sec.tau2 + sec.omega * t) % TWO_PI
                piece = sec.lagged(tau, z, end - t, u, f - u, act.time_constant)
                self.seg = Span(t0 + t, tau, z, end_t if end == sec.period else t0 + end,
                                piece.z, piece.impacts, 0.0, (u, f - u, act.time_constant))
                events += self._model_events(self.seg)
                z, f = np.array(piece.z, dtype=float), float(piece.force)
            t = end
        self._force_end = f
        return events

    def _model_head(self, start: float):
        """(events up to ``start``, the deviation there) of the free flow from the sample."""
        sec = self.section
        if start <= 0.0:
            return [], self.z
        head = sec.advance(sec.tau2, self.z, start)
        return self._model_events(Span(self.t, sec.tau2, self.z, self.t + start, head.z,
                                       head.impacts)), head.z

    def _model_actuate(self, z_head, dv_correction: float, start: float) -> list:
        """The kick ``start`` after the sample and the flow on to t_k+1 (n-DOF); with a
        pulse width w > 0 the pulse on [start, start + w] and the flow on (the legs of
        :func:`grazing_control.dynamics.maps.modal_map.pulse_step`)."""
        sec, w = self.section, self.settings.pulse_width
        tau = (sec.tau2 + sec.omega * start) % TWO_PI
        if w > 0.0:
            force = sec.pulse_force(dv_correction, w, self.settings.force_limit or math.inf)
            # the durations as pulse_step's legs (t1 - t0), so lockstep is its calls
            mid = sec.pushed(tau, np.array(z_head, dtype=float), (start + w) - start, force)
            events = self._model_events(Span(self.t + start, tau, z_head, self.t + start + w,
                                             mid.z, mid.impacts, force))
            end = start + w
            tau = (sec.tau2 + sec.omega * end) % TWO_PI
            tail = sec.advance(tau, np.array(mid.z, dtype=float), sec.period - end)
            self.seg = Span(self.t + end, tau, mid.z, (self.k + 1) * sec.period, tail.z,
                            tail.impacts)
            return events + self._model_events(self.seg)
        z = sec.kicked(z_head, dv_correction)
        tail = sec.advance(tau, z, sec.period - start)
        self.seg = Span(self.t + start, tau, z, (self.k + 1) * sec.period, tail.z,
                        tail.impacts)
        return self._model_events(self.seg)

    def _model_split(self, tc: float, dv_correction: float) -> list:
        """:meth:`split` of an n-DOF scene: the flow from the stretch's start to tc, the
        kick, the flow to the next sample."""
        s, sec = self.seg, self.section
        tc = min(max(tc, s.ts), s.te)
        head = sec.advance(s.tau, s.z, tc - s.ts)
        tau_c = (s.tau + sec.omega * (tc - s.ts)) % TWO_PI
        z = sec.kicked(head.z, dv_correction)
        tail = sec.advance(tau_c, z, s.te - tc)
        self.seg = Span(tc, tau_c, z, s.te, tail.z, tail.impacts)
        return self._model_events(self.seg)

    def _measured(self, j0: int, states: list) -> list:
        """The n-DOF stream's samples j0, j0 + 1, ... (``states``, exact) as the sensor
        measures them (:func:`~grazing_control.oscillator.ndof.section.measure_coordinates`)."""
        sensor = self.settings.sensor
        if sensor.exact and sensor.velocity or not states:
            return states
        xm, vm = measure_coordinates(sensor, j0, [e.x for e in states],
                                     [e.v for e in states])
        return [e._replace(x=tuple(float(a) for a in x), v=tuple(float(a) for a in v))
                for e, x, v in zip(states, xm, vm)]

    def _model_events(self, s: Span) -> list:
        """The events of an n-DOF stretch (as :meth:`_events`): its impacts, the stream's
        samples on the grid in (ts, te] as the sensor measures them, the Pi1 crossing."""
        sec = self.section
        events = [Event(s.ts + i.dt, "impact", float(i.v_minus), float(i.v_plus),
                        float(i.phase) % TWO_PI) for i in s.impacts]
        rel, kinds, j0 = self._published_times(s.ts, s.te, s.tau)
        if rel:
            zs = (sec.deviations_between(s.tau, s.z, s.impacts, rel, s.force)
                  if s.lag is None else
                  sec.lag_deviations_between(s.tau, s.z, s.impacts, rel, *s.lag))
            states = []
            for h, kind, z in zip(rel, kinds, zs):
                tau = sec.tau_star if kind == "pi1" else (s.tau + sec.omega * h) % TWO_PI
                (states if kind == "state" else events).append(
                    self._state(s.ts + h, kind, tau, z))
            events += self._measured(j0, states)
        events.sort(key=lambda e: e.t)
        return events

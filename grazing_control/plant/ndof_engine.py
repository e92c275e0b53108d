"""The simulated n-DOF oscillator, sample by sample: what sim_node drives with ``model_file``.

:class:`NdofEngine` has the interface of :class:`grazing_control.plant.engine.Engine`
that the loops (:mod:`.lockstep`, :mod:`.realtime`) and sim_node use, over the n-DOF
exact core (issue 17): the state is the deviation z in R^{2n} = (x - x_p, v - v_p) from
the periodic response at the current Pi2 sample k (t_k = k T), and each period is the
core's :func:`grazing_control.oscillator.ndof.impact.advance` from Pi2 with the
correction on the actuated velocity,

    z+ = z + e_{n + i_a} Delta v,    z_{k+1} = advance(flow, tau2, z+, T).z,

the calls :class:`grazing_control.dynamics.maps.ndof_map.NdofMap` makes with Delta v = k^T z,
so a lockstep run with that controller repeats NdofMap's iterates bit for bit. A
correction delayed by s is the flow to t_k + s, the jump there, the flow to t_k+1 (as
the 1-DOF engine, docs/theory_delay.md); realtime on-arrival corrections split the
period the same way.

Everything published between two samples (the state stream, the Pi1 crossing) is
evaluated from the period's impact list without changing the trajectory: between
impacts the deviation flows linearly, z(t + h) = Phi(h) z(t) (the periodic response
absorbs the forcing; docs/ndof_model.md), and an impact changes only the wall
coordinate's velocity, by v+ - v-, which adds (v+ - v-) e_{n + i_w} to z. A period with
a sticking impact is evaluated by ``advance`` from its start instead.

The state stream is what the scene's sensor (``settings.sensor``, a
:class:`grazing_control.plant.sensor.SensorModel`: noise, bias, quantum, position only)
measures of every coordinate: sample j's coordinate i is the sensor's draw number
j n + i (:func:`measure_coordinates`), a pure function of (seed, j) as in 1-DOF, and
for n = 1 the 1-DOF sensor's draws bit for bit. A position-only sensor's velocities
are NaN (published as an empty velocity list).

The events are :class:`NdofEvent` (x, v: tuples of the n coordinates) for the state
stream, Pi1 and Pi2, and the 1-DOF :class:`~grazing_control.plant.engine.Event` for an
impact (x = v-, v = v+ of the wall coordinate). No ROS.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.plant.engine import Event

__all__ = ["NdofEvent", "Span", "NdofEngine", "measure_coordinates"]

TWO_PI = 2.0 * math.pi


def measure_coordinates(sensor, j0: int, x, v):
    """What ``sensor`` (a :class:`~grazing_control.plant.sensor.SensorModel`) measures of
    the stream samples j0, j0 + 1, ... with true positions ``x`` and velocities ``v``
    (m, n): coordinate i of sample j is the sensor's sample j n + i (its draws, bias,
    quantum), velocities NaN for a position-only sensor. Returns (x~, v~), (m, n)."""
    x = np.asarray(x, dtype=float)
    v = np.asarray(v, dtype=float)
    m, n = x.shape
    xm, vm = sensor.measure(j0 * n, x.reshape(-1), v.reshape(-1))
    return xm.reshape(m, n), vm.reshape(m, n)


class NdofEvent(NamedTuple):
    """A state to publish at simulation time t: kind 'state', 'pi1' or 'pi2' (the sample
    before its correction); ``x``, ``v`` the physical positions and velocities of the n
    coordinates; ``phase`` the forcing phase."""

    t: float
    kind: str
    x: tuple
    v: tuple
    phase: float


class Span(NamedTuple):
    """One stretch of a period after its last correction: from (ts, tau, z) to te."""

    ts: float          # start time
    tau: float         # forcing phase at the start
    z: np.ndarray      # deviation at the start, after any correction
    te: float          # end time (the next Pi2 sample)
    z_end: np.ndarray  # deviation at te
    impacts: tuple     # the core's impacts of the stretch (dt from ts)


class NdofEngine:
    """The n-DOF oscillator between ROS and the core (module docstring).

    ``settings`` is a :class:`grazing_control.plant.ndof_settings.NdofSettings`.
    Model changes while running are not built (sim_node refuses them).
    """

    def __init__(self, settings):
        self.settings = settings
        self.model = settings.model
        self.flow = NdofFlow.of(self.model)
        self.p = self.model          # what the loops read: p.period
        self.n = self.model.n
        self.pending = None
        self.impacts = 0
        self.reset()

    # ---------------------------------------------------------------- samples
    def reset(self) -> NdofEvent:
        """Back to the initial state, the grazing point X** (z = 0): sample 0 at t = 0."""
        self.k = 0
        self.z = np.zeros(2 * self.n)
        self.impacts = 0
        self.seg = None
        return self.sample()

    @property
    def done(self) -> bool:
        """Whether ``max_periods`` periods have run (never when max_periods = 0)."""
        return 0 < self.settings.max_periods <= self.k

    @property
    def t(self) -> float:
        """Time of the current sample, t_k = k T."""
        return self.k * self.model.period

    def _state(self, t: float, kind: str, tau: float, z) -> NdofEvent:
        X = self.flow.to_physical(tau, z)
        n = self.n
        return NdofEvent(t, kind, tuple(float(a) for a in X[:n]),
                         tuple(float(a) for a in X[n:]), tau)

    def sample(self) -> NdofEvent:
        """The current Pi2 sample (physical, before its correction)."""
        return self._state(self.t, "pi2", self.flow.tau2, self.z)

    def measured(self, ev: NdofEvent) -> NdofEvent:
        """Sample k as the controller sees it: as it is (measurement noise is refused for
        n-DOF by the settings)."""
        return ev

    def correction_lost(self) -> bool:
        """Whether sample k's correction is dropped by the injected loss (FaultModel)."""
        return self.settings.loss > 0.0 and self.settings.faults.draw(self.k).dropped

    def actuation_delay(self) -> float:
        """Delay of sample k's correction: actuation_delay + jitter e_k, in [0, T)."""
        s = self.settings
        if s.jitter == 0.0:
            return s.actuation_delay
        return s.faults.actuation_delay(s.actuation_delay, self.k, self.model.period)

    # ---------------------------------------------------------------- periods
    def _kicked(self, z, dv: float) -> np.ndarray:
        """z + e_{n + i_a} Delta v (the kick on the actuated velocity)."""
        z = np.array(z, dtype=float)
        z[self.n + self.model.i_a] += dv
        return z

    def begin_period(self, dv_correction: float, delay: float = 0.0) -> list:
        """Integrate the period from the current sample with ``dv_correction`` acting
        ``delay`` after it (module docstring). Returns the events of (t_k, t_k+1] in time
        order (state, Pi1, impacts), the next sample excluded."""
        t0, tau2 = self.t, self.flow.tau2
        if delay > 0.0:
            head = advance(self.flow, tau2, self.z, delay)
            events = self._events(Span(t0, tau2, self.z, t0 + delay, head.z, head.impacts))
            return events + self._actuate(head.z, dv_correction, delay)
        z = self._kicked(self.z, dv_correction)
        seg = advance(self.flow, tau2, z, self.model.period)
        self.seg = Span(t0, tau2, z, (self.k + 1) * self.model.period, seg.z, seg.impacts)
        return self._events(self.seg)

    def actuation_start(self, delay: float) -> float:
        """When a correction acting ``delay`` after its sample starts to act: then (the
        velocity jump; no pulses for n-DOF)."""
        return delay

    def actuate(self, dv_correction: float, delay: float) -> list:
        """Apply ``dv_correction`` exactly ``delay`` after the current sample (scheduled):
        the flow to t_k + delay, the jump, the flow to t_k+1, as :meth:`begin_period` with
        that delay. Returns the events from the actuation to t_k+1."""
        head = advance(self.flow, self.flow.tau2, self.z, delay)
        return self._actuate(head.z, dv_correction, delay)

    def _actuate(self, z_head, dv_correction: float, start: float) -> list:
        m = self.model
        tau = (self.flow.tau2 + m.omega * start) % TWO_PI
        z = self._kicked(z_head, dv_correction)
        tail = advance(self.flow, tau, z, m.period - start)
        self.seg = Span(self.t + start, tau, z, (self.k + 1) * m.period, tail.z, tail.impacts)
        return self._events(self.seg)

    def split(self, tc: float, dv_correction: float) -> list:
        """Apply ``dv_correction`` at time tc inside the current period (realtime, on
        arrival): the flow from the stretch's start to tc, the jump, the flow to the next
        sample. Returns the events of (tc, t_k+1)."""
        s, m = self.seg, self.model
        tc = min(max(tc, s.ts), s.te)
        head = advance(self.flow, s.tau, s.z, tc - s.ts)
        tau_c = (s.tau + m.omega * (tc - s.ts)) % TWO_PI
        z = self._kicked(head.z, dv_correction)
        tail = advance(self.flow, tau_c, z, s.te - tc)
        self.seg = Span(tc, tau_c, z, s.te, tail.z, tail.impacts)
        return self._events(self.seg)

    def end_period(self) -> tuple:
        """Move to the next sample: returns (sample event, None)."""
        self.z = self.seg.z_end
        self.k += 1
        self.seg = None
        return self.sample(), None

    def initial_states(self) -> list:
        """The state stream's sample at t = 0 (none when state_period = 0), published
        with sample 0."""
        if self.settings.state_period <= 0.0 or self.t != 0.0:
            return []
        return self._measured(0, [self._state(0.0, "state", self.flow.tau2, self.z)])

    def _measured(self, j0: int, states: list) -> list:
        """The stream's samples j0, j0 + 1, ... (``states``, exact) as the sensor
        measures them (:func:`measure_coordinates`)."""
        sensor = self.settings.sensor
        if sensor.exact and sensor.velocity or not states:
            return states
        xm, vm = measure_coordinates(sensor, j0, [e.x for e in states],
                                     [e.v for e in states])
        return [e._replace(x=tuple(float(a) for a in x), v=tuple(float(a) for a in v))
                for e, x, v in zip(states, xm, vm)]

    # ---------------------------------------------------------------- events
    def deviations_between(self, s: Span, times) -> np.ndarray:
        """z at ``times`` (sorted, since ``s.ts``, within the stretch) from the stretch's
        impact list (module docstring): the free flow between impacts, the wall
        coordinate's velocity jump at each. With a sticking impact, ``advance`` from the
        stretch's start to each time."""
        out = np.empty((len(times), 2 * self.n))
        if any(i.sticking for i in s.impacts):
            for j, h in enumerate(times):
                out[j] = advance(self.flow, s.tau, s.z, h).z
            return out
        jump = self.n + self.model.i_w
        t0, z, k = 0.0, np.asarray(s.z, dtype=float), 0
        for j, h in enumerate(times):
            while k < len(s.impacts) and s.impacts[k].dt <= h:
                imp = s.impacts[k]
                z = self.flow.transition(imp.dt - t0) @ z
                z[jump] += imp.v_plus - imp.v_minus
                t0 = imp.dt
                k += 1
            out[j] = self.flow.transition(h - t0) @ z
        return out

    def _events(self, s: Span) -> list:
        """The events of stretch ``s``: its impacts, the state stream's samples on the grid
        j * state_period in (ts, te], and the Pi1 crossing; in time order."""
        m = self.model
        events = [Event(s.ts + i.dt, "impact", float(i.v_minus), float(i.v_plus),
                        float(i.phase) % TWO_PI) for i in s.impacts]
        rel, kinds = [], []
        sp = self.settings.state_period
        j0 = None
        if sp > 0.0:
            j = math.floor(s.ts / sp)
            while j * sp <= s.te:
                if j * sp > s.ts:
                    j0 = j if j0 is None else j0
                    rel.append(j * sp - s.ts)
                    kinds.append("state")
                j += 1
        d1 = ((self.flow.tau_star - s.tau) % TWO_PI) / m.omega
        if 0.0 < d1 < s.te - s.ts:
            rel.append(d1)
            kinds.append("pi1")
        if rel:
            order = np.argsort(rel, kind="stable")
            rel = [rel[i] for i in order]
            kinds = [kinds[i] for i in order]
            zs = self.deviations_between(s, rel)
            states = []
            for h, kind, z in zip(rel, kinds, zs):
                tau = self.flow.tau_star if kind == "pi1" else (s.tau + m.omega * h) % TWO_PI
                (states if kind == "state" else events).append(
                    self._state(s.ts + h, kind, tau, z))
            events += self._measured(j0, states)
        events.sort(key=lambda e: e.t)
        return events

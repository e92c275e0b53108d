"""Sampling Pi2 from a sensor stream: which samples belong to which section, when a
section's estimate is due, and the closed loop of plant, sensor, estimator and Eq. 28.

The stream's samples arrive in time order (stamp t, simulation time; the section times
are t_k = k T, the simulator's origin: docs/nodes.md, "The sensor stream"). The
estimate of section k uses the samples with t_{k-1} < t <= t_k (a sample at t_k is
before that section's correction) and is due as soon as no further sample before t_k can
come: when t + h >= t_k for the newest sample (h the sample period; a sample at t_k
itself is not waited for; realtime, ``after_section``: with the sample at t_k), or when a
sample after t_k arrives (one was lost). :class:`StreamEstimator` is that bookkeeping
over the estimators of :mod:`grazing_control.dynamics.estimation.section_state`; the controller node
feeds it from ``oscillator/state``, and :func:`simulate_stream` from the exact flow
through a sensor's ``measure`` (a :class:`grazing_control.plant.sensor.SensorModel`:
the plant layer lies above this one, so the caller passes it in).

With an n-DOF model (:class:`~grazing_control.oscillator.ndof.model.NdofModel`) the
samples are the position (and maybe velocity) of one coordinate ``coordinate`` and the
estimator is the model filter over the exact n-DOF map alone
(docs/theory_estimation.md, (E11)): the estimate is 2n-dimensional; where the filter
has no state at the section before (the start) or its fit fails (a kick that acted
otherwise than known, a jump), the period's samples are fitted from the uninformative
prior (``NDOF_PRIOR``)^2 I about the filter's state (z = 0 at the start); where that
fails too the estimate is the filter's state carried one period through the model
(source ``predicted``), or z = 0 at the start (source ``prior``: the answer is 0).
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections import deque
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator import kernel as _kernel
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.estimation.section_state import (
    CHI2_SIGMAS, ESTIMATORS, Estimate, FilterState, arc_fit, deviation_samples,
    detect_impact, model_update, nearest_estimate, unkick)
from grazing_control.dynamics.estimation.motion import (carry, section_force, trajectory,
                                                         trajectory_end)

__all__ = ["IMPACT_SOURCES", "StreamEstimator", "StreamRun", "simulate_stream", "predict_section",
           "pulse_shape", "warm_up"]

#: Where impacts come from: the rig's impact sensor, or detection in the stream.
IMPACT_SOURCES = ("topic", "stream")
#: The n-DOF filter's prior std at a (re)start: far wider than any Pi2 deviation near
#: grazing, so that the first period's samples alone decide (E11).
NDOF_PRIOR = 1.0
#: Tolerance on times, relative to T: a sample within it of t_k is at t_k.
_TOL = 1e-9
#: A sample more than this many periods after the newest is a stray unless the next
#: sample follows it (then the stream jumped: a restart from there).
MAX_GAP = 4


class StreamEstimator:
    """Estimates of the Pi2 states from a stream of samples (no ROS).

    Parameters
    ----------
    p : OscillatorParams
        The model (Delta d included: the impacts of the model need the wall).
    estimator : str
        ``nearest``, ``arc`` or ``model`` (:mod:`grazing_control.dynamics.estimation.section_state`).
    sigma : float
        The sensor's noise std (> 0 for ``arc`` and ``model``; the covariances scale
        with it).
    impact_source : str
        ``topic`` (impacts given by :meth:`add_impact`) or ``stream`` (detected).
    sample_period : float
        The stream's sample period h; 0: the gap between the last two samples.
    floor : float
        The model filter's floor (:func:`grazing_control.dynamics.estimation.section_state.model_update`).
    after_section : bool
        Make a section due with its last sample, the one at t_k included (realtime: the
        simulator publishes it before its Pi2 sample; with the newest sample t at
        t + h / 2 + lead > t_k, or a sample after t_k when that one is lost; the
        estimate is the one the first sample after t_k made due before, bit for bit), not
        with the last sample before t_k (lockstep: the simulator waits for the answer; a
        sample at t_k itself is not waited for).
    lead : float
        Make a section due ``lead`` (time, >= 0) before its last sample: with the newest
        sample t at t + h + lead >= t_k, or with ``after_section`` t + h / 2 + lead >
        t_k (a realtime rig, issue 28: the answer is computed
        while the last samples before t_k are on their way; this section's estimate has
        not got them, and the model filter, which fits each period's own samples, never
        uses them). 0: with the last sample (the default).
    pulse_width, force_limit : float
        How the corrections act in the plant: a velocity kick at the actuation delay
        (``pulse_width`` 0, the default), or the rig's force pulse of that width centred
        there, its force clipped to ``force_limit`` (> 0; inf: none). The model filter
        and :func:`predict_section` integrate it exactly
        (:func:`grazing_control.dynamics.estimation.motion.trajectory`); a kick in the model of
        a pulse in the plant put the rig scene's mean 5e-5 off its orbit.
    actuator : Actuator or None
        The plant's first-order actuator between the commanded pulse and the force
        (:class:`grazing_control.dynamics.simulation.actuator.Actuator`; needs ``pulse_width`` > 0):
        the model filter and :func:`predict_section` integrate the lag exactly, from the
        force left at each section by the known earlier corrections
        (:meth:`section_force`). None: the force is the command.
    kernel : bool or None
        Run the model filter compiled
        (:func:`grazing_control.dynamics.estimation.motion.trajectory`'s ``kernel``:
        the same estimates bit for bit, tests/test_estimation_compiled.py); None: where the
        compiled kernel is in use (:func:`grazing_control.oscillator.kernel.use_kernel`,
        ``GRAZING_KERNEL``). Kept as the ``kernel`` attribute, for
        :func:`predict_section`.
    """

    def __init__(self, p: OscillatorParams, estimator: str = "model", sigma: float = 1e-4,
                 impact_source: str = "stream", sample_period: float = 0.0,
                 floor: float = 1e-2, after_section: bool = False, lead: float = 0.0, *,
                 pulse_width: float = 0.0, force_limit: float = math.inf, actuator=None,
                 kernel: bool | None = None, coordinate: int = 0):
        if isinstance(p, NdofModel):
            if estimator != "model":
                raise ParameterError(f"estimator={estimator!r} is invalid with an n-DOF "
                                     "model: valid is model (E11)")
            if isinstance(coordinate, bool) or not isinstance(coordinate, int) \
                    or not 0 <= coordinate < p.n:
                raise ParameterError(f"sensor_coordinate={coordinate!r} is invalid: valid "
                                     f"range is 0 <= sensor_coordinate < n = {p.n}")
        self.coordinate = coordinate
        self.flow = NdofFlow.of(p) if isinstance(p, NdofModel) else None
        if estimator not in ESTIMATORS:
            raise ParameterError(f"estimator={estimator!r} is invalid: valid values are "
                                 f"{', '.join(ESTIMATORS)}")
        if impact_source not in IMPACT_SOURCES:
            raise ParameterError(f"impact_source={impact_source!r} is invalid: valid values "
                                 f"are {', '.join(IMPACT_SOURCES)}")
        sigma = float(sigma)
        if not (math.isfinite(sigma) and (sigma > 0.0 or estimator == "nearest"
                                          and sigma >= 0.0)):
            raise ParameterError(f"sensor_noise={sigma!r} is invalid: valid range is a finite "
                                 "sensor_noise > 0 (>= 0 for the nearest estimator)")
        sample_period = float(sample_period)
        if not (math.isfinite(sample_period) and 0.0 <= sample_period < p.period):
            raise ParameterError(f"state_period={sample_period!r} is invalid: valid range is "
                                 f"0 <= state_period < T = {p.period!r} (0: from the stamps)")
        self.p, self.estimator, self.sigma = p, estimator, sigma
        self.impact_source, self.sample_period, self.floor = impact_source, sample_period, floor
        self.after_section = bool(after_section)
        lead = float(lead)
        if not (math.isfinite(lead) and 0.0 <= lead < p.period):
            raise ParameterError(f"answer_lead={lead!r} is invalid: valid range is "
                                 f"0 <= answer_lead < T = {p.period!r}")
        self.lead = lead
        self.pulse = pulse_shape(p, pulse_width, force_limit)
        if actuator is not None and actuator.ideal:
            actuator = None
        if actuator is not None and self.pulse[0] == 0.0:
            raise ParameterError("pulse_width=0.0 is invalid with an actuator: valid range is "
                                 f"0 < pulse_width < T = {p.period!r} (the command's width)")
        self.actuator = actuator
        self.kernel = _kernel.use_kernel() if kernel is None else bool(kernel)
        #: Called with k when section k falls due, before its estimate is made (None:
        #: nothing): a controller whose answer does not depend on the estimate gives it
        #: at once (controller_node: the sections before the control is on, issue 30).
        self.before_estimate = None
        self.reset()

    def reset(self) -> None:
        """Forget everything (the simulator was reset)."""
        self.samples = _Samples()       # (t, x, v) of the last two periods
        self.next_k = None              # the next section to estimate
        self.kicks = {}                 # section k -> (time of the kick, dv)
        self.final = set()              # sections whose kick the plant reported (acted)
        self.force_at = (None, 0.0)     # (section, actuator force there) before self.kicks
        self.delay = 0.0
        self.impacts = deque(maxlen=64)  # impact times (topic or detected)
        self.filter = None              # FilterState at section filter_k
        self.filter_k = None
        self.resets = 0                 # model fits that fell back to the arc fit
        self.unseen_impacts = 0         # arc estimates carried through an impact after
        #                                 their last sample (an answer lead past it, (E2''))
        self.last_t = None
        self.ignored = 0                # samples not used: duplicates, older, strays
        self._jump = None               # a sample far ahead, kept until confirmed

    # ----------------------------------------------------------------- input
    def add_impact(self, t: float) -> None:
        """An impact at time t from the rig's impact sensor (``impact_source`` topic)."""
        if self.impact_source == "topic":
            self.impacts.append(float(t))

    def set_correction(self, k: int, dv: float, delay: float = 0.0) -> None:
        """The correction answered to section k, applied ``delay`` after t_k (unless the
        plant already said what acted there: :meth:`acted`)."""
        if k in self.final:
            return
        self.kicks[k] = (k * self.p.period + delay, float(dv))
        self.delay = delay
        for old in sorted(j for j in self.kicks if j < k - 3):
            if self.actuator is not None:   # its force is carried on (section_force)
                self.force_at = (old + 1, self.section_force(old + 1))
            del self.kicks[old]
        self.final = {j for j in self.final if j >= k - 3}

    def acted(self, k: int, dv: float, delay: float = 0.0) -> None:
        """What acted at section k according to the plant (a deadline miss: 0, or the
        prediction substituted for a late answer): it replaces the answered correction,
        also one answered after this call."""
        self.final.discard(k)
        self.set_correction(k, dv, delay)
        self.final.add(k)

    def add_sample(self, t: float, x: float, v: float = math.nan) -> list:
        """A sample (x~, v~; v NaN if not measured) at time t; returns the sections
        [(k, t_k, Estimate)] now due (normally none or one)."""
        T = self.p.period
        tol = _TOL * T
        if not math.isfinite(t):
            self.ignored += 1
            return []
        if self.last_t is not None and t < self.last_t - T:
            ignored, resets = self.ignored, self.resets
            self.reset()                # back to the start: the simulator was reset
            self.ignored, self.resets = ignored, resets
        elif self.last_t is not None and t <= self.last_t:
            self.ignored += 1           # a duplicate or an older sample: not used
            return []
        elif self.last_t is not None and t > self.last_t + MAX_GAP * T:
            jump, self._jump = self._jump, (t, x, v)
            if jump is None or not 0.0 < t - jump[0] <= 2.0 * T:
                self.ignored += 1       # a stray far ahead, unless the next one follows
                return []
            ignored, resets = self.ignored, self.resets
            self.reset()                # the stream jumped ahead: start again there
            self.ignored, self.resets = ignored - 1, resets
            return self.add_sample(*jump) + self.add_sample(t, x, v)
        self._jump = None
        due = []
        if self.next_k is None:
            self.next_k = max(0, math.ceil((t - tol) / T))
        while t > self.next_k * T + tol:
            due.append(self._due(self.next_k))     # late: a sample was lost
        h = self.sample_period
        if h == 0.0 and self.samples:
            h = t - self.samples.t[-1]
        self.samples.append(float(t), float(x), float(v))
        self.samples.drop_before(t - 2.0 * T - tol)
        self.last_t = t if self.last_t is None else max(self.last_t, t)
        if self.after_section:
            # realtime: due with the section's last sample, the one at t_k included (the
            # next would be after t_k; half a sample period of margin for the stamps'
            # rounding). Waiting for the first sample after t_k, which the estimate does
            # not use, cost a simulator's wake-up, 0.5 ms at T/200 x1000 (issue 30)
            if h > 0.0 and t + 0.5 * h + self.lead > self.next_k * T + tol:
                due.append(self._due(self.next_k))
        # due when the next sample would be at t_k or after it: a sample at t_k itself
        # (up to rounding, 1e-3 h) is not waited for (a simulator publishes the samples
        # before t_k, then waits for the answer)
        elif h <= 0.0 or t + h + self.lead >= self.next_k * T - 1e-3 * h:
            due.append(self._due(self.next_k))
        return due

    def plain_run(self, t) -> int:
        """How many of the samples ``t`` (times, in order) :meth:`add_sample` would only
        keep, one after the other: each finite, after the one before it (the newest kept
        first) within MAX_GAP periods, making no section due. 0 before the first sample
        since :meth:`reset`. The same conditions as :meth:`add_sample`'s, term for term."""
        if self.last_t is None or self.next_k is None or not self.samples:
            return 0
        T = self.p.period
        tol = _TOL * T
        edge = self.next_k * T + tol
        lead, after, h0 = self.lead, self.after_section, self.sample_period
        before = self.last_t
        n = 0
        for ti in t:
            if not (before < ti <= before + MAX_GAP * T) or ti > edge:
                break
            h = h0 if h0 != 0.0 else ti - before
            if after:
                if h > 0.0 and ti + 0.5 * h + lead > edge:
                    break
            elif h <= 0.0 or ti + h + lead >= self.next_k * T - 1e-3 * h:
                break
            before = ti
            n += 1
        return n

    def add_plain(self, t, x, v) -> None:
        """Keep a run of samples that :meth:`plain_run` counted (all of ``t``), as
        :meth:`add_sample` on each would keep them, in one step: a sensor's block
        (ros/stream_block.py) holds 10 of them between two sections at T/200 x1000."""
        if not t:
            return
        T = self.p.period
        self._jump = None
        self.samples.extend(t, x, v)
        self.samples.drop_before(t[-1] - 2.0 * T - _TOL * T)
        self.last_t = t[-1]

    def add_samples(self, t, x, v) -> list:
        """Samples in order (lists): the sections now due, as :meth:`add_sample` on each
        (the leading :meth:`plain_run` kept in one step)."""
        n = self.plain_run(t)
        self.add_plain(t[:n], x[:n], v[:n])
        due = []
        for i in range(n, len(t)):
            due += self.add_sample(t[i], x[i], v[i])
        return due

    def flush(self, k: int) -> list:
        """The sections up to k not yet estimated (the stream stopped short of t_k)."""
        due = []
        if self.next_k is None:
            self.next_k = k
        while self.next_k <= k:
            due.append(self._due(self.next_k))
        return due

    # ----------------------------------------------------------------- estimates
    def _due(self, k: int):
        self.next_k = k + 1
        if self.before_estimate is not None:
            self.before_estimate(k)
        return k, k * self.p.period, self.estimate(k)

    def _window(self, k: int, since: float):
        """Samples with since < t <= t_k + tol as arrays (s relative to t_k)."""
        tk = k * self.p.period
        t, x, v = self.samples.between(since, tk + _TOL * self.p.period)
        return t - tk, x, v

    def estimate(self, k: int) -> Estimate:
        """The estimate of section k from the samples received (model, else arc, else
        nearest, else the last position with an unknown velocity)."""
        p, T = self.p, self.p.period
        if isinstance(p, NdofModel):
            return self._ndof_model(k)
        tk = k * T
        if self.estimator == "model":
            est = self._model(k)
            if est is not None:
                return est
        if self.estimator in ("model", "arc"):
            est = self._arc(k)
            if est is not None:
                if self.estimator == "model":
                    self.filter, self.filter_k = FilterState(est.z, est.cov, 0), k
                return est
        s, x, v = self._window(k, tk - 2.0 * T)
        if s.size == 0:
            return Estimate((math.nan, math.nan), np.full((2, 2), math.inf), "none")
        y, w = deviation_samples(p, s, x, v, tau_start=p.tau2)
        last = self.impacts[-1] - tk if self.impacts else -math.inf
        keep = s > last if (s > last).sum() >= 2 else np.ones(s.size, bool)
        return nearest_estimate(s[keep], y[keep], w[keep], self.sigma)

    def section_force(self, k: int) -> float:
        """The actuator's force at section k, left by the known corrections of the
        periods before: :func:`grazing_control.dynamics.estimation.motion.section_force` period
        by period from the force carried at the oldest section kept (``force_at``, moved
        on as old corrections are dropped; 0 at the first correction since
        :meth:`reset`), a period without a known correction with none; 0 without an
        actuator."""
        if self.actuator is None:
            return 0.0
        T = self.p.period
        base, f = self.force_at
        if base is None or base > k:
            base, f = min(self.kicks, default=k), 0.0
        for j in range(base, k):
            at, dv = self.kicks.get(j, (j * T + self.delay, 0.0))
            f = section_force(self.p, f, dv, at - j * T, self.pulse[0], self.pulse[1],
                              self.actuator)
        return f

    def correction_shape(self, k: int) -> dict:
        """How the correction of period k acts, as keywords of
        :func:`grazing_control.dynamics.estimation.motion.trajectory`: the pulse, the actuator
        and its force at section k."""
        shape = dict(width=self.pulse[0], force_limit=self.pulse[1])
        if self.actuator is not None:
            shape.update(actuator=self.actuator, force0=self.section_force(k))
        return shape

    def _kicks(self, k: int):
        """The known corrections before t_k as (time relative to t_k, dv)."""
        tk = k * self.p.period
        return [(at - tk, dv) for j, (at, dv) in self.kicks.items() if j < k]

    def _arc(self, k: int):
        """The arc fit over the samples since the last impact (topic or detected),
        carried to t_k through an impact after its last sample (:meth:`_carried`).

        The split test looks for that impact over the last period of samples: with an
        answer lead, the one that ended ``lead`` before t_k, so that an impact that fell
        after the last sample of section k - 1's arc is found among section k's samples.
        """
        p, T = self.p, self.p.period
        tk = k * T
        s, x, v = self._window(k, tk - 2.0 * T)
        if s.size < 2:
            return None
        y, w = deviation_samples(p, s, x, v, tau_start=p.tau2)
        kicks = self._kicks(k)
        if self.impact_source == "stream":
            ya, _wa = unkick(p, s, y, w, kicks)
            recent = s > -T - self.lead - _TOL * T
            hit = detect_impact(p, s[recent] + T, ya[recent], self.sigma)
            if hit is not None:
                t_hit = hit - T + tk
                if not self.impacts or abs(self.impacts[-1] - t_hit) > 0.25 * T:
                    self.impacts.append(t_hit)
        last = max((i for i in self.impacts if i <= tk), default=-math.inf) - tk
        keep = s > last
        measured = keep.sum() + np.isfinite(w[keep]).sum()
        if measured < 2:
            return None
        return (self._carried(s[keep], y[keep], w[keep], kicks)
                or arc_fit(p, s[keep], y[keep], w[keep], self.sigma, 0.0, kicks))

    def _carried(self, s, y, w, kicks):
        """The arc's state at its last sample s_m carried to t_k by the exact flow
        (:func:`~grazing_control.dynamics.estimation.motion.carry`), where the mass
        reaches the wall in between: the arc's free flow to t_k would pass through the
        wall (docs/theory_estimation.md, (E2'')). The kicks after s_m act in the carry,
        not in the fit. None where no impact falls between s_m and t_k (the arc fit at
        t_k itself is the estimate) or the arc cannot be fitted at s_m, and without an
        answer lead: its unsampled stretch is under one sample period, and the carry's
        second fit and flow would cost every arc estimate ~0.1 ms (the section after a
        start or a reset, on the answer's path)."""
        end = float(s[-1])
        if not (self.lead > 0.0 and end < -_TOL * self.p.period):
            return None
        before = [(at, dv) for at, dv in kicks if at <= end]
        after = [(at, dv) for at, dv in kicks if at > end]
        try:
            at_end = arc_fit(self.p, s, y, w, self.sigma, end, before)
            z, m, impacts = carry(self.p, at_end.z, end, -end, after, kernel=self.kernel)
        except (ValueError, np.linalg.LinAlgError, ArithmeticError):
            return None
        if not impacts:
            return None
        self.unseen_impacts += 1
        cov = m @ at_end.cov @ m.T
        return Estimate((float(z[0]), float(z[1])), 0.5 * (cov + cov.T), "arc")

    def _model(self, k: int):
        """One period of the model filter from section k - 1 (None: start or reset)."""
        p, T = self.p, self.p.period
        if self.filter is None or self.filter_k != k - 1:
            return None
        s, x, v = self._window(k, (k - 1) * T + _TOL * T)
        if s.size == 0:
            return None
        s = s + T
        y, w = deviation_samples(p, s, x, v, tau_start=p.tau2)
        at, dv = self.kicks.get(k - 1, ((k - 1) * T, 0.0))
        try:
            new, chi2, n = model_update(p, self.filter, s, y, w, self.sigma, dv,
                                        at - (k - 1) * T, floor=self.floor,
                                        kernel=self.kernel, **self.correction_shape(k - 1))
        except (ValueError, np.linalg.LinAlgError, ArithmeticError):
            self.filter = None
            self.resets += 1
            return None
        if chi2 > n + CHI2_SIGMAS * math.sqrt(2.0 * n):
            self.filter = None
            self.resets += 1
            return None
        self.filter, self.filter_k = new, k
        return Estimate(new.z, new.cov, "model")

    def _ndof_model(self, k: int) -> Estimate:
        """Section k of the model filter over the n-DOF map (module docstring): the fit of
        the period's samples from the filter's state at k - 1, else from the
        uninformative prior; where neither fits, the filter's state carried one period
        through the model (with the known kick) with the uninformative covariance, or
        the prior itself at the start."""
        p, T = self.p, self.p.period
        wide = NDOF_PRIOR ** 2 * np.eye(2 * p.n)
        start = FilterState(tuple(0.0 for _ in range(2 * p.n)), wide, 0)
        held = self.filter if self.filter is not None and self.filter_k == k - 1 else None
        s, x, v = self._window(k, (k - 1) * T + _TOL * T)
        at, dv = self.kicks.get(k - 1, ((k - 1) * T, 0.0))
        if k > 0 and s.size:
            s = s + T
            # the deviations of the measured coordinate from X_p(tau2 + omega s)
            e = self.flow.amplitudes[self.coordinate] * np.exp(
                1j * (self.flow.tau2 + p.omega * s))
            y, w = x - e.real, v - (1j * p.omega * e).real
            for prior in (held, FilterState(start.z if held is None else held.z, wide, 0)):
                if prior is None:
                    continue
                try:
                    new, chi2, n = self._ndof_fit(k, prior, s, y, w, dv, at - (k - 1) * T)
                except (ValueError, np.linalg.LinAlgError, ArithmeticError):
                    continue
                if chi2 <= n + CHI2_SIGMAS * math.sqrt(2.0 * n):
                    self.filter, self.filter_k = new, k
                    return Estimate(new.z, new.cov, "model")
            self.resets += 1
        z, source = start.z, "prior"
        if held is not None:
            try:
                z = tuple(float(a) for a in predict_section(
                    p, held.z, dv, at - (k - 1) * T, width=self.pulse[0],
                    force_limit=self.pulse[1]))
                source = "predicted"
            except (ValueError, ArithmeticError):
                pass
        self.filter, self.filter_k = FilterState(z, wide, 0), k
        return Estimate(z, wide, source)

    def _ndof_fit(self, k: int, prior: FilterState, s, y, w, dv: float, delay: float):
        """One period of the n-DOF model filter from ``prior`` (at section k - 1) to
        section k on the period's deviations ``y``, ``w`` at ``s``: (FilterState, chi2,
        measurements); raises where the fit fails. The augmented filter's own
        (dynamics/estimation/augmented.py) carries a bias and Delta d besides."""
        return model_update(self.p, prior, s, y, w, self.sigma, dv, delay, floor=self.floor,
                            coordinate=self.coordinate, kernel=self.kernel,
                            **self.correction_shape(k - 1))


class _Samples:
    """The samples kept, (t, x, v) in increasing t, as three lists from index ``first``:
    a window is two bisections and three slices (issue 30: filtering a deque of tuples
    and making an array of the rows took 50 of the ~370 µs of a section's estimate)."""

    __slots__ = ("t", "x", "v", "first")

    def __init__(self):
        self.t, self.x, self.v, self.first = [], [], [], 0

    def __bool__(self) -> bool:
        return len(self.t) > self.first

    def append(self, t: float, x: float, v: float) -> None:
        """A sample after the last one (StreamEstimator.add_sample keeps t increasing)."""
        self.t.append(t)
        self.x.append(x)
        self.v.append(v)

    def extend(self, t, x, v) -> None:
        """Samples after the last one, in increasing t (floats)."""
        self.t.extend(t)
        self.x.extend(x)
        self.v.extend(v)

    def drop_before(self, start: float) -> None:
        """Forget the samples before ``start`` (the lists are cut once half is dropped)."""
        t, i = self.t, self.first
        while i < len(t) and t[i] < start:
            i += 1
        if i > 256 and 2 * i > len(t):
            del self.t[:i], self.x[:i], self.v[:i]
            i = 0
        self.first = i

    def between(self, since: float, until: float):
        """The samples with since < t <= until, as three arrays."""
        lo = bisect_right(self.t, since, self.first)
        hi = bisect_right(self.t, until, lo)
        return (np.array(self.t[lo:hi], dtype=float), np.array(self.x[lo:hi], dtype=float),
                np.array(self.v[lo:hi], dtype=float))


@dataclass
class StreamRun:
    """A closed-loop run on the stream, one row per section k: the true deviation
    ``truth`` (before the correction), the ``estimate`` and its ``cov`` (k, 2, 2), the
    ``corrections``, the ``impacts_per_period`` and the estimator's ``resets``."""

    truth: np.ndarray
    estimate: np.ndarray
    cov: np.ndarray
    corrections: np.ndarray
    impacts_per_period: np.ndarray
    resets: int


def simulate_stream(p: OscillatorParams, gains: Gains, measure, periods: int, rate: int, *,
                    estimator: str = "model", sigma: float = 1e-4,
                    impact_source: str = "stream", deviation=(0.0, 0.0),
                    control_after: int = 0, floor: float = 1e-2,
                    model: OscillatorParams | None = None, stream_estimator=None,
                    plant_at=None, switch=None, observe=None, pulse_width: float = 0.0,
                    force_limit: float = math.inf, actuator=None) -> StreamRun:
    """The closed loop on a sensor stream: exact plant (:func:`trajectory`), samples at
    t_j = j T / ``rate`` measured by ``measure(j0, x, v) -> (x~, v~)`` (a
    :class:`grazing_control.plant.sensor.SensorModel`'s ``measure``), the estimator of
    :class:`StreamEstimator`, and Eq. 28 on the estimate from section ``control_after``
    on, applied ``gains.delay`` after the section. ``model``: the estimator's model of
    the plant when it is not ``p`` (a model error); default ``p``.

    Hooks for the watchful loop (issue 29; none changes the run when left out):
    ``stream_estimator`` an estimator object to use instead of building one (e.g.
    :class:`grazing_control.dynamics.estimation.augmented.AugmentedStreamEstimator`);
    ``plant_at(k)`` the plant's parameters in period k (a drifting wall; same period
    and forcing as ``p``); ``switch(k, estimate) -> factor`` the share of Eq. 28's
    correction applied at section k (a capture rule or a gain ramp,
    :mod:`grazing_control.dynamics.design.capture`); ``observe(k, estimator)`` called after
    each section's estimate (to feed a consistency monitor).

    ``pulse_width`` > 0: the plant's corrections are force pulses of that width centred
    at ``gains.delay`` (force clipped to ``force_limit``), and the estimator built here
    models them (pass ``stream_estimator`` built without them to see what a kick model
    of a pulse plant costs). ``actuator``: the pulse is the command of the plant's
    first-order actuator (the force carried from period to period), modelled likewise.
    """
    if int(rate) != rate or rate < 2:
        raise ParameterError(f"rate={rate!r} is invalid: valid range is an integer >= 2 "
                             "samples per period")
    T = p.period
    h = T / rate
    est = stream_estimator if stream_estimator is not None else StreamEstimator(
        p if model is None else model, estimator, sigma, impact_source, h, floor,
        pulse_width=pulse_width, force_limit=force_limit, actuator=actuator)
    z = (float(deviation[0]), float(deviation[1]))
    force = 0.0                 # the actuator's force at the section
    truth = np.empty((periods, 2))
    zhat = np.empty((periods, 2))
    cov = np.empty((periods, 2, 2))
    corr = np.zeros(periods)
    counts = np.zeros(periods, dtype=int)
    xm, vm = measure(0, np.array([p.x_ref + z[0]]), np.array([p.v_ref + z[1]]))
    pending = est.add_sample(0.0, float(xm[0]), float(vm[0]))
    for k in range(periods):
        truth[k] = z
        pending += est.flush(k)
        (_, _, e), = [d for d in pending if d[0] == k]
        zhat[k], cov[k] = e.z, e.cov
        if observe is not None:
            observe(k, est)
        dv = 0.0
        if k >= control_after and np.all(np.isfinite(e.z)):
            dv = gains.c1 * e.z[0] + gains.c2 * e.z[1]
            if switch is not None:
                dv *= switch(k, e)
        corr[k] = dv
        est.set_correction(k, dv, gains.delay)
        j0 = math.floor((k * T + _TOL * T) / h) + 1
        j1 = math.floor(((k + 1) * T + _TOL * T) / h)
        js = np.arange(j0, j1 + 1)
        s = js * h - k * T
        plant = p if plant_at is None else plant_at(k)
        lag = {} if actuator is None else dict(actuator=actuator, force0=force)
        dev, _jac, z, _m, imps = trajectory(plant, z, s, dv, gains.delay, width=pulse_width,
                                            force_limit=force_limit, **lag)
        if lag:
            force = section_force(plant, force, dv, gains.delay, pulse_width, force_limit,
                                  actuator)
        counts[k] = len(imps)
        psi = p.tau2 + p.omega * s - p.lag
        x = p.amplitude * np.cos(psi) + dev[:, 0]
        v = -p.amplitude * p.omega * np.sin(psi) + dev[:, 1]
        xm, vm = measure(int(j0), x, v)
        pending = []
        # the period's samples in order, each impact before the first sample at or after
        # it; each run between two impacts as a sensor's block (add_samples: the samples
        # that only append kept in one step, bit for bit add_sample on each)
        t, xm, vm = (js * h).tolist(), xm.tolist(), vm.tolist()
        start = 0
        for ti in sorted(k * T + i[0] for i in imps):
            end = bisect_left(t, ti, start)
            pending += est.add_samples(t[start:end], xm[start:end], vm[start:end])
            est.add_impact(ti)
            start = end
        pending += est.add_samples(t[start:], xm[start:], vm[start:])
    return StreamRun(truth, zhat, cov, corr, counts, est.resets)


def predict_section(p: OscillatorParams, z, correction: float, delay: float = 0.0, *,
                    width: float = 0.0, force_limit: float = math.inf, actuator=None,
                    force0: float = 0.0, kernel: bool = False):
    """The next section's state (deviation, before its correction) predicted from the
    estimate ``z`` with ``correction`` applied ``delay`` after the section (a kick, or
    a force pulse of ``width``, through ``actuator`` from the force ``force0`` at the
    section): one exact period of the model (issue 16 section 3; :func:`trajectory`,
    compiled with ``kernel``: a stream estimator's ``kernel``); the end alone where
    no actuator's lag is in it (:func:`trajectory_end`, the same numbers)."""
    if not isinstance(p, NdofModel) and (actuator is None or (actuator.ideal
                                                               and force0 == 0.0)):
        return trajectory_end(p, z, correction, delay, width=width, force_limit=force_limit,
                              kernel=kernel)
    *_rest, end, _m, _imps = trajectory(p, z, np.empty(0), correction, delay, width=width,
                                        force_limit=force_limit, actuator=actuator,
                                        force0=force0, kernel=kernel)
    return end


def warm_up(p: OscillatorParams | None = None) -> None:
    """Load the compiled model filter where the kernel is in use (the kernel and
    :mod:`grazing_control.dynamics.estimation.compiled_flow`: compiled on a machine's first
    call, then loaded from numba's cache, ~1 s) so that the first section does not wait
    for it: controller_node calls it at start in stream mode. With an n-DOF model ``p``
    also :mod:`grazing_control.dynamics.estimation.compiled_modal_flow` (its model filter's
    evaluation at the samples) and the compiled n-DOF event search
    (:func:`grazing_control.oscillator.kernel.warm_up_modal`); a 1-DOF controller never
    loads them."""
    if _kernel.use_kernel():
        _kernel.warm_up()
        trajectory(OscillatorParams(delta_d=-1e-3), (0.0, 0.0), np.array([1.0]), 0.1, 1.0,
                   width=0.1, kernel=True)
        if isinstance(p, NdofModel):
            from .compiled_modal_flow import modal_flow_at_samples

            _kernel.warm_up_modal()       # the n-DOF event search (issue 32)

            flow = NdofFlow.of(p)
            e = np.exp(np.multiply.outer(np.zeros(1), flow.eigenvalues))
            rows = np.zeros((1, 2 * p.n))
            modal_flow_at_samples(flow.modes, e, flow.inverse, np.zeros(1, np.int64), rows,
                                  np.zeros((1, 2 * p.n, 2 * p.n)), rows, True)



def warm_up_all() -> None:
    """:func:`warm_up` of every compiled filter, the n-DOF ones through a model of two
    masses (any two masses load the same code): what a process that will run nodes of
    either kind loads once (the test suite's conftest, ros/node_zygote.py)."""
    from grazing_control.oscillator.ndof.model import model_from_mapping

    warm_up(model_from_mapping({
        "M": [[1.0, 0.0], [0.0, 1.0]], "C": [[0.04, -0.02], [-0.02, 0.04]],
        "K": [[1.0, -1.0], [-1.0, 2.0]], "f": [0.0, 1.0], "omega": 0.5, "i_w": 0}))

def pulse_shape(p: OscillatorParams, pulse_width: float, force_limit: float) -> tuple:
    """(width, force limit) of the plant's corrections, validated: ParameterError naming
    ``pulse_width`` (0 <= w < T) or ``force_limit`` (> 0, inf: none; 0 is read as none,
    as sim_node's force_limit)."""
    w, f = float(pulse_width), float(force_limit)
    if not (math.isfinite(w) and 0.0 <= w < p.period):
        raise ParameterError(f"pulse_width={pulse_width!r} is invalid: valid range is "
                             f"0 <= pulse_width < T = {p.period!r} (0: a velocity kick)")
    if f == 0.0:
        f = math.inf
    if not f > 0.0:
        raise ParameterError(f"force_limit={force_limit!r} is invalid: valid range is "
                             "force_limit > 0 (0 or inf: no limit)")
    return w, f

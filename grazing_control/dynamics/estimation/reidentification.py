"""Re-identification in the loop (issue 29 section 3): the model refitted from the stream the
controller received, and the switch to it, without ROS (docs/theory_reidentification.md).

A controller whose consistency test names a wrong model (:mod:`.consistency`), or that is
asked to, fits the model again on its last N periods of stream and switches its
estimator and gains to the new model when the design is admissible there. Three pure
steps, each with its named failure (:class:`ReidentificationError`, ``reason``):

1. :class:`StreamRecord` keeps the last N periods as received (samples, the phase
   reference, each section's estimate and the kick that acted, the impacts known);
   :class:`StreamWindow` is its snapshot from the model filter's last restart, as a
   :class:`grazing_control.dynamics.identification.Recording` with the impacts sensed or
   predicted (``too_few_periods``: less than :data:`MIN_PERIODS` periods).
2. :func:`refit`: :func:`grazing_control.dynamics.identification.identify` (the core of
   ``grazing identify``) started from the running model's zeta with its units held
   (:data:`UNITS`), and the controller's model from it (:func:`model_from_fit`): zeta
   and r as fitted, the wall where the fit put it in the stream's units, the time base
   (omega, the section phase offset) kept (``no_impacts``; ``fit_failed``: no
   convergence, a residual beyond :data:`RESIDUAL_RATIO` sigma; ``not_identified``: a
   singular fit, zeta or r beyond :data:`RELATIVE_SE`, outside the model's ranges).
3. :func:`redesign`: the degenerate design c1(c2; delta) of the new model for the
   running c2 and delay (Eq. 38, docs/theory_delay.md (D5)), with the design's
   conditions re-checked there (:func:`grazing_control.dynamics.design.gains.condition_values`;
   ``no_admissible_design``).

:func:`plan_switch` runs 2-3 (what a worker thread runs); :func:`switch_estimator` moves
a stream estimator's filter to the new model at a Pi2 section (the state carried over in
absolute coordinates, the covariance kept). A request while a fit runs is refused
(``busy``) by the caller that owns the worker (:class:`Reidentifier`).

One implementation for every model (issue 32), dispatching on the running model: the
1-DOF oscillator (:class:`OscillatorParams`, all of the above, unchanged bit for bit) or
a model file of n masses (:class:`~grazing_control.oscillator.ndof.model.NdofModel`,
docs/theory_reidentification.md "n > 1"): the window's impacts predicted over the exact
n-DOF motion from each section's 2n-state estimate, or, where the filter restarted too
recently for a window, the whole record's found in the samples of x_w
(:mod:`.sampled_impacts`); step 2 the multiple-shooting fit of
the wall coordinate's modal parameters
(:func:`grazing_control.dynamics.identification.modal_fit.identify_modal`, the core of
``grazing identify`` on an n-DOF bag) started from the running model's modes, realised
as a model file (:func:`grazing_control.dynamics.identification.modal.realise`, its
misfit within :data:`REALISATION_LIMIT` standard errors) with the running time base;
step 3 the family member k(mu) of the new model at the running gains' mu
(docs/theory_ndof.md §3, (N9) with the delay, §15 with the pulse) with the conditions of
``grazing design --model`` (:func:`grazing_control.dynamics.design.family.evaluate_design`)
re-checked: :class:`VectorGains`.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
import dataclasses
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.estimation.section_state import FilterState
from grazing_control.dynamics.estimation.motion import trajectory
from grazing_control.dynamics.estimation.sampled_impacts import impacts_from_samples
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import NdofModel

# The solvers (scipy.optimize, through the identification's fit and the design's orbits)
# are imported where they are used, in the worker: a node that never refits does not load
# them at start (tests/test_node_common.py). So the design's condition sets are named here
# too (tests/test_reidentification.py checks them against dynamics.design.gains.CONDITIONS).
#: The design's condition sets (dynamics.design.gains.CONDITIONS).
CONDITIONS = ("combined", "impacting", "non-impacting")

__all__ = ["REASONS", "MIN_PERIODS", "REFIT_PERIODS", "ReidentificationError", "StreamRecord",
           "StreamWindow", "Refit", "SwitchPlan", "VectorGains", "model_from_fit", "refit",
           "redesign", "plan_switch", "switch_estimator", "Reidentifier"]

#: The named failures (ReidentificationError.reason); the loop keeps its state on each.
REASONS = ("too_few_periods", "no_impacts", "fit_failed", "not_identified",
           "no_admissible_design", "busy")
#: Fewest periods of stream a refit accepts (each has two arcs, an impact and a kick:
#: ten periods give the fit's 6 parameters about 2000 samples at T/200).
MIN_PERIODS = 10
#: The default window of the refit, in periods.
REFIT_PERIODS = 20
#: The running model's units, held by the refit: its time (1 / natural frequency) and
#: length (forcing amplitude / natural frequency^2) scales. Free, they trade off against
#: zeta and the wall (measured on 20 periods at T/200, sigma 1e-4: zeta 0.01051 +- 3.7e-4
#: and the wall 1.1e-5 off with them free; docs/theory_reidentification.md).
UNITS = {"natural_frequency": 1.0, "forcing_amplitude": 1.0}
#: The largest relative standard error of zeta and r a refit may switch to: beyond it the
#: window does not determine the parameter (a refit of a stream with an unmodelled sensor
#: bias of 1e-4 gave r = 0.95 +- 0.22 and the wall on the wrong side).
RELATIVE_SE = 0.1
#: The largest ratio of the fit's residual noise to the sensor's a refit may switch to:
#: beyond it the fitted model does not explain the window (a fit that ended in another
#: minimum, seed 11 of the benchmark: zeta 0.018 +- 2e-4, residual 1.8e-3 against the
#: sensor's 1e-4).
RESIDUAL_RATIO = 1.5
#: The solver's budget per continuation step (identify's default: 100 did not converge
#: on 20 controlled periods through the nodes).
MAX_NFEV = 400
#: The refit's wall-clock budget (s): beyond it the fit stops and the plan is refused as
#: ``not_identified`` (a window of controlled periods only, control on from section 0,
#: hardly determines zeta: its refit had not ended 124 s later and the loop waited on it,
#: ``busy``, for the rest of the scene).
REFIT_SECONDS = 60.0
#: The largest misfit, in standard errors, of the realised n-DOF model's modal parameters
#: (``grazing identify --out-model``'s limit, cli/identify.py REALISATION_LIMIT): beyond it
#: no symmetric M, C, K near the running model shows the fitted modes (``not_identified``).
REALISATION_LIMIT = 3.0


class ReidentificationError(ValueError):
    """A refit or a switch refused; ``reason`` one of :data:`REASONS`, the message says
    why in one line."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


class StreamRecord:
    """The last ``periods`` periods of the stream as the controller received it.

    ``add_sample(t, x, v, cos_tau, sin_tau)`` (v NaN: position only; a phase reference
    of the forcing frequency: the stream's, or omega t), ``add_section(k, state, dv,
    at)`` (the controller's estimate of section k as an absolute state (x^, v^), for n
    masses the 2n values X^ = (x^, v^), the kick answered and its instant),
    ``acted(k, dv, at)`` (what the plant says acted there instead), ``add_impact(t)`` (an
    impact sensor's); :meth:`snapshot` the window, taken in the caller's thread.
    """

    def __init__(self, period: float, periods: int = REFIT_PERIODS):
        if isinstance(periods, bool) or int(periods) != periods or periods < MIN_PERIODS:
            raise ParameterError(f"reidentify_periods={periods!r} is invalid: valid range is "
                                 f"an integer >= {MIN_PERIODS} periods")
        self.period, self.periods = float(period), int(periods)
        self.samples = deque()
        self.sections = {}              # k -> (state, dv, instant of the kick, fitted)
        self.impacts = deque()

    def clear(self) -> None:
        """Forget the stream (a simulator reset)."""
        self.samples.clear()
        self.sections.clear()
        self.impacts.clear()

    def add_sample(self, t: float, x: float, v: float, cos_tau: float,
                   sin_tau: float = math.nan) -> None:
        if self.samples and t <= self.samples[-1][0]:
            if t < self.samples[-1][0] - self.period:
                self.clear()            # back to the start: the simulator was reset
            else:
                return                  # a duplicate or an older sample
        self.samples.append((float(t), float(x), float(v), float(cos_tau), float(sin_tau)))
        start = t - self.periods * self.period
        while self.samples[0][0] < start:
            self.samples.popleft()
        while self.impacts and self.impacts[0] < start:
            self.impacts.popleft()

    def add_samples(self, rows) -> None:
        """Rows (t, x, v, cos_tau, sin_tau) in increasing t: as :meth:`add_sample` on
        each, in one step where they all follow the last sample kept."""
        if not rows:
            return
        if self.samples and rows[0][0] <= self.samples[-1][0]:
            for row in rows:
                self.add_sample(*row)
            return
        self.samples.extend(rows)
        start = rows[-1][0] - self.periods * self.period
        while self.samples[0][0] < start:
            self.samples.popleft()
        while self.impacts and self.impacts[0] < start:
            self.impacts.popleft()

    def add_section(self, k: int, z, dv: float, at: float, fitted: bool = True) -> None:
        """Section k's estimate (absolute), its kick and instant; ``fitted``: the model
        filter made the estimate (not an arc fit after a start or a reset)."""
        self.sections[int(k)] = (tuple(float(a) for a in z), float(dv), float(at),
                                 bool(fitted))
        for old in [j for j in self.sections if j < k - self.periods - 2]:
            del self.sections[old]

    def acted(self, k: int, dv: float, at: float) -> None:
        if k in self.sections:
            state, _dv, _at, fitted = self.sections[k]
            self.sections[k] = (state, float(dv), float(at), fitted)

    def add_impact(self, t: float) -> None:
        if not self.impacts or t > self.impacts[-1]:
            self.impacts.append(float(t))

    @property
    def covered(self) -> float:
        """The periods of stream held (from the first sample to the last)."""
        if len(self.samples) < 2:
            return 0.0
        return (self.samples[-1][0] - self.samples[0][0]) / self.period

    def _usable_start(self) -> float:
        """Where the window may start: without an impact sensor, after the last section
        that the model filter did not estimate (its prediction of the impacts is not
        trusted: two missed impacts after the start made a refit's residual 18 sigma,
        docs/theory_reidentification.md), else the first sample."""
        first = self.samples[0][0] if self.samples else 0.0
        if self.impacts or not self.sections:
            return first
        unfitted = [k for k, sec in self.sections.items() if not sec[3]]
        return max(first, (max(unfitted) + 1) * self.period - 1e-9 * self.period) \
            if unfitted else first

    def snapshot(self, find_impacts: bool = False) -> "StreamWindow":
        """The window (copies), from :meth:`_usable_start`. ReidentificationError
        ``too_few_periods`` when it covers less than :data:`MIN_PERIODS` periods.
        ``find_impacts`` (an n-DOF model's, :meth:`Reidentifier.request`): where that
        leaves less, the whole record with the impacts found in its samples instead
        (:mod:`.sampled_impacts`; docs/theory_reidentification.md §6)."""
        start = self._usable_start()
        covered = (self.samples[-1][0] - start) / self.period if self.samples else 0.0
        sampled = False
        if find_impacts and covered < MIN_PERIODS - 0.5 and self.samples:
            start, sampled = self.samples[0][0], True
            covered = self.covered
        if covered < MIN_PERIODS - 0.5:
            raise ReidentificationError(
                "too_few_periods", f"too few periods of stream to refit: {covered:.1f} "
                f"received since the model filter's last restart, need at least "
                f"{MIN_PERIODS}")
        rows = np.array([r for r in self.samples if r[0] >= start])
        return StreamWindow(rows, {k: v for k, v in self.sections.items()
                                   if k * self.period >= start - 1e-9 * self.period},
                            np.array(self.impacts), self.period, sampled)


@dataclass(frozen=True)
class StreamWindow:
    """A snapshot of a :class:`StreamRecord`: samples (n, 5) rows (t, x, v, cos tau,
    sin tau), sections {k: (z, dv, at)}, impact times, the period; ``sampled``: without
    an impact sensor, the impacts are found in the samples, not predicted."""

    samples: np.ndarray
    sections: dict
    impacts: np.ndarray
    period: float
    sampled: bool = False

    def kicks(self) -> np.ndarray:
        """The instants of the non-zero kicks inside the samples' span."""
        t0, t1 = self.samples[0, 0], self.samples[-1, 0]
        at = np.array(sorted(sec[2] for sec in self.sections.values() if sec[1] != 0.0))
        return at[(at > t0) & (at < t1)] if at.size else at

    def kick_sizes(self) -> np.ndarray:
        """The sizes of the kicks of :meth:`kicks`, in the same order (the n-DOF fit's
        ``correction_dv``: the actuated coordinate's response is fitted from them)."""
        t0, t1 = self.samples[0, 0], self.samples[-1, 0]
        rows = sorted((sec[2], sec[1]) for sec in self.sections.values() if sec[1] != 0.0)
        return np.array([dv for at, dv in rows if t0 < at < t1], dtype=float)

    def predicted_impacts(self, p: OscillatorParams, delay: float) -> np.ndarray:
        """The impact times of the running model from each section's estimate with its
        kick (one exact period each, :func:`grazing_control.dynamics.estimation.motion.trajectory`):
        the starts of the fit's impact times where no impact sensor gave them (the fit
        moves each between the samples around it, and to the next interval when it stops
        at a bound)."""
        if isinstance(p, NdofModel):
            return self._ndof_impacts(p, delay)
        out = []
        for k in sorted(self.sections):
            state, dv, at, _fitted = self.sections[k]
            z = (state[0] - p.x_ref, state[1] - p.v_ref)
            if not (math.isfinite(z[0]) and math.isfinite(z[1])):
                continue
            try:
                *_rest, imps = trajectory(p, z, np.empty(0), dv, at - k * self.period)
            except (ValueError, ArithmeticError, RuntimeError):
                continue
            out += [k * self.period + i[0] for i in imps]
        return np.array(sorted(out))

    def _ndof_impacts(self, p: NdofModel, delay) -> np.ndarray:
        """:meth:`predicted_impacts` over the exact n-DOF motion (motion.trajectory of a
        model file): z = X^ - X_p(tau2), the kick or the pulse of ``delay`` (a
        :class:`VectorGains`' ``actuation``: the delay, or the design's Actuation)."""
        flow = NdofFlow.of(p)
        ref = flow.particular(flow.tau2)
        width, lag = _pulse_of(delay)
        out = []
        for k in sorted(self.sections):
            state, dv, at, _fitted = self.sections[k]
            z = np.asarray(state, float) - ref
            if z.size != ref.size or not np.all(np.isfinite(z)):
                continue
            try:
                *_rest, imps = trajectory(p, z, np.empty(0), dv, at - k * self.period,
                                          width=width, actuator=lag)
            except (ValueError, ArithmeticError, RuntimeError):
                continue
            out += [k * self.period + i[0] for i in imps]
        return np.array(sorted(out))

    def recording(self, p: OscillatorParams, delay: float):
        """The window as a Recording: the impact sensor's times, else those found in
        the samples (``sampled``: :func:`.sampled_impacts.impacts_from_samples`), else
        the model's (:meth:`predicted_impacts`); the kicks' instants; no impact
        velocities."""
        from grazing_control.dynamics.identification.data import Recording

        a = self.samples
        t0, t1 = a[0, 0], a[-1, 0]
        if self.impacts.size:
            imp = self.impacts
        elif self.sampled:
            imp = impacts_from_samples(a[:, 0], a[:, 1], self.kicks())
            if not imp.size:
                raise ReidentificationError(
                    "no_impacts", "no impact found in the window's samples (free flight, "
                    "or impacts too slow for the noise: sampled_impacts)")
        else:
            imp = self.predicted_impacts(p, delay)
        imp = imp[(imp > t0) & (imp < t1)]
        keep = np.concatenate([[True], np.diff(imp) > 1e-9 * self.period]) if imp.size \
            else np.zeros(0, bool)
        imp = imp[keep]
        nan = np.full(imp.size, math.nan)
        return Recording(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], imp, nan, nan.copy(),
                         self.kicks())


@dataclass(frozen=True)
class Refit:
    """A refit: the controller's new ``model``, the standard errors of its zeta, r and
    Delta d (``stderr``), the fit's noise ``sigma``, its natural frequency and forcing
    amplitude in the stream's units (``units``: 1 where the running time base is right),
    the forcing phase at t = 0 against the new model's section phase (``phase_error``,
    rad), the periods, samples and impacts used, the fit's CPU seconds.

    For n masses: ``model`` the realised model file, ``stderr`` zeta and its error the
    lowest mode's damping ratio (the row's field), r and delta_d, ``modal`` the fit's
    :class:`~grazing_control.dynamics.identification.modal.ModalModel` with every
    parameter's standard error (``modal_stderr``), ``units`` (nan, nan) (the modal fit
    has no unit scales), ``phase_error`` the new model's Pi2 phase tau2 less the
    running one's."""

    model: OscillatorParams
    stderr: dict
    sigma: float
    units: tuple
    phase_error: float
    periods: float
    samples: int
    impacts: int
    cpu_s: float
    modal: object = None
    modal_stderr: dict | None = None


@dataclass(frozen=True)
class VectorGains:
    """An n-DOF law's gains: ``k`` (2n, on x_0..x_n-1, v_0..v_n-1), how the correction
    acts (``actuation``: the delay, or the design's
    :class:`~grazing_control.dynamics.design.family.Actuation` for a force pulse) and the
    family's parameter ``mu`` = N(k)_{i_w, i_w} on the model they run with
    (docs/theory_ndof.md §3): the redesign keeps mu and the actuation."""

    k: np.ndarray
    actuation: object = 0.0
    mu: float = math.nan

    @classmethod
    def of(cls, model: NdofModel, k, actuation=0.0) -> "VectorGains":
        """The gains ``k`` running on ``model``, with their mu (family.family_mu)."""
        from grazing_control.dynamics.design.family import family_mu

        k = np.array(k, dtype=float).reshape(-1)
        return cls(k, actuation, family_mu(model, k, actuation))

    @property
    def delay(self):
        """What predicted_impacts and the fit read as the delay (the actuation)."""
        return self.actuation


def _pulse_of(actuation) -> tuple:
    """(width, Actuator or None) of an n-DOF actuation: (0, None) for a delay."""
    if isinstance(actuation, (int, float)):
        return 0.0, None
    from grazing_control.dynamics.simulation.actuator import Actuator

    lag = (Actuator(actuation.time_constant, actuation.latency)
           if actuation.time_constant > 0.0 or actuation.latency > 0.0 else None)
    return actuation.width, lag


@dataclass(frozen=True)
class SwitchPlan:
    """What a worker hands back: the refit and the new gains (``gains``), or the refusal
    (``error``: a ReidentificationError) with the refit where one was made."""

    refit: Refit | None = None
    gains: Gains | None = None
    error: ReidentificationError | None = None
    requested_at: int | None = None

    @property
    def admissible(self) -> bool:
        return self.error is None


def model_from_fit(ident, running: OscillatorParams) -> OscillatorParams:
    """The controller's model from an Identification (module docstring, step 2).

    The stream is in the running model's units and time (sections at t_k = k T), so
    the new model keeps ``running``'s omega and pi2_offset, takes zeta and r as fitted,
    and puts the wall where the fit found it in the stream's units: Delta d = d_fit -
    a(omega; zeta_fit). (Delta d of the fit's own nondimensional model, d Omega^2 / A -
    a(omega / Omega), would carry the errors of Omega and A, each times d* ~ 1.8: at
    Delta d ~ 1e-6 they dominate; docs/theory_reidentification.md.)
    ReidentificationError ``not_identified`` outside the model's ranges.

    An n-DOF ``running`` model: :func:`_realised` (the fit's modes as a model file).
    """
    if isinstance(running, NdofModel):
        return _realised(ident, running)[0]
    m = ident.model
    try:
        new = running.with_(zeta=m.zeta, r=m.r, delta_d=0.0)
        return new.with_(delta_d=m.d - new.d_star)
    except ParameterError as exc:
        raise ReidentificationError("not_identified", f"the fitted model is outside the "
                                    f"model's ranges: {exc}") from None


def _check(ident, se: dict, named: dict, sigma) -> None:
    """The refit's checks in order (:func:`refit`'s reasons): every standard error of
    ``se`` finite and > 0 (``not_identified``: a singular fit), each parameter of
    ``named`` (name: value) within :data:`RELATIVE_SE` (``not_identified``), converged
    (``fit_failed``), the residual noise within :data:`RESIDUAL_RATIO` ``sigma``
    (``fit_failed``; None: not checked)."""
    bad = [n for n, s in se.items() if not (math.isfinite(s) and s > 0.0)]
    if bad:
        raise ReidentificationError("not_identified", f"the refit does not identify "
                                    f"{', '.join(bad)} (no finite standard error: a "
                                    "singular fit)")
    vague = [f"{n} = {v:.4g} +- {se[n]:.2g}" for n, v in named.items()
             if not se[n] <= RELATIVE_SE * abs(v)]
    if vague:
        raise ReidentificationError("not_identified", f"the refit does not determine "
                                    f"{', '.join(vague)} (standard error beyond "
                                    f"{RELATIVE_SE:.0%})")
    if not ident.converged:
        raise ReidentificationError("fit_failed", f"the refit did not converge: "
                                    f"{ident.message}")
    if sigma is not None and not ident.sigma <= RESIDUAL_RATIO * sigma:
        raise ReidentificationError("fit_failed", f"the refit does not explain the window: "
                                    f"residual noise {ident.sigma:.3g}, "
                                    f"{ident.sigma / sigma:.3g} x the sensor's {sigma:.3g}")


def _realised(ident, running: NdofModel) -> tuple:
    """(model, misfit) of an n-DOF fit: the model file whose wall coordinate shows the
    fitted modes (:func:`grazing_control.dynamics.identification.modal.realise`, nearest
    the running model), with the running time base (omega, phase, pi2_offset) and the
    wall where the fit put it, Delta d = d_fit - d*(new model).

    The sections of the stream are the plant's (t_k = k T at its Pi2 phase), so the
    phase of the fitted periodic response against the reference omega t says nothing of
    the model (arg X_fit = pi2_offset): only its amplitude d* does, and it alone is
    realised (``amplitude_only``); the phase of X_w is the realised model's, nearest the
    running one (forcing the running phase on the fitted modes moved f from (0, 1) to
    (-0.59, 2.14) and held the loop 14 times farther from the true orbit, measured in
    tests/test_reidentification_ndof.py's scene). ReidentificationError
    ``not_identified`` beyond :data:`REALISATION_LIMIT` standard errors or outside the
    model's ranges."""
    from grazing_control.dynamics.identification.modal import realise

    fitted = ident.model
    se = [ident.stderr[k] for k in ident.names]
    try:
        model, misfit = realise(fitted, running, se, running.phase, amplitude_only=True)
        new = dataclasses.replace(model, omega=running.omega, phase=running.phase,
                                  pi2_offset=running.pi2_offset, delta_d=0.0)
        new = dataclasses.replace(new, delta_d=fitted.d - NdofFlow.of(new).d_star)
    except (ParameterError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise ReidentificationError("not_identified", f"the fitted modes have no model "
                                    f"file near the running one: {exc}") from None
    if not misfit <= REALISATION_LIMIT:
        raise ReidentificationError(
            "not_identified", f"no symmetric M, C, K near the running model shows the "
            f"fitted modes: the nearest misses them by {misfit:.3g} standard errors (limit "
            f"{REALISATION_LIMIT:g})")
    return new, misfit


def _refit_ndof(record, running: NdofModel, kicks, actuation, max_nfev: int,
                periods, sigma, seconds) -> Refit:
    """:func:`refit` of an n-DOF model (module docstring): the modal fit of the wall
    coordinate from the running model's modes, the impact times of ``record`` as its
    start, ``kicks`` the corrections' sizes on the actuated coordinate as a kick or
    the ``actuation``'s pulse; the checks and reasons of the 1-DOF refit, over every
    mode's damping ratio and r."""
    from grazing_control.dynamics.identification import IdentificationError
    from grazing_control.dynamics.identification.fit import FitTimedOut
    from grazing_control.dynamics.identification.modal import modal_of
    from grazing_control.dynamics.identification.modal_fit import identify_modal

    c0 = time.process_time()
    if not record.impact_t.size:
        raise ReidentificationError("no_impacts", "the refit's window has no impact: the "
                                    "wall is not identifiable from free flight")
    own = modal_of(running)
    width, lag = _pulse_of(actuation)
    act = {}
    if width > 0.0:
        from grazing_control.dynamics.simulation.actuation import pulse_start

        act = dict(width=width, time_constant=0.0 if lag is None else lag.time_constant,
                   latency=0.0 if lag is None else lag.latency,
                   pulse_offset=pulse_start(running.period, actuation.delay, width)
                   - actuation.delay)
    try:
        ident = identify_modal(record, running.n, correction_dv=kicks,
                               kick_on_wall=running.i_a == running.i_w, max_arcs=None,
                               max_nfev=max_nfev, modes=(own.natural_frequency,
                                                         own.damping_ratio),
                               deadline=time.monotonic() + seconds, **act)
    except FitTimedOut as exc:
        raise ReidentificationError("not_identified", f"the refit did not end within "
                                    f"{seconds:g} s: {exc}") from None
    except IdentificationError as exc:
        reason = "no_impacts" if str(exc).startswith("impacts") else "fit_failed"
        raise ReidentificationError(reason, f"the refit failed: {exc}") from None
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise ReidentificationError("fit_failed", f"the refit failed: {exc}") from None
    m, se = ident.model, ident.stderr
    named = [f"damping_ratio_{j}" for j in range(m.n)] + ["r"]
    _check(ident, {k: se[k] for k in named + [f"natural_frequency_{j}" for j in range(m.n)]
                   + ["delta_d"]}, {k: ident.value(k) for k in named}, sigma)
    new = model_from_fit(ident, running)
    phase = math.remainder(NdofFlow.of(new).tau2 - NdofFlow.of(running).tau2, 2.0 * math.pi)
    span = record.t[-1] - record.t[0]
    return Refit(new, {"zeta": se["damping_ratio_0"], "r": se["r"], "delta_d": se["delta_d"]},
                 ident.sigma, (math.nan, math.nan), phase,
                 periods if periods is not None else span / running.period,
                 ident.samples_used, ident.impacts_used, time.process_time() - c0,
                 m, dict(se))


def refit(record, running: OscillatorParams, *, max_nfev: int = MAX_NFEV,
          periods: float | None = None, sigma: float | None = None,
          seconds: float = REFIT_SECONDS, kicks=None, actuation=0.0) -> Refit:
    """Fit the model to ``record`` (:func:`grazing_control.dynamics.identification.identify`
    with the recorded impact times where there are some, else found from the motion,
    started from the running model's zeta and Omega = 1) and map it to the controller's
    model (:func:`model_from_fit`).

    ``sigma``: the sensor's noise std; the fit's residual noise must not exceed
    :data:`RESIDUAL_RATIO` times it (None: not checked). ``seconds``: the fit's
    wall-clock budget (:data:`REFIT_SECONDS`; beyond it ``not_identified``).

    Raises ReidentificationError: ``no_impacts`` (none recorded or found), ``fit_failed``
    (the solver did not converge, no initial guess, a residual beyond RESIDUAL_RATIO
    sigma), ``not_identified`` (zeta, r or d
    without a finite standard error: a singular fit; zeta or r with a standard error
    beyond :data:`RELATIVE_SE` of its value; or outside the model's ranges).

    An n-DOF ``running`` model (:func:`_refit_ndof`): ``kicks`` the sizes of
    ``record``'s corrections, ``actuation`` how they act (:class:`VectorGains`); the
    impact times must be in ``record`` (the fit starts from them; ``no_impacts``).
    """
    if isinstance(running, NdofModel):
        return _refit_ndof(record, running, kicks, actuation, max_nfev, periods, sigma,
                           seconds)
    # the fit's solver (scipy.optimize) is imported here, in the worker: a node that
    # never refits does not load it (tests/test_node_common.py)
    from grazing_control.dynamics.identification import IdentificationError, identify
    from grazing_control.dynamics.identification.fit import FitTimedOut

    c0 = time.process_time()
    impacts = "recorded" if record.impact_t.size else "motion"
    try:
        ident = identify(record, impacts=impacts, max_arcs=None, max_nfev=max_nfev,
                         prior=(running.zeta, 1.0), fixed=UNITS,
                         deadline=time.monotonic() + seconds)
    except FitTimedOut as exc:
        raise ReidentificationError("not_identified", f"the refit did not end within "
                                    f"{seconds:g} s: {exc}") from None
    except IdentificationError as exc:
        reason = "no_impacts" if "no impact" in str(exc) else "fit_failed"
        raise ReidentificationError(reason, f"the refit failed: {exc}") from None
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise ReidentificationError("fit_failed", f"the refit failed: {exc}") from None
    if ident.impacts_used == 0:
        raise ReidentificationError("no_impacts", "the refit's window has no impact: the "
                                    "wall is not identifiable from free flight")
    se = {"zeta": ident.stderr["zeta"], "r": ident.stderr["r"], "d": ident.stderr["d"]}
    _check(ident, se, {n: getattr(ident.model, n) for n in ("zeta", "r")}, sigma)
    new = model_from_fit(ident, running)
    m = ident.model
    phase = math.remainder(m.tau0 + m.forcing_phase - new.tau2, 2.0 * math.pi)
    span = record.t[-1] - record.t[0]
    return Refit(new, {"zeta": se["zeta"], "r": se["r"], "delta_d": se["d"]}, ident.sigma,
                 (m.natural_frequency, m.forcing_amplitude), phase,
                 periods if periods is not None else span / running.period,
                 ident.samples_used, ident.impacts_used, time.process_time() - c0)


def redesign(p: OscillatorParams, gains: Gains, conditions: str = "combined") -> Gains:
    """The gains of the new model ``p``: the running c2 and delay, c1 from the degenerate
    condition N_g,12 = 0 of ``p`` (Eq. 38 / (D5)), when the design's ``conditions``
    (:data:`grazing_control.dynamics.design.gains.CONDITIONS`) hold for ``p`` at that c2
    (:func:`grazing_control.dynamics.design.gains.condition_values`: the limit multipliers
    inside the unit circle, the 1/1 motion's existence, the non-impacting motion's
    stability). ReidentificationError ``no_admissible_design`` otherwise.

    An n-DOF model ``p`` with :class:`VectorGains`: k(mu) of ``p``'s family at the
    running mu with the running actuation (:func:`_family_member`)."""
    from grazing_control.dynamics.design.gains import condition_values, degenerate_c1

    if conditions not in CONDITIONS:
        raise ParameterError(f"design_conditions={conditions!r} is invalid: valid values are "
                             f"{', '.join(CONDITIONS)}")
    try:
        if isinstance(p, NdofModel):
            new, ok, where = _family_member(p, gains, conditions)
        else:
            c1 = degenerate_c1(p, gains.c2, gains.delay)
            ok = condition_values(p, gains.c2, gains.delay).holds(conditions)
            new, where = Gains(c1, gains.c2, gains.delay), (
                f"zeta={p.zeta:.6g}, r={p.r:.6g}, delta_d={p.delta_d:.6g}) has no "
                f"admissible design at c2={gains.c2:.6g}, delay={gains.delay:g} ("
                f"{conditions} conditions")
    except (ParameterError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise ReidentificationError("no_admissible_design", f"no design for the refitted "
                                    f"model: {exc}") from None
    if not ok:
        raise ReidentificationError("no_admissible_design", f"the refitted model ({where}): "
                                    "old model and gains kept")
    return new


#: The FamilyDesign property that says a condition set holds (``grazing design --model``).
_FAMILY_HOLDS = {"combined": "admissible", "impacting": "admissible_impacting",
                 "non-impacting": "free_stable"}


def _family_member(p: NdofModel, gains: VectorGains, conditions: str) -> tuple:
    """(VectorGains, whether ``conditions`` hold, what the refusal says) of the n-DOF
    redesign: k = k(mu) of ``p`` (docs/theory_ndof.md §3, (N9) with the delay, §15 with
    the pulse: :func:`grazing_control.dynamics.design.family.gain_family`) at the running
    ``gains.mu`` and actuation, the conditions of
    :func:`grazing_control.dynamics.design.family.evaluate_design` (the limit spectrum
    inside the unit circle and gamma1 > 0: impacting; |mu| < 1 and the transmission
    zeros inside: non-impacting)."""
    from grazing_control.dynamics.design.family import evaluate_design

    design = evaluate_design(p, gains.mu, gains.actuation)
    k = np.array(design.gains, dtype=float)
    k.setflags(write=False)
    return VectorGains(k, gains.actuation, gains.mu), bool(
        getattr(design, _FAMILY_HOLDS[conditions])), (
        f"r={p.r:.6g}, delta_d={p.delta_d:.6g}) has no admissible design at mu="
        f"{gains.mu:.6g} ({conditions} conditions: limit radius {design.limit_radius:.4g}, "
        f"gamma1 {design.gamma1:.4g}, zeros radius {design.zeros_radius:.4g}")


def plan_switch(window: StreamWindow, running: OscillatorParams, gains: Gains,
                conditions: str = "combined", *, max_nfev: int = MAX_NFEV,
                requested_at: int | None = None, sigma: float | None = None) -> SwitchPlan:
    """The window's Recording, refit and redesign (steps 1-3): a SwitchPlan with the new
    gains, or with the refusal (never raises a ReidentificationError)."""
    from grazing_control.dynamics.identification.data import RecordingError

    try:
        record = window.recording(running, gains.delay)
        more = {} if not isinstance(running, NdofModel) else dict(
            kicks=window.kick_sizes(), actuation=gains.actuation)
        fit = refit(record, running, max_nfev=max_nfev, sigma=sigma, **more)
    except ReidentificationError as exc:
        return SwitchPlan(error=exc, requested_at=requested_at)
    except (RecordingError, ValueError) as exc:
        return SwitchPlan(error=ReidentificationError("fit_failed", f"the refit failed: {exc}"),
                          requested_at=requested_at)
    try:
        new_gains = redesign(fit.model, gains, conditions)
    except ReidentificationError as exc:
        return SwitchPlan(refit=fit, error=exc, requested_at=requested_at)
    return SwitchPlan(refit=fit, gains=new_gains, requested_at=requested_at)


def switch_estimator(stream, new: OscillatorParams, wall_std: float | None = None) -> None:
    """Move a stream estimator (:class:`grazing_control.dynamics.estimation.stream.StreamEstimator`
    or the augmented one) to the model ``new`` at a Pi2 section, after its estimate and
    before its correction: the filter's deviation z (from the old model's X**) becomes
    z + X**_old - X**_new, the same absolute state; its covariance is kept. The
    augmented filter's Delta d restarts at the new model's with its prior variance
    kept, or set to ``wall_std`` (the refit's standard error of the wall, which the
    tracking then refines: docs/theory_reidentification.md); its bias estimate is kept
    (it belongs to the sensor). An n-DOF stream estimator (plain or augmented): z (2n)
    the same way, with X** = X_p(tau2) of each model, and its flow the new model's."""
    old = stream.p
    if isinstance(old, NdofModel):
        a, b = (NdofFlow.of(m) for m in (old, new))
        shift = tuple(a.particular(a.tau2) - b.particular(b.tau2))
    else:
        shift = (old.x_ref - new.x_ref, old.v_ref - new.v_ref)

    def moved(z):
        return tuple(zi + si for zi, si in zip(z, shift))

    if getattr(stream, "filter", None) is not None:
        f = stream.filter
        stream.filter = FilterState(moved(f.z), f.cov, f.periods)
    if hasattr(stream, "identified"):           # the augmented filter
        stream.identified = new
        stream.params = (stream.params[0], float(new.delta_d))
        renew = wall_std is not None and stream.use_wall and math.isfinite(wall_std)
        if renew:
            stream.params_cov = stream.params_cov.copy()
            stream.params_cov[1, :] = stream.params_cov[:, 1] = 0.0
            stream.params_cov[1, 1] = float(wall_std) ** 2
        state = stream.state
        if state is not None:
            cov = state.cov.copy()
            w = len(shift) + 1                  # Delta d after z and the bias
            if renew:
                cov[w, :] = cov[:, w] = 0.0
                cov[w, w] = float(wall_std) ** 2
            stream.state = type(state)(moved(state.z), state.bias, float(new.delta_d), cov,
                                       state.periods)
    if isinstance(old, NdofModel):
        stream.flow = NdofFlow.of(new)
    stream.p = new


class Reidentifier:
    """The worker: one refit at a time in a thread of its own, so that the caller (the
    control loop) never waits for it.

    ``request(record, running, gains, k)`` starts :func:`plan_switch` on a snapshot;
    ReidentificationError ``busy`` while one runs. ``take()`` returns the finished
    SwitchPlan once (None while running or idle): the caller applies it at its next Pi2
    section.
    """

    def __init__(self, conditions: str = "combined", max_nfev: int = MAX_NFEV,
                 sigma: float | None = None):
        if conditions not in CONDITIONS:
            raise ParameterError(f"design_conditions={conditions!r} is invalid: valid values "
                                 f"are {', '.join(CONDITIONS)}")
        self.conditions, self.max_nfev, self.sigma = conditions, max_nfev, sigma
        self._thread = None
        self._result = None
        self._lock = threading.Lock()
        self.started_at = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def request(self, record: StreamRecord, running: OscillatorParams, gains: Gains,
                k: int | None = None) -> None:
        """Start a refit of ``record``'s window (its snapshot is taken here, in the
        caller's thread). ReidentificationError ``busy`` while a fit runs or its result
        was not taken, ``too_few_periods`` when the window is short (nothing started)."""
        with self._lock:
            if self.running or self._result is not None:
                raise ReidentificationError("busy", "a refit is already running: request "
                                            "refused")
        window = record.snapshot(isinstance(running, NdofModel))  # too_few_periods here
        self.started_at = k

        def work():
            plan = plan_switch(window, running, gains, self.conditions,
                               max_nfev=self.max_nfev, requested_at=k, sigma=self.sigma)
            with self._lock:
                self._result = plan

        self._thread = threading.Thread(target=work, name="reidentify", daemon=True)
        self._thread.start()

    def take(self) -> SwitchPlan | None:
        with self._lock:
            if self._result is None or self.running:
                return None
            plan, self._result = self._result, None
            self._thread = None
            return plan

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

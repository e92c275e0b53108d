"""Event-driven simulation on section Pi2, single trajectory and batch.

A run is a sequence of forcing periods, each from one Pi2 sample to the next: the
state is sampled on Pi2 (before the controller acts), the correction of Eq. 28 is
applied if the controller is on, and the exact flow with impacts
(:func:`grazing_control.oscillator.impact.advance`) carries it over one period T. One call of
:func:`period_step` per period is the whole integration, so the ROS simulator node,
which calls the same function, reproduces this module sample for sample.

Time origin: t = 0 is the first Pi2 sample; the phase there is tau2.
"""

from __future__ import annotations

import math
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from grazing_control.oscillator import kernel as _kernel
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.flow import propagate, to_deviation, to_physical
from grazing_control.dynamics.simulation.fidelity import FIDELITIES, ModelValidityError, choose_fidelity
from grazing_control.dynamics.simulation.fidelity import period_step as fidelity_step
from grazing_control.oscillator.impact import (NonFiniteStateError, Segment, advance,
                                               check_state)
from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["SimulationResult", "period_step", "core_period_step", "states_between",
           "core_states_between", "simulate", "simulate_batch", "MAX_PERIODS"]

TWO_PI = 2.0 * math.pi
#: Largest number of periods of one :func:`simulate` call: it keeps 4 floats and an
#: integer per period (~40 bytes), so 1e7 periods need ~400 MB; split longer runs.
MAX_PERIODS = 10_000_000


def period_step(p: OscillatorParams, dx: float, dv: float, dv_correction: float = 0.0, *,
                delay: float = 0.0) -> Segment:
    """One forcing period from a Pi2 sample (deviation dx, dv) with a correction dv_correction.

    The correction enters as an instantaneous velocity change (Eq. 28) applied ``delay``
    after the sample (0 <= delay < T; 0: on Pi2 itself, the study's controller); the rest
    is the exact flow with impacts from phase tau2 over one period. Impact times in the
    returned segment count from the sample. Runs on the compiled kernel when it is in use
    (:func:`grazing_control.oscillator.kernel.use_kernel`), which gives the same result.
    """
    if _kernel.use_kernel() and (delay == 0.0 or 0.0 < delay < p.period):
        return _kernel.period_step(p, dx, dv, dv_correction, delay=delay)
    return core_period_step(p, dx, dv, dv_correction, delay=delay)


def core_period_step(p: OscillatorParams, dx: float, dv: float, dv_correction: float = 0.0, *,
                     delay: float = 0.0) -> Segment:
    """:func:`period_step` on the pure-Python core (the reference), whatever
    ``GRAZING_KERNEL`` says: the sweeps' python engine runs it."""
    if delay == 0.0:
        return advance(p, p.tau2, dx, dv + dv_correction, p.period)
    if not 0.0 < delay < p.period:
        raise ValueError(f"delay={delay!r} is invalid: valid range is 0 <= delay < T = {p.period!r}")
    first = advance(p, p.tau2, dx, dv, delay)
    tau = (p.tau2 + p.omega * delay) % TWO_PI
    second = advance(p, tau, first.dx, first.dv + dv_correction, p.period - delay)
    later = [i._replace(dt=i.dt + delay, release=i.release + delay) for i in second.impacts]
    return Segment(second.dx, second.dv, first.impacts + later, None)


def states_between(p: OscillatorParams, tau0: float, dx: float, dv: float,
                   impacts, times) -> np.ndarray:
    """Dense output: physical (x, v) at ``times`` (since the segment start, sorted).

    ``(dx, dv)`` is the deviation at the start, just after any correction, and
    ``impacts`` the segment's impact list from :func:`advance`; between events the
    closed-form flow is evaluated, so dense output never changes the trajectory. Runs
    on the compiled kernel when it is in use
    (:func:`grazing_control.oscillator.kernel.use_kernel`) and ``times`` is 1-D, which
    gives the same numbers bit for bit; :func:`core_states_between` is the reference.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim == 1 and _kernel.use_kernel():
        return _kernel.states_between(p, tau0, dx, dv, impacts, times)
    return core_states_between(p, tau0, dx, dv, impacts, times)


def core_states_between(p: OscillatorParams, tau0: float, dx: float, dv: float,
                        impacts, times) -> np.ndarray:
    """:func:`states_between` in pure Python (the reference), whatever ``GRAZING_KERNEL``
    says: per sample, the deviation flow z(t) = Phi(t - t0) z(t0) from the last event
    (:func:`~grazing_control.oscillator.flow.propagate`, docs/theory.md "Deviation
    coordinates") plus the non-impacting motion y_p
    (:func:`~grazing_control.oscillator.flow.to_physical`); after an impact the flow
    restarts from (d, v+) at its phase, and after a sticking one the mass rests at
    (d, 0) until the release, then flows from (d, 0)."""
    times = np.asarray(times, dtype=float)
    out = np.empty((times.size, 2))
    t0, z, stuck_until = 0.0, (dx, dv), -math.inf
    events = list(impacts)
    k = 0
    for j, t in enumerate(times):
        while k < len(events) and events[k].dt <= t:
            imp = events[k]
            if imp.sticking:  # on the wall at rest until the release, then free from (d, 0)
                stuck_until = imp.release
                t0 = min(imp.release, 1e300)
                z = to_deviation(p, tau0 + p.omega * t0, p.d, 0.0)
            else:
                t0 = imp.dt
                z = to_deviation(p, imp.phase, p.d, imp.v_plus)
            k += 1
        if t < stuck_until:
            out[j] = (p.d, 0.0)
            continue
        dzx, dzv = propagate(p.zeta, z[0], z[1], t - t0)
        out[j] = to_physical(p, tau0 + p.omega * t, dzx, dzv)
    return out


@dataclass
class SimulationResult:
    """A simulated run, one entry per forcing period k = 0 .. N-1.

    Attributes
    ----------
    pi2 : (N, 2) array of the physical Pi2 samples (x, v), before control.
    pi2_deviation : (N, 2) array of (x - x**, v - v**) at full precision.
    corrections : (N,) array of the velocity corrections applied at each sample.
    impacts_per_period : (N,) int array.
    impacts : (M, 5) array of [period k, time t, phase, v-, v+].
    final_deviation : deviation at the sample after the last period.
    fidelity, fidelity_reason : the model used and why (see :mod:`grazing_control.dynamics.simulation.fidelity`).
    """

    params: OscillatorParams
    gains: Gains | None
    control_after: int | None
    pi2: np.ndarray
    pi2_deviation: np.ndarray
    corrections: np.ndarray
    impacts_per_period: np.ndarray
    impacts: np.ndarray
    final_deviation: tuple = field(default=(0.0, 0.0))
    fidelity: str = "exact"
    fidelity_reason: str = ""


def simulate(p: OscillatorParams, periods: int, *, x0: float | None = None,
             v0: float | None = None, deviation=None, gains: Gains | None = None,
             control_after: int | None = 0, fidelity: str = "exact",
             tol: float = 1e-9, progress: bool = False) -> SimulationResult:
    """Simulate ``periods`` forcing periods from a state on Pi2.

    Parameters
    ----------
    p : OscillatorParams
    periods : int
        Number of forcing periods N >= 0.
    x0, v0 : float, optional
        Initial state on Pi2; default X** (the grazing orbit's point), or
    deviation : (float, float), optional
        the initial state as (x - x**, v - v**).
    gains : Gains, optional
        Controller gains; None runs the uncontrolled system.
    control_after : int or None
        The controller acts at samples k >= control_after (the study switches it on
        after 1000 samples); None never.
    fidelity : str
        'exact' (default), 'zdm2', 'zdm1', 'ode' (:mod:`grazing_control.dynamics.simulation.fidelity`), or
        'auto': the cheapest of exact/zdm2/zdm1 whose estimated error over this scene's
        horizon is <= ``tol`` (the choice and its reason are in the result).
    tol : float
        Tolerance for 'auto'.
    progress : bool
        Show a progress bar (tqdm, on stderr); for interactive use.

    Returns
    -------
    SimulationResult

    Raises
    ------
    NonFiniteStateError
        A state or a correction became non-finite or absurdly large (an input
        overflowed); the message names it and the period.
    """
    if int(periods) != periods or not 0 <= periods <= MAX_PERIODS:
        raise ValueError(f"periods={periods!r} is invalid: valid range is an integer in "
                         f"[0, {MAX_PERIODS}] (memory: one Pi2 sample is kept per period; "
                         f"split longer runs)")
    if control_after is not None and (int(control_after) != control_after or control_after < 0):
        raise ValueError(
            f"control_after={control_after!r} is invalid: valid range is an integer >= 0 or None")
    periods = int(periods)
    if deviation is not None:
        dx, dv = (float(deviation[0]), float(deviation[1]))
    else:
        x = p.x_ref if x0 is None else float(x0)
        v = p.v_ref if v0 is None else float(v0)
        dx, dv = x - p.x_ref, v - p.v_ref
    check_state(dx, dv, p.zeta, "the initial state")
    active = gains is not None and control_after is not None
    reason = "exact: the closed-form flow (requested)" if fidelity == "exact" else \
        f"{fidelity}: requested"
    auto = fidelity == "auto"
    delay = gains.delay if active else 0.0  # actuation delay (docs/theory_delay.md)
    if delay != 0.0 and not 0.0 < delay < p.period:
        raise ParameterError(f"delay={delay!r} is invalid: valid range is 0 <= delay < T = "
                             f"{p.period!r} (the correction acts within the period it answers)")
    if auto and delay != 0.0:
        fidelity, reason, auto = "exact", "exact: the maps do not model an actuation delay", False
    if auto:
        choice = choose_fidelity(p, max(periods, 1), tol, deviation=(dx, dv),
                                 gains=gains if active else None,
                                 control_after=control_after if active else None)
        fidelity, reason = choice.fidelity, choice.reason
    elif fidelity not in FIDELITIES:
        raise ValueError(f"fidelity={fidelity!r} is invalid: valid values are "
                         f"{', '.join(FIDELITIES)}, auto")
    if delay != 0.0 and fidelity != "exact":
        raise ValueError(f"fidelity={fidelity!r} does not model an actuation delay "
                         f"(delay={delay!r}): use fidelity='exact'")
    args = (p, periods, dx, dv, gains if active else None, control_after if active else None)
    if fidelity == "exact" and _kernel.use_kernel():  # the same loop, compiled
        dev, corr, counts, imps, (dx, dv) = _kernel.simulate_exact(*args, delay=delay,
                                                                   progress=progress)
        fallbacks = 0
    else:
        dev, corr, counts, imps, (dx, dv), fallbacks = _simulate_loop(
            *args, delay=delay, progress=progress, fidelity=fidelity, fall_back=auto)
    if fallbacks:
        reason += (f"; exact in {fallbacks} of {periods} periods where {fidelity} "
                   "does not apply")
    pi2 = dev + np.array([p.x_ref, p.v_ref])
    return SimulationResult(p, gains, control_after if active else None, pi2, dev, corr, counts,
                            np.array(imps, dtype=float).reshape(-1, 5), (dx, dv),
                            fidelity, reason)


def _simulate_loop(p, periods, dx, dv, gains, control_after, *, delay=0.0, progress=False,
                   fidelity="exact", fall_back=False):
    """The period loop of :func:`simulate` in Python (any fidelity); the compiled kernel's
    :func:`grazing_control.oscillator.kernel.simulate_exact` is the same loop for the exact flow.

    Returns (deviation (N, 2), corrections (N,), impacts per period (N,), impact rows
    [k, t, phase, v-, v+], final deviation, periods where a map fell back to exact).
    """
    dev = np.empty((periods, 2))
    corr = np.zeros(periods)
    counts = np.zeros(periods, dtype=int)
    imps = []
    fallbacks = 0
    ks = range(periods)
    if progress:
        from tqdm import tqdm

        ks = tqdm(ks, total=periods, unit="period", file=sys.stderr, leave=False)
    for k in ks:
        dev[k] = dx, dv
        controlled = gains is not None and k >= control_after
        dvc = gains.c1 * dx + gains.c2 * dv if controlled else 0.0
        if not abs(dvc) <= 1e150:
            raise NonFiniteStateError(
                f"the correction c1*dx + c2*dv = {dvc!r} at period {k} is not finite or exceeds 1e150: "
                f"an input overflowed "
                f"(c1={gains.c1!r}, c2={gains.c2!r}, dx={dx!r}, dv={dv!r})")
        corr[k] = dvc
        try:
            if fidelity == "exact" or (delay != 0.0 and controlled):
                seg = period_step(p, dx, dv, dvc, delay=delay if controlled else 0.0)
            else:
                try:
                    seg = fidelity_step(p, dx, dv, dvc, fidelity)
                except ModelValidityError:
                    if not fall_back:
                        raise
                    seg = period_step(p, dx, dv, dvc)  # auto: exact where the map does not apply
                    fallbacks += 1
        except NonFiniteStateError as exc:
            raise NonFiniteStateError(f"at period {k}: {exc}") from None
        counts[k] = len(seg.impacts)
        for i in seg.impacts:
            imps.append((k, k * p.period + i.dt, i.phase, i.v_minus, i.v_plus))
        dx, dv = seg.dx, seg.dv
    return dev, corr, counts, imps, (dx, dv), fallbacks


def _batch_one(args):
    p, periods, keep, kwargs = args
    res = simulate(p, periods, **kwargs)
    return res.pi2[-keep:], res.impacts_per_period[-keep:]


def simulate_batch(p: OscillatorParams, delta_d, periods: int, *, keep: int | None = None,
                   workers: int = 1, **kwargs):
    """Simulate the same scene for many values of Delta d (bifurcation diagrams).

    Parameters
    ----------
    p : OscillatorParams
        The other parameters; its delta_d is replaced by each value.
    delta_d : array_like
        Values of Delta d.
    periods : int
        Periods per value.
    keep : int, optional
        Keep only the last ``keep`` samples (after transients); default all.
    workers : int
        Processes to use (1: in this process).
    **kwargs
        Passed to :func:`simulate` (initial state, gains, control_after).

    Returns
    -------
    pi2 : (len(delta_d), keep, 2) array
    impacts_per_period : (len(delta_d), keep) array
    """
    values = np.atleast_1d(np.asarray(delta_d, dtype=float))
    keep = periods if keep is None else int(keep)
    jobs = [(p.with_(delta_d=float(d)), periods, keep, kwargs) for d in values]
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as ex:
            out = list(ex.map(_batch_one, jobs, chunksize=max(1, len(jobs) // (4 * workers))))
    else:
        out = [_batch_one(j) for j in jobs]
    pi2 = np.stack([o[0] for o in out]) if out else np.empty((0, keep, 2))
    counts = np.stack([o[1] for o in out]) if out else np.empty((0, keep), dtype=int)
    return pi2, counts

"""The closed loop through the exact core with faults: loss, noise, delay jitter.

Issue 8 section 3, docs/robustness.md. :func:`simulate_with_faults` runs the Pi2 loop of
:mod:`grazing_control.dynamics.simulation.simulate` with the faults of :class:`grazing_control.plant.faults.FaultModel`
drawn per sample (the nodes draw the same ones, so a node run can be compared with it
sample for sample):

* sample k (counted from the scene's first sample, ``first_sample`` for a run that starts
  later) is measured as (x + sigma e_x, v + sigma e_v);
* its correction c1 (x~ - x**) + c2 (v~ - v**) is dropped with probability ``loss``;
* otherwise it acts at delay + jitter e_d after the sample (clipped to [0, T)), through
  :func:`grazing_control.dynamics.simulation.simulate.period_step` with that delay.

**Capture** (:func:`capture_statistics`): the loop has captured the controlled 1/1 orbit
z* (the exact orbit of :func:`grazing_control.dynamics.orbits.one_one.orbit` for the designed gains and
delay) at sample n if the distance |z_k - z*| (Euclidean, on the Pi2 deviation) is
<= ``threshold`` for the ``hold`` consecutive samples k = n, ..., n + hold - 1, all inside
the first N = ``horizon`` controlled samples. The **stationary spread** is the RMS of that
distance over the last ``tail`` samples of the run.

**Prediction** (:func:`predicted_spread`, docs/robustness.md): for small faults the
deviation from z* obeys the linearised loop e_{k+1} = J e_k + u_k, J the orbit's
monodromy M2 (M1 + e2 k^T) (docs/theory_delay.md (D3)), u_k the fault's effect at the
end of the period; its stationary RMS is sqrt(tr Sigma + |m|^2) with Sigma the solution
of the discrete Lyapunov equation Sigma = J Sigma J^T + Cov u and m = (I - J)^{-1} E u.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.plant.faults import FaultModel
from grazing_control.oscillator.impact import ImpactCapError, InitialStateError
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.design.noise import loop_linearisation
from grazing_control.dynamics.simulation.simulate import period_step, simulate

__all__ = ["simulate_with_faults", "attractor_states", "CaptureResult", "capture_time",
           "capture_statistics", "LEVELS", "fault_sweep", "predicted_spread"]


def simulate_with_faults(p: OscillatorParams, gains: Gains, faults: FaultModel, periods: int, *,
                         deviation=(0.0, 0.0), first_sample: int = 0) -> np.ndarray:
    """Controlled Pi2 deviations over ``periods`` samples with the faults of ``faults``.

    Parameters
    ----------
    p : OscillatorParams
    gains : Gains
        c1, c2 and the designed actuation delay (``gains.delay``).
    faults : FaultModel
    periods : int
        Number of samples N >= 0 (all controlled).
    deviation : (float, float)
        Pi2 deviation (x - x**, v - v**) at the first sample.
    first_sample : int
        Index k of the first sample in the scene (the faults of sample k are drawn).

    Returns
    -------
    (N + 1, 2) array of the deviations at samples first_sample .. first_sample + N.
    """
    if int(periods) != periods or periods < 0:
        raise ValueError(f"periods={periods!r} is invalid: valid range is an integer >= 0")
    dx, dv = float(deviation[0]), float(deviation[1])
    out = np.empty((int(periods) + 1, 2))
    out[0] = dx, dv
    for j in range(int(periods)):
        k = first_sample + j
        f = faults.draw(k)
        if f.dropped:
            seg = period_step(p, dx, dv)
        else:
            dvc = gains.c1 * (dx + f.noise_x) + gains.c2 * (dv + f.noise_v)
            seg = period_step(p, dx, dv, dvc, delay=faults.actuation_delay(gains.delay, k, p.period))
        dx, dv = seg.dx, seg.dv
        out[j + 1] = dx, dv
    return out


def predicted_spread(p: OscillatorParams, gains: Gains, kind: str, level: float, target=None) -> float:
    """Stationary RMS distance to z* of the linearised loop for one fault kind and level.

    noise: u = M2 e2 k^T n, n ~ N(0, sigma^2 I); jitter: the kick dv* acts eps later, so
    the state after it differs by (I - Phi(eps)) e2 dv* = -eps A e2 dv* + O(eps^2),
    u = -M2 A e2 dv* eps, eps = max(-delay, jitter e), e ~ N(0, 1) (the clip at the
    sample; its mean and variance are those of the clipped normal); loss: u = -M2 e2 dv*
    with probability p (mean and covariance).
    Valid while the faults keep the motion in the orbit's linear regime (docs/robustness.md).
    """
    from scipy.linalg import solve_discrete_lyapunov

    from grazing_control.dynamics.orbits import one_one

    if target is None:
        target = one_one.orbit(p, gains).state
    j, m2, dvc = loop_linearisation(p, gains, target)
    mean = np.zeros(2)
    if kind == "noise":
        b = m2[:, 1]
        q = level ** 2 * (gains.c1 ** 2 + gains.c2 ** 2) * np.outer(b, b)
    elif kind == "jitter":
        u = -(m2 @ np.array([1.0, -2.0 * p.zeta])) * dvc  # A e2 = (1, -2 zeta)
        e_mean, e_var = _clipped_normal_moments(-gains.delay, level)
        mean = np.linalg.solve(np.eye(2) - j, e_mean * u)
        q = e_var * np.outer(u, u)
    elif kind == "loss":
        u = -m2[:, 1] * dvc
        mean = np.linalg.solve(np.eye(2) - j, level * u)
        q = level * (1.0 - level) * np.outer(u, u)
    else:
        raise ValueError(f"kind={kind!r} is invalid: valid values are {', '.join(LEVELS)}")
    sigma = solve_discrete_lyapunov(j, q)
    return float(math.sqrt(max(np.trace(sigma), 0.0) + mean @ mean))


def _clipped_normal_moments(a: float, sigma: float):
    """Mean and variance of max(a, sigma Z), Z ~ N(0, 1), a <= 0."""
    if sigma == 0.0:
        return 0.0, 0.0
    al = a / sigma
    cdf = 0.5 * math.erfc(-al / math.sqrt(2.0))
    pdf = math.exp(-0.5 * al * al) / math.sqrt(2.0 * math.pi)
    mean = a * cdf + sigma * pdf
    second = a * a * cdf + sigma * sigma * (1.0 - cdf + al * pdf)
    return mean, max(second - mean * mean, 0.0)


def attractor_states(p: OscillatorParams, count: int, *, transient: int = 1000, stride: int = 7,
                     deviation=(0.0, 0.0)) -> np.ndarray:
    """``count`` Pi2 deviations on the uncontrolled attractor (the study's scenes).

    One uncontrolled run from ``deviation`` (default X**): ``transient`` samples, then a
    state every ``stride`` samples. Returns a (count, 2) array; the state i is sample
    transient + i * stride of that run.
    """
    n = transient + stride * max(count - 1, 0) + 1
    res = simulate(p, n, deviation=deviation)
    return res.pi2_deviation[transient::stride][:count].copy()


def capture_time(distance: np.ndarray, threshold: float, hold: int) -> int | None:
    """First n with distance[n : n + hold] all <= threshold, or None."""
    ok = np.asarray(distance) <= threshold
    run = 0
    for k, flag in enumerate(ok):
        run = run + 1 if flag else 0
        if run >= hold:
            return k - hold + 1
    return None


@dataclass(frozen=True)
class CaptureResult:
    """Capture statistics over seeds for one fault setting.

    captured : fraction of seeds captured within the first ``horizon`` samples.
    times : capture sample of each seed (nan: not captured).
    spread : RMS distance to z* over the last ``tail`` samples, per seed.
    """

    captured: float
    times: np.ndarray
    spread: np.ndarray


def _one_run(args):
    p, gains, faults, start, horizon, tail, first_sample, target, threshold, hold = args
    try:
        traj = simulate_with_faults(p, gains, faults, horizon + tail, deviation=start,
                                    first_sample=first_sample)
    except (ImpactCapError, InitialStateError, ValueError):
        return math.nan, math.nan
    dist = np.hypot(traj[:, 0] - target[0], traj[:, 1] - target[1])
    n = capture_time(dist[: horizon + hold], threshold, hold)
    t = math.nan if n is None or n + hold > horizon else float(n)
    spread = float(np.sqrt(np.mean(dist[-tail:] ** 2)))
    return t, spread


def capture_statistics(p: OscillatorParams, gains: Gains, target, starts, fault_models, *,
                       horizon: int = 400, tail: int = 200, threshold: float = 1e-4,
                       hold: int = 20, first_sample: int = 1000, executor=None) -> CaptureResult:
    """Capture probability and spread over seeds: one fault model and start state per seed.

    ``target`` is z* (Pi2 deviation of the controlled 1/1 orbit). Each run is
    ``horizon + tail`` controlled samples from its start; captured if the capture
    (module docstring) completes within ``horizon`` samples. ``executor``: an optional
    concurrent.futures executor to map the runs over.
    """
    jobs = [(p, gains, f, tuple(s), horizon, tail, first_sample, tuple(target), threshold, hold)
            for f, s in zip(fault_models, starts)]
    results = list(executor.map(_one_run, jobs)) if executor is not None else [_one_run(j) for j in jobs]
    times = np.array([r[0] for r in results])
    spread = np.array([r[1] for r in results])
    return CaptureResult(float(np.mean(~np.isnan(times))), times, spread)


#: Fault levels of the sweep (docs/robustness.md): loss probability, noise std on the
#: measured x and v, jitter std of the actuation time (simulation units; T = 9.42).
LEVELS = {
    "loss": (0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.4),
    "noise": (0.0, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3),
    "jitter": (0.0, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0),
}


def fault_sweep(p: OscillatorParams, gains: Gains, delta_d: float, kind: str, levels, seeds: int, *,
                horizon: int = 400, tail: int = 200, threshold: float = 1e-4, hold: int = 20,
                transient: int = 1000, executor=None) -> dict:
    """Capture probability and spread vs the level of one fault kind, at one Delta d.

    Seed i starts from the i-th state of :func:`attractor_states` (1000 uncontrolled
    samples, then one every 7) with FaultModel(kind=level, seed=i), its faults drawn for
    samples ``transient`` + j (control switched on at sample ``transient``, as in the
    study's scenes). Returns a JSON-ready dict with per-level statistics.
    """
    from grazing_control.dynamics.orbits import one_one

    if kind not in LEVELS:
        raise ValueError(f"kind={kind!r} is invalid: valid values are {', '.join(LEVELS)}")
    q = p.with_(delta_d=delta_d)
    target = one_one.orbit(q, gains).state
    starts = attractor_states(q, seeds, transient=transient)
    rows = []
    for level in levels:
        models = [FaultModel(**{kind: float(level)}, seed=i) for i in range(seeds)]
        res = capture_statistics(q, gains, target, starts, models, horizon=horizon, tail=tail,
                                 threshold=threshold, hold=hold, first_sample=transient,
                                 executor=executor)
        t = res.times[~np.isnan(res.times)]
        sp = res.spread[~np.isnan(res.spread)]
        rows.append({
            "level": float(level),
            "capture_probability": res.captured,
            "capture_time_median": float(np.median(t)) if t.size else None,
            "spread_median": float(np.median(sp)) if sp.size else None,
            "spread_p10": float(np.quantile(sp, 0.1)) if sp.size else None,
            "spread_p90": float(np.quantile(sp, 0.9)) if sp.size else None,
            "failed_runs": int(np.sum(np.isnan(res.spread))),
            "spread_predicted": predicted_spread(q, gains, kind, float(level), target),
        })
    return {"delta_d": delta_d, "kind": kind, "c1": gains.c1, "c2": gains.c2,
            "actuation_delay": gains.delay, "target": list(target), "seeds": seeds,
            "horizon": horizon, "tail": tail, "threshold": threshold, "hold": hold, "rows": rows}

"""Is the fitted model the right one? Residual whiteness, re-simulation, the verdict
(docs/theory_identification.md, "Poor fit").

A least-squares fit always returns numbers; a wrong model (a soft wall, a nonlinear
spring, a bias) shows in what is left over:

* whiteness: with the right model the position residuals are the sensor's noise, white;
  a model error leaves a smooth, correlated misfit. The lag-1 autocorrelation rho of the
  residuals of consecutive samples of one arc, over N pairs, is N(0, 1/N) for white
  noise: |rho| sqrt(N) > :data:`WHITENESS_LIMIT` says the model is wrong (unless the
  residuals are at rounding: a noise-free exact fit);
* re-simulation: the identified model, with its own impact detection
  (:func:`grazing_control.oscillator.impact.advance`), simulated for one forcing period
  from the fitted state at each arc's first sample, against the recorded positions: its
  RMS error over the fit's noise estimate is about 1 with the right model;
* the fitted values: a restitution outside (0, 1) or a damping ratio outside (0, 1) is
  no oscillator of this kind;
* the solver converged.
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.dynamics.simulation.simulate import states_between
from grazing_control.oscillator.flow import to_deviation
from grazing_control.oscillator.impact import advance
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.identification.model import free_flight

__all__ = ["WHITENESS_LIMIT", "RESIMULATION_LIMIT", "whiteness", "resimulate", "verdict",
           "suspects"]

#: Largest |rho| sqrt(N) of the residuals' lag-1 autocorrelation of a good fit (5 sigma).
WHITENESS_LIMIT = 5.0
#: Largest ratio of the one-period re-simulation's RMS error to the noise estimate.
RESIMULATION_LIMIT = 10.0
#: Residuals below this fraction of the motion's size are rounding: an exact fit.
ROUNDING = 1e-9


def whiteness(ident) -> dict:
    """Lag-1 autocorrelation of the position residuals within arcs (module docstring)."""
    prob = ident.problem
    r = prob.residual(ident.solution)[:prob.rec.t.size]
    arc = prob.arcs.sample_arc
    same = arc[1:] == arc[:-1]
    a, b = r[:-1][same], r[1:][same]
    n = int(a.size)
    denom = float(np.sqrt((a @ a) * (b @ b)))
    rho = float(a @ b) / denom if denom > 0 else 0.0
    return {"lag1_autocorrelation": rho, "pairs": n, "z": rho * math.sqrt(max(n, 1))}


def suspects(ident, usual: str) -> str:
    """The whiteness reason's list of suspects: ``usual``, and with corrections in the
    recording a force pulse or actuator other than the one modelled (the parameter
    record's; docs/theory_identification.md section 12)."""
    if ident.problem.rec.corrections.size == 0:
        return usual
    act = getattr(ident.problem, "actuator", None)
    modelled = (f"pulse_width {act.width:g}, tau_a {act.time_constant:g}, latency "
                f"{act.latency:g}" if act is not None else "kicks")
    return (f"{usual} corrections that acted otherwise than modelled ({modelled}): "
            "pulse_width, actuator_bandwidth, actuator_latency in the parameter record?")


def _arc_state(ident, k, tt):
    """The fitted state of arc k at times tt (:func:`.model.free_flight`)."""
    prob = ident.problem
    g, S, X, V = prob.unpack(ident.solution)
    zeta, Om, A, th = g[:4]
    om = prob.omega
    return free_flight(zeta, Om, A, om, om * S[k] + prob.tau0 + th, tt - S[k], X[k], V[k])


def resimulate(ident, *, windows: int = 100) -> dict:
    """One forcing period of the identified model from the fitted state at the first
    sample of (up to ``windows``, evenly spread) arcs, against the recorded positions
    (module docstring). RMS and largest error, in the recording's units."""
    m = ident.model
    try:
        p = m.nondimensional()
    except ParameterError as exc:
        return {"windows": 0, "rms": math.nan, "max": math.nan, "error": str(exc)}
    prob = ident.problem
    rec = prob.rec
    Om, A = m.natural_frequency, m.forcing_amplitude
    L = A / Om ** 2
    T = 2.0 * math.pi / m.omega
    starts = prob.unpack(ident.solution)[1]
    corrections = starts[prob.arcs.kind == 2]
    act = getattr(prob, "actuator", None)
    if act is not None:        # the model re-simulated free: from the input's onsets on
        corrections = act.onsets
    arcs = np.unique(prob.arcs.sample_arc)
    if arcs.size > windows:
        arcs = arcs[np.linspace(0, arcs.size - 1, windows).astype(int)]
    errs = []
    used = 0
    for k in arcs:
        first = int(np.searchsorted(rec.t, starts[k], side="left"))
        while first < rec.t.size and prob.arcs.sample_arc[first] != k:
            first += 1
        if first >= rec.t.size:
            continue
        t0 = rec.t[first]
        if act is not None and np.any((act.onsets < t0) & (act.onsets + act.reach > t0)):
            continue           # a command's force still acts there
        later = corrections[corrections > t0]
        t1 = min(t0 + T, later[0] if later.size else np.inf, rec.t[-1])
        sel = np.flatnonzero((rec.t > t0) & (rec.t <= t1))
        if sel.size == 0:
            continue
        x0, v0 = (float(np.real(u)) for u in _arc_state(ident, k, t0))
        tau = (m.omega * t0 + m.tau0 + m.forcing_phase) % (2.0 * math.pi)
        dx, dv = to_deviation(p, tau, x0 / L, v0 / (L * Om))
        if dx - p.delta_d - (x0 / L - p.d) > 0 and x0 / L > p.d:   # started beyond the wall
            dx -= x0 / L - p.d
        try:
            seg = advance(p, tau, dx, dv, Om * (t1 - t0))
        except Exception:   # noqa: BLE001 - a state the model refuses is a failed check
            errs.append(np.full(sel.size, np.inf))
            continue
        out = states_between(p, tau, dx, dv, seg.impacts, Om * (rec.t[sel] - t0))
        errs.append(out[:, 0] * L - rec.x[sel])
        used += 1
    e = np.concatenate(errs) if errs else np.zeros(0)
    return {"windows": used, "samples": int(e.size),
            "rms": float(np.sqrt(np.mean(e ** 2))) if e.size else math.nan,
            "max": float(np.max(np.abs(e))) if e.size else math.nan}


def verdict(ident) -> dict:
    """The checks (module docstring) and the verdict: ``good`` or ``poor`` with reasons."""
    m = ident.model
    white = whiteness(ident)
    resim = resimulate(ident)
    scale = m.forcing_amplitude / m.natural_frequency ** 2 if m.natural_frequency > 0 else 1.0
    rounding = ident.rms_x <= ROUNDING * max(scale, abs(m.d), 1e-300)
    floor = max(ident.sigma, ROUNDING * max(scale, abs(m.d)))
    ratio = resim["rms"] / floor if floor > 0 else math.inf
    reasons = []
    if not ident.converged:
        reasons.append(f"the least-squares solver did not converge ({ident.message})")
    if not 0.0 < m.r < 1.0:
        reasons.append(f"the fitted restitution r = {m.r:.6g} is outside (0, 1)")
    if not 0.0 < m.zeta < 1.0:
        reasons.append(f"the fitted damping ratio zeta = {m.zeta:.6g} is outside (0, 1)")
    if not rounding and abs(white["z"]) > WHITENESS_LIMIT:
        reasons.append(f"the residuals are not white: lag-1 autocorrelation "
                       f"{white['lag1_autocorrelation']:.3f} over {white['pairs']} pairs "
                       f"({abs(white['z']):.1f} sigma > {WHITENESS_LIMIT:g}): the motion is not "
                       "this model's ("
                       + suspects(ident, "soft wall? nonlinear spring? sensor bias?") + ")")
    if not (ratio <= RESIMULATION_LIMIT):
        reasons.append(f"the re-simulated model misses the recording: one-period RMS error "
                       f"{resim['rms']:.3g} = {ratio:.3g} x the noise estimate "
                       f"(limit {RESIMULATION_LIMIT:g})")
    return {"fit": "poor" if reasons else "good", "reasons": reasons, "whiteness": white,
            "resimulation": dict(resim, ratio_to_noise=ratio)}

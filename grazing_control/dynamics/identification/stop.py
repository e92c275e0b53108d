"""Which stop the data support: rigid, Kelvin-Voigt, or Kelvin-Voigt with friction (issue 31
part 4; docs/theory_contact.md section 17).

The data are the Pi2 samples z_k = (x - x**, v - v**) of a scene before the correction,
and the corrections dv_k applied on Pi2 (Eq. 28; 0 where none). Each candidate stop gives
the period map P_theta, and

    z_{k+1} = P_theta(z_k + (0, dv_k)) + e_k,

with e_k the scene's noise between samples (sim_node's ``noise``: a Gaussian velocity
kick at each sample). With e_k Gaussian of one variance sigma^2 over both components the
maximum-likelihood theta is the least-squares one (scipy.optimize.least_squares), the
likelihood concentrated in sigma is -2 log L = N log(RSS / N) + const (N = 2 n
residuals), and the standard errors are sqrt(diag(sigma^2 (J^T J)^-1)) at the optimum
(J the residuals' Jacobian, sigma^2 = RSS / (N - p)). The model the data support is the
one of least BIC = N log(RSS / N) + p log N (Schwarz 1978): a parameter more must lower
-2 log L by more than log N; friction, nested in Kelvin-Voigt at F_f = 0, must also pass
the likelihood-ratio test at 0.1 % (:func:`select_stop`). The candidates:

* ``rigid``: the study's wall, theta = (r,) (the exact flow of dynamics.simulation.fidelity);
* ``kelvin_voigt``: theta = (k_c, c_c), :func:`~grazing_control.oscillator.contact.compliant_period_step`;
* ``kelvin_voigt_friction``: theta = (k_c, c_c, F_f), with F_s = F_f.

The oscillator's own parameters are fitted with the stop (``oscillator="fit"``, the
default): zeta, omega (the forcing frequency over the natural one), the forcing
amplitude A and phase theta (behind the phase at which the samples are taken), and
Delta d (:data:`OSCILLATOR_NAMES`), every candidate's parameter vector being these five
and its stop's, the standard errors from the joint Jacobian (so a stop's error carries
the oscillator's uncertainty). This is multiple shooting with the Pi2 samples as the
nodes: one shooting interval per period, the contact phases (the stop's regions, stick
phases) inside the exact period map, the samples in the recording's units (x = A x~,
x~ the model's). ``oscillator="known"`` holds them at the given parameters and fits the
stop alone. The fits start from ``start_oscillator`` (default ``p``'s; A = 1, theta =
0): the rigid one there; Kelvin-Voigt from the best of three starts run jointly for
:data:`START_NFEV` evaluations (the stop alone fitted at the given oscillator, and a grid
in log10 k_c = 1 ... 8 at the contact damping ratio of the rigid fit's r, Eq. C3, at
the given and at the rigid fit's oscillator); friction from the Kelvin-Voigt fit; k_c
at most K_MAX. The fit is local: checked from starts off the truth, not proved global
(docs/theory_contact.md section 17).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.contact import (Coulomb, KelvinVoigt, compliant_period_step,
                                                kelvin_voigt_damping, load_compiled)
from grazing_control.oscillator.flow import particular
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.fidelity import period_step

__all__ = ["STOPS", "OSCILLATOR_NAMES", "StopFit", "fit_stop", "select_stop"]

#: the candidate stops, cheapest first
STOPS = ("rigid", "kelvin_voigt", "kelvin_voigt_friction")
#: the oscillator's parameters fitted with the stop (``oscillator="fit"``)
OSCILLATOR_NAMES = ("zeta", "omega", "forcing_amplitude", "forcing_phase", "delta_d")
_NAMES = {"rigid": ("r",), "kelvin_voigt": ("stiffness", "damping"),
          "kelvin_voigt_friction": ("stiffness", "damping", "friction")}
#: a residual where the candidate's map refuses the state (a state deep in the stop)
_REFUSED = 1.0
#: the likelihood-ratio threshold for friction: the 0.1 % point of 0.5 chi2_0 + 0.5 chi2_1
#: (F_f = 0 on the bound; chi2_1's 0.2 % point, 9.5495)
LR_FRICTION = 9.5495
#: the stiffest stop fitted (the chart's end, docs/theory_contact.md section 15): a rigid
#: motion drives k_c there, where the compliant period is within ~1e-4 of the rigid one
K_MAX = 1e8
#: evaluations of each start of a joint compliant fit (:func:`_start`): enough to tell
#: a start that converges from one that does not, at a fraction of a fit's cost
START_NFEV = 12


class StopFit(NamedTuple):
    """One candidate's fit: its parameters and standard errors by name (the oscillator's
    too where fitted), the residual sum of squares, the number of residuals N, -2 log L
    (concentrated) and BIC."""

    stop: str
    values: dict
    stderr: dict
    rss: float
    n: int
    minus_2_log_l: float
    bic: float


def _oscillator(frame: OscillatorParams, osc, r: float) -> OscillatorParams:
    """The model of the oscillator's parameters ``osc`` (:data:`OSCILLATOR_NAMES`) with
    its Pi2 at the samples' phase: the forcing phase there is frame.tau2 + theta."""
    zeta, omega, _a, theta, delta_d = osc
    p = OscillatorParams(zeta=zeta, r=r, omega=omega, delta_d=delta_d)
    offset = (frame.tau2 + theta - p.tau_star) % (2.0 * math.pi)
    return p.with_(pi2_offset=offset if offset > 0.0 else 2.0 * math.pi)


def _predict(frame: OscillatorParams, stop: str, theta, osc, s, dv) -> np.ndarray:
    """The next sample of each sample ``s`` (n x 2, the recording's units) and correction
    ``dv``: x = A x~ (module docstring)."""
    out = np.empty((len(dv), 2))
    law = friction = None
    if stop != "rigid":
        law = KelvinVoigt(theta[0], theta[1])
        if stop == "kelvin_voigt_friction" and theta[2] > 0.0:
            friction = Coulomb(theta[2])
    try:
        p = _oscillator(frame, osc, theta[0] if stop == "rigid" else frame.r)
    except ParameterError:
        return np.full((len(dv), 2), np.nan)
    a = osc[2]
    xp, vp = particular(p, p.tau2)
    for k, ((x, v), c) in enumerate(zip(s, dv)):
        dx, dvk = x / a - xp, v / a - vp
        try:
            if law is None:
                seg = period_step(p, dx, dvk, c / a)
                out[k] = seg.dx, seg.dv
            else:
                seg = compliant_period_step(p, law, dx, dvk, c / a, friction=friction)
                out[k] = seg.x, seg.v
        except (ValueError, ArithmeticError):
            out[k] = np.nan
    return a * (out + (xp, vp))


def _residuals(frame, stop, theta, osc, s, dv) -> np.ndarray:
    pred = _predict(frame, stop, theta, osc, s[:-1], dv[:-1])
    res = (s[1:] - pred).ravel()
    return np.where(np.isfinite(res), res, _REFUSED)


def _bounds(stop: str):
    if stop == "rigid":
        return [1e-6], [1.0 - 1e-9]
    lo, hi = [1e-3, 0.0], [K_MAX, np.inf]
    if stop == "kelvin_voigt_friction":
        lo.append(0.0)
        hi.append(np.inf)
    return lo, hi


#: bounds of the oscillator's parameters (:data:`OSCILLATOR_NAMES`)
_OSC_LO = [1e-6, 1e-3, 1e-12, -math.pi, -np.inf]
_OSC_HI = [1.0 - 1e-6, np.inf, np.inf, math.pi, np.inf]


def _valid(theta, zeta: float) -> bool:
    k, c = theta[0], theta[1]
    return c < 2.0 * math.sqrt(k) and (2.0 * zeta + c) ** 2 < 4.0 * (1.0 + k)


def _start_oscillator(start: OscillatorParams, frame: OscillatorParams) -> list:
    """The oscillator's start (:data:`OSCILLATOR_NAMES`): ``start``'s, A = 1, and the
    forcing phase theta that puts ``start``'s Pi2 at the samples' phase."""
    theta = math.remainder(start.tau2 - frame.tau2, 2.0 * math.pi)
    return [start.zeta, start.omega, 1.0, theta, start.delta_d]


def fit_stop(p: OscillatorParams, stop: str, z, dv, start=None, *,
             oscillator: str = "fit", start_oscillator=None, known=None,
             max_nfev: int | None = None) -> StopFit:
    """The least-squares (maximum-likelihood) fit of one candidate stop to the Pi2
    samples ``z`` (n x 2, deviations from ``p``'s X** before the correction) and
    corrections ``dv`` (n), with the oscillator's parameters (``oscillator="fit"``) or
    at ``p``'s (``"known"``). ``p`` also gives the samples' frame (their phase tau2 and
    X**); ``start``: the stop's start, ``start_oscillator``: the oscillator's (a list
    in :data:`OSCILLATOR_NAMES` order, default ``p``'s); ``known``: fits made already
    {stop: StopFit}, the cheaper candidates' that start this one (:func:`_start`)."""
    from scipy.optimize import least_squares

    if stop not in STOPS:
        raise ParameterError(f"stop={stop!r} is invalid: valid values are {', '.join(STOPS)}")
    if oscillator not in ("fit", "known"):
        raise ParameterError(f"oscillator={oscillator!r} is invalid: valid values are fit, "
                             "known")
    z = np.asarray(z, dtype=float)
    dv = np.asarray(dv, dtype=float)
    if z.ndim != 2 or z.shape[1] != 2 or len(z) < 8 or dv.shape != (len(z),):
        raise ParameterError("samples are invalid: expected at least 8 Pi2 samples (n x 2) "
                             "and as many corrections")
    s = z + (p.x_ref, p.v_ref)          # the recorded states
    if stop != "rigid":
        load_compiled()   # thousands of flows: the compiled bracketing, the same floats
    osc0 = list(start_oscillator) if start_oscillator is not None else \
        _start_oscillator(p, p)
    joint = oscillator == "fit"
    if start is None:
        start, osc0 = _start(p, stop, z, dv, osc0, joint, known)
    lo, hi = _bounds(stop)
    q_osc = len(OSCILLATOR_NAMES) if joint else 0
    if joint:
        lo, hi = _OSC_LO + lo, _OSC_HI + hi
        x0 = list(osc0) + list(start)
    else:
        x0 = list(start)

    def split(x):
        return (x[:q_osc], x[q_osc:]) if joint else (osc0, x)

    def fun(x):
        osc, theta = split(x)
        if stop != "rigid" and not _valid(theta, osc[0]):
            return np.full(2 * (len(z) - 1), _REFUSED)
        return _residuals(p, stop, theta, osc, s, dv)

    sol = least_squares(fun, np.clip(x0, lo, hi), bounds=(lo, hi), x_scale="jac",
                        method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                        max_nfev=max_nfev or (200 if joint else 100))
    res = sol.fun
    n, q = res.size, len(sol.x)
    rss = float(res @ res)
    sigma2 = rss / max(n - q, 1)
    try:
        cov = sigma2 * np.linalg.inv(sol.jac.T @ sol.jac)
        se = np.sqrt(np.abs(np.diag(cov)))
    except np.linalg.LinAlgError:
        se = np.full(q, math.inf)
    m2ll = n * math.log(max(rss, 1e-300) / n)
    names = (OSCILLATOR_NAMES if joint else ()) + _NAMES[stop]
    return StopFit(stop, dict(zip(names, map(float, sol.x))), dict(zip(names, map(float, se))),
                   rss, n, m2ll, m2ll + q * math.log(n))


def _start(p, stop, z, dv, osc0, joint, known=None):
    """(the stop's start, the oscillator's) of a candidate (module docstring);
    ``known``: the fits made already {stop: StopFit} (select_stop's, not made again)."""
    mode = "fit" if joint else "known"
    known = {} if known is None else known
    if stop == "rigid":
        return [p.r], osc0
    base = "kelvin_voigt" if stop.endswith("friction") else "rigid"
    prev = known.get(base) or fit_stop(p, base, z, dv, oscillator=mode,
                                        start_oscillator=osc0, known=known)
    start_osc = osc0
    if joint:
        osc0 = [prev.values[n] for n in OSCILLATOR_NAMES]
    if stop.endswith("friction"):
        return [prev.values["stiffness"], prev.values["damping"], 1e-3], osc0
    s = z + (p.x_ref, p.v_ref)
    zeta_c = kelvin_voigt_damping(min(max(prev.values["r"], 0.14), 1.0))

    thetas = [[10.0 ** lk, 2.0 * zeta_c * 10.0 ** (lk / 2)] for lk in range(1, 9)]

    def grid(osc):          # the best k_c of the grid at this oscillator
        res = [_residuals(p, stop, theta, osc, s, dv) for theta in thetas]
        return thetas[int(np.argmin([float(r @ r) for r in res]))]

    if not joint:
        return grid(osc0), osc0
    given = grid(start_osc)  # once: it starts the stop alone and is a start itself
    # the rigid fit's oscillator is biased where the stop is compliant, and its grid
    # points at a rigid-like k_c (K_MAX, flat), from where a joint fit does not come
    # back; a grid at an oscillator that is off can point anywhere (docs section 17).
    # Three starts, each run jointly for START_NFEV evaluations, the best continued:
    # the stop alone fitted at the given oscillator (where that is close), and the grid
    # at the given and at the rigid fit's oscillator
    alone = fit_stop(p, stop, z, dv, given, oscillator="known", start_oscillator=start_osc)
    starts = [([alone.values[n] for n in _NAMES[stop]], start_osc),
              (given, start_osc), (grid(osc0), osc0)]
    fits = [fit_stop(p, stop, z, dv, theta, start_oscillator=osc, max_nfev=START_NFEV)
            for theta, osc in starts]
    best = min(fits, key=lambda f: f.rss)
    return [best.values[n] for n in _NAMES[stop]], [best.values[n] for n in OSCILLATOR_NAMES]


def select_stop(p: OscillatorParams, z, dv, stops=STOPS, *, oscillator: str = "fit",
                start_oscillator=None) -> tuple:
    """(the stop the data support, its fit, every candidate's fit) for the Pi2 samples
    (``oscillator``, ``start_oscillator``: :func:`fit_stop`).

    Rigid against Kelvin-Voigt by least BIC (not nested: the rigid wall is the limit
    k_c -> inf); friction only where the likelihood-ratio statistic of Kelvin-Voigt
    against Kelvin-Voigt with friction, -2 log L(KV) + 2 log L(KV+F), exceeds
    :data:`LR_FRICTION` (F_f = 0 is on the bound of its range: the statistic is then
    distributed as the mixture 0.5 chi2_0 + 0.5 chi2_1, whose 0.1 % point this is), and
    friction's BIC is also the least: BIC alone admits a friction that is not there
    about 1.4 % of the time at 60 periods (seen once on a recorded bag, F_f = 2e-5 at
    2.3 standard errors, docs/theory_contact.md section 17)."""
    fits = {}
    for s in STOPS:                   # cheapest first: each starts the next (_start)
        if s in stops:
            fits[s] = fit_stop(p, s, z, dv, oscillator=oscillator,
                               start_oscillator=start_oscillator, known=fits)
    base = min((f for s, f in fits.items() if s != "kelvin_voigt_friction"),
               key=lambda f: f.bic, default=None)
    best = base
    friction = fits.get("kelvin_voigt_friction")
    if friction is not None:
        kv = fits.get("kelvin_voigt")
        lr = math.inf if kv is None else kv.minus_2_log_l - friction.minus_2_log_l
        if base is None or (lr > LR_FRICTION and friction.bic < base.bic):
            best = friction
    return best.stop, best, list(fits.values())

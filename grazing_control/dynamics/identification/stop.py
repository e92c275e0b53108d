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

The oscillator's own parameters (zeta, omega, Delta d, ...) are taken as known (from
``grazing identify``'s fit of the free flight, or the scene's file): what is selected is
the stop. The compliant fits start from a grid in log10 k_c (1 ... 7) at the contact
damping ratio of the rigid fit's r (Eq. C3), the best start refined, k_c at most K_MAX.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.contact import (Coulomb, KelvinVoigt, compliant_period_step,
                                                kelvin_voigt_damping)
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.fidelity import period_step

__all__ = ["STOPS", "StopFit", "fit_stop", "select_stop"]

#: the candidate stops, cheapest first
STOPS = ("rigid", "kelvin_voigt", "kelvin_voigt_friction")
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


class StopFit(NamedTuple):
    """One candidate's fit: its parameters and standard errors by name, the residual sum
    of squares, the number of residuals N, -2 log L (concentrated) and BIC."""

    stop: str
    values: dict
    stderr: dict
    rss: float
    n: int
    minus_2_log_l: float
    bic: float


def _predict(p: OscillatorParams, stop: str, theta, z0, dv) -> np.ndarray:
    out = np.empty((len(dv), 2))
    law = friction = None
    if stop != "rigid":
        law = KelvinVoigt(theta[0], theta[1])
        if stop == "kelvin_voigt_friction" and theta[2] > 0.0:
            friction = Coulomb(theta[2])
    else:
        p = p.with_(r=theta[0])
    for k, ((dx, dvk), c) in enumerate(zip(z0, dv)):
        try:
            if law is None:
                seg = period_step(p, dx, dvk, c)
                out[k] = seg.dx, seg.dv
            else:
                seg = compliant_period_step(p, law, dx, dvk, c, friction=friction)
                out[k] = seg.x, seg.v
        except (ValueError, ArithmeticError):
            out[k] = np.nan
    return out


def _residuals(p, stop, theta, z, dv) -> np.ndarray:
    pred = _predict(p, stop, theta, z[:-1], dv[:-1])
    res = (z[1:] - pred).ravel()
    return np.where(np.isfinite(res), res, _REFUSED)


def _bounds(stop: str, zeta: float):
    if stop == "rigid":
        return [1e-6], [1.0 - 1e-9]
    lo, hi = [1e-3, 0.0], [K_MAX, np.inf]
    if stop == "kelvin_voigt_friction":
        lo.append(0.0)
        hi.append(np.inf)
    return lo, hi


def _valid(theta, zeta: float) -> bool:
    k, c = theta[0], theta[1]
    return c < 2.0 * math.sqrt(k) and (2.0 * zeta + c) ** 2 < 4.0 * (1.0 + k)


def fit_stop(p: OscillatorParams, stop: str, z, dv, start=None) -> StopFit:
    """The least-squares (maximum-likelihood) fit of one candidate stop to the Pi2
    samples ``z`` (n x 2, deviations before the correction) and corrections ``dv`` (n)."""
    from scipy.optimize import least_squares

    if stop not in STOPS:
        raise ParameterError(f"stop={stop!r} is invalid: valid values are {', '.join(STOPS)}")
    z = np.asarray(z, dtype=float)
    dv = np.asarray(dv, dtype=float)
    if z.ndim != 2 or z.shape[1] != 2 or len(z) < 8 or dv.shape != (len(z),):
        raise ParameterError("samples are invalid: expected at least 8 Pi2 samples (n x 2) "
                             "and as many corrections")
    if start is None:
        start = _start(p, stop, z, dv)
    lo, hi = _bounds(stop, p.zeta)

    def fun(theta):
        if stop != "rigid" and not _valid(theta, p.zeta):
            return np.full(2 * (len(z) - 1), _REFUSED)
        return _residuals(p, stop, theta, z, dv)

    sol = least_squares(fun, np.clip(start, lo, hi), bounds=(lo, hi), x_scale="jac",
                        method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=100)
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
    names = _NAMES[stop]
    return StopFit(stop, dict(zip(names, map(float, sol.x))), dict(zip(names, map(float, se))),
                   rss, n, m2ll, m2ll + q * math.log(n))


def _start(p, stop, z, dv):
    if stop == "rigid":
        return [p.r]
    r = fit_stop(p, "rigid", z, dv).values["r"]
    zeta_c = kelvin_voigt_damping(min(max(r, 0.14), 1.0))
    best = None
    for lk in range(1, 9):
        k = 10.0 ** lk
        theta = [k, 2.0 * zeta_c * math.sqrt(k)] + ([0.0] if stop.endswith("friction") else [])
        res = _residuals(p, stop, theta, z, dv)
        rss = float(res @ res)
        if best is None or rss < best[0]:
            best = (rss, theta)
    if stop.endswith("friction"):
        base = fit_stop(p, "kelvin_voigt", z, dv)
        best = (0.0, [base.values["stiffness"], base.values["damping"], 1e-3])
    return best[1]


def select_stop(p: OscillatorParams, z, dv, stops=STOPS) -> tuple:
    """(the stop the data support, its fit, every candidate's fit) for the Pi2 samples.

    Rigid against Kelvin-Voigt by least BIC (not nested: the rigid wall is the limit
    k_c -> inf); friction only where the likelihood-ratio statistic of Kelvin-Voigt
    against Kelvin-Voigt with friction, -2 log L(KV) + 2 log L(KV+F), exceeds
    :data:`LR_FRICTION` (F_f = 0 is on the bound of its range: the statistic is then
    distributed as the mixture 0.5 chi2_0 + 0.5 chi2_1, whose 0.1 % point this is), and
    friction's BIC is also the least: BIC alone admits a friction that is not there
    about 1.4 % of the time at 60 periods (seen once on a recorded bag, F_f = 2e-5 at
    2.3 standard errors, docs/theory_contact.md section 17)."""
    fits = {s: fit_stop(p, s, z, dv) for s in stops}
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

"""Model fidelities for one forcing period on Pi2, and the choice of the cheapest adequate one.

"Model no more than a scene needs." One period from a Pi2 sample (deviation z, after
the correction dv) can be computed by

* ``exact``: the closed-form flow with certified impact detection
  (:func:`grazing_control.oscillator.impact.advance`);
* ``zdm2`` / ``zdm1``: the normal-form map of docs/theory_zdm.md: the smooth flow to
  Pi1, the second- (leading-) order discontinuity map there, the smooth flow back to
  Pi2: z' = Phi(s) D(Phi(T - s) z), s = pi2_offset / omega. Valid while the only impacts
  are low-velocity ones near tau*; its error per period is O(H^1.5) (O(H)) in the
  penetration H of the virtual motion;
* ``ode``: scipy's solve_ivp (DOP853, event location, restart at each impact) in physical
  coordinates, for comparison only, never chosen automatically.

:func:`choose_fidelity` picks the cheapest of exact, zdm2, zdm1 whose estimated error
over the scene's horizon meets a tolerance, and says why (docs/theory_zdm.md,
"Fidelity choice"): it runs a short exact probe of the scene, measures each map's
one-period error against the exact period on the probe's own samples (the local error
eps), estimates the growth of errors from the exact monodromies of the probe (the
geometric mean L of their spectral norms), and bounds the error after N periods by
eps * (1 + L + ... + L^(N-1)). It is an estimate calibrated on the scene, not a proof.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from grazing_control.oscillator.flow import (amplitude_bound, to_deviation, to_physical,
                                             transition_matrix)
from grazing_control.oscillator.impact import Impact, Segment, advance, check_state
from grazing_control.oscillator.kernel import exact_advance
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.zdm import local_grazing, zdm_event

__all__ = ["FIDELITIES", "period_step", "FidelityChoice", "choose_fidelity",
           "ModelValidityError", "zdm_window", "ZDM_WINDOW"]

#: Largest half-width |psi| (rad) of the phase window around tau* in which a ZDM period
#: may have contacts (docs/theory_zdm.md, "Validity of the maps").
ZDM_WINDOW = 0.5


class ModelValidityError(ValueError):
    """A map fidelity (zdm1, zdm2) does not apply to this state or these parameters."""

#: Fidelities, cheapest model first among the maps; 'ode' is a comparison path.
FIDELITIES = ("exact", "zdm2", "zdm1", "ode")
_AUTO_CANDIDATES = ("zdm1", "zdm2", "exact")  # cheapest first

TWO_PI = 2.0 * math.pi


def _check(fidelity):
    if fidelity not in FIDELITIES:
        raise ValueError(f"fidelity={fidelity!r} is invalid: valid values are "
                         f"{', '.join(FIDELITIES)} (or 'auto' where a scene is given)")


def zdm_window(p: OscillatorParams, amplitude: float) -> float:
    """Half-width psi_c of the phases where a deviation of amplitude |C| can touch the wall.

    The gap is g = z_x - Delta d - 2 a sin^2(psi / 2) with |z_x| <= |C|, so a contact
    needs 2 a sin^2(psi / 2) <= |C| - Delta d: |psi| <= psi_c = 2 asin(sqrt((|C| -
    Delta d) / (2 a))), and -1 (no contact anywhere) when |C| <= Delta d.
    """
    excess = amplitude - p.delta_d
    if excess < 0.0:
        return -1.0
    return 2.0 * math.asin(min(1.0, math.sqrt(excess / (2.0 * p.amplitude))))


def _zdm_check(p: OscillatorParams, amplitude: float, where: str, order: int) -> None:
    """Refuse a ZDM period whose contacts are not confined near tau*, away from Pi2."""
    psi_c = zdm_window(p, amplitude)
    if psi_c < 0.0:
        return
    if psi_c > ZDM_WINDOW or not psi_c < p.pi2_offset < TWO_PI - psi_c:
        raise ModelValidityError(
            f"zdm{order} does not apply: the deviation {where} (amplitude {amplitude:.3g}, "
            f"Delta d = {p.delta_d:.3g}) can touch the wall within {psi_c:.3g} rad of tau*; "
            f"the map needs contacts within {ZDM_WINDOW} rad of tau* and clear of Pi2 "
            f"(pi2_offset = {p.pi2_offset:.3g}); use fidelity exact")


def _zdm_period(p: OscillatorParams, dx: float, dv: float, order: int) -> Segment:
    """Normal-form period on Pi2: Phi(s) D(Phi(T - s) z), with the grazing impact it implies.

    Refused (:class:`ModelValidityError`) where the map does not apply: grazing not
    regular (alpha <= 0, Eq. 3), or a deviation before or after the impact large enough
    to touch the wall outside a window of ZDM_WINDOW rad around tau* or at Pi2 (a sample
    beyond the wall), see :func:`zdm_window`.
    """
    try:
        local_grazing(p)
    except ValueError as exc:
        raise ModelValidityError(f"zdm{order} does not apply: {exc}") from None
    _zdm_check(p, amplitude_bound(p.zeta, dx, dv), "on Pi2", order)
    s = p.pi2_offset / p.omega
    f11, f12, f21, f22 = transition_matrix(p.zeta, p.period - s)
    zx, zv, t1, v_minus = zdm_event(p, (f11 * dx + f12 * dv, f21 * dx + f22 * dv), order)
    if t1 is not None:
        _zdm_check(p, amplitude_bound(p.zeta, zx, zv), "after the impact", order)
    impacts = []
    if t1 is not None:
        t_imp = p.period - s + t1
        impacts.append(Impact(t_imp, (p.tau2 + p.omega * t_imp) % TWO_PI, v_minus, -p.r * v_minus))
    f11, f12, f21, f22 = transition_matrix(p.zeta, s)
    return Segment(f11 * zx + f12 * zv, f21 * zx + f22 * zv, impacts, None)


def _ode_period(p: OscillatorParams, dx: float, dv: float, rtol: float) -> Segment:
    """One period by solve_ivp (DOP853) with a terminal wall event and restarts."""
    from scipy.integrate import solve_ivp

    tau0, d, w, zeta, r = p.tau2, p.d, p.omega, p.zeta, p.r

    def rhs(t, y):
        return (y[1], math.cos(w * t + tau0) - 2.0 * zeta * y[1] - y[0])

    def wall(t, y):
        return y[0] - d

    wall.terminal, wall.direction = True, 1.0
    y = list(to_physical(p, tau0, dx, dv))
    t, end, impacts = 0.0, p.period, []
    while True:
        sol = solve_ivp(rhs, (t, end), y, method="DOP853", rtol=rtol, atol=rtol * 1e-3,
                        events=wall)
        hits = [(te, ye) for te, ye in zip(sol.t_events[0], sol.y_events[0]) if te > t + 1e-12 * end]
        if sol.status == 1 and hits:
            te, ye = hits[0]
            impacts.append(Impact(te, (tau0 + w * te) % TWO_PI, ye[1], -r * ye[1]))
            t, y = te, [d, -r * ye[1]]
            if len(impacts) > 10000:
                raise RuntimeError("ode fidelity: more than 10000 impacts in one period")
            continue
        y = sol.y[:, -1]
        break
    zx, zv = to_deviation(p, tau0 + w * end, y[0], y[1])
    return Segment(zx, zv, impacts, None)


def period_step(p: OscillatorParams, dx: float, dv: float, dv_correction: float = 0.0,
                fidelity: str = "exact", *, rtol: float = 1e-9) -> Segment:
    """One forcing period from a Pi2 sample with the given model fidelity.

    ``exact`` is :func:`grazing_control.dynamics.simulation.simulate.period_step` itself; the maps return
    the impact their discontinuity map implies (time, phase and velocity to the map's
    order); ``rtol`` is solve_ivp's tolerance for ``ode``.
    """
    _check(fidelity)
    dv = dv + dv_correction
    check_state(dx, dv, p.zeta, "the Pi2 state after the correction")
    if fidelity == "exact":
        return exact_advance()(p, p.tau2, dx, dv, p.period)
    if fidelity == "zdm2":
        return _zdm_period(p, dx, dv, 2)
    if fidelity == "zdm1":
        return _zdm_period(p, dx, dv, 1)
    return _ode_period(p, dx, dv, rtol)


@dataclass(frozen=True)
class FidelityChoice:
    """The chosen fidelity, the reason in words, and the estimates behind it.

    ``estimates`` maps each candidate to (seconds per period, local error per period,
    estimated error over the horizon).
    """

    fidelity: str
    reason: str
    growth: float
    estimates: dict = field(default_factory=dict)


def choose_fidelity(p: OscillatorParams, periods: int, tol: float, *, deviation=(0.0, 0.0),
                    gains=None, control_after=None, probe: int = 40) -> FidelityChoice:
    """The cheapest fidelity whose estimated Pi2 error over ``periods`` is <= ``tol``.

    Parameters
    ----------
    p : OscillatorParams
    periods : int
        Horizon N of the scene (forcing periods), >= 1.
    tol : float
        Tolerance on the Pi2 state error at the end of the horizon, > 0.
    deviation : (float, float)
        The scene's initial Pi2 state as (x - x**, v - v**).
    gains, control_after
        The scene's controller, as for :func:`grazing_control.dynamics.simulation.simulate.simulate`.
    probe : int
        Periods of the exact probe run (calibration), >= 2.
    """
    if not (isinstance(periods, int) and periods >= 1):
        raise ValueError(f"periods={periods!r} is invalid: valid range is an integer >= 1")
    if not (math.isfinite(tol) and tol > 0.0):
        raise ValueError(f"tol={tol!r} is invalid: valid range is a finite tol > 0")
    if probe < 2:
        raise ValueError(f"probe={probe!r} is invalid: valid range is probe >= 2")
    dx, dv = deviation
    samples, log_norms, t_exact = [], [], 0.0
    for k in range(probe):
        dvc = 0.0
        if gains is not None and control_after is not None and k >= control_after:
            dvc = gains.c1 * dx + gains.c2 * dv
        samples.append((dx, dv, dvc))
        t0 = time.perf_counter()
        seg = advance(p, p.tau2, dx, dv + dvc, p.period, monodromy=True)
        t_exact += time.perf_counter() - t0
        m = np.array(seg.monodromy).reshape(2, 2)
        if gains is not None and dvc != 0.0:
            m = m @ np.array([[1.0, 0.0], [gains.c1, 1.0 + gains.c2]])
        log_norms.append(math.log(max(np.linalg.norm(m, 2), 1e-300)))
        dx, dv = seg.dx, seg.dv
    growth = math.exp(float(np.mean(log_norms)))
    amplification = (periods if abs(growth - 1.0) < 1e-12
                     else (growth ** periods - 1.0) / (growth - 1.0) if growth < 1.0 or
                     periods * math.log(growth) < 700 else math.inf)
    exact_cost = t_exact / probe
    estimates = {"exact": (exact_cost, 4.0 * np.finfo(float).eps * (1.0 + abs(p.v_ref)),
                           None)}
    refused = {}
    for fid in ("zdm2", "zdm1"):
        err, cost = 0.0, 0.0
        try:
            for sx, sv, dvc in samples:
                t0 = time.perf_counter()
                approx = period_step(p, sx, sv, dvc, fid)
                cost += time.perf_counter() - t0
                ref = advance(p, p.tau2, sx, sv + dvc, p.period)
                err = max(err, abs(approx.dx - ref.dx), abs(approx.dv - ref.dv))
        except ModelValidityError as exc:
            refused[fid] = str(exc)
            err = math.inf
        estimates[fid] = (cost / len(samples), err, None)
    estimates = {k: (c, e, e * amplification) for k, (c, e, _b) in estimates.items()}
    for fid in _AUTO_CANDIDATES:
        cost, local, bound = estimates[fid]
        if fid == "exact" and refused:
            why = (f"exact: the maps do not apply to this scene ({'; '.join(refused.values())}); "
                   f"{cost * 1e6:.0f} us per period")
            return FidelityChoice("exact", why, growth, estimates)
        if bound <= tol:
            why = (f"{fid}: local error {local:.2g} per period, growth factor {growth:.3g} over "
                   f"{periods} periods -> estimated error {bound:.2g} <= tol {tol:g}; "
                   f"{cost * 1e6:.0f} us per period")
            cheaper = [f"{k} ({estimates[k][2]:.2g} > tol)" for k in _AUTO_CANDIDATES
                       if k != fid and estimates[k][0] < cost]
            if cheaper:
                why += "; rejected cheaper " + ", ".join(cheaper)
            return FidelityChoice(fid, why, growth, estimates)
    cost, local, bound = estimates["exact"]
    why = (f"exact: no model meets tol {tol:g} over {periods} periods (growth factor "
           f"{growth:.3g} per period amplifies even rounding to {bound:.2g}); exact is the "
           "most accurate available")
    return FidelityChoice("exact", why, growth, estimates)

"""The cheapest adequate stop for a scene: rigid, compliant, or compliant with friction
(issue 31 part 4; docs/theory_contact.md section 18).

The scene's stop is given in full (a Kelvin-Voigt law and, optionally, Coulomb
friction). The candidates, cheapest first: ``rigid`` (the wall with the stop's
restitution r of Eq. C3: the study's exact flow, about 6x cheaper than the compliant
one, docs/benchmarks.md), ``compliant`` (the law without the friction) and
``compliant_friction`` (the full model, the reference). As :func:`.fidelity.choose_fidelity`
does for the maps: a probe of ``probe`` periods of the full model from the scene's
start, each candidate's one-period error eps on the probe's own samples (against the
full model's period), the growth L of errors from the probe's Jacobians (central
differences of the full map, :class:`.compliant_model.CompliantOneDOF`; the geometric
mean of their spectral norms), and the error after N periods bounded by
eps (1 + L + ... + L^(N-1)); the cheapest candidate whose bound is within ``tol`` is
chosen, with the reason. An estimate calibrated on the scene, not a proof.

:func:`simulate_stop` runs a scene on the chosen model (``grazing simulate --contact``):
``auto`` the cheapest adequate one, or the user's choice, checked against the same
bound (a warning with the numbers where it exceeds the tolerance).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, compliant_period_step
from grazing_control.oscillator.impact import check_state
from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.simulation.simulate import SimulationResult, simulate

__all__ = ["STOP_FIDELITIES", "StopFidelity", "choose_stop_fidelity", "rigid_stand_in",
           "simulate_stop", "simulate_stop_choice"]

STOP_FIDELITIES = ("rigid", "compliant", "compliant_friction")


class StopFidelity(NamedTuple):
    """The chosen stop, why, and each candidate's (one-period error, bound over N)."""

    stop: str
    reason: str
    estimates: dict


def rigid_stand_in(p, law: KelvinVoigt):
    """The rigid wall a Kelvin-Voigt stop stands for: ``p`` with the stop's restitution
    r (Eq. C3)."""
    return p.with_(r=min(law.restitution, 1.0 - 1e-12))


def choose_stop_fidelity(p, law: KelvinVoigt, friction: Coulomb | None, periods: int,
                         tol: float, *, deviation=(0.0, 0.0), gains=None,
                         probe: int = 20) -> StopFidelity:
    """The cheapest stop whose estimated Pi2 error over ``periods`` is <= ``tol``
    (module docstring). ``gains``: the scene's controller from the first sample."""
    if not (isinstance(periods, int) and periods >= 1):
        raise ValueError(f"periods={periods!r} is invalid: valid range is an integer >= 1")
    if not (math.isfinite(tol) and tol > 0.0):
        raise ValueError(f"tol={tol!r} is invalid: valid range is a finite tol > 0")
    full = CompliantOneDOF(p, gains, law=law, friction=friction)
    candidates = {"rigid": OneDOF(rigid_stand_in(p, law), gains),
                  "compliant": dataclasses.replace(full, friction=None)}
    z = np.array(deviation, dtype=float)
    samples, log_norms = [], []
    for _ in range(probe):
        step = full.step(z, jacobian=True)
        samples.append((z, step.state))
        log_norms.append(math.log(max(np.linalg.norm(step.jacobian, 2), 1e-300)))
        z = step.state
    growth = math.exp(float(np.mean(log_norms)))
    amplification = (periods if abs(growth - 1.0) < 1e-12 else
                     (growth ** periods - 1.0) / (growth - 1.0)
                     if growth < 1.0 or periods * math.log(growth) < 700 else math.inf)
    estimates = {}
    for name, model in candidates.items():
        err = 0.0
        for z0, ref in samples:
            try:
                err = max(err, float(np.max(np.abs(model.step(z0).state - ref))))
            except (ValueError, ArithmeticError):
                err = math.inf
        estimates[name] = (err, err * amplification)
    estimates["compliant_friction"] = (0.0, 0.0)
    if friction is None:
        estimates.pop("compliant_friction")
    for name in STOP_FIDELITIES:
        if name in estimates and estimates[name][1] <= tol:
            break
    reason = (f"{name}: estimated Pi2 error {estimates[name][1]:.3g} <= tol {tol:.3g} over "
              f"{periods} periods (one-period error {estimates[name][0]:.3g} on a "
              f"{probe}-period probe of the full stop, growth {growth:.3g})")
    cheaper = [n for n in STOP_FIDELITIES[:STOP_FIDELITIES.index(name)] if n in estimates]
    if cheaper:
        reason += "; " + ", ".join(f"{n} refused ({estimates[n][1]:.3g})" for n in cheaper)
    return StopFidelity(name, reason, estimates)


def simulate_stop(p, law: KelvinVoigt, friction: Coulomb | None, periods: int, *,
                  deviation=(0.0, 0.0), gains=None, control_after: int | None = 0,
                  stop: str = "auto", tol: float = 1e-3) -> tuple:
    """(SimulationResult, StopFidelity, warning or None): the scene of ``periods``
    periods from the Pi2 ``deviation`` on the stop model ``stop`` (``auto``: the cheapest
    adequate for ``tol``, :func:`choose_stop_fidelity`; else one of
    :data:`STOP_FIDELITIES`, checked against the same bound: the warning gives the
    numbers where it exceeds ``tol``). ``rigid`` is :func:`.simulate.simulate` on
    :func:`rigid_stand_in` (the exact flow), the compliant ones
    :func:`~grazing_control.oscillator.contact.compliant_period_step` with the
    correction on Pi2 (Eq. 28) from sample ``control_after`` on. The bound's probe has
    the scene's controller where it acts from the first sample, else none (a probe of
    20 periods; the controller's later start is not in it)."""
    active = gains is not None and control_after is not None
    if active and gains.delay != 0.0:
        raise ValueError(f"delay={gains.delay!r} is invalid with a compliant stop: the "
                         "compliant map takes the correction on Pi2 only (delay 0)")
    choice, warning = simulate_stop_choice(
        p, law, friction, periods, deviation=deviation,
        gains=gains if active and control_after == 0 else None, stop=stop, tol=tol)
    stop = choice.stop
    if stop == "rigid":
        res = simulate(rigid_stand_in(p, law), periods, deviation=deviation, gains=gains,
                       control_after=control_after)
        res.fidelity_reason = f"stop {choice.reason}; the exact flow of the rigid wall"
        return res, choice, warning
    return (_compliant_scene(p, law, friction if stop == "compliant_friction" else None,
                             periods, deviation, gains if active else None, control_after,
                             f"stop {choice.reason}"), choice, warning)


def simulate_stop_choice(p, law: KelvinVoigt, friction: Coulomb | None, periods: int, *,
                         deviation=(0.0, 0.0), gains=None, stop: str = "auto",
                         tol: float = 1e-3) -> tuple:
    """(StopFidelity, warning or None): ``auto`` the cheapest adequate stop model for the
    scene (:func:`choose_stop_fidelity`), or the model ``stop`` names with its bound
    checked against ``tol`` (the warning says by how much it exceeds it, and which model
    is adequate); ``gains``: the controller from the first sample (None: the probe runs
    uncontrolled)."""
    if stop != "auto" and stop not in STOP_FIDELITIES:
        raise ValueError(f"stop={stop!r} is invalid: valid values are auto, "
                         f"{', '.join(STOP_FIDELITIES)}")
    if stop == "compliant_friction" and friction is None:
        raise ValueError("stop='compliant_friction' is invalid without friction: give a "
                         "friction > 0 or choose compliant")
    choice = choose_stop_fidelity(p, law, friction, max(periods, 1), tol,
                                  deviation=deviation, gains=gains)
    if stop == "auto":
        return choice, None
    bound = choice.estimates[stop][1]
    reason = (f"{stop}: requested; its estimated Pi2 error {bound:.3g} over {periods} "
              f"periods against the full stop")
    warning = None
    if not bound <= tol:
        warning = (f"stop model {stop} is not adequate for this scene: its estimated Pi2 "
                   f"error {bound:.3g} exceeds tol {tol:.3g} over {periods} periods "
                   f"(one-period error {choice.estimates[stop][0]:.3g}); the cheapest "
                   f"adequate is {choice.stop}")
        reason += f" exceeds tol {tol:.3g} (the cheapest adequate: {choice.stop})"
    else:
        reason += f" <= tol {tol:.3g}"
    return choice._replace(stop=stop, reason=reason), warning


def _compliant_scene(p, law, friction, periods, deviation, gains, control_after,
                     reason) -> SimulationResult:
    """The Pi2 loop of :func:`.simulate.simulate` on the compliant period map."""
    dx, dv = float(deviation[0]), float(deviation[1])
    check_state(dx, dv, p.zeta, "the initial state")
    dev = np.empty((periods, 2))
    corr = np.zeros(periods)
    counts = np.zeros(periods, dtype=int)
    imps = []
    for k in range(periods):
        dev[k] = dx, dv
        if gains is not None and k >= control_after:
            corr[k] = gains.c1 * dx + gains.c2 * dv
        seg = compliant_period_step(p, law, dx, dv, corr[k], friction=friction)
        counts[k] = len(seg.contacts)
        imps.extend((k, k * p.period + c.dt, c.phase, c.v_minus, c.v_plus)
                    for c in seg.contacts)
        dx, dv = seg.x, seg.v
    return SimulationResult(p, gains, control_after if gains is not None else None,
                            dev + np.array([p.x_ref, p.v_ref]), dev, corr, counts,
                            np.array(imps, dtype=float).reshape(-1, 5), (dx, dv),
                            "exact", reason)

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
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.maps.model import OneDOF

__all__ = ["STOP_FIDELITIES", "StopFidelity", "choose_stop_fidelity"]

STOP_FIDELITIES = ("rigid", "compliant", "compliant_friction")


class StopFidelity(NamedTuple):
    """The chosen stop, why, and each candidate's (one-period error, bound over N)."""

    stop: str
    reason: str
    estimates: dict


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
    candidates = {"rigid": OneDOF(p.with_(r=min(law.restitution, 1.0 - 1e-12)), gains),
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

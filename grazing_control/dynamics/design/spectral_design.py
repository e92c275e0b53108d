"""Gains by the multipliers of the model itself: the least spectral radius of the
controlled orbit (issue 31, part 3; docs/theory_contact.md section 15).

The rigid design (:mod:`.design`, Eq. 38) cancels the square-root singularity of the
rigid grazing map; a compliant stop has no such singularity (Eqs. C7, C9), so its
degenerate condition has nothing to cancel, and where the rigid gains fail on the
compliant plant the design is made on that plant's own map: over any
:class:`~.model.PeriodMap` with gain parameters ``c1`` and ``c2``, the gains that minimise
the largest |multiplier| of its controlled 1/1 orbit,

    min over (c1, c2) of  rho(c1, c2) = max |eig DP(z*(c1, c2))|,   P(z*) = z*,

with the orbit found by Newton shooting (:func:`.shooting.find_periodic`, from the last
orbit found) and the minimum by Nelder-Mead (scipy.optimize.minimize: rho is
continuous but not smooth where two multipliers meet, the usual case at a minimum of a
spectral radius). Where the orbit is not found the objective is +inf.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize

from grazing_control.dynamics.orbits.shooting import ShootingFailed, find_periodic

__all__ = ["SpectralDesign", "spectral_radius", "least_spectral_radius"]


class SpectralDesign(NamedTuple):
    """The gains found, the spectral radius there and at the start, the orbit's state,
    and the number of orbits shot."""

    c1: float
    c2: float
    rho: float
    rho_start: float
    state: np.ndarray
    evaluations: int


def spectral_radius(model, guess) -> tuple[float, np.ndarray]:
    """(largest |multiplier|, state) of the model's 1/1 orbit near ``guess``."""
    orbit = find_periodic(model, guess)
    return float(np.max(np.abs(np.linalg.eigvals(orbit.monodromy)))), orbit.state


def least_spectral_radius(model, guess, *, xatol: float = 1e-4,
                          max_evaluations: int = 200) -> SpectralDesign:
    """The (c1, c2) minimising the spectral radius of ``model``'s controlled 1/1 orbit,
    from the model's own gains (the start: the rigid design, say) and the orbit near
    ``guess``. The model must have the parameters ``c1`` and ``c2``."""
    c1, c2 = model.parameter("c1"), model.parameter("c2")
    rho0, state0 = spectral_radius(model, guess)
    last = {"state": np.array(state0)}
    count = [1]

    def objective(k):
        count[0] += 1
        trial = model.with_parameter("c1", float(k[0])).with_parameter("c2", float(k[1]))
        try:
            rho, state = spectral_radius(trial, last["state"])
        except (ShootingFailed, ValueError, ArithmeticError):
            return math.inf
        if rho < 1.0:
            last["state"] = state
        return rho

    res = minimize(objective, [c1, c2], method="Nelder-Mead",
                   options={"xatol": xatol, "fatol": 1e-6, "maxfev": max_evaluations,
                            "initial_simplex": [[c1, c2], [c1 + 0.2, c2], [c1, c2 + 0.2]]})
    best = model.with_parameter("c1", float(res.x[0])).with_parameter("c2", float(res.x[1]))
    rho, state = spectral_radius(best, last["state"])
    return SpectralDesign(float(res.x[0]), float(res.x[1]), rho, rho0, state, count[0])

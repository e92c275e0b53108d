"""The multipliers of a model file's 1/1 orbit against Delta d, and their growth exponent
(the study of docs/ndof_commands.md, "Near grazing": |lambda| ~ |Delta d|^p, p = -1,
-1/2, -1/4 or bounded); each orbit by the one entry of the 1/1 orbit
(:mod:`grazing_control.dynamics.orbits.one_one`)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.orbits.orbits import OrbitNotFound

__all__ = ["Scaling", "multiplier_scaling", "fit_exponent"]


class Scaling(NamedTuple):
    """Multipliers of the 1/1 orbit on a grid of Delta d (rows in grid order; nan where
    no orbit was found, with the reason in ``errors``)."""

    delta_d: np.ndarray
    multipliers: np.ndarray
    v_minus: np.ndarray
    errors: tuple

    @property
    def largest(self) -> np.ndarray:
        return np.max(np.abs(self.multipliers), axis=1)


def multiplier_scaling(model, gains, deltas, delay: float = 0.0) -> Scaling:
    """The multipliers of the 1/1 orbit born at grazing at each Delta d of ``deltas`` (each
    by the one entry :func:`grazing_control.dynamics.orbits.one_one.orbit`, the previous
    point's orbit tried after the prediction); another 1/1 orbit (not
    :attr:`~grazing_control.dynamics.orbits.one_one.Orbit11.near_grazing`) counts as not
    found. The kick acts ``delay`` after the sample (docs/theory_ndof.md §14)."""
    deltas = np.asarray(deltas, dtype=float).reshape(-1)
    n2 = 2 * model.n
    lam = np.full((deltas.size, n2), np.nan, dtype=complex)
    vm = np.full(deltas.size, np.nan)
    errors = []
    prev = None
    for j, dd in enumerate(deltas):
        extra = () if prev is None else (("previous point", prev),)
        try:
            o = one_one.orbit(model, gains, dd, extra_guesses=extra, delay=delay)
        except (OrbitNotFound, ValueError) as exc:
            errors.append(str(exc))
            prev = None
            continue
        if not o.near_grazing:
            errors.append(f"the 1/1 orbit found at delta_d={dd!r} is not the one born at "
                          f"grazing (v- = {o.v_minus:.3g}, {o.prediction_offset:.3g} away "
                          "from the local map's prediction)")
            prev = None
            continue
        lam[j], vm[j] = o.multipliers, o.v_minus
        prev = o.state
        errors.append("")
    return Scaling(deltas, lam, vm, tuple(errors))


def fit_exponent(delta_d, values) -> float:
    """Least-squares slope of log|values| against log|Delta d| (the growth exponent:
    -1/2 for |lambda| ~ |Delta d|^(-1/2)); nan with fewer than two finite points."""
    x = np.log(np.abs(np.asarray(delta_d, dtype=float)))
    y = np.log(np.abs(np.asarray(values, dtype=float)))
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 2:
        return math.nan
    return float(np.polyfit(x[ok], y[ok], 1)[0])

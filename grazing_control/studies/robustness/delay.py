"""Robustness of the degenerate design to the actuation delay (docs/theory_delay.md, 6).

Gains designed for a delay delta_a (c1 = c1(c2; delta_a), Eq. (D5)) act, in the real
loop, at some other delay delta. Then N_g,12(delta) != 0 and the singular multiplier of
the 1/1 orbit is back: it grows like 1/|Delta d| as Delta d -> 0-, so the interval of
delays where the orbit is stable shrinks onto delta_a as the wall approaches grazing.
This module measures that on the exact 1/1 orbit (:func:`grazing_control.dynamics.orbits.one_one.orbit`
with the delayed kick, saltation at the impact) and, for comparison, with the
perturbation series (:func:`grazing_control.dynamics.maps.perturbation.perturbation_multipliers`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1, max_design_delay
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.orbits.orbits import OrbitNotFound
from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["largest_multiplier", "multiplier_curve", "stability_interval", "StabilityMap",
           "stability_map", "design_gains"]


def design_gains(p: OscillatorParams, c2: float, design_delay: float) -> Gains:
    """(c1(c2; design_delay), c2): the degenerate gains for a delay (Eq. (D5)), no delay set."""
    return Gains(degenerate_c1(p, c2, design_delay), c2)


def largest_multiplier(p: OscillatorParams, gains: Gains, delay: float) -> float:
    """max |lambda| of the 1/1 orbit at ``p.delta_d`` with ``gains`` acting ``delay`` after Pi2.

    nan where no 1/1 orbit born at grazing exists at this Delta d (the
    branch left the impacting side, or the kick falls after the impact: delay >= T - sigma);
    orbits of other 1/1 branches are not the near-grazing motion of the design.
    """
    g = Gains(gains.c1, gains.c2, delay)
    try:
        orbit = one_one.orbit(p, g, branch="grazing")
    except (OrbitNotFound, ValueError):
        return math.nan
    return float(np.max(np.abs(orbit.multipliers)))


def multiplier_curve(p: OscillatorParams, gains: Gains, delays) -> np.ndarray:
    """:func:`largest_multiplier` over an array of actual delays."""
    return np.array([largest_multiplier(p, gains, float(d)) for d in delays])


def stability_interval(p: OscillatorParams, gains: Gains, around: float, lo: float = 0.0,
                       hi: float | None = None, n: int = 201):
    """The interval of actual delays, containing ``around``, where the 1/1 orbit is stable.

    Scans [lo, hi] (default hi just below T - s) on n points plus ``around``, then refines
    each end by Brent's method on max|lambda| - 1 where the orbit exists on both sides
    (else the end is where the orbit stops existing, to the grid's resolution, and the
    flag says so). Returns (start, end, (start_kind, end_kind)) with kinds 'multiplier',
    'no orbit' or 'range'; None if the orbit at ``around`` is not stable.
    """
    hi = math.nextafter(max_design_delay(p), 0.0) if hi is None else hi
    if not lo <= around <= hi:
        raise ParameterError(f"around={around!r} is invalid: valid range is [{lo!r}, {hi!r}]")
    grid = np.union1d(np.linspace(lo, hi, n), [around])
    vals = multiplier_curve(p, gains, grid)
    k0 = int(np.searchsorted(grid, around))
    if not vals[k0] < 1.0:
        return None

    def f(d):
        return largest_multiplier(p, gains, d) - 1.0

    def end(k, step):
        while 0 <= k + step < grid.size and vals[k + step] < 1.0:
            k += step
        if not 0 <= k + step < grid.size:
            return float(grid[k]), "range"
        a, b = grid[k], grid[k + step]
        if math.isnan(vals[k + step]):
            return float(0.5 * (a + b)), "no orbit"
        return float(brentq(f, min(a, b), max(a, b), xtol=1e-12)), "multiplier"

    (start, ks), (stop, ke) = end(k0, -1), end(k0, 1)
    return start, stop, (ks, ke)


@dataclass(frozen=True)
class StabilityMap:
    """max|lambda| of the 1/1 orbit over a (c2, delay) grid, for one design rule.

    design : 'delayed' (c1 = c1(c2; delay), the gains designed for the actual delay) or
    'undelayed' (c1 = c1(c2; 0), today's design acting at the delay).
    values[i, j] is for c2s[j] and delays[i]; nan where no 1/1 orbit exists there.
    """

    delta_d: float
    design: str
    c2s: np.ndarray
    delays: np.ndarray
    values: np.ndarray


def _map_row(args):
    p, design, delay, c2s = args
    row = []
    for c2 in c2s:
        try:
            g = design_gains(p, c2, delay if design == "delayed" else 0.0)
        except ParameterError:
            row.append(math.nan)
            continue
        row.append(largest_multiplier(p, g, delay))
    return row


def stability_map(p: OscillatorParams, design: str, c2s, delays, workers: int = 1) -> StabilityMap:
    """:class:`StabilityMap` at ``p.delta_d`` for design 'delayed' or 'undelayed'."""
    if design not in ("delayed", "undelayed"):
        raise ValueError(f"design={design!r} is invalid: valid values are 'delayed', 'undelayed'")
    c2s, delays = np.asarray(c2s, dtype=float), np.asarray(delays, dtype=float)
    jobs = [(p, design, float(d), c2s) for d in delays]
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=workers) as ex:
            rows = list(ex.map(_map_row, jobs))
    else:
        rows = [_map_row(j) for j in jobs]
    return StabilityMap(p.delta_d, design, c2s, delays, np.array(rows))

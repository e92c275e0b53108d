"""The result of a basin grid: the attractor of every start, the attractors, the files."""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.params import OscillatorParams
from grazing_control.studies.sweeps.result import write_npz
from .attractors import Attractor

__all__ = ["BasinResult", "attractor_colors"]

_FORMAT = "grazing_control.basins/1"

#: Colours of the periodic attractors: 0/1 and 1/1 keep theirs in every picture, the
#: others take the rest in order; chaotic motions light grey, failed starts black.
_FIXED = {"0/1": "#2ca02c", "1/1": "#1f77b4"}
_CYCLE = ("#ff7f0e", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#bcbd22", "#17becf",
          "#7f7f7f", "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5")
_SPECIAL = {"chaotic": "#c7c7c7", "failed": "#000000"}


def attractor_colors(attractors) -> list:
    """One colour (hex) per attractor, as the picture and the summary give them."""
    out, k = [], 0
    for a in attractors:
        if a.kind != "periodic":
            out.append(_SPECIAL[a.kind])
        elif a.label in _FIXED:
            out.append(_FIXED[a.label])
        else:
            out.append(_CYCLE[k % len(_CYCLE)])
            k += 1
    return out


@dataclass(frozen=True)
class BasinResult:
    """The attractor reached from each start of a grid on Pi2.

    Grids are (nv, nx): x - x** along a row (``xs``), v - v** down the rows (``vs``).

    Attributes
    ----------
    params : OscillatorParams
    xs, vs : (nx,), (nv,) the starts' deviations from X** on Pi2.
    attractor : (nv, nx) int, index into ``attractors`` of each start's attractor.
    period : (nv, nx) int, detected period (0 none, -1 failed).
    mean_impacts : (nv, nx) float, impacts per period over the record.
    final : (nv, nx, 2) the last recorded sample (deviation; nan when failed).
    errors : (nv, nx) str, the failure of a start ('' when it ran).
    attractors : tuple of :class:`.attractors.Attractor`.
    c1, c2, delay, control_after : the controller (nan, nan, 0, -1: uncontrolled).
    transient, max_period, period_tol, match_tol, engine : how it was run; the record
        after the transient is 2 max_period samples.
    """

    params: OscillatorParams
    xs: np.ndarray
    vs: np.ndarray
    attractor: np.ndarray
    period: np.ndarray
    mean_impacts: np.ndarray
    final: np.ndarray
    errors: np.ndarray
    attractors: tuple
    c1: float
    c2: float
    delay: float
    control_after: int
    transient: int
    max_period: int
    period_tol: float
    match_tol: float
    engine: str = ""

    @property
    def n_starts(self) -> int:
        return int(self.attractor.size)

    @property
    def controlled(self) -> bool:
        return not math.isnan(self.c2)

    @property
    def reference(self) -> tuple:
        """X** = (x**, v**): physical Pi2 point = deviation + X**."""
        return (self.params.x_ref, self.params.v_ref)

    def fractions(self) -> list:
        """Fraction of the starts that reach each attractor (sums to 1)."""
        return [a.starts / self.n_starts for a in self.attractors]

    def summary(self) -> dict:
        """The JSON summary: parameters, grid, and per attractor its label, kind, cycle
        (deviation and physical Pi2 points), starts, fraction and colour."""
        x_ref, v_ref = self.reference
        colors = attractor_colors(self.attractors)
        rows = []
        for a, f, c in zip(self.attractors, self.fractions(), colors):
            row = {"label": a.label, "kind": a.kind, "period": a.period, "impacts": a.impacts,
                   "starts": a.starts, "slow_starts": a.slow, "fraction": f, "color": c,
                   "first_start": [float(self.xs[a.first % self.xs.size]),
                                   float(self.vs[a.first // self.xs.size])]}
            if a.kind == "periodic":
                row["cycle_deviation"] = a.points.tolist()
                row["cycle_pi2"] = (a.points + [x_ref, v_ref]).tolist()
            if a.kind == "failed":
                row["first_error"] = str(self.errors.flat[a.first])
            rows.append(row)
        p = self.params
        return {
            "format": _FORMAT,
            "params": {f.name: getattr(p, f.name) for f in dataclasses.fields(p)},
            "delta_d": p.delta_d,
            "controller": None if not self.controlled else {
                "c1": self.c1, "c2": self.c2, "delay": self.delay,
                "control_after": self.control_after},
            "reference_pi2": [x_ref, v_ref],
            "grid": {"dx_range": [float(self.xs[0]), float(self.xs[-1])],
                     "dv_range": [float(self.vs[0]), float(self.vs[-1])],
                     "nx": int(self.xs.size), "nv": int(self.vs.size),
                     "starts": self.n_starts},
            "transient": self.transient, "record": 2 * self.max_period,
            "max_period": self.max_period, "period_tol": self.period_tol,
            "match_tol": self.match_tol, "engine": self.engine,
            "attractors": rows,
        }

    def to_npz(self, path) -> None:
        """Every grid and the attractors' table in an uncompressed npz (plain numpy), the
        summary's JSON as ``meta``; equal results give byte-identical files."""
        arrays = {"xs": self.xs, "vs": self.vs, "attractor": self.attractor,
                  "period": self.period, "mean_impacts": self.mean_impacts,
                  "final": self.final, "errors": self.errors,
                  "meta": np.array(json.dumps(self.summary(), sort_keys=True)),
                  "attractor_label": np.array([a.label for a in self.attractors]),
                  "attractor_kind": np.array([a.kind for a in self.attractors]),
                  "attractor_period": np.array([a.period for a in self.attractors]),
                  "attractor_impacts": np.array([a.impacts for a in self.attractors]),
                  "attractor_starts": np.array([a.starts for a in self.attractors]),
                  "attractor_slow": np.array([a.slow for a in self.attractors])}
        for j, a in enumerate(self.attractors):
            arrays[f"attractor_points_{j}"] = a.points
        write_npz(path, arrays)

    def same_as(self, other: "BasinResult") -> bool:
        """Bitwise equality of every grid and attractor (the local-against-Dask check)."""
        grids = ("xs", "vs", "attractor", "period", "mean_impacts", "final", "errors")
        return (self.params == other.params
                and all(np.array_equal(getattr(self, g), getattr(other, g),
                                       equal_nan=g != "errors") for g in grids)
                and len(self.attractors) == len(other.attractors)
                and all(_same_attractor(a, b) for a, b in zip(self.attractors, other.attractors))
                and json.dumps(self.summary()) == json.dumps(other.summary()))


def _same_attractor(a: Attractor, b: Attractor) -> bool:
    return ((a.label, a.kind, a.period, a.impacts, a.starts, a.first, a.slow)
            == (b.label, b.kind, b.period, b.impacts, b.starts, b.first, b.slow)
            and np.array_equal(a.points, b.points, equal_nan=True))

"""Basins of attraction on Pi2 and the attractors that coexist (issue 18, section 3).

Public API::

    basins(params, *, dx_range=None, dv_range=None, nx=101, nv=101, gains=None,
           control_after=None, transient=2000, max_period=64, period_tol=1e-10,
           match_tol=None, workers=None, scheduler=None, engine="auto",
           progress=False) -> BasinResult
    default_box(params) -> (dx_range, dv_range)
    orbit_scale(params) -> float   (the 1/1 orbit's distance from X** at -|Delta d|)
    identify(records, counts, period, match_tol) -> (index, attractors)
    picture(result, out, name="basins") -> [png, svg]

A grid of starts (x - x**, v - v**) on Pi2 runs through the sweep's runner
(:mod:`grazing_control.studies.sweeps`: the compiled kernel or the Python core, local
processes or a Dask cluster, identical results); each start is classified by the
attractor its motion reaches after the transient: n/p (n impacts in p periods: 0/1,
1/1, 2/2, ...), ``chaotic`` (no period up to max_period) or ``failed``; attractors are
identified across starts by their cycles' points (:mod:`.attractors`). The command:
``grazing basins`` (docs/basins.md).
"""

from .attractors import Attractor, canonical_cycle, cycle_distance, identify, reduced_period
from .plot import picture
from .result import BasinResult, attractor_colors
from .run import basins, default_box, orbit_scale

__all__ = ["basins", "default_box", "orbit_scale", "identify", "picture", "BasinResult", "Attractor",
           "attractor_colors", "cycle_distance", "canonical_cycle", "reduced_period"]

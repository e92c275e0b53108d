"""Running a basin grid: starts on Pi2 through the sweep's runner, then the attractors.

The starts are the sweep's starts (:func:`grazing_control.studies.sweeps.sweep` with one
grid point and an (n, 2) array of deviations), so a basin runs on the compiled kernel or
the pure-Python core, in this process, on local processes or on a Dask cluster exactly
as a sweep does, with the same chunking, the same failures per start and the same period
detection; each start runs ``transient`` periods and then a record of 2 max_period
samples, on which its period is detected. The records are then grouped by attractor
(:class:`.attractors.Grouping`). Large grids run in blocks of :data:`BLOCK` starts, so
the records held at once stay bounded (one block's, plus a cycle per attractor and per
slow start); blocks do not change the result.
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from .attractors import Grouping
from .result import BasinResult

__all__ = ["BLOCK", "BLOCK_SAMPLES", "MAX_STARTS", "DEFAULT_MAX_PERIOD", "BOX_SCALE", "MATCH_SCALE", "orbit_scale",
           "default_box", "basins"]

#: Starts per call of the sweep runner (records of 2 * max_period samples each), at most;
BLOCK = 16384
#: and at most this many recorded samples per call (~100 MB of records and counts).
BLOCK_SAMPLES = 4 * 1024 * 1024
#: Largest grid accepted (nx * nv).
MAX_STARTS = 4_000_000
#: The sweep's default longest detected period.
DEFAULT_MAX_PERIOD = 64
#: Half-width of the default box in units of the 1/1 orbit's distance from X**.
BOX_SCALE = 4.0


#: The default match_tol in units of the same distance.
MATCH_SCALE = 1e-3


def orbit_scale(params: OscillatorParams) -> float:
    """max(|x - x**|, |v - v**|) of the uncontrolled 1/1 orbit born at grazing
    (:func:`grazing_control.dynamics.orbits.one_one.orbit`) at -|Delta d|: the scale of the
    near-grazing motions on Pi2, which grows like |Delta d| (spec section 2); on the
    non-impacting side the orbit at the mirrored Delta d gives it. ParameterError where
    there is none (Delta d = 0: the orbit is X** itself)."""
    from grazing_control.dynamics.orbits import one_one
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    if params.delta_d == 0.0:
        raise ParameterError("delta_d=0.0 has no default box of starts (the 1/1 orbit is X** "
                             "itself): give dx_range and dv_range (--dx, --dv)")
    try:
        orbit = one_one.orbit(params, None, -abs(params.delta_d), branch="grazing")
    except OrbitNotFound:
        raise ParameterError(f"delta_d={params.delta_d!r} has no 1/1 orbit at -|delta_d| to "
                             "scale the default box of starts: give dx_range and dv_range "
                             "(--dx, --dv)") from None
    return float(np.max(np.abs(orbit.state)))


def default_box(params: OscillatorParams):
    """((dx_lo, dx_hi), (dv_lo, dv_hi)): the default square of starts around X**.

    Centred on X** (the grazing orbit's point, the origin of the deviations), of
    half-width BOX_SCALE times :func:`orbit_scale`. The same box with and without
    control, so that the two pictures compare.
    """
    h = BOX_SCALE * orbit_scale(params)
    return (-h, h), (-h, h)


def _range(name, value):
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}={value!r} is invalid: expected (low, high)") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ParameterError(f"{name}={value!r} is invalid: valid range is finite low < high")
    return lo, hi


def _count(name, value, low, high=None):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low \
            or (high is not None and value > high):
        top = "" if high is None else f" and <= {high}"
        raise ParameterError(f"{name}={value!r} is invalid: valid range is an integer >= {low}"
                             f"{top}")
    return int(value)


def basins(params: OscillatorParams, *, dx_range=None, dv_range=None, nx: int = 101,
           nv: int = 101, gains: Gains | None = None, control_after: int | None = None,
           transient: int = 2000, max_period: int = DEFAULT_MAX_PERIOD,
           period_tol: float = 1e-10, match_tol: float | None = None,
           workers: int | None = None, scheduler=None, engine: str = "auto",
           progress: bool = False) -> BasinResult:
    """The attractor reached from each start of an nx x nv grid on Pi2.

    Parameters
    ----------
    params : OscillatorParams
        The model, Delta d included.
    dx_range, dv_range : (low, high), optional
        The starts' x - x** and v - v** (deviations from X** on Pi2), both ends included;
        default :func:`default_box`.
    nx, nv : int
        Grid points along x and v (>= 1 each, nx * nv <= MAX_STARTS).
    gains : Gains, optional
        The controller of Eq. 28 (with its actuation delay, 0 <= delay < T), on from
        sample ``control_after`` (default 0); None: uncontrolled.
    transient : int
        Periods run before the record (>= 0).
    max_period : int
        Longest period detected (>= 1); the record is 2 max_period samples long.
    period_tol : float
        Tolerance of the period detection (deviation coordinates, > 0).
    match_tol : float, optional
        Largest distance of two cycles of one attractor (:func:`.attractors.cycle_distance`);
        default MATCH_SCALE (1e-3) times :func:`orbit_scale` (without one, at Delta d = 0,
        the box's half-width / BOX_SCALE), at least 10 period_tol.
    workers, scheduler, engine, progress
        As :func:`grazing_control.studies.sweeps.sweep`: local processes (None: all cores,
        1: this process), a Dask address or Client, the kernel or the Python core.

    Returns
    -------
    BasinResult

    Raises
    ------
    ParameterError
        An argument outside its range (the message names it), before anything runs.
    """
    from grazing_control.studies.sweeps import sweep

    if not isinstance(params, OscillatorParams):
        raise ParameterError("params is invalid: expected an OscillatorParams")
    nx = _count("nx", nx, 1)
    nv = _count("nv", nv, 1)
    if nx * nv > MAX_STARTS:
        raise ParameterError(f"nx * nv = {nx * nv} is invalid: valid range is at most "
                             f"{MAX_STARTS} starts")
    transient = _count("transient", transient, 0)
    max_period = _count("max_period", max_period, 1, 100_000)
    if gains is not None and not isinstance(gains, Gains):
        raise ParameterError("gains is invalid: expected a Gains or None")
    if control_after is not None:
        control_after = _count("control_after", control_after, 0)
        if gains is None:
            raise ParameterError("control_after needs the gains: give gains (c1, c2)")
    if not (isinstance(period_tol, (int, float)) and math.isfinite(period_tol)
            and period_tol > 0):
        raise ParameterError(
            f"period_tol={period_tol!r} is invalid: valid range is a finite value > 0")
    if dx_range is None or dv_range is None:
        box = default_box(params)
        dx_range = box[0] if dx_range is None else dx_range
        dv_range = box[1] if dv_range is None else dv_range
    dx_range = _range("dx_range", dx_range)
    dv_range = _range("dv_range", dv_range)
    if match_tol is None:
        try:
            scale = orbit_scale(params)
        except ParameterError:  # Delta d = 0 with a box given: the box's scale
            scale = max(dx_range[1] - dx_range[0], dv_range[1] - dv_range[0]) / (2 * BOX_SCALE)
        match_tol = max(MATCH_SCALE * scale, 10.0 * period_tol)
    elif not (isinstance(match_tol, (int, float)) and math.isfinite(match_tol)
              and match_tol > 0):
        raise ParameterError(
            f"match_tol={match_tol!r} is invalid: valid range is a finite value > 0")
    xs = np.linspace(*dx_range, nx)
    vs = np.linspace(*dv_range, nv)
    grid_x, grid_v = np.meshgrid(xs, vs)   # (nv, nx): x along a row, v down the rows
    starts = np.column_stack([grid_x.ravel(), grid_v.ravel()])
    record = 2 * max_period
    periods = transient + record
    n = starts.shape[0]
    period = np.empty(n, dtype=np.int64)
    mean_impacts = np.empty(n)
    final = np.empty((n, 2))
    errors = np.empty(n, dtype=object)
    grouping = Grouping(match_tol)
    engine_used = ""
    block = min(BLOCK, max(1, BLOCK_SAMPLES // record))
    for lo in range(0, n, block):
        hi = min(n, lo + block)
        res = sweep(params, {"delta_d": [params.delta_d]}, periods=periods, transient=transient,
                    deviation=starts[lo:hi], gains=gains, control_after=control_after,
                    workers=workers, scheduler=scheduler, engine=engine,
                    period_tol=float(period_tol), max_period=max_period, progress=progress)
        grouping.add(res.pi2_deviation, res.impacts_per_period, res.period)
        period[lo:hi] = res.period
        mean_impacts[lo:hi] = res.impacts_per_period.mean(axis=1)
        final[lo:hi] = res.pi2_deviation[:, -1]
        errors[lo:hi] = res.errors
        engine_used = res.engine
    index, attractors = grouping.finish()
    controlled = gains is not None
    return BasinResult(
        params=params, xs=xs, vs=vs, attractor=index.reshape(nv, nx),
        period=period.reshape(nv, nx), mean_impacts=mean_impacts.reshape(nv, nx),
        final=final.reshape(nv, nx, 2), errors=errors.astype(str).reshape(nv, nx),
        attractors=attractors, c1=gains.c1 if controlled else math.nan,
        c2=gains.c2 if controlled else math.nan, delay=gains.delay if controlled else 0.0,
        control_after=(control_after or 0) if controlled else -1, transient=transient,
        max_period=max_period, period_tol=float(period_tol), match_tol=float(match_tol),
        engine=engine_used)

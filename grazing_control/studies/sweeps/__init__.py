"""Parameter sweeps on Pi2: bifurcation diagrams by direct simulation, local or on Dask.

Public API (stable; figures and the ``grazing sweep`` command use it)::

    sweep(params, grid, *, periods, transient, deviation=(0.0, 0.0), gains=None,
          control_after=None, workers=None, scheduler=None, engine="auto",
          period_tol=1e-10, max_period=None, progress=False) -> SweepResult

    grid : dict[str, array_like]   name -> values; names are OscillatorParams fields
        (delta_d, zeta, r, omega, tau0, pi2_offset) or the gains c1, c2. Several names
        span their Cartesian product (first name slowest). A gridded c2 without a gridded c1
        takes c1 from the degenerate condition, Eq. 38, for each c2 (as the CLI does).
    deviation : (dx, dv) or (n_starts, 2) array of starts on Pi2, as (x - x**, v - v**);
        several starts are the last, fastest axis of the points.
    gains, control_after : the controller (Eq. 28) acts at samples k >= control_after;
        control_after=None means 0 when there are gains (and never without). The gains'
        actuation delay (Gains.delay, 0 <= delay < T) is honoured as simulate does: the
        kick acts that long after the sample.
    workers : processes on this machine (None: all cores; 1: in this process).
    scheduler : a Dask scheduler address ("tcp://host:port") or a distributed.Client;
        then the points run on that cluster (identical results to the local run).
    engine : "auto" (the compiled kernel when numba imports), "kernel" or "python"
        (the pure-Python reference core, grazing_control.oscillator.impact).

    SweepResult (frozen dataclass), n = number of points, m = periods - transient:
        names, axes            the grid: names and the values along each axis
        shape                  grid shape + (n_starts,); n = prod(shape)
        points                 dict name -> (n,) value of each gridded name per point
        starts                 (n, 2) start deviation of each point
        pi2                    (n, m, 2) physical Pi2 samples (x, v), before control
        pi2_deviation          (n, m, 2) the same as (x - x**, v - v**) at full precision
        impacts_per_period     (n, m) int
        period                 (n,) int: detected period p >= 1, 0 none (chaos or too
                               slow a transient), -1 the point failed (see ``errors``)
        errors                 (n,) str, '' where the point ran
        c1, c2                 (n,) gains per point (nan: uncontrolled)
        delay                  the actuation delay of the gains (0.0 without)
        to_npz(path), SweepResult.from_npz(path)

Every point is an independent run from its own start (no continuation from the
neighbouring parameter value), so the result does not depend on how the points are
split between processes or Dask workers.
"""

from .period import detect_period
from .result import SweepResult
from .run import GRID_NAMES, sweep

__all__ = ["sweep", "SweepResult", "detect_period", "GRID_NAMES"]

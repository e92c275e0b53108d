"""A sweep of a model file's model (``grazing sweep --model``): the brute-force bifurcation
diagram of one parameter on Pi2 for any n (issue 17, figure (a)).

For each value of one model parameter (``delta_d`` by default) the period map of
:class:`~grazing_control.dynamics.maps.modal_map.ModalMap` is iterated ``periods`` times from a
start on Pi2 and the last ``periods - transient`` samples are kept (deviations from the
grazing orbit, before the kick), with the impacts of each period and the detected
period on Pi2 (:func:`grazing_control.studies.sweeps.period.detect_period`, any
dimension). This is the 1-DOF sweep's algorithm (studies/sweeps/run.py) over the
period-map protocol instead of the compiled 1-DOF kernel: points are independent, so
strided chunks of points go to local processes, or to a Dask cluster when a scheduler
address is given (optional: ``distributed`` is imported only then).
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.oscillator.control import gain_vector
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.params import ParameterError
from .period import detect_period
from .run import _count, local_workers

__all__ = ["MODEL_GRID_NAMES", "NdofDiagram", "diagram", "run_points"]

#: Model parameters a diagram may vary (scalar fields of NdofModel).
MODEL_GRID_NAMES = ("delta_d", "omega", "r", "phase", "pi2_offset")


@dataclass(frozen=True)
class NdofDiagram:
    """The kept Pi2 samples of every point (``samples``: (points, kept, 2n) deviations;
    ``reference``: (points, 2n) the grazing orbit's physical state on Pi2, so that the
    physical samples are ``samples + reference[:, None]``), impacts per kept period,
    detected period (0: none up to max_period, -1: failed) and the failure messages;
    ``delay``: the actuation delay of the kick (0: on Pi2)."""

    name: str
    values: np.ndarray
    coordinates: tuple
    samples: np.ndarray
    reference: np.ndarray
    impacts_per_period: np.ndarray
    period: np.ndarray
    errors: tuple
    periods: int
    transient: int
    control_after: int
    gains: np.ndarray | None
    delay: float = 0.0

    def to_npz(self, path) -> None:
        """Write the arrays (and the settings as 0-d arrays) to an npz file."""
        np.savez_compressed(
            path, name=np.array(self.name), values=self.values,
            coordinates=np.array(self.coordinates), samples=self.samples,
            reference=self.reference, impacts_per_period=self.impacts_per_period,
            period=self.period, errors=np.array(self.errors, dtype=str),
            periods=np.array(self.periods), transient=np.array(self.transient),
            control_after=np.array(self.control_after),
            gains=np.array([]) if self.gains is None else self.gains,
            delay=np.array(self.delay))


def _coordinates(n):
    return tuple(f"x{i}" for i in range(n)) + tuple(f"v{i}" for i in range(n))


def run_points(model, name, values, start, gains, periods, transient, control_after,
               period_tol, max_period, delay=0.0):
    """Run the points ``values`` (one chunk); returns (samples, counts, period, errors).
    The kick acts ``delay`` after each sample while the controller is on (``ModalMap``'s
    exact delayed map, docs/theory_ndof.md §14), as ``grazing simulate --model --delay``."""
    m = periods - transient
    n2 = 2 * model.n
    samples = np.full((len(values), m, n2), np.nan)
    counts = np.zeros((len(values), m), dtype=np.int32)
    period = np.zeros(len(values), dtype=np.int64)
    errors = [""] * len(values)
    for j, value in enumerate(values):
        try:
            mj = dataclasses.replace(model, **{name: float(value)})
            free = ModalMap(mj)
            ctl = ModalMap(mj, gains, delay) if gains is not None and control_after >= 0 \
                else None
            z = np.array(start, dtype=float)
            for k in range(periods):
                pmap = ctl if ctl is not None and k >= control_after else free
                step = pmap.step(z)
                if k >= transient:
                    samples[j, k - transient] = z
                    counts[j, k - transient] = len(step.impacts)
                z = step.state
                if not np.all(np.isfinite(z)):
                    raise ArithmeticError(f"the state is not finite at period {k}")
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            errors[j] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            period[j] = -1
            continue
        period[j] = detect_period(samples[j], period_tol, max_period)
    return samples, counts, period, errors


def diagram(model, values, *, name: str = "delta_d", periods: int, transient: int,
            start=None, gains=None, control_after: int | None = None,
            workers: int | None = None, scheduler=None, period_tol: float = 1e-10,
            max_period: int | None = None, progress: bool = False,
            delay: float = 0.0) -> NdofDiagram:
    """Simulate every value of ``name`` and keep its Pi2 samples after the transient.

    Parameters
    ----------
    model : NdofModel
        The other parameters.
    values : array_like
        Values of ``name`` (one of :data:`MODEL_GRID_NAMES`), finite.
    periods, transient : int
        Periods run per point (>= 1) and dropped first (0 <= transient < periods).
    start : array_like, optional
        Start on Pi2 as a deviation from the grazing orbit (2n values; default 0).
    gains : array_like, optional
        2n gains k of the kick v[i_a] += k^T z; on from sample ``control_after``
        (default 0 when gains are given).
    delay : float
        The kick acts this long after each sample (0 <= delay < T at every point;
        docs/theory_ndof.md §14); ignored without gains.
    workers : int, optional
        Local processes (default: all cores); ignored with ``scheduler``.
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (tcp://HOST:PORT) or client: run the chunks there.
    """
    if name not in MODEL_GRID_NAMES:
        raise ParameterError(f"grid name {name!r} is invalid with --model: valid names are "
                             f"{', '.join(MODEL_GRID_NAMES)}")
    vals = np.atleast_1d(np.asarray(values, dtype=float))
    if vals.ndim != 1 or vals.size == 0 or not np.all(np.isfinite(vals)):
        raise ParameterError(f"values of {name} are invalid: expected a non-empty list of "
                             "finite numbers")
    _count("periods", periods, 1)        # the 1-DOF sweep's checks (run.py)
    _count("transient", transient, 0)
    if not transient < periods:
        raise ParameterError(f"transient={transient!r} is invalid: valid range is 0 <= "
                             f"transient < periods={periods}")
    n2 = 2 * model.n
    z0 = np.zeros(n2) if start is None else np.asarray(start, dtype=float).reshape(-1)
    if z0.shape != (n2,) or not np.all(np.isfinite(z0)):
        raise ParameterError(f"start is invalid: expected {n2} finite values (deviation from "
                             "the grazing orbit on Pi2)")
    k = None if gains is None else gain_vector(gains, model.n)
    after = -1 if k is None else (0 if control_after is None else int(control_after))
    for v in vals:   # every point's model (and its delayed kick) is valid before anything runs
        mv = dataclasses.replace(model, **{name: float(v)})
        if k is not None:
            ModalMap(mv, k, delay)
    args = (model, name)
    delay = 0.0 if k is None else float(delay)
    rest = (z0, k, int(periods), int(transient), after, float(period_tol), max_period, delay)
    m = periods - transient
    samples = np.full((vals.size, m, n2), np.nan)
    counts = np.zeros((vals.size, m), dtype=np.int32)
    period = np.zeros(vals.size, dtype=np.int64)
    errors = [""] * vals.size

    index = np.arange(vals.size)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=vals.size, unit="pt", desc="diagram", leave=False)

    def store(idx, out):
        s, c, p, e = out
        samples[idx], counts[idx], period[idx] = s, c, p
        for i, msg in zip(idx, e):
            errors[i] = msg
        if bar is not None:
            bar.update(len(idx))

    try:
        if scheduler is not None:
            _run_dask(scheduler, index, vals, args, rest, store)
        else:
            nw = min(local_workers(workers), vals.size)
            chunks = [index[i::max(1, 4 * nw)] for i in range(min(vals.size, max(1, 4 * nw)))]
            if nw == 1:
                for idx in chunks:
                    store(idx, run_points(*args, vals[idx], *rest))
            else:
                with ProcessPoolExecutor(max_workers=nw) as ex:
                    futs = {ex.submit(run_points, *args, vals[idx], *rest): idx for idx in chunks}
                    for fut in as_completed(futs):
                        store(futs[fut], fut.result())
    finally:
        if bar is not None:
            bar.close()

    reference = np.empty((vals.size, n2))
    for j, v in enumerate(vals):
        flow = NdofFlow.of(dataclasses.replace(model, **{name: float(v)}))
        reference[j] = flow.to_physical(flow.tau2, np.zeros(n2))
    return NdofDiagram(name, vals, _coordinates(model.n), samples, reference, counts, period,
                       tuple(errors), int(periods), int(transient), after, k, delay)


def _run_dask(scheduler, index, vals, args, rest, store):
    """The chunks on a Dask cluster (studies/sweeps/run.py's client: address check,
    timeout, closing)."""
    from distributed import as_completed as dask_completed

    from grazing_control.studies.sweeps.run import dask_client

    with dask_client(scheduler) as (client, nw):
        chunks = [index[i::4 * nw] for i in range(min(index.size, 4 * nw))]
        futs = [client.submit(run_points, *args, vals[idx], *rest, pure=False) for idx in chunks]
        where = {f.key: idx for f, idx in zip(futs, chunks)}
        for fut in dask_completed(futs, loop=client.loop):
            store(where[fut.key], fut.result())

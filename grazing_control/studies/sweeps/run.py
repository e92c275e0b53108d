"""Running a sweep: the grid of points, their split into chunks, local processes or Dask.

Each point is one run of ``periods`` forcing periods on Pi2 from its own start
(:func:`grazing_control.dynamics.simulation.simulate.period_step`'s exact flow with impacts, through the
compiled kernel or the pure-Python core), of which the last ``periods - transient``
samples are kept. Points are independent, so a chunk of points is the unit of work for
a process pool or a Dask worker, and the result is the same however they are split.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import re
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import fields

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from .period import detect_period
from .result import SweepResult

__all__ = ["GRID_NAMES", "CONNECT_TIMEOUT", "sweep", "run_chunk"]

#: Seconds to wait for a Dask scheduler given by address before giving up.
CONNECT_TIMEOUT = 10.0

_PARAM_NAMES = tuple(f.name for f in fields(OscillatorParams))
#: Names a sweep grid may use: the model's parameters and the controller's gains.
GRID_NAMES = _PARAM_NAMES + ("c1", "c2")


def _values(name, values):
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1 or arr.size == 0:
        raise ParameterError(f"grid[{name!r}] is invalid: expected a non-empty 1-d array of values")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"grid[{name!r}] is invalid: valid range is finite real values")
    return arr


def _starts(deviation):
    arr = np.asarray(deviation, dtype=float)
    if arr.shape == (2,):
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0 or not np.all(np.isfinite(arr)):
        raise ParameterError(
            "deviation is invalid: expected (dx, dv) or an (n_starts, 2) array of finite values")
    return arr


def _count(name, value, low):
    if isinstance(value, bool) or int(value) != value or value < low:
        raise ParameterError(f"{name}={value!r} is invalid: valid range is an integer >= {low}")
    return int(value)


def _points(params, grid, starts, gains, control_after):
    """Per point: (OscillatorParams, start, c1, c2); gains nan when uncontrolled."""
    names = tuple(grid)
    axes = tuple(_values(n, grid[n]) for n in names)
    for n in names:
        if n not in GRID_NAMES:
            raise ParameterError(
                f"grid name {n!r} is invalid: valid names are {', '.join(GRID_NAMES)}")
    gridded_gains = "c1" in names or "c2" in names
    if "c1" in names and "c2" not in names and gains is None:
        raise ParameterError("grid has c1 without c2 and no gains: give c2 (grid or gains)")
    controlled = (gains is not None or gridded_gains) and control_after is not None
    out = []
    for combo in itertools.product(*axes):
        values = dict(zip(names, combo))
        p = params.with_(**{k: v for k, v in values.items() if k in _PARAM_NAMES})
        c1 = c2 = math.nan
        if controlled:
            c2 = values["c2"] if "c2" in values else gains.c2
            if "c1" in values:
                c1 = values["c1"]
            elif "c2" in values:  # c1 from the degenerate condition for each c2 (Eq. 38)
                from grazing_control.dynamics.design.gains import degenerate_c1

                c1 = degenerate_c1(p, c2)
            else:
                c1 = gains.c1
            Gains(c1, c2)  # validated
        for start in starts:
            out.append((p, (float(start[0]), float(start[1])), float(c1), float(c2)))
    return names, axes, out


def _run_point_python(p, start, c1, c2, periods, transient, control_after, delay=0.0):
    """One point by the pure-Python reference core: (deviation (m, 2), counts (m,)).

    Each period is simulate.period_step's exact flow with impacts on the pure-Python
    core (simulate.core_period_step), whichever path period_step would take; the kick
    acts ``delay`` after the sample while the controller is on, as in simulate.
    """
    from grazing_control.dynamics.simulation.simulate import core_period_step
    from grazing_control.oscillator.impact import NonFiniteStateError

    m = periods - transient
    dev = np.full((m, 2), np.nan)
    counts = np.zeros(m, dtype=np.int32)
    dx, dv = start
    controlled = not math.isnan(c1)
    for k in range(periods):
        dvc = 0.0
        kick_delay = 0.0
        if controlled and k >= control_after:  # as simulate: Eq. 28 and its overflow check
            kick_delay = delay
            dvc = c1 * dx + c2 * dv
            if not abs(dvc) <= 1e150:
                raise NonFiniteStateError(
                    f"the correction c1*dx + c2*dv = {dvc!r} at period {k} is not finite or "
                    f"exceeds 1e150: an input overflowed (c1={c1!r}, c2={c2!r}, dx={dx!r}, "
                    f"dv={dv!r})")
        try:
            seg = core_period_step(p, dx, dv, dvc, delay=kick_delay)
        except NonFiniteStateError as exc:
            raise NonFiniteStateError(f"at period {k}: {exc}") from None
        if k >= transient:
            dev[k - transient] = dx, dv
            counts[k - transient] = len(seg.impacts)
        dx, dv = seg.dx, seg.dv
    return dev, counts


def run_chunk(chunk, periods, transient, control_after, engine, period_tol, max_period,
              delay=0.0, lyapunov=False):
    """Run a list of points; returns (indices, deviation, counts, period, errors, spectrum).

    ``spectrum`` (n, 2): with ``lyapunov``, the Lyapunov exponents per period of the kept
    samples' orbit (dynamics.simulation.lyapunov.lyapunov_exact from the first kept sample over the
    same periods, the controller switched on at the same sample: the same orbit, the same
    floats); nan otherwise and for a failed point.

    The unit of work of a local process or a Dask worker; a point that fails (state
    beyond the wall, more impacts than the cap, non-finite state) is reported in
    ``errors`` with period -1 and nan samples, and does not stop the others.
    """
    from grazing_control.oscillator.impact import ImpactCapError, InitialStateError

    m = periods - transient
    idx = np.array([c[0] for c in chunk], dtype=np.int64)
    dev = np.full((len(chunk), m, 2), np.nan)
    counts = np.zeros((len(chunk), m), dtype=np.int32)
    period = np.zeros(len(chunk), dtype=np.int64)
    errors = [""] * len(chunk)
    spectrum = np.full((len(chunk), 2), np.nan)
    run_point = _run_point_python
    if engine == "kernel":
        from grazing_control.oscillator.kernel import run_point as kernel_point

        def run_point(p, start, c1, c2, periods, transient, control_after, delay):
            return kernel_point(p, periods, transient, start[0], start[1], c1, c2, control_after,
                                delay)
    for j, (_i, p, start, c1, c2) in enumerate(chunk):
        try:
            dev[j], counts[j] = run_point(p, start, c1, c2, periods, transient, control_after,
                                          delay)
        except (ImpactCapError, InitialStateError, ValueError, ArithmeticError) as exc:
            errors[j] = f"{type(exc).__name__}: {exc}"
            period[j] = -1
            continue
        period[j] = detect_period(dev[j], period_tol, max_period)
        if period[j] == -1:
            errors[j] = "non-finite state"
        elif lyapunov:
            spectrum[j] = _spectrum(p, dev[j][0], c1, c2, periods - transient, control_after,
                                    transient, delay, engine)
    return idx, dev, counts, period, errors, spectrum


def _spectrum(p, first, c1, c2, m, control_after, transient, delay, engine):
    """The kept samples' Lyapunov exponents (largest first), by the sweep's engine."""
    from grazing_control.dynamics.simulation.lyapunov import lyapunov_exact

    gains = None if math.isnan(c1) or control_after < 0 else Gains(c1, c2, delay=delay)
    after = None if gains is None else max(0, control_after - transient)
    res = lyapunov_exact(p, (float(first[0]), float(first[1])), m, 0, gains, after,
                         engine=engine)
    return res.exponents


def local_workers(workers) -> int:
    """Local processes of a sweep: ``workers``, or all cores (None); the 1-DOF sweep's and a
    model file's (:mod:`.model_file`)."""
    if workers is None:
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:  # pragma: no cover - not Linux
            return max(1, os.cpu_count() or 1)
    return _count("workers", workers, 1)


def _progress(total, enabled):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="pt", desc="sweep", leave=False)


def _chunks(points, n_chunks):
    """Split into n_chunks strided chunks (point i to chunk i mod n_chunks): neighbouring
    grid values cost alike (chaos costs more than a 1/1 orbit), so striding balances."""
    n_chunks = max(1, min(n_chunks, len(points)))
    return [points[i::n_chunks] for i in range(n_chunks)]


def sweep(params: OscillatorParams, grid: dict, *, periods: int, transient: int,
          deviation=(0.0, 0.0), gains: Gains | None = None, control_after: int | None = None,
          workers: int | None = None, scheduler=None, engine: str = "auto",
          period_tol: float = 1e-10, max_period: int | None = None,
          progress: bool = False, lyapunov: bool = False) -> SweepResult:
    """Simulate every point of a parameter grid and keep its Pi2 samples after a transient.

    See :mod:`grazing_control.studies.sweeps` for the parameters and the result. Raises
    :class:`~grazing_control.oscillator.params.ParameterError` (one line naming the argument and its
    valid range) before anything runs if an argument or a grid value is invalid.
    """
    if not isinstance(params, OscillatorParams):
        raise ParameterError("params is invalid: expected an OscillatorParams")
    if not isinstance(grid, dict) or not grid:
        raise ParameterError("grid is invalid: expected a non-empty dict name -> values")
    periods = _count("periods", periods, 1)
    transient = _count("transient", transient, 0)
    if transient >= periods:
        raise ParameterError(
            f"transient={transient!r} is invalid: valid range is 0 <= transient < "
            f"periods={periods}")
    if control_after is not None:
        control_after = _count("control_after", control_after, 0)
    has_gains = gains is not None or "c1" in grid or "c2" in grid
    if has_gains and control_after is None:
        control_after = 0
    if not has_gains:
        control_after = None
    if engine not in ("auto", "kernel", "python"):
        raise ParameterError(f"engine={engine!r} is invalid: valid values are auto, kernel, python")
    if not (isinstance(period_tol, (int, float)) and math.isfinite(period_tol) and period_tol > 0):
        raise ParameterError(
            f"period_tol={period_tol!r} is invalid: valid range is a finite value > 0")
    if max_period is not None:
        max_period = _count("max_period", max_period, 1)
    starts = _starts(deviation)
    names, axes, pts = _points(params, grid, starts, gains, control_after)
    delay = gains.delay if gains is not None and control_after is not None else 0.0
    for p, *_rest in pts:
        if not delay < p.period:
            raise ParameterError(f"delay={delay!r} is invalid: valid range is 0 <= delay < T = "
                                 f"{p.period!r} (the correction acts within the period it "
                                 "answers)")
    engine = _resolve_engine(engine)
    n = len(pts)
    m = periods - transient
    indexed = [(i,) + pt for i, pt in enumerate(pts)]
    args = (periods, transient, -1 if control_after is None else control_after, engine,
            float(period_tol), max_period, delay, bool(lyapunov))

    dev = np.empty((n, m, 2))
    counts = np.empty((n, m), dtype=np.int32)
    period = np.empty(n, dtype=np.int64)
    errors = np.empty(n, dtype=object)
    spectrum = np.full((n, 2), np.nan)

    def store(out):
        idx, d, c, pr, er, ly = out
        dev[idx], counts[idx], period[idx], spectrum[idx] = d, c, pr, ly
        for i, e in zip(idx, er):
            errors[i] = e
        if bar is not None:
            bar.update(len(idx))

    bar = _progress(n, progress)
    try:
        if scheduler is not None:
            _run_dask(scheduler, indexed, args, store)
        else:
            nw = min(local_workers(workers), n)
            if nw == 1:
                for chunk in _chunks(indexed, max(1, min(n, 100))):
                    store(run_chunk(chunk, *args))
            else:
                _prepare(engine)
                with ProcessPoolExecutor(max_workers=nw) as ex:
                    futs = [ex.submit(run_chunk, c, *args) for c in _chunks(indexed, 8 * nw)]
                    for fut in as_completed(futs):
                        store(fut.result())
    finally:
        if bar is not None:
            bar.close()

    base = {k: getattr(params, k) for k in _PARAM_NAMES if k not in names}
    return SweepResult(
        names=names, axes=axes, shape=tuple(a.size for a in axes) + (starts.shape[0],),
        points={nm: np.array([_point_value(pt, nm) for pt in pts]) for nm in names},
        starts=np.array([pt[1] for pt in pts]).reshape(n, 2),
        pi2_deviation=dev,
        reference=np.array([(pt[0].x_ref, pt[0].v_ref) for pt in pts]).reshape(n, 2),
        impacts_per_period=counts, period=period, errors=errors.astype(str),
        c1=np.array([pt[2] for pt in pts]), c2=np.array([pt[3] for pt in pts]),
        periods=periods, transient=transient,
        control_after=-1 if control_after is None else control_after, base=base, engine=engine,
        delay=delay, lyapunov=spectrum if lyapunov else None)


def _point_value(pt, name):
    p, _start, c1, c2 = pt
    return {"c1": c1, "c2": c2}[name] if name in ("c1", "c2") else getattr(p, name)


def _resolve_engine(engine):
    from grazing_control.oscillator import kernel

    if engine == "python":
        return "python"
    if engine == "kernel":
        if not kernel.available():
            raise ParameterError("engine='kernel' is invalid here: numba is not installed")
        return "kernel"
    return "kernel" if kernel.use_kernel() else "python"


def _prepare(engine):
    """Compile (or load from cache) before forking, so workers inherit the machine code."""
    if engine == "kernel":
        from grazing_control.oscillator.kernel import warm_up

        warm_up()


#: A Dask scheduler address: protocol://host:port (the protocols distributed speaks).
_ADDRESS = re.compile(r"^(tcp|tls|ucx|ws|wss)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")


def check_scheduler(scheduler) -> str:
    """``scheduler`` if it is an address ``tcp://HOST:PORT``; else ParameterError.

    Checked before a ``distributed.Client`` exists: a Client built from a malformed address
    fails, and its finaliser then waits 20 s to close a connection that never was.
    """
    m = _ADDRESS.match(scheduler.strip()) if isinstance(scheduler, str) else None
    if m is None or not 0 < int(m.group(3)) < 65536:
        raise ParameterError(f"scheduler={scheduler!r} is invalid: expected an address "
                             "PROTOCOL://HOST:PORT (tcp, tls, ucx, ws, wss; port 1..65535) "
                             "or a distributed.Client")
    return scheduler.strip()


@contextlib.contextmanager
def dask_client(scheduler):
    """``(client, threads)`` for an address (tcp://host:port, checked first) or a Client;
    a Client made here is closed on exit. A cluster that cannot be reached within
    CONNECT_TIMEOUT is a ParameterError naming the address. The sweeps, the basins and
    the n-DOF diagram share it."""
    from distributed import Client

    own = not isinstance(scheduler, Client)
    if own:
        check_scheduler(scheduler)
    try:
        client = Client(scheduler, set_as_default=False, timeout=CONNECT_TIMEOUT) if own \
            else scheduler
    except (OSError, TimeoutError, ValueError) as exc:
        raise ParameterError(f"scheduler={scheduler!r} is invalid: cannot connect within "
                             f"{CONNECT_TIMEOUT:g} s ({type(exc).__name__})") from None
    try:
        yield client, max(1, sum(client.nthreads().values()))
    finally:
        if own:
            client.close()


def _run_dask(scheduler, indexed, args, store):
    """Run the chunks on a Dask cluster: an address (tcp://host:port) or a Client."""
    from distributed import as_completed as dask_completed

    with dask_client(scheduler) as (client, nw):
        chunks = _chunks(indexed, 8 * nw)
        futs = client.map(run_chunk, chunks, *[[a] * len(chunks) for a in args], pure=False)
        for fut in dask_completed(futs, loop=client.loop):
            store(fut.result())

"""The compiled exact kernel: the core's flow with impacts, compiled by numba.

The same algorithm as :mod:`grazing_control.oscillator.impact` and
:func:`grazing_control.dynamics.simulation.simulate.period_step` (closed-form flow in deviation coordinates,
certified impact detection, chattering summation and sticking, the controller's kick with
an optional delay), mirrored function by function in :mod:`.compiled` so that a fix in
the core ports line by line. The pure-Python core stays the readable
reference and the fallback; the equivalence of the two is tested scene by scene and by a
differential fuzz test (tests/test_kernel.py).

Which path runs
---------------
:func:`use_kernel` decides, from the environment variable ``GRAZING_KERNEL``:

* unset, ``auto``: the kernel if numba can be imported, else the pure-Python core;
* ``python``: always the pure-Python core (the reference);
* ``numba``: always the kernel (an error if numba is missing).

Compilation happens on the first call in a process and is cached on disk by numba
(``cache=True``: ``__pycache__`` next to the source, or ``NUMBA_CACHE_DIR``; stamped by
every file of this folder, :mod:`.caching`), so later processes only load the machine
code (:func:`warm_up` does either explicitly).

The n-DOF model's certified event search has its compiled mirror too
(:mod:`.compiled_modal`, the same floats as oscillator/ndof/impact.py's): the n-DOF core
takes it (:func:`modal_search`) once :func:`warm_up_modal` has loaded it, and searches in
Python before; a controller of an n-DOF model loads it at its start. With it come the
compiled flow with impacts (:func:`modal_advance`: ndof.impact.advance without sticking)
and the model filter's events of a period (:func:`modal_events`:
dynamics.estimation.motion.modal_trajectory's loop), the same floats as well.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import math
import os
import signal
import threading
import time

import numpy as np

from grazing_control.oscillator.impact import (Impact, ImpactCapError, InitialStateError,
                                               NonFiniteStateError, Segment, check_state)

__all__ = ["ENV", "available", "use_kernel", "loaded", "warm_up", "next_impact",
           "next_impact_unchecked", "advance",
           "period_step", "states_between", "simulate_exact", "run_point", "lyapunov_sums",
           "params_tuple",
           "warm_up_modal", "modal_search", "modal_advance", "modal_events"]

#: Environment variable that chooses the path: auto (default), python, numba.
ENV = "GRAZING_KERNEL"
_CHOICES = ("auto", "python", "numba")


def available() -> bool:
    """numba is installed (the kernel can be compiled or loaded)."""
    try:
        return importlib.util.find_spec("numba") is not None
    except (ImportError, ValueError):  # ValueError: sys.modules["numba"] is None
        return False


def use_kernel() -> bool:
    """True if the compiled kernel runs the exact simulation (see ``GRAZING_KERNEL``)."""
    choice = os.environ.get(ENV, "auto").strip().lower() or "auto"
    if choice not in _CHOICES:
        raise ValueError(f"{ENV}={choice!r} is invalid: valid values are {', '.join(_CHOICES)}")
    if choice == "python":
        return False
    if choice == "numba" and not available():
        raise RuntimeError(f"{ENV}=numba but numba is not installed (pip install numba)")
    return available()


_module = None
_load_seconds = {}


def loaded() -> bool:
    """Whether this process has loaded the kernel (:func:`warm_up` or a first call done):
    a caller with a choice (the controller's prediction, issue 30) takes it then, and
    the Python flow, bit for bit the same, before; never waits for the load."""
    return bool(_load_seconds)


def _compiled():
    """The numba module, twice: as the mirror of impact (ki) and of simulate (ks), which
    it both is. The first call imports it and compiles, or loads from numba's cache,
    every specialisation (the calls of :func:`warm_up`), with SIGINT held back until
    that is done (:func:`_sigint_held`)."""
    global _module
    if _module is None:
        with _sigint_held():
            t0 = time.perf_counter()
            from . import compiled

            t1 = time.perf_counter()
            _module = compiled  # set first: the calls below go through the wrappers
            try:
                _first_calls()
            except BaseException:
                _module = None
                raise
            _load_seconds.update({"import": t1 - t0, "first_call": time.perf_counter() - t1})
    return _module, _module


@contextlib.contextmanager
def _sigint_held():
    """Hold a SIGINT back while numba compiles or loads machine code, then deliver it.

    A KeyboardInterrupt raised inside numba's compiler or llvmlite's ctypes callbacks is
    either lost there (printed as ignored; the command then runs on) or leaves llvmlite
    half set up, and the process crashes at exit (SIGSEGV): 2 of 60 Ctrl-C at random
    moments of the first second of ``grazing simulate`` did one or the other. Only in
    the main thread and over a handler set from Python (not one set from C, as rclpy's);
    a first compile holds the signal for its few seconds, a cache load for ~0.3 s.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is None:  # installed from C: not ours to swap
        yield
        return
    caught = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(frame))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        if callable(previous):
            previous(signal.SIGINT, caught[-1])
        elif previous == signal.SIG_DFL:
            signal.raise_signal(signal.SIGINT)


def params_tuple(p):
    """(zeta, r, omega, omega_d, lag, amplitude, delta_d, d, period, tau2, 2, 1/3) of an
    OscillatorParams: the tuple ``P`` of the compiled functions, in the order of the
    indices ``_ZETA`` .. ``_THIRD`` of :mod:`.compiled`.

    The last two are the exponents of the core's ``x ** 2`` and ``x ** (1 / 3)``: CPython
    computes those with libm's pow, which is not always x * x to the last bit, while
    LLVM turns a constant exponent 2 into a multiplication. Passed at run time, they
    keep the kernel on pow, the same function, and so on the same floats
    (``compiled.power``).
    """
    return (p.zeta, p.r, p.omega, p.omega_d, p.lag, p.amplitude, p.delta_d, p.d, p.period,
            p.tau2, 2.0, 1.0 / 3.0)


@functools.lru_cache(maxsize=1024)
def _params(p):
    return params_tuple(p)


@functools.lru_cache(maxsize=64)
def _grid(p):
    """The window grid of a period from Pi2 (tau2, T), shared by every period_step call."""
    ki = _compiled()[0]
    grid = ki.window_grid(_params(p), p.tau2, p.period)
    return grid


_NO_GRID = np.zeros((0, 9))


_local = threading.local()


def _scratch():
    """Per-thread work arrays: one period's impacts, and the search's stack."""
    bufs = getattr(_local, "bufs", None)
    if bufs is None:
        ki, ks = _compiled()
        # one period's impact rows (run, period_step), and the search's stack
        bufs = _local.bufs = (np.empty((2 * ks.MAX_IMPACTS, 6)), ki.search_stack())
    return bufs


def _raise(status, info, *, max_impacts, duration, p=None, state=None, times=None):
    """The core's exception (and message) for a kernel status.

    ``state``: the (dx, dv) the kernel returned with STATUS_NONFINITE, ``times``: the
    (tau0, horizon) of the call, for the same messages as impact.check_state's.
    """
    ki = _compiled()[0]
    if status == ki.STATUS_IMPACT_CAP:
        raise ImpactCapError(
            f"more than max_impacts={max_impacts} impacts in {duration:.6g} time units "
            f"at phase {info:.6f}: the motion is not resolvable at this cap")
    if status == ki.STATUS_BEYOND_WALL:
        raise InitialStateError(f"state beyond the wall: x - d = {info:.3e} > 0 (valid: x <= d)")
    if status == ki.STATUS_NONFINITE:
        check_state(state[0], state[1], p.zeta, "the start state")
        tau0, horizon = times
        raise NonFiniteStateError(f"tau0={tau0!r} and duration={horizon!r} must be finite")
    raise RuntimeError(f"kernel status {status}")  # pragma: no cover - no other status


def warm_up() -> dict:
    """Compile (or load from the cache) every kernel function; returns the seconds taken.

    ``{"import": s, "first_call": s}``: importing numba and the modules, then the first
    calls, which compile all specialisations or load them from the on-disk cache (both
    0.0 when an earlier call in this process did it).
    """
    loaded = _module is not None
    _compiled()
    return {"import": 0.0, "first_call": 0.0} if loaded else dict(_load_seconds)


def _first_calls():
    """One call of each entry point: numba compiles, or loads, each specialisation."""
    from grazing_control.oscillator.params import OscillatorParams

    p = OscillatorParams(delta_d=-1e-3)
    period_step(p, 0.0, 0.0, 0.0)
    period_step(p, 0.0, 0.0, 0.0, delay=1.0)
    next_impact(p, p.tau2, 0.0, 0.0, p.period)
    advance(p, p.tau2, 0.0, 0.0, p.period)
    states_between(p, p.tau2, 0.0, 0.0, [], np.zeros(1))
    simulate_exact(p, 2, 0.0, 0.0)
    run_point(p, 2, 1, 0.0, 0.0)
    lyapunov_sums(p, 2, 1, 0.0, 0.0)


_modal = None


def warm_up_modal() -> float:
    """Load the compiled n-DOF event search, flow with impacts and model filter's events
    (:mod:`.compiled_modal`: compiled on a machine's first call, ~30 s, then loaded from
    numba's cache, ~0.1 s after :func:`warm_up`) where the kernel is in use; seconds
    taken (0.0 when loaded before or not in use). Until then :func:`modal_search`,
    :func:`modal_advance` and :func:`modal_events` are None and the n-DOF core runs in
    Python, with the same floats: a caller that needs the speed (controller_node's start, through
    ``dynamics.estimation.stream.warm_up``) loads it first, and nothing else waits for it."""
    global _modal
    if _modal is not None or not use_kernel():
        return 0.0
    t0 = time.perf_counter()
    with _sigint_held():
        from . import compiled_modal as km

        _modal_first_calls(km)
        _modal = km
    return time.perf_counter() - t0


def _modal_first_calls(km):
    """One call of each entry point of :mod:`.compiled_modal` with the argument types of
    the n-DOF core's calls (tests/test_ndof_compiled.py checks them): numba compiles, or
    loads, each specialisation."""
    # one mode (lambda = -0.1 + i) of a model with n = 1 (SearchConstants' layout)
    table = np.array([[-0.1, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0]])
    scalars = np.array([1.0, 0.0, 1.0, -1e-3, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.5, 2.0,
                        0.8, 0.0, 1.0, 1e150])
    stack = km.search_stack()
    km.next_impact(table, scalars, 0.0, np.zeros(2), 1.0, 0.0, stack)
    parts = (np.ones((2, 1)), np.zeros((2, 1)), np.ones((1, 2)), np.zeros((1, 2)),
             np.array([[0.0, 1.0], [-1.0, -0.2]]))
    km.advance(table, scalars, *parts, 0.0, np.zeros(2), 1.0, 1e-6, 10000, stack)
    km.modal_events(table, scalars, *parts, 0.0, 0, np.zeros(2),
                    np.array([[0.0, 1.0, 0.0, -1e-3]]), np.zeros((1, 2)), 1e-6, stack)


def modal_search():
    """The compiled n-DOF event search once :func:`warm_up_modal` has loaded it and while
    the kernel is in use (``GRAZING_KERNEL``), else None: a function (table, scalars,
    tau0, z0, horizon, max_step) -> (time of the first impact or None, the gap at a start
    beyond the wall or None) over a flow's
    :func:`~grazing_control.oscillator.ndof.impact.search_constants`, with ``max_step``
    0.0 for the default window."""
    if _modal is None or os.environ.get(ENV, "auto").strip().lower() == "python":
        return None      # (numba is there: loaded; use_kernel() asks importlib, ~2 us)
    return _modal_next_impact


def modal_advance():
    """The compiled n-DOF flow with impacts (:func:`.compiled_modal.advance`) where
    :func:`modal_search` is in use, else None: a function (search constants, tau0, z0,
    duration, chatter_time, max_impacts) -> (z, tau, impacts as rows (time, phase, v-,
    v+)), or None where the pure path must run (a stick, a contact at rest, a refused
    start, the cap)."""
    return None if modal_search() is None else _modal_advance


def _modal_advance(k, tau0, z0, duration, chatter, max_impacts):
    """:func:`modal_advance`'s function."""
    status, z, tau, imps = _modal.advance(k.table, k.scalars, k.modes_re, k.modes_im,
                                          k.inverse_re, k.inverse_im, k.A, tau0, z0, duration,
                                          chatter, max_impacts, _modal_stack())
    return None if status != _modal.STATUS_OK else (z, tau, imps.tolist())


def modal_events():
    """The compiled events of the n-DOF model filter's period
    (:func:`.compiled_modal.modal_events`, dynamics.estimation.motion.modal_trajectory's)
    where :func:`modal_search` is in use, else None: a function (search constants of the
    free flow, tau2, i_a, z0, legs, shifts, chatter_time) -> (times, z_e, M_e, shifts, z,
    M, impacts) or None where the pure path must run."""
    return None if modal_search() is None else _modal_events


def _modal_events(k, tau2, i_a, z0, legs, shifts, chatter):
    """:func:`modal_events`' function."""
    out = _modal.modal_events(k.table, k.scalars, k.modes_re, k.modes_im, k.inverse_re,
                              k.inverse_im, k.A, tau2, i_a, z0, legs, shifts, chatter,
                              _modal_stack())
    return None if out[0] != _modal.STATUS_OK else out[1:]


def _modal_stack():
    """The compiled n-DOF search's work array of this thread."""
    stack = getattr(_local, "modal_stack", None)
    if stack is None:
        stack = _local.modal_stack = _modal.search_stack()
    return stack


def _modal_next_impact(table, scalars, tau0, z0, horizon, max_step):
    """:func:`modal_search`'s function (per-thread work array, the kernel's statuses)."""
    h, status, info = _modal.next_impact(table, scalars, tau0,
                                         np.ascontiguousarray(z0, dtype=float), horizon,
                                         max_step, _modal_stack())
    if status == _modal.STATUS_BEYOND_WALL:
        return None, info
    return (None if h == _modal.NONE else h), None


def exact_advance():
    """The exact flow with impacts to call: :func:`advance` (compiled) while the kernel is
    in use (:func:`use_kernel`), else :func:`grazing_control.oscillator.impact.advance`. Both give
    the same segment bit for bit; callers that split periods themselves (sim_node, the
    exact fidelity) resolve it once and call it per segment."""
    if use_kernel():
        return advance
    from grazing_control.oscillator.impact import advance as reference

    return reference


def next_impact(p, tau0, dx0, dv0, horizon, max_step=None):
    """:func:`grazing_control.oscillator.impact.next_impact`, compiled."""
    ki = _compiled()[0]
    h, status, info = ki.next_impact(_params(p), float(tau0), float(dx0), float(dv0),
                                     float(horizon), float(max_step or 0.0), _scratch()[1],
                                     _NO_GRID)
    if status != ki.STATUS_OK:
        if status == ki.STATUS_NONFINITE and math.isfinite(dx0) and math.isfinite(dv0) and \
                not (math.isfinite(tau0) and math.isfinite(horizon)):
            raise NonFiniteStateError(f"tau0={tau0!r} and horizon={horizon!r} must be finite")
        _raise(status, info, max_impacts=0, duration=horizon, p=p, state=(dx0, dv0),
               times=(tau0, horizon))
    return None if h == ki.NONE else h


def next_impact_unchecked(p, tau0, dx0, dv0, horizon):
    """:func:`grazing_control.oscillator.impact._next_impact` (inputs checked by the
    caller, the default window), compiled: the contact entry of the compliant stop's flow
    (oscillator/contact.py, once its compiled searches are loaded)."""
    ki = _compiled()[0]
    h, status, info = ki.next_impact_unchecked(_params(p), tau0, dx0, dv0, horizon, 0.0,
                                               _scratch()[1], _NO_GRID)
    if status != ki.STATUS_OK:
        _raise(status, info, max_impacts=0, duration=horizon, p=p, state=(dx0, dv0),
               times=(tau0, horizon))
    return None if h == ki.NONE else h


def _impacts(rows):
    return [Impact(r[0], r[1], r[2], r[3], bool(r[4]), r[5]) for r in rows.tolist()]


def advance(p, tau0, dx, dv, duration, *, max_impacts=10000, chatter_time=None) -> Segment:
    """:func:`grazing_control.oscillator.impact.advance` without the monodromy, compiled."""
    ki = _compiled()[0]
    rows = max(int(max_impacts), 1)
    out, stack = _scratch()             # this thread's rows (copied out below), if they fit
    if rows > out.shape[0]:
        out = np.empty((rows, 6))
    ndx, ndv, n, status, info = ki.advance(
        _params(p), float(tau0), float(dx), float(dv), float(duration), int(max_impacts),
        -1.0 if chatter_time is None else float(chatter_time), out, 0, stack, _NO_GRID)
    if status != ki.STATUS_OK:
        _raise(status, info, max_impacts=max_impacts, duration=duration, p=p, state=(ndx, ndv),
               times=(tau0, duration))
    return Segment(ndx, ndv, _impacts(out[:n]) if n else [], None)


def period_step(p, dx, dv, dv_correction=0.0, *, delay=0.0) -> Segment:
    """:func:`grazing_control.dynamics.simulation.simulate.period_step`, compiled (0 <= delay < T checked there)."""
    ki, ks = _compiled()
    scratch, stack = _scratch()
    dx, dv, n, status, info = ks.period_step(_params(p), float(dx), float(dv),
                                             float(dv_correction), float(delay), scratch, 0, stack,
                                             _grid(p))
    if status != ki.STATUS_OK:
        _raise(status, info, max_impacts=ks.MAX_IMPACTS, duration=p.period, p=p,
               state=(dx, dv), times=(p.tau2, p.period))
    return Segment(dx, dv, _impacts(scratch[:n]), None)


def states_between(p, tau0, dx, dv, impacts, times) -> np.ndarray:
    """:func:`grazing_control.dynamics.simulation.simulate.states_between`, compiled: the
    physical (x, v) at ``times`` (1-D, since the segment's start, sorted) of the segment
    from the deviation (dx, dv) at phase ``tau0`` with the impact list ``impacts``; bit
    for bit the Python function's numbers (:func:`.compiled.states_between`)."""
    ki = _compiled()[0]
    times = np.ascontiguousarray(times, dtype=float)
    rows = np.array([(i.dt, i.phase, i.v_minus, i.v_plus, 1.0 if i.sticking else 0.0,
                      i.release) for i in impacts], dtype=float).reshape(-1, 6)
    return ki.states_between(_params(p), float(tau0), float(dx), float(dv), rows, times,
                             np.empty((times.size, 2)))


def _run(p, periods, dx, dv, c1, c2, control_after, delay, record_from, keep_impacts,
         progress=False):
    """simulate's loop on the kernel, in blocks of _BLOCK periods (progress bar, resizing).

    Errors as simulate raises them: NonFiniteStateError "at period k: ..." for a state,
    and its message for a correction that overflowed.
    """
    ki, ks = _compiled()
    m = periods - record_from
    dev = np.empty((m, 2))
    corr = np.zeros(m)
    counts = np.zeros(m, dtype=np.int64)
    impacts = np.empty((max(16, 2 * periods) if keep_impacts else 0, 5))
    controlled = not (math.isnan(c1) or control_after is None)
    after = 0 if control_after is None else int(control_after)
    bar = None
    if progress:
        import sys

        from tqdm import tqdm

        bar = tqdm(total=periods, unit="period", file=sys.stderr, leave=False)
    k, n = 0, 0
    try:
        while k < periods:
            end = min(periods, k + _BLOCK)
            k1, dx, dv, n, status, info = ks.run(
                _params(p), k, end, float(dx), float(dv), controlled, float(c1), float(c2),
                after, float(delay), record_from, dev, corr, counts, impacts, n, *_scratch())
            if bar is not None:
                bar.update(k1 - k)
            k = k1
            if status == ks.STATUS_BUFFER_FULL:
                more = np.empty((impacts.shape[0] + 2 * ks.MAX_IMPACTS, 5))
                impacts = np.concatenate([impacts, more])
                continue
            if status == ks.STATUS_CORRECTION:
                raise NonFiniteStateError(
                    f"the correction c1*dx + c2*dv = {info!r} at period {k} is not finite or "
                    f"exceeds 1e150: an input overflowed (c1={c1!r}, c2={c2!r}, dx={dx!r}, "
                    f"dv={dv!r})")
            if status != ki.STATUS_OK:
                try:
                    _raise(status, info, max_impacts=ks.MAX_IMPACTS, duration=p.period, p=p,
                           state=(dx, dv), times=(p.tau2, p.period))
                except NonFiniteStateError as exc:
                    raise NonFiniteStateError(f"at period {k}: {exc}") from None
    finally:
        if bar is not None:
            bar.close()
    return dev, corr, counts, impacts[:n], (dx, dv)


_BLOCK = 50_000  # periods per kernel call (a progress bar moves once per block)


def simulate_exact(p, periods, dx, dv, gains=None, control_after=None, *, delay=0.0,
                   progress=False):
    """The exact loop of :func:`grazing_control.dynamics.simulation.simulate.simulate`, compiled (with its
    checks and messages; ``progress``: a tqdm bar on stderr).

    Returns (deviation (N, 2), corrections (N,), impacts per period (N,),
    impacts (M, 5) rows [k, t, phase, v-, v+], final deviation).
    """
    c1, c2 = (math.nan, math.nan) if gains is None else (gains.c1, gains.c2)
    return _run(p, int(periods), dx, dv, c1, c2, control_after, delay, 0, True, progress)


def run_point(p, periods, transient, dx, dv, c1=math.nan, c2=math.nan, control_after=0,
              delay=0.0):
    """One sweep point: the deviation (m, 2) and impact counts (m,) of the last m =
    periods - transient samples (c1 = nan: uncontrolled; ``delay``: the kick acts that long
    after the sample, 0 <= delay < T, as in :func:`simulate_exact`)."""
    dev, _corr, counts, _imps, _end = _run(p, int(periods), dx, dv, c1, c2, control_after,
                                           float(delay), int(transient), False)
    return dev, counts


def lyapunov_sums(p, periods, transient, dx, dv, c1=math.nan, c2=math.nan, control_after=0,
                  delay=0.0):
    """The compiled tangent propagation along the orbit of :func:`run_point` (same floats).

    Returns (sum log R11, sum log R22, impacts, stuck periods, sum log|1 + c2|, final
    deviation) over periods transient..periods-1
    (:func:`grazing_control.dynamics.simulation.lyapunov.lyapunov_exact` makes exponents of them);
    errors as :func:`simulate_exact`.
    """
    ki, ks = _compiled()
    controlled = not (math.isnan(c1) or control_after is None)
    after = 0 if control_after is None else int(control_after)
    k, ndx, ndv, status, info, l1, l2, imps, stuck, lg = ks.lyapunov_run(
        _params(p), int(periods), int(transient), float(dx), float(dv), controlled,
        float(c1), float(c2), after, float(delay), *_scratch())
    if status == ks.STATUS_CORRECTION:
        raise NonFiniteStateError(
            f"the correction c1*dx + c2*dv = {info!r} at period {k} is not finite or "
            f"exceeds 1e150: an input overflowed (c1={c1!r}, c2={c2!r}, dx={ndx!r}, "
            f"dv={ndv!r})")
    if status != ki.STATUS_OK:
        try:
            _raise(status, info, max_impacts=ks.MAX_IMPACTS, duration=p.period, p=p,
                   state=(ndx, ndv), times=(p.tau2, p.period))
        except NonFiniteStateError as exc:
            raise NonFiniteStateError(f"at period {k}: {exc}") from None
    return l1, l2, int(imps), int(stuck), lg, (ndx, ndv)

"""Compiled mirror of :func:`grazing_control.simulate.period_step` and of the period loop.

:func:`period_step` is one forcing period from a Pi2 sample with the correction applied
``delay`` after it, exactly as the core's; :func:`run` chains periods with the
controller of Eq. 28 (dv_correction = c1 dx + c2 dv at samples k >= control_after), as
:func:`grazing_control.simulate.simulate` does, and is the whole inner loop of a sweep
point or of an exact simulation.
"""

from __future__ import annotations

import numpy as np

from .impact import STATUS_OK, TWO_PI, _OMEGA, _PERIOD, _TAU2, advance, jit, window_grid

__all__ = ["period_step", "run", "STATUS_BUFFER_FULL", "STATUS_CORRECTION", "MAX_IMPACTS"]

#: The impact buffer of :func:`run` is full: resume at the returned period with more room.
STATUS_BUFFER_FULL = 3
#: simulate's check: the correction c1 dx + c2 dv is not finite or exceeds 1e150 (info).
STATUS_CORRECTION = 5
#: The core's default cap of impacts per advance call.
MAX_IMPACTS = 10000


@jit
def period_step(P, dx, dv, dv_correction, delay, out, n0, stack, grid):
    """simulate.period_step: (dx, dv, n, status, info); impact rows n0..n-1 of ``out``.

    ``out`` needs n0 + 2 MAX_IMPACTS rows when delay > 0 (two advance calls), n0 +
    MAX_IMPACTS otherwise. Impact times count from the sample. The caller validates
    0 <= delay < T. ``grid``: window_grid(P, tau2, T) (or empty), reused when delay = 0.
    """
    if delay == 0.0:
        return advance(P, P[_TAU2], dx, dv + dv_correction, P[_PERIOD], MAX_IMPACTS, -1.0,
                       out, n0, stack, grid)
    dx1, dv1, n1, status, info = advance(P, P[_TAU2], dx, dv, delay, MAX_IMPACTS, -1.0, out, n0,
                                          stack, grid)
    if status != STATUS_OK:
        return dx1, dv1, n1, status, info
    tau = (P[_TAU2] + P[_OMEGA] * delay) % TWO_PI
    dx2, dv2, n2, status, info = advance(P, tau, dx1, dv1 + dv_correction, P[_PERIOD] - delay,
                                         MAX_IMPACTS, -1.0, out, n1, stack, grid)
    for i in range(n1, n2):
        out[i, 0] += delay
        out[i, 5] += delay
    return dx2, dv2, n2, status, info


@jit
def run(P, k0, periods, dx, dv, controlled, c1, c2, control_after, delay, record_from,
        dev, corr, counts, impacts, n_impacts, scratch, stack):
    """Periods k0 .. periods-1 from the Pi2 deviation (dx, dv) at sample k0.

    Sample k (>= record_from) is stored at row k - record_from of ``dev`` (deviation
    before the correction), ``corr`` (the correction) and ``counts`` (impacts in the
    period). Impact rows (k, time since sample 0, phase, v-, v+) are appended to
    ``impacts`` from row ``n_impacts`` when it has any rows (an exact simulation) and
    skipped when it has none (a sweep); ``scratch`` holds one period's impacts
    (2 MAX_IMPACTS rows).

    Returns
    -------
    (k, dx, dv, n_impacts, status, info)
        k = periods and STATUS_OK when done. STATUS_BUFFER_FULL: period k did not fit in
        ``impacts``; (dx, dv) is still sample k's, so the call can be resumed from k with
        a larger array. STATUS_CORRECTION: simulate's overflow check of the correction
        (info) failed at sample k, whose (dx, dv) are returned. Any other status is the
        core's error at period k, with (dx, dv) the state it is about (impact.advance).
    """
    period = P[_PERIOD]
    keep = impacts.shape[0] > 0
    grid = window_grid(P, P[_TAU2], period)
    for k in range(k0, periods):
        dvc = 0.0
        if controlled and k >= control_after:
            dvc = c1 * dx + c2 * dv
            if not abs(dvc) <= 1e150:  # simulate's check: an input overflowed
                return k, dx, dv, n_impacts, STATUS_CORRECTION, dvc
        ndx, ndv, n, status, info = period_step(P, dx, dv, dvc, delay, scratch, 0, stack, grid)
        if status != STATUS_OK:  # (ndx, ndv): the state the error is about
            return k, ndx, ndv, n_impacts, status, info
        if keep:
            if n_impacts + n > impacts.shape[0]:
                return k, dx, dv, n_impacts, STATUS_BUFFER_FULL, 0.0
            for i in range(n):
                impacts[n_impacts, 0] = k
                impacts[n_impacts, 1] = k * period + scratch[i, 0]
                impacts[n_impacts, 2] = scratch[i, 1]
                impacts[n_impacts, 3] = scratch[i, 2]
                impacts[n_impacts, 4] = scratch[i, 3]
                n_impacts += 1
        if k >= record_from:
            j = k - record_from
            dev[j, 0] = dx
            dev[j, 1] = dv
            corr[j] = dvc
            counts[j] = n
        dx, dv = ndx, ndv
    return periods, dx, dv, n_impacts, STATUS_OK, 0.0


def scratch_buffer():
    """The per-period impact buffer :func:`run` and :func:`period_step` need."""
    return np.empty((2 * MAX_IMPACTS, 6))


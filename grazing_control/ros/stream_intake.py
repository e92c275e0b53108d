"""The controller's checks of each stream sample, and the run of a block's rows that passes them.

A stream sample (one ``oscillator/state`` message, or one row of a block on
``oscillator/state_block``, ros/stream_block.py) is checked before the estimator takes
it: a position that is not finite or an infinite velocity is malformed (NaN velocity: a
position-only sensor), and the shaker's phase reference (effort [cos tau, sin tau] or
[cos tau]) must agree with the phase the sections assume, tau = tau2 + omega t
(docs/nodes.md, "The sensor stream"), within :data:`PHASE_TOLERANCE`.

:func:`plain_rows` gives the leading rows of a block that pass both checks as three
columns, so that the controller hands them to the estimator in one step
(``StreamEstimator.plain_run`` and ``add_plain``) instead of sample by sample: at T/200
and x1000 a block holds ~10 samples and comes every 0.5 ms, and the per-sample calls were
most of the controller's CPU between two sections (issue 30, docs/benchmarks.md). A row
that fails a check ends the run; it and the rows after it take the per-sample path,
which counts and logs it.
"""

from __future__ import annotations

import math

from .stream_block import Rows

__all__ = ["PHASE_TOLERANCE", "phase_error", "plain_rows", "take_run"]

#: The largest difference between the stream's phase reference and (cos tau, sin tau)
#: that is no mismatch.
PHASE_TOLERANCE = 1e-6


def phase_error(effort, tau: float) -> float:
    """The largest of |effort[0] - cos tau| and |effort[1] - sin tau| (those it has; 0
    for an empty effort), NaN where either is NaN (``max`` would skip a NaN that is not
    first: a NaN sin tau went uncounted)."""
    errs = [abs(e - w) for e, w in zip(effort[:2], (math.cos(tau), math.sin(tau)))]
    if any(e != e for e in errs):
        return math.nan
    return max(errs, default=0.0)


def plain_rows(rows: Rows, coordinate: int, tau2: float, omega: float, first: int = 0):
    """(t, x, v) of the rows of ``rows`` from row ``first`` on, up to the first one whose
    sample does not pass the checks: x
    finite, v not infinite, the phase reference within :data:`PHASE_TOLERANCE` of
    tau2 + omega t; t = sec + nanosec 1e-9 as the per-sample path computes it
    (ros/stream_block.py :func:`~grazing_control.ros.stream_block.samples`)."""
    n, flat = rows
    w, ix, iv = 4 + 2 * n, 2 + coordinate, 2 + n + coordinate
    cos, sin, isfinite, isinf = math.cos, math.sin, math.isfinite, math.isinf
    ts, xs, vs = [], [], []
    for i in range(first * w, len(flat), w):
        x, v = flat[i + ix], flat[i + iv]
        if not isfinite(x) or isinf(v):
            break
        t = int(flat[i]) + int(flat[i + 1]) * 1e-9
        tau = tau2 + omega * t
        if not (abs(flat[i + w - 2] - cos(tau)) <= PHASE_TOLERANCE
                and abs(flat[i + w - 1] - sin(tau)) <= PHASE_TOLERANCE):
            break
        ts.append(t)
        xs.append(x)
        vs.append(v)
    return ts, xs, vs


def take_run(stream, reid, t, x, v) -> int:
    """Hand the leading samples (t, x, v) that only append (``stream.plain_run``: no
    section falls due among them) to the estimator ``stream`` and to the
    re-identification's record ``reid`` (a ``ReidentifySide``, or None) in one step;
    the number taken. The rest takes the per-sample path, in order."""
    n = stream.plain_run(t)
    if n:
        if reid is not None:
            reid.samples(t[:n], x[:n], v[:n])
        stream.add_plain(t[:n], x[:n], v[:n])
    return n

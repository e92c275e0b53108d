"""Attractors identified across starts: which recorded motions are the same attractor.

Each start of a basin grid ends in a record of Pi2 samples (deviation coordinates
z = (x - x**, v - v**)) with its impact counts and its detected period p
(:func:`grazing_control.studies.sweeps.detect_period`: the smallest p with
|z_{k+p} - z_k| <= period_tol over the record; 0 none, -1 the run failed).

A periodic motion is the cycle of its last p samples, with n impacts in those p
forcing periods: the p/n notation of the study is "impacts/periods", so it is labelled
``n/p`` (spec section 1: 0/1 no impact, 1/1 one impact per period, 2/2 two impacts in
two periods). Two starts reach the same attractor when their cycles have the same p
and n and coincide point by point, up to where the cycle was entered:

    min over s of max_k |z^a_k - z^b_{(k+s) mod p}| <= match_tol   (both components),

so two starts on the two points of one 2-cycle are one attractor. A detected period
whose cycle repeats within ``match_tol`` after a divisor q of it is taken as q
(:func:`reduced_period`: a slow alternating transient onto a q-cycle). Starts are taken in
index order and each joins the first attractor it matches (its representative is the
first start that reached it), so the result depends on the records alone, not on how
they were computed. Records without a period up to the maximum are one class,
``chaotic`` (chaos, a quasi-periodic motion, a period above the maximum, or a transient
longer than the run: coexisting chaotic attractors are not told apart), and failed runs
another, ``failed``.

A record with no period at period_tol that is periodic at ``match_tol`` (the tolerance
at which two points are one) is a transient still converging onto a cycle, slowly: a
multiplier near -1 (|lambda| = 0.995 for the controlled 1/1 orbit at c2 = -2 near the
end of the admissible set) leaves 1e-8 after 2000 periods. It joins that cycle's
attractor and is counted in its ``slow`` starts, not called chaotic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Attractor", "identify", "reduced_period", "cycle_distance", "canonical_cycle"]


@dataclass(frozen=True)
class Attractor:
    """One attractor reached from the basin grid.

    Attributes
    ----------
    label : str
        ``n/p`` (n impacts in p periods), with ``#2``, ``#3``, ... when several distinct
        attractors share n and p; ``chaotic``; ``failed``.
    kind : str
        ``periodic``, ``chaotic`` or ``failed``.
    period : int
        p, the Pi2 samples per cycle (0 chaotic, -1 failed).
    impacts : int
        n, the impacts in one cycle (periodic); for the others the impacts in the record
        of the representative start (-1 failed).
    points : (k, 2) array
        Deviation coordinates: the cycle's p points (:func:`canonical_cycle` order) when
        periodic; the representative start's record when chaotic; empty when failed.
    starts : int
        Starts that reach it.
    slow : int
        Of those, the starts whose record is periodic only at match_tol, not at period_tol
        (still converging at the end of the transient).
    first : int
        Index of the representative start, whose cycle is ``points``: the first settled
        start that reaches it (the first slow one when none settled).
    """

    label: str
    kind: str
    period: int
    impacts: int
    points: np.ndarray
    starts: int
    first: int
    slow: int = 0


def canonical_cycle(cycle) -> np.ndarray:
    """The cycle's points rotated to begin at its point of least x (then least v)."""
    cycle = np.asarray(cycle, dtype=float)
    k = int(np.lexsort((cycle[:, 1], cycle[:, 0]))[0])
    return np.roll(cycle, -k, axis=0)


def cycle_distance(a, b) -> float:
    """min over cyclic shifts s of max_k |a_k - b_{k+s}| (both components): the distance
    of two p-cycles on Pi2 whatever point each was entered at; inf if p differs."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != b.shape:
        return float("inf")
    return float(min(np.max(np.abs(a - np.roll(b, -s, axis=0))) for s in range(a.shape[0])))


def reduced_period(cycle, counts, match_tol: float) -> int:
    """The least divisor q of p = len(cycle) with the cycle q-periodic to ``match_tol``
    (|z_{k+q} - z_k| <= match_tol, both components) and the same impacts every q periods.

    The detection's p is exact to period_tol, but a transient that approaches a q-cycle
    along a multiplier near -1 of P^q alternates about it: z_{k+2q} - z_k is then
    smaller than z_{k+q} - z_k by the factor 1 + lambda, so the record can pass as a 2q
    cycle (a 3/3 cycle with lambda = -0.965 shows as "6/6" after 1500 periods). At the
    tolerance that decides which points are one, such a cycle is the q-cycle.
    """
    cycle = np.asarray(cycle, dtype=float)
    counts = np.asarray(counts)
    p = cycle.shape[0]
    for q in range(1, p):
        if p % q == 0 and np.array_equal(counts[q:], counts[:-q]) \
                and np.max(np.abs(cycle[q:] - cycle[:-q])) <= match_tol:
            return q
    return p


def identify(records, counts, period, match_tol: float):
    """Group starts by attractor.

    Parameters
    ----------
    records : (n, m, 2) array
        Each start's last m Pi2 samples in deviation coordinates.
    counts : (n, m) int array
        Impacts in each recorded period.
    period : (n,) int array
        Detected period per start (>= 1, 0 none, -1 failed).
    match_tol : float
        Largest :func:`cycle_distance` of two cycles of one attractor (> 0).

    Returns
    -------
    index : (n,) int array
        The attractor of each start, an index into ``attractors``.
    attractors : tuple of Attractor
        Periodic ones ordered by (p, n, representative start), then ``chaotic``, then
        ``failed``.
    """
    from grazing_control.studies.sweeps.period import detect_period

    records = np.asarray(records, dtype=float)
    counts = np.asarray(counts)
    period = np.asarray(period)
    n = period.shape[0]
    groups = []          # [kind, p, impacts, cycle, [members]]
    by_key = {}
    special = {}
    periods = period.astype(np.int64).copy()
    slow = np.zeros(n, dtype=bool)
    for i in np.flatnonzero(periods == 0):  # a slow transient onto a cycle, or chaos
        periods[i] = detect_period(records[i], match_tol, records.shape[1] // 2)
        slow[i] = periods[i] > 0
    # settled starts first, so that an attractor's cycle is a settled record where any is
    for i in sorted(range(n), key=lambda i: (bool(slow[i]), i)):
        p = int(periods[i])
        if p >= 1:
            p = reduced_period(records[i, -p:], counts[i, -p:], match_tol)
            cycle = records[i, -p:]
            key = (p, int(np.sum(counts[i, -p:])))
            for g in by_key.setdefault(key, []):
                if cycle_distance(cycle, g[3]) <= match_tol:
                    g[4].append(i)
                    break
            else:
                g = ["periodic", p, key[1], cycle, [i]]
                by_key[key].append(g)
                groups.append(g)
        else:
            kind = "chaotic" if p == 0 else "failed"
            if kind not in special:
                record = records[i] if kind == "chaotic" else np.empty((0, 2))
                special[kind] = [kind, p, int(np.sum(counts[i])) if p == 0 else -1, record, []]
            special[kind][4].append(i)
    periodic = sorted(groups, key=lambda g: (g[1], g[2], g[4][0]))
    ordered = periodic + [special[k] for k in ("chaotic", "failed") if k in special]
    # members[0] is the representative (its cycle is the attractor's), the rest in order
    index = np.empty(n, dtype=np.int64)
    attractors = []
    for j, (kind, p, impacts, points, members) in enumerate(ordered):
        index[members] = j
        if kind == "periodic":
            same = [g for g in periodic if (g[1], g[2]) == (p, impacts)]
            label = f"{impacts}/{p}"
            if len(same) > 1:
                label += f" #{next(k for k, g in enumerate(same) if g is ordered[j]) + 1}"
            points = canonical_cycle(points)
        else:
            label = kind
        attractors.append(Attractor(label, kind, p, impacts, np.array(points), len(members),
                                    members[0], int(np.sum(slow[members]))))
    return index, tuple(attractors)

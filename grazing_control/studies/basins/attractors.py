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
index order, the settled ones before the slow ones (below), and each joins the first
attractor it matches (its representative, whose cycle the attractor keeps, is the first
start that reached it), so the result depends on the records alone, not on how they
were computed or split into blocks (:class:`Grouping`). Records without a period up to the maximum are one class,
``chaotic`` (chaos, a quasi-periodic motion, a period above the maximum, or a transient
longer than the run: coexisting chaotic attractors are not told apart), and failed runs
another, ``failed``.

A record with no period at period_tol that is periodic at ``match_tol`` (the tolerance
at which two points are one) is a transient still converging onto a cycle, slowly: a
multiplier near -1 (|lambda| = 0.995 for the controlled 1/1 orbit at c2 = -2 near the
end of the admissible set) left 8e-8 after 2128 periods from one start. It joins that cycle's
attractor and is counted in its ``slow`` starts, not called chaotic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Attractor", "Grouping", "identify", "reduced_period", "cycle_distance",
           "canonical_cycle"]


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
    """Group starts by attractor (all records at once; :class:`Grouping` block by block).

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
    grouping = Grouping(match_tol)
    grouping.add(records, counts, period)
    return grouping.finish()


class Grouping:
    """:func:`identify` over blocks of consecutive starts: :meth:`add` each block in
    order, then :meth:`finish`. It keeps a cycle per attractor, each slow start's cycle
    (at most max_period points) and one chaotic record, not the blocks' records, and
    gives the result :func:`identify` gives on all the records at once."""

    def __init__(self, match_tol: float):
        self.match_tol = float(match_tol)
        self.n = 0
        self.groups = []      # [kind, p, impacts, cycle, [members]]
        self.by_key = {}
        self.special = {}
        self.pending = []     # slow starts: (index, cycle, impacts), grouped at the end
        self.slow = []

    def add(self, records, counts, period) -> None:
        """The next block: records (b, m, 2), counts (b, m), detected periods (b,)."""
        from grazing_control.studies.sweeps.period import detect_period

        records = np.asarray(records, dtype=float)
        counts = np.asarray(counts)
        for j, p in enumerate(np.asarray(period)):
            i, p = self.n + j, int(p)
            slow = False
            if p == 0:    # a slow transient onto a cycle, or chaos (module docstring)
                p = detect_period(records[j], self.match_tol, records.shape[1] // 2)
                slow = p > 0
            if p >= 1:
                p = reduced_period(records[j, -p:], counts[j, -p:], self.match_tol)
                entry = (i, records[j, -p:].copy(), int(np.sum(counts[j, -p:])))
                if slow:  # settled starts first: an attractor's cycle is a settled one's
                    self.pending.append(entry)
                    self.slow.append(i)
                else:
                    self._join(*entry)
                continue
            kind = "chaotic" if p == 0 else "failed"
            if kind not in self.special:
                record = records[j].copy() if kind == "chaotic" else np.empty((0, 2))
                self.special[kind] = [kind, p, int(np.sum(counts[j])) if p == 0 else -1,
                                      record, []]
            self.special[kind][4].append(i)
        self.n += records.shape[0]

    def _join(self, i, cycle, impacts):
        key = (cycle.shape[0], impacts)
        for g in self.by_key.setdefault(key, []):
            if cycle_distance(cycle, g[3]) <= self.match_tol:
                g[4].append(i)
                return
        g = ["periodic", key[0], impacts, cycle, [i]]
        self.by_key[key].append(g)
        self.groups.append(g)

    def finish(self):
        """(index (n,), attractors) as :func:`identify` returns them."""
        for entry in self.pending:
            self._join(*entry)
        self.pending = []
        slow = np.zeros(self.n, dtype=bool)
        slow[self.slow] = True
        periodic = sorted(self.groups, key=lambda g: (g[1], g[2], g[4][0]))
        ordered = periodic + [self.special[k] for k in ("chaotic", "failed")
                              if k in self.special]
        # members[0] is the representative (its cycle is the attractor's)
        index = np.empty(self.n, dtype=np.int64)
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
            attractors.append(Attractor(label, kind, p, impacts, np.array(points),
                                        len(members), members[0], int(np.sum(slow[members]))))
        return index, tuple(attractors)

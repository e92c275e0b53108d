"""The controller's checks of a stream sample, and the run of a block's rows that passes
them (grazing_control.ros.stream_intake)."""

import math

import numpy as np

from grazing_control.ros import stream_block
from grazing_control.ros.stream_intake import PHASE_TOLERANCE, phase_error, plain_rows

TAU2, OMEGA = 0.7, 1.9


def test_the_phase_error_is_the_larger_difference_and_nan_wherever_one_is_nan():
    tau = 0.3
    c, s = math.cos(tau), math.sin(tau)
    assert phase_error((c, s), tau) == 0.0
    assert phase_error((c + 2e-6, s - 5e-6), tau) == abs(s - 5e-6 - s)
    assert phase_error((c + 3e-6,), tau) == abs(c + 3e-6 - c)      # [cos tau] only
    assert phase_error((), tau) == 0.0                             # no reference
    for effort in ((math.nan, s), (c, math.nan), (math.nan, math.nan)):
        assert math.isnan(phase_error(effort, tau)), effort        # not max()'s pick
    assert phase_error((c, s, 9.0), tau) == 0.0                    # beyond two: ignored


def _one_by_one(rows, c, first):
    """The per-sample path's checks on each row from row ``first`` (controller_node.
    _take_sample and _check_phase), by brute force: the rows up to the first that fails."""
    out = []
    for sec, ns, x, v, effort in stream_block.samples(rows, c)[first:]:
        t = sec + ns * 1e-9
        tau = TAU2 + OMEGA * t
        want = (math.cos(tau), math.sin(tau))
        if not math.isfinite(x) or math.isinf(v) or not all(
                abs(e - w) <= PHASE_TOLERANCE for e, w in zip(effort, want)):
            break
        out.append((t, x, v))
    return out


def test_the_plain_rows_are_the_leading_rows_that_pass_every_check():
    """Against the checks row by row on 4000 seeded blocks of 1-3 masses, each coordinate,
    from any row on:
    a NaN or infinite position, an infinite or NaN velocity (NaN is a position-only
    sensor: it passes), a phase reference off by 0.5-2 tolerances or NaN."""
    rng = np.random.default_rng(2030)
    runs = []
    for _ in range(4000):
        n = int(rng.integers(1, 4))
        flat = []
        for j in range(int(rng.integers(1, 15))):
            t = float(rng.uniform(0.0, 100.0))
            sec, ns = int(t), int(rng.integers(0, 10**9))
            tt = sec + ns * 1e-9
            x = list(rng.normal(size=n))
            v = list(rng.normal(size=n))
            tau = TAU2 + OMEGA * tt
            cs = [math.cos(tau), math.sin(tau)]
            if rng.random() < 0.1:
                x[int(rng.integers(0, n))] = float(rng.choice([math.nan, math.inf]))
            if rng.random() < 0.1:
                v[int(rng.integers(0, n))] = float(rng.choice([math.nan, math.inf, -math.inf]))
            if rng.random() < 0.1:
                cs[int(rng.integers(0, 2))] += float(rng.choice([0.5, 0.99, 1.01, 2.0])) \
                    * PHASE_TOLERANCE * float(rng.choice([-1, 1]))
            if rng.random() < 0.03:
                cs[int(rng.integers(0, 2))] = math.nan
            flat += [sec, ns, *x, *v, *cs]
        rows = stream_block.read(stream_block.pack(flat, n))
        c = int(rng.integers(0, n))
        assert rows.count == len(flat) // (4 + 2 * n)
        first = int(rng.integers(0, 3)) if rng.random() < 0.5 else 0
        got = plain_rows(rows, c, TAU2, OMEGA, first)
        want = _one_by_one(rows, c, first)
        assert repr(list(zip(*got))) == repr(want)
        assert stream_block.samples(rows, c, first, first + 1) == \
            stream_block.samples(rows, c)[first:first + 1]
        runs.append(len(want) == max(0, rows.count - first))
    assert 0.2 < np.mean(runs) < 0.8            # whole blocks and cut ones, both often

"""dynamics/estimation/clock_relation.py: ROS time = offset + (1 + drift) rig time, by least squares.

Differential test against mpmath at 60 digits (the textbook normal equations, no
shifting needed at that precision; the floats themselves are the data) over hundreds of seeded cases with offsets up to
1e5 s, drifts up to 1e-4 and read jitter; recovery of a known offset and drift within a
few standard errors (the standard errors themselves checked by Monte Carlo); the
sliding window; refusal of non-increasing and non-finite pairs.
"""

import math

import mpmath
import numpy as np
import pytest

from grazing_control.dynamics.estimation.clock_relation import ClockRelation, fit_clock


def _truth(s, t):
    """(offset, drift, jitter) of the least-squares line at 60 digits."""
    with mpmath.workdps(60):
        return _truth_60(s, t)


def _truth_60(s, t):
    S = [mpmath.mpf(float(x)) for x in s]
    T = [mpmath.mpf(float(x)) for x in t]
    n = len(S)
    sm, tm = sum(S) / n, sum(T) / n
    sxx = sum((x - sm) ** 2 for x in S)
    slope = sum((x - sm) * (y - tm) for x, y in zip(S, T)) / sxx
    offset = tm - slope * sm
    res = [y - offset - slope * x for x, y in zip(S, T)]
    jitter = mpmath.sqrt(sum(r * r for r in res) / (n - 2)) if n > 2 else mpmath.mpf(0)
    return offset, slope - 1, jitter


def _case(rng):
    n = int(rng.integers(3, 300))
    start = rng.uniform(0.0, 1e5)
    rate = rng.choice([10.0, 100.0, 1000.0])
    s = start + np.cumsum(rng.uniform(0.5, 1.5, n)) / rate
    offset = rng.uniform(-1e5, 1e5)
    drift = rng.uniform(-1e-4, 1e-4)
    jitter = rng.choice([0.0, 1e-7, 1e-5, 1e-3])
    t = offset + (1.0 + drift) * s + jitter * rng.standard_normal(n)
    return s, t, offset, drift, jitter


def test_the_fit_equals_the_60_digit_least_squares_line():
    rng = np.random.default_rng(2028)
    for _ in range(300):
        s, t, *_ = _case(rng)
        fit = fit_clock(s, t)
        off, drift, jit = _truth(s, t)
        # the fit works on differences from the first pair (exact in floating point),
        # so its error is a few roundings of the largest time, not the conditioning
        # (1 + s_mean / span) of the textbook formula (measured: 2.5 eps and 2.1 eps)
        eps = np.finfo(float).eps
        scale = float(max(abs(s).max(), abs(t).max()))
        span = float(s.max() - s.min())
        assert abs(fit.offset - float(off)) <= 8 * eps * scale
        assert abs(fit.drift - float(drift)) <= 8 * eps
        assert abs(fit.jitter - float(jit)) <= 1e-9 * float(jit) + 8 * eps * scale / span
        assert fit.n == s.size and fit.span == pytest.approx(span, rel=1e-12)


def test_a_known_offset_and_drift_are_recovered_within_their_standard_errors():
    rng = np.random.default_rng(7)
    z_off, z_drift = [], []
    for _ in range(400):
        s = 5e4 + np.arange(200) * 0.1
        offset, drift, jitter = rng.uniform(-1e5, 1e5), rng.uniform(-1e-4, 1e-4), 1e-4
        t = offset + (1.0 + drift) * s + jitter * rng.standard_normal(s.size)
        fit = fit_clock(s, t)
        z_off.append((fit.offset - offset) / fit.offset_se)
        z_drift.append((fit.drift - drift) / fit.drift_se)
        assert abs(z_off[-1]) < 5 and abs(z_drift[-1]) < 5
        assert fit.jitter == pytest.approx(jitter, rel=0.3)
    # the standard errors are right: the normalised errors have unit spread (t with
    # 198 dof: std 1.005; 400 draws: +- 0.04 at one sigma)
    assert np.std(z_off) == pytest.approx(1.0, abs=0.15)
    assert np.std(z_drift) == pytest.approx(1.0, abs=0.15)


def test_one_pair_gives_the_offset_with_an_unknown_drift():
    fit = fit_clock([10.0], [110.5])
    assert (fit.offset, fit.drift, fit.n) == (100.5, 0.0, 1)
    assert math.isinf(fit.offset_se) and math.isinf(fit.drift_se)
    two = fit_clock([10.0, 20.0], [110.0, 120.001])
    assert two.drift == pytest.approx(1e-4, rel=1e-9) and math.isinf(two.drift_se)


def test_the_window_slides_and_keeps_the_last_pairs():
    rel = ClockRelation(window=50)
    assert rel.fit is None
    for i in range(120):          # the drift changes at pair 60: the window forgets it
        s = 1000.0 + 0.1 * i
        drift = 1e-5 if i < 60 else -3e-5
        assert rel.add(s, 7.0 + (1 + drift) * s + (0.0 if i < 60 else 60 * 0.1 * 4e-5))
    assert len(rel.pairs) == 50 and rel.pairs[0][0] == pytest.approx(1000.0 + 0.1 * 70)
    s, t = zip(*rel.pairs)
    assert rel.fit == fit_clock(s, t)
    assert rel.fit.drift == pytest.approx(-3e-5, abs=1e-9)


@pytest.mark.parametrize("pair", [(5.0, 1.0), (4.0, 1.0), (math.nan, 1.0), (6.0, math.inf),
                                  (math.inf, 1.0), (6.0, math.nan)])
def test_non_increasing_and_non_finite_pairs_are_refused(pair):
    rel = ClockRelation(window=10)
    assert rel.add(4.0, 0.5) and rel.add(5.0, 1.5)
    before = rel.fit
    assert rel.add(*pair) is False
    assert rel.fit == before and len(rel.pairs) == 2


@pytest.mark.parametrize("bad", [([1.0, math.nan], [1.0, 2.0]), ([1.0, 2.0], [1.0]),
                                 ([], []), ([[1.0]], [[1.0]]), ([1.0, 2.0], [math.inf, 1.0])])
def test_fit_clock_refuses_bad_arrays(bad):
    with pytest.raises(ValueError):
        fit_clock(*bad)


@pytest.mark.parametrize("window", [1, 0, -3, 2.5, True, "10"])
def test_a_bad_window_is_refused(window):
    with pytest.raises(ValueError, match="window="):
        ClockRelation(window=window)

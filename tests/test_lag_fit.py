"""recordings/lag_fit.py: the minimum of the delay check's misfit over its window."""

import math
import random

import pytest

from grazing_control.recordings.lag_fit import GRID, window_minimum


def v_on_a_rugged_plateau(c0: float, half: float, ripple: float, lo: float, hi: float):
    """A narrow V (zero at c0, reaching the plateau ``half`` away) and beyond it a plateau
    with ripples: the shape of the median departure against sample 0's lag."""
    def misfit(c):
        v = min(abs(c - c0) / half, 1.0)
        return v + (ripple * math.sin(40.0 * (c - lo) / (hi - lo) * math.pi)
                    if abs(c - c0) > half else 0.0)
    return misfit


def test_a_narrow_v_beside_a_rugged_plateau_is_found_where_brent_alone_is_misled():
    from scipy.optimize import minimize_scalar

    misfit = v_on_a_rugged_plateau(0.1, 0.5, 0.02, 0.0, 5.0)
    alone = minimize_scalar(misfit, bounds=(0.0, 5.0), method="bounded",
                            options={"xatol": 1e-7})
    assert abs(alone.x - 0.1) > 0.5                     # the failure this module mends
    assert abs(window_minimum(misfit, 0.0, 5.0) - 0.1) < 1e-6


def test_seeded_windows_against_a_dense_grid():
    """2000 seeded landscapes, the V's half width at least a grid cell: the minimiser is
    the V's bottom, to Brent's own tolerance (sqrt(eps) |x| + xatol: scipy's bounded
    method), where Brent over the whole window alone misses it in some of them."""
    from scipy.optimize import minimize_scalar

    rng = random.Random(2026)
    missed = 0
    for _ in range(2000):
        lo = rng.uniform(-1e-2, 1e-2)
        hi = lo + rng.uniform(1e-3, 1e-2)
        cell = (hi - lo) / (GRID - 1)
        c0 = rng.uniform(lo, hi)
        half = cell * rng.uniform(1.0, 8.0)
        misfit = v_on_a_rugged_plateau(c0, half, rng.uniform(0.0, 0.3), lo, hi)
        found = window_minimum(misfit, lo, hi, xatol=1e-12)
        assert abs(found - c0) <= 3.0 * (1.5e-8 * abs(c0) + 1e-12), (lo, hi, c0, half, found)
        alone = minimize_scalar(misfit, bounds=(lo, hi), method="bounded",
                                options={"xatol": 1e-12})
        missed += abs(alone.x - c0) > half
    assert missed > 100


def test_the_coarse_misfit_only_places_the_grid():
    """A cheaper misfit with the same minimum places the grid; the result is the full
    misfit's minimum (here offset by a tiny amount from the coarse one's)."""
    full = v_on_a_rugged_plateau(2.0e-3, 4e-4, 0.1, 0.0, 5e-3)
    coarse = v_on_a_rugged_plateau(2.0e-3 + 2e-5, 4e-4, 0.1, 0.0, 5e-3)
    assert abs(window_minimum(full, 0.0, 5e-3, coarse=coarse, xatol=1e-12) - 2.0e-3) < 1e-10


@pytest.mark.parametrize("lo, hi", [(1.0, 1.0), (2.0, 1.0), (0.0, math.nan)])
def test_an_empty_window_is_refused(lo, hi):
    with pytest.raises(ValueError, match="valid windows have lo < hi"):
        window_minimum(abs, lo, hi)

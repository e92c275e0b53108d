"""The minimum of a one-dimensional misfit over a window: a grid, then a local refinement.

The realtime delay check (:func:`grazing_control.recordings.numbers._delay_check`) fits
sample 0's unknown publish lag c as the minimiser of the median departure of the
periods re-integrated with each correction at its arrival. That median is a narrow V
about the lag (a few tenths of a millisecond wide in a window of 5 ms: measured on the
realtime test's bags, 2.8e-6 at the minimum, 4e-4 0.25 ms off, 1e-3 to 6e-3 beyond,
with flat and rippled stretches). Bounded Brent over the whole window alone could settle
on the far stretch (median 3.3e-3, the lag at the window's end: test_bagtools_replay
failed so, 1 run in 5 to 1 in 3 under load, 2026-11-29); a grid first finds the V, and
Brent inside its two neighbouring cells finds its bottom.
"""

from __future__ import annotations

import numpy as np

__all__ = ["window_minimum"]

#: Grid points over the window (the cells 5 ms / 40 = 0.125 ms wide: inside the V's
#: half width, so the best grid point lies in the V's cell or next to it).
GRID = 41


def window_minimum(misfit, lo: float, hi: float, coarse=None, xatol: float = 1e-7) -> float:
    """The minimiser of ``misfit`` over [lo, hi]: the best of GRID equally spaced points
    (of ``coarse``, a cheaper misfit with the same minimum, where given), then bounded
    Brent on ``misfit`` between that point's neighbours (the better of the two ends of
    the refinement and its result is kept, so a refinement never loses the grid's)."""
    from scipy.optimize import minimize_scalar

    if not lo < hi:
        raise ValueError(f"window ({lo!r}, {hi!r}) is invalid: valid windows have lo < hi")
    grid = np.linspace(lo, hi, GRID)
    rough = coarse if coarse is not None else misfit
    values = np.array([rough(c) for c in grid])
    i = int(np.argmin(values))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, GRID - 1)]
    best = minimize_scalar(misfit, bounds=(a, b), method="bounded", options={"xatol": xatol})
    candidates = [(float(best.fun), float(best.x)), (float(misfit(grid[i])), float(grid[i]))]
    return min(candidates)[1]

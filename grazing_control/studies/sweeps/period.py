"""Detected period of a recorded Pi2 sequence (the p of a p-periodic motion on Pi2).

A motion is p-periodic on Pi2 when z_{k+p} = z_k for every recorded sample; with
rounding and a transient that has not fully died, "=" is |z_{k+p} - z_k| <= tol in
deviation coordinates (x - x**, v - v**), where near-grazing states keep full relative
precision. The detected period is the smallest such p that repeats at least twice in
the record (2 p <= m samples), and 0 when there is none up to ``max_period``:
chaos, a quasi-periodic motion, a period longer than ``max_period``, or a transient
that is still decaying above ``tol``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["detect_period"]


def detect_period(deviation, tol: float = 1e-10, max_period: int | None = None) -> int:
    """Smallest p with max_k |z_{k+p} - z_k| <= tol over the record, or 0.

    Parameters
    ----------
    deviation : (m, 2) array
        Recorded Pi2 samples in deviation coordinates.
    tol : float
        Absolute tolerance on each component, > 0.
    max_period : int, optional
        Largest period tried (default 64, at most m // 2).

    Returns
    -------
    int
        The period, or 0 if none; -1 if the record holds a non-finite value.
    """
    z = np.asarray(deviation, dtype=float)
    m = z.shape[0]
    if m and not np.all(np.isfinite(z)):
        return -1
    top = min(64 if max_period is None else int(max_period), m // 2)
    for p in range(1, top + 1):
        if np.max(np.abs(z[p:] - z[:-p])) <= tol:
            return p
    return 0

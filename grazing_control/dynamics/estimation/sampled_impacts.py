"""Impact times found in the sampled wall coordinate itself (issue 32): the start of an
n-DOF refit's impact times where the model filter's predictions are not trusted
(docs/theory_reidentification.md §6, "n > 1").

The sensor gives x_w at a uniform step h with noise sigma; the wall is at x_w = d, on
the side of the maxima. At an impact the velocity reverses (v+ = -r v-): x_w has a
concave kink, at a smooth maximum it has none. So each local maximum of the samples
(the largest within ``half`` samples either side) is fitted twice over its 2 half + 1
samples:

* smooth: one quintic in t (a cubic left the higher mode's ringing over the 17
  samples: smooth maxima then gave kinks of 30 to 100 sigma^2, the quintic 0.1 to 3);
* kinked: two cubics that meet at tau (continuous position, every other coefficient
  free on each side), for tau on a grid over the two sample intervals either side of
  the maximum (linear least squares at each tau; the best tau wins).

A maximum is an impact when the kink explains the samples by more than
:data:`KINK_CHI2` sigma^2 of the residual sum of squares (sigma from the samples'
fourth differences: the motion's own fourth derivative there is ~1e-6 of the noise's
at T/200), the slope falls across it (v- > v+) and its apex (the position at tau) is
within :data:`WALL_SPREAD` sigma of the highest such apex (every impact is at the
wall); tau is its time. A kink within 1.5 h of a correction is not counted (a kick on
the wall coordinate is a kink too).

What it cannot see: a grazing impact of small velocity. The kink's chi^2 grows as
v-^2 (measured on the two-mass scene at T/200, sigma 1e-4: 6000 at v- = 0.07,
2.7e5 at 0.22), so impacts below v- ~ 0.01 there are not found; such an impact changes
the motion little, and a fit that misses one ends with a residual that says so.
"""

from __future__ import annotations

import numpy as np

__all__ = ["KINK_CHI2", "WALL_SPREAD", "HALF_WINDOW", "noise_of", "kinked_fits",
           "impacts_from_samples"]

#: The least drop of the residual sum of squares, in sigma^2, that a kink must give over
#: a smooth cubic (about 10 standard errors of the kink's slope change).
KINK_CHI2 = 100.0
#: How far below the highest kink's apex, in sigma, a kink may reach and be an impact
#: (every impact is at the wall; measured on the two-mass scene: the apexes of 20 impacts
#: within 3.6 sigma of one another, a smooth maximum's kink 1000 sigma below them).
WALL_SPREAD = 30.0
#: Samples either side of a maximum that its fits use.
HALF_WINDOW = 8
#: Grid points of tau per sample interval.
_GRID = 40


def noise_of(x) -> float:
    """The samples' noise std from their fourth differences (variance 70 sigma^2),
    by the median absolute deviation."""
    d4 = np.diff(np.asarray(x, float), 4)
    if d4.size < 8:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d4 - np.median(d4))) / np.sqrt(70.0))


def _smooth_rss(u, y) -> float:
    B = np.vander(u, 6)
    coef, *_ = np.linalg.lstsq(B, y, rcond=None)
    return float(np.sum((y - B @ coef) ** 2))


def kinked_fits(u, y, taus):
    """For each tau of ``taus``: (rss, slope before, slope after, position at tau) of the
    two cubics that meet at tau (module docstring), as four arrays. One least-squares
    problem per tau, all at once: each design (len(u) x 7) by a Householder QR (NumPy's
    stacked ``qr``) and R c = Q^T y; the residual sums formed from the residuals
    themselves. tests/test_sampled_impacts.py holds them to a ``lstsq`` per tau."""
    s = u[None, :] - np.asarray(taus, float)[:, None]
    left = s < 0.0
    cols = [np.ones_like(s)]
    for p in (1, 2, 3):
        sp = s ** p
        cols.append(np.where(left, sp, 0.0))
        cols.append(np.where(left, 0.0, sp))
    B = np.stack(cols, axis=-1)
    q, r = np.linalg.qr(B)
    coef = np.linalg.solve(r, np.einsum("kmj,m->kj", q, y)[..., None])[..., 0]
    res = y[None, :] - np.einsum("kmj,kj->km", B, coef)
    return np.sum(res * res, axis=1), coef[:, 1], coef[:, 2], coef[:, 0]


def impacts_from_samples(t, x, corrections=(), *, sigma: float | None = None,
                         half: int = HALF_WINDOW) -> np.ndarray:
    """The impact times found in the samples ``(t, x)`` of the wall coordinate (module
    docstring), sorted; ``corrections``: the instants of the kicks (no impact counted
    within 1.5 steps of one); ``sigma``: the noise std (None: :func:`noise_of`)."""
    t, x = np.asarray(t, float), np.asarray(x, float)
    if t.size < 2 * half + 1:
        return np.zeros(0)
    h = float(np.median(np.diff(t)))
    sigma = noise_of(x) if sigma is None else float(sigma)
    if not np.isfinite(sigma) or sigma <= 0.0:
        sigma = 1e-12 * max(1.0, float(np.max(np.abs(x))))
    kicks = np.asarray(corrections, float)
    out = []
    j = half
    while j < t.size - half:
        w = slice(j - half, j + half + 1)
        if x[j] < np.max(x[w]) or x[j] <= x[j - 1]:
            j += 1
            continue
        u, y = t[w] - t[j], x[w] - x[j]
        smooth = _smooth_rss(u, y)
        lo, hi = u[half - 2], u[half + 2]
        taus = np.linspace(lo, hi, 4 * _GRID + 1)[1:-1]
        fits = kinked_fits(u, y, taus)
        i = int(np.argmin(fits[0]))       # the first of equal sums, as a scan keeps
        rss, before, after, apex = (float(f[i]) for f in fits)
        tau = float(taus[i])
        at = t[j] + tau
        if ((smooth - rss) / sigma ** 2 > KINK_CHI2 and before > after
                and not (kicks.size and np.min(np.abs(kicks - at)) < 1.5 * h)):
            out.append((at, apex + x[j]))
            j += half
        else:
            j += 1
    if not out:
        return np.zeros(0)
    at, apex = np.array(out).T
    return at[apex >= np.max(apex) - WALL_SPREAD * sigma]

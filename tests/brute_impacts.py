"""Brute-force first impacts on a dense grid, vectorised over many cases (numpy).

The yardstick of the differential test of the certified search
(:func:`grazing_control.oscillator.impact.next_impact`). It shares no code with the core: the
closed-form flow is written again here (spec section 1) in deviation coordinates,

    z_x(t) = e^{-zeta t} (c1 cos(omega_d t) + c2 sin(omega_d t)),   c1 = dx0,
    c2 = (dv0 + zeta dx0) / omega_d,
    g(t) = z_x(t) - Delta d - 2 a sin^2(psi / 2),   v(t) = -a omega sin psi + z_v(t),
    psi = tau0 + omega t - phi,

and the search is the naive one: ``samples`` + 1 grid points per case; in each cell
an upward sign change of g brackets a root, and a maximum of g inside the cell (v going
from + to -, or v rising above 0 and back inside the cell, found from the sign change
of the acceleration) is located by bisection on v and tested, so that a grazing hump
whose g is negative at every grid point is still seen. Roots are refined by 80
bisections. Assumption (true for cells much shorter than the shortest period,
2 pi / max(1, omega)): the acceleration changes sign at most once per cell.

The n-DOF model's cases (:class:`NdofCases`, the yardstick of
:func:`grazing_control.oscillator.ndof.impact.next_impact`) write its periodic response and
modal flow again the same way (docs/ndof_model.md, docs/theory_ndof_flow.md)::

    (K - omega^2 M + i omega C) X = f,  d* = |X_w|,  tau* = -arg X_w,
    z(t) = V e^{Lambda t} V^-1 z0  (A = V Lambda V^-1, A = [[0, I], [-M^-1 K, -M^-1 C]]),
    g(t) = Re sum_k c_k e^{lambda_k t} - Delta d - 2 d* sin^2(psi / 2),
    c_k = V_wk (V^-1 z0)_k,  psi = tau0 + omega t - tau*,

and go through the same search (cells much shorter than the fastest mode's and the
forcing's periods; cases of different n padded with zero modes).

Each maximum of g found is returned with the case, so that the test can tell the
ambiguous cases (a maximum within the rounding of the gap of 0) from real
disagreements.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Cases", "NdofCases", "first_impacts"]


class Cases:
    """Arrays (one entry per case) of parameters and start states."""

    def __init__(self, zeta, omega, delta_d, tau0, dx0, dv0, horizon):
        self.zeta = np.asarray(zeta, float)
        self.omega = np.asarray(omega, float)
        self.delta_d = np.asarray(delta_d, float)
        self.tau0 = np.asarray(tau0, float)
        self.dx0 = np.asarray(dx0, float)
        self.dv0 = np.asarray(dv0, float)
        self.horizon = np.asarray(horizon, float)
        w = self.omega
        self.amp = 1.0 / np.hypot(1.0 - w * w, 2.0 * self.zeta * w)
        self.lag = np.arctan2(2.0 * self.zeta * w, 1.0 - w * w)
        self.wd = np.sqrt(1.0 - self.zeta ** 2)
        self.c2 = (self.dv0 + self.zeta * self.dx0) / self.wd

    def take(self, idx):
        return Cases(self.zeta[idx], self.omega[idx], self.delta_d[idx], self.tau0[idx],
                     self.dx0[idx], self.dv0[idx], self.horizon[idx])

    def eval(self, t, idx=slice(None)):
        """(g, v, acc) at times t (shape (n,) or (n, m)) for the cases idx."""
        t = np.asarray(t, float)
        shape = (-1,) + (1,) * (t.ndim - 1)
        z, w, dd = self.zeta[idx].reshape(shape), self.omega[idx].reshape(shape), \
            self.delta_d[idx].reshape(shape)
        amp, lag, wd = self.amp[idx].reshape(shape), self.lag[idx].reshape(shape), \
            self.wd[idx].reshape(shape)
        c1, c2, tau0 = self.dx0[idx].reshape(shape), self.c2[idx].reshape(shape), \
            self.tau0[idx].reshape(shape)
        e = np.exp(-z * t)
        c, s = np.cos(wd * t), np.sin(wd * t)
        zx = e * (c1 * c + c2 * s)
        zv = e * ((wd * c2 - z * c1) * c - (wd * c1 + z * c2) * s)
        psi = tau0 + w * t - lag
        g = zx - dd - 2.0 * amp * np.sin(0.5 * psi) ** 2
        v = -amp * w * np.sin(psi) + zv
        acc = -amp * w * w * np.cos(psi) - 2.0 * z * zv - zx
        return g, v, acc


class NdofCases:
    """Per case: the wall coordinate's modal coefficients c_k, eigenvalues lambda_k (padded
    to a common count), d*, tau*, omega, Delta d, tau0 and the horizon."""

    def __init__(self, lam, c, d_star, tau_star, omega, delta_d, tau0, horizon):
        self.lam, self.c = np.asarray(lam, complex), np.asarray(c, complex)
        self.d_star, self.tau_star = np.asarray(d_star, float), np.asarray(tau_star, float)
        self.omega, self.delta_d = np.asarray(omega, float), np.asarray(delta_d, float)
        self.tau0, self.horizon = np.asarray(tau0, float), np.asarray(horizon, float)

    @classmethod
    def build(cls, cases, modes: int = 6):
        """From (M, C, K, f, omega, i_w, delta_d, tau0, z0, horizon) tuples."""
        rows = []
        for M, C, K, f, omega, i_w, dd, tau0, z0, horizon in cases:
            n = len(M)
            X = np.linalg.solve(K - omega ** 2 * M + 1j * omega * C, np.asarray(f, complex))
            A = np.block([[np.zeros((n, n)), np.eye(n)],
                          [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
            lam, V = np.linalg.eig(A)
            c = V[i_w] * np.linalg.solve(V, np.asarray(z0, complex))
            pad = modes - 2 * n
            rows.append((np.concatenate([lam, np.zeros(pad)]), np.concatenate([c, np.zeros(pad)]),
                         abs(X[i_w]), (-np.angle(X[i_w])) % (2 * np.pi), omega, dd, tau0, horizon))
        cols = list(zip(*rows))
        return cls(np.array(cols[0]), np.array(cols[1]), *cols[2:])

    def take(self, idx):
        return NdofCases(self.lam[idx], self.c[idx], self.d_star[idx], self.tau_star[idx],
                         self.omega[idx], self.delta_d[idx], self.tau0[idx], self.horizon[idx])

    def eval(self, t, idx=slice(None)):
        """(g, v, acc) at times t (shape (m,) or (m, s)) of the cases idx."""
        t = np.asarray(t, float)
        shape = (-1,) + (1,) * (t.ndim - 1)
        lam, c = self.lam[idx], self.c[idx]
        d, w = self.d_star[idx].reshape(shape), self.omega[idx].reshape(shape)
        psi = self.tau0[idx].reshape(shape) + w * t - self.tau_star[idx].reshape(shape)
        e = c.reshape(lam.shape + (1,) * (t.ndim - 1)) * np.exp(
            lam.reshape(lam.shape + (1,) * (t.ndim - 1)) * t[:, None, ...])
        lam_b = lam.reshape(lam.shape + (1,) * (t.ndim - 1))
        zx = e.sum(axis=1).real
        zv = (lam_b * e).sum(axis=1).real
        za = (lam_b * lam_b * e).sum(axis=1).real
        g = zx - self.delta_d[idx].reshape(shape) - 2.0 * d * np.sin(0.5 * psi) ** 2
        v = -d * w * np.sin(psi) + zv
        acc = -d * w * w * np.cos(psi) + za
        return g, v, acc


def _bisect(cases, idx, lo, hi, which, up, iters=80):
    """Bisection on component ``which`` (0: g, 1: v, 2: acc) of each case idx in [lo, hi];
    the component goes from < 0 to >= 0 (up) or from > 0 to <= 0 (not up)."""
    lo, hi = lo.copy(), hi.copy()
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        val = cases.eval(mid, idx)[which]
        right = val >= 0.0 if up else val <= 0.0
        hi = np.where(right, mid, hi)
        lo = np.where(right, lo, mid)
    return hi


def first_impacts(cases: Cases, samples: int = 4096):
    """First impact time of every case (nan: none) and its maxima of g.

    Returns
    -------
    times : (n,) array, nan where no impact in (0, horizon].
    maxima : list of (case, time, g) of every interior maximum of g found before the
        first impact (all of them when there is none).
    """
    n = cases.horizon.size
    frac = np.linspace(0.0, 1.0, samples + 1)
    t = cases.horizon[:, None] * frac[None, :]
    g, v, acc = cases.eval(t)
    lo, hi = t[:, :-1], t[:, 1:]
    first = np.full(n, np.inf)
    # candidate brackets (case, lo, hi) of a first root with g(lo) < 0 <= g(hi)
    cand_case, cand_lo, cand_hi = [], [], []
    rows, cols = np.nonzero((g[:, :-1] < 0.0) & (g[:, 1:] >= 0.0))
    cand_case.append(rows), cand_lo.append(lo[rows, cols]), cand_hi.append(hi[rows, cols])
    # maxima of g: v from + to - in the cell ...
    mr, mc = np.nonzero((v[:, :-1] > 0.0) & (v[:, 1:] <= 0.0))
    m_case, m_lo, m_hi, m_cell = [mr], [lo[mr, mc]], [hi[mr, mc]], [lo[mr, mc]]
    # ... or v rising above 0 and back inside the cell (acc from + to -, v <= 0 at both ends)
    ar, ac = np.nonzero((acc[:, :-1] > 0.0) & (acc[:, 1:] <= 0.0)
                        & (v[:, :-1] <= 0.0) & (v[:, 1:] <= 0.0))
    if ar.size:
        tv = _bisect(cases, ar, lo[ar, ac], hi[ar, ac], 2, up=False)
        up = cases.eval(tv, ar)[1] > 0.0
        m_case.append(ar[up]), m_lo.append(tv[up]), m_hi.append(hi[ar[up], ac[up]])
        m_cell.append(lo[ar[up], ac[up]])
    m_case, m_lo, m_hi, m_cell = (np.concatenate(a) for a in (m_case, m_lo, m_hi, m_cell))
    maxima = []
    if m_case.size:
        tm = _bisect(cases, m_case, m_lo, m_hi, 1, up=False)
        gm = cases.eval(tm, m_case)[0]
        maxima = list(zip(m_case.tolist(), tm.tolist(), gm.tolist()))
        hit = gm >= 0.0
        # the root lies between the cell's start (g < 0 there, else an earlier root) and tm
        ok = hit & (cases.eval(m_cell, m_case)[0] < 0.0)
        cand_case.append(m_case[ok]), cand_lo.append(m_cell[ok]), cand_hi.append(tm[ok])
    c_case, c_lo, c_hi = (np.concatenate(a) for a in (cand_case, cand_lo, cand_hi))
    if c_case.size:
        roots = _bisect(cases, c_case, c_lo, c_hi, 0, up=True)
        np.minimum.at(first, c_case, roots)
    times = np.where(np.isfinite(first), first, np.nan)
    maxima = [m for m in maxima if not m[1] > first[m[0]]]
    return times, maxima

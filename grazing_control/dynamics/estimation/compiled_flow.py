"""The per-sample evaluation of :func:`grazing_control.dynamics.estimation.motion.trajectory`,
compiled by numba (issue 30: the controller's estimate at each section).

``trajectory`` finds the events of a period (start, kick, pulse edges, impacts) with the
exact flow, then evaluates the deviation and its Jacobian at every sample time s_j from
the last event before it: z(s_j) = Phi(s_j - s_e) z_e (shifted by a pulse's force F:
Phi (z_e - F e1) + F e1) and d z / d z0 = Phi(s_j - s_e) M_e. In NumPy that is a dozen
array operations on ~150 samples, most of the model filter's time once the flow is the
compiled kernel's. Here the same floating point operations, in the same order, as the
NumPy code they replace (``searchsorted``, ``clip``, ``einsum``, ``outer``: each output a
sum of two products, 0.0 + first + second, as ``einsum`` sums them: its zero start makes
a sum of two -0.0 products +0.0), so the results are the same bit for bit (tests/test_estimation_compiled.py). The transcendental functions of
Phi stay NumPy's (:func:`~grazing_control.dynamics.estimation.motion.phi_rows`):
NumPy's vectorised ``exp`` differs from libm's, which numba would call, in the last bit
of ~5 % of arguments.

Only this module's functions are compiled here and none calls another file's, so numba's
on-disk cache (``cache=True``, keyed on this file) never loads stale code
(oscillator/kernel/compiled.py, module docstring).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["event_offsets", "flow_at_samples"]

jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@jit
def event_offsets(times, s):
    """For each sample time s_j, the last event strictly before it (the index i of
    ``np.clip(np.searchsorted(times, s, "left") - 1, 0, len(times) - 1)``) and
    s_j - times[i]."""
    n, e = s.size, times.size
    idx = np.empty(n, np.int64)
    hh = np.empty(n)
    for j in range(n):
        x = s[j]
        if x != x:                  # NaN sorts after everything (NumPy's order)
            lo = e
        else:
            lo, hi = 0, e
            while lo < hi:
                mid = (lo + hi) >> 1
                if times[mid] < x:
                    lo = mid + 1
                else:
                    hi = mid
        i = min(max(lo - 1, 0), e - 1)
        idx[j] = i
        hh[j] = x - times[i]
    return idx, hh


@jit
def flow_at_samples(e, c, sn, zeta, wd, idx, zs, ms, forces, gs, shifted, wall):
    """(z (n, 2), jac (n, 2, 2), g (n, 2)) at the samples from their events ``idx``:
    Phi = ``phi_rows(zeta, h)`` from NumPy's e^{-zeta h}, cos(wd h) and sin(wd h)
    (``e``, ``c``, ``sn``; the rest of phi_rows here, element by element as there), then
    ``einsum("nij,nj->ni", phi, z_e)``, through the force where ``shifted`` (any event
    in a pulse: z_e - F (1, 0), then + F (1, 0), as ``np.outer(F, (1.0, 0.0))``),
    ``einsum("nij,njk->nik", phi, M_e)`` and, with ``wall``, ``einsum(phi, g_e)``
    (else g is empty)."""
    n = idx.size
    out = np.empty((n, 2))
    jac = np.empty((n, 2, 2))
    g = np.empty((n if wall else 0, 2))
    for j in range(n):
        i = idx[j]
        ej, sj = e[j], sn[j] / wd
        a = ej * (c[j] + zeta * sj)
        b = ej * sj
        c_ = -ej * sj
        d = ej * (c[j] - zeta * sj)
        z0, z1 = zs[i, 0], zs[i, 1]
        if shifted:
            f = forces[i]
            z0 = z0 - f * 1.0
            z1 = z1 - f * 0.0
            out[j, 0] = ((0.0 + a * z0) + b * z1) + f * 1.0
            out[j, 1] = ((0.0 + c_ * z0) + d * z1) + f * 0.0
        else:
            out[j, 0] = (0.0 + a * z0) + b * z1
            out[j, 1] = (0.0 + c_ * z0) + d * z1
        m00, m01, m10, m11 = ms[i, 0, 0], ms[i, 0, 1], ms[i, 1, 0], ms[i, 1, 1]
        jac[j, 0, 0] = (0.0 + a * m00) + b * m10
        jac[j, 0, 1] = (0.0 + a * m01) + b * m11
        jac[j, 1, 0] = (0.0 + c_ * m00) + d * m10
        jac[j, 1, 1] = (0.0 + c_ * m01) + d * m11
        if wall:
            g0, g1 = gs[i, 0], gs[i, 1]
            g[j, 0] = (0.0 + a * g0) + b * g1
            g[j, 1] = (0.0 + c_ * g0) + d * g1
    return out, jac, g

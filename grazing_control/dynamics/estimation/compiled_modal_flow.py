"""The per-sample evaluation of the n-DOF model filter's exact motion
(:func:`grazing_control.dynamics.estimation.motion.modal_trajectory`), compiled by numba
(issue 32: the rig of n masses at physical speed).

``modal_trajectory`` finds the events of a period (start, pulse edges, impacts) with the
exact n-DOF flow, then evaluates the deviation and its Jacobian at every sample time s_j
from the last event before it: Phi(h) = Re(V e^{Lambda h} U), z(s_j) = Phi(s_j - s_e)
z_e (+ sigma F in a pulse) and d z / d z0 = Phi(s_j - s_e) M_e. In NumPy that is a
complex ``einsum`` building a (m, 2n, 2n) array and two more over it (~500 samples a
period at the two-mass rig's 2 kHz: 1.5 ms of a 2.8 ms trajectory, measured in
benchmarks/bench_stream_estimator.py ``--scene masses``). Here the same floating point
operations in the same order, so the results are the same bit for bit
(tests/test_estimation_compiled.py):

* Phi's entries as ``einsum("ik,mk,kj->mij", V, e, U).real``: for each (i, j) the complex
  products (V_ik e_k) U_kj summed over k from a zero start (NumPy's generic
  sum-of-products loop, the one it runs for three complex operands);
* z and the Jacobian as ``einsum("mij,mj->mi")`` and ``einsum("mij,mjk->mik")`` over
  that ``.real`` view: sequential sums over j from a zero start (the view is strided,
  so NumPy takes its strided loop, not its SIMD dot product: checked by the test on the
  outputs, which it must match);
* the pulse's shift added after, as ``out + shifts[idx]``.

The complex exponentials e^{lambda_k h_j} stay NumPy's (``np.exp`` of the same array as
the pure path's): NumPy's and libm's exp, which numba would call, may differ in the
last bit (as in :mod:`.compiled_flow`). The samples' events and offsets are
:func:`.compiled_flow.event_offsets` (NumPy's search, tested there).

Only this module's functions are compiled here and none calls another file's, so numba's
on-disk cache (``cache=True``, keyed on this file) never loads stale code
(oscillator/kernel/compiled.py, module docstring).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["modal_flow_at_samples"]

jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@jit
def modal_flow_at_samples(modes, e, inverse, idx, zs, ms, shifts, shifted):
    """(z (m, 2n), jac (m, 2n, 2n)) at the samples from their events ``idx``: Phi_j =
    Re(sum_k (modes[:, k] e[j, k]) inverse[k, :]) (``e`` = e^{lambda_k h_j} from NumPy),
    z_j = Phi_j zs[idx_j] (+ shifts[idx_j] where ``shifted``: a pulse in the period),
    jac_j = Phi_j ms[idx_j]; each in the order of the NumPy code it replaces (module
    docstring)."""
    m, n2, nk = idx.size, modes.shape[0], e.shape[1]
    out = np.empty((m, n2))
    jac = np.empty((m, n2, n2))
    phi = np.empty((n2, n2))
    re1 = np.empty(nk)
    im1 = np.empty(nk)
    for a in range(m):
        i_e = idx[a]
        for i in range(n2):
            for k in range(nk):     # V_ik e_k, the same for every j
                x, y = modes[i, k], e[a, k]
                re1[k] = x.real * y.real - x.imag * y.imag
                im1[k] = x.real * y.imag + x.imag * y.real
            for j in range(n2):
                acc = 0.0
                for k in range(nk):
                    w = inverse[k, j]
                    acc = (re1[k] * w.real - im1[k] * w.imag) + acc
                phi[i, j] = acc
        for i in range(n2):
            acc = 0.0
            for j in range(n2):
                acc = acc + phi[i, j] * zs[i_e, j]
            out[a, i] = acc
            for c in range(n2):
                acc = 0.0
                for j in range(n2):
                    acc = acc + phi[i, j] * ms[i_e, j, c]
                jac[a, i, c] = acc
        if shifted:
            for i in range(n2):
                out[a, i] = out[a, i] + shifts[i_e, i]
    return out, jac

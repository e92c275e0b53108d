"""Sticking of the wall coordinate of the n-DOF oscillator: the constrained flow and its
certified release (issue 32; derivation in docs/theory_ndof.md, section 16).

While the wall coordinate rests on the wall (x_w = d, v_w = 0) the wall supplies the
contact force lambda e_w, and the other coordinates y (index set ``others``, n - 1 of
them) move by the constrained equations

    M_yy y'' + C_yy y' + K_yy y = f_y cos tau - K_yw d,                        (S1)
    lambda = (f_w - s f_y) cos tau - (K_ww - s K_yw) d - (K_wy - s K_yy) y
             - (C_wy - s C_yy) y',   s = M_wy M_yy^-1,                          (S2)

(S2) the row w of the equations of motion with y'' from (S1). lambda > 0 pushes x_w into
the wall; lambda has the sign of the free acceleration of x_w at that state (section 16),
so for n = 1 it is the 1-DOF wall force cos tau - d. (S1) is linear with forcing: its
solution is the periodic response Y_p(tau) = (Re(Y e^{i tau}) + y_c, Re(i omega Y
e^{i tau})), (K_yy - omega^2 M_yy + i omega C_yy) Y = f_y, K_yy y_c = -K_yw d, plus the
modal flow e^{A_r h} of A_r = [[0, I], [-M_yy^-1 K_yy, -M_yy^-1 C_yy]]: closed form,
as the free flow (oscillator/ndof/flow.py). The release is the first zero of lambda,
found by a certified subdivision (:meth:`StuckFlow.release`).
"""

from __future__ import annotations

import cmath
import math
from functools import lru_cache

import numpy as np

from grazing_control.oscillator.params import ParameterError

from .flow import MAX_CONDITION, NdofFlow

__all__ = ["StuckFlow", "stuck_flow"]

TWO_PI = 2.0 * math.pi
_EPS = 2.0 ** -52
#: A stretch of positive contact force shorter than this fraction of T, on which lambda
#: stays within the bound of its rounding and curvature, counts as no release: the force
#: touches zero there to within ~(1e-9 T)^2 |lambda''| (section 16, "Release").
_TOUCH = 1e-9


class StuckFlow:
    """The constrained motion of an :class:`NdofFlow`'s model with x_w held at the wall.

    Build it with :func:`stuck_flow` (cached per flow). States are the physical reduced
    states Y = (y, y') of the other coordinates, shape (2(n - 1),).

    Raises
    ------
    ParameterError
        (at construction) K_yy singular (the other coordinates have no static
        equilibrium with x_w held), omega at an undamped resonance of (S1), or a
        (nearly) defective A_r.
    """

    def __init__(self, flow: NdofFlow):
        m = flow.model
        n, w = m.n, m.i_w
        self.flow = flow
        self.others = np.array([i for i in range(n) if i != w], dtype=int)
        o = self.others
        p = n - 1
        self.p = p
        self.d = flow.d_star + m.delta_d
        omega = m.omega
        Myy, Cyy, Kyy = (a[np.ix_(o, o)] for a in (m.M, m.C, m.K))
        s = np.linalg.solve(Myy.T, m.M[w, o]) if p else np.zeros(0)   # s = M_wy M_yy^-1
        self.g_f = float(m.f[w] - s @ m.f[o])
        self.g_d = float(m.K[w, w] - s @ m.K[o, w])
        self.ell = np.concatenate([m.K[w, o] - s @ Kyy, m.C[w, o] - s @ Cyy])
        if p:
            if np.linalg.cond(Kyy) > 1e14:
                raise ParameterError(
                    f"K is invalid for sticking: with x{w} held at the wall the other "
                    f"coordinates have no static equilibrium (K without row and column {w} "
                    f"is singular)")
            D = Kyy - omega * omega * Myy + 1j * omega * Cyy
            if np.linalg.cond(D) > 1e14:
                raise ParameterError(f"omega={omega!r} is invalid for sticking: at an undamped "
                                     f"resonance of the motion with x{w} held at the wall")
            self.Y = np.linalg.solve(D, m.f[o].astype(complex))
            self.y_c = np.linalg.solve(Kyy, -m.K[o, w] * self.d)
            A = np.zeros((2 * p, 2 * p))
            A[:p, p:] = np.eye(p)
            A[p:, :p] = -np.linalg.solve(Myy, Kyy)
            A[p:, p:] = -np.linalg.solve(Myy, Cyy)
            lam, V = np.linalg.eig(A)
            cond = float(np.linalg.cond(V))
            if not cond <= MAX_CONDITION:
                raise ParameterError(
                    f"C, K are invalid for sticking: the motion with x{w} held at the wall "
                    f"is (nearly) defective, cond(V) = {cond:.3g} > {MAX_CONDITION:.0e}")
            self.A = A
            self.eigenvalues, self.modes, self.inverse = lam, V, np.linalg.inv(V)
        else:
            self.Y = self.y_c = np.zeros(0)
            self.A = np.zeros((0, 0))
            self.eigenvalues, self.modes, self.inverse = (np.zeros(0, complex),
                                                          np.zeros((0, 0)), np.zeros((0, 0)))
        # lambda along Y_p: Re(Lambda e^{i tau}) + lambda_c
        self.Lam = complex(self.g_f - self.ell[:p] @ self.Y - self.ell[p:] @ (1j * omega * self.Y)) \
            if p else complex(self.g_f)
        self.lam_c = float(-self.g_d * self.d - (self.ell[:p] @ self.y_c if p else 0.0))

    # ------------------------------------------------------------------ the flow
    def transition(self, h: float) -> np.ndarray:
        """e^{A_r h}, (2(n - 1), 2(n - 1))."""
        if not self.p:
            return np.zeros((0, 0))
        return ((self.modes * np.exp(self.eigenvalues * float(h))) @ self.inverse).real

    def particular(self, tau: float) -> np.ndarray:
        """Y_p(tau), the periodic response of (S1) (with its constant part y_c)."""
        e = self.Y * np.exp(1j * float(tau))
        return np.concatenate([e.real + self.y_c, (1j * self.flow.model.omega * e).real])

    def force(self, tau: float, Y) -> float:
        """Contact force lambda (S2) at phase tau and reduced state Y."""
        return float(self.g_f * math.cos(tau) - self.g_d * self.d - self.ell @ np.asarray(Y))

    def state(self, tau: float, Y0, h: float) -> np.ndarray:
        """Reduced state after time h on the wall from Y0 at phase tau."""
        om = self.flow.model.omega
        return self.particular(tau + om * h) + self.transition(h) @ (np.asarray(Y0) - self.particular(tau))

    # ------------------------------------------------- between full and reduced
    def reduce(self, tau: float, z) -> np.ndarray:
        """Reduced physical state Y of the full deviation z at phase tau."""
        X = self.flow.to_physical(tau, z)
        n = self.flow.n
        return np.concatenate([X[self.others], X[n + self.others]])

    def expand(self, tau: float, Y) -> np.ndarray:
        """Full deviation z of the state on the wall at rest, others at Y, phase tau."""
        flow = self.flow
        n, w = flow.n, flow.model.i_w
        Xp = flow.particular(tau)
        z = np.zeros(2 * n)
        z[self.others] = Y[:self.p] - Xp[self.others]
        z[n + self.others] = Y[self.p:] - Xp[n + self.others]
        z[w], z[n + w] = flow.on_wall(tau)
        return z

    def embedded(self, h: float) -> np.ndarray:
        """d z(end) / d z(start) of a stuck stretch of length h, (2n, 2n): the wall
        coordinate's perturbations die, the others' flow by e^{A_r h} (section 16)."""
        n = self.flow.n
        rows = np.concatenate([self.others, n + self.others])
        out = np.zeros((2 * n, 2 * n))
        out[np.ix_(rows, rows)] = self.transition(h)
        return out

    # ------------------------------------------------------------- the release
    def release(self, tau: float, Y0, start: float, horizon: float) -> float | None:
        """First h in [start, horizon] with lambda(h) <= 0 along the stuck flow from Y0 at
        phase tau, or None (still stuck at the horizon). Certified (section 16): lambda is
        Re(Lambda e^{i(tau + omega h)}) + lambda_c + sum_k Re(c_k e^{mu_k h}), so
        |lambda''| <= |Lambda| omega^2 + sum |c_k| |mu_k|^2 e^{Re(mu_k) h}; a piece on
        which the chord minus that curvature allowance stays above the rounding has no
        zero, other pieces are bisected; a sign change is bisected to adjacent floats."""
        om = self.flow.model.omega
        zeta0 = np.asarray(Y0, dtype=float) - self.particular(tau)
        if self.p:
            c = -(self.ell @ self.modes) * (self.inverse @ zeta0)
        else:
            c = np.zeros(0, complex)
        terms = [(complex(mu), complex(ck)) for mu, ck in zip(self.eigenvalues, c)]
        Lam, lam_c = self.Lam, self.lam_c
        H = float(horizon)

        def lam(h):
            v = (Lam * cmath.exp(1j * (tau + om * h))).real + lam_c
            for mu, ck in terms:
                v += (ck * cmath.exp(mu * h)).real
            return v

        grow = [math.exp(max(mu.real, 0.0) * H) for mu, _ in terms]
        err = 16.0 * _EPS * (abs(Lam) * (2.0 + abs(tau) + om * H) + abs(lam_c)
                             + sum(abs(ck) * g * (2.0 + abs(mu) * H) for (mu, ck), g in zip(terms, grow))
                             + abs(self.g_d * self.d) + abs(self.g_f)
                             + float(np.abs(self.ell) @ np.abs(np.asarray(Y0))))

        def curvature(a):
            return abs(Lam) * om * om + sum(abs(ck) * abs(mu) ** 2 * math.exp(mu.real * a) * g
                                            for (mu, ck), g in zip(terms, grow))

        touch = _TOUCH * self.flow.model.period

        def sign_change(a, b):      # lambda(a) > 0 >= lambda(b): bisect to adjacent floats
            while True:
                mid = 0.5 * (a + b)
                if mid <= a or mid >= b:
                    return b
                if lam(mid) > 0.0:
                    a = mid
                else:
                    b = mid

        def first(a, b, la, lb):
            if la <= 0.0:
                return a
            if lb <= 0.0:
                # the first zero: none before a sign change inside [a, mid] either
                mid = 0.5 * (a + b)
                if b - a > touch and mid > a:
                    lm = lam(mid)
                    r = first(a, mid, la, lm)
                    return r if r is not None else first(mid, b, lm, lb)
                return sign_change(a, b)
            if min(la, lb) - curvature(a) * (b - a) ** 2 / 8.0 > err:
                return None
            if b - a <= touch:
                return None         # touches zero within the rounding: no release
            mid = 0.5 * (a + b)
            lm = lam(mid)
            r = first(a, mid, la, lm)
            return r if r is not None else first(mid, b, lm, lb)

        a = float(start)
        if a >= H:
            return None if lam(H) > 0.0 else H
        rho = max([om] + [abs(mu) for mu, _ in terms])
        step = min(self.flow.model.period / 16.0, 0.25 * math.pi / rho)
        count = max(1, int(math.ceil((H - a) / step)))
        la = lam(a)
        for k in range(1, count + 1):
            b = H if k == count else float(start) + k * ((H - float(start)) / count)
            lb = lam(b)
            r = first(a, b, la, lb)
            if r is not None:
                return r
            a, la = b, lb
        return None


@lru_cache(maxsize=64)
def stuck_flow(flow: NdofFlow) -> StuckFlow:
    """The :class:`StuckFlow` of ``flow``, built once per flow (NdofFlow hashes by
    identity)."""
    return StuckFlow(flow)

"""Multiple-shooting least squares for the n-DOF model's modal parameters
(docs/theory_identification.md, section 11; the quantities: :mod:`.modal`).

As the 1-DOF fit (:mod:`.fit`), with the arc's state the 2n modal numbers (alpha_k,
beta_k) of the wall coordinate's deviation from its periodic response. Unknowns: the
global vector g (:class:`.modal.ModalLayout`), every arc's modal state at its start and
every impact's time (bounded by the samples around it; corrections act at their
recorded instants). Residuals, in the recording's units:

* data: x_w(t_j) - x~_j, v_w(t_j) - v~_j where measured, recorded v-, v+ at impacts;
* constraints, weight W: at an impact b the arc before reaches the wall, W (x_w - d),
  and the modal state jumps by the kick Delta v = -(1 + r) v-:
  W (a_b - e^{A_m h} a_{b-1} - Delta v (c, s)) (2n rows); at a correction of recorded
  size dv the jump dv (c^a, s^a) (the wall's own (c, s) when the kick is on the wall
  coordinate).

The constraints are exact in the model; W is raised 1, 1e2, 1e4 as in the 1-DOF fit.
Jacobian by complex step, the arcs' parameters in two colours (even and odd arcs), per
state component and time: (4n + 2 + size of g) evaluations of the residual. Standard
errors sigma^2 (J^T J)^{-1} from the SVD of J (:func:`.fit._covariance`).

The initial guess (:func:`initial_modal`): the eigenvalues from the exact ARX(2n)
recursion of the sampled free flight (the 1-DOF ARX(2) of section 5 with 2n roots
e^{lambda_k q h}, on every q-th sample, q h at most T/16 so that modes up to 8 omega
stay below the Nyquist limit), then the
periodic response and each arc's modal state by linear least squares, then d, r and the
kicks' coefficients from the arcs' jumps at the events.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from grazing_control.dynamics.identification.data import Recording, RecordingError, cut_arcs
from grazing_control.dynamics.identification.fit import (CONTINUATION, FitTimedOut,
                                                         FitTooLarge,
                                                         IdentificationError, check_size,
                                                         ShootingFit, actuator_input,
                                                         _covariance,
                                                         coloured_jacobian, interior)
from grazing_control.dynamics.identification.force_input import (ActuatorInput, equivalent_kick,
                                                                 forced_increment, kicked)
from grazing_control.dynamics.identification.modal import (ModalLayout, ModalModel,
                                                           kick_coefficients, modal_flow,
                                                           particular, propagate, rates)
from grazing_control.dynamics.identification.phase import PhaseError, PhaseReference, fit_phase

__all__ = ["ModalProblem", "ModalIdentification", "identify_modal", "initial_modal"]



class ModalProblem:
    """The residual vector and its Jacobian (module docstring) of one recording of the
    wall coordinate cut into arcs. ``correction_dv``: the recorded kicks (one per
    correction time of ``rec``); ``kick_on_wall``: they act on the wall coordinate;
    ``actuator``: the commands as the force's known input (:mod:`.force_input`: a pulse,
    through the first-order actuator): the state is continuous at a correction and the
    input's response is added to every stretch; None: each correction is a kick."""

    def __init__(self, rec: Recording, arcs, phase: PhaseReference, n: int,
                 correction_dv, kick_on_wall: bool, impact_velocities: bool = True,
                 actuator: ActuatorInput | None = None):
        self.rec, self.arcs, self.phase, self.n_modes = rec, arcs, phase, n
        self.actuator = actuator
        K = arcs.count
        self.kick_on_wall = bool(kick_on_wall)
        self.b_imp = np.flatnonzero(arcs.kind == 1)
        self.b_cor = np.flatnonzero(arcs.kind == 2)
        ct = np.asarray(rec.corrections, float)
        which = [int(np.argmin(np.abs(ct - arcs.start[b]))) for b in self.b_cor]
        self.dv = np.asarray(correction_dv, float)[which] if which else np.zeros(0)
        self.layout = ModalLayout(n, actuator=bool(self.b_cor.size) and not kick_on_wall
                                  and n > 1)
        ng = self.layout.size
        self.ng = ng
        self.iA = ng + np.arange(K * 2 * n).reshape(K, 2 * n)
        nn = ng + K * 2 * n
        self.iT = np.full(K, -1)
        for k in np.flatnonzero(arcs.time_free):
            self.iT[k] = nn
            nn += 1
        self.n = nn
        self.weight = CONTINUATION[-1]
        self.vrows = np.flatnonzero(np.isfinite(rec.v))
        use = bool(impact_velocities)
        bi = self.b_imp
        self.b_vm = bi[np.isfinite(arcs.v_minus[bi])] if use else bi[:0]
        self.b_vp = bi[np.isfinite(arcs.v_plus[bi])] if use else bi[:0]
        self.vm_of_imp = np.searchsorted(bi, self.b_vm)     # b_vm's places in b_imp
        sizes = [rec.t.size, self.vrows.size, self.b_vm.size, self.b_vp.size, bi.size,
                 2 * n * bi.size, 2 * n * self.b_cor.size]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)])
        self.m = int(self.offsets[-1])
        self.m_data = int(self.offsets[4])
        self.n_constraints = self.m - self.m_data
        owner = [[] for _ in range(K)]
        o = self.offsets
        sa = arcs.sample_arc
        for j, k in enumerate(sa):
            owner[k].append(o[0] + j)
        for i, j in enumerate(self.vrows):
            owner[sa[j]].append(o[1] + i)
        for block, bs, width in ((2, self.b_vm, 1), (3, self.b_vp, 1), (4, bi, 1),
                                 (5, bi, 2 * n), (6, self.b_cor, 2 * n)):
            for i, b in enumerate(bs):
                rows = list(range(o[block] + width * i, o[block] + width * (i + 1)))
                owner[b] += rows
                owner[b - 1] += rows
        self.rows_of_arc = [np.array(r, int) for r in owner]
        if actuator is not None:
            # the commands acting on each stretch (its start within its time's bounds)
            s_lo = np.where(arcs.time_free, arcs.lower, arcs.start)
            s_hi = np.where(arcs.time_free, arcs.upper, arcs.start)
            self._last = {}
            self.relevant = {
                "samples": actuator.relevant(rec.t, s_lo[sa]),
                "impacts": actuator.relevant(s_hi[bi], s_lo[bi - 1]),
                "corrections": actuator.relevant(s_hi[self.b_cor], s_lo[self.b_cor - 1])}

    def _forced(self, which, sig, w, t, s, kc, ks):
        """The input's (alpha, beta) over the stretches (s, t] (:mod:`.force_input`), or
        0 without an input."""
        if self.actuator is None:
            return 0.0, 0.0
        # the complex step of an arc's state leaves the input's response as it was: the
        # last one of each kind is kept for the same (sigma, w, t, s)
        key = b"".join(np.asarray(a, complex).tobytes() for a in (sig, w, t, s))
        hit = self._last.get(which)
        if hit is None or hit[0] != key:
            hit = (key, forced_increment(sig, w, t, s, self.actuator, self.relevant[which]))
            self._last[which] = hit
        return kicked(kc, ks, *hit[1])

    def pack(self, g, start, a) -> np.ndarray:
        p = np.zeros(self.n)
        p[:self.ng] = g
        p[self.iA] = a
        f = self.iT >= 0
        p[self.iT[f]] = start[f]
        return p

    def unpack(self, p):
        """(g, start times, modal states (K, 2n)) of a parameter vector (complex allowed),
        or of each row of a batch (B, n): each with the batch's leading axis."""
        S = np.empty(p.shape[:-1] + self.arcs.start.shape, p.dtype)
        S[...] = self.arcs.start
        f = self.iT >= 0
        S[..., f] = p[..., self.iT[f]]
        return p[..., :self.ng], S, p[..., self.iA]

    def bounds(self):
        lo = np.full(self.n, -np.inf)
        hi = np.full(self.n, np.inf)
        n = self.n_modes
        lo[:n] = 1e-12                              # Omega_k > 0
        lo[n:2 * n], hi[n:2 * n] = 1e-12, 1.0 - 1e-12      # 0 < zeta_k < 1
        ir = self.layout.index_d + 1
        lo[ir], hi[ir] = 0.0, 2.0                   # r (beyond 1: a poor fit)
        f = self.iT >= 0
        lo[self.iT[f]] = self.arcs.lower[f]
        hi[self.iT[f]] = self.arcs.upper[f]
        return lo, hi

    def residual(self, p) -> np.ndarray:
        """The residual vector (module docstring) at p (real or complex), or the (B, m)
        residuals of a batch p (B, n) without an input (:meth:`jacobian`): each row the
        same arithmetic as the row alone."""
        lead = p.shape[:-1]
        g, S, a = self.unpack(p)
        n = self.n_modes
        Om, ze, ci, Pc, Ps, d, r, ka = self.layout.split(g)
        sig, w = rates(Om, ze)
        c, s = kick_coefficients(Om, ze, ci, 1.0)
        kc, ks = (c, s) if ka is None else kick_coefficients(Om, ze, ka, 0.0)
        if self.actuator is not None and lead:
            raise ValueError("residual: a batch of parameter vectors is only for a fit "
                             "without an input")
        # per mode (..., 1, n) against the rows (..., m, n); per vector (..., 1)
        sig_, w_, c_, s_, kc_, ks_ = (u[..., None, :] for u in (sig, w, c, s, kc, ks))
        Pc, Ps, d, r = (u[..., None] for u in (Pc, Ps, d, r))
        om, tau0 = self.phase.omega, self.phase.tau0
        rec, arcs = self.rec, self.arcs
        al, be = a[..., :n], a[..., n:]
        sa = arcs.sample_arc
        h = (rec.t - S[..., sa])[..., None]
        y, dy = modal_flow(sig_, w_, al[..., sa, :], be[..., sa, :], h)
        if self.actuator is not None:
            fa, fb = self._forced("samples", sig, w, rec.t, S[sa], kc, ks)
            y = y + np.sum(fa, axis=-1)
            dy = dy + np.sum(w * fb - sig * fa, axis=-1)
        xp, vp = particular(Pc, Ps, om, om * rec.t + tau0)
        W = self.weight
        out = [y + xp - rec.x, (dy + vp)[..., self.vrows] - rec.v[self.vrows]]
        bi, bc = self.b_imp, self.b_cor
        # the arcs before each impact, at the impact
        hb = (S[..., bi] - S[..., bi - 1])[..., None]
        ym, dym = modal_flow(sig_, w_, al[..., bi - 1, :], be[..., bi - 1, :], hb)
        ia = ib = 0.0
        if self.actuator is not None:
            ia, ib = self._forced("impacts", sig, w, S[bi], S[bi - 1], kc, ks)
            ym = ym + np.sum(ia, axis=-1)
            dym = dym + np.sum(w * ib - sig * ia, axis=-1)
        xpi, vpi = particular(Pc, Ps, om, om * S[..., bi] + tau0)
        vminus = dym + vpi
        out.append(vminus[..., self.vm_of_imp] - arcs.v_minus[self.b_vm])
        bp = self.b_vp
        y0, dy0 = modal_flow(sig_, w_, al[..., bp, :], be[..., bp, :], np.zeros((bp.size, 1)))
        _x, vpp = particular(Pc, Ps, om, om * S[..., bp] + tau0)
        out.append(dy0 + vpp - arcs.v_plus[bp])
        out.append(W * (ym + xpi - d))
        pa, pb = propagate(sig_, w_, al[..., bi - 1, :], be[..., bi - 1, :], hb)
        jump = (-(1.0 + r) * vminus)[..., None]
        out.append(W * np.concatenate([al[..., bi, :] - pa - ia - jump * c_,
                                       be[..., bi, :] - pb - ib - jump * s_], axis=-1))
        if bc.size:
            pa, pb = propagate(sig_, w_, al[..., bc - 1, :], be[..., bc - 1, :],
                               (S[..., bc] - S[..., bc - 1])[..., None])
            if self.actuator is not None:      # the input carries the command: no jump
                ja, jb = self._forced("corrections", sig, w, S[bc], S[bc - 1], kc, ks)
            else:
                ja, jb = self.dv[:, None] * kc_, self.dv[:, None] * ks_
            out.append(W * np.concatenate([al[..., bc, :] - pa - ja, be[..., bc, :] - pb - jb],
                                          axis=-1))
        return np.concatenate([np.asarray(o).reshape(lead + (-1,)) for o in out], axis=-1)

    def jacobian(self, p) -> np.ndarray:
        """Complex-step Jacobian, dense (m, n) (module docstring): the perturbed vectors
        as one batch of residuals where there is no input."""
        columns = [self.iA[:, i] for i in range(self.iA.shape[1])] + [self.iT]
        return coloured_jacobian(self.residual, p, self.m, self.ng, columns, self.rows_of_arc,
                                 batch=self.actuator is None)


# ---------------------------------------------------------------------- initial guess
def _arx_eigenvalues(rec, arcs, phase, n):
    """The n mode pairs lambda_k from the ARX(2n) recursion on every q-th sample inside
    the arcs (module docstring); InitialGuessError-like IdentificationError if it finds
    fewer than n oscillating modes."""
    t, x = rec.t, rec.x
    dt = float(np.median(np.diff(t)))
    # (a sample of arc -1 is left out: under an input's force, :func:`initial_modal`)
    lengths = np.bincount(arcs.sample_arc[arcs.sample_arc >= 0], minlength=arcs.count)
    # q h at most T/16: modes up to 8 omega stay below the Nyquist limit pi / (q h)
    q = max(1, min(int(np.median(lengths[lengths > 0]) // (4 * n)),
                   int(2.0 * math.pi / phase.omega / (16.0 * dt))))
    order = 2 * n
    rows, rhs = [], []
    tau = phase.phase(t)
    sa = arcs.sample_arc
    for j in range(t.size - order * q):
        idx = j + q * np.arange(order + 1)
        if sa[idx[0]] < 0 or np.any(sa[idx] != sa[idx[0]]) or abs(t[idx[-1]] - t[j] - order * q * dt) > 1e-6 * dt * q:
            continue
        rows.append(np.concatenate([x[idx[-2::-1]], [np.cos(tau[j]), np.sin(tau[j])]]))
        rhs.append(x[idx[-1]])
    if len(rows) < 4 * (order + 2):
        raise IdentificationError(
            f"n={n}: too few stretches of {order * q + 1} uniformly spaced samples inside "
            f"the free-flight arcs ({len(rows)}) for the modes' initial guess")
    A = np.array(rows)
    coef = np.linalg.lstsq(A, np.array(rhs), rcond=None)[0]
    roots = np.roots(np.concatenate([[1.0], -coef[:order]]))
    lam = np.log(roots.astype(complex)) / (q * dt)
    lam = lam[lam.imag > 1e-9]
    if lam.size < n:
        raise IdentificationError(
            f"n={n}: the motion shows {lam.size} oscillating modes, not n = {n} (the "
            "wall coordinate's free flight has fewer damped oscillations than the model's "
            "degrees of freedom)")
    lam = lam[np.argsort(np.abs(lam))][:n]
    Om = np.abs(lam)
    zeta = np.clip(-lam.real / Om, 1e-4, 0.9)
    return Om, zeta


def initial_modal(rec, arcs, phase, n, dv, kick_on_wall, actuator=None, offset=0.0,
                  modes=None):
    """(g, start times, modal states (K, 2n)) to start the fit from (module docstring);
    ``modes``: (Omega, zeta) of the n modes to start from instead of the ARX guess (a
    model's, :func:`.modal.modal_of`: the refit in the loop starts from the running
    model, docs/theory_reidentification.md);
    ``actuator``: the corrections are the input's commands (:class:`ModalProblem`), each
    ``offset`` after its correction's time: the samples under their force are left out
    of the arcs' linear fits, the jumps read as the commands' equivalent kicks
    (:func:`.force_input.equivalent_kick`)."""
    if actuator is not None:
        # under the force: from the onset to 8 tau_a after the pulse (e^-8: 3e-4 of it)
        acting = actuator.relevant(rec.t, rec.t)
        end = actuator.onsets[acting.commands] + actuator.width + 8.0 * actuator.time_constant
        under = np.zeros(rec.t.size, bool)
        under[acting.rows[rec.t[acting.rows] < end]] = True
        arcs = dataclasses.replace(arcs, sample_arc=np.where(under, -1, arcs.sample_arc))
    if modes is None:
        Om, zeta = _arx_eigenvalues(rec, arcs, phase, n)
    else:
        Om, zeta = (np.array(a, dtype=float).reshape(n) for a in modes)
    sig, w = rates(Om, zeta)
    om, tau0 = phase.omega, phase.tau0
    K = arcs.count
    S = arcs.start.astype(float)
    sa = arcs.sample_arc
    psi = om * rec.t + tau0
    F = np.column_stack([np.cos(psi), np.sin(psi)])
    basis = []
    for k in range(K):
        j = np.flatnonzero(sa == k)
        h = (rec.t[j] - S[k])[:, None]
        E = np.exp(-sig * h)
        basis.append((j, np.hstack([E * np.cos(w * h), E * np.sin(w * h)])))
    # the periodic response with each well-sampled arc's coefficients projected out
    Fp, xp = [], []
    for j, B in basis:
        if j.size > 2 * n + 1:
            Q, _ = np.linalg.qr(B)
            Fp.append(F[j] - Q @ (Q.T @ F[j]))
            xp.append(rec.x[j] - Q @ (Q.T @ rec.x[j]))
    if not Fp:
        raise IdentificationError(f"n={n}: no free-flight arc has more than {2 * n + 1} "
                                  "samples: the modes cannot be started")
    P = np.linalg.lstsq(np.vstack(Fp), np.concatenate(xp), rcond=None)[0]
    a = np.zeros((K, 2 * n))
    good = np.zeros(K, bool)
    for k, (j, B) in enumerate(basis):
        if j.size > 2 * n + 1:
            a[k] = np.linalg.lstsq(B, rec.x[j] - F[j] @ P, rcond=None)[0]
            good[k] = True

    def at_end(k):
        """x, v and the propagated modal state of arc k at the next arc's start."""
        h = np.array([[S[k + 1] - S[k]]])
        y, dy = modal_flow(sig, w, a[k:k + 1, :n], a[k:k + 1, n:], h)
        xq, vq = particular(P[0], P[1], om, om * S[k + 1] + tau0)
        pa, pb = propagate(sig, w, a[k, :n], a[k, n:], h[0])
        return float(y[0] + xq), float(dy[0] + vq), np.concatenate([pa, pb])

    def start_v(k):
        _y, dy = modal_flow(sig, w, a[k:k + 1, :n], a[k:k + 1, n:], np.zeros((1, 1)))
        return float(dy[0] + particular(P[0], P[1], om, om * S[k] + tau0)[1])

    bi = np.flatnonzero(arcs.kind == 1)
    pairs = [b for b in bi if good[b] and good[b - 1]]
    if not pairs:
        raise IdentificationError(f"n={n}: no impact between two well-sampled arcs: r and "
                                  "the impact's modal response cannot be started")
    xm, vm, jumps, dvs, vps = [], [], [], [], []
    for b in pairs:
        x_, v_, prop = at_end(b - 1)
        vp = arcs.v_plus[b] if np.isfinite(arcs.v_plus[b]) else start_v(b)
        v_ = arcs.v_minus[b] if np.isfinite(arcs.v_minus[b]) else v_
        xm.append(x_)
        vm.append(v_)
        vps.append(vp)
        jumps.append(a[b] - prop)
        dvs.append(vp - v_)
    d = float(np.median(xm))
    r = float(np.clip(np.median(-np.array(vps) / np.array(vm)), 0.05, 0.98))
    dvs = np.array(dvs)
    cs = (dvs @ np.array(jumps)) / (dvs @ dvs)
    g_free = [Om, zeta, np.column_stack([cs[:n], cs[n:]])[:n - 1].ravel(), P, [d, r]]
    layout_actuator = bool(np.count_nonzero(arcs.kind == 2)) and not kick_on_wall and n > 1
    ka_cs = None
    if layout_actuator:
        bc = np.flatnonzero(arcs.kind == 2)
        cj, cd = [], []
        for i, b in enumerate(bc):
            if good[b] and good[b - 1] and dv[i] != 0.0:
                cj.append(a[b] - at_end(b - 1)[2])
                cd.append(dv[i])
        cd = np.array(cd)
        ka_cs = (cd @ np.array(cj)) / (cd @ cd) if cd.size else np.zeros(2 * n)
        if actuator is not None:   # the command's jump back to the kick's (C / F)
            fr, fi = equivalent_kick(sig, w, actuator, offset)
            f = fr[0] + 1j * fi[0]
            kick = (ka_cs[:n] - 1j * ka_cs[n:]) / f
            ka_cs = np.concatenate([kick.real, -kick.imag])
        g_free.append(np.column_stack([ka_cs[:n], ka_cs[n:]])[:n - 1].ravel())
    g = np.concatenate([np.asarray(v, float).ravel() for v in g_free])
    # short arcs: carried on from the arc before, through its event
    layout = ModalLayout(n, layout_actuator)
    _Om, _ze, ci, *_rest, ka = layout.split(g)
    c, s = kick_coefficients(Om, zeta, ci, 1.0)
    kc, ks = (c, s) if ka is None else kick_coefficients(Om, zeta, ka, 0.0)
    if actuator is not None:
        fr, fi = equivalent_kick(sig, w, actuator, offset)
        kc, ks = kicked(kc, ks, fr[0], fi[0])
    bc_list = np.flatnonzero(arcs.kind == 2).tolist()
    for k in range(1, K):
        if good[k]:
            continue
        x_, v_, prop = at_end(k - 1)
        if arcs.kind[k] == 1:
            jump = -(1.0 + r) * v_
            a[k] = prop + jump * np.concatenate([c, s])
        else:
            a[k] = prop + dv[bc_list.index(k)] * np.concatenate([kc, ks])
        good[k] = True
    return g, S, a


def _sorted_modes(prob, p):
    """p with the modes in increasing natural frequency (the fit may converge to the same
    model with its modes' labels exchanged: every residual is symmetric in them)."""
    lay, n = prob.layout, prob.n_modes
    g = p[:prob.ng]
    order = np.argsort(g[:n], kind="stable")
    if np.array_equal(order, np.arange(n)):
        return p
    Om, ze, ci, Pc, Ps, d, r, ka = lay.split(g)
    c, s = kick_coefficients(Om, ze, ci, 1.0)
    parts = [Om[order], ze[order], np.column_stack([c, s])[order][:n - 1].ravel(),
             [Pc, Ps, d, r]]
    if ka is not None:
        kc, ks = kick_coefficients(Om, ze, ka, 0.0)
        parts.append(np.column_stack([kc, ks])[order][:n - 1].ravel())
    q = p.copy()
    q[:prob.ng] = np.concatenate([np.asarray(a, float).ravel() for a in parts])
    q[prob.iA] = p[prob.iA][:, np.concatenate([order, n + order])]
    return q


@dataclass
class ModalIdentification(ShootingFit):
    """The result of :func:`identify_modal`.

    model : ModalModel; names, values, stderr: the global vector g with its standard
    errors (:class:`.modal.ModalLayout` names) plus ``delta_d`` and ``d_star``;
    covariance of g; sigma, rms_x, constraint_rms; problem (for
    :func:`.checks.whiteness`); and the :class:`.fit.ShootingFit` fields."""

    model: ModalModel
    names: tuple
    values: np.ndarray
    stderr: dict
    covariance: np.ndarray
    sigma: float
    rms_x: float
    constraint_rms: float
    problem: ModalProblem
    checks: dict = field(default_factory=dict)

    def value(self, name: str) -> float:
        if name == "delta_d":
            return self.model.delta_d
        if name == "d_star":
            return self.model.d_star
        return float(self.values[self.names.index(name)])


def identify_modal(rec: Recording, n: int, *, correction_dv=None, kick_on_wall=False,
                   impact_velocities: bool = True, max_arcs: int | None = 100,
                   max_nfev: int = 200, coincidence: float = 1.5e-9,
                   shrink: bool = False, width: float = 0.0, time_constant: float = 0.0,
                   latency: float = 0.0, pulse_offset: float | None = None,
                   modes=None, deadline: float | None = None) -> ModalIdentification:
    """Fit the modal parameters of an n-DOF model to a recording of its wall coordinate
    (module docstring). ``rec``'s impacts must be recorded (their times start the fit);
    ``correction_dv``: the kick of each of ``rec.corrections`` (on the wall coordinate if
    ``kick_on_wall``, else on another: its response is fitted too). ``shrink``: where
    ``max_arcs`` arcs would exceed JACOBIAN_BYTES, fit as many as it allows (as
    :func:`.fit.identify`). ``width`` > 0 or ``time_constant`` > 0: each correction is
    commanded as a force pulse of that width starting ``pulse_offset`` after its time
    (default -width / 2: centred there; the plant's ``pulse_width``) through the
    first-order actuator (tau_a ``time_constant``, ``latency`` L; the bag's parameter
    record): the force is the fit's known input (:mod:`.force_input`), every sample kept.
    A kick (both 0) acts L after its time. ``modes``: (Omega, zeta) of the modes to
    start from (:func:`initial_modal`; None: the ARX guess). ``deadline``: a
    ``time.monotonic()`` instant by which the fit must end (as :func:`.fit.identify`'s:
    the solver stops there and FitTimedOut is raised; None: none).

    Raises IdentificationError on bad input (no phase reference, no or too few impacts,
    too few samples, no initial guess, a Jacobian beyond JACOBIAN_BYTES).
    """
    while True:
        try:
            return _identify_modal(rec, n, correction_dv, kick_on_wall, impact_velocities,
                                   max_arcs, max_nfev, coincidence,
                                   (width, time_constant, latency, pulse_offset), modes,
                                   deadline)
        except FitTooLarge as exc:
            if not shrink or max_arcs is not None and exc.fits >= max_arcs:
                raise
            max_arcs = exc.fits


def _identify_modal(rec, n, correction_dv, kick_on_wall, impact_velocities, max_arcs,
                    max_nfev, coincidence, actuation=(0.0, 0.0, 0.0, None), modes=None,
                    deadline=None) -> ModalIdentification:
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise IdentificationError(f"n={n!r} is invalid: valid is an integer >= 1")
    dv = np.zeros(rec.corrections.size) if correction_dv is None else \
        np.asarray(correction_dv, float)
    if dv.size != rec.corrections.size:
        raise IdentificationError(f"correction_dv has {dv.size} values for "
                                  f"{rec.corrections.size} corrections")
    width, tau_a, latency, offset = actuation
    actuator, rec = actuator_input(rec, dv, width, tau_a, latency, offset)
    offset = (-0.5 * width if offset is None else float(offset)) + latency
    try:
        events = np.concatenate([rec.corrections, rec.impact_t])
        rec = rec.without_samples(rec.near(events, coincidence))
        phase = fit_phase(rec.t, rec.cos_tau, rec.sin_tau)
        if max_arcs is not None:
            ev = np.sort(events[events > rec.t[0]])
            if ev.size >= max_arcs:
                keep_c = (rec.corrections >= rec.t[0]) & (rec.corrections < ev[max_arcs - 1])
                dv = dv[keep_c]
                rec = rec.window(rec.t[0], ev[max_arcs - 1])
        arcs = cut_arcs(rec.t, rec.impact_t, rec.corrections, impact_v_minus=rec.impact_v_minus,
                        impact_v_plus=rec.impact_v_plus, free_times=True)
    except (PhaseError, RecordingError) as exc:
        raise IdentificationError(str(exc)) from None
    keep = (rec.corrections > rec.t[0]) & (rec.corrections < rec.t[-1])
    rec_dv = dv[keep]
    rec = Recording(rec.t, rec.x, rec.v, rec.cos_tau, rec.sin_tau, rec.impact_t,
                    rec.impact_v_minus, rec.impact_v_plus, rec.corrections[keep])
    impacts = int(np.count_nonzero(arcs.kind == 1))
    need_impacts = 2
    if impacts < need_impacts:
        raise IdentificationError(
            f"impacts: the recording has {impacts} impact(s) inside its state stream: the "
            f"n-DOF fit needs at least {need_impacts} recorded impacts (oscillator/impact) "
            "to identify d, r and the impact's modal response")
    prob = ModalProblem(rec, arcs, phase, n, rec_dv, kick_on_wall, impact_velocities,
                        actuator)
    check_size(prob)
    dof = prob.m_data - (prob.n - prob.n_constraints)
    if dof <= 0:
        raise IdentificationError(f"too few samples: {prob.m_data} data values for "
                                  f"{prob.n - prob.n_constraints} free parameters")
    g0, S0, a0 = initial_modal(rec, arcs, phase, n, rec_dv, kick_on_wall, actuator, offset,
                               modes)
    lo, hi = prob.bounds()
    inner_lo, inner_hi = interior(lo, hi)
    p = np.clip(prob.pack(g0, S0, a0), inner_lo, inner_hi)

    def in_time(intermediate_result=None):
        if time.monotonic() > deadline:
            raise StopIteration

    for weight in CONTINUATION:
        prob.weight = weight
        sol = least_squares(prob.residual, p, jac=prob.jacobian, bounds=(lo, hi),
                            method="trf", x_scale="jac", xtol=1e-15, ftol=1e-15,
                            gtol=1e-15, max_nfev=max_nfev,
                            callback=None if deadline is None else in_time)
        if deadline is not None and time.monotonic() > deadline:
            raise FitTimedOut(f"the fit did not finish in its time budget ({sol.nfev} "
                              f"evaluations at weight {weight:g})")
        p = sol.x
    p = _sorted_modes(prob, p)
    res = prob.residual(p)
    J = prob.jacobian(p)
    data = res[:prob.m_data]
    sigma2 = float(data @ data) / dof
    ng = prob.ng
    cov = _covariance(J, sigma2, ng)
    se = np.sqrt(np.diag(cov))
    model = ModalModel.from_vector(p[:ng], prob.layout, phase.omega)
    names = prob.layout.names
    stderr = {k: float(v) for k, v in zip(names, se)}
    # delta_d = d - hypot(P_c, P_s) and d* by the delta method
    i = prob.layout.index_d
    Pc, Ps = p[i - 2], p[i - 1]
    ds = math.hypot(Pc, Ps)
    G = np.zeros((2, ng))
    G[0, [i - 2, i - 1, i]] = [-Pc / ds, -Ps / ds, 1.0]
    G[1, [i - 2, i - 1]] = [Pc / ds, Ps / ds]
    with np.errstate(invalid="ignore"):
        cd = G @ np.where(np.isfinite(cov), cov, 0.0) @ G.T
    inf = ~np.isfinite(np.diag(cov))
    for row, name in enumerate(("delta_d", "d_star")):
        stderr[name] = (math.inf if np.any(inf[G[row] != 0])
                        else float(math.sqrt(max(cd[row, row], 0.0))))
    cons = res[prob.m_data:] / prob.weight
    xres = data[:rec.t.size]
    return ModalIdentification(
        model=model, names=names, values=p[:ng].copy(), stderr=stderr, covariance=cov,
        sigma=math.sqrt(sigma2), rms_x=float(np.sqrt(np.mean(xres ** 2))),
        constraint_rms=float(np.sqrt(np.mean(cons ** 2))) if cons.size else 0.0,
        phase=phase, problem=prob, solution=p, arcs_used=arcs.count, impacts_used=impacts,
        samples_used=int(rec.t.size), dof=int(dof), converged=bool(sol.status > 0),
        message=str(sol.message))


def modal_verdict(ident: ModalIdentification) -> dict:
    """The checks of docs/theory_identification.md section 8 that apply to the modal fit:
    convergence, r and every zeta_k in (0, 1), white position residuals (unless at
    rounding: an exact fit). (The 1-DOF re-simulation is not run for n > 1.)"""
    from grazing_control.dynamics.identification.checks import (ROUNDING, WHITENESS_LIMIT,
                                                                 suspects, whiteness)

    m = ident.model
    white = whiteness(ident)
    rounding = ident.rms_x <= ROUNDING * max(m.d_star, abs(m.d), 1e-300)
    reasons = []
    if not ident.converged:
        reasons.append(f"the least-squares solver did not converge ({ident.message})")
    if not 0.0 < m.r < 1.0:
        reasons.append(f"the fitted restitution r = {m.r:.6g} is outside (0, 1)")
    for k, z in enumerate(m.damping_ratio):
        if not 0.0 < z < 1.0:
            reasons.append(f"the fitted damping ratio of mode {k}, {z:.6g}, is outside (0, 1)")
    if not rounding and abs(white["z"]) > WHITENESS_LIMIT:
        reasons.append(f"the residuals are not white: lag-1 autocorrelation "
                       f"{white['lag1_autocorrelation']:.3f} over {white['pairs']} pairs "
                       f"({abs(white['z']):.1f} sigma > {WHITENESS_LIMIT:g}): the motion is not "
                       "this model's (" + suspects(ident, "another n? soft wall? sensor bias?")
                       + ")")
    return {"fit": "poor" if reasons else "good", "reasons": reasons, "whiteness": white}

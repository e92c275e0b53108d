"""Multiple-shooting least squares for the model's parameters (docs/theory_identification.md).

Unknowns: the model g = (zeta, Omega, A, theta, d, r) (:data:`.model.GLOBAL_NAMES`), the
start of every free-flight arc (after an impact only its velocity V_b, the position being
d; else (X_b, V_b)) and the events' times t_b (impacts, corrections), each bounded by
the samples around it.

Residuals, all in the recording's units:

* data: x(t_j) - x~_j and v(t_j) - v~_j (where measured), x(t) by the closed-form flow
  of the sample's arc (:func:`.model.free_flight`); recorded impact velocities
  v-(t_b) - v-~_b and V_b - v+~_b;
* constraints, weighted by W = :data:`CONSTRAINT_WEIGHT`: at an impact b the arc before
  reaches the wall, W (x_{b-1}(t_b) - d), and the impact law links the arcs,
  W (V_b + r v_{b-1}(t_b)) (Eq. 1); at a correction the position is continuous,
  W (x_{b-1}(t_b) - X_b).

The constraints are exact in the model, so at the solution of noise-free data every
residual vanishes; with noise they hold to O(sigma / W^2) (docs: "Constraints"). The
weight is raised in steps (:data:`CONTINUATION`), each solve starting from the last:
the initial guess violates the constraints, and a solve at the full weight from there
would chase them far from the data. An event time that stops at a bound (a sample) was
guessed in the wrong sample interval: it is moved to the next one and the fit repeated
(:data:`MAX_SHIFTS` rounds; the solve of least cost is kept).

Jacobian: by complex step, J e_p = Im r(p + i h e_p) / h with h = 1e-30, exact to
rounding because every residual is analytic in the parameters; the arcs' parameters
are perturbed together in two colours (even and odd arcs), whose rows never overlap
(an arc's parameters reach only its samples and its two boundaries), so a Jacobian
costs 6 + 2 x 3 evaluations of the residual.

Standard errors: sigma^2 (J^T J)^{-1} from the SVD of J at the solution, sigma^2 the
data residuals' sum of squares over m_data - (n - n_constraints) degrees of freedom;
the study's nondimensional parameters by the delta method (their complex-step gradient).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from grazing_control.dynamics.identification.data import Arcs, Recording, RecordingError, cut_arcs
from grazing_control.dynamics.identification.force_input import ActuatorInput, forced_increment
from grazing_control.dynamics.identification.initial import InitialGuessError, find_impacts, initial_guess
from grazing_control.dynamics.identification.model import (GLOBAL_NAMES, NONDIMENSIONAL_NAMES, RigModel, free_flight,
                    nondimensional_vector)
from grazing_control.dynamics.identification.phase import PhaseError, PhaseReference, fit_phase

__all__ = ["CONSTRAINT_WEIGHT", "JACOBIAN_BYTES", "IdentificationError", "Problem",
           "Identification", "ShootingFit", "identify", "coloured_jacobian", "interior",
           "check_size"]

#: Weight of the impact and continuity constraints against the data residuals.
CONSTRAINT_WEIGHT = 1e4
#: The weights of the penalty continuation, the last being CONSTRAINT_WEIGHT.
CONTINUATION = (1.0, 1e2, CONSTRAINT_WEIGHT)
#: Rounds of moving event times that stopped at a bound to the next sample interval.
MAX_SHIFTS = 4
#: The most bytes of the dense (m, n) Jacobian a fit may allocate (about 300 arcs of the
#: study's recordings). The solver (trf, a dense SVD per step) and the covariance hold a
#: few arrays of this size, so a fit stays below about 0.2 GB; a fit beyond it is
#: refused before anything of its size exists (issue 27: the 1,420 arcs of a
#: 1,300-period bag, --max-arcs 100000, took over 2 GB for a 702 MiB Jacobian). m and n
#: grow with the arcs, so the bytes grow as arcs^2 and the time as arcs^3 (100 arcs:
#: 4 s idle, 33 s on a loaded 2-core machine; 400 arcs over 300 s there).
JACOBIAN_BYTES = 32 << 20
_H = 1e-30
#: The most residual values of one batched call of the complex-step Jacobian (4 MiB of
#: complex values; a modal fit's temporaries are n_modes times that): a long fit's
#: perturbed vectors go in chunks.
BATCH_VALUES = 1 << 18


class IdentificationError(ValueError):
    """The recording cannot be fitted (bad input: too short, no impacts, no reference)."""


class FitTimedOut(IdentificationError):
    """The fit did not finish by its ``deadline`` (a caller's wall-clock budget)."""


class FitTooLarge(IdentificationError):
    """The fit's dense Jacobian would exceed JACOBIAN_BYTES; ``fits``: about how many arcs
    stay within it."""

    def __init__(self, message: str, fits: int):
        super().__init__(message)
        self.fits = fits


class Problem:
    """The residual vector and its Jacobian for one recording cut into arcs."""

    def __init__(self, rec: Recording, arcs: Arcs, phase: PhaseReference, *,
                 impact_velocities: bool = True, actuator: ActuatorInput | None = None):
        self.rec, self.arcs, self.phase = rec, arcs, phase
        self.actuator = actuator
        self.weight = CONSTRAINT_WEIGHT
        self.omega, self.tau0 = phase.omega, phase.tau0
        K = arcs.count
        n = 6
        self.iX = np.full(K, -1)
        self.iV = np.zeros(K, int)
        self.iT = np.full(K, -1)
        for k in range(K):
            if arcs.kind[k] != 1:
                self.iX[k] = n
                n += 1
            self.iV[k] = n
            n += 1
        for k in np.flatnonzero(arcs.time_free):
            self.iT[k] = n
            n += 1
        self.n = n
        # rows: x data, v data, recorded v-, recorded v+, impact position, impact law,
        # correction continuity
        sa = arcs.sample_arc
        self.vrows = np.flatnonzero(np.isfinite(rec.v))
        b = np.arange(1, K)
        self.b_imp = b[arcs.kind[1:] == 1]
        self.b_cor = b[arcs.kind[1:] == 2]
        use = bool(impact_velocities)
        self.b_vm = self.b_imp[np.isfinite(arcs.v_minus[self.b_imp])] if use else b[:0]
        self.b_vp = self.b_imp[np.isfinite(arcs.v_plus[self.b_imp])] if use else b[:0]
        self.vm_of_imp = np.searchsorted(self.b_imp, self.b_vm)   # b_vm's places in b_imp
        # with the input, the velocity is continuous at a correction too (the force is
        # the input's, not a jump)
        self.b_cor_v = self.b_cor if actuator is not None else b[:0]
        sizes = [rec.t.size, self.vrows.size, self.b_vm.size, self.b_vp.size,
                 self.b_imp.size, self.b_imp.size, self.b_cor.size, self.b_cor_v.size]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)])
        self.m = int(self.offsets[-1])
        self.m_data = int(self.offsets[4])
        self.n_constraints = int(self.m - self.m_data)
        # rows of each arc (its samples, its two boundaries): the Jacobian's colouring
        owner = [[] for _ in range(K)]
        o = self.offsets
        for j, k in enumerate(sa):
            owner[k].append(o[0] + j)
        for i, j in enumerate(self.vrows):
            owner[sa[j]].append(o[1] + i)
        for block, bs in ((2, self.b_vm), (3, self.b_vp), (4, self.b_imp), (5, self.b_imp),
                          (6, self.b_cor), (7, self.b_cor_v)):
            for i, bb in enumerate(bs):
                owner[bb].append(o[block] + i)
                owner[bb - 1].append(o[block] + i)
        self.rows_of_arc = [np.array(r, int) for r in owner]
        if actuator is not None:     # the commands acting on each stretch (.force_input)
            s_lo = np.where(arcs.time_free, arcs.lower, arcs.start)
            s_hi = np.where(arcs.time_free, arcs.upper, arcs.start)
            self.acting = (actuator.relevant(rec.t, s_lo[sa]),
                           actuator.relevant(s_hi[self.b_imp], s_lo[self.b_imp - 1]),
                           actuator.relevant(s_hi[self.b_cor], s_lo[self.b_cor - 1]))

    def forced(self, g, which: int, t, s):
        """(x, v) the input adds over the stretches (s, t] (:mod:`.force_input`; the
        kick's response of the one mode is -i / w: x = Im F / w, v = Re F - sigma Im F /
        w); 0 without an input."""
        if self.actuator is None:
            return 0.0, 0.0
        zeta, Om = g[0], g[1]
        sig, w = zeta * Om, Om * np.sqrt(1.0 - zeta * zeta)
        fr, fi = forced_increment(sig, w, t, s, self.actuator, self.acting[which])
        return fi[:, 0] / w, fr[:, 0] - sig * fi[:, 0] / w

    # ------------------------------------------------------------------ vector
    def pack(self, g, start, X, V) -> np.ndarray:
        """The parameter vector of (g, arcs' start times, X, V) (module docstring)."""
        p = np.zeros(self.n)
        p[:6] = g
        k = self.iX >= 0
        p[self.iX[k]] = X[k]
        p[self.iV] = V
        f = self.iT >= 0
        p[self.iT[f]] = start[f]
        return p

    def unpack(self, p):
        """(g, start times, X, V) of a parameter vector (complex allowed), or of each row
        of a batch of them ((B, n): each of the four with the batch's leading axis)."""
        g = p[..., :6]
        lead = p.shape[:-1]
        X = np.empty(lead + (self.arcs.count,), dtype=p.dtype)
        k = self.iX >= 0
        X[..., k] = p[..., self.iX[k]]
        X[..., ~k] = g[..., 4, None]
        V = p[..., self.iV]
        S = np.empty_like(X)
        S[...] = self.arcs.start
        f = self.iT >= 0
        S[..., f] = p[..., self.iT[f]]
        return g, S, X, V

    def bounds(self):
        """Bounds: 0 < zeta < 1, Omega > 0, A > 0, 0 <= r <= 2 (a fitted r beyond 1 is a
        poor fit, reported), impact times between their samples."""
        lo = np.full(self.n, -np.inf)
        hi = np.full(self.n, np.inf)
        lo[0], hi[0] = 1e-12, 1.0 - 1e-12       # zeta
        lo[1] = 1e-12                           # Omega
        lo[2] = 1e-300                          # A
        lo[5], hi[5] = 0.0, 2.0                 # r (beyond 1: the fit says "wrong model")
        f = self.iT >= 0
        lo[self.iT[f]] = self.arcs.lower[f]
        hi[self.iT[f]] = self.arcs.upper[f]
        return lo, hi

    # ------------------------------------------------------------------ residuals
    def residual(self, p) -> np.ndarray:
        """The residual vector (module docstring) at parameters p (real or complex), or
        the (B, m) residuals of a batch p (B, n) without an input (:meth:`jacobian`):
        each row the same arithmetic as the row alone."""
        g, S, X, V = self.unpack(p)
        zeta, Om, A, th, d, r = (g[..., None, i] for i in range(6))   # (1,) or (B, 1)
        om = self.omega
        psi0 = om * S + self.tau0 + th
        rec = self.rec
        a = self.arcs.sample_arc
        x, v = free_flight(zeta, Om, A, om, psi0[..., a], rec.t - S[..., a], X[..., a],
                           V[..., a])
        bi, bc = self.b_imp, self.b_cor
        xi, vi = free_flight(zeta, Om, A, om, psi0[..., bi - 1], S[..., bi] - S[..., bi - 1],
                             X[..., bi - 1], V[..., bi - 1])
        xc, vc = free_flight(zeta, Om, A, om, psi0[..., bc - 1], S[..., bc] - S[..., bc - 1],
                             X[..., bc - 1], V[..., bc - 1])
        if self.actuator is not None:    # the input's share: one vector at a time
            if p.ndim != 1:
                raise ValueError("residual: a batch of parameter vectors is only for a "
                                 "fit without an input")
            fx, fv = self.forced(g, 0, rec.t, S[a])
            x, v = x + fx, v + fv
            fx, fv = self.forced(g, 1, S[bi], S[bi - 1])
            xi, vi = xi + fx, vi + fv
            fx, fv = self.forced(g, 2, S[bc], S[bc - 1])
            xc, vc = xc + fx, vc + fv
        W = self.weight
        ar = self.arcs
        return np.concatenate([
            x - rec.x,
            v[..., self.vrows] - rec.v[self.vrows],
            vi[..., self.vm_of_imp] - ar.v_minus[self.b_vm],
            V[..., self.b_vp] - ar.v_plus[self.b_vp],
            W * (xi - d),
            W * (V[..., bi] + r * vi),
            W * (xc - X[..., bc]),
            W * (vc[..., :self.b_cor_v.size] - V[..., self.b_cor_v]),
        ], axis=-1)

    def jacobian(self, p) -> np.ndarray:
        """Complex-step Jacobian (module docstring), dense (m, n): the perturbed vectors
        as one batch of residuals where there is no input."""
        return coloured_jacobian(self.residual, p, self.m, 6, (self.iX, self.iV, self.iT),
                                 self.rows_of_arc, batch=self.actuator is None)


def coloured_jacobian(residual, p, m: int, globals_: int, indices, rows_of_arc, *,
                      batch: bool = False) -> np.ndarray:
    """The dense (m, len(p)) complex-step Jacobian of a multiple-shooting residual
    (module docstring): the first ``globals_`` parameters one by one, then each arc
    parameter kind (``indices``: per arc its column, -1 where none) in two colours, even
    and odd arcs together, arc k's column read on its rows ``rows_of_arc[k]`` only.

    ``batch``: ``residual`` takes the perturbed vectors as a (B, n) batch and returns
    their (B, m) residuals (a call per :data:`BATCH_VALUES` values instead of one per
    vector: the same values, row for row)."""
    p = np.asarray(p, float)
    K = len(rows_of_arc)
    steps = []           # (the columns perturbed together, per column its rows or None)
    for j in range(globals_):
        steps.append(([j], None))
    for index in indices:
        for colour in (0, 1):
            ks = [k for k in range(colour, K, 2) if index[k] >= 0]
            if ks:
                steps.append((index[ks], [rows_of_arc[k] for k in ks]))
    Q = np.repeat(p.astype(complex)[None, :], len(steps), axis=0)
    for row, (columns, _rows) in zip(Q, steps):
        row[columns] += 1j * _H
    if batch:            # in chunks of at most BATCH_VALUES residual values a call
        rows = max(1, BATCH_VALUES // max(m, 1))
        im = np.concatenate([residual(Q[i:i + rows]).imag
                             for i in range(0, len(steps), rows)]) / _H
    else:
        im = np.array([residual(q).imag for q in Q]) / _H
    J = np.zeros((m, p.size))
    for i, (columns, rows) in enumerate(steps):
        if rows is None:
            J[:, columns[0]] = im[i]
        else:
            for c, r in zip(columns, rows):
                J[r, c] = im[i, r]
    return J


def check_size(prob) -> None:
    """FitTooLarge (naming --max-arcs and about how many arcs fit) when the problem's
    dense (m, n) Jacobian would exceed :data:`JACOBIAN_BYTES`; before anything of its
    size is allocated."""
    need = 8 * prob.m * prob.n
    if need > JACOBIAN_BYTES:
        count = prob.arcs.count
        fits = max(2, int(count * math.sqrt(JACOBIAN_BYTES / need)))
        raise FitTooLarge(
            f"max_arcs: the fit of the {count} arcs used needs a dense Jacobian of "
            f"{prob.m} x {prob.n} ({need / 2 ** 20:.0f} MiB), beyond the "
            f"{JACOBIAN_BYTES >> 20} MiB bound of a fit: fit at most about {fits} arcs "
            "(--max-arcs)", fits)


def interior(lo, hi):
    """Bounds moved 1e-12 (relative) inside: least_squares starts strictly inside."""
    inner_lo, inner_hi = lo.copy(), hi.copy()
    f = np.isfinite(lo)
    inner_lo[f] += 1e-12 * np.maximum(1.0, np.abs(lo[f]))
    f = np.isfinite(hi)
    inner_hi[f] -= 1e-12 * np.maximum(1.0, np.abs(hi[f]))
    return inner_lo, inner_hi


@dataclass
class ShootingFit:
    """What a multiple-shooting fit reports beside its parameters (this module's and
    :mod:`.modal_fit`'s): the phase reference, the solution vector, the counts of arcs,
    impacts, samples and degrees of freedom, the solver's convergence and message."""

    phase: PhaseReference
    solution: np.ndarray
    arcs_used: int
    impacts_used: int
    samples_used: int
    dof: int
    converged: bool
    message: str


@dataclass
class Identification(ShootingFit):
    """The result of :func:`identify`.

    Attributes
    ----------
    model : RigModel, the fitted model in the recording's units.
    stderr : dict name -> standard error of the model's parameters (GLOBAL_NAMES).
    nondimensional : dict name -> (value, stderr) of the study's zeta, r, omega, d, delta_d.
    covariance : (6, 6) covariance of g.
    nondimensional_covariance : (5, 5) covariance of (zeta, r, omega, d, delta_d) by the
        delta method (inf on the diagonal of a parameter not identified).
    sigma : estimated noise standard deviation (data residuals).
    rms_x, rms_v : RMS of the position and velocity residuals.
    constraint_rms : RMS of the (unweighted) constraint violations.
    phase : PhaseReference.
    problem, solution : the least-squares problem and its solution vector.
    arcs_used, impacts_used, samples_used : counts.
    converged : bool, message : the solver's status.
    events_moved : event times moved to another sample interval before the kept solve
        (:data:`MAX_SHIFTS` rounds at most; the solve of least cost is kept).
    checks : dict filled by :mod:`.checks`.
    """

    model: RigModel
    stderr: dict
    nondimensional: dict
    covariance: np.ndarray
    sigma: float
    rms_x: float
    rms_v: float
    constraint_rms: float
    problem: Problem
    events_moved: int = 0
    checks: dict = field(default_factory=dict)
    nondimensional_covariance: np.ndarray | None = None


def _covariance(J, sigma2, k=6):
    """sigma^2 (J^T J)^{-1} restricted to the first k parameters, from the SVD of J;
    directions with singular values below 1e-13 of the largest are not identified (inf)."""
    _U, s, Vt = np.linalg.svd(J, full_matrices=False)
    inv = np.where(s > 1e-13 * s[0], 1.0 / np.where(s > 0, s, 1.0) ** 2, np.inf)
    Vk = Vt[:, :k]
    with np.errstate(invalid="ignore"):
        cov = (Vk.T * inv) @ Vk
    # a not-identified direction that touches a parameter makes its variance infinite
    touched = (np.abs(Vk) > 1e-12)[~np.isfinite(inv)].any(axis=0) if np.any(~np.isfinite(inv)) \
        else np.zeros(k, bool)
    cov = np.where(np.isfinite(cov), cov, 0.0)
    cov[touched, :] = np.inf
    cov[:, touched] = np.inf
    return sigma2 * cov


def _solve(rec, phase, impact_t, vm, vp, corr_t, free, impact_velocities, correction_times,
           max_nfev, prior=None, fixed=None, deadline=None, actuator=None):
    """Arcs, initial guess and the penalty continuation: (Problem, last solution);
    ``fixed`` {index in GLOBAL_NAMES: value} held out of the solve (sol.x is the whole
    vector)."""
    arcs = cut_arcs(rec.t, impact_t, corr_t, impact_v_minus=vm, impact_v_plus=vp,
                    free_times=free, free_corrections=correction_times)
    if np.count_nonzero(arcs.kind == 1) == 0:
        raise IdentificationError(
            "the recording has no impact: r and d (so delta_d) are not identifiable "
            "from free flight alone (record a scene with impacts)")
    prob = Problem(rec, arcs, phase, impact_velocities=impact_velocities, actuator=actuator)
    check_size(prob)
    g0, start0, X0, V0 = initial_guess(rec, arcs, phase, prior)
    lo, hi = prob.bounds()
    inner_lo, inner_hi = interior(lo, hi)
    p = np.clip(prob.pack(g0, start0, X0, V0), inner_lo, inner_hi)
    if prob.m_data - (prob.n - prob.n_constraints) <= 0:
        raise IdentificationError(f"too few samples: {prob.m_data} data values for "
                                  f"{prob.n - prob.n_constraints} free parameters")
    fixed = fixed or {}
    for j, value in fixed.items():
        p[j] = value
    free = np.setdiff1d(np.arange(prob.n), list(fixed))

    def full(q):
        out = p.astype(np.result_type(p, q))
        out[free] = q
        return out

    # penalty continuation: the initial guess violates the constraints; raising their
    # weight in steps keeps each solve near the last one (docs: "Constraints")
    def in_time(intermediate_result=None):
        if deadline is not None and time.monotonic() > deadline:
            raise StopIteration

    for weight in CONTINUATION:
        prob.weight = weight
        sol = least_squares(lambda q: prob.residual(full(q)), p[free],
                            jac=lambda q: prob.jacobian(full(q))[:, free],
                            bounds=(lo[free], hi[free]), method="trf", x_scale="jac",
                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_nfev,
                            callback=None if deadline is None else in_time)
        if deadline is not None and time.monotonic() > deadline:
            raise FitTimedOut(f"the fit did not finish in its time budget ({sol.nfev} "
                              f"evaluations at weight {weight:g}): the data do not pin the "
                              "model down fast enough")
        p = full(sol.x)
    sol.x = p
    return prob, sol


def actuator_input(rec: Recording, correction_dv, width: float, time_constant: float,
                   latency: float, pulse_offset: float | None):
    """(ActuatorInput or None, rec): the corrections of ``rec`` as the force's known input
    (:func:`identify`'s arguments; the commands of size 0 left out); without one (a kick)
    ``rec`` with its corrections L later. IdentificationError when the sizes are missing
    or do not match the corrections."""
    if width > 0.0 or time_constant > 0.0:
        dv = None if correction_dv is None else np.asarray(correction_dv, float).ravel()
        if dv is None or dv.size != rec.corrections.size:
            raise IdentificationError(
                f"correction_dv has {0 if dv is None else dv.size} values for "
                f"{rec.corrections.size} corrections: a force pulse or actuator needs the "
                "size of every correction")
        offset = (-0.5 * width if pulse_offset is None else float(pulse_offset)) + latency
        acting = dv != 0.0
        return ActuatorInput(rec.corrections[acting] + offset, dv[acting], width,
                             time_constant, latency), rec
    if latency:
        import dataclasses

        return None, dataclasses.replace(rec, corrections=rec.corrections + latency)
    return None, rec


def _shift_from_bounds(prob, p):
    """Fitted event times with those stopped at a bound moved to the middle of the next
    sample interval beyond it (the event was between other samples); None if none is."""
    a = prob.arcs
    S = np.real(prob.unpack(p)[1]).copy()
    t = prob.rec.t
    tol = 1e-9 * (a.upper - a.lower)
    at_hi = np.flatnonzero(a.time_free & (S >= a.upper - tol))
    at_lo = np.flatnonzero(a.time_free & (S <= a.lower + tol))
    moved = S.copy()
    for b in at_hi:
        j = int(np.searchsorted(t, a.upper[b], side="right"))
        if j < t.size:
            moved[b] = 0.5 * (t[j - 1] + t[j])
    for b in at_lo:
        j = int(np.searchsorted(t, a.lower[b], side="left"))
        if j >= 1:
            moved[b] = 0.5 * (t[j - 1] + t[j])
    return None if np.array_equal(moved, S) else moved


def identify(rec: Recording, *, impacts: str = "recorded", impact_velocities: bool = True,
             max_arcs: int | None = 100, max_nfev: int = 400,
             coincidence: float = 1.5e-9, correction_times: bool = True,
             shrink: bool = False, prior=None, fixed: dict | None = None,
             deadline: float | None = None, correction_dv=None, width: float = 0.0,
             time_constant: float = 0.0, latency: float = 0.0,
             pulse_offset: float | None = None) -> Identification:
    """Fit the model to a recording (module docstring).

    ``shrink``: where ``max_arcs`` arcs would exceed the Jacobian's memory bound (a dense
    stream: 300 samples per period gave 40 MiB for 100 arcs), fit as many as it allows
    instead of refusing (``Identification.arcs_used`` says how many); the CLI's default.

    Parameters
    ----------
    rec : Recording
    impacts : "recorded" (the recording's impact events cut the arcs, their times start
        the fit) or "motion" (found from the state stream). Either way the impact times
        are fitted: held fixed, a recorded time that is off (a soft contact's entry, a
        detector's delay) would make the impact constraints inconsistent.
    impact_velocities : use the recorded v-, v+ as data (weighted like a sample).
    max_arcs : fit the recording up to its max_arcs-th event (None: all of it).
    max_nfev : most evaluations of the least-squares solver.
    coincidence : samples within this time of a correction or a recorded impact are left
        out: their velocity is either side of the jump (default: 1.5 ns, the resolution
        of a bag's stamps).
    correction_times : fit the corrections' instants too (bounded by the samples around
        the given ones): a correction applied on arrival, or with a jitter, acts at an
        instant the recording does not carry exactly.
    prior : (zeta, Omega) known beforehand, in place of the ARX step of the initial
        guess (:func:`.initial.initial_guess`); None: from the data.
    fixed : {name: value} of :data:`.model.GLOBAL_NAMES` held at the value, not fitted
        (a controller's re-identification holds its units: natural_frequency and
        forcing_amplitude 1); their standard errors are 0.
    deadline : a ``time.monotonic()`` instant by which the fit must end (None: none):
        beyond it the solver stops and FitTimedOut is raised (a controller's worker must
        not fit for minutes on data that hardly determine the model).
    correction_dv, width, time_constant, latency, pulse_offset : how the corrections
        reached the mass (the bag's parameter record): with ``width`` > 0 or
        ``time_constant`` > 0 each correction of size ``correction_dv`` (one per
        ``rec.corrections``) is commanded as a force pulse of that width starting
        ``pulse_offset`` after its time (default -width / 2: centred) through the
        first-order actuator (tau_a, latency L): the force is a known input
        (:mod:`.force_input`), the state continuous at the corrections, their times
        held. Both 0: a kick L after its time, its size fitted (V free after it).

    Raises
    ------
    IdentificationError
        Bad input: no phase reference, too few samples, no impact, no initial guess.
    """
    fixed = {GLOBAL_NAMES.index(n): float(v) for n, v in (fixed or {}).items()
             if n in GLOBAL_NAMES}
    while True:
        try:
            return _identify(rec, impacts, impact_velocities, max_arcs, max_nfev,
                             coincidence, correction_times, prior, fixed, deadline,
                             (correction_dv, width, time_constant, latency, pulse_offset))
        except FitTooLarge as exc:
            if not shrink or max_arcs is not None and exc.fits >= max_arcs:
                raise
            max_arcs = exc.fits


def _identify(rec, impacts, impact_velocities, max_arcs, max_nfev, coincidence,
              correction_times, prior, fixed, deadline=None,
              actuation=(None, 0.0, 0.0, 0.0, None)) -> Identification:
    if impacts not in ("recorded", "motion"):
        raise IdentificationError(f"impacts={impacts!r} is invalid: valid values are "
                                  "recorded, motion")
    actuator, rec = actuator_input(rec, *actuation)
    if actuator is not None:
        correction_times = False     # known instants: the state is continuous there
    try:
        # a sample stamped at an event's instant is ambiguous (before or after the jump)
        events = np.concatenate([rec.corrections, rec.impact_t if impacts == "recorded"
                                 else np.zeros(0)])
        rec = rec.without_samples(rec.near(events, coincidence))
        phase = fit_phase(rec.t, rec.cos_tau, rec.sin_tau)
        if impacts == "motion" or rec.impact_t.size == 0:
            # impacts from the motion (the corrections cut the arcs first)
            pre = cut_arcs(rec.t, np.zeros(0), rec.corrections)
            found = find_impacts(rec.t, rec.x, phase.phase(rec.t), pre.sample_arc)
            mid = np.array([0.5 * (a + b) for a, b in found])
            rec_events = mid
            free = True
            vm = vp = None
        else:
            rec_events = rec.impact_t
            free = True      # recorded times start the fit; the state stream decides
            vm, vp = rec.impact_v_minus, rec.impact_v_plus
        if max_arcs is not None:
            ev = np.sort(np.concatenate([rec_events[(rec_events > rec.t[0])],
                                         rec.corrections[rec.corrections > rec.t[0]]]))
            if ev.size >= max_arcs:
                end = ev[max_arcs - 1]
                rec = rec.window(rec.t[0], end)
                keep = rec_events < end
                rec_events = rec_events[keep]
                if vm is not None:
                    vm, vp = vm[keep], vp[keep]
        corr_t = rec.corrections
        shifts, best = 0, None
        for _round in range(MAX_SHIFTS + 1):
            prob, sol = _solve(rec, phase, rec_events, vm, vp, corr_t, free,
                               impact_velocities, correction_times, max_nfev, prior, fixed,
                               deadline, actuator)
            if best is None or sol.cost < best[2].cost:   # an event on a sample may cycle
                best = (shifts, prob, sol)
            moved = _shift_from_bounds(prob, sol.x)
            if moved is None:
                break
            shifts += int(np.count_nonzero(moved != np.real(prob.unpack(sol.x)[1])))
            a = prob.arcs
            rec_events, corr_t = moved[a.kind == 1], moved[a.kind == 2]
            vm, vp = a.v_minus[a.kind == 1], a.v_plus[a.kind == 1]
        shifts, prob, sol = best
    except (PhaseError, RecordingError, InitialGuessError) as exc:
        raise IdentificationError(str(exc)) from None
    p = sol.x
    dof = prob.m_data - (prob.n - len(fixed) - prob.n_constraints)
    if dof <= 0:
        raise IdentificationError(f"too few samples: {prob.m_data} data values for "
                                  f"{prob.n - prob.n_constraints} free parameters")
    res = prob.residual(p)
    J = prob.jacobian(p)
    data = res[:prob.m_data]
    sigma2 = float(data @ data) / dof
    g_free = [j for j in range(6) if j not in fixed]
    cov = np.zeros((6, 6))
    cov[np.ix_(g_free, g_free)] = _covariance(
        J[:, np.setdiff1d(np.arange(prob.n), list(fixed))], sigma2, len(g_free))
    se = np.sqrt(np.diag(cov))
    model = RigModel.from_vector(p, phase.omega, phase.tau0)
    # the study's parameters by the delta method (complex-step gradient)
    g = p[:6]
    nd = nondimensional_vector(g, phase.omega)
    G = np.zeros((nd.size, 6))
    for j in range(6):
        q = g.astype(complex)
        q[j] += 1j * _H
        G[:, j] = nondimensional_vector(q, phase.omega).imag / _H
    with np.errstate(invalid="ignore"):
        cov_nd = G @ np.where(np.isfinite(cov), cov, 0.0) @ G.T
    inf_nd = (np.abs(G) > 0) @ (~np.isfinite(np.diag(cov))).astype(float) > 0
    # omega / Omega also carries the reference's uncertainty
    cov_nd[2, 2] += (phase.omega_stderr / g[1]) ** 2
    se_nd = np.sqrt(np.maximum(np.diag(cov_nd), 0.0))
    se_nd[inf_nd] = np.inf
    cov_nd[np.flatnonzero(inf_nd), np.flatnonzero(inf_nd)] = np.inf
    xres = data[:rec.t.size]
    vres = data[rec.t.size:prob.offsets[2]]
    cons = res[prob.m_data:] / prob.weight
    return Identification(
        model=model,
        stderr={n: float(s) for n, s in zip(GLOBAL_NAMES, se)},
        nondimensional={n: (float(v), float(s))
                        for n, v, s in zip(NONDIMENSIONAL_NAMES, nd, se_nd)},
        covariance=cov, sigma=math.sqrt(sigma2),
        rms_x=float(np.sqrt(np.mean(xres ** 2))),
        rms_v=float(np.sqrt(np.mean(vres ** 2))) if vres.size else math.nan,
        constraint_rms=float(np.sqrt(np.mean(cons ** 2))) if cons.size else 0.0,
        phase=phase, problem=prob, solution=p, arcs_used=prob.arcs.count,
        impacts_used=int(np.count_nonzero(prob.arcs.kind == 1)), samples_used=int(rec.t.size),
        dof=int(dof), converged=bool(sol.status > 0), message=str(sol.message),
        nondimensional_covariance=cov_nd,
        events_moved=shifts)

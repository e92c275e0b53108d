"""The initial guess of the fit, from linear regressions (docs/theory_identification.md,
"Initial guess").

1. ARX(2): samples x_j at a uniform step h of one free-flight arc obey exactly

       x_{j+1} = a1 x_j + a2 x_{j-1} + b1 cos tau_j + b2 sin tau_j,
       a1 = 2 e^{-zeta Omega h} cos(w h),  a2 = -e^{-2 zeta Omega h},

   (the homogeneous part is a sum of two exponentials e^{lambda t}, lambda = -zeta Omega
   +- i w, and the forced part a harmonic of tau), so a linear regression on the
   triples inside arcs gives zeta and Omega (:func:`arx`, :func:`modal`).
2. With zeta, Omega fixed the motion is linear in (A cos theta, A sin theta) and in each
   arc's two homogeneous coefficients: one linear least-squares problem, solved with
   each arc's coefficients projected out (:func:`linear_arcs`).
3. d and r from the arcs at the impacts: the median of the positions at the impact times,
   the median of -v+ / v- (or of the recorded impact velocities).

Impacts not recorded are found from the motion (:func:`find_impacts`): a triple that
straddles an impact breaks the ARX recursion; its residual stands out against the
robust spread of the others (least median of squares).
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.dynamics.identification.model import forced_response, free_flight

__all__ = ["InitialGuessError", "arx", "modal", "linear_arcs", "find_impacts",
           "refine_impact_times", "initial_guess"]


class InitialGuessError(ValueError):
    """The data do not determine an initial guess (the message says why)."""


def _triples(t, arc, exclude=None, rtol=1e-6):
    """Centres j of triples (j-1, j, j+1) inside one arc at the recording's modal step h
    (``exclude``: a boolean per sample, centres not to use)."""
    dt = np.diff(t)
    if dt.size < 2:
        raise InitialGuessError("fewer than 3 samples")
    h = float(np.median(dt))
    j = np.arange(1, t.size - 1)
    ok = ((arc[j - 1] == arc[j]) & (arc[j + 1] == arc[j])
          & (np.abs(dt[j - 1] - h) <= rtol * h) & (np.abs(dt[j] - h) <= rtol * h))
    if exclude is not None:
        ok &= ~exclude[j]
    return j[ok], h


def arx(t, x, tau, arc, exclude=None):
    """Least-squares ARX(2) coefficients (a1, a2, b1, b2), the step h, the centres used
    and their residuals (module docstring, step 1)."""
    j, h = _triples(t, arc, exclude)
    if j.size < 6:
        raise InitialGuessError(f"only {j.size} sample triples inside free-flight arcs at a "
                                "uniform step: need at least 6 (more samples per period)")
    M = np.column_stack([x[j], x[j - 1], np.cos(tau[j]), np.sin(tau[j])])
    coef, *_ = np.linalg.lstsq(M, x[j + 1], rcond=None)
    return coef, h, j, x[j + 1] - M @ coef


def modal(a1, a2, h):
    """(zeta, Omega) from the ARX coefficients: zeta Omega = -ln(-a2) / (2 h),
    cos(w h) = a1 / (2 sqrt(-a2)), Omega^2 = w^2 + (zeta Omega)^2."""
    if not -1.0 < a2 < 0.0:
        raise InitialGuessError(f"the ARX recursion is not a damped oscillation "
                                f"(a2 = {a2:.3g}, expected -1 < a2 < 0)")
    k = -math.log(-a2) / (2.0 * h)
    cw = a1 / (2.0 * math.sqrt(-a2))
    w = math.acos(min(1.0, max(-1.0, cw))) / h
    Omega = math.hypot(w, k)
    if not (Omega > 0.0 and k / Omega < 1.0):
        raise InitialGuessError("the ARX recursion gives no underdamped oscillation")
    return k / Omega, Omega


def _forcing_columns(zeta, Omega, omega, tau):
    """Responses (x, v) to cos tau and to -sin tau (module docstring, step 2)."""
    D = Omega * Omega - omega * omega
    E = 2.0 * zeta * Omega * omega
    N = D * D + E * E
    c, s = np.cos(tau), np.sin(tau)
    return ((D * c + E * s) / N, (E * c - D * s) / N,
            omega * (E * c - D * s) / N, -omega * (D * c + E * s) / N)


def _basis(zeta, Omega, h):
    """Homogeneous solutions e^{-zeta Omega h} (cos wh, sin wh) and their derivatives (the
    free flight of :func:`.model.free_flight` without forcing)."""
    k = zeta * Omega
    w = Omega * math.sqrt(1.0 - zeta * zeta)
    e = np.exp(-k * h)
    c, s = np.cos(w * h), np.sin(w * h)
    return e * c, e * s, e * (-k * c - w * s), e * (-k * s + w * c)


def linear_arcs(t, x, v, tau, start, sample_arc, zeta, Omega, omega):
    """(A, theta) and the homogeneous part (x - x_p, v - v_p) of each arc's start state
    (NaN for arcs with fewer than 2 measured values), by linear least squares (module
    docstring, step 2)."""
    fxa, fxb, fva, fvb = _forcing_columns(zeta, Omega, omega, tau)
    h = t - start[sample_arc]
    bx1, bx2, bv1, bv2 = _basis(zeta, Omega, h)
    hasv = np.isfinite(v)
    K = start.size
    order = np.argsort(sample_arc, kind="stable")
    bounds = np.searchsorted(sample_arc[order], np.arange(K + 1))
    normal, rhs = np.zeros((2, 2)), np.zeros(2)
    pieces = []
    for k in range(K):
        idx = order[bounds[k]:bounds[k + 1]]
        vi = idx[hasv[idx]]
        B = np.vstack([np.column_stack([bx1[idx], bx2[idx]]), np.column_stack([bv1[vi], bv2[vi]])])
        F = np.vstack([np.column_stack([fxa[idx], fxb[idx]]), np.column_stack([fva[vi], fvb[vi]])])
        y = np.concatenate([x[idx], v[vi]])
        pieces.append((B, F, y))
        if y.size < 3:
            continue
        Q, _ = np.linalg.qr(B)
        Fp = F - Q @ (Q.T @ F)
        yp = y - Q @ (Q.T @ y)
        normal += Fp.T @ Fp
        rhs += Fp.T @ yp
    try:
        a, b = np.linalg.solve(normal, rhs)
    except np.linalg.LinAlgError:
        raise InitialGuessError("the forcing's amplitude is not determined (arcs too "
                                "short)") from None
    k_ = zeta * Omega
    w = Omega * math.sqrt(1.0 - zeta * zeta)
    X, V = np.full(K, np.nan), np.full(K, np.nan)
    for k, (B, F, y) in enumerate(pieces):
        if y.size < 2:
            continue
        C, *_ = np.linalg.lstsq(B, y - F @ np.array([a, b]), rcond=None)
        X[k], V[k] = C[0], -k_ * C[0] + w * C[1]
    return math.hypot(a, b), math.atan2(b, a), X, V


def find_impacts(t, x, tau, arc, *, threshold=10.0, trials=300, seed=0):
    """Impact intervals found from the motion: (lower, upper) sample times of each.

    A triple that straddles an impact breaks the ARX recursion. The recursion is fitted
    robustly, by least median of squares (Rousseeuw 1984): exact fits to ``trials``
    random sets of 8 triples (seeded), the one whose median squared residual is the
    smallest wins, then least squares on its inliers. Triples whose residual exceeds
    ``threshold`` robust standard deviations (and a floor at rounding) straddle an
    impact; a run of flagged centres j_a..j_b puts one impact in each sample interval
    (t_i, t_i+1), i = j_a..j_b - 1 (one flagged centre: the interval on the side of the
    larger position).
    """
    j, _h = _triples(t, arc)
    if j.size < 16:
        raise InitialGuessError(f"only {j.size} sample triples at a uniform step: too few "
                                "to find the impacts in the motion")
    M = np.column_stack([x[j], x[j - 1], np.cos(tau[j]), np.sin(tau[j])])
    y = x[j + 1]
    rng = np.random.default_rng(seed)
    best, best_med = None, np.inf
    for _ in range(trials):
        pick = rng.choice(j.size, 8, replace=False)
        coef, *_ = np.linalg.lstsq(M[pick], y[pick], rcond=None)
        med = float(np.median((y - M @ coef) ** 2))
        if med < best_med:
            best, best_med = coef, med
    floor = 1e-12 * max(1.0, float(np.max(np.abs(x))))
    coef = best
    for _ in range(2):
        e = y - M @ coef
        spread = 1.4826 * float(np.sqrt(np.median(e ** 2)))
        inlier = np.abs(e) <= threshold * spread + floor
        coef, *_ = np.linalg.lstsq(M[inlier], y[inlier], rcond=None)
    e = y - M @ coef
    spread = 1.4826 * float(np.median(np.abs(e[inlier])))
    flagged = j[np.abs(e) > threshold * spread + floor]
    intervals = []
    if flagged.size:
        runs = np.split(flagged, np.flatnonzero(np.diff(flagged) > 1) + 1)
        for run in runs:
            if run.size == 1:
                c = int(run[0])
                i = c if x[c + 1] >= x[c - 1] else c - 1
                intervals.append((t[i], t[i + 1]))
            else:
                for i in range(int(run[0]), int(run[-1])):
                    intervals.append((t[i], t[i + 1]))
    return intervals


def refine_impact_times(g, omega, tau0, start, X, V, lower, upper, which):
    """For each boundary b in ``which`` (an impact between the samples lower[b], upper[b]),
    the time where the arcs b - 1 and b meet (x continuous at an impact), on a grid
    refined by bisection; the interval's middle if they do not meet.

    All boundaries at once: the grid of 63 inner points and the 60 bisection steps are
    each one array evaluation of the gap x_{b-1}(t) - x_b(t) (:func:`.model.free_flight`)
    over every boundary, elementwise the same arithmetic as one boundary at a time
    (tests/test_identification.py checks the two agree over random arcs)."""
    zeta, Om, A, th = g[:4]
    out = start.copy()
    which = np.asarray(which, int)
    b = which[np.isfinite(X[which - 1]) & np.isfinite(X[which])]
    if b.size == 0:
        return out
    a = b - 1
    psi_a, psi_b = omega * start[a] + tau0 + th, omega * start[b] + tau0 + th

    def gap(tt, rows=slice(None), col=False):
        """x_{b-1}(tt) - x_b(tt) over the boundaries ``rows`` (tt: one time per row, or
        a row of times per boundary with ``col``)."""
        def at(v):
            return v[rows][:, None] if col else v[rows]

        xa, _ = free_flight(zeta, Om, A, omega, at(psi_a), tt - at(start[a]), at(X[a]),
                            at(V[a]))
        xb, _ = free_flight(zeta, Om, A, omega, at(psi_b), tt - at(start[b]), at(X[b]),
                            at(V[b]))
        return xa - xb

    grid = np.linspace(lower[b], upper[b], 65, axis=1)[:, 1:-1]
    f = gap(grid, col=True)
    change = np.sign(f[:, :-1]) * np.sign(f[:, 1:]) <= 0
    met = change.any(axis=1)
    out[b[~met]] = grid[~met, np.argmin(np.abs(f[~met]), axis=1)]
    if met.any():
        rows = np.flatnonzero(met)
        s = np.argmax(change[rows], axis=1)          # the first sign change
        lo, hi = grid[rows, s], grid[rows, s + 1]
        flo = gap(lo, rows)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            fm = gap(mid, rows)
            same = np.sign(fm) == np.sign(flo)
            lo, flo = np.where(same, mid, lo), np.where(same, fm, flo)
            hi = np.where(same, hi, mid)
        out[b[rows]] = 0.5 * (lo + hi)
    return out


def initial_guess(rec, arcs, phase, prior=None):
    """Initial vector g = (zeta, Omega, A, theta, d, r) and the arcs' start states
    (X, V), the arcs' start times (free impact times refined); module docstring.

    ``prior``: (zeta, Omega) known beforehand (a controller re-identifying the model it
    runs, :mod:`grazing_control.dynamics.estimation.reidentification`), used in place of step 1:
    the ARX regression is ill-conditioned on densely sampled noisy data (200 samples a
    period at sigma 1e-4: "no underdamped oscillation"); steps 2-3 are unchanged.
    """
    t, x, v = rec.t, rec.x, rec.v
    tau = phase.phase(t)
    if prior is None:
        coef, h, _j, _e = arx(t, x, tau, arcs.sample_arc)
        zeta, Omega = modal(coef[0], coef[1], h)
    else:
        zeta, Omega = (float(a) for a in prior)
    start = arcs.start.copy()
    A, theta, X, V = _states(t, x, v, tau, start, arcs, zeta, Omega, phase)
    g = np.array([zeta, Omega, A, theta, 0.0, 0.5])
    free = np.flatnonzero(arcs.time_free & (arcs.kind == 1))     # impacts: where arcs meet
    if free.size:
        # the arcs' states at their (provisional) starts -> where neighbours meet
        start = refine_impact_times(g, phase.omega, phase.tau0, start, X, V, arcs.lower,
                                    arcs.upper, free)
        A, theta, X, V = _states(t, x, v, tau, start, arcs, zeta, Omega, phase)
        g[2:4] = A, theta
    imp = np.flatnonzero(arcs.kind == 1)
    ends = []
    for b in imp:
        if np.isfinite(X[b - 1]):
            ends.append(_end_state(g, phase, start, X, V, b))
        else:
            ends.append((np.nan, np.nan))
    ends = np.array(ends).reshape(-1, 2)
    positions = np.concatenate([ends[:, 0], X[imp]])
    positions = positions[np.isfinite(positions)]
    if positions.size == 0:
        raise InitialGuessError("no impact with a fitted arc before or after it: d is "
                                "not determined")
    g[4] = float(np.median(positions))
    vm, vp = arcs.v_minus[imp], arcs.v_plus[imp]
    rec_ok = np.isfinite(vm) & np.isfinite(vp) & (vm > 0)
    if np.any(rec_ok):
        ratios = -vp[rec_ok] / vm[rec_ok]
    else:
        ok = np.isfinite(ends[:, 1]) & np.isfinite(V[imp]) & (ends[:, 1] > 0)
        ratios = -V[imp][ok] / ends[ok, 1]
    ratios = ratios[np.isfinite(ratios)]
    g[5] = float(np.clip(np.median(ratios), 0.05, 0.98)) if ratios.size else 0.5
    # arcs without a fit of their own: chained from the arc before
    for b in range(arcs.count):
        if np.isfinite(X[b]) and np.isfinite(V[b]):
            if arcs.kind[b] == 1:
                X[b] = g[4]
            continue
        if b == 0:
            raise InitialGuessError("the first arc has fewer than 2 measured values")
        xe, ve = _end_state(g, phase, start, X, V, b)
        if arcs.kind[b] == 1:
            X[b], V[b] = g[4], -g[5] * ve
        else:
            X[b], V[b] = xe, ve
    return g, start, X, V


def _end_state(g, phase, start, X, V, b):
    """State of arc b - 1 at the start of arc b (:func:`.model.free_flight`)."""
    zeta, Om, A, th = g[:4]
    om = phase.omega
    return free_flight(zeta, Om, A, om, om * start[b - 1] + phase.tau0 + th,
                       start[b] - start[b - 1], X[b - 1], V[b - 1])


def _states(t, x, v, tau, start, arcs, zeta, Omega, phase):
    """(A, theta) and the arcs' start states: :func:`linear_arcs` plus the forced
    response (:func:`.model.forced_response`)."""
    A, theta, C1, C2v = linear_arcs(t, x, v, tau, start, arcs.sample_arc, zeta, Omega,
                                    phase.omega)
    # linear_arcs returns the homogeneous part at the start: add the forced response
    xp, vp = forced_response(zeta, Omega, A, phase.omega, phase.phase(start) + theta)
    return A, theta, xp + C1, vp + C2v

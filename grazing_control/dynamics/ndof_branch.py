"""The controlled 1/1 branch of the n-DOF oscillator, explicit in the impact phase.

docs/theory_ndof.md §5 (the n-DOF form of docs/theory.md §5). Take the wall as the
section: an impact at forcing phase tau* + psi, just before it the deviation
z- = X- - X_p has wall position Delta d + 2 d* sin^2(psi/2) and wall velocity
v- + d* omega sin psi; after it z+ = z- - (1 + r) v- e_v. Over one period
z- = M(psi) z+, M(psi) = Phi(T - sigma)(I + b k^T) Phi(sigma), sigma = s - psi/omega
the time from the impact to Pi2. Periodicity (M - I) z- = (1 + r) v- M e_v gives, for a
given psi, z- = (1 + r) v- (I + R) e_v with R = (M - I)^-1; its wall velocity and position
components fix v- and Delta d:

    v- = d* omega sin(psi) / (r + (1 + r) e_v^T R e_v),
    Delta d = (1 + r) v- w^T R e_v - 2 d* sin^2(psi/2),

so the branch is an explicit curve psi -> (Delta d, v-, z-), exact up to rounding. Its
monodromy at the impact is J = M S, S the saltation matrix (oscillator/ndof/impact.py).
This is the exact reference for the limit multipliers and the existence coefficient of
ndof_design (no shooting, no expansion); it assumes the one impact of the period is the only contact (a local
statement: the orbit near grazing; shooting on the exact period map is the global check).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.ndof.impact import saltation_matrix
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from .ndof_design import _flow, _gains, _transition, _vectors, smooth_map

__all__ = ["BranchPoint", "branch_point", "branch_coefficients", "orbit_at", "branch_fold"]


class BranchPoint(NamedTuple):
    """One 1/1 orbit on the branch: impact phase psi (after tau*), wall offset Delta d,
    impact velocity v-, the deviation z- just before the impact, its monodromy J there
    (None where v- <= 0: not a physical orbit), and the Pi2 state (before the kick) of
    the same orbit."""

    psi: float
    delta_d: float
    v_minus: float
    state: np.ndarray
    monodromy: np.ndarray
    pi2_state: np.ndarray


def _impact_map(model: NdofModel, k: np.ndarray, psi: float):
    """(M(psi), Phi(sigma)): the period map from an impact at tau* + psi to the next,
    M = Phi(T - sigma)(I + b k^T) Phi(sigma), sigma = s - psi/omega (module docstring)."""
    om = model.omega
    s = model.pi2_offset / om
    sigma = s - psi / om
    if not (0.0 < sigma < model.period) or not math.isfinite(psi):
        raise ParameterError(f"psi={psi!r} is invalid: valid range is "
                             f"{-om * (model.period - s)!r} < psi < {om * s!r} "
                             f"(impact between kicks)")
    _w, _ev, b = _vectors(model)
    pm = _transition(model, sigma)
    eye = np.eye(2 * model.n)
    return _transition(model, model.period - sigma) @ (eye + np.outer(b, k)) @ pm, pm


def branch_point(model: NdofModel, gains, psi: float) -> BranchPoint:
    """The 1/1 orbit with its impact at phase tau* + psi (§5, Eq. (N5)).

    Periodicity (M - I) z- = (1 + r) v- M e_v gives z- = (1 + r) v- (e_v + R e_v),
    R = (M - I)^-1, whose wall velocity and position components are

        v- = d* omega sin(psi) / (r + (1 + r) e_v^T R e_v),
        Delta d = (1 + r) v- w^T R e_v - 2 d* sin^2(psi/2).

    psi must put the impact between the Pi2 kicks: -omega (T - s) < psi < omega s.
    """
    k = _gains(model, gains)
    psi = float(psi)
    m, pm = _impact_map(model, k, psi)
    w, ev, _b = _vectors(model)
    dstar, om, r = _flow(model).d_star, model.omega, model.r
    try:
        rev = np.linalg.solve(m - np.eye(2 * model.n), ev)
    except np.linalg.LinAlgError:
        raise ParameterError(f"psi={psi!r} is invalid: the period map M(psi) has the "
                             f"eigenvalue 1 there (no isolated 1/1 orbit)") from None
    v = dstar * om * math.sin(psi) / (r + (1.0 + r) * float(ev @ rev))
    dd = (1.0 + r) * v * float(w @ rev) - 2.0 * dstar * math.sin(0.5 * psi) ** 2
    z = (1.0 + r) * v * (ev + rev)
    flow = _flow(model)
    jac = m @ saltation_matrix(flow, flow.tau_star + psi, z) if v > 0.0 else None
    z2 = pm @ (z - (1.0 + r) * v * ev)
    return BranchPoint(psi, dd, v, z, jac, z2)


def branch_coefficients(model: NdofModel, gains):
    """(d1, gamma1, v1): Delta d = d1 psi - gamma1 psi^2 + O(psi^3), v- = v1 psi + O(psi^2)
    on the 1/1 branch born at grazing, for any gains (§7, Eq. (N7')).

    With N = N(k), R = (N - I)^-1, M' = [A, N]/omega, q0 = r + (1 + r) e_v^T R e_v:
    v1 = d* omega / q0, d1 = (1 + r) v1 w^T R e_v (proportional to G(1) of §2: zero iff
    the branch is smooth), gamma1 = d*/2 - (1 + r)(v1 b1 + v2 b0) with b0 = w^T R e_v,
    b1 = -w^T R M' R e_v, v2 = -(1 + r) v1 a1' / q0, a1' = -e_v^T R M' R e_v.
    On the family (w^T N = mu w^T) gamma1 is ndof_design.existence_coefficient.
    """
    k = _gains(model, gains)
    n_mat = smooth_map(model, k)
    w, ev, _b = _vectors(model)
    a = _flow(model).A
    dstar, om, r = _flow(model).d_star, model.omega, model.r
    res = np.linalg.inv(n_mat - np.eye(2 * model.n))
    mp = (a @ n_mat - n_mat @ a) / om
    q0 = r + (1.0 + r) * float(ev @ res @ ev)
    v1 = dstar * om / q0
    b0 = float(w @ res @ ev)
    b1 = -float(w @ res @ mp @ res @ ev)
    a1p = -float(ev @ res @ mp @ res @ ev)
    v2 = -(1.0 + r) * v1 * a1p / q0
    return (1.0 + r) * v1 * b0, 0.5 * dstar - (1.0 + r) * (v1 * b1 + v2 * b0), v1


def orbit_at(model: NdofModel, gains, delta_d: float, psi_max: float = 0.3) -> BranchPoint:
    """The 1/1 orbit born at grazing at the wall offset ``delta_d`` (< 0), v- > 0.

    Walks |psi| outwards on both sides of grazing (1e-12 .. psi_max, logarithmic) and
    solves Delta d(psi) = delta_d by Brent's method on the first bracket with v- > 0 on
    the side nearer grazing. Raises ValueError when no such orbit is found.
    """
    k = _gains(model, gains)
    mags = np.geomspace(1e-12, psi_max, 400)
    best = None
    for sign in (1.0, -1.0):
        prev = None
        for a in mags:
            bp = branch_point(model, k, sign * a)
            if bp.v_minus <= 0.0:
                break
            val = bp.delta_d - delta_d
            if prev is not None and (val > 0.0) != (prev[1] > 0.0):
                if best is None or a < best[2]:
                    best = (prev[0], sign * a, a)
                break
            prev = (sign * a, val)
    if best is None:
        raise ValueError(f"delta_d={delta_d!r}: no 1/1 orbit born at grazing with v- > 0 "
                         f"for |psi| <= {psi_max!r}")
    psi = brentq(lambda x: branch_point(model, k, x).delta_d - delta_d, best[0], best[1],
                 xtol=1e-300, rtol=4.0 * 2.0 ** -52, maxiter=400)
    return branch_point(model, k, psi)


def branch_fold(model: NdofModel, gains, steps: int = 2000):
    """The first fold of the branch born at grazing (``gains`` None: uncontrolled),
    walking away from grazing in the impact phase, or None if there is none before v-
    or the window of psi ends.

    A fold is a turning point of Delta d(psi) (§5): there d(Delta d)/dpsi = 0 and the
    orbit is not isolated in Delta d, so its monodromy has the multiplier 1. Where a
    continuation in Delta d stops (it cannot pass a turning point), this names it.
    The side of grazing is that of v- ~ v1 psi > 0 (``branch_coefficients``); the fold
    is bracketed on a grid of ``steps`` phases up to the end of the window
    -omega (T - s) < psi < omega s and located by Brent's method on a central-difference
    slope.
    """
    k = _gains(model, np.zeros(2 * model.n) if gains is None else gains)
    sgn = math.copysign(1.0, branch_coefficients(model, k)[2])
    s = model.pi2_offset / model.omega
    bound = model.omega * s if sgn > 0 else model.omega * (model.period - s)
    grid = sgn * np.linspace(1e-6 * bound, 0.999 * bound, steps)

    def slope(psi):
        h = 1e-7 * max(1e-3, abs(psi))
        return (branch_point(model, k, psi + h).delta_d
                - branch_point(model, k, psi - h).delta_d) / (2.0 * h)

    first = slope(grid[0]) > 0.0
    prev = grid[0]
    for psi in grid[1:]:
        try:
            if branch_point(model, k, psi).v_minus <= 0.0:
                return None
            turned = (slope(psi) > 0.0) != first
        except ParameterError:
            return None
        if turned:
            return branch_point(model, k, brentq(slope, prev, psi, xtol=1e-13))
        prev = psi
    return None

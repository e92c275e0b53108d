"""Periodic orbits of any period map by Newton shooting; Floquet multipliers; test functions.

Written once over the model protocol (:class:`grazing_control.dynamics.maps.model.PeriodMap`):
a p/n orbit is a fixed point of P^n, found by Newton's method on the residual
P^n(z) - z with the Jacobian DP^n - I, DP^n the product of the per-period Jacobians in
time order (the monodromy: Phi, S and G along the orbit, spec section 5). Its
eigenvalues are the Floquet multipliers, and the bifurcation test functions of
docs/theory.md section 7 are functions of them:

* period doubling: det(J + I) = prod (1 + lambda_i), zero when a multiplier is -1;
* fold: det(J - I) = prod (lambda_i - 1), zero when a multiplier is +1;
* Neimark-Sacker: prod over pairs i < j of (lambda_i lambda_j - 1), taken where a
  complex pair is the one on the unit circle (for n = 2: det J - 1 with
  tr^2 < 4 det), else nan.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.maps.model import PeriodMap

__all__ = ["Orbit", "ShootingFailed", "iterate", "find_periodic", "floquet_multipliers",
           "bifurcation_tests", "TEST_FUNCTIONS"]

#: Names of the test functions of :func:`bifurcation_tests`, in order.
TEST_FUNCTIONS = ("period-doubling", "fold", "neimark-sacker")


class ShootingFailed(RuntimeError):
    """Newton shooting did not converge, or the map failed along the way."""


class Orbit(NamedTuple):
    """A fixed point of P^n: section state, monodromy J = DP^n, impacts of the n periods
    (``dt`` counted from the first sample), and n."""

    state: np.ndarray
    monodromy: np.ndarray
    impacts: tuple
    periods: int


def iterate(model: PeriodMap, state, periods: int = 1):
    """P^n(state) with its Jacobian (the product of DP in time order) and the impacts,
    whose ``dt`` counts from the first sample. Returns (state, jacobian, impacts)."""
    z = np.asarray(state, dtype=float)
    jac = np.eye(model.dimension)
    impacts = []
    for k in range(periods):
        s = model.step(z, jacobian=True)
        impacts += [i._replace(dt=i.dt + k * model.period) for i in s.impacts]
        jac = s.jacobian @ jac
        z = s.state
    return z, jac, tuple(impacts)


def find_periodic(model: PeriodMap, guess, periods: int = 1, *, tol: float = 1e-14,
                  max_iter: int = 60) -> Orbit:
    """The p/n orbit near ``guess`` by Newton shooting on P^n(z) - z = 0.

    Converged when the Newton step is below ``tol`` relative to |z| (or stagnates at
    the map's rounding floor: no quadratic decrease below 1e-8 relative).

    Raises
    ------
    ShootingFailed
        No convergence in ``max_iter`` steps, a singular Jacobian (a multiplier at 1),
        or a step that leaves the model's domain (the map raises ValueError or
        ArithmeticError).
    """
    if int(periods) != periods or periods < 1:
        raise ValueError(f"periods={periods!r} is invalid: valid range is an integer >= 1")
    z = np.array(guess, dtype=float)
    if z.shape != (model.dimension,) or not np.all(np.isfinite(z)):
        raise ValueError(f"guess={guess!r} is invalid: expected {model.dimension} finite values")
    eye = np.eye(model.dimension)
    previous = math.inf
    for _ in range(max_iter):
        try:
            zn, jac, _ = iterate(model, z, periods)
            step = np.linalg.solve(jac - eye, -(zn - z))
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            raise ShootingFailed(f"Newton shooting failed at z={z.tolist()}: {exc}") from None
        z = z + step
        size = float(np.max(np.abs(step)))
        scale = max(float(np.max(np.abs(z))), 1e-300)
        if size <= tol * scale or (size > 0.5 * previous and size <= 1e-8 * scale):
            break
        previous = size
    else:
        raise ShootingFailed(f"Newton shooting did not converge in {max_iter} iterations")
    try:
        _, jac, impacts = iterate(model, z, periods)
    except (ValueError, ArithmeticError) as exc:
        raise ShootingFailed(f"the converged orbit leaves the model's domain: {exc}") from None
    return Orbit(z, jac, impacts, int(periods))


def floquet_multipliers(monodromy, det: float | None = None) -> np.ndarray:
    """Eigenvalues of the monodromy, sorted by decreasing modulus (complex array).

    For a 2x2 matrix they come from trace and determinant with the cancellation-free
    quadratic formula (lambda1 = (tr + sign(tr) sqrt(tr^2 - 4 det)) / 2,
    lambda2 = det / lambda1), so the small multiplier stays accurate when the large one
    grows like 1/v- near grazing; ``det`` may then be given exactly (e.g.
    e^{-2 zeta n T} r^(2 m) (1 + c2)^n, :meth:`PeriodMap.jacobian_det`). Larger
    matrices: numpy's eigenvalues (LAPACK).
    """
    m = np.asarray(monodromy, dtype=float)
    if m.size == 4:
        m = m.reshape(2, 2)
        tr = m[0, 0] + m[1, 1]
        if det is None:
            det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        root = np.sqrt(complex(tr * tr - 4.0 * det))
        if tr * tr - 4.0 * det >= 0.0:
            l1 = 0.5 * (tr + math.copysign(1.0, tr) * root.real)
            l2 = det / l1 if l1 != 0.0 else 0.0
            lam = np.array([l1, l2], dtype=complex)
        else:
            lam = np.array([0.5 * (tr + root), 0.5 * (tr - root)])
    else:
        lam = np.linalg.eigvals(m).astype(complex)
    return lam[np.argsort(-np.abs(lam), kind="stable")]


def bifurcation_tests(multipliers) -> dict:
    """The test functions of the module docstring from the multipliers (real values;
    Neimark-Sacker nan unless the pair nearest the unit circle is complex)."""
    lam = np.asarray(multipliers, dtype=complex)
    pd = float(np.prod(1.0 + lam).real)
    fold = float(np.prod(lam - 1.0).real)
    ns = math.nan
    pairs = [(i, j) for i in range(lam.size) for j in range(i + 1, lam.size)]
    if pairs:
        i, j = min(pairs, key=lambda ij: abs(abs(lam[ij[0]] * lam[ij[1]]) - 1.0))
        if abs(lam[i].imag) > 0.0 and np.isclose(lam[i], np.conj(lam[j]), rtol=1e-9):
            ns = float(np.prod([lam[a] * lam[b] - 1.0 for a, b in pairs]).real)
    return {"period-doubling": pd, "fold": fold, "neimark-sacker": ns}

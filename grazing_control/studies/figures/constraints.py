"""The control constraints against c2 and the admissible set: Figs. 2(a) and 2(b).

For each c2, c1 follows from the degenerate condition N_g,12 = 0 (Eq. 38); then
(spec section 6, docs/theory.md §6)

* (a) the limit multipliers lambda0 (Eq. 23): the near-grazing 1/1 motion is stable
  iff max|lambda0| < 1 (Eqs. 34, 35);
* (b) the existence coefficient gamma1 (Eq. 36): the controlled 1/1 motion lives on
  the impacting side d < d* iff gamma1 > 0;
* and, drawn in (a), the multipliers of the controlled non-impacting 0/1 motion
  (Delta d > 0), the eigenvalues of N_g (Eqs. 29-32): the controller acts on that
  motion too, and it stays stable only where max|eig N_g| < 1.

Lines are the exact route (:func:`grazing_control.dynamics.design.gains.evaluate_design`), circles the
perturbation formulas (:mod:`grazing_control.dynamics.maps.perturbation`); the shaded set is
:func:`grazing_control.dynamics.design.gains.admissible_c2`, the design tool's own answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from scipy.optimize import brentq

from grazing_control.dynamics.design.gains import admissible_c2, degenerate_c1, evaluate_design
from grazing_control.dynamics.maps.maps import smooth_return_matrix
from grazing_control.dynamics.orbits.orbits import multipliers
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.perturbation import (admissible_c2_perturbation,
                                                   existence_coefficient_perturbation,
                                                   limit_multipliers_perturbation)
from grazing_control.support.plotting import COLORS, PANEL_SIZE, pyplot, save
from .report import Number, Panel

__all__ = ["ConstraintData", "constraint_data", "panel_2a", "panel_2b"]


@dataclass(frozen=True)
class ConstraintData:
    """lambda0 and gamma1 against c2, exact (lines) and perturbation (circles).

    c2, lambda0 (n, 2) complex, gamma1 (n,), free (n,) = max|eig N_g|: exact on a fine
    grid; c2_p, lambda0_p, gamma1_p: perturbation on a coarse grid; admissible,
    admissible_p: the intervals.
    """

    c2: np.ndarray
    lambda0: np.ndarray
    gamma1: np.ndarray
    free: np.ndarray
    c2_p: np.ndarray
    lambda0_p: np.ndarray
    gamma1_p: np.ndarray
    admissible: tuple
    admissible_p: tuple


def constraint_data(p: OscillatorParams, c2_range=(-3.0, 1.0), points: int = 401,
                    circles: int = 21) -> ConstraintData:
    """Evaluate the design on ``points`` values of c2 (and the perturbation on ``circles``)."""
    c2 = np.linspace(*c2_range, points)
    designs = [evaluate_design(p, float(c)) for c in c2]
    c2_p = np.linspace(*c2_range, circles)
    gains = [Gains(degenerate_c1(p, float(c)), float(c)) for c in c2_p]
    return ConstraintData(
        c2=c2,
        lambda0=np.array([d.multipliers_limit for d in designs]).reshape(-1, 2),
        gamma1=np.array([d.gamma1 for d in designs]),
        free=np.array([_free(p, float(c)) for c in c2]),
        c2_p=c2_p,
        lambda0_p=np.array([limit_multipliers_perturbation(p, g) for g in gains]).reshape(-1, 2),
        gamma1_p=np.array([existence_coefficient_perturbation(p, g) for g in gains]),
        admissible=tuple(tuple(float(x) for x in iv) for iv in admissible_c2(p)),
        admissible_p=tuple(tuple(float(x) for x in iv) for iv in admissible_c2_perturbation(p)),
    )


def _free(p: OscillatorParams, c2: float) -> float:
    """max|eig N_g| with c1 from Eq. 38: the controlled 0/1 motion's largest multiplier."""
    g = Gains(degenerate_c1(p, c2), c2)
    return float(np.max(np.abs(multipliers(smooth_return_matrix(p, g)))))


def _free_range(p: OscillatorParams, data: ConstraintData):
    """The c2 interval around the chosen grid's stable part of the 0/1 motion, its ends
    refined by Brent's method on max|eig N_g| - 1."""
    ok = data.free < 1.0
    if not ok.any():
        return None
    k = np.flatnonzero(ok)
    lo, hi = k[0], k[-1]
    f = lambda c: _free(p, c) - 1.0  # noqa: E731
    a = brentq(f, data.c2[lo - 1], data.c2[lo], xtol=1e-13) if lo > 0 else float(data.c2[0])
    b = brentq(f, data.c2[hi], data.c2[hi + 1], xtol=1e-13) if hi + 1 < data.c2.size \
        else float(data.c2[-1])
    return float(a), float(b)


def _gamma1_zero(p: OscillatorParams, data: ConstraintData):
    """The zero of gamma1 (not a pole) on the grid, refined by Brent's method."""
    g = data.gamma1
    flips = [k for k in np.flatnonzero(np.diff(np.sign(g)) != 0) if k not in _poles(data)]
    if not flips:
        return None
    k = flips[0]
    return float(brentq(lambda c: evaluate_design(p, c).gamma1, data.c2[k], data.c2[k + 1],
                        xtol=1e-13))


def _binding(p: OscillatorParams, c2: float, tol: float = 1e-6) -> str:
    """Which drawn conditions are marginal (within tol) at c2: '|λ0| = 1', 'γ1 = 0',
    'max|eig N_g| = 1'."""
    d = evaluate_design(p, c2)
    out = []
    if abs(float(np.max(np.abs(d.multipliers_limit))) - 1.0) < tol:
        out.append("|λ0| = 1")
    if abs(d.gamma1) < tol:
        out.append("γ1 = 0")
    if abs(_free(p, c2) - 1.0) < tol:
        out.append("max|eig N_g| = 1")
    return " and ".join(out) or "none of the drawn conditions"


def _shade(ax, data: ConstraintData, chosen: float):
    for k, (lo, hi) in enumerate(data.admissible):
        ax.axvspan(lo, hi, color=COLORS["admissible"], alpha=0.12, lw=0,
                   label="admissible c2 (design.admissible_c2)" if k == 0 else None)
    ax.axvline(chosen, color="k", lw=0.8, ls=":", label=f"chosen c2 = {chosen:g}")


def _interval_numbers(data: ConstraintData, chosen: float, p: OscillatorParams):
    exact = data.admissible
    pert = data.admissible_p
    d = evaluate_design(p, chosen)
    out = [Number("admissible_c2", "admissible c2 (exact)", exact[0] if len(exact) == 1 else exact,
                  fmt=".10g", note="design.admissible_c2"),
           Number("admissible_ends_binding", "conditions marginal at its ends",
                  " / ".join(_binding(p, float(c)) for iv in exact for c in iv),
                  note="evaluated at the ends (tolerance 1e-6)"),
           Number("admissible_c2_perturbation", "admissible c2 (perturbation)",
                  pert[0] if len(pert) == 1 else pert, fmt=".10g",
                  note="perturbation.admissible_c2_perturbation"),
           Number("c1_at_chosen", f"c1 at c2 = {chosen:g}", float(d.c1), "−1.02060", fmt=".8f",
                  note="Eq. 38")]
    return out, d


def panel_2a(p: OscillatorParams, data: ConstraintData, chosen: float, out) -> Panel:
    """Fig. 2(a): |lambda0| against c2 with the stability bound |lambda0| < 1."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    _shade(ax, data, chosen)
    mods = np.abs(data.lambda0)
    ax.plot(data.c2, mods[:, 0], "-", color="k", lw=1.4, label="|λ0,1| (exact)")
    ax.plot(data.c2, mods[:, 1], "-", color="0.55", lw=1.4, label="|λ0,2| (exact)")
    pm = np.abs(data.lambda0_p)
    ax.plot(data.c2_p, pm[:, 0], "o", mfc="none", color=COLORS["perturbation"], ms=6,
            label="perturbation (Eq. 23)")
    ax.plot(data.c2_p, pm[:, 1], "o", mfc="none", color=COLORS["perturbation"], ms=6)
    ax.plot(data.c2, data.free, "-.", color=COLORS["stable"], lw=1.2,
            label="max|eig N_g|: 0/1 motion, Δd > 0")
    ax.axhline(1.0, color=COLORS["unstable"], lw=0.9, ls="--", label="|λ| = 1")
    ax.set(xlim=(data.c2[0], data.c2[-1]), ylim=(0.0, min(2.5, 1.05 * mods.max())),
           xlabel="c2  (c1 from N_g,12 = 0, Eq. 38)", ylabel="|λ|",
           title="Fig. 2(a): stability of the controlled 1/1 motion at grazing")
    fig.legend(fontsize=7.5, loc="outside lower center", ncol=3)
    files = save(fig, out, "fig2a")
    nums, d = _interval_numbers(data, chosen, p)
    stable = mods[:, 0] < 1.0
    nums += [Number("lambda0_at_chosen", f"|λ0| at c2 = {chosen:g}",
                    tuple(float(a) for a in np.abs(d.multipliers_limit)), fmt=".8f"),
             Number("stable_c2", "c2 grid range with max|λ0| < 1",
                    (float(data.c2[stable].min()), float(data.c2[stable].max())) if stable.any() else None,
                    fmt=".4g", note=f"{data.c2.size}-point grid"),
             Number("min_abs_lambda0", "min over c2 of max|λ0|", float(mods[:, 0].min()), fmt=".6f",
                    note=f"at c2 = {data.c2[np.argmin(mods[:, 0])]:.4g}"),
             Number("free_stable_c2", "c2 where the controlled 0/1 motion is stable",
                    _free_range(p, data), fmt=".10g",
                    note="max|eig N_g| < 1 (Eqs. 29-32), ends by Brent"),
             Number("free_abs_at_chosen", f"|eig N_g| at c2 = {chosen:g}",
                    float(data.free[np.argmin(np.abs(data.c2 - chosen))]), fmt=".6f")]
    return Panel("fig2a", "control constraint |λ0| < 1",
                 "Moduli of the limit multipliers λ0 of the controlled 1/1 motion at grazing "
                 "(Eq. 23) against c2, c1 from the degenerate condition (Eq. 38): exact "
                 "(lines) and perturbation (circles). Stability needs both inside the unit "
                 "circle (below the dashed line). Dash-dotted: the largest multiplier of the "
                 "controlled non-impacting 0/1 motion (Δd > 0, eig N_g), which the controller "
                 "also acts on. Shaded: the admissible set as computed by "
                 "design.admissible_c2; dotted: the study's c2 = −1.",
                 tuple(files), tuple(nums))


def _poles(data: ConstraintData) -> np.ndarray:
    """Grid cells where gamma1 changes sign through a pole: large on both sides (a zero
    is small on one side at least)."""
    g = data.gamma1
    flips = np.flatnonzero(np.diff(np.sign(g)) != 0)
    return flips[np.minimum(np.abs(g[flips]), np.abs(g[flips + 1])) > 10.0]


def panel_2b(p: OscillatorParams, data: ConstraintData, chosen: float, out) -> Panel:
    """Fig. 2(b): gamma1 against c2 with the existence bound gamma1 > 0 (symlog axis)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    _shade(ax, data, chosen)
    poles = _poles(data)
    ax.plot(np.insert(data.c2, poles + 1, np.nan), np.insert(data.gamma1, poles + 1, np.nan),
            "-", color="k", lw=1.4, label="γ1 (exact)")
    for k, i in enumerate(poles):
        ax.axvline(0.5 * (data.c2[i] + data.c2[i + 1]), color="0.5", lw=0.7, ls="-.",
                   label="pole of γ1" if k == 0 else None)
    ax.plot(data.c2_p, data.gamma1_p, "o", mfc="none", color=COLORS["perturbation"], ms=6,
            label="γ1 (perturbation)")
    ax.axhline(0.0, color=COLORS["unstable"], lw=0.9, ls="--", label="γ1 = 0")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set(xlim=(data.c2[0], data.c2[-1]), xlabel="c2  (c1 from N_g,12 = 0, Eq. 38)",
           ylabel="γ1  (symmetric log scale)",
           title="Fig. 2(b): existence of the controlled 1/1 motion for d < d*")
    ax.legend(fontsize=8, loc="lower center")
    files = save(fig, out, "fig2b")
    d = evaluate_design(p, chosen)
    pos = data.gamma1 > 0.0
    flips = np.flatnonzero(np.diff(np.sign(data.gamma1)) != 0)
    big = np.isin(flips, poles)
    cell = [float(0.5 * (data.c2[k] + data.c2[k + 1])) for k in flips]
    nums = [Number("gamma1_at_chosen", f"γ1 at c2 = {chosen:g}", float(d.gamma1), fmt=".6g"),
            Number("gamma1_zeros", "c2 grid cells where γ1 crosses 0",
                   tuple(c for c, b in zip(cell, big) if not b), fmt=".4g",
                   note=f"{data.c2.size}-point grid; the admissible set's end is Brent's"),
            Number("gamma1_poles", "c2 grid cells where γ1 jumps through ±∞",
                   tuple(c for c, b in zip(cell, big) if b), fmt=".4g"),
            Number("gamma1_zero", "c2 where γ1 = 0", _gamma1_zero(p, data), fmt=".10g",
                   note="Brent in the grid cell of the zero crossing"),
            Number("gamma1_positive_fraction", "fraction of the c2 grid with γ1 > 0",
                   float(np.mean(pos)), fmt=".3f")]
    return Panel("fig2b", "control constraint γ1 > 0",
                 "The existence coefficient γ1 (Eq. 36; Δd = −γ1 ψ² + … along the controlled "
                 "branch) against c2: exact (line) and perturbation (circles), on a symmetric "
                 "log axis. The controlled 1/1 motion exists on the impacting side d < d* "
                 "where γ1 > 0. Shaded: the admissible set as computed by "
                 "design.admissible_c2 (the stability constraints are in Fig. 2(a)).", tuple(files), tuple(nums))

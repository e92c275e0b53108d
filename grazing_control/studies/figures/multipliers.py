"""Floquet multipliers of the 1/1 motion, shooting against perturbation: Figs. 1(d), 2(d), 2(e).

Lines: the exact multipliers along the continued branch (impact-phase shooting,
:mod:`grazing_control.studies.figures.branches`). Circles: the perturbation estimates of
:mod:`grazing_control.dynamics.maps.perturbation` (series in the impact velocity delta2, spec
section 7), at a few Delta d where the exact multipliers are also computed directly
(:func:`grazing_control.dynamics.orbits.one_one.orbit`) for the numbers. |Delta d| is on a
logarithmic axis: the uncontrolled large multiplier grows like 1/|Delta d| (the
square-root singularity of the discontinuity map, docs/theory.md §5); the controlled
ones tend to lambda0 (Eq. 23) with an error O(delta2) = O(|Delta d|^(1/2)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import limit_multipliers
from grazing_control.dynamics.orbits import one_one
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.perturbation import (limit_multipliers_perturbation,
                                                   perturbation_multipliers,
                                                   period_doubling_perturbation)
from grazing_control.support.plotting import COLORS, PANEL_SIZE, pyplot, save
from .branches import BranchData, loglog_slope
from .report import Number, Panel

__all__ = ["Samples", "samples", "panel_1d", "panel_2d", "panel_2e"]


@dataclass(frozen=True)
class Samples:
    """Multipliers at chosen Delta d: exact (one_one.orbit) and perturbation ((n, 2) complex)."""

    delta_d: np.ndarray
    exact: np.ndarray
    perturbation: np.ndarray
    truncation: str


def samples(p: OscillatorParams, gains: Gains | None, delta_d, truncation: str) -> Samples:
    """Exact and perturbation multipliers at each Delta d (< 0) of ``delta_d``."""
    dd = np.asarray(delta_d, dtype=float)
    exact = [one_one.orbit(p, gains, float(d), check=False).multipliers for d in dd]
    pert = [perturbation_multipliers(p.with_(delta_d=float(d)), gains, truncation) for d in dd]
    return Samples(dd, np.array(exact).reshape(-1, 2), np.array(pert).reshape(-1, 2), truncation)


def _rel_diff(s: Samples, lo: float, hi: float) -> float:
    """max over lo <= |Delta d| <= hi of the relative difference of the largest modulus."""
    keep = (np.abs(s.delta_d) >= lo) & (np.abs(s.delta_d) <= hi)
    a, b = np.abs(s.exact[keep, 0]), np.abs(s.perturbation[keep, 0])
    ok = np.isfinite(b)
    return float(np.max(np.abs(b[ok] - a[ok]) / a[ok])) if np.any(ok) else float("nan")


_XLABEL = "|Δd|  (Δd < 0; grazing to the right)"
_TRUNC = {"limit": "Eq. 26 truncation", "practical": "Eq. 25 truncation"}


def panel_1d(p: OscillatorParams, data: BranchData, s: Samples, out) -> Panel:
    """Fig. 1(d): |multipliers| of the uncontrolled 1/1 motion against |Delta d| (log-log)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    ad = np.abs(data.delta_d)
    mods = np.abs(data.multipliers)
    ax.loglog(ad, mods[:, 0], "-", color="k", lw=1.4, label="|λ1|, shooting")
    ax.loglog(ad, mods[:, 1], "-", color="0.55", lw=1.4, label="|λ2|, shooting")
    pm = np.abs(s.perturbation)
    ax.loglog(np.abs(s.delta_d), pm[:, 0], "o", mfc="none", color=COLORS["perturbation"], ms=6,
              label=f"perturbation ({_TRUNC[s.truncation]})")
    ax.loglog(np.abs(s.delta_d), pm[:, 1], "o", mfc="none", color=COLORS["perturbation"], ms=6)
    ax.axhline(1.0, color="0.3", lw=0.7, ls="--")
    pd = data.bifurcation("period-doubling")
    ax.axvline(abs(pd.delta_d), color=COLORS["bifurcation"], lw=0.8, ls=":",
               label=f"period doubling, Δd = {pd.delta_d:.6g}")
    stable = data.stable
    ax.fill_between(ad, 1e-30, 1e30, where=stable, color=COLORS["stable"], alpha=0.08, lw=0,
                    label="1/1 stable")
    ax.set(xlim=(ad.min(), ad.max()), ylim=(0.5 * mods[:, 1].min(), 2.0 * mods[:, 0].max()),
           xlabel=_XLABEL, ylabel="|λ|",
           title="Fig. 1(d): multipliers of the 1/1 motion (uncontrolled)")
    ax.invert_xaxis()
    ax.legend(fontsize=8, loc="upper left")
    files = save(fig, out, "fig1d")
    pd_lim, _ = period_doubling_perturbation(p, None, "limit")
    pd_pra, _ = period_doubling_perturbation(p, None, "practical")
    small = np.argmin(ad)
    numbers = (
        Number("pd_delta_d", "period doubling Δd_PD (shooting, continuation)", pd.delta_d,
               "−1.00527e-5", fmt=".12g", note="multiplier −1: 1 + tr J + det J = 0"),
        Number("pd_multipliers", "multipliers at Δd_PD", tuple(float(x.real) for x in pd.multipliers),
               fmt=".6f"),
        Number("pd_delta_d_perturbation_limit", "Δd_PD, perturbation (Eq. 26)", pd_lim,
               "−1.00527e-5", fmt=".9g",
               note="1 + tr + ψ0 = 0 with the truncated trace"),
        Number("pd_delta_d_perturbation_practical", "Δd_PD, perturbation (with χ1 δ2)", pd_pra,
               fmt=".9g"),
        Number("slope", "max|λ| ∝ |Δd|^s: s on [1e-12, 1e-8]",
               loglog_slope(data.delta_d, mods[:, 0], 1e-12, 1e-8), fmt=".5f",
               note="least squares on the shooting line; theory −1"),
        Number("growth_constant", f"|Δd| max|λ| at Δd = {data.delta_d[small]:.3g}",
               float(ad[small] * mods[small, 0]), fmt=".5g"),
        Number("perturbation_rel_error_near", "max rel. difference |λ1| perturbation vs shooting, "
               "|Δd| ≤ 1e-8", _rel_diff(s, 0.0, 1e-8), fmt=".2e", note="at the circles"),
        Number("perturbation_rel_error_far", "the same for 1e-8 < |Δd| ≤ 1e-5",
               _rel_diff(s, 1e-8 * (1 + 1e-12), 1e-5), fmt=".2e"),
        Number("complex_pair_abs", f"|λ| of the complex pair at Δd = {data.delta_d[0]:.3g}",
               float(mods[0, 0]), fmt=".6f", note="√det J = r e^{−ζT}"),
    )
    return Panel("fig1d", "moduli of the multipliers, shooting and perturbation",
                 "Moduli of the two Floquet multipliers of the uncontrolled 1/1 motion against "
                 "|Δd| (log axis, grazing to the right): shooting (lines, the exact monodromy along the "
                 "continued branch) and the perturbation series (circles). Far from grazing "
                 "they are a complex pair of modulus r e^{−ζT}; closer in they split, one "
                 "crosses −1 at the period doubling (dotted line; the 1/1 motion is stable in "
                 "the shaded range) and the largest then grows without bound, like 1/|Δd|, "
                 "while the product stays det J = r² e^{−2ζT}.",
                 tuple(files), numbers)


def panel_2d(p: OscillatorParams, data: BranchData, s: Samples, out,
             uncontrolled: BranchData | None = None) -> Panel:
    """Fig. 2(d): |multipliers| of the controlled 1/1 motion: bounded, tending to lambda0."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    ad = np.abs(data.delta_d)
    mods = np.abs(data.multipliers)
    lam0 = limit_multipliers(p, data.gains)
    lam0_p = limit_multipliers_perturbation(p, data.gains)
    ax.semilogx(ad, mods[:, 0], "-", color="k", lw=1.4, label="|λ1|, shooting")
    ax.semilogx(ad, mods[:, 1], "-", color="0.55", lw=1.4, label="|λ2|, shooting")
    pm = np.abs(s.perturbation)
    ax.semilogx(np.abs(s.delta_d), pm[:, 0], "o", mfc="none", color=COLORS["perturbation"], ms=6,
                label=f"perturbation ({_TRUNC[s.truncation]})")
    ax.semilogx(np.abs(s.delta_d), pm[:, 1], "o", mfc="none", color=COLORS["perturbation"], ms=6)
    if uncontrolled is not None:
        ax.semilogx(np.abs(uncontrolled.delta_d), np.abs(uncontrolled.multipliers[:, 0]), "--",
                    color=COLORS["unstable"], lw=1.0, alpha=0.7, label="|λ1| uncontrolled")
    ax.axhline(abs(lam0[0]), color=COLORS["controlled"], lw=0.9, ls="--",
               label=f"|λ0| = {abs(lam0[0]):.6f} (Eq. 23, limit Δd → 0⁻)")
    ax.axhline(1.0, color="0.3", lw=0.7, ls=":", label="|λ| = 1")
    ax.set(xlim=(ad.min(), ad.max()), ylim=(-0.03, 1.08),
           xlabel=_XLABEL, ylabel="|λ|",
           title=f"Fig. 2(d): multipliers of the controlled 1/1 motion (c2 = {data.gains.c2:g})")
    ax.invert_xaxis()
    ax.legend(fontsize=8, loc="center right")
    files = save(fig, out, "fig2d")
    at = {}
    for dd in (-5e-6, -9e-6):
        k = int(np.argmin(np.abs(s.delta_d - dd)))
        at[dd] = (s.delta_d[k], float(np.abs(s.exact[k, 0])), float(np.abs(s.perturbation[k, 0])))
    numbers = (
        Number("c1", "c1 (degenerate condition, Eq. 38)", float(data.gains.c1), "−1.02060", fmt=".8f"),
        Number("lambda0", "λ0 (exact limit, design.limit_multipliers)",
               tuple(float(x.real) for x in lam0), fmt=".8f"),
        Number("lambda0_perturbation", "λ0 (perturbation, Eq. 23)",
               tuple(float(x.real) for x in lam0_p), fmt=".8f"),
        Number("max_abs_multiplier", "max |λ| along the branch", float(mods.max()), fmt=".6f",
               note=f"|Δd| in [{ad.min():.2g}, {ad.max():.2g}]"),
        Number("all_stable", "stable along the whole branch", bool(np.all(data.stable)), "yes (bounded)"),
        *(Number(f"abs_lambda1_{abs(dd):.0e}", f"|λ1| at Δd = {d:.3g}: shooting / perturbation",
                 (a, b), fmt=".6f") for dd, (d, a, b) in at.items()),
        Number("second_multiplier_max", "max |λ2| (c2 = −1: det G = 0)", float(mods[:, 1].max()),
               fmt=".3g", note="exactly 0 by det J = r² e^{−2ζT}(1 + c2)"),
    )
    return Panel("fig2d", "multipliers of the controlled 1/1 motion",
                 "Moduli of the multipliers of the controlled 1/1 motion (c2 = −1, c1 from "
                 "Eq. 38) against |Δd|: shooting (lines) and perturbation (circles). They stay "
                 "bounded and inside the unit circle all the way to grazing, tending to λ0 "
                 "(green dashed); the second multiplier is exactly 0 because 1 + c2 = 0. The "
                 "uncontrolled largest multiplier (red dashed) leaves the unit circle at the "
                 "period doubling and grows without bound.",
                 tuple(files), numbers)


def panel_2e(p: OscillatorParams, data: BranchData, s: Samples, out) -> Panel:
    """Fig. 2(e): |lambda1 - lambda0| against |Delta d| (log-log): the O(delta2) approach."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    lam0 = limit_multipliers(p, data.gains)[0]
    ad = np.abs(data.delta_d)
    err = np.abs(data.multipliers[:, 0] - lam0)
    ax.loglog(ad, err, "-", color="k", lw=1.4, label="|λ1 − λ0|, shooting")
    perr = np.abs(s.perturbation[:, 0] - lam0)
    ax.loglog(np.abs(s.delta_d), perr, "o", mfc="none", color=COLORS["perturbation"], ms=6,
              label=f"|λ1 − λ0|, perturbation ({_TRUNC[s.truncation]})")
    slope = loglog_slope(data.delta_d, err, 1e-12, 1e-8)
    ref = err[np.argmin(np.abs(ad - 1e-8))]
    xs = np.array([1e-12, 1e-4])
    ax.loglog(xs, 3.0 * ref * (xs / 1e-8) ** 0.5, ":", color="0.4", lw=1,
              label="slope 1/2 (offset ×3)")
    ax.set(xlabel=_XLABEL, ylabel="|λ1 − λ0|",
           title="Fig. 2(e): approach of the controlled multiplier to λ0")
    ax.invert_xaxis()
    ax.legend(fontsize=8, loc="upper right")
    files = save(fig, out, "fig2e")
    ratio = err / data.v_minus
    k = int(np.argmin(ad))
    numbers = (
        Number("slope", "|λ1 − λ0| ∝ |Δd|^s: s on [1e-12, 1e-8]", slope, fmt=".5f",
               note="least squares; theory 1/2: λ = λ0 + O(δ2), δ2 ∝ |Δd|^(1/2) (Eqs. 18, 23)"),
        Number("error_per_v_minus", f"|λ1 − λ0| / v⁻ at Δd = {data.delta_d[k]:.3g}",
               float(ratio[k]), fmt=".5g"),
        Number("perturbation_vs_shooting", "max |λ1 perturbation − λ1 shooting| at the circles",
               float(np.nanmax(np.abs(s.perturbation[:, 0] - s.exact[:, 0]))), fmt=".3g",
               note="Eq. 25 keeps χ1 δ2"),
    )
    return Panel("fig2e", "approach of the controlled multiplier to λ0",
                 "The distance of the controlled 1/1 motion's multiplier from its grazing "
                 "limit λ0 (Eq. 23) against |Δd|, log-log: shooting (line) and the practical "
                 "perturbation truncation (circles, Eq. 25). It vanishes like |Δd|^(1/2), i.e. "
                 "linearly in the impact velocity δ2: the eigenvalues are λ0 + O(δ2), bounded.",
                 tuple(files), numbers)

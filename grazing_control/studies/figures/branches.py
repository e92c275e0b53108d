"""The 1/1 branch by continuation, uncontrolled and controlled: Figs. 1(c) and 2(c).

The branch is the exact impact-phase shooting of :mod:`grazing_control.dynamics.orbits.orbits`
(docs/theory.md §5), continued in the impact phase by
:func:`grazing_control.dynamics.orbits.continuation.continue_11` (§7) with every point verified by
the exact flow (one impact per period, periodic). Each point is drawn at its Pi2
sample x (the section of the brute-force diagram, Fig. 1(a)), stable solid and
unstable dashed. On the non-impacting side Delta d > 0 the attractor is the 0/1
motion, whose Pi2 point is X** for every Delta d and whose multipliers are the
eigenvalues of N_g (Eqs. 29-32): the same motion with and without control, since
the correction of Eq. 28 vanishes at X**.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grazing_control.dynamics.orbits.continuation import continue_11
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.maps.maps import smooth_return_matrix
from grazing_control.dynamics.orbits.orbits import _orbit_from_phase, multipliers, orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.support.plotting import (COLORS, PANEL_SIZE, pyplot, save,
                                              stability_segments)
from .report import Number, Panel

__all__ = ["BranchData", "branch_data", "loglog_slope", "panel_1c", "panel_2c"]


@dataclass(frozen=True)
class BranchData:
    """The 1/1 branch from ``start`` towards grazing, ordered by increasing Delta d.

    delta_d, psi, x_pi2, v_minus : (n,) arrays; multipliers : (n, 2) complex, largest
    modulus first; stable : (n,) bool; bifurcations : from the continuation;
    non_impacting : multipliers of the 0/1 motion (Delta d > 0), eig N_g.
    """

    gains: Gains | None
    delta_d: np.ndarray
    psi: np.ndarray
    x_pi2: np.ndarray
    v_minus: np.ndarray
    multipliers: np.ndarray
    stable: np.ndarray
    bifurcations: tuple
    non_impacting: np.ndarray

    def bifurcation(self, kind: str):
        """The first located bifurcation of this kind, or None."""
        return next((b for b in self.bifurcations if b.type == kind), None)


def branch_data(p: OscillatorParams, gains: Gains | None = None, start: float = -1e-3,
                stop: float = -1e-12, points: int = 400, uniform: int = 0) -> BranchData:
    """Continue the 1/1 branch from ``start`` to ``stop`` (both < 0) and sample it on Pi2.

    The continuation's grid is logarithmic in the impact phase (dense near grazing);
    ``uniform`` > 0 adds that many orbits equally spaced in Delta d over the range
    (:func:`grazing_control.dynamics.orbits.orbits.orbit_11`), for panels with a linear Delta d axis.
    The located bifurcation points are part of the curve, so that stability changes
    exactly there.
    """
    br = continue_11(p, start, stop, gains, points=points, check=True)
    rows = []
    for b in br.points:
        o = _orbit_from_phase(p, b.psi, gains, check=False)
        rows.append((b.delta_d, b.psi, o.pi2[0], b.v_minus, b.multipliers))
    for b in br.bifurcations:
        if b.type != "grazing":
            o = _orbit_from_phase(p, b.psi, gains, check=False)
            rows.append((b.delta_d, b.psi, o.pi2[0], o.v_minus, b.multipliers))
    for dd in np.linspace(start, stop, uniform) if uniform else ():
        o = orbit_11(p.with_(delta_d=float(dd)), gains, check=True)
        psi = (o.impact_phase - p.tau_star + np.pi) % (2.0 * np.pi) - np.pi
        rows.append((float(dd), psi, o.pi2[0], o.v_minus, o.multipliers))
    rows.sort(key=lambda row: row[0])
    lam = np.array([row[4] for row in rows]).reshape(-1, 2)
    n_g = smooth_return_matrix(p, gains)
    return BranchData(
        gains=gains,
        delta_d=np.array([row[0] for row in rows]),
        psi=np.array([row[1] for row in rows]),
        x_pi2=np.array([row[2] for row in rows]),
        v_minus=np.array([row[3] for row in rows]),
        multipliers=lam,
        # |lambda| = 1 at a bifurcation point counts as unstable: the curve changes there
        stable=np.max(np.abs(lam), axis=1) < 1.0 - 1e-12,
        bifurcations=tuple(br.bifurcations),
        non_impacting=multipliers(n_g),
    )


def loglog_slope(x, y, lo: float, hi: float) -> float:
    """Least-squares slope of log|y| against log|x| over lo <= |x| <= hi."""
    x, y = np.abs(np.asarray(x)), np.abs(np.asarray(y))
    keep = (x >= lo) & (x <= hi) & (y > 0)
    if np.count_nonzero(keep) < 2:
        return float("nan")
    return float(np.polyfit(np.log(x[keep]), np.log(y[keep]), 1)[0])


def draw_branch(ax, data: BranchData, x_ref: float, window, color_stable, color_unstable,
                label: str, zorder: float = 0.5):
    """The 1/1 branch on Pi2 in ``window`` = (lo, hi) of Delta d, and the 0/1 motion
    (x = x_ref) on (0, hi]: solid where stable, dashed where unstable."""
    lo, hi = window
    keep = (data.delta_d >= lo - 1e-9 * abs(lo)) & (data.delta_d <= 0.0)
    first = {True: True, False: True}
    for xs, ys, st in stability_segments(data.delta_d[keep], data.x_pi2[keep], data.stable[keep]):
        tag = f"{label}, {'stable' if st else 'unstable'}"
        ax.plot(xs, ys, "-" if st else "--", lw=1.6, zorder=zorder,
                color=color_stable if st else color_unstable, label=tag if first[st] else None)
        first[st] = False
    if hi > 0.0:
        st = bool(np.max(np.abs(data.non_impacting)) < 1.0)
        ax.plot([0.0, hi], [x_ref, x_ref], "-" if st else "--", lw=1.6, zorder=zorder,
                color=color_stable if st else color_unstable)


def _mark_pd(ax, data: BranchData, color=COLORS["bifurcation"]):
    pd = data.bifurcation("period-doubling")
    if pd is not None:
        ax.axvline(pd.delta_d, color=color, lw=0.8, ls=":",
                   label=f"period doubling, Δd = {pd.delta_d:.6g}")
    return pd


def panel_1c(p: OscillatorParams, data: BranchData, window, out) -> Panel:
    """Fig. 1(c): the uncontrolled 1/1 branch on Pi2 against Delta d, stability marked."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    draw_branch(ax, data, p.x_ref, window, COLORS["stable"], COLORS["unstable"], "1/1")
    ax.plot([], [], "-", color=COLORS["stable"], lw=1.6, label="0/1 (Δd > 0), stable")
    pd = _mark_pd(ax, data)
    ax.axvline(0.0, color="0.5", lw=0.6)
    ax.plot([0.0], [p.x_ref], "o", ms=4, color="k", label="grazing, Δd = 0")
    ax.set(xlim=window, xlabel="Δd = d − d*", ylabel="x on Π2",
           title="Fig. 1(c): 1/1 branch by continuation (uncontrolled)")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3))
    ax.legend(fontsize=8, loc="lower right")
    files = save(fig, out, "fig1c")
    in_win = data.delta_d >= window[0]
    unstable = data.delta_d[~data.stable]
    numbers = (
        Number("points", "branch points drawn (each a verified 1/1 orbit)", int(data.delta_d.size),
               note="continue_11(check=True) and orbit_11 on a uniform grid, Δd from "
                    f"{data.delta_d[0]:.3g} to {data.delta_d[-1]:.3g}"),
        Number("pd_delta_d", "period doubling Δd_PD", pd.delta_d if pd else None, "−1.00527e-5",
               fmt=".12g", note="test function 1 + tr J + det J, Brent in ψ"),
        Number("unstable_from", "unstable 1/1 from Δd", float(unstable.min()) if unstable.size else None,
               fmt=".6g", note="the period-doubling point"),
        Number("unstable_to", "unstable up to Δd", float(unstable.max()) if unstable.size else None,
               fmt=".3g", note="last grid point (grazing at 0)"),
        Number("x_pi2_at_window", f"x on Π2 at Δd = {data.delta_d[in_win][0]:.3g}",
               float(data.x_pi2[in_win][0]), fmt=".6g"),
        Number("v_minus_slope", "v⁻ ∝ |Δd|^s: s on [1e-12, 1e-8]",
               loglog_slope(data.delta_d, data.v_minus, 1e-12, 1e-8), fmt=".5f",
               note="least squares; docs/theory.md §5 predicts 1"),
        Number("non_impacting_abs", "|multipliers| of the 0/1 motion (Δd > 0)",
               tuple(float(a) for a in np.abs(data.non_impacting)), fmt=".6g",
               note="eig Φ(T) = e^{−ζT ± iω_d T}"),
    )
    return Panel("fig1c", "continuation of the 1/1 branch",
                 "The uncontrolled 1/1 motion born at grazing, continued in its impact phase "
                 "(exact shooting, each point checked by the exact flow), drawn at its Π2 "
                 "sample: stable (solid) for Δd below the period-doubling point, unstable "
                 "(dashed) from there to grazing at Δd = 0, where it ends at X**. For Δd > 0 "
                 "the non-impacting 0/1 motion (x = x** on Π2) is the stable periodic motion.",
                 tuple(files), numbers)


def panel_2c(p: OscillatorParams, uncontrolled: BranchData, controlled: BranchData,
             window, out) -> Panel:
    """Fig. 2(c): controlled and uncontrolled 1/1 branches on Pi2, stability marked."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    draw_branch(ax, uncontrolled, p.x_ref, window, "0.45", COLORS["unstable"], "uncontrolled")
    draw_branch(ax, controlled, p.x_ref, window, COLORS["controlled"], "tab:brown",
                f"controlled (c1 = {controlled.gains.c1:.6g}, c2 = {controlled.gains.c2:g})")
    _mark_pd(ax, uncontrolled)
    ax.axvline(0.0, color="0.5", lw=0.6)
    ax.plot([0.0], [p.x_ref], "o", ms=4, color="k", label="grazing")
    ax.set(xlim=window, xlabel="Δd = d − d*", ylabel="x on Π2 (before the correction)",
           title="Fig. 2(c): controlled and uncontrolled 1/1 branches")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3))
    ax.legend(fontsize=7.5, loc="lower right")
    files = save(fig, out, "fig2c")
    c_max = float(np.max(np.abs(controlled.multipliers)))
    numbers = (
        Number("controlled_points", "controlled branch points", int(controlled.delta_d.size),
               note=f"Δd from {controlled.delta_d[0]:.3g} to {controlled.delta_d[-1]:.3g}"),
        Number("controlled_all_stable", "controlled 1/1 stable at every point",
               bool(np.all(controlled.stable)), "yes"),
        Number("controlled_max_abs_multiplier", "max |λ| on the controlled branch", c_max, fmt=".6f"),
        Number("controlled_bifurcations", "bifurcations on the controlled branch",
               ", ".join(b.type for b in controlled.bifurcations) or "none", "none (bounded)"),
        Number("uncontrolled_pd_delta_d", "uncontrolled period doubling Δd_PD",
               uncontrolled.bifurcation("period-doubling").delta_d, "−1.00527e-5", fmt=".12g"),
        Number("controlled_v_minus_slope", "controlled v⁻ ∝ |Δd|^s: s on [1e-12, 1e-8]",
               loglog_slope(controlled.delta_d, controlled.v_minus, 1e-12, 1e-8), fmt=".5f",
               note="degenerate grazing: 1/2 (docs/theory.md §5)"),
        Number("controlled_non_impacting_abs", "|multipliers| of the controlled 0/1 motion",
               tuple(float(a) for a in np.abs(controlled.non_impacting)), fmt=".6g",
               note="eig N_g (Eqs. 29-32)"),
    )
    return Panel("fig2c", "controlled and uncontrolled continuations",
                 "The 1/1 branch with the controller in the loop (c2 = −1, c1 from the "
                 "degenerate condition, Eq. 38) next to the uncontrolled one, both drawn at "
                 "their Π2 sample (before the correction), stable solid and unstable dashed. "
                 "The controlled branch is stable all the way to grazing and leaves X** like "
                 "√|Δd| (degenerate grazing) instead of linearly.",
                 tuple(files), numbers)

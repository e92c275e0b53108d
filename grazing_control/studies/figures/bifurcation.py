"""Brute-force bifurcation diagrams on Pi2 across grazing: Figs. 1(a) and 1(b).

Every value of Delta d on the grid is an independent run of the uncontrolled
oscillator from the same starts on Pi2 (:func:`grazing_control.studies.sweeps.sweep`: the
exact flow with impacts), of which the Pi2 samples x after a transient are drawn as
dots. Two starts are used: X** itself (black; the grazing motion's point, which is
also the 0/1 motion's, so on Delta d > 0 it stays there) and X** + (1e-3, 0) (grey;
it reveals the chaotic attractor that coexists with the non-impacting motion just
past grazing). The 1/1 branch from continuation (:mod:`.branches`) is drawn over
them, stable solid and unstable dashed: the period-1 dots sit on it, and the
period doubling of the dots happens where the branch loses stability.

The detected period per point is the sweep's (smallest p with |z_{k+p} - z_k| below
a tolerance over the kept samples, 0 for none: chaos or a slow transient).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from grazing_control.dynamics.orbits import one_one
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.studies.sweeps import sweep
from grazing_control.support.plotting import (COLORS, PANEL_SIZE, pyplot, save,
                                              stability_segments)
from .branches import BranchData, draw_branch
from .two_cycle import two_cycle
from .report import Number, Panel

__all__ = ["STARTS", "DiagramData", "diagram_data", "panel_1a", "panel_1b"]

#: A detected period 2 counts as a 2-cycle when its two x differ by more than this.
TWO_CYCLE_SPREAD = 1e-6

#: Starts on Pi2 as deviations from X** (x - x**, v - v**).
STARTS = ((0.0, 0.0), (1e-3, 0.0))


@dataclass(frozen=True)
class DiagramData:
    """A brute-force diagram: delta_d (n,), starts (s, 2), x (n, s, m) physical Pi2
    samples after the transient, last (n, s, 2) the last sample as a deviation from X**,
    period (n, s), impacts (n, s, m), lyapunov (n, s, 2) the Lyapunov exponents per
    period of the kept orbit (dynamics.simulation.lyapunov), and how it was run."""

    delta_d: np.ndarray
    starts: np.ndarray
    x: np.ndarray
    last: np.ndarray
    period: np.ndarray
    impacts: np.ndarray
    periods: int
    transient: int
    engine: str
    seconds: float
    lyapunov: np.ndarray | None = None


def diagram_data(p: OscillatorParams, delta_d, *, periods: int, transient: int,
                 starts=STARTS, workers: int | None = None, progress: bool = False,
                 lyapunov: bool = True) -> DiagramData:
    """Run the sweep over ``delta_d`` from each start; keep x on Pi2, the periods and (with
    ``lyapunov``) the Lyapunov exponents of the kept orbits."""
    dd = np.asarray(delta_d, dtype=float)
    st = np.asarray(starts, dtype=float).reshape(-1, 2)
    t0 = time.perf_counter()
    res = sweep(p, {"delta_d": dd}, periods=periods, transient=transient, deviation=st,
                workers=workers, progress=progress, lyapunov=lyapunov)
    seconds = time.perf_counter() - t0
    n, s, m = dd.size, st.shape[0], periods - transient
    return DiagramData(dd, st, res.pi2[:, :, 0].reshape(n, s, m),
                       res.pi2_deviation[:, -1, :].reshape(n, s, 2), res.period.reshape(n, s),
                       res.impacts_per_period.reshape(n, s, m), periods, transient,
                       str(res.engine), seconds,
                       None if res.lyapunov is None else res.lyapunov.reshape(n, s, 2))


def _scatter(ax, data: DiagramData, size: float):
    for j in reversed(range(data.starts.shape[0])):
        x = data.x[:, j, :]
        dd = np.repeat(data.delta_d, x.shape[1])
        color = COLORS["brute"] if j == 0 else COLORS["brute_other"]
        dz = data.starts[j]
        label = "brute force from X**" if j == 0 else \
            f"brute force from X** + ({dz[0]:g}, {dz[1]:g})"
        ax.scatter(dd, x.ravel(), s=size, c=color, marker=".", linewidths=0, rasterized=True,
                   label=label)


def _first(dd, mask):
    k = np.flatnonzero(mask)
    return float(dd[k[0]]) if k.size else None


def _branch_agreement(p, data: DiagramData, limit: int = 25) -> float | None:
    """max |x - x_11| over (up to ``limit``) period-1 points from X** with Delta d < 0:
    the brute-force fixed point against the exact 1/1 orbit at the same Delta d."""
    k = np.flatnonzero((data.period[:, 0] == 1) & (data.delta_d < 0.0))
    if not k.size:
        return None
    k = k[np.linspace(0, k.size - 1, min(limit, k.size)).astype(int)]
    errs = []
    for i in k:
        o = one_one.orbit(p, None, float(data.delta_d[i]), check=False)
        errs.append(abs(data.x[i, 0, -1] - o.physical[0]))
    return float(max(errs))


def panel_1a(p: OscillatorParams, data: DiagramData, branch: BranchData, out) -> Panel:
    """Fig. 1(a): the brute-force diagram across grazing with the 1/1 branch."""
    plt = pyplot()
    if data.lyapunov is None:
        fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    else:   # lambda_max beneath the diagram, on the same Delta d axis
        w, h = PANEL_SIZE
        fig, (ax, lx) = plt.subplots(2, 1, figsize=(w, h * 1.45), sharex=True,
                                     gridspec_kw={"height_ratios": (3, 1.2)},
                                     constrained_layout=True)
    _scatter(ax, data, size=1.0 if data.delta_d.size > 300 else 4.0)
    window = (float(data.delta_d[0]), float(data.delta_d[-1]))
    draw_branch(ax, branch, p.x_ref, window, COLORS["stable"], COLORS["unstable"], "1/1 branch")
    ax.axvline(0.0, color="0.5", lw=0.6)
    ax.set(xlim=window, xlabel="" if data.lyapunov is not None else "Δd = d − d*",
           ylabel="x on Π2", title="Fig. 1(a): bifurcation diagram on Π2 (uncontrolled)")
    if data.lyapunov is not None:
        lmax = data.lyapunov[:, 0, 0]
        ok = np.isfinite(lmax)
        lx.axhline(0.0, color="0.5", lw=0.6)
        lx.axvline(0.0, color="0.5", lw=0.6)
        lx.plot(data.delta_d[ok], lmax[ok], ".", color=COLORS["brute"], markersize=2.0,
                markeredgewidth=0)
        lx.set(xlim=window, xlabel="Δd = d − d*", ylabel="λ_max / period (from X**)")
        lx.ticklabel_format(axis="x", style="sci", scilimits=(-3, 3))
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3))
    ax.legend(fontsize=7.5, loc="lower left", markerscale=6)
    files = save(fig, out, "fig1a")
    per = data.period[:, 0]
    neg, posd = data.delta_d < 0.0, data.delta_d > 0.0
    other = data.impacts[:, 1:, :]
    stays = np.all(other == 0, axis=2) if other.size else np.zeros((data.delta_d.size, 0), bool)
    numbers = (
        Number("grid", "grid: Δd values × starts, periods (transient)",
               f"{data.delta_d.size} × {data.starts.shape[0]}, {data.periods} ({data.transient})",
               note=f"Δd in [{window[0]:.3g}, {window[1]:.3g}], sweep engine {data.engine}, "
                    f"{data.seconds:.1f} s"),
        Number("period1_fraction_negative", "Δd < 0 from X**: fraction of period-1 points",
               float(np.mean(per[neg] == 1)) if neg.any() else None, fmt=".3f"),
        Number("chaos_from", "Δd < 0 from X**: the range next to grazing with no period ≤ 64 "
               "starts at", _chaos_from(data.delta_d[neg], per[neg]), fmt=".4g",
               note="chaos (or a transient slower than the run)"),
        Number("other_attractor_ranges", "Δd ranges before the doubling where X** reaches "
               "an attractor other than the 1/1 motion",
               _runs(data.delta_d, _off_branch(data, branch)) or None, fmt=".3g",
               note="Δd < Δd_PD with samples > 1e-3 off the 1/1 orbit: coexisting attractors"),
        Number("period_at_positive", "Δd > 0 from X**: periods seen",
               tuple(int(v) for v in np.unique(per[posd])) if posd.any() else None,
               note="X** is the 0/1 motion's point"),
        Number("positive_still_impacting", "Δd > 0 from the second start: fraction still "
               "impacting after the transient",
               float(np.mean(~stays[posd, 0])) if posd.any() and stays.shape[1] else None,
               fmt=".3f", note="the chaotic attractor coexists with the 0/1 motion"),
        Number("branch_agreement", "max |x − x(1/1 orbit)| at period-1 points",
               _branch_agreement(p, data), fmt=".2e",
               note="brute force vs exact shooting (one_one.orbit), up to 25 points"),
    ) + _lyapunov_numbers(p, data)
    return Panel("fig1a", "bifurcation diagram on Π2 across grazing",
                 "Brute force: for each Δd the uncontrolled oscillator runs from X** (black) "
                 "and from X** + (1e-3, 0) (grey); the Π2 samples x after the transient are "
                 "dots. The 1/1 branch from continuation is drawn over them (blue solid "
                 "stable, red dashed unstable). From the left: the stable 1/1 motion, its "
                 "period doubling at the end of the blue line, a short cascade into chaos "
                 "near grazing, and on the non-impacting side Δd > 0 the 0/1 motion "
                 "(x = x**) with a chaotic attractor coexisting just past grazing.",
                 tuple(files), numbers)


def _lyapunov_numbers(p, data: DiagramData) -> tuple:
    """λ_max's sign against the detected period, and the worst residual of the sum
    identity (L3) over the Δd < 0 points from X** (docs/theory_lyapunov.md)."""
    if data.lyapunov is None:
        return ()
    lam = data.lyapunov[:, 0, :]
    per = data.period[:, 0]
    neg = data.delta_d < 0.0
    chaotic = neg & (per == 0) & np.isfinite(lam[:, 0])
    periodic = neg & (per > 0) & np.isfinite(lam[:, 0])
    nu = data.impacts[:, 0, :].mean(axis=1)
    expected = -2.0 * p.zeta * p.period + 2.0 * nu * np.log(p.r)
    ok = neg & np.all(np.isfinite(lam), axis=1)
    resid = np.abs(lam.sum(axis=1) - expected)[ok]
    return (
        Number("lyapunov_chaotic_positive", "Δd < 0 from X**, no period ≤ 64: fraction with "
               "λ_max > 0", float(np.mean(lam[chaotic, 0] > 0)) if chaotic.any() else None,
               fmt=".3f", note="tangent propagation through flow and saltation matrices"),
        Number("lyapunov_periodic_max", "Δd < 0 from X**, periodic points: largest λ_max",
               float(lam[periodic, 0].max()) if periodic.any() else None, fmt=".3g",
               note="≤ 0 on periodic windows (0 at a bifurcation)"),
        Number("lyapunov_sum_residual", "max |λ1 + λ2 − (−2ζT + 2ν ln r)|",
               float(resid.max()) if resid.size else None, fmt=".2e",
               note="the determinant identity (L3), exact to rounding"),
    )


def _runs(dd, mask):
    """Maximal runs of True in mask as (first Delta d, last Delta d) pairs."""
    k = np.flatnonzero(mask)
    if not k.size:
        return ()
    return tuple((float(dd[r[0]]), float(dd[r[-1]]))
                 for r in np.split(k, np.flatnonzero(np.diff(k) != 1) + 1))


def _two_cycle_agreement(data: DiagramData, tc) -> float | None:
    """max over the grid points with a brute-force 2-cycle (from X**) and a shot 2/2
    orbit of the distance between their two Pi2 x values (sorted)."""
    if tc is None or not tc.delta_d.size:
        return None
    errs = []
    for d, xs in zip(tc.delta_d, tc.x):
        i = int(np.searchsorted(data.delta_d, d))
        if i < data.delta_d.size and data.delta_d[i] == d and data.period[i, 0] == 2:
            brute = np.sort(data.x[i, 0, -2:])
            errs.append(float(np.max(np.abs(brute - np.sort(xs)))))
    return max(errs) if errs else None


def _chaos_from(dd, per):
    """The left end of the last run of period-0 points reaching the right end of the grid."""
    if not per.size or per[-1] != 0:
        return None
    k = np.flatnonzero(per != 0)
    return float(dd[k[-1] + 1]) if k.size else float(dd[0])


def _off_branch(data: DiagramData, branch: BranchData) -> np.ndarray:
    """Points from X** on the stable side of the 1/1 branch (Delta d < Delta d_PD) whose
    samples stay more than 1e-3 away from the 1/1 orbit: another attractor was reached."""
    pd = branch.bifurcation("period-doubling")
    x11 = np.interp(data.delta_d, branch.delta_d, branch.x_pi2)
    far = np.max(np.abs(data.x[:, 0, :] - x11[:, None]), axis=1) > 1e-3
    return far & (data.delta_d < (pd.delta_d if pd is not None else 0.0))


def panel_1b(p: OscillatorParams, data: DiagramData, branch: BranchData, out) -> Panel:
    """Fig. 1(b): the diagram magnified around the period doubling."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    _scatter(ax, data, size=1.5 if data.delta_d.size > 300 else 5.0)
    window = (float(data.delta_d[0]), float(data.delta_d[-1]))
    draw_branch(ax, branch, p.x_ref, window, COLORS["stable"], COLORS["unstable"], "1/1 branch",
                zorder=3)
    pd = branch.bifurcation("period-doubling")
    ax.axvline(pd.delta_d, color=COLORS["bifurcation"], lw=0.8, ls=":",
               label=f"period doubling (continuation), Δd = {pd.delta_d:.6g}")
    per, dd = data.period[:, 0], data.delta_d
    k1 = np.flatnonzero(per == 1)
    last1 = float(dd[k1[-1]]) if k1.size else None
    # a 2-cycle, not the alternating transient of a multiplier near -1 (critical slowing
    # down next to the doubling), which the period test alone can take for period 2
    spread = np.ptp(data.x[:, 0, :], axis=1)
    k2 = np.flatnonzero((per == 2) & (spread > TWO_CYCLE_SPREAD)
                        & (dd > (last1 if last1 is not None else -np.inf)))
    first2 = float(dd[k2[0]]) if k2.size else None
    tc = two_cycle(p, dd[k2[0]:], data.last[k2[0], 0]) if k2.size else None
    if tc is not None and tc.delta_d.size:
        labelled = set()
        for col in (0, 1):
            for xs, ys, st in stability_segments(tc.delta_d, tc.x[:, col], tc.stable):
                tag = f"2/2 orbit (Newton shooting), {'stable' if st else 'unstable'}"
                ax.plot(xs, ys, "-" if st else "--", lw=1.0, zorder=3,
                        color=COLORS["perturbation"] if st else "tab:brown",
                        label=None if st in labelled else tag)
                labelled.add(st)
        if tc.period_doubling is not None:
            ax.axvline(tc.period_doubling, color="tab:brown", lw=0.8, ls=":",
                       label=f"2/2 period doubling, Δd = {tc.period_doubling:.6g}")
    regular = data.x[(data.period[:, 0] > 0) & (data.period[:, 0] <= 16), 0, :]
    if regular.size:  # frame the cascade; chaotic points beyond it are clipped
        lo, hi = float(regular.min()), float(regular.max())
        pad = 0.25 * (hi - lo) + 1e-6
        ax.set_ylim(lo - pad, hi + pad)
    ax.set(xlim=window, xlabel="Δd = d − d*", ylabel="x on Π2",
           title="Fig. 1(b): magnified near the period doubling")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3))
    fig.legend(fontsize=7, loc="outside lower center", ncol=2, markerscale=6)
    files = save(fig, out, "fig1b")
    after = first2 if first2 is not None else -np.inf
    bracket = last1 is not None and first2 is not None and last1 <= pd.delta_d <= first2
    numbers = (
        Number("pd_delta_d", "period doubling Δd_PD (continuation)", pd.delta_d, "−1.00527e-5",
               fmt=".12g", note="exact: Brent on 1 + tr J + det J"),
        Number("brute_last_period1", "brute force from X**: last period-1 Δd", last1, fmt=".6g",
               note=f"grid step {dd[1] - dd[0]:.2g}"),
        Number("brute_first_period2", "brute force: first period-2 Δd after it", first2, fmt=".6g",
               note=f"its two points more than {TWO_CYCLE_SPREAD:g} apart"),
        Number("slow_points", "grid points between the two (slow transients)",
               int(np.count_nonzero((dd > last1) & (dd < first2))) if bracket else None),
        Number("pd_in_bracket", "Δd_PD (continuation) lies between the two", bool(bracket), "—",
               note="critical slowing down blurs the grid points next to Δd_PD"),
        Number("two_cycle_pd", "2/2 orbit: period doubling Δd (shooting + Brent)",
               tc.period_doubling if tc is not None else None, fmt=".9g",
               note="1 + tr J + det J of the 2/2 monodromy"),
        Number("brute_first_period4", "brute force: first period-4 Δd after that",
               _first(dd, (per == 4) & (dd > after)), fmt=".6g"),
        Number("two_cycle_agreement", "max |x − x(2/2 orbit)| at the brute-force period-2 points",
               _two_cycle_agreement(data, tc), fmt=".2e",
               note=f"{tc.delta_d.size if tc is not None else 0} orbits shot along the grid"),
        Number("brute_first_period8", "brute force: first period-8 Δd after that",
               _first(dd, (per == 8) & (dd > after)), fmt=".6g"),
        Number("brute_chaos_from", "brute force: Δd from which no point has a period ≤ 64",
               _chaos_from(dd, per), fmt=".6g", note="chaos (or transients longer than the run)"),
        Number("grid", "grid: Δd values × starts, periods (transient)",
               f"{dd.size} × {data.starts.shape[0]}, {data.periods} ({data.transient})",
               note=f"{data.seconds:.1f} s"),
    )
    return Panel("fig1b", "magnified near the period doubling",
                 "The brute-force diagram of Fig. 1(a) on a finer grid around the period "
                 "doubling, with the exactly located bifurcation (dotted, continuation) and "
                 "the 1/1 branch. The period-1 dots split into two where the branch turns "
                 "unstable; the two points of the 2-cycle lie on the 2/2 orbit found by "
                 "Newton shooting (orange), which doubles in turn (brown dotted), and the "
                 "cascade (2, 4, 8, …) ends in chaos.",
                 tuple(files), numbers)

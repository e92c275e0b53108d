"""Charts of the robustness studies (docs/theory_delay.md section 6, docs/robustness.md).

matplotlib with the Agg backend; each function takes computed results (plain data) and
writes one PNG.
"""

from __future__ import annotations

import numpy as np

from grazing_control.support.plotting import pyplot, save_png

__all__ = ["plot_delay_curves", "plot_stability_maps", "plot_fault_sweep", "plot_noise_gain",
           "plot_model_bands"]


def _plt():
    return pyplot()


def plot_delay_curves(curves, path, dpi=80):
    """max|lambda| vs the actual delay, one panel per design.

    curves: list of dicts {design_delay, c2, c1, delays, by_delta_d: {dd: values},
    perturbation: {dd: values}, intervals: {dd: (lo, hi) or None}}.
    """
    plt = _plt()
    fig, axes = plt.subplots(1, len(curves), figsize=(5.2 * len(curves), 3.8), squeeze=False)
    for ax, c in zip(axes[0], curves):
        for k, (dd, vals) in enumerate(sorted(c["by_delta_d"].items())):
            line, = ax.semilogy(c["delays"], vals, lw=1.3, label=f"exact, Δd = {dd:.0e}")
            pert = c.get("perturbation", {}).get(dd)
            if pert is not None:
                ax.semilogy(c["delays"], pert, ls=":", lw=1.6, color=line.get_color())
        ax.axhline(1.0, color="k", lw=0.8)
        ax.axvline(c["design_delay"], color="gray", ls="--", lw=0.8)
        ax.set_title(f"designed for δ_a = {c['design_delay']:g} (c2 = {c['c2']:g})", fontsize=9)
        ax.set_xlabel("actual actuation delay δ")
        ax.set_ylabel("max |λ| of the 1/1 orbit")
        ax.set_ylim(0.1, 1e3)
        ax.legend(fontsize=7, title="dotted: perturbation", title_fontsize=7)
    fig.tight_layout()
    save_png(fig, path, dpi=dpi)


def plot_stability_maps(maps, path, boundaries=None, dpi=80):
    """log10 max|lambda| over (c2, delay), rows = design rule, columns = Delta d.

    maps: dict {(design, delta_d): StabilityMap}; boundaries: optional dict
    {delay: [(lo, hi), ...]} of the design's admissible c2 (drawn on the 'delayed' row).
    """
    plt = _plt()
    designs = ["delayed", "undelayed"]
    dds = sorted({dd for _d, dd in maps}, reverse=True)
    fig, axes = plt.subplots(2, len(dds), figsize=(3.6 * len(dds), 6.2), squeeze=False,
                             sharex=True, sharey=True)
    for i, design in enumerate(designs):
        for j, dd in enumerate(dds):
            ax = axes[i, j]
            m = maps[(design, dd)]
            vals = np.log10(m.values)
            ax.set_facecolor("0.75")  # no 1/1 orbit
            mesh = ax.pcolormesh(m.c2s, m.delays, np.ma.masked_invalid(vals), vmin=-1, vmax=2,
                                 cmap="RdYlBu_r", shading="nearest")
            if np.any(np.isfinite(vals)):
                ax.contour(m.c2s, m.delays, np.nan_to_num(vals, nan=3.0), levels=[0.0],
                           colors="k", linewidths=0.8)
            if design == "delayed" and boundaries:
                # the design's true ends may lie outside the plotted c2 grid (or at
                # infinity, beyond its search limit): only those on the chart are marked
                ends = [(x, delay) for delay, ivs in boundaries.items() for iv in ivs for x in iv
                        if m.c2s[0] <= x <= m.c2s[-1]]
                if ends:
                    ex, ey = zip(*ends)
                    ax.plot(ex, ey, "m.", ms=2.5, label="admissible-set ends (design)")
            ax.set_xlim(m.c2s[0], m.c2s[-1])
            if i == 0:
                ax.set_title(f"Δd = {dd:.0e}", fontsize=9)
            if j == 0:
                ax.set_ylabel(f"{design} design\nactual delay δ")
            if i == 1:
                ax.set_xlabel("c2")
    fig.colorbar(mesh, ax=axes, shrink=0.8, label="log10 max|λ| (black: |λ| = 1; gray: no 1/1 orbit)")
    if boundaries:
        axes[0, 0].legend(fontsize=6, loc="lower left")
    save_png(fig, path, dpi=dpi)


def plot_fault_sweep(results, path, dpi=80):
    """Capture probability (top) and stationary spread (bottom) vs loss, noise, jitter.

    results: list of fault_sweep dicts (any Delta d / configurations), grouped by kind.
    """
    plt = _plt()
    kinds = ["loss", "noise", "jitter"]
    xlabel = {"loss": "loss probability p", "noise": "measurement noise σ",
              "jitter": "delay jitter (std, time units)"}
    fig, axes = plt.subplots(2, 3, figsize=(12, 6), sharex="col")
    for j, kind in enumerate(kinds):
        for res in (r for r in results if r["kind"] == kind):
            rows = res["rows"]
            x = np.array([r["level"] for r in rows])
            xs = np.where(x > 0, x, np.nan)
            lab = f"Δd = {res['delta_d']:.0e}, c2 = {res['c2']:g}, δ = {res['actuation_delay']:g}"
            line, = axes[0, j].semilogx(xs, [r["capture_probability"] for r in rows], "o-", ms=3,
                                        label=lab)
            med = np.array([np.nan if r["spread_median"] is None else r["spread_median"] for r in rows])
            lo = np.array([np.nan if r["spread_p10"] is None else r["spread_p10"] for r in rows])
            hi = np.array([np.nan if r["spread_p90"] is None else r["spread_p90"] for r in rows])
            axes[1, j].loglog(xs, med, "o-", ms=3, color=line.get_color())
            pred = [r.get("spread_predicted") for r in rows]
            if any(v is not None for v in pred):
                axes[1, j].loglog(xs, [np.nan if v is None else v for v in pred], "--", lw=1,
                                  color=line.get_color())
            axes[1, j].fill_between(xs, np.maximum(lo, 1e-16), hi, color=line.get_color(), alpha=0.15)
        axes[0, j].set_ylim(-0.05, 1.05)
        axes[0, j].set_ylabel(f"P(capture, N = {results[0]['horizon']})")
        axes[1, j].set_ylabel("spread (RMS)")
        axes[1, j].set_xlabel(xlabel[kind])
    axes[1, 0].set_ylim(1e-5, 1e-1)  # runs without a loss in their tail sit at ~1e-15
    fig.suptitle("capture probability (top) and stationary spread, median and 10-90 % "
                 "(bottom; dashed: linear prediction)", fontsize=9)
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    save_png(fig, path, dpi=dpi)


def plot_noise_gain(record, path, dpi=80):
    """Noise gain (log) over the admissible c2, one curve per Delta d; the least gain
    marked (o) and the study's c2 (dotted). ``record``: :func:`.noise.noise_gain_curves`."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for curve in record["curves"]:
        c2 = np.array(curve["c2"])
        g = np.array([np.nan if x is None else x for x in curve["gain"]], dtype=float)
        (line,) = ax.semilogy(c2, g, lw=1.2, label=f"Δd = {curve['delta_d']:.0e}")
        b = curve["best"]
        ax.semilogy([b["c2"]], [b["gain"]], "o", color=line.get_color(), ms=4)
    ax.axvline(record["study_c2"], color="0.4", ls=":", lw=1, label=f"study c2 = {record['study_c2']:g}")
    ax.set_xlabel("c2 (c1 from the degenerate condition)")
    ax.set_ylabel("noise gain: std of Π2 position per unit σ")
    delay = record["delay"]
    ax.set_title("measurement noise through the controlled loop" + (f", delay {delay:g}" if delay else ""),
                 fontsize=9)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=7)
    save_png(fig, path, dpi=dpi)


def plot_model_bands(record, path, dpi=80):
    """|band end| (log) against the relative error (log), one panel per parameter with a
    band, one line per design (positive errors; for n-DOF records negative ones too,
    hollow), the series' prediction dashed where there is one. ``record``:
    :func:`.model.model_error_bands` (either model)."""
    plt = _plt()
    names = list(dict.fromkeys(r["parameter"] for d in record["designs"] for r in d["bands"]))
    params = [n for n in names
              if any(r["parameter"] == n and r["end"] < 0 for d in record["designs"] for r in d["bands"])]
    params = params or names[:1]
    fig, axes = plt.subplots(1, len(params), figsize=(4.6 * len(params), 3.8), squeeze=False)
    symbols = {"zeta": "ζ", "omega": "ω"}
    for ax, name in zip(axes[0], params):
        series = False
        for d in record["designs"]:
            label = d["label"] + (f" (c2 = {d['c2']:.4g})" if "c2" in d else "")
            for sign, fill in ((1.0, "o-"), (-1.0, "o--")):
                if sign < 0 and "c2" in d:
                    continue   # 1-DOF: negative errors open no band on d < d*
                rows = [r for r in d["bands"]
                        if r["parameter"] == name and sign * r["error"] > 0 and r["end"] < 0]
                if not rows:
                    continue
                e = np.array([abs(r["error"]) for r in rows])
                (line,) = ax.loglog(e, [-r["end"] for r in rows], fill, ms=3,
                                    mfc=None if sign > 0 else "none",
                                    label=label + ("" if sign > 0 else " (e < 0)"))
                pred = [r["predicted"] for r in rows]
                if all(p is not None and np.isfinite(p) for p in pred):
                    ax.loglog(e, [-p for p in pred], "--", color=line.get_color(), lw=0.8)
                    series = True
        ax.set_xlabel(f"relative error in {symbols.get(name, name)}")
        if ax is axes[0][0]:
            ax.set_ylabel("band |Δd| where control fails")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=7, title="dashed: series, ∝ e²" if series else "hollow: e < 0",
                  title_fontsize=7)
    save_png(fig, path, dpi=dpi)

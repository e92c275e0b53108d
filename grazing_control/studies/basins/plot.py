"""The basin picture: each start coloured by its attractor, the attractors drawn over."""

from __future__ import annotations

import numpy as np

from .result import attractor_colors

__all__ = ["picture"]


def picture(result, out, name: str = "basins", title: str | None = None) -> list:
    """Write ``name``.png and ``name``.svg to the folder ``out``; returns the file names.

    The grid of starts (x - x**, v - v** on Pi2) is drawn as cells coloured by attractor
    (legend: label and fraction of the starts); periodic attractors are drawn at their
    cycle's points (white-edged markers), the chaotic one as the record of its first
    start (dark dots); X** is the cross at the origin.
    """
    from matplotlib.colors import ListedColormap

    from grazing_control.support.plotting import PANEL_SIZE, pyplot, save

    plt = pyplot()
    colors = attractor_colors(result.attractors)
    xs, vs = result.xs, result.vs
    fig, ax = plt.subplots(figsize=(PANEL_SIZE[0] + 1.6, PANEL_SIZE[1]), constrained_layout=True)
    hx = (xs[-1] - xs[0]) / (2 * max(xs.size - 1, 1)) if xs.size > 1 else abs(xs[0]) or 1.0
    hv = (vs[-1] - vs[0]) / (2 * max(vs.size - 1, 1)) if vs.size > 1 else abs(vs[0]) or 1.0
    ax.imshow(result.attractor, origin="lower", cmap=ListedColormap(colors),
              vmin=-0.5, vmax=len(colors) - 0.5, interpolation="nearest", aspect="auto",
              extent=(xs[0] - hx, xs[-1] + hx, vs[0] - hv, vs[-1] + hv), rasterized=True)
    handles = []
    for a, c, f in zip(result.attractors, colors, result.fractions()):
        label = f"{a.label}: {100 * f:.1f} %"
        if a.kind == "periodic":
            h, = ax.plot(a.points[:, 0], a.points[:, 1], "o", ms=6, mfc=c, mec="white",
                         mew=1.2, label=label)
            ax.plot(a.points[:, 0], a.points[:, 1], "o", ms=8, mfc="none", mec="black",
                    mew=0.6)
        elif a.kind == "chaotic":
            ax.plot(a.points[:, 0], a.points[:, 1], ".", ms=1.5, color="0.25", rasterized=True)
            h = plt.Rectangle((0, 0), 1, 1, fc=c, ec="0.25", label=label + " (dots: its record)")
        else:
            h = plt.Rectangle((0, 0), 1, 1, fc=c, label=label)
        handles.append(h)
    ax.plot([0.0], [0.0], "+", color="black", ms=10, mew=1.2)
    handles.append(ax.plot([], [], "+", color="black", ms=10, mew=1.2,
                           label="X** (grazing point)")[0])
    ax.set_xlim(xs[0] - hx, xs[-1] + hx)
    ax.set_ylim(vs[0] - hv, vs[-1] + hv)
    ax.set_xlabel("x − x** on Π2 (start)")
    ax.set_ylabel("v − v** on Π2 (start)")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3), useOffset=False)
    p = result.params
    control = ("uncontrolled" if not result.controlled else
               f"c1 = {result.c1:.5g}, c2 = {result.c2:.5g}"
               + (f", delay {result.delay:.4g}" if result.delay else "")
               + (f", on from sample {result.control_after}" if result.control_after else ""))
    ax.set_title(title or f"Basins on Π2: Δd = {p.delta_d:g}, ω = {p.omega:.6g}, "
                          f"{control}\n{result.n_starts} starts, {result.transient} periods "
                          f"transient, periods ≤ {result.max_period}", fontsize=9)
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              frameon=False)
    return save(fig, out, name)

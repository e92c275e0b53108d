"""Pictures of the n-DOF studies: diagram, multipliers against |Delta d|, control scene.

Each function draws exactly the data it is given (support/plotting.py's Agg backend and
look) and writes one PNG; the figure set (studies/figures/ndof.py) and ``grazing sweep
--model`` use them.
"""

from __future__ import annotations

import numpy as np

from grazing_control.support.plotting import COLORS, pyplot, save_png

__all__ = ["coordinate_index", "diagram_png", "scaling_png", "scene_png"]

LABELS = {"delta_d": r"$\Delta d$", "omega": r"$\omega$", "r": "r", "phase": "phase",
          "pi2_offset": "Pi2 offset"}


def coordinate_index(coordinates, name: str) -> int:
    """Index of a coordinate name (x0.., v0..) in the state; ValueError naming the valid."""
    if name not in coordinates:
        raise ValueError(f"coordinate {name!r} is invalid: valid names are "
                         f"{', '.join(coordinates)}")
    return list(coordinates).index(name)


def diagram_png(result, path, *, coordinate: str, deviation: bool = False,
                title: str | None = None, dpi: int = 150):
    """Every kept Pi2 sample of ``coordinate`` (physical, or the deviation from the
    grazing orbit) against the swept value: a brute-force bifurcation diagram."""
    plt = pyplot()
    j = coordinate_index(result.coordinates, coordinate)
    m = result.samples.shape[1]
    xs = np.repeat(result.values, m)
    ys = result.samples[:, :, j] + (0.0 if deviation else result.reference[:, j][:, None])
    ys = ys.ravel()
    ok = np.isfinite(ys)
    fig, ax = plt.subplots(figsize=(7.0, 4.5), constrained_layout=True)
    ax.plot(xs[ok], ys[ok], ".", color=COLORS["brute"], markersize=1.5, markeredgewidth=0,
            rasterized=True)
    ax.set_xlabel(LABELS.get(result.name, result.name))
    ax.set_ylabel(f"{coordinate}{' - grazing' if deviation else ''} on $\\Pi_2$")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3), useOffset=False)
    ax.set_title(title or f"{result.values.size} points x {m} periods "
                          f"(after {result.transient} transient)", fontsize=9)
    save_png(fig, path, dpi=dpi)
    return str(path)


def scaling_png(curves, path, *, title: str = "", dpi: int = 150):
    """max |lambda| against |Delta d| on log-log axes.

    ``curves``: list of dicts with ``delta_d``, ``largest``, ``label``, ``color`` and
    optionally ``limit`` (a predicted limit, dashed) and ``slope`` (shown in the legend).
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    for c in curves:
        x = np.abs(np.asarray(c["delta_d"], dtype=float))
        y = np.asarray(c["largest"], dtype=float)
        ok = np.isfinite(x) & np.isfinite(y) & (y > 0)
        label = c["label"]
        if c.get("slope") is not None and np.isfinite(c["slope"]):
            label += f" (slope {c['slope']:.3f})"
        ax.loglog(x[ok], y[ok], "o-", color=c["color"], markersize=3, linewidth=1,
                  label=label)
        if c.get("limit") is not None:
            ax.axhline(c["limit"], color=c["color"], linestyle="--", linewidth=0.8,
                       label=f"predicted limit {c['limit']:.4g}")
    ax.axhline(1.0, color="0.6", linewidth=0.6)
    ax.set_xlabel(r"$|\Delta d|$")
    ax.set_ylabel(r"$\max |\lambda|$ of the 1/1 orbit")
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    save_png(fig, path, dpi=dpi)
    return str(path)


def scene_png(scene, path, *, coordinate_index_: int, coordinate: str, dpi: int = 150):
    """The scene's Pi2 samples of one coordinate (deviation) against the sample index,
    the moment control goes on, and the distance to the controlled orbit (log scale)."""
    plt = pyplot()
    k = np.arange(scene.samples.shape[0])
    rows = 2 if scene.distance is not None else 1
    fig, axes = plt.subplots(rows, 1, figsize=(7.0, 2.4 * rows + 1.0), sharex=True,
                             constrained_layout=True, squeeze=False)
    ax = axes[0, 0]
    ax.plot(k, scene.samples[:, coordinate_index_], ".", color=COLORS["brute"],
            markersize=1.5, markeredgewidth=0, rasterized=True)
    ax.set_ylabel(f"{coordinate} - grazing on $\\Pi_2$")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3), useOffset=False)
    ax.set_title(f"$\\Delta d$ = {scene.delta_d:.3g}", fontsize=9)
    for a in axes[:, 0]:
        if scene.control_after >= 0:
            a.axvline(scene.control_after, color=COLORS["controlled"], linewidth=0.8)
    if scene.distance is not None:
        ad = axes[1, 0]
        d = np.where(scene.distance > 0, scene.distance, np.nan)
        ad.semilogy(k, d, color=COLORS["controlled"], linewidth=0.8)
        ad.set_ylabel("distance to the\ncontrolled 1/1 orbit")
    axes[-1, 0].set_xlabel("sample on $\\Pi_2$")
    save_png(fig, path, dpi=dpi)
    return str(path)

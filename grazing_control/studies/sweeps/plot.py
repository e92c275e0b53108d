"""The bifurcation diagram of a sweep: recorded Pi2 samples against the first grid axis."""

from __future__ import annotations

import numpy as np

__all__ = ["LABELS", "diagram", "atlas", "coordinate_index", "diagram_png"]

LABELS = {"delta_d": r"$\Delta d$", "zeta": r"$\zeta$", "r": "r", "omega": r"$\omega$",
          "tau0": r"$\tau_0$", "pi2_offset": "Pi2 offset", "c1": "$c_1$", "c2": "$c_2$",
          "phase": "phase"}


def diagram(result, path, *, component: str = "x", title: str | None = None, dpi: int = 150):
    """Write a PNG of every recorded Pi2 sample (black dots) against ``result.names[0]``.

    component : 'x' or 'v', the coordinate on Pi2 (physical). Points of other grid axes
    and of all starts are drawn over each other, as in a brute-force diagram.
    """
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()

    if component not in ("x", "v"):
        raise ValueError(f"component={component!r} is invalid: valid values are x, v")
    name = result.names[0]
    m = result.pi2_deviation.shape[1]
    xs = np.repeat(result.points[name], m)
    ys = result.pi2[:, :, 0 if component == "x" else 1].ravel()
    ok = np.isfinite(ys)
    if result.lyapunov is None:
        fig, ax = plt.subplots(figsize=(7.0, 4.5), constrained_layout=True)
    else:   # lambda_max beneath, on the same axis
        fig, (ax, lx) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True,
                                     gridspec_kw={"height_ratios": (3, 1.3)},
                                     constrained_layout=True)
        _lyapunov_panel(lx, result.points[name], result.lyapunov[:, 0], LABELS.get(name, name))
    ax.plot(xs[ok], ys[ok], ".", color="black", markersize=1.0, markeredgewidth=0,
            rasterized=True)
    if result.lyapunov is None:
        ax.set_xlabel(LABELS.get(name, name))
    ax.set_ylabel(f"${component}$ on $\\Pi_2$")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3), useOffset=False)
    ax.set_title(title or f"{result.n_points} points x {m} periods "
                          f"(after {result.transient} transient)", fontsize=9)
    save_png(fig, path, dpi=dpi)
    return path


def _lyapunov_panel(ax, xs, lmax, label):
    """lambda_max per forcing period against the swept parameter, zero line, -inf clipped."""
    finite = np.isfinite(lmax)
    ax.axhline(0.0, color="0.6", linewidth=0.8)
    ax.plot(xs[finite], lmax[finite], ".", color="tab:red", markersize=2.0, markeredgewidth=0)
    low = lmax[finite].min() if finite.any() else -1.0
    neg_inf = lmax == -np.inf
    if neg_inf.any():   # a singular map (sticking, or det G = 0): drawn at the bottom
        ax.plot(xs[neg_inf], np.full(neg_inf.sum(), low), "v", color="tab:red", markersize=2.5)
    ax.set_ylabel(r"$\lambda_{\max}$ / period")
    ax.set_xlabel(label)
    ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 3), useOffset=False)


def atlas(result, path, *, dpi: int = 150):
    """Two-parameter atlas: the detected period and (with Lyapunov) lambda_max over the
    plane of the two grid axes (the first start of each point)."""
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()
    if len(result.names) != 2:
        raise ValueError(f"an atlas needs two grid axes, the sweep has {len(result.names)}")
    a, b = result.names
    shape = result.shape
    first = np.arange(result.n_points).reshape(shape)[..., 0]
    period = result.period[first].astype(float)
    period[period <= 0] = np.nan
    panels = [("detected period on $\\Pi_2$ (none: chaotic or longer)", period, "viridis")]
    if result.lyapunov is not None:
        lm = result.lyapunov[first, 0].copy()
        lm[~np.isfinite(lm)] = np.nan
        panels.append((r"$\lambda_{\max}$ per period", lm, "coolwarm"))
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.2),
                             constrained_layout=True, squeeze=False)
    xa, xb = result.axes
    for ax, (title, data, cmap) in zip(axes[0], panels):
        kw = {}
        if cmap == "coolwarm" and np.isfinite(data).any():
            m = np.nanmax(np.abs(data))
            kw = dict(vmin=-m, vmax=m)
        im = ax.pcolormesh(xb, xa, data, shading="nearest", cmap=cmap, **kw)
        fig.colorbar(im, ax=ax)
        ax.set_xlabel(LABELS.get(b, b))
        ax.set_ylabel(LABELS.get(a, a))
        ax.set_title(title, fontsize=9)
        ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3), useOffset=False)
    save_png(fig, path, dpi=dpi)
    return path


def coordinate_index(coordinates, name: str) -> int:
    """Index of a coordinate name (x0.., v0..) in the state; ValueError naming the valid."""
    if name not in coordinates:
        raise ValueError(f"coordinate {name!r} is invalid: valid names are "
                         f"{', '.join(coordinates)}")
    return list(coordinates).index(name)


def diagram_png(result, path, *, coordinate: str, deviation: bool = False,
                title: str | None = None, dpi: int = 150):
    """Every kept Pi2 sample of ``coordinate`` (physical, or the deviation from the
    grazing orbit) against the swept value: a brute-force bifurcation diagram of a model
    file's sweep (:mod:`.model_file`, ``grazing sweep --model``)."""
    from grazing_control.support.plotting import COLORS, pyplot, save_png

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

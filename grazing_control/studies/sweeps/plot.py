"""The bifurcation diagram of a sweep: recorded Pi2 samples against the first grid axis."""

from __future__ import annotations

import numpy as np

__all__ = ["LABELS", "diagram"]

LABELS = {"delta_d": r"$\Delta d$", "zeta": r"$\zeta$", "r": "r", "omega": r"$\omega$",
          "tau0": r"$\tau_0$", "pi2_offset": "Pi2 offset", "c1": "$c_1$", "c2": "$c_2$"}


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
    fig, ax = plt.subplots(figsize=(7.0, 4.5), constrained_layout=True)
    ax.plot(xs[ok], ys[ok], ".", color="black", markersize=1.0, markeredgewidth=0,
            rasterized=True)
    ax.set_xlabel(LABELS.get(name, name))
    ax.set_ylabel(f"${component}$ on $\\Pi_2$")
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 3), useOffset=False)
    ax.set_title(title or f"{result.n_points} points x {m} periods "
                          f"(after {result.transient} transient)", fontsize=9)
    save_png(fig, path, dpi=dpi)
    return path

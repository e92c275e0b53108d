"""Shared plotting: the Agg backend, one look, PNG + SVG output (figures) or one PNG.

Used by the figures, the sweeps' diagram, the robustness charts and the analysis
reports, so that every picture of the package is drawn and written the same way.

Every panel is its own figure, saved twice: a PNG (raster, for reading and for
docs/) and an SVG (vector; dense point clouds are rasterized inside it so the file
stays small).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["pyplot", "save", "save_png", "thumbnail", "stability_segments", "COLORS",
           "PANEL_SIZE"]

#: One size for every panel (inches), so the panels line up in figures.md.
PANEL_SIZE = (6.4, 4.4)

COLORS = {
    "brute": "black",
    "brute_other": "0.6",
    "stable": "tab:blue",
    "unstable": "tab:red",
    "controlled": "tab:green",
    "perturbation": "tab:orange",
    "bifurcation": "tab:purple",
    "admissible": "tab:green",
}


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, out: Path, name: str, dpi: int = 150) -> list:
    """Write ``name``.png and ``name``.svg to ``out``; close the figure; return the names."""
    plt = pyplot()
    out = Path(out)
    files = []
    for ext in ("png", "svg"):
        path = out / f"{name}.{ext}"
        fig.savefig(path, dpi=dpi, metadata={"Date": None} if ext == "svg" else None)
        files.append(path.name)
    plt.close(fig)
    return files


def save_png(fig, path, dpi: int = 150) -> None:
    """Write ``fig`` as one PNG at ``path`` and close it (the reports and charts)."""
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)


def thumbnail(src, dst, width: int = 640) -> int:
    """Write a downscaled copy of the PNG ``src`` to ``dst`` (``width`` pixels wide, 256
    colours) for docs/; returns its size in bytes."""
    from PIL import Image

    with Image.open(src) as im:
        rgb = im.convert("RGB")
    w, h = rgb.size
    small = rgb.resize((width, round(h * width / w)), Image.LANCZOS)
    small.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(dst, optimize=True)
    return Path(dst).stat().st_size


def stability_segments(x, y, stable):
    """Split a curve into maximal runs of equal stability: [(x, y, stable), ...].

    Consecutive runs share their end point so that the drawn curve has no gap.
    """
    x, y, stable = np.asarray(x), np.asarray(y), np.asarray(stable, dtype=bool)
    if x.size == 0:
        return []
    cuts = np.flatnonzero(stable[1:] != stable[:-1]) + 1
    out = []
    lo = 0
    for hi in list(cuts) + [x.size]:
        end = min(hi + 1, x.size)
        out.append((x[lo:end], y[lo:end], bool(stable[lo])))
        lo = hi
    return out

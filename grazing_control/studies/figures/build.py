"""All panels of Figs. 1 and 2 in one call, with figures.md and figures.json.

:data:`FULL` is the resolution of the published panels, :data:`QUICK` a coarse one
(seconds) that draws every panel from the same code; the numbers of figures.md are
computed from the data each panel was drawn from, whatever the resolution.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.studies.demo import SCENES
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.params import OscillatorParams
from .bifurcation import diagram_data, panel_1a, panel_1b
from .branches import branch_data, panel_1c, panel_2c
from .constraints import constraint_data, panel_2a, panel_2b
from .multipliers import panel_1d, panel_2d, panel_2e, samples
from .report import numbers_dict, render_markdown
from .scenes import panel_scene

__all__ = ["Settings", "FULL", "QUICK", "make_figures"]

#: The study's controller: c2 = -1, c1 from the degenerate condition (Eq. 38).
C2 = -1.0


@dataclass(frozen=True)
class Settings:
    """Resolution and ranges of the panels.

    window : Delta d range of Figs. 1(a), 1(c), 2(c) (across grazing);
    zoom : Delta d range of Fig. 1(b) (around the period doubling);
    diagram_points, zoom_points : grid sizes of the brute-force diagrams;
    periods, transient : per point of 1(a); zoom_periods, zoom_transient : of 1(b)
    (longer: critical slowing down at the period doubling);
    branch_points : continuation grid; uniform_points : orbits added on a uniform grid
    in Delta d over ``window`` (linear axes); log_range : |Delta d| range of the log panels;
    circles : perturbation samples; c2_range, c2_points, c2_circles : Figs. 2(a, b).
    """

    window: tuple = (-3e-5, 5e-6)
    zoom: tuple = (-1.08e-5, -7.6e-6)
    diagram_points: int = 1000
    zoom_points: int = 600
    periods: int = 1200
    transient: int = 1000
    zoom_periods: int = 3200
    zoom_transient: int = 3000
    branch_points: int = 400
    uniform_points: int = 300
    log_range: tuple = (1e-12, 1e-3)
    circles: int = 19
    c2_range: tuple = (-3.0, 1.0)
    c2_points: int = 401
    c2_circles: int = 21


FULL = Settings()
# QUICK's zoom keeps a 1000-period transient: next to the cascade the motion settles
# slowly, and the narrow period-4 window (about -8.40e-6 ... -8.16e-6) is found on the
# coarse grid only with it
QUICK = Settings(diagram_points=48, zoom_points=32, periods=260, transient=200,
                 zoom_periods=1060, zoom_transient=1000, branch_points=80, uniform_points=40,
                 circles=10, c2_points=81, c2_circles=9)


def make_figures(out, settings: Settings = FULL, *, bags=None, workers=None,
                 progress: bool = False, log=print, docs=None) -> list:
    """Write every panel (PNG + SVG), figures.md and figures.json to ``out``.

    Parameters
    ----------
    out : path-like
        Output folder (created).
    settings : Settings
        FULL (default) or QUICK, or your own.
    bags : path-like, optional
        Folder with the demo's recordings (scene_5e-6, scene_9e-6) for Figs. 2(f, g);
        default: simulate the scenes with the core.
    workers : int, optional
        Processes for the brute-force sweeps (default: all cores).
    progress : bool
        Progress bars for the sweeps.
    log : callable
        Called with one line per panel (None: silent).
    docs : path-like, optional
        Also write ``docs``/figures.md with thumbnails in ``docs``/img/figures/.

    Returns
    -------
    list of Panel
    """
    if bags is not None:  # refuse before anything runs or is written
        missing = [name for name, _dd in SCENES if not (Path(bags) / name).exists()]
        if missing:
            raise ValueError(f"bags={str(bags)!r} is invalid: no recording {missing[0]} in it "
                             "(expected the folder `grazing demo` writes: out/demo/bags)")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log = log or (lambda *_: None)
    s = settings
    p = OscillatorParams()
    gains = Gains(degenerate_c1(p, C2), C2)
    t_all = time.perf_counter()
    panels = []

    def add(make):
        t0 = time.perf_counter()
        panel = make()
        panel = replace(panel, seconds=time.perf_counter() - t0)
        panels.append(panel)
        log(f"figures: {panel.name} ({panel.seconds:.1f} s): {panel.title}")

    lo, hi = s.log_range
    uncontrolled_win = branch_data(p, None, start=s.window[0], points=s.branch_points,
                                   uniform=s.uniform_points)
    uncontrolled_log = branch_data(p, None, start=-hi, stop=-lo, points=s.branch_points)
    controlled_win = branch_data(p, gains, start=s.window[0], points=s.branch_points,
                                 uniform=s.uniform_points)
    controlled_log = branch_data(p, gains, start=-hi, stop=-lo, points=s.branch_points)

    def fig_1a():
        dd = np.linspace(*s.window, s.diagram_points)
        data = diagram_data(p, dd, periods=s.periods, transient=s.transient, workers=workers,
                            progress=progress)
        return panel_1a(p, data, uncontrolled_win, out)

    def fig_1b():
        dd = np.linspace(*s.zoom, s.zoom_points)
        data = diagram_data(p, dd, periods=s.zoom_periods, transient=s.zoom_transient,
                            workers=workers, progress=progress, lyapunov=False)
        return panel_1b(p, data, uncontrolled_win, out)

    circles = -np.logspace(np.log10(lo), np.log10(hi), s.circles)
    scene_dd = np.array([d for _n, d in SCENES])
    add(fig_1a)
    add(fig_1b)
    add(lambda: panel_1c(p, uncontrolled_win, s.window, out))
    add(lambda: panel_1d(p, uncontrolled_log, samples(p, None, circles, "limit"), out))
    cdata = constraint_data(p, s.c2_range, s.c2_points, s.c2_circles)
    add(lambda: panel_2a(p, cdata, C2, out))
    add(lambda: panel_2b(p, cdata, C2, out))
    add(lambda: panel_2c(p, uncontrolled_win, controlled_win, s.window, out))
    csamples = samples(p, gains, np.sort(np.concatenate([circles, scene_dd])), "practical")
    add(lambda: panel_2d(p, controlled_log, csamples, out, uncontrolled=uncontrolled_log))
    add(lambda: panel_2e(p, controlled_log, csamples, out))
    add(lambda: panel_scene(p, gains, "f", out, bags))
    add(lambda: panel_scene(p, gains, "g", out, bags))
    total = time.perf_counter() - t_all
    mode = "quick" if s == QUICK else ("full" if s == FULL else "custom")
    cmd = "grazing figures" + (" --quick" if mode == "quick" else "") + \
        (f" --docs {docs}" if docs is not None else "")
    header = _header(cmd, mode, s, total)
    (out / "figures.md").write_text(render_markdown(panels, header), encoding="utf-8")
    doc = {"mode": mode, "seconds": total, "settings": asdict(s), "panels": numbers_dict(panels),
           "files": {pn.name: list(pn.files) for pn in panels}}
    (out / "figures.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    log(f"figures: {len(panels)} panels, figures.md and figures.json in {out} ({total:.1f} s)")
    if docs is not None:
        _write_docs(Path(docs), out, panels, header)
        log(f"figures: {Path(docs) / 'figures.md'} and thumbnails in {Path(docs) / 'img/figures'}")
    return panels


def _write_docs(docs: Path, out: Path, panels, header: str):
    """docs/figures.md (numbers as in out/figures.md) and small PNGs in docs/img/figures."""
    from grazing_control.support.plotting import thumbnail

    img = docs / "img" / "figures"
    img.mkdir(parents=True, exist_ok=True)
    for p in panels:
        png = next(f for f in p.files if f.endswith(".png"))
        thumbnail(out / png, img / png)
    brute = sum(p.seconds for p in panels if p.name in ("fig1a", "fig1b"))
    total = sum(p.seconds for p in panels)
    note = ("The panels below are thumbnails (640 px) of the PNGs the command writes; it "
            "also writes each panel as SVG, this text as figures.md and the numbers as "
            "figures.json to its output folder (`make figures`: out/figures). Of the "
            f"{total:.0f} s spent on the panels, the brute-force diagrams 1(a) and 1(b) took "
            f"{brute:.0f} s; timings were taken on a shared 2-core machine and are noisy.")
    text = render_markdown(panels, header + "\n\n" + note, image_prefix="img/figures/",
                           files=False)
    (docs / "figures.md").write_text(text, encoding="utf-8")


def _header(cmd: str, mode: str, s: Settings, total: float) -> str:
    return "\n".join([
        "# The study's Figs. 1 and 2",
        "",
        f"Made by `{cmd}` ({mode} resolution, {total:.0f} s). Study parameters: ζ = 0.01, "
        "r = 0.68, ω = 2ω_d/3 + 5·10⁻⁴; Δd = d − d*. Every number below is computed from "
        "the data its panel was drawn from; the study's value is given where the study "
        "(spec §8, issue 10) states one (\"yes\": a qualitative claim of the study).",
        "",
        f"Brute-force diagrams: {s.diagram_points} values of Δd in [{s.window[0]:g}, "
        f"{s.window[1]:g}] × {s.periods} periods ({s.transient} transient) for 1(a); "
        f"{s.zoom_points} values in [{s.zoom[0]:g}, {s.zoom[1]:g}] × {s.zoom_periods} "
        f"({s.zoom_transient} transient) for 1(b). Continuation: {s.branch_points} points.",
    ])

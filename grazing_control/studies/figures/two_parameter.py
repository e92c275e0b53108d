"""The two-parameter diagram of the 1/1 orbit: `grazing continue2` (issue 18 section 1).

Three panels, each PNG + SVG (:func:`grazing_control.support.plotting.save`), and the
numbers as one JSON file and the curves as one CSV, all from the same
:class:`grazing_control.dynamics.orbits.two_parameter.Diagram`:

* ``two_parameter``: the PD and fold curves in (mu, Delta d), Delta d on a symmetric
  log scale; the grazing curve is Delta d = 0; degenerate grazing points marked;
  physical 1/1 orbits solid, points whose orbit fails the exact-flow check (another
  contact in the period) dotted;
* ``two_parameter_absolute``: the same in the absolute clearance d = d*(mu) + Delta d,
  with the grazing curve d*(mu) (Eq. 2);
* ``two_parameter_local``: |Delta d| against |mu - mu*| at each degenerate point, the
  exact curve (markers) and the leading order kappa (mu - mu*)^2 (lines),
  docs/theory_two_parameter.md.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from grazing_control.dynamics.orbits.two_parameter import KINDS, Diagram
from grazing_control.support.plotting import COLORS, PANEL_SIZE, pyplot, save

__all__ = ["diagram_dict", "write_diagram", "LABELS"]

#: Axis labels of the second parameter.
LABELS = {"omega": "ω", "zeta": "ζ", "r": "r", "c2": "c2"}
_COLOR = {KINDS[0]: COLORS["bifurcation"], KINDS[1]: COLORS["perturbation"]}
_SHORT = {KINDS[0]: "PD", KINDS[1]: "fold"}
#: Most series the local panel's legend names.
_LEGEND = 10


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _resonance(diagram: Diagram, value: float, params):
    """m and 2 omega_d / m for an uncontrolled omega diagram (the study's omega*), else None."""
    if diagram.parameter != "omega" or params is None:
        return None
    m = max(1, round(2.0 * params.omega_d / value))
    return m, 2.0 * params.omega_d / m


def diagram_dict(diagram: Diagram, params=None, gains=None) -> dict:
    """The diagram as plain JSON-able data (the file ``continue2.json``)."""
    codim2 = []
    for c in diagram.codim2:
        row = {"value": c.value, "curves": {}}
        res = _resonance(diagram, c.value, params) if gains is None else None
        if res is not None:
            row.update(m=res[0], omega_star=res[1], difference=c.value - res[1])
        for a, shape, (p, kappa) in zip(c.asymptotics, c.shapes, c.fits):
            row["curves"][a.kind] = {
                "kappa": a.kappa, "exponent": a.exponent, "side": a.side,
                "v_minus_rate": a.rate,
                "fitted_exponent": _finite(p), "measured_kappa": _finite(kappa),
                "shape": [{"offset": float(d), "delta_d": float(dd), "psi": float(s)}
                          for d, dd, s in shape]}
        codim2.append(row)
    curves = []
    for c in diagram.curves:
        curves.append({
            "kind": c.kind, "seed": c.seed, "ends": list(c.ends), "meets_grazing_at": list(c.codim2),
            "points": [{"value": q.value, "psi": q.psi, "delta_d": q.delta_d, "d": q.d,
                        "v_minus": q.v_minus,
                        "multipliers": [[_finite(z.real), _finite(z.imag)] for z in q.multipliers],
                        "physical": q.physical} for q in c.points]})
    return {
        "parameter": diagram.parameter, "from": diagram.lo, "to": diagram.hi,
        "base": diagram.base,
        "model": None if params is None else {"zeta": params.zeta, "r": params.r,
                                              "omega": params.omega,
                                              "pi2_offset": params.pi2_offset},
        "gains": None if gains is None else {"c1": gains.c1, "c2": gains.c2,
                                             "delay": gains.delay},
        "design": diagram.design,
        "grazing": [{"value": float(x), "delta_d": 0.0, "d": float(d)}
                    for x, d in diagram.grazing],
        "codim2": codim2, "curves": curves,
    }


def _write_csv(diagram: Diagram, path: Path) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["curve", "kind", diagram.parameter, "psi", "delta_d", "d", "v_minus",
                    "abs_lambda1", "abs_lambda2", "physical"])
        for i, c in enumerate(diagram.curves):
            for q in c.points:
                lam = np.abs(q.multipliers)
                w.writerow([i, c.kind, repr(q.value), repr(q.psi), repr(q.delta_d), repr(q.d),
                            repr(q.v_minus), repr(float(lam[0])), repr(float(lam[1])),
                            int(q.physical)])


def _runs(curve, y):
    """Maximal runs of equal ``physical`` along a curve: [(x, y, physical)], joined."""
    xs = np.array([q.value for q in curve.points])
    ys = np.array([y(q) for q in curve.points])
    ok = np.array([q.physical or q.psi == 0.0 for q in curve.points])
    out, lo = [], 0
    for hi in list(np.flatnonzero(ok[1:] != ok[:-1]) + 1) + [len(xs)]:
        end = min(hi + 1, len(xs))
        out.append((xs[lo:end], ys[lo:end], bool(ok[lo])))
        lo = hi
    return out


def _draw_curves(ax, diagram, y):
    seen = set()
    for c in diagram.curves:
        for xs, ys, ok in _runs(c, y):
            tag = (c.kind, ok)
            label = None
            if tag not in seen:
                label = f"{_SHORT[c.kind]}" + ("" if ok else " (not a 1/1 orbit: other contacts)")
                seen.add(tag)
            ax.plot(xs, ys, "-" if ok else ":", lw=1.5 if ok else 0.9, color=_COLOR[c.kind],
                    label=label)


def _title(gains, parameter) -> str:
    if gains is None:
        return "1/1 orbit"
    c2 = "" if parameter == "c2" else f", c2 = {gains.c2:.4g}"
    return f"controlled 1/1 orbit (c1 = {gains.c1:.4g}{c2})"


def _design_title(diagram, gains) -> str:
    return "design family (c1 from Eq. 38)" if diagram.design else _title(gains, diagram.parameter)


def _panel_delta_d(diagram: Diagram, params, out: Path, gains=None) -> list:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    ax.axhline(0.0, color="k", lw=1.2, label="grazing, Δd = 0")
    _draw_curves(ax, diagram, lambda q: q.delta_d)
    every = max(1, math.ceil(len(diagram.codim2) / 8))   # at most ~8 labels
    for i, c in enumerate(diagram.codim2):
        ax.plot([c.value], [0.0], "o", ms=5, mfc="white", mec="k", zorder=5)
        if i % every:
            continue
        res = _resonance(diagram, c.value, params)
        text = f"m={res[0]}" if res else f"{c.value:.6g}"
        ax.annotate(text, (c.value, 0.0), textcoords="offset points", xytext=(3, 6), fontsize=8)
    if diagram.codim2:
        ax.plot([], [], "o", ms=5, mfc="white", mec="k",
                label="λ0 = ∓1 at grazing" if diagram.design else "degenerate grazing (N_g,12 = 0)")
    sizes = [abs(q.delta_d) for c in diagram.curves for q in c.points if q.delta_d != 0.0]
    low = math.floor(math.log10(max(min(sizes, default=1e-9), 1e-12))) + 1
    high = math.ceil(math.log10(max(sizes, default=1.0)))
    ax.set_yscale("symlog", linthresh=10.0 ** low)
    step = max(1, (high - low + 5) // 6)   # about six labelled decades a side
    decades = [10.0 ** k for k in range(high, low, -step)]
    ax.set_yticks([-x for x in decades] + [0.0] + decades[::-1])
    name = LABELS[diagram.parameter]
    ax.set(xlim=(diagram.lo, diagram.hi), xlabel=name, ylabel="Δd = d − d*  (symlog)",
           title=f"{_design_title(diagram, gains)}: PD and fold curves in ({name}, Δd)")
    ax.legend(fontsize=7, loc="best")
    return save(fig, out, "two_parameter")


def _panel_absolute(diagram: Diagram, out: Path) -> list:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    ax.plot(diagram.grazing[:, 0], diagram.grazing[:, 1], "-", color="k", lw=1.2,
            label="grazing, d = d*")
    _draw_curves(ax, diagram, lambda q: q.d)
    for c in diagram.codim2:
        d = float(np.interp(c.value, diagram.grazing[:, 0], diagram.grazing[:, 1]))
        ax.plot([c.value], [d], "o", ms=5, mfc="white", mec="k", zorder=5)
    name = LABELS[diagram.parameter]
    top = float(np.max(diagram.grazing[:, 1]))
    bottom = float(np.min(diagram.grazing[:, 1]))
    if bottom > 0.0 and top / bottom > 20.0:
        ax.set_yscale("log")
    ax.set(xlim=(diagram.lo, diagram.hi), xlabel=name, ylabel="wall clearance d",
           title=f"the same in the absolute clearance d = d*({name}) + Δd")
    ax.legend(fontsize=7, loc="best")
    return save(fig, out, "two_parameter_absolute")


def _panel_local(diagram: Diagram, params, out: Path) -> list:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    name = LABELS[diagram.parameter]
    for i, c in enumerate(diagram.codim2):
        res = _resonance(diagram, c.value, params)
        where = f"m={res[0]}" if res else f"{name}*={c.value:.6g}"
        for a, shape, (p, _k) in zip(c.asymptotics, c.shapes, c.fits):
            if len(shape) == 0:
                continue
            marker = "o" if a.kind == KINDS[0] else "s"
            line, = ax.plot(shape[:, 0], np.abs(shape[:, 1]), marker, ms=4, mfc="none",
                            label=f"{where} {_SHORT[a.kind]}: κ = {a.kappa:.4g}, p = {p:.4f}")
            xs = np.array([shape[0, 0], shape[-1, 0]])
            ax.plot(xs, abs(a.kappa) * xs ** a.exponent, "--", lw=0.8, color=line.get_color())
    ax.set(xlabel=f"|{name} − {name}*|", ylabel="|Δd| on the curve",
           title="near degenerate grazing: exact (markers), κ |μ − μ*|^p (dashed)")
    if ax.lines:
        ax.set(xscale="log", yscale="log")
        if len(ax.lines) <= 2 * _LEGEND:   # each series drawn twice (markers, line)
            ax.legend(fontsize=6, loc="best")
        else:
            ax.text(0.02, 0.98, f"{len(ax.lines) // 2} curves: κ, p in continue2.json",
                    transform=ax.transAxes, va="top", fontsize=7)
    else:
        ax.text(0.5, 0.5, f"no degenerate grazing point (N_g,12 = 0) in {name} ∈ "
                f"[{diagram.lo:g}, {diagram.hi:g}]", ha="center", va="center",
                transform=ax.transAxes)
    return save(fig, out, "two_parameter_local")


def write_diagram(diagram: Diagram, out, params=None, gains=None) -> dict:
    """Write the three panels, ``continue2.json`` and ``continue2_curves.csv`` into
    ``out`` (created); returns the JSON document with the file names under 'files'."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = diagram_dict(diagram, params, gains)
    files = _panel_delta_d(diagram, params if gains is None else None, out, gains)
    files += _panel_absolute(diagram, out)
    files += _panel_local(diagram, params if gains is None else None, out)
    _write_csv(diagram, out / "continue2_curves.csv")
    files += ["continue2_curves.csv", "continue2.json"]
    doc["files"] = files
    (out / "continue2.json").write_text(json.dumps(doc, allow_nan=False, indent=1),
                                        encoding="utf-8")
    return doc

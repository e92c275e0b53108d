"""The figure set of a model file near grazing (issue 17): diagram, multipliers against
|Delta d|, control scene; the 1-DOF study's figures are :mod:`.build`.

``grazing figures --model FILE`` draws, for any model file:

* (a) ``ndof_diagram.png``: the brute-force bifurcation diagram on Pi2 against Delta d
  near grazing, uncontrolled (:func:`grazing_control.studies.sweeps.model_file.diagram`);
* (b) ``ndof_multipliers.png``: max |lambda| of the 1/1 orbit born at grazing against
  |Delta d| on log-log axes, on the side of grazing where it exists
  (:func:`grazing_control.dynamics.orbits.near_grazing.grazing_side`) (:func:`grazing_control.studies.near_grazing.scaling.multiplier_scaling`):
  uncontrolled, with a gain of the design family (bounded, the predicted limit
  :func:`grazing_control.dynamics.design.family.limit_multipliers` dashed) and with the gain
  that cancels only w^T N u and one that cancels w^T N u and G(1)
  (``cancel_first_markov``), each with its fitted
  exponent over |Delta d| <= ``fit_below``;
* (c) ``ndof_scene.png``: uncontrolled iterations, then the controller on, and the
  distance to the controlled 1/1 orbit (:func:`grazing_control.studies.near_grazing.scene.control_scene`),
  like the study's Figs. 2(f, g).

With an actuation ``delay`` (``grazing figures --model FILE --delay D``) the kick k^T z of
the sample acts D later: the family member, its limit, the multipliers of (b) and the
scene of (c) are the delayed kick's (docs/theory_ndof.md §14); the uncontrolled (a) is
the same. The numbers read off the panels go to ``ndof_figures.json``. The default
settings keep the whole set under a minute on two cores.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from grazing_control.oscillator.params import ParameterError
from grazing_control.support.plotting import COLORS, pyplot, save_png

__all__ = ["NdofFigureSettings", "DEFAULT", "QUICK", "choose_mu", "markov_gain", "scaling_curves",
           "make_ndof_figures"]


@dataclass(frozen=True)
class NdofFigureSettings:
    """What the figure set computes (all Delta d in the model's length unit)."""

    diagram_from: float = -2e-5          # (a) Delta d range, points, periods per point
    diagram_to: float = 0.0
    diagram_points: int = 60
    diagram_periods: int = 300
    diagram_transient: int = 200
    scaling_from: float = 1e-3           # (b) |Delta d| grid, log-spaced, largest first
    scaling_to: float = 1e-10
    scaling_points: int = 15
    fit_below: float = 1e-6              # fit exponents over |Delta d| <= fit_below
    markov_offset: float = 0.05          # the cancel-first-Markov gain: k(mu) + this |k| d
    scene_delta_d: float = -5e-6         # (c) the scene
    scene_before: int = 300
    scene_after: int = 200
    mu: float | None = None              # the family's member (default: design's choice)


DEFAULT = NdofFigureSettings()
QUICK = replace(DEFAULT, diagram_points=20, diagram_periods=120, diagram_transient=80,
                scaling_points=8, scene_before=100, scene_after=100)


def _complex_list(values):
    return [[float(np.real(z)), float(np.imag(z))] for z in np.atleast_1d(values)]


def _finite_or_none(x):
    return float(x) if x is not None and math.isfinite(x) else None


def choose_mu(model, delay: float = 0.0) -> tuple[float, str]:
    """The family member drawn: the middle of the widest admissible interval of mu
    (docs/ndof_commands.md); without one, of the widest interval where only the
    impacting-side conditions hold, else where the controlled 1/1 orbit exists
    (gamma1 > 0, on a grid of [-1, 1]); else 0. The delayed kick's family with a
    ``delay``."""
    from grazing_control.dynamics.design.family import admissible_mu, existence_coefficient

    for conditions, why in (("combined", "the middle of the widest admissible interval"),
                            ("impacting", "no admissible mu: the middle of the widest "
                                          "interval where |lambda0| < 1 and gamma1 > 0")):
        intervals = [(float(a), float(b)) for a, b in admissible_mu(model, conditions, delay)]
        if intervals:
            lo, hi = max(intervals, key=lambda iv: iv[1] - iv[0])
            if math.isfinite(lo) and math.isfinite(hi):
                return 0.5 * (lo + hi) + 0.0, why
            return (hi - 1.0 if math.isfinite(hi) else lo + 1.0), why
    grid = np.linspace(-1.0, 1.0, 41)
    ok = np.array([existence_coefficient(model, mu, delay) > 0.0 for mu in grid])
    if ok.any():
        runs, start = [], None
        for i, flag in enumerate(list(ok) + [False]):
            if flag and start is None:
                start = i
            elif not flag and start is not None:
                runs.append((i - start, start, i - 1))
                start = None
        _n, a, b = max(runs)
        return float(0.5 * (grid[a] + grid[b])) + 0.0, ("no mu with |lambda0| < 1: the middle "
                                                        "of the widest run where gamma1 > 0")
    return 0.0, "mu = 0: the controlled 1/1 orbit exists for no mu in [-1, 1]"


def markov_gain(model, mu: float, settings, smooth_branch: bool = True,
                delay: float = 0.0) -> np.ndarray:
    """k(mu) + offset d: a gain that cancels w^T N u, and G(1) too with ``smooth_branch``
    (``family.cancel_first_markov``), |offset| = ``markov_offset`` |k(mu)|, of the
    sign for which the local map has a 1/1 orbit born at grazing (whether it exists for
    d < d* depends on that sign; family's docstring); the delayed kick's with a ``delay``."""
    from grazing_control.dynamics.design.family import cancel_first_markov, gain_family
    from grazing_control.dynamics.orbits.near_grazing import predicted_orbit

    size = settings.markov_offset * max(float(np.linalg.norm(gain_family(model, mu, delay))),
                                        1.0)
    candidates = [np.asarray(cancel_first_markov(model, mu, sign * size,
                                                 smooth_branch=smooth_branch, delay=delay),
                             dtype=float) for sign in (1.0, -1.0)]
    for k in candidates:
        if any(predicted_orbit(model, k, side * settings.fit_below, delay)[0] is not None
               for side in (-1.0, 1.0)):
            return k
    return candidates[0]


def scaling_curves(model, settings: NdofFigureSettings, mu: float, delay: float = 0.0):
    """The three curves of (b) with their fitted exponents and the predicted limit (the
    delayed kick's with a ``delay``)."""
    from grazing_control.dynamics.design.family import gain_family, limit_multipliers
    from grazing_control.dynamics.orbits.near_grazing import grazing_side
    from grazing_control.studies.near_grazing.scaling import fit_exponent, multiplier_scaling

    sizes = np.geomspace(settings.scaling_from, settings.scaling_to, settings.scaling_points)
    cases = [("uncontrolled", None, "tab:red"),
             (f"design family, mu = {mu:.4g}", np.asarray(gain_family(model, mu, delay)),
              "tab:green")]
    numbers = {}
    # w^T N u = 0 alone leaves the branch linear in psi (v- ~ |Delta d|): |Delta d|^-1/2;
    # with G(1) = 0 too the branch is smooth (v- ~ |Delta d|^1/2): |Delta d|^-1/4
    # (docs/theory_ndof.md section 9)
    for label, smooth, color in (("cancels only w^T N u", False, "tab:purple"),
                                 ("cancels w^T N u and G(1)", True, "tab:orange")):
        try:
            cases.append((label, markov_gain(model, mu, settings, smooth, delay), color))
        except ParameterError as exc:   # n = 1: w^T N u = 0 is the whole family (Eq. 33)
            numbers[label] = {"error": " ".join(str(exc).split())}
    limit = float(np.max(np.abs(limit_multipliers(model, mu, delay))))
    curves = []
    for label, k, color in cases:
        side = grazing_side(model, k, settings.fit_below, 0.0 if k is None else delay)
        sc = multiplier_scaling(model, k, side * sizes, 0.0 if k is None else delay)
        big = sc.largest
        near = np.abs(sc.delta_d) <= settings.fit_below
        slope = fit_exponent(sc.delta_d[near], big[near])
        curve = {"delta_d": sc.delta_d, "largest": big, "color": color, "slope": slope,
                 "label": label + (" (on Delta d > 0)" if side > 0 else "")}
        ok = np.isfinite(big)
        entry = {"gains": None if k is None else k.tolist(), "side": side,
                 "delta_d": sc.delta_d.tolist(),
                 "largest": [_finite_or_none(x) for x in big],
                 "fitted_exponent": _finite_or_none(slope),
                 "fit_points": int(np.sum(near & ok)),
                 "smallest_delta_d_found": _finite_or_none(
                     float(sc.delta_d[ok][np.argmin(np.abs(sc.delta_d[ok]))]) if ok.any() else None),
                 "failures": [e.split(" (")[0] for e in sc.errors if e][:3]}
        if k is not None and label.startswith("design"):
            curve["limit"] = limit
            entry["predicted_limit"] = limit
            entry["limit_multipliers"] = _complex_list(limit_multipliers(model, mu, delay))
            if ok.any():
                last = big[ok][np.argmin(np.abs(sc.delta_d[ok]))]
                entry["difference_to_limit_at_smallest"] = float(abs(last - limit))
            entry["bounded"] = bool(ok.any() and np.nanmax(big) < 1e3 * max(1.0, limit))
        curves.append(curve)
        numbers[label.split(",")[0].split(" (")[0]] = entry
    return curves, numbers


def make_ndof_figures(model, out, settings: NdofFigureSettings = DEFAULT, *,
                      model_file: str = "", workers: int | None = None, log=None,
                      delay: float = 0.0) -> dict:
    """Compute and draw (a), (b), (c) of the module docstring into ``out``, the kick
    ``delay`` after the sample; returns the numbers (also written to
    ``out/ndof_figures.json``)."""
    from grazing_control.dynamics.design.family import gain_family
    from grazing_control.studies.sweeps.model_file import diagram
    from grazing_control.studies.sweeps.plot import diagram_png
    from grazing_control.studies.near_grazing.scene import control_scene

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out={str(out)!r} is invalid: it exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    say = log or (lambda line: None)
    if settings.mu is None:
        mu, why = choose_mu(model, delay)
    else:
        mu, why = float(settings.mu), "given"
    k = np.asarray(gain_family(model, mu, delay), dtype=float)
    coord = f"x{model.i_w}"
    numbers = {"model": model_file, "n": model.n, "mu": mu, "mu_chosen": why,
               "gains": k.tolist(), "settings": asdict(settings)}
    if delay:
        numbers["actuation_delay"] = float(delay)

    say("(a) brute-force diagram on Pi2 against Delta d ...")
    values = np.linspace(settings.diagram_from, settings.diagram_to, settings.diagram_points)
    dia = diagram(model, values, periods=settings.diagram_periods,
                  transient=settings.diagram_transient, workers=workers)
    diagram_png(dia, out / "ndof_diagram.png", coordinate=coord,
                title=f"uncontrolled, {dia.values.size} values of Delta d x "
                      f"{dia.periods - dia.transient} kept periods")
    per, cnt = np.unique(dia.period, return_counts=True)
    numbers["diagram"] = {"png": "ndof_diagram.png", "coordinate": coord,
                          "detected_periods": {str(int(p)): int(c) for p, c in zip(per, cnt)},
                          "failed": int(np.sum(dia.period == -1))}

    say("(b) multipliers of the 1/1 orbit against |Delta d| ...")
    curves, scal = scaling_curves(model, settings, mu, delay)
    scaling_png(curves, out / "ndof_multipliers.png",
                title=f"1/1 orbit by shooting; exponents fitted over |Delta d| <= "
                      f"{settings.fit_below:g}")
    numbers["multipliers"] = {"png": "ndof_multipliers.png", **scal}

    say("(c) control scene ...")
    sc = control_scene(model, k, delta_d=settings.scene_delta_d,
                       control_after=settings.scene_before,
                       periods=settings.scene_before + settings.scene_after, delay=delay)
    scene_png(sc, out / "ndof_scene.png", coordinate_index_=model.i_w, coordinate=coord)
    before = sc.impacts_per_period[:settings.scene_before]
    numbers["scene"] = {
        "png": "ndof_scene.png", "delta_d": sc.delta_d,
        "impacts_per_period_before_last_20": before[-20:].tolist(),
        "impacts_per_period_after_last_20": sc.impacts_per_period[-20:].tolist(),
        "final_distance": None if sc.distance is None else float(sc.distance[-1]),
        "distance_at_switch": None if sc.distance is None else float(
            sc.distance[settings.scene_before]),
        "orbit_error": sc.orbit_error,
    }
    (out / "ndof_figures.json").write_text(json.dumps(numbers, indent=1, allow_nan=False)
                                           + "\n", encoding="utf-8")
    return numbers


# ---------------------------------------------------------------------------- pictures
# (the diagram panel is studies/sweeps/plot.py's diagram_png, as ``grazing sweep --model``'s)
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

"""The two control scenes: Figs. 2(f) and 2(g) (spec section 8; the demo's scenes).

Each scene (Delta d = -5e-6 and -9e-6) runs the uncontrolled oscillator for 1000
Pi2 samples, then switches the controller of Eq. 28 on (c2 = -1, c1 from Eq. 38).
The scene is read with :mod:`grazing_control.recordings.analysis` (the demo's reader and
numbers): from a core simulation by default, or from a recording made by
``grazing demo`` when its bag folder is given. The exact controlled 1/1 orbit
(:func:`grazing_control.dynamics.orbits.one_one.orbit`) is drawn as the target.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grazing_control.recordings.analysis import (scene_from_bag, scene_from_simulation,
                                                 summarize)
from grazing_control.oscillator.control import Gains
from grazing_control.studies.demo import CONTROL_AFTER, PERIODS, SCENES
from grazing_control.dynamics.orbits import one_one
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.support.plotting import COLORS, PANEL_SIZE, pyplot, save
from .report import Number, Panel

__all__ = ["load_scene", "panel_scene"]


def load_scene(p: OscillatorParams, gains: Gains, name: str, bags=None):
    """(Scene, source): from ``bags``/name if that recording exists, else simulated."""
    if bags is not None:
        bag = Path(bags) / name
        if not bag.exists():
            raise ValueError(f"bags={str(bags)!r} is invalid: no recording {bag} "
                             f"(expected the folder `grazing demo` writes, out/demo/bags)")
        return scene_from_bag(bag), f"recording {bag}"
    res = simulate(p, PERIODS, gains=gains, control_after=CONTROL_AFTER)
    return scene_from_simulation(res), "core simulation"


def panel_scene(p: OscillatorParams, gains: Gains, which: str, out, bags=None) -> Panel:
    """Fig. 2(f) (which='f', Delta d = -5e-6) or 2(g) (which='g', Delta d = -9e-6)."""
    name, dd = SCENES[{"f": 0, "g": 1}[which]]
    q = p.with_(delta_d=dd)
    scene, source = load_scene(q, gains, name, bags)
    numbers = summarize(scene)
    exact = one_one.orbit(q, gains)
    on = numbers["control_on"] if numbers["control_on"] is not None else len(scene.t)
    k = np.arange(len(scene.t))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=PANEL_SIZE, constrained_layout=True)
    ax.plot(k[:on], scene.pi2[:on, 0], ".", ms=2.5, color="k", label="uncontrolled")
    ax.plot(k[on:], scene.pi2[on:, 0], ".", ms=2.5, color=COLORS["controlled"],
            label="controlled")
    ax.axvline(on, color="0.3", lw=0.8, ls="--", label=f"control on (sample {on})")
    ax.axhline(exact.physical[0], color=COLORS["stable"], lw=0.9, ls=":",
               label=f"controlled 1/1 orbit, x = {exact.physical[0]:.6g}")
    ax.set(xlabel="Π2 sample k (forcing periods)", ylabel="x on Π2",
           title=f"Fig. 2({which}): Δd = {dd:g}, control switched on after {CONTROL_AFTER} samples")
    fig.legend(fontsize=8, loc="outside lower center", ncol=2)
    files = save(fig, out, f"fig2{which}")
    per = numbers["uncontrolled_period"]
    hist = numbers["uncontrolled_impacts_per_period"]
    err = float(np.max(np.abs(scene.pi2[-1] - exact.physical)))
    nums = (
        Number("source", "source", source),
        Number("delta_d", "Δd", dd, f"{dd:g}", fmt="g"),
        Number("control_on", "control switched on at sample", on, str(CONTROL_AFTER)),
        Number("uncontrolled_period", "uncontrolled motion before control: period",
               per if per else "none ≤ 64 (chaotic)", note="last 200 samples, analysis.summarize"),
        Number("uncontrolled_impacts_histogram", "impacts per period before control (0, 1, 2, …)",
               tuple(hist) if hist else None),
        Number("samples_to_converge", "samples after switching on until within 1e-8",
               numbers["samples_to_converge"]),
        Number("one_impact_per_period", "1/1 motion after convergence",
               numbers.get("one_impact_per_period_after_convergence"), "yes"),
        Number("final_error", "|final sample − exact controlled 1/1 orbit|", err, fmt=".2e"),
        Number("final_v_minus", "final impact velocity v⁻", numbers["final_v_minus"], fmt=".6g",
               note=f"exact orbit: {exact.v_minus:.6g}"),
        Number("max_abs_correction", "max |Δv| of the corrections", numbers["max_abs_correction"],
               fmt=".3g"),
    )
    kind = "chaotic" if not per else f"period-{per}"
    return Panel(f"fig2{which}", f"control scene Δd = {dd:g}",
                 f"x on Π2 per forcing period at Δd = {dd:g} ({source}): {CONTROL_AFTER} samples "
                 f"of the uncontrolled ({kind}) motion, then the controller (c2 = {gains.c2:g}, "
                 f"c1 = {gains.c1:.6g}) is on and the response converges to the controlled 1/1 "
                 "motion (dotted: its exact Π2 point from shooting).",
                 tuple(files), nums)

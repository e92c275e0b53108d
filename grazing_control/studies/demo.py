"""The main job: the study's two control scenes (spec section 8, Fig. 2 f, g) and a report.

For each scene (Delta d = -5e-6 and -9e-6; 1000 uncontrolled Pi2 samples, then the
controller with c2 = -1 and c1 from the degenerate condition) the run goes through
the real ROS 2 nodes as separate processes (sim_node, controller_node, recorder_node,
started by :mod:`grazing_control.ros.launcher`) in lockstep, recorded to MCAP; the report
(figures and numbers) is then made from the recordings alone. ``--offline`` runs the
same scenes through the core instead (no ROS), with the same report.

The core's exact answers (the controlled 1/1 orbit, and the core simulation of the
same scene) are printed next to the recorded numbers as a cross-check, labelled so.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from grazing_control.recordings.analysis import (plot_scene, scene_from_bag,
                                                 scene_from_simulation, summarize)
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import (degenerate_c1, evaluate_design,
                                             write_controller_yaml)
from grazing_control.dynamics.orbits import one_one
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate

__all__ = ["SCENES", "main"]

#: (name, Delta d) of the study's two scenes.
SCENES = (("scene_5e-6", -5e-6), ("scene_9e-6", -9e-6))
C2 = -1.0
CONTROL_AFTER = 1000
PERIODS = 1300


def _run_nodes(p, controller_yaml, bag_dir, periods):
    """Record the scene into a fresh folder, then put it in place of ``bag_dir``.

    The demo owns its output folder: a second run replaces the bag of the first (the
    recorder itself never writes into an existing bag), and only once the new one is
    complete, so a failed or interrupted run leaves the previous bag as it was.
    """
    import shutil
    import tempfile

    from grazing_control.ros.launcher import run_scene

    bag_dir = Path(bag_dir)
    bag_dir.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{bag_dir.name}.", dir=bag_dir.parent))
    try:
        fresh = work / bag_dir.name          # the .mcap is named after its folder
        result = run_scene(p, controller_yaml, fresh, periods=periods,
                           enable_after=CONTROL_AFTER)
        if bag_dir.exists():
            os.replace(bag_dir, work / "previous")
        os.replace(fresh, bag_dir)
        return result
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _nodes_available() -> bool:
    import importlib.util

    return all(importlib.util.find_spec(m) is not None for m in (
        "grazing_control.ros.launcher", "sim_node.sim_node", "grazing_control.ros.controller_node",
        "grazing_control.ros.recorder_node"))


def main(args) -> int:
    if not args.offline and not _nodes_available():
        print("demo: the ROS 2 nodes or the launcher are not available; running offline (core)")
        args.offline = True
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = OscillatorParams()
    gains = Gains(degenerate_c1(base, C2), C2)
    design = evaluate_design(base, C2)
    controller_yaml = out / "controller.yaml"
    write_controller_yaml(controller_yaml, base, gains)
    print(f"design: c2 = {C2}, c1 = {gains.c1:.15g}, |lambda0| = "
          f"{np.abs(design.multipliers_limit).round(6).tolist()}, written to {controller_yaml}")
    report = {"design": {"c1": gains.c1, "c2": gains.c2,
                         "multipliers_limit_abs": np.abs(design.multipliers_limit).tolist()},
              "mode": "offline (core)" if args.offline else "ROS 2 nodes, lockstep, recorded to MCAP",
              "scenes": {}}
    lines = ["# Grazing control: the study's two control scenes", "",
             f"Mode: {report['mode']}. Controller: c2 = {C2}, c1 = {gains.c1:.12g} "
             f"(degenerate grazing, Eq. 38); on after {CONTROL_AFTER} Π2 samples.", ""]
    for name, dd in SCENES:
        p = base.with_(delta_d=dd)
        t0 = time.perf_counter()
        if args.offline:
            scene = scene_from_simulation(simulate(p, PERIODS, gains=gains, control_after=CONTROL_AFTER))
            source = "core simulation"
        else:
            bag = out / "bags" / name
            _run_nodes(p, controller_yaml, bag, PERIODS)
            scene = scene_from_bag(bag)
            source = f"recording {bag}"
        wall = time.perf_counter() - t0
        numbers = summarize(scene)
        exact = one_one.orbit(p, gains)
        core = simulate(p, len(scene.t), gains=gains, control_after=CONTROL_AFTER)
        n = min(len(core.pi2), len(scene.pi2))
        cross = {
            "exact_controlled_orbit_pi2": exact.physical.tolist(),
            "exact_v_minus": exact.v_minus,
            "final_pi2_error_vs_exact": float(np.max(np.abs(scene.pi2[-1] - exact.physical))),
            "max_sample_difference_vs_core_simulation": float(np.max(np.abs(scene.pi2[:n] - core.pi2[:n]))),
        }
        report["scenes"][name] = {"delta_d": dd, "source": source, "wall_seconds": wall,
                                  "numbers": numbers, "core_cross_check": cross}
        fig = out / f"{name}.png"
        plot_scene(scene, f"Δd = {dd:g}: {CONTROL_AFTER} uncontrolled Π2 samples, then control", fig)
        per = numbers["uncontrolled_period"]
        lines += [
            f"## Δd = {dd:g}", "", f"![{name}]({fig.name})", "",
            f"* source: {source} ({wall:.1f} s wall)",
            f"* samples: {numbers['samples']}, impacts: {numbers['impacts']}",
            "* uncontrolled attractor: "
            + (f"period {per}" if per else "not periodic over the last 200 samples (chaotic)")
            + f"; impacts per period histogram before control: {numbers['uncontrolled_impacts_per_period']}",
            f"* control on at sample {numbers['control_on']}; converged (to 1e-8) after "
            f"{numbers['samples_to_converge']} samples",
            f"* final Π2 point: ({numbers['final_pi2'][0]:.12g}, {numbers['final_pi2'][1]:.12g}); "
            f"impacts per period at the end: {numbers['final_impacts_per_period']}; "
            f"final v⁻ = {numbers['final_v_minus']:.6g}",
            f"* core cross-check: exact controlled 1/1 orbit on Π2 = ({exact.physical[0]:.12g}, "
            f"{exact.physical[1]:.12g}), v⁻ = {exact.v_minus:.6g}; |final − exact| = "
            f"{cross['final_pi2_error_vs_exact']:.2e}; max |recorded − core simulation| over "
            f"all samples = {cross['max_sample_difference_vs_core_simulation']:.2e}",
            "",
        ]
        ok = numbers.get("one_impact_per_period_after_convergence")
        print(f"{name}: Δd = {dd:g}: control on at {numbers['control_on']}, converged after "
              f"{numbers['samples_to_converge']} samples, 1/1 at the end: {bool(ok)}, "
              f"|final - exact orbit| = {cross['final_pi2_error_vs_exact']:.1e} ({wall:.1f} s)")
    if not args.offline:     # the bag analysis of the recordings (docs/analysis.md)
        from grazing_control.recordings.analyze import analyze

        analyze([out / "bags" / name for name, _ in SCENES], out / "analysis")
        lines += ["Bag analysis of the recordings (measured vs predicted contraction, "
                  "parameter record): [analysis/report.md](analysis/report.md)", ""]
    (out / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"report: {out / 'report.md'} (numbers: {out / 'report.json'})")
    return 0

"""Analysis of a scene and the offline main job: numbers earned against the core."""

import json
from types import SimpleNamespace

import numpy as np

from grazing_control.recordings.analysis import (control_lines, convergence,
                                                  scene_from_simulation, summarize)
from grazing_control.oscillator.control import Gains
from grazing_control.studies.demo import main as demo_main
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate


def test_summary_of_a_controlled_scene_matches_the_exact_orbit():
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(degenerate_c1(p, -1.0), -1.0)
    s = summarize(scene_from_simulation(simulate(p, 1100, gains=g, control_after=1000)))
    assert s["control_on"] == 1000
    assert s["samples_to_converge"] is not None and s["samples_to_converge"] < 50
    assert s["one_impact_per_period_after_convergence"]
    assert np.allclose(s["final_pi2"], orbit_11(p, g).pi2, rtol=0, atol=1e-12)


def test_convergence_is_said_with_the_tolerance_it_was_measured_to():
    """summarize keeps its tol; the report and grazing analyze's line say it, and a scene
    that never settles within it (a noisy loop) says so, not "after None"."""
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(degenerate_c1(p, -1.0), -1.0)
    scene = scene_from_simulation(simulate(p, 1100, gains=g, control_after=1000))
    tight, loose = summarize(scene), summarize(scene, tol=1e-4)
    assert tight["converge_tol"] == 1e-8 and loose["converge_tol"] == 1e-4
    assert loose["samples_to_converge"] < tight["samples_to_converge"]
    assert convergence(loose["samples_to_converge"], 1e-4) == \
        f"converged to 0.0001 after {loose['samples_to_converge']} samples"
    assert convergence(None, 1e-8) == "not converged to 1e-08 by the end"
    assert convergence(3, None) == "converged to 1e-08 after 3 samples"   # older numbers
    lines = control_lines({"control_on_sample": 1000, "control_on_time_s": 9418.2,
                           "samples_to_converge": None, "converge_tol": 1e-6,
                           "measured_contraction": None, "predicted": {}})
    assert lines == ["* control on at sample 1000 (t = 9418.2 s); not converged to 1e-06 "
                     "by the end"]


def test_periodic_uncontrolled_attractor_is_recognised():
    # Delta d = -1e-3 settles on the stable 1/1 orbit: period 1, one impact per period
    p = OscillatorParams(delta_d=-1e-3)
    s = summarize(scene_from_simulation(simulate(p, 400)))
    assert s["uncontrolled_period"] == 1 and s["control_on"] is None


def test_offline_demo_writes_a_report_with_both_scenes_converged(tmp_path):
    assert demo_main(SimpleNamespace(out=str(tmp_path), offline=True)) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert set(report["scenes"]) == {"scene_5e-6", "scene_9e-6"}
    for scene in report["scenes"].values():
        assert scene["numbers"]["one_impact_per_period_after_convergence"]
        assert scene["core_cross_check"]["final_pi2_error_vs_exact"] < 1e-10
        assert (tmp_path / "report.md").exists()
    assert (tmp_path / "scene_5e-6.png").stat().st_size > 10_000

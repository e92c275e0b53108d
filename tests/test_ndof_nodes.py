"""An n-DOF scene through the real nodes (issue 17): sim_node and controller_node with
``model_file`` as separate processes over Fast DDS, recorded by recorder_node and
analysed from the bag alone.

The scene is config/models/two_mass_scene.yaml (the two-mass chain at omega = 0.275,
Delta d = -1e-5): uncontrolled its Pi2 samples settle on a period-2 motion near grazing
(one impact every second period); the controller with the design's k(mu = 0)
(dynamics.ndof_design, written by write_gain_yaml) switched on at sample 400 takes them
to the controlled 1/1 orbit that Newton shooting finds on NdofMap with the same gains.
The references are the core's: the engine replayed with the recorded corrections
(bit for bit: the node is the engine) and find_periodic.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.ndof_design import evaluate_design, write_gain_yaml
from grazing_control.dynamics.ndof_map import NdofMap
from grazing_control.dynamics.shooting import find_periodic
from grazing_control.oscillator.ndof.model import load_model
from grazing_control.plant.ndof_engine import NdofEngine
from grazing_control.plant.ndof_settings import ndof_settings_from_values
from grazing_control.recordings import reader
from grazing_control.recordings.analyze import analyze
from grazing_control.recordings.scenes import load
from grazing_control.ros import launcher, scene_nodes
from test_closed_loop import new_domain

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "config" / "models" / "two_mass_scene.yaml"
MODEL = load_model(SCENE)


def first_message(raw, topic: str, kind):
    """The first message of ``topic`` in a bag, deserialized by rclpy."""
    from rclpy.serialization import deserialize_message

    b = reader._Body(raw.pool, raw.offsets(topic))
    return deserialize_message(raw.pool[b.body[0] - 4:b.end[0]].tobytes(), kind)


def test_a_two_mass_scene_through_the_nodes_converges_to_the_controlled_orbit(tmp_path):
    from sensor_msgs.msg import JointState

    n, on = 470, 400
    gains = tmp_path / "gains.yaml"
    write_gain_yaml(gains, MODEL, evaluate_design(MODEL, 0.0), SCENE)
    bag = tmp_path / "bag"
    res = launcher.run(None, gains, bag, n, enable_after=on, domain_id=new_domain(),
                       timeout=90, log_dir=tmp_path / "logs", model=SCENE,
                       sim_overrides={"state_period": 2.0})
    logs = {k: Path(v).read_text() for k, v in res.logs.items()}
    assert res.ok, (res, logs)
    assert "n=2 i_w=0 i_a=1" in logs["sim_node"] and "model_file=" in logs["controller_node"]

    data = load(bag)
    assert data.joints == 2 and len(data.scenes) == 1
    scene = data.scenes[0].scene
    X = scene.pi2
    assert X.shape == (n, 4) and np.all(data.scenes[0].answered)
    raw = reader.read_raw(data.file)
    for topic, efforts in (("/oscillator/pi2", 1), ("/oscillator/state", 2),
                           ("/oscillator/pi1", 1)):
        msg = first_message(raw, topic, JointState)
        assert list(msg.name) == ["mass0", "mass1"], topic
        assert len(msg.position) == len(msg.velocity) == 2 and len(msg.effort) == efforts

    # the node is the engine: replayed with the recorded corrections, bit for bit
    eng = NdofEngine(ndof_settings_from_values({}, str(SCENE)))
    for k in range(n):
        ev = eng.sample()
        assert np.array_equal(np.array(ev.x + ev.v), X[k]), k
        eng.begin_period(float(scene.correction[k]))
        eng.end_period()
    assert np.all(scene.correction[:on] == 0.0) and np.all(scene.correction[on:] != 0.0)

    # uncontrolled: period 2 near grazing, not 1
    before = X[on - 40:on]
    assert np.max(np.abs(before[2:] - before[:-2])) < 1e-9
    assert np.min(np.max(np.abs(before[1:] - before[:-1]), axis=1)) > 1e-3
    # controlled: the exact controlled 1/1 orbit
    P = NdofMap(MODEL, evaluate_design(MODEL, 0.0).gains)
    xref = P.flow.particular(P.flow.tau2)
    orbit = find_periodic(P, X[-1] - xref)
    distance = float(np.max(np.abs(X[-1] - (xref + orbit.state))))
    assert distance < 1e-12, distance
    print(f"two_mass_scene through the nodes: |X_final - X_orbit| = {distance:.2e}")

    # grazing analyze of the bag: per-coordinate numbers from the bag alone
    report = analyze([bag], tmp_path / "report")
    s = report["bags"][0]["scenes"][0]
    assert report["bags"][0]["setup"]["n"] == 2
    assert s["uncontrolled"]["period"] == 2 and s["control_on_sample"] == on
    assert s["final_vs_exact_orbit"] < 1e-12 and s["model_check"]["max_departure"] < 1e-12
    assert s["final_impacts_per_period"] == 1
    assert s["contraction_relative_error"] < 0.05
    assert set(s["final_vs_exact_orbit_per_coordinate"]) == {"x0", "x1", "v0", "v1"}
    text = (tmp_path / "report" / "report.md").read_text()
    assert "n-DOF scene" in text and "v1" in text and (tmp_path / "report" / "bag.png").is_file()


def test_bad_model_files_and_gains_stop_the_nodes_with_one_line(tmp_path):
    broken = tmp_path / "broken.yaml"
    broken.write_text("M: [[1.0, 0.0], [0.0\n")
    domain = new_domain()
    env = launcher.node_env(domain)
    sim, ctl = launcher.SIM_MODULE, launcher.CONTROLLER_MODULE
    cases = {
        "broken file": (sim, {"model_file": str(broken)}, "model_file="),
        "1-DOF option": (sim, {"model_file": str(SCENE), "zeta": 0.02},
                         "zeta=0.02 is invalid with model_file"),
        "gains length": (ctl, {"model_file": str(SCENE), "gains": [1.0, 2.0, 3.0]},
                         "gains has 3 values: valid is 2n = 4"),
        "no gains": (ctl, {"model_file": str(SCENE)}, "gains is not given"),
    }
    procs = {name: subprocess.Popen(launcher.node_command(module, (), over), env=env,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, (module, over, _) in cases.items()}
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=30)
        lines = [ln for ln in (out + err).splitlines() if ln.strip()]
        assert proc.returncode == 2, (name, out, err)
        assert len(lines) == 1 and "Traceback" not in err, (name, lines)
        assert cases[name][2] in lines[0] and "[ERROR]" in lines[0], (name, lines[0])


def test_grazing_run_with_a_model_gives_both_nodes_the_file(tmp_path):
    with pytest.raises(ValueError, match="needs the controller's gains"):
        launcher.run(model=SCENE)
    gains = tmp_path / "gains.yaml"
    write_gain_yaml(gains, MODEL, evaluate_design(MODEL, 0.0), SCENE)
    assert scene_nodes.design_model(gains) == str(SCENE)
    over = scene_nodes.scene_overrides(gains, model="config/models/two_mass_scene.yaml",
                                       delta_d=-3e-6)
    assert over["sim_node"]["model_file"] == over["controller_node"]["model_file"] == \
        os.path.abspath("config/models/two_mass_scene.yaml")     # nodes in any folder
    assert over["controller_node"]["delta_d"] == -3e-6        # its model of the plant
    values = scene_nodes.sim_values_for_model(ROOT / "config" / "study.yaml")
    assert "zeta" not in values and "delta_d" not in values and values["max_periods"] == 1200

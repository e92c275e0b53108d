"""A composed scene (``grazing run --compose``, grazing_control/ros/composed.py; issue 30):
sim_node, controller_node and recorder_node in one process behave as in three."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros import launcher

from test_closed_loop import CONTROLLER, STUDY, new_domain

pytestmark = pytest.mark.timeout(180)

N, ON = 300, 200      # periods, first controlled sample (test_closed_loop's lockstep scene)


@pytest.fixture(scope="module")
def composed(tmp_path_factory):
    """One composed lockstep scene with the recorder: (RunResult, bag, log text)."""
    tmp = tmp_path_factory.mktemp("composed")
    bag = tmp / "bag"
    res = launcher.run(STUDY, CONTROLLER, bag, N, domain_id=new_domain(), timeout=120,
                       controller_overrides={"enable_after": ON}, log_dir=tmp / "logs",
                       compose=True)
    return res, bag, Path(res.logs["sim_node"]).read_text()


def test_a_composed_lockstep_scene_is_the_core_sample_for_sample(composed):
    """The bag of a composed scene: Pi2 bitwise equal to simulate() before the control,
    1e-9 after (as tests/test_closed_loop.py for three processes), every message recorded
    (the recorder's closed record: status 0, nothing missed), one process's log."""
    from grazing_control.ros.recording import read_messages

    res, bag, log = composed
    assert res.ok, (res, log)
    assert (res.sim, res.controller, res.recorder) == (0, 0, 0)
    assert set(res.logs.values()) == {str(Path(res.logs["sim_node"]))}   # one log
    for node in ("sim_node", "controller_node", "recorder_node"):
        assert f"[{node}]: " in log
    assert "executor=events" in log
    assert launcher.recorded_status(bag) == 0 and launcher.recorded_losses(bag) == ""
    p = OscillatorParams(delta_d=-5e-6)
    ref = simulate(p, N, gains=Gains(degenerate_c1(p, -1.0), -1.0), control_after=ON)
    msgs = defaultdict(list)
    for m in read_messages(bag):
        msgs[m.topic].append(m.message)
    pi2 = np.array([(m.position[0], m.velocity[0]) for m in msgs["/oscillator/pi2"]])
    assert pi2.shape == (N, 2)
    np.testing.assert_array_equal(pi2[:ON], ref.pi2[:ON])
    rel = (np.linalg.norm(pi2[ON:] - ref.pi2[ON:], axis=1)
           / np.linalg.norm(ref.pi2[ON:], axis=1))
    assert rel.max() < 1e-9, rel.max()
    dv = np.array([m.twist.linear.x for m in msgs["/controller/velocity_correction"]])
    assert dv.shape == (N,)
    np.testing.assert_array_equal(dv[:ON], 0.0)
    np.testing.assert_allclose(dv[ON:], ref.corrections[ON:], rtol=1e-6, atol=1e-14)
    assert len(msgs["/oscillator/impact"]) == ref.impacts.shape[0]
    assert len(msgs["/oscillator/pi1"]) == N
    assert len(msgs["/oscillator/state"]) == int(np.floor(N * p.period)) + 1


def test_a_composed_node_refusing_to_start_ends_the_scene_with_status_2(tmp_path):
    """A bad parameter of one composed node: one line naming it, that node's status 2,
    the scene stopped at once (nothing simulated), the statuses written whole."""
    res = launcher.run(STUDY, CONTROLLER, None, 20, domain_id=new_domain(), timeout=60,
                       sim_overrides={"time_scale": -1.0}, log_dir=tmp_path, compose=True)
    log = Path(res.logs["sim_node"]).read_text()
    assert not res.ok and res.sim == 2, (res, log)
    assert "time_scale" in log and "summary: periods=0" not in log.replace(
        "(interrupted)", "")
    assert "Traceback" not in log


def test_the_composed_statuses_file_is_read_or_the_process_status_stands(tmp_path):
    """The launcher takes each node's status from the composed process's file; without
    one (killed) every node gets the process's status."""
    path = tmp_path / "statuses.json"
    path.write_text(json.dumps({"sim_node": 0, "controller_node": 1}))
    assert launcher._composed_statuses(path, None, False) == {"sim_node": 0,
                                                              "controller_node": 1}

    class Killed:
        returncode = -9
    assert launcher._composed_statuses(tmp_path / "none.json", Killed(), True) == {
        "sim_node": -9, "controller_node": -9, "recorder_node": -9}

"""The reference recordings in bags/: the study's two control scenes, recorded by
`make demo` through the three node processes in lockstep.

They are read by two independent readers, and the numbers the report takes from
them alone are checked against the exact core (same scene, same gains).
"""

from pathlib import Path

import numpy as np
import pytest

from grazing_control.recordings.analysis import scene_from_bag, summarize
from grazing_control.oscillator.control import Gains
from grazing_control.studies.demo import CONTROL_AFTER, SCENES
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros.recording import read_messages, read_messages_rosbags, read_metadata
from grazing_control.dynamics.simulation.simulate import simulate

BAGS = Path(__file__).resolve().parent.parent / "bags"


@pytest.mark.parametrize("name,delta_d", SCENES)
def test_reference_bag_reproduces_the_core_and_converges(name, delta_d):
    scene = scene_from_bag(BAGS / name)
    p = OscillatorParams(delta_d=delta_d)
    gains = Gains(degenerate_c1(p, -1.0), -1.0)
    core = simulate(p, len(scene.t), gains=gains, control_after=CONTROL_AFTER)
    # same integration: bit for bit before control, rounding level after
    assert np.array_equal(scene.pi2[:CONTROL_AFTER], core.pi2[:CONTROL_AFTER])
    assert np.max(np.abs(scene.pi2 - core.pi2)) < 1e-12
    assert np.array_equal(scene.impacts_per_period[:-1], core.impacts_per_period[:-1])
    numbers = summarize(scene)
    assert numbers["control_on"] == CONTROL_AFTER
    assert numbers["one_impact_per_period_after_convergence"]
    assert np.max(np.abs(np.array(numbers["final_pi2"]) - orbit_11(p, gains).pi2)) < 1e-12


@pytest.mark.parametrize("name", [s[0] for s in SCENES])
def test_reference_bag_reads_equal_in_both_readers(name):
    meta = read_metadata(BAGS / name)
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    a = [(m.topic, m.log_time_ns) for m in read_messages(BAGS / name)]
    b = [(m.topic, m.log_time_ns) for m in read_messages_rosbags(BAGS / name)]
    assert len(a) == meta["message_count"] and sorted(a) == sorted(b)
    pi2_a = [tuple(m.message.position) for m in read_messages(BAGS / name, ["/oscillator/pi2"])]
    pi2_b = [tuple(m.message.position) for m in read_messages_rosbags(BAGS / name, ["/oscillator/pi2"])]
    assert pi2_a == pi2_b and len(pi2_a) == 1300

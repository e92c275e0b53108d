"""The model check of a scene whose wall drifted, for every n (issue 32).

Bags written in-process from the simulator's engine (:class:`grazing_control.plant.engine.
Engine`, lockstep, the wall moving by ``delta_d_drift`` per period): the Pi2 samples and
the corrections as the nodes record them, and the parameter record. ``grazing analyze``
re-integrates each recorded period at the plant's Delta d of that period (the recorded
Delta d + delta_d_drift k, t_k = k T), so the drifting scene checks at rounding; the
same samples under a record whose drift is 1 % off (or 0: the check before issue 32)
depart by far more: the check still tells a wrong model on a drifting scene.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bagtools_helpers import masses_joint_state, string, twist_stamped, write_rosbags
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values
from grazing_control.recordings.analyze import analyze
from grazing_control.ros.recording.record import encode

ROOT = Path(__file__).resolve().parents[1]
CHAIN = str(ROOT / "config" / "models" / "two_mass_chain.yaml")
ONE = str(ROOT / "config" / "models" / "study_1dof.yaml")
DELTA_D, DRIFT, DELAY, PERIODS = -1e-3, 2e-5, 1.0, 60


def drifting_bags(folder: Path, model_file: str, width: float, drifts) -> list:
    """One lockstep scene of the engine with the wall drifting by DRIFT per period from
    DELTA_D (corrections 1e-3 sin(0.7 k), acting DELAY after each sample: the kick, or
    the pulse of ``width``), written once per recorded drift of ``drifts``."""
    values = {"delta_d": DELTA_D, "delta_d_drift": DRIFT, "actuation_delay": DELAY,
              "pulse_width": width}
    eng = Engine(settings_from_values(values, model_file))
    msgs = []
    for k in range(PERIODS):
        ev = eng.sample()
        stamp = round(ev.t * 1e9)
        dv = 1e-3 * math.sin(0.7 * k)
        eng.begin_period(dv, DELAY)
        eng.end_period()
        msgs += [("/oscillator/pi2", "sensor_msgs/msg/JointState", 1_000_000 + 10 * k,
                  masses_joint_state(stamp, np.atleast_1d(ev.x), np.atleast_1d(ev.v))),
                 ("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped",
                  1_000_001 + 10 * k, twist_stamped(stamp, dv))]
    bags = []
    for i, drift in enumerate(drifts):
        record = {**values, "mode": "lockstep", "delta_d_drift": drift}
        if model_file:
            record["model_file"] = model_file
        head = [("/grazing/parameters", "std_msgs/msg/String", 0,
                 string(encode("/sim_node", record))),
                ("/grazing/parameters", "std_msgs/msg/String", 1,
                 string(encode("/controller_node", {"actuation_delay": DELAY,
                                                    "model_file": model_file})))]
        bags.append(write_rosbags(folder / f"bag{i}", head + msgs))
    return bags


@pytest.mark.parametrize("model_file, width", [("", 0.0), ("", 0.5), (ONE, 0.0),
                                               (CHAIN, 0.0), (CHAIN, 0.5)],
                         ids=["1-DOF", "1-DOF pulse", "n=1 file", "chain", "chain pulse"])
def test_a_drifting_wall_checks_at_rounding_and_a_wrong_drift_departs(tmp_path, model_file,
                                                                      width):
    """The right drift: every period reproduced to rounding (measured 8.9e-16 to 5.1e-15,
    as a scene without drift: 1.5e-15 to 2.9e-15), the report's note and model-check line
    naming the drift, no problem; a record with the drift 1 % off departs by more than
    1e-5 (measured 7.0e-5 to 8.2e-4; a problem of the 1-DOF lockstep scene,
    numbers.scene_problems, the number alone for a model file's), and one without the
    drift by more than 1e-3 (measured 6.7e-3 to 4.6e-2: the check at the recorded
    constant Delta d before issue 32)."""
    bags = drifting_bags(tmp_path, model_file, width, (DRIFT, DRIFT * 1.01, 0.0))
    checks = []
    for i, bag in enumerate(bags):
        report = analyze([bag], tmp_path / f"report{i}", figures=False)
        check = report["bags"][0]["scenes"][0]["model_check"]
        assert check["periods"] == PERIODS - 1, check
        checks.append(check["max_departure"])
        if i == 0:
            text = report["markdown"]
            assert f"the plant's wall drifted (delta_d_drift={DRIFT:g} per period)" in text
            assert f"the wall drifting by {DRIFT:g} per period" in text
            assert check["delta_d_drift"] == DRIFT
            assert not report["bags"][0]["problems"], report["bags"][0]["problems"]
        elif not model_file:       # the 1-DOF lockstep check names a departure a problem
            assert any("the model check departs" in problem
                       for problem in report["bags"][0]["problems"]), report["bags"][0]
    right, off, none = checks
    print(f"drifting wall {model_file or '1-DOF'} width {width}: right {right:.2e}, "
          f"1 % off {off:.2e}, no drift {none:.2e}")
    assert right < 1e-13, checks
    assert off > 1e-5 and none > 1e-3, checks

"""A simulated rig of two masses through the real nodes (issue 32, docs/rig_scene.md "A rig
of n masses"): sim_node with the rig file simulates its n-DOF model and speaks the driver
contract with the measured masses; controller_node with the same file reads the first
measured mass from rig/sensor and answers with force pulses. One short scene, read from
its bag and logs.

The bag is replayed through rig_mock (grazing replay-rig: the same pulses bit for bit).

The rig is config/rigs/two_mass_beam.yaml with the sensor's noise at 0.2 um (10x less):
the orbit the design holds meets the stop at v- 0.005-0.009 (model units; 0.8-1.4 mm/s),
and at the file's 2 um (sigma / |Delta d| = 8) 4 of 16 held periods had no impact
(measured through the nodes, 2026-11-28); at 0.2 um every held period has one. The sensor at 500 Hz (125 samples a period, not the
file's 500) and the scene at half of physical speed (SLOW). At physical speed with the
file's 2 kHz the controller answers in time at idle (its fit stops within 1e-3 of the
posterior std: docs/theory_estimation.md, "Where the fit stops"; docs/rig_scene.md), and
this scene passed 3 of 3 runs at load 6, but a held period without an impact failed it
in a fresh clone's suite beside other agents' tests (load 7) and in 2 of 4 runs of
another agent at load 3-5: at physical speed the answers' margin is a few ms, so the
test's scene keeps the margin of half speed. What the tests read (the SI boundary, the
pulse map, capture) does not depend on the rate or the speed; physical speed is
benchmarks/bench_rig_scene.py's."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from test_rig_scene import _seconds, run_rig_scene

pytestmark = pytest.mark.timeout(240)

RIG = Path(__file__).resolve().parents[1] / "config" / "rigs" / "two_mass_beam.yaml"
PERIODS, ON, SLOW, RATE = 10, 1, 2.0, "500 Hz"
#: The held periods, one impact each (the control acts from section 1; over 16 periods
#: at 1/8 of physical speed and 2 kHz, one impact in each from the fifth on).
HELD = 5


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig_masses_scene")
    doc = yaml.safe_load(RIG.read_text())
    doc["sensor"]["noise"] = "0.2 um"
    doc["sensor"]["rate"] = RATE
    path = out / "two_mass_quiet.yaml"
    path.write_text(yaml.safe_dump(doc))
    topics = ("/rig/sensor", "/rig/phase", "/rig/force_pulse", "/rig/applied",
              "/oscillator/state", "/oscillator/impact", "/oscillator/pi2",
              "/controller/velocity_correction")
    return run_rig_scene(out, path, PERIODS, ON, topics, slow=SLOW)


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_force_pulse_is_the_correction_times_the_effective_mass(scene):
    rig, res, m = scene
    st = rig.structure
    m_a = 1.0 / np.linalg.inv(st.M)[st.actuated, st.actuated]     # kg: 0.8, lumped masses
    assert m_a == pytest.approx(0.8, rel=1e-15)
    start = _seconds(m["/rig/phase"][0][1].header.stamp)          # rig time of t = 0
    dv = {round(_seconds(msg.header.stamp) * 1e6): msg.twist.linear.x
          for _, msg in m["/controller/velocity_correction"]}
    pulses = [msg.wrench for _, msg in m["/rig/force_pulse"]]
    assert PERIODS <= len(pulses) <= PERIODS + 1                  # each section answered
    w, scale = rig.actuator.pulse_width, rig.omega_n * rig.scales.length
    for wrench in pulses:
        t = (wrench.torque.y - start) * rig.omega_n               # the section, model time
        F = m_a * scale * dv[round(t * 1e6)] / w                  # N: m_a Delta v / w
        assert wrench.force.x == pytest.approx(F, rel=1e-12, abs=1e-12)
        assert wrench.torque.x == w
    assert max(abs(p.force.x) for p in pulses) > 0.5               # not all zeros
    applied = [msg.wrench.force.z for _, msg in m["/rig/applied"]]
    assert applied.count(0.0) >= PERIODS - 2                       # in time (0: pre-roll)


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_sensor_gives_the_measured_masses_in_metres(scene):
    rig, res, m = scene
    l = rig.scales.length
    start = _seconds(m["/rig/phase"][0][1].header.stamp)
    state = {round(_seconds(msg.header.stamp) * 1e6): list(msg.position)
             for _, msg in m["/oscillator/state"]}
    sensor = [msg for _, msg in m["/rig/sensor"]]
    # every sample of the scene but those of its end (it ended first)
    assert len(sensor) >= 0.99 * PERIODS * rig.sensor.rate / rig.frequency
    matched = 0
    for msg in sensor:
        assert list(msg.name) == ["mass1", "mass0"] and len(msg.velocity) == 0
        key = round((_seconds(msg.header.stamp) - start) * rig.omega_n * 1e6)
        if key in state:
            matched += 1
            x = state[key]                                         # model x~_0, x~_1
            assert list(msg.position) == pytest.approx([x[1] * l, x[0] * l], rel=1e-12,
                                                       abs=1e-18)
    assert matched >= 0.95 * len(sensor)
    log = Path(res.logs["controller_node"]).read_text()
    assert "sensor_coordinate=1 " in log and "n=2 i_a=0" in log


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_scene_is_captured_one_impact_per_held_period(scene):
    rig, res, m = scene
    period = 2.0 * math.pi / rig.model().omega
    counts = [0] * PERIODS
    for _, msg in m["/oscillator/impact"]:
        counts[int(_seconds(msg.header.stamp) // period)] += 1
    assert counts[-HELD:] == [1] * HELD, counts


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_each_section_is_the_n_dof_pulse_map_of_the_force_that_acted(scene):
    """The plant behind the contract is the rig's model: each Pi2 sample is the exact
    n-DOF pulse map (ModelController.predict: modal_map.pulse_step) of the one before with
    the correction of the force rig/applied says acted (F w / (m_a omega_n l))."""
    from grazing_control.ros.controller_values import model_controller_from_values
    from grazing_control.ros.rig_boundary import controller_values, correction_of

    rig, res, m = scene
    values = controller_values(rig, math.nan)
    ndof = model_controller_from_values(values, str(RIG), values["gains"], rig.model())
    start = _seconds(m["/rig/phase"][0][1].header.stamp)
    acted = {round((msg.wrench.torque.y - start) * rig.omega_n * 1e6):
             correction_of(rig, msg.wrench.force.x, rig.actuator.pulse_width)
             for _, msg in m["/rig/applied"]}
    pi2 = [(round(_seconds(msg.header.stamp) * 1e6), np.array(msg.position),
            np.array(msg.velocity)) for _, msg in m["/oscillator/pi2"]]
    assert len(pi2) == PERIODS
    worst = 0.0
    for (key, x, v), (_, x1, v1) in zip(pi2, pi2[1:]):
        xn, vn = ndof.predict(x, v, acted[key], values["actuation_delay"],
                              (values["pulse_width"], values["force_limit"]))
        worst = max(worst, float(np.max(np.abs(np.concatenate([xn - x1, vn - v1])))))
    assert worst < 1e-11, worst


@pytest.mark.realtime      # the scene's bag replayed: a controller at the recorded pace x 2
def test_the_replay_through_mock_hardware_gives_the_same_pulses_bit_for_bit(scene, tmp_path):
    """The scene's bag through rig_mock (rig/sensor of both masses, rig/phase, rig/clock
    and rig/applied in their recorded order) and a controller_node with the recorded
    parameters (recordings/rig_replay.py): every rig/force_pulse again, float64 bytes
    equal field by field.

    The recorded parameters passed on are the controller's settings less what the rig
    file derives (for n masses MASSES_CONTROLLER_KEYS: the gains, mu, n, ...), so that a
    changed rig_mu takes effect: before, the recorded gains were passed on as given and
    with `--controller-param rig_mu:=0.1` the controller refused to start beside them
    (every command "missing", nothing compared; measured, docs/benchmarks.md). The
    comparison failing on another parameter is test_rig_scene's (one replay here: each
    costs a controller's start, ~10 s of the suite)."""
    from grazing_control.recordings.rig_replay import recorded_controller, replay_rig
    from grazing_control.ros.rig_boundary import MASSES_CONTROLLER_KEYS

    _rig, res, m = scene
    values = recorded_controller(res.bag_dir)
    assert values["rig_file"].endswith("two_mass_quiet.yaml") and "rig_mu" in values
    assert set(values) & set(MASSES_CONTROLLER_KEYS) <= {"answer_lead"}, values
    same = replay_rig(res.bag_dir, time_scale=2.0, log_dir=tmp_path / "same", timeout=120)
    recorded = len({msg.wrench.torque.y for _, msg in m["/rig/force_pulse"]})
    assert same["status"] == 0, same
    assert (same["identical"], same["differing"], same["missing"], same["extra"]) == (
        recorded, 0, 0, 0), same
    assert same["controller"]["applied_after_use"] == "0", same["controller"]


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_right_models_bag_analyses_as_before_rig_applied_was_read(scene, tmp_path):
    """Its commands are on the rig's grid: grazing analyze's report (report.md and
    report.json) is byte for byte the one without rig/applied read (recordings/
    rig_acts.py leaves the scene as it is)."""
    from grazing_control.recordings import analyze as module

    _rig, res, _m = scene
    report = module.analyze([res.bag_dir], tmp_path / "acts", figures=False)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(module, "_acts", lambda bag, data, rig: None)
        before = module.analyze([res.bag_dir], tmp_path / "before", figures=False)
    assert "off the rig's" not in report["markdown"]
    assert report["markdown"] == before["markdown"]
    check = report["bags"][0]["scenes"][0]["model_check"]
    assert check["periods"] > 0 and check["max_departure"] < 1e-12, check
    for name in ("report.md", "report.json"):
        assert (tmp_path / "acts" / name).read_bytes() == (tmp_path / "before" / name).read_bytes()

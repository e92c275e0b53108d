"""A rig scene whose controller's model is wrong (docs/driver_contract.md, "Off the rig's
section"), through the real nodes: the acceptance rig (config/rigs/acceptance.yaml)
simulated, its controller given the same rig with a damping ratio 5 % low (0.0095; 5 %
high gives its own Delta d > 0, which its design refuses). The controller's Pi2 section,
from its own model, lies 14 us before the rig's: every command is off the rig's section
grid, and the simulated rig applies each at its apply time, as a driver executes timed
output (sim_node/rig_io.py, plant/realtime.py's timed answers).

The same for a rig of two masses (config/rigs/two_mass_beam.yaml as
tests/test_rig_masses_scene.py runs it), its controller given the rig with the first
mode's damping ratio 5 % low (0.0095): its section lies 42 us before the rig's, and
``grazing analyze`` reads the bag by what acted (recordings/rig_acts.py) as for one mass."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from test_rig_scene import RIG, _seconds, _summary, run_rig_scene

pytestmark = pytest.mark.timeout(240)

PERIODS, ON = 40, 3
#: Both scenes at a quarter of physical speed, 20 ms of wall time a command (the budget of
#: 5 ms rig time). At half speed, on a machine running at half its speed (2026-11-30, a
#: Python loop 2x slower, the suite 14-17 min): the one-mass scene's samples went out up
#: to 9.9 ms late and its answers took up to 13.5 ms, 4 deadlines missed, and the orbit
#: left the 0.03 band for that; the two-mass scene missed 8 of 11 in a suite (answers
#: 8-19 ms after their samples, p99 45 ms) and 1 alone at idle (p99 16.8 ms), and 0 in 3
#: runs at a quarter (alone, and beside three busy processes). What they check is the
#: wrong model and the analysis of what acted, not the budget.
SLOW = 4.0


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig_wrong_model")
    wrong = out / "wrong.yaml"
    text = RIG.read_text()
    assert "\ndamping_ratio: 0.01\n" in text
    wrong.write_text(text.replace("\ndamping_ratio: 0.01\n", "\ndamping_ratio: 0.0095\n"))
    topics = ("/rig/phase", "/rig/force_pulse", "/rig/applied", "/oscillator/pi2",
              "/oscillator/impact")
    return run_rig_scene(out, RIG, PERIODS, ON, topics, {"rig_file": str(wrong)},
                         slow=SLOW)


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_off_grid_commands_act_at_their_apply_times_exactly(scene):
    rig, res, m = scene
    T = rig.forcing_period
    phases = [_seconds(msg.header.stamp) for _, msg in m["/rig/phase"]]
    pulses = [msg for _, msg in m["/rig/force_pulse"]]
    # every command is off the rig's own section (beyond the 1e-6 T of one of its own)
    off = [msg.wrench.torque.y - phases[0] - round((msg.wrench.torque.y - phases[0]) / T) * T
           for msg in pulses]
    assert all(abs(o) > 1e-6 * T for o in off), off
    by_start = {(p.header.stamp.sec, p.header.stamp.nanosec): p for p in pulses}
    in_time = acting = 0
    for _, a in m["/rig/applied"]:
        if a.wrench.force.z != 0.0:
            continue
        in_time += 1
        # what acted is a command, from its own apply time (the stamp, exactly) ...
        cmd = by_start[(a.header.stamp.sec, a.header.stamp.nanosec)]
        # ... in the slot of the rig's section it reports (torque.y, the rig's grid)
        assert 0.0 <= _seconds(cmd.header.stamp) - a.wrench.torque.y < T
        assert a.wrench.force.x == pytest.approx(cmd.wrench.force.x, rel=1e-12, abs=1e-15)
        acting += a.wrench.force.x != 0.0
    sim = _summary(res.logs["sim_node"], r"\b(in_time|malformed|safe|ignored)=(\d+)")
    assert sim["malformed"] == 0 and sim["safe"] == 0 and sim["ignored"] == 0
    assert sim["in_time"] == in_time >= 0.75 * (PERIODS - 1), (in_time, sim)
    assert acting >= 0.75 * (PERIODS - ON - 1)        # the corrections act


#: Sections after a deadline missed before the orbit is judged again: a missed command
#: (the rig then applies the controller's predicted correction, worse under the wrong
#: model) kicks the motion to 0.045 of X**, and the loop brings it back at a factor 0.87
#: a period, under 0.03 seven sections on (measured: a suite run on a loaded host missed
#: sections 7, 22 and 36, answers 18-36 ms after their samples against 9-20 ms budgets:
#: departures 0.036, 0.045, 0.045, 0.042, 0.038, 0.033, 0.029 after the first).
SETTLE = 8


def _missed_sections(rig, m):
    """The sections whose command did not act in time (a /rig/applied record flagged
    predicted or nothing, force.z != 0), by index: the record's section (torque.y, rig
    time) from the first /rig/phase stamp (the rig time of sample 0), in periods."""
    T, t0 = rig.forcing_period, _seconds(m["/rig/phase"][0][1].header.stamp)
    return sorted(round((a.wrench.torque.y - t0) / T) for _, a in m["/rig/applied"]
                  if a.wrench.force.z != 0.0)


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_wrong_model_holds_the_orbit_near_the_exact_one(scene):
    """The controlled 1/1 orbit of the rig's own model (X** on Pi2, one impact a
    period): the wrong model's corrections hold the motion there, farther off than the
    right model does. Measured: within 0.008 of X** (dimensionless) over the last 10 of
    40 periods, one impact in 8 of them (none in 2: the held motion sits nearer grazing,
    impact velocity 0.0049 against the orbit's 0.0144); at 200 periods (grazing analyze) 3.6e-5 m from the
    orbit at the end and a spread of 4.1e-5 m, against 1.4e-7 m and 4.9e-7 m with the
    right model: its estimator's fit fails every period (model_resets), as the χ² test
    of its own model says.

    The hold is the model's where its corrections act: the samples judged are those of
    the last 27 periods whose previous SETTLE sections all acted in time (every one on
    a machine that keeps the budget; a stall of the machine that misses a deadline
    takes the SETTLE after it out), at least 10 of them."""
    rig, res, m = scene
    p = rig.params()
    pi2 = [(_seconds(msg.header.stamp), msg.position[0], msg.velocity[0])
           for _, msg in m["/oscillator/pi2"]]
    t, x, v = np.array(pi2).T
    dep = np.hypot(x - p.x_ref, v - p.v_ref)
    missed = _missed_sections(rig, m)
    judged = [k for k in range(ON + 10, len(t)) if not any(k - SETTLE <= j < k for j in missed)]
    assert len(judged) >= 10, (missed, judged)
    assert dep[judged].max() < 0.03, (missed, dep)
    hits = np.array([_seconds(msg.header.stamp) for _, msg in m["/oscillator/impact"]])
    per = [int(((hits > t[k - 1]) & (hits <= t[k])).sum()) for k in judged[-10:]]
    print("departure", dep[judged].max(), "impacts", per, "missed", missed)
    assert set(per) <= {0, 1} and sum(per) >= 5, per      # no chatter, mostly 1/1
    ctl = _summary(res.logs["controller_node"], r"\b(model_resets|answered)=(\d+)")
    assert ctl["model_resets"] >= PERIODS - ON - 2       # the wrong model's fit fails


def test_the_missed_sections_are_read_from_the_rigs_applied_records():
    """_missed_sections on records built by hand: the flagged ones, by section index."""
    from types import SimpleNamespace as NS

    rig = NS(forcing_period=0.075)
    rec = lambda ty, z: (0, NS(wrench=NS(torque=NS(y=ty), force=NS(z=z))))
    m = {"/rig/applied": [rec(1000.044, 2.0), rec(1000.119, 0.0), rec(1000.569, 1.0),
                          rec(1001.693, 1.0), rec(1001.768, 0.0)],
         "/rig/phase": [(0, NS(header=NS(stamp=NS(sec=1000, nanosec=44_000_000))))]}
    assert _missed_sections(rig, m) == [0, 7, 22]


MASSES = Path(__file__).resolve().parents[1] / "config" / "rigs" / "two_mass_beam.yaml"
#: The two-mass scene: as tests/test_rig_masses_scene.py's (the sensor at 500 Hz with
#: 0.2 um of noise), at a quarter of physical speed: 12 periods of 0.25 s take 12 s.
M_PERIODS, M_ON = 12, 3


def _analyze(bag, out, by_stamp=False):
    """(report.json's bag entry, report.md) of ``grazing analyze``; ``by_stamp``: as
    before rig_acts.py read a rig of n masses (no rig/applied read, the answers matched
    to the samples by their stamps)."""
    from grazing_control.recordings import analyze as module

    with pytest.MonkeyPatch.context() as mp:
        if by_stamp:
            mp.setattr(module, "_acts", lambda bag, data, rig: None)
        report = module.analyze([bag], out, figures=False)
    return report["bags"][0], report["markdown"]


@pytest.fixture(scope="module")
def two_mass(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig_wrong_model_masses")
    doc = yaml.safe_load(MASSES.read_text())
    doc["sensor"].update(noise="0.2 um", rate="500 Hz")
    path = out / "two_mass_quiet.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert doc["damping_ratios"] == [0.01, 0.02]
    wrong = out / "wrong.yaml"
    wrong.write_text(yaml.safe_dump({**doc, "damping_ratios": [0.0095, 0.02]}))
    rig, res, _ = run_rig_scene(out, path, M_PERIODS, M_ON, (), {"rig_file": str(wrong)},
                                slow=SLOW)
    return rig, res, out


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_a_two_mass_rigs_bag_off_its_grid_is_read_by_what_acted(two_mass):
    """Measured (2026-11-29, 40 periods, control from 3, the same rigs; grazing analyze):
    before, the answers matched by their stamps were one section off (answer time p50
    493 ms, half a second of wall time a period), 1 late answer where the rig counted
    none, and no model (measured numbers only; with the rig's model the check departed
    by 0.36, 36 of 39 periods above 1e-12); read by what acted: answer time p50 -6.5 ms
    (the right model's scene: -8.1 ms), late 0 as the rig's, the model check 1.1e-16."""
    rig, res, out = two_mass
    entry, text = _analyze(res.bag_dir, out / "analyze")
    n = entry["scenes"][0]
    T = rig.forcing_period
    off = entry["rig_commands_off_grid"]
    assert off["commands"] >= M_PERIODS - 1
    assert 1e-6 * T < -off["median_offset_s"] < 1e-4, off          # 42 us early
    assert "the controller's sections are" in text and "its model is not the rig's" in text
    assert "the model: the simulated rig's (grazing/rig, n = 2)" in text
    mc = n["model_check"]           # re-integrated with what acted, at its starts
    assert mc["max_departure"] < 1e-12 and mc["failed"] == 0, mc
    assert mc["periods"] == M_PERIODS - 1
    assert mc["pulses_at_recorded_starts"] >= M_PERIODS - 2, mc    # not section 0's
    rt = n["realtime"]
    sim = _summary(res.logs["sim_node"], r"\b(late|in_time|predicted|nothing)=(\d+)")
    assert rt["late_answers"] == sim["late"], (rt, sim)            # the simulator's count
    assert rt["rig_applied"]["predicted"] == sim["predicted"], (rt, sim)
    assert rt["rig_applied"]["in_time"] == sim["in_time"] >= M_PERIODS - 3, (rt, sim)
    # answered within the budget in wall time (5 ms x SLOW), as the right model's are
    assert abs(rt["answer_time_ms"]["p50"]) < 5.0 * SLOW, rt["answer_time_ms"]
    assert n["corrections"]["max_abs"] > 0.0                        # the corrections act
    before, before_text = _analyze(res.bag_dir, out / "by_stamp", by_stamp=True)
    assert "off the rig's" not in before_text
    b = before["scenes"][0]
    assert b["model_check"]["max_departure"] > 1e-4, b["model_check"]   # a section off
    assert "rig_commands_off_grid" not in before
    assert b["realtime"]["answer_time_ms"]["p50"] > 0.5 * T * SLOW * 1e3   # a section off


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_two_mass_scene_by_stamp_departs_from_the_rigs_model(two_mass):
    """The same bag matched by stamps, re-integrated by the rig's own model: each
    correction a section off, at the rig's own instant, departs far from rounding."""
    from grazing_control.recordings.analysis import ndof_scene_numbers, ndof_setup
    from grazing_control.recordings.scenes import load

    rig, res, _ = two_mass
    data = load(res.bag_dir)
    n = ndof_scene_numbers(data.scenes[0], ndof_setup(data, rig))
    assert n["model_check"]["max_departure"] > 1e-4, n["model_check"]

"""`grazing replay` and the analysis of bags recorded here through the real nodes.

Replay through a real controller_node (over Fast DDS, a domain of its own): the
reference bag's own gains give bit-identical corrections; other gains give exactly what
Eq. 28 computes with them on the recorded samples. Replay through sim_node in lockstep
reproduces a lockstep bag bit for bit, and a realtime one departs (reported with why).
A realtime bag and a bag whose recorder was SIGKILLed are recorded in the tests.
"""

import os
import signal
import time

import numpy as np
import pytest

pytest.importorskip("rclpy")

from grazing_control import cli
from grazing_control.ros import launcher                       # noqa: E402
from grazing_control.recordings.analyze import analyze            # noqa: E402
from grazing_control.recordings.replay import replay_controller, replay_simulator  # noqa: E402
from grazing_control.recordings.numbers import realtime_numbers, resolve_setup  # noqa: E402
from grazing_control.recordings.scenes import load                # noqa: E402
from grazing_control.oscillator.control import Gains, correction          # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1, write_controller_yaml  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams             # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate                   # noqa: E402

from bagtools_helpers import BAGS                               # noqa: E402
# a claimed domain (launcher.claim_domain): a random one collided with a scene on
# the other worker (2 reruns of the replays in a fresh clone)
from test_closed_loop import NO_WATCHDOG, new_domain              # noqa: E402




def test_replay_with_the_recorded_gains_is_bit_identical_through_both_nodes(tmp_path):
    res = replay_controller(BAGS / "scene_9e-6", tmp_path / "ctl", domain_id=new_domain())
    cmp_ = res["comparison"]
    assert res["answers"] == 1300 and cmp_["answered_in_both"] == 1300
    assert cmp_["all_bit_identical"] and cmp_["bit_identical"] == 1300
    assert res["gains_source"] == "the bag's parameter record (controller_node)"
    # the replay bag is itself analysable: the controller's record is in it
    data = load(tmp_path / "ctl")
    assert data.parameters["nodes"]["controller_node"][0]["enable_after"] == 1000
    sim = replay_simulator(BAGS / "scene_9e-6", tmp_path / "sim", domain_id=new_domain())
    assert sim["samples_replayed"] == 1300 and sim["stamps_equal"]
    # replay bags carry rosbag2's offered_qos_profiles like the recorder's (they had none)
    from mcap.reader import make_reader
    for bag in ("ctl", "sim"):
        with open(next((tmp_path / bag).glob("*.mcap")), "rb") as fh:
            channels = make_reader(fh).get_summary().channels.values()
        for ch in channels:
            assert "reliability: reliable" in ch.metadata["offered_qos_profiles"], (bag, ch)
    assert sim["bit_identical_samples"] == 1300 and sim["max_departure"] == 0.0


def test_replay_of_a_bag_without_parameter_record_uses_the_default_gains_it_shows(tmp_path):
    """A bag without the nodes' parameter record (rewritten from the reference bag with
    its samples, corrections and impacts only): the gains inferred from its corrections
    match config/controller.yaml's, which then answer bit for bit."""
    from bagtools_helpers import scene_messages, write_rosbags

    bag = write_rosbags(tmp_path / "plain", scene_messages(BAGS / "scene_5e-6")[0])
    res = replay_controller(bag, tmp_path / "ctl", domain_id=new_domain())
    assert "config/controller.yaml (matches the recording)" in res["gains_source"]
    assert res["comparison"]["all_bit_identical"] and res["comparison"]["bit_identical"] == 1300


def test_replay_without_a_record_uses_the_model_options_for_x_star_star(tmp_path):
    """A scene of another model (r 0.75, zeta 0.02, Delta d -6e-6, c2 -0.6) rewritten
    without its parameter record: replayed with those model options, the controller's X**
    and gains are the run's, not config/controller.yaml's, and every answer is the
    recorded one bit for bit (it differed by up to 6.2e-4, issue 19 §4)."""
    from bagtools_helpers import scene_messages, write_rosbags

    p = OscillatorParams(r=0.75, zeta=0.02, delta_d=-6e-6)
    gains = Gains(degenerate_c1(p, -0.6), -0.6)
    write_controller_yaml(tmp_path / "ctl.yaml", p, gains)
    res = launcher.run({"r": 0.75, "zeta": 0.02, "delta_d": -6e-6}, tmp_path / "ctl.yaml",
                       tmp_path / "bag", 300, enable_after=100, domain_id=new_domain())
    assert res.ok, res
    bag = write_rosbags(tmp_path / "norec", scene_messages(tmp_path / "bag")[0])
    out = replay_controller(bag, tmp_path / "re", domain_id=new_domain(),
                            options={"r": 0.75, "zeta": 0.02, "delta_d": -6e-6, "c2": -0.6})
    assert any("x_ref" in n and "this run's model" in n for n in out["notes"])
    cmp_ = out["comparison"]
    assert cmp_["all_bit_identical"] and cmp_["bit_identical"] == 300, cmp_


def test_replay_with_other_gains_gives_what_eq28_commands(tmp_path, capsys):
    p = OscillatorParams(delta_d=-5e-6)
    gains = Gains(degenerate_c1(p, -0.5), -0.5)
    yaml_path = tmp_path / "c05.yaml"
    write_controller_yaml(yaml_path, p, gains)
    code = cli.main(["replay", str(BAGS / "scene_5e-6"), "--bag", str(tmp_path / "out"),
                     "--controller-params", str(yaml_path), "--no-sim",
                     "--domain-id", str(new_domain())])
    text = capsys.readouterr().out
    assert code == 0
    assert "300 of 1300 answers differ" in text and "| after the original switch-on | 300 |" in text
    assert "|λ|max = 0.4376" in text and "(stable)" in text
    new = load(tmp_path / "out").scenes[0]
    orig = load(BAGS / "scene_5e-6").scenes[0].scene
    want = [0.0] * 1000 + [correction(gains, x, v, p.x_ref, p.v_ref) for x, v in orig.pi2[1000:]]
    assert new.answered.all() and new.scene.correction.tolist() == want


@pytest.mark.realtime
def test_realtime_bag_recorded_here_analysed_and_replayed(tmp_path):
    bag = tmp_path / "rt"
    # x250: the 60 periods take 2.3 s of wall time (x100: 5.7 s in the realtime group);
    # its delay check read a departure of 6.9e-6 against 1.3e-2 for kicks on Pi2 (x100:
    # 1.6e-6 against 6.4e-4), the bound a tenth
    n, on, scale = 60, 30, 250.0
    res = launcher.run(None, None, bag, n, domain_id=new_domain(), timeout=90,
                       sim_overrides={"mode": "realtime", "time_scale": scale,
                                      "delta_d": -5e-6, **NO_WATCHDOG},
                       controller_overrides={"enable_after": on}, log_dir=tmp_path / "logs")
    assert res.ok, res
    rep = analyze([bag], tmp_path / "report")["bags"][0]
    assert rep["parameter_record"] and rep["setup"]["mode"] == "realtime"
    assert rep["setup"]["sources"]["delta_d"] == "parameter record"
    assert rep["setup"]["time_scale"] == scale
    rt = rep["scenes"][0]["realtime"]
    # one latency message per applied correction: all of them unless the loaded machine
    # delayed an answer past the next two samples (the simulator then ignores it)
    assert n - 5 <= rt["latency_ms"]["n"] <= n and rt["latency_ms"]["p50"] > 0
    assert rt["answer_time_ms"]["n"] == n and rt["missing_answers"] == 0
    assert rt["sample_lag_ms"]["n"] == n
    dc = rt["delay_check"]
    if rt["latency_ms"]["n"] == n:    # every correction applied: the delays explain the run
        # (to within the sample lag, which the bag records only in wall time: a tenth of
        # the departure of the kicks-on-Pi2 model at most; typically 1-3 %)
        assert dc["median_departure"] < 1e-1 * dc["median_departure_kicks_on_pi2"], dc
    else:
        assert dc is None
    assert (tmp_path / "report" / "rt.png").is_file()
    assert "realtime latency" in (tmp_path / "report" / "report.md").read_text()
    if dc is not None:
        # sample 0 published 3 ms late (a preempted simulator; its correction is 0): the
        # others' lags relative to it are negative, the delays still explain the run
        data = load(bag)
        setup = resolve_setup(data, {})
        sd = data.scenes[0]
        sd.pi2_pub_ns[0] += 3_000_000
        late = realtime_numbers(sd, setup)["delay_check"]
        assert late["median_departure"] < 1e-1 * dc["median_departure_kicks_on_pi2"], late
        assert late["fitted_first_sample_lag_ms"] >= 3.0 - 1e-3
    ctl = replay_controller(bag, tmp_path / "ctl", domain_id=new_domain())
    assert ctl["gains_source"].startswith("the bag's parameter record")
    assert ctl["comparison"]["all_bit_identical"]
    sim = replay_simulator(bag, tmp_path / "sim", domain_id=new_domain())
    assert sim["samples_replayed"] == n and sim["stamps_equal"]
    # corrections acted at their arrival in realtime: the lockstep replay departs
    assert sim["first_sample_above_1e-12"] is not None and "arrival" in sim["why"]


@pytest.mark.parametrize("plant", [
    {"force_limit": 0.5, "actuator_bandwidth": 2.0},
    {"contact": "kelvin_voigt", "contact_stiffness": 1e3, "contact_damping": 0.5,
     "friction": 1e-4, "actuator_bandwidth": 2.0}], ids=["actuator", "compliant_stop"])
def test_a_pulse_scene_through_the_actuator_is_replayed_bit_for_bit(tmp_path, plant):
    """The simulator's replay takes how a correction acted and what the stop is from the
    record: the pulse, its force limit and the actuator's lag (without them a pulse
    scene's replay departed by 1.6e-3 at its first correction), the compliant stop and
    the friction (without them the replay ran the rigid wall); the compliant stop behind
    the actuator (its force in the stop's flow, docs/theory_contact.md §21)."""
    p, delay = OscillatorParams(delta_d=-5e-6), 3.0
    write_controller_yaml(tmp_path / "ctl.yaml", p, Gains(degenerate_c1(p, -1.0, delay), -1.0,
                                                          delay))
    res = launcher.run(None, str(tmp_path / "ctl.yaml"), tmp_path / "bag", 40,
                       domain_id=new_domain(), timeout=90,
                       sim_overrides={"delta_d": -5e-6, "actuation_delay": delay,
                                      "pulse_width": 0.1, **plant},
                       controller_overrides={"enable_after": 10}, log_dir=tmp_path / "logs")
    assert res.ok, res
    sim = replay_simulator(tmp_path / "bag", tmp_path / "sim", domain_id=new_domain())
    assert sim["samples_replayed"] == 40 and sim["stamps_equal"]
    assert sim["bit_identical_samples"] == 40 and sim["max_departure"] == 0.0, sim


def test_sigkilled_recorder_leaves_a_bag_the_analysis_reads(tmp_path):
    """kill -9 of the recorder: no summary, no metadata.yaml; the analysis reads every
    complete chunk, says so, and the samples equal the core's simulation bit for bit."""
    domain, n, on = new_domain(), 150, 100
    bag = tmp_path / "killed"
    rec = launcher.start_node(launcher.RECORDER_MODULE, (),
                              {"output": str(bag), "chunk_size": 2048}, domain_id=domain,
                              log=tmp_path / "recorder.log")
    try:
        res = launcher.run(None, None, None, n, domain_id=domain, timeout=90,
                           sim_overrides={"wait_for_subscribers": 1, "delta_d": -5e-6},
                           enable_after=on)
        assert res.ok, res
        time.sleep(1.0)
    finally:
        os.kill(rec.pid, signal.SIGKILL)
        rec.wait(10)
    assert not (bag / "metadata.yaml").exists()
    rep = analyze([bag], tmp_path / "report", figures=False)["bags"][0]
    assert not rep["closed_cleanly"]
    assert any("no summary" in s for s in rep["problems"])
    s = rep["scenes"][0]
    assert n // 2 <= s["samples"] <= n
    data = load(bag)
    got = data.scenes[0].scene.pi2
    p = OscillatorParams(delta_d=-5e-6)
    core = simulate(p, len(got), gains=Gains(degenerate_c1(p, -1.0), -1.0), control_after=on)
    assert np.array_equal(got[:on], core.pi2[:on])
    assert np.max(np.abs(got - core.pi2)) < 1e-12


def test_replay_at_the_recorded_rate(tmp_path):
    res = replay_controller(BAGS / "scene_9e-6", tmp_path / "ctl", rate=2.0,
                            domain_id=new_domain())
    assert res["answers"] == 1300 and res["comparison"]["all_bit_identical"]


@pytest.mark.parametrize("argv,message", [
    (["--rate", "0"], "--rate"),
    (["--rate", "nan"], "--rate"),
    (["--domain-id", "999"], "--domain-id"),
    (["--controller-params", "/nonexistent.yaml"], "no such file"),
])
def test_replay_bad_input_one_line_error(tmp_path, capsys, argv, message):
    code = cli.main(["replay", str(BAGS / "scene_5e-6"), "--bag", str(tmp_path / "o")] + argv)
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("grazing: error:") and message in err
    assert err.count("\n") == 1


def test_replay_refuses_a_non_empty_output_and_a_missing_bag(tmp_path, capsys):
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "x").write_text("keep me")
    code = cli.main(["replay", str(BAGS / "scene_5e-6"), "--bag", str(tmp_path / "o"),
                     "--no-sim"])
    err = capsys.readouterr().err
    assert code == 2 and "not an empty directory" in err
    assert (tmp_path / "o" / "x").read_text() == "keep me"
    code = cli.main(["replay", str(tmp_path / "missing"), "--bag", str(tmp_path / "p")])
    err = capsys.readouterr().err
    assert code == 2 and "no such bag" in err and not (tmp_path / "p").exists()

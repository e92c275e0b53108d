"""``grazing rig FILE`` and ``--rig FILE`` on the model's commands (cli/rig.py, docs/rig.md).

* ``grazing rig`` on the issue's lab rig: every number against its own route (the
  design by ``grazing design`` with the numbers given by hand, the SI gains and pulses
  by hand from c1, c2, the predicted spread = ``grazing design``'s position-only noise
  gain x the sensor noise); the measured compute tail; infeasible budgets and slow
  sensors (status 2, one line naming controller.budget or sensor.rate).
* ``--rig`` sets exactly what the numbers given by hand set, command by command, and
  ``grazing design --rig F`` prints what ``grazing design`` with those numbers prints;
  an option the rig sets given too is one line naming both.
* Hostile rig files: thousands of seeded mutations, each one line naming the field,
  through ``grazing rig`` and through ``--rig`` (in-process, the parser built once), a
  few by subprocess.
"""

import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grazing_control.ros.rig_boundary import answer_lead

from grazing_control.cli import commands
from grazing_control.cli.rig import rig_options
from grazing_control.plant.rig import rig_from_dict

from rig_files import HOSTILE_TEXTS, LAB, dump, mutations

ROOT = Path(__file__).resolve().parent.parent
LAB_FILE = ROOT / "config" / "rigs" / "lab_20hz.yaml"


@pytest.fixture
def cli(capsys):
    """main(argv) -> (status, stdout, stderr) (main's parser is built once a process)."""

    def run(*argv):
        try:
            code = commands.main([str(a) for a in argv])
        except SystemExit as exc:        # argparse's own errors
            code = exc.code
        out = capsys.readouterr()
        return code, out.out, out.err
    return run


def _parser():
    """The ``grazing`` parser of main (built once a process: a parse does not change it)."""
    return commands._parser()


def _write(tmp_path, doc, name="rig.yaml"):
    path = tmp_path / name
    path.write_text(dump(doc) if not isinstance(doc, str) else doc, encoding="utf-8")
    return path


def _json(code, out, err):
    assert code == 0, err
    return json.loads(out)


def _by_hand(rig):
    """The options given by hand for ``rig`` (repr: every digit)."""
    p = rig.params()
    return ["--zeta", repr(p.zeta), "--r", repr(p.r), "--omega", repr(p.omega),
            "--pi2-offset", repr(p.pi2_offset)]


# ------------------------------------------------------------------ grazing rig
@pytest.fixture(scope="module")
def lab_report():
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert commands.main(["rig", str(LAB_FILE), "--json", "--compute-tail", "1e-3"]) == 0
    return json.loads(buf.getvalue())


def test_grazing_rig_says_the_rig_in_si_and_its_model(lab_report):
    r = lab_report
    rig = rig_from_dict(LAB)
    si, sc, dl = r["si"], r["scales"], r["dimensionless"]
    k = 0.5 * (2 * math.pi * 20) ** 2
    assert si["stiffness_N_per_m"] == pytest.approx(k, rel=1e-15)
    assert si["damping_N_s_per_m"] == pytest.approx(2 * 0.01 * math.sqrt(k * 0.5), rel=1e-15)
    assert si["natural_frequency_Hz"] == pytest.approx(20.0, rel=1e-15)
    assert si["forcing_period_s"] == pytest.approx(1 / 13.342666649999167, rel=1e-15)
    assert sc["time_s"] == pytest.approx(1 / (2 * math.pi * 20), rel=1e-15)
    assert sc["length_m"] == pytest.approx(50 / k, rel=1e-15)
    assert sc["velocity_m_per_s"] == pytest.approx(2 * math.pi * 20 * 50 / k, rel=1e-15)
    assert sc["force_N"] == pytest.approx(50.0, rel=1e-14)
    assert dl["omega"] == pytest.approx(2 * math.sqrt(1 - 1e-4) / 3 + 5e-4, rel=1e-15)
    assert dl["delta_d"] == pytest.approx(-5e-6, rel=1e-9)
    assert dl["actuation_delay"] == pytest.approx(5e-3 * 2 * math.pi * 20, rel=1e-15)
    assert dl["time_scale"] == pytest.approx(2 * math.pi * 20, rel=1e-15)
    assert dl["sensor_noise"] == pytest.approx(2e-6 * k / 50, rel=1e-14)
    assert dl["pulse_width"] == pytest.approx(2e-3 * 2 * math.pi * 20, rel=1e-15)
    assert dl["state_period"] == pytest.approx(2 * math.pi * 20 / 2000, rel=1e-15)
    assert dl["samples_per_period"] == 150
    assert r["grazing"]["gap_at_grazing_m"] == pytest.approx(dl["d_star"] * 50 / k, rel=1e-15)
    assert r["grazing"]["gap_minus_grazing_m"] == pytest.approx(-5e-6 * 50 / k, rel=1e-8)
    assert r["grazing"]["gap_m"] == pytest.approx(rig.gap, rel=1e-15)


def test_grazing_rig_designs_as_grazing_design_with_the_numbers_by_hand(lab_report, cli):
    r = lab_report
    rig = rig_from_dict(LAB)
    p = rig.params()
    delay = rig.dimensionless()["actuation_delay"]
    # the rig's controller answers answer_lead = budget - w/2 = 4 ms before the section's
    # last sample: the estimate's covariance without the samples of that stretch
    lead = 4e-3 * 2 * math.pi * 20
    hand = _by_hand(rig) + ["--delay", repr(delay), "--delta-d", repr(p.delta_d),
                            "--sensor-rate", "150", "--sensor-lead", repr(lead), "--json"]
    opt = _json(*cli("design", *hand, "--optimize", "noise"))
    de = r["design"]
    assert "least noise gain" in de["c2_from"]
    assert (de["c1"], de["c2"]) == (opt["c1"], opt["c2"])
    assert de["actuation_delay"] == delay
    # SI gains from c1, c2 by hand
    wn, m, w = 2 * math.pi * 20, 0.5, 2e-3
    assert de["si"]["c1_per_s"] == pytest.approx(de["c1"] * wn, rel=1e-15)
    assert de["si"]["force_gain_position_N_per_m"] == pytest.approx(m * de["c1"] * wn / w, rel=1e-14)
    assert de["si"]["force_gain_velocity_N_s_per_m"] == pytest.approx(m * de["c2"] / w, rel=1e-14)
    # the pulses: 1 um -> dv = c1 omega_n 1e-6 m/s, F = m dv / w; 1 mm/s -> dv = c2 1e-3
    co = r["corrections"]
    assert co["for_position_error"]["velocity_m_per_s"] == pytest.approx(de["c1"] * wn * 1e-6, rel=1e-13)
    assert co["for_position_error"]["force_N"] == pytest.approx(m * de["c1"] * wn * 1e-6 / w, rel=1e-13)
    assert co["for_velocity_error"]["velocity_m_per_s"] == pytest.approx(de["c2"] * 1e-3, rel=1e-13)
    assert co["for_velocity_error"]["force_N"] == pytest.approx(m * de["c2"] * 1e-3 / w, rel=1e-13)
    orbit = co["at_controlled_orbit"]
    z = orbit["pi2_deviation"]
    dv = (de["c1"] * z[0] + de["c2"] * z[1]) * wn * 50 / (0.5 * wn * wn)
    assert orbit["velocity_m_per_s"] == pytest.approx(dv, rel=1e-12)
    assert orbit["within_force_limit"] is (abs(orbit["force_N"]) <= 20.0)
    # the predicted spread: design's position-only gain x the sensor noise (exactly)
    at_c2 = _json(*cli("design", *hand, "--c2", repr(de["c2"])))
    sp = r["predicted_spread"]
    assert sp["noise_gain_position_only"] == at_c2["noise_gain_position_only"]
    assert sp["spread_m"] == at_c2["noise_gain_position_only"] * rig.sensor.noise
    assert at_c2["position_only_sensor"] == {"samples_per_period": 150, "estimator": "model",
                                             "lead": pytest.approx(lead, rel=1e-15)}
    assert "nearest integer, 150" in sp["note"]
    # the timing budget with the given tail
    ti = r["timing"]
    assert ti["feasible"] and ti["estimate_from"] == "given by --compute-tail"
    assert ti["needed_s"] == pytest.approx(0.5e-3 + 0.5e-3 + 1e-3, rel=1e-12)
    assert ti["available_s"] == pytest.approx(4e-3, rel=1e-12)


def test_grazing_rig_with_c2_and_as_text(cli):
    code, out, err = cli("rig", LAB_FILE, "--c2", "-1", "--compute-tail", "0.002")
    assert code == 0, err
    for line in ("rig ", "scales", "dimensionless model", "grazing", "design for the actuation "
                 "delay 0.628319 (c2 from --c2)", "c2 = -1  (admissible",
                 "1 um position error", "1 mm/s velocity error", "predicted Pi2 spread",
                 "timing budget", "estimate 2 ms", "given by --compute-tail"):
        assert line in out, line
    code, out, err = cli("rig", LAB_FILE, "--c2", "-1", "--optimize", "noise")
    assert code == 2 and err.count("\n") == 1 and "--c2 and --optimize" in err


def test_grazing_rig_measures_the_estimate_tail(tmp_path, cli):
    """The budgeted tail is the estimate's CPU-time p99 (the same on an idle and a loaded
    machine), the wall-clock p99 with --tail wall; both are reported."""
    doc = copy.deepcopy(LAB)
    doc["controller"]["budget"] = "50 ms"      # room for a loaded machine's wall tail
    code, out, err = cli("rig", _write(tmp_path, doc), "--json", "--c2", "-1", "--runs", "20")
    r = _json(code, out, err)
    m = r["timing"]["measured"]
    assert (m["estimator"], m["samples_per_period"], m["runs"]) == ("model", 150, 20)
    assert r["timing"]["estimate_s"] == m["cpu_p99_s"] > 0 and m["p99_s"] > 0
    assert r["timing"]["estimate_from"].startswith("CPU-time p99 of 20 measured here; wall p99 ")
    code, out, err = cli("rig", _write(tmp_path, doc), "--json", "--c2", "-1", "--runs", "20",
                         "--tail", "wall")
    if code == 2:       # a machine so loaded that the wall p99 passed 49 ms: said, as it must be
        assert err.startswith("grazing: error: controller.budget=50 ms is infeasible")
        assert "wall-clock p99 of 20 measured here" in err and err.count("\n") == 1
        return
    r = _json(code, out, err)
    assert r["timing"]["estimate_s"] == r["timing"]["measured"]["p99_s"]
    assert r["timing"]["estimate_from"].startswith("wall-clock p99 of 20 measured here at load")


@pytest.mark.parametrize("budget,width,latency,tail,field,needed", [
    ("1.2 ms", "2 ms", "0.5 ms", "0", "controller.budget=1.2 ms is infeasible",
     "controller.budget >= 2 ms"),
    ("2 ms", "2 ms", "0 s", "0.0008", "sensor.rate=2000 Hz is too slow",
     "sensor.rate >= 5000 Hz"),
])
def test_an_infeasible_budget_is_status_2_and_one_line(tmp_path, cli, budget, width, latency,
                                                        tail, field, needed):
    doc = copy.deepcopy(LAB)
    doc["controller"]["budget"], doc["actuator"]["pulse_width"] = budget, width
    doc["sensor"]["latency"] = latency
    code, out, err = cli("rig", _write(tmp_path, doc), "--compute-tail", tail, "--c2", "-1")
    assert code == 2 and out == "" and err.count("\n") == 1
    assert err.startswith(f"grazing: error: {field}") and needed in err


def test_an_infeasible_budget_by_subprocess(tmp_path):
    doc = copy.deepcopy(LAB)
    doc["controller"]["budget"] = "1.2 ms"
    run = subprocess.run([sys.executable, "-m", "grazing_control.cli", "rig",
                          str(_write(tmp_path, doc)), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and run.stdout == "" and run.stderr.count("\n") == 1
    assert run.stderr.startswith("grazing: error: controller.budget=1.2 ms is infeasible")
    assert "measured here" in run.stderr and "Traceback" not in run.stderr


def test_a_rig_beyond_grazing_has_no_spread_and_designs_at_the_studys_delta_d(tmp_path, cli):
    doc = copy.deepcopy(LAB)
    doc["gap"] = "11.5 mm"                      # beyond d* l = 11.408 mm: no impacts
    r = _json(*cli("rig", _write(tmp_path, doc), "--json", "--compute-tail", "0"))
    assert r["dimensionless"]["delta_d"] > 0
    assert r["predicted_spread"]["spread_m"] is None
    assert "beyond grazing" in r["predicted_spread"]["note"]
    assert "Delta d = -5e-6" in r["design"]["c2_from"]
    assert "at_controlled_orbit" not in r["corrections"]


# ------------------------------------------------------------------ --rig on the commands
_COMMANDS = [
    ["design", "--c2", "-1"],
    ["design", "--optimize", "noise"],
    ["orbit"],
    ["orbit", "--c2", "-1"],
    ["continue", "--from", "-1e-4", "--to", "-1e-6"],
    ["continue", "--from", "-1e-4", "--to", "-1e-6", "--c2", "-1"],
    ["continue2", "--parameter", "r"],
    ["simulate", "--periods", "5"],
    ["simulate", "--periods", "5", "--c2", "-1"],
    ["sweep", "--grid", "c2=-1.5:-0.5:3"],
    ["sweep", "--grid", "delta_d=-1e-4:-1e-6:3"],
    ["basins", "--c2", "-1"],
    ["robustness", "delay"],
    ["robustness", "faults"],
    ["robustness", "noise"],
    ["robustness", "model"],
]


def _parsed(argv):
    args = _parser().parse_args(argv)
    from grazing_control.cli.rig import apply_rig

    apply_rig(args, argv)
    return args


@pytest.mark.parametrize("argv", _COMMANDS, ids=lambda a: " ".join(a))
def test_rig_sets_what_the_numbers_by_hand_set(argv):
    rig = rig_from_dict(LAB)
    p = rig.params()
    delay = rig.dimensionless()["actuation_delay"]
    with_rig = vars(_parsed(argv + ["--rig", str(LAB_FILE)]))
    hand = list(argv) + _by_hand(rig)
    command, c2 = argv[0], "--c2" in argv
    if command == "design":
        hand += ["--delta-d", repr(p.delta_d), "--delay", repr(delay), "--sensor-rate", "150",
                 "--sensor-lead", repr(answer_lead(rig))]
    elif command in ("orbit", "simulate", "basins"):
        hand += ["--delta-d", repr(p.delta_d)]
    elif command == "robustness" and argv[1] != "model":
        hand += ["--delta-d", repr(p.delta_d)]
    if c2 and command not in ("design", "sweep"):
        hand += ["--delay", repr(delay)]
    if command == "robustness" and argv[1] == "noise":
        hand += ["--delay", repr(delay)]
    by_hand = vars(_parsed(hand))
    if command == "sweep" and "delta_d" not in argv[-1]:
        grid = dict(with_rig.pop("grid"))
        assert grid["delta_d"].tolist() == [p.delta_d]       # the rig's Delta d, one point
        assert [n for n, _ in by_hand.pop("grid")] == ["c2"]
    else:
        with_rig["grid"] = [(n, list(v)) for n, v in with_rig.get("grid", [])]
        by_hand["grid"] = [(n, list(v)) for n, v in by_hand.get("grid", [])]
    with_rig.pop("func"), by_hand.pop("func")
    assert with_rig == by_hand


def test_design_with_rig_prints_what_design_with_the_numbers_prints(cli):
    rig = rig_from_dict(LAB)
    p = rig.params()
    hand = _by_hand(rig) + ["--delta-d", repr(p.delta_d), "--delay",
                            repr(rig.dimensionless()["actuation_delay"]), "--sensor-rate", "150",
                            "--sensor-lead", repr(answer_lead(rig))]
    for extra in (["--c2", "-1"], ["--c2", "0.1", "--estimator", "arc"]):
        a = _json(*cli("design", "--rig", LAB_FILE, "--json", *extra))
        b = _json(*cli("design", *hand, "--json", *extra))
        a.pop("seconds"), b.pop("seconds")
        assert a == b
    code, text_a, _ = cli("design", "--rig", LAB_FILE, "--c2", "-1")
    code, text_b, _ = cli("design", *hand, "--c2", "-1")
    strip = [ln for ln in text_a.splitlines() if "method" not in ln]
    assert strip == [ln for ln in text_b.splitlines() if "method" not in ln]


def test_orbit_and_simulate_with_rig_run_at_the_rigs_delta_d(cli):
    rig = rig_from_dict(LAB)
    a = _json(*cli("orbit", "--rig", LAB_FILE, "--c2", "-1", "--json"))
    assert a["delta_d"] == rig.params().delta_d
    assert a["actuation_delay"] == rig.dimensionless()["actuation_delay"]
    s = _json(*cli("simulate", "--rig", LAB_FILE, "--periods", "4", "--json"))
    assert s["impacts_per_period"] == [1, 1, 1, 1]
    code, out, err = cli("orbit")
    assert code == 2 and "--delta-d" in err and err.count("\n") == 1


@pytest.mark.parametrize("argv,named", [
    (["design", "--c2", "-1", "--zeta", "0.02"], "--zeta"),
    (["design", "--c2", "-1", "--delay", "0.1"], "--delay"),
    (["design", "--c2", "-1", "--sensor-rate", "100"], "--sensor-rate"),
    (["design", "--c2", "-1", "--delta-d", "-1e-6"], "--delta-d"),
    (["orbit", "--delta-d", "-1e-6"], "--delta-d"),
    (["orbit", "--c2", "-1", "--delay", "0"], "--delay"),
    (["simulate", "--periods", "3", "--omega=0.7"], "--omega"),
    (["continue", "--from", "-1e-4", "--to", "-1e-6", "--r", "0.5"], "--r"),
    (["basins", "--pi2-offset", "1"], "--pi2-offset"),
    (["robustness", "noise", "--delay", "0.2"], "--delay"),
    (["robustness", "delay", "--delta-d", "-1e-5"], "--delta-d"),
])
def test_an_option_the_rig_sets_given_too_is_one_line_naming_both(cli, argv, named):
    code, out, err = cli(*argv, "--rig", LAB_FILE)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert err.startswith(f"grazing: error: --rig FILE and {named} are both given")


def test_rig_with_params_or_model_is_refused(cli, tmp_path):
    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    zeta: 0.02\n")
    code, _, err = cli("orbit", "--rig", LAB_FILE, "--params", params)
    assert code == 2 and "--rig FILE and --params FILE are both given" in err
    code, _, err = cli("orbit", "--delta-d", "-1e-5", "--rig", LAB_FILE, "--model",
                       ROOT / "config" / "models" / "two_mass_chain.yaml")
    assert code == 2 and "--rig is a 1-DOF option" in err


def test_options_the_rig_leaves_alone_stay_free():
    rig = rig_from_dict(LAB)
    args = _parser().parse_args(["orbit", "--rig", str(LAB_FILE)])
    table = rig_options(rig, args)
    assert set(table) == {"--zeta", "--r", "--omega", "--pi2-offset", "--delta-d"}
    args = _parser().parse_args(["sweep", "--grid", "c2=-1:0:2", "--rig", str(LAB_FILE)])
    assert set(rig_options(rig, args)) == {"--zeta", "--r", "--omega", "--pi2-offset"}


# ------------------------------------------------------------------ hostile files
_ROUTES = [["rig", "{}", "--compute-tail", "0"], ["design", "--c2", "-1", "--rig", "{}"],
           ["orbit", "--rig", "{}"], ["simulate", "--periods", "1", "--rig", "{}"],
           ["continue", "--from", "-1e-4", "--to", "-1e-5", "--rig", "{}"],
           ["continue2", "--rig", "{}"], ["sweep", "--grid", "c2=-1:0:2", "--rig", "{}"],
           ["basins", "--rig", "{}"], ["robustness", "noise", "--rig", "{}"]]


def test_thousands_of_mutated_rig_files_are_each_one_line_naming_the_field(tmp_path, cli):
    cases = mutations(seed=28, count=3000)
    kinds = set()
    for i, (what, doc, named) in enumerate(cases):
        path = _write(tmp_path, doc, f"m{i % 7}.yaml")
        route = _ROUTES[i % len(_ROUTES)]
        code, out, err = cli(*[a.replace("{}", str(path)) for a in route])
        assert code == 2 and out == "", (what, doc, err)
        assert err.count("\n") == 1 and "Traceback" not in err, (what, err)
        assert err.startswith("grazing: error: " + ("" if route[0] == "rig" else "--rig ")), err
        assert str(path) in err and named in err, (what, named, err)
        kinds.add(what.split(":")[0])
    assert kinds == {"bad", "missing", "unknown", "number", "type", "structure"}


@pytest.mark.parametrize("text,why", HOSTILE_TEXTS)
def test_files_that_are_not_rig_files_are_one_line(tmp_path, cli, text, why):
    path = tmp_path / "rig.yaml"
    path.write_bytes(text.encode("latin-1") if "\xff" in text else text.encode())
    for route in (_ROUTES[0], _ROUTES[2]):
        code, out, err = cli(*[a.replace("{}", str(path)) for a in route])
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert str(path) in err and "Traceback" not in err
        if why:
            assert why in err


def test_a_few_hostile_files_by_subprocess(tmp_path):
    cases = mutations(seed=7, count=4)
    for i, (what, doc, named) in enumerate(cases):
        path = _write(tmp_path, doc, f"s{i}.yaml")
        argv = ["rig", str(path)] if i % 2 == 0 else ["orbit", "--rig", str(path)]
        run = subprocess.run([sys.executable, "-m", "grazing_control.cli", *argv],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 2 and run.stdout == "", (what, run.stderr)
        assert run.stderr.count("\n") == 1 and named in run.stderr, (what, run.stderr)


def test_the_mutations_are_valid_but_for_the_mutation():
    """The lab rig itself loads: every refusal above is the mutation's."""
    assert rig_from_dict(copy.deepcopy(LAB)).mass == 0.5
    assert np.isfinite(rig_from_dict(LAB).params().delta_d)


def test_the_predicted_spread_is_what_the_closed_loop_gives(lab_report):
    """The reference of the rig scene: the design's position-only noise gain x sigma
    against the exact closed loop on the stream as the rig's controller runs it
    (dynamics.estimation.stream.simulate_stream: the model filter at 150 samples per period
    answering answer_lead = 4 ms before the section's last sample, the 2 ms pulse in the
    plant and in the model), 1200 periods after 300 of transient, about the pulse
    loop's orbit. The prediction left out the lead until 2026-11-28 (0.218 x sigma, and
    the loop with the lead gave 1.2x that); with it 0.252 (docs/rig.md)."""
    from grazing_control.dynamics.simulation.actuation import pulse_orbit
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.estimation.stream import StreamEstimator, simulate_stream
    from grazing_control.oscillator.control import Gains
    from grazing_control.plant.sensor import SensorModel

    rig = rig_from_dict(LAB)
    p, dl = rig.params(), rig.dimensionless()
    c2, delay, sigma = lab_report["design"]["c2"], dl["actuation_delay"], dl["sensor_noise"]
    w, limit = dl["pulse_width"], dl["force_limit"]
    g = Gains(degenerate_c1(p, c2, delay), c2, delay)
    target = pulse_orbit(p, g, w, force_limit=limit).pi2_deviation
    est = StreamEstimator(p, "model", sigma, "stream", p.period / 150, lead=answer_lead(rig),
                          pulse_width=w, force_limit=limit)
    run = simulate_stream(p, g, SensorModel(noise=sigma, velocity=False, seed=1).measure,
                          1500, 150, sigma=sigma, deviation=target, stream_estimator=est,
                          pulse_width=w, force_limit=limit)
    assert run.resets == 0 and np.all(run.impacts_per_period == 1)
    measured = float(np.sqrt(np.mean((run.truth[300:, 0] - target[0]) ** 2))) * rig.scales.length
    predicted = lab_report["predicted_spread"]["spread_m"]
    print(f"measured / predicted {measured / predicted:.4f}")
    assert 0.85 < measured / predicted < 1.1

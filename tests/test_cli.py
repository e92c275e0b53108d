"""The `grazing` command line, run as a real subprocess (``python -m grazing_control.cli``).

Contract (grazing_control/cli/commands.py module docstring and the issue):

* with --json, stdout is exactly one JSON object with the keys of the spec, and the
  values are those of the library calls;
* a user error exits 2 with exactly one line ``grazing: error: ...`` on stderr that
  names the parameter, never a traceback, and nothing on stdout;
* without --json every subcommand prints a human-readable report (design: the
  ``--out`` run below).

All commands run once, concurrently, in a module fixture, each a process forked from one
that has imported numpy, scipy and numba once (tests/cli_forkserver.py; the tests that
start a scene or read a signal run the command itself); the tests then read their
results.

Observed extra keys of ``design --json`` (allowed by the spec): "gamma1", "admissible".
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from grazing_control.dynamics.orbits.continuation import continue_11
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import (admissible_c2, degenerate_c1, evaluate_design,
                                             write_controller_yaml)
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate
from test_closed_loop import new_domain

ROOT = Path(__file__).resolve().parents[1]
P = OscillatorParams()

JSON_CASES = {
    "design": ["design", "--c2", "-1", "--json"],
    "design_outside": ["design", "--c2", "1.5", "--json"],
    "design_actuator": ["design", "--optimize", "noise", "--delay", "3", "--pulse-width",
                        "0.1", "--actuator-bandwidth", "2.0", "--json"],
    "orbit": ["orbit", "--delta-d", "-1e-6", "--json"],
    "orbit_ctrl": ["orbit", "--delta-d", "-1e-6", "--c2", "-1", "--json"],
    "orbit_gains": ["orbit", "--delta-d=-2e-5", "--c1", "0.1", "--c2", "-0.5", "--json"],
    "continue": ["continue", "--from", "-1e-2", "--to", "-1e-8", "--points", "30", "--json"],
    "continue_ctrl": ["continue", "--from", "-1e-4", "--to", "-1e-10", "--points", "20",
                      "--c2", "-1", "--json"],
    "simulate": ["simulate", "--delta-d", "-5e-6", "--periods", "25", "--json"],
    "scene5": ["simulate", "--delta-d", "-5e-6", "--periods", "1100", "--control-after", "1000",
               "--c2", "-1", "--json"],
    "scene9": ["simulate", "--delta-d", "-9e-6", "--periods", "1100", "--control-after", "1000",
               "--c2", "-1", "--json"],
    "orbit_near": ["orbit", "--delta-d", "-1e-7", "--json"],
    "orbit_near_perturbation": ["orbit", "--delta-d", "-1e-7", "--json", "--method",
                                "perturbation"],
}

HUMAN_CASES = {
    "orbit": (["orbit", "--delta-d", "-1e-6"], ["1/1 orbit", "multipliers"]),
    "continue": (["continue", "--from", "-1e-2", "--to", "-1e-8", "--points", "30"],
                 ["period-doubling", "bifurcations"]),
    "simulate": (["simulate", "--delta-d", "-5e-6", "--periods", "20", "--c2", "-1"],
                 ["impacts per period"]),
}

# (argv, regex naming the parameter)
BAD_CASES = {
    "zeta": (["design", "--c2", "-1", "--zeta", "2"], r"\bzeta\b"),
    "r": (["orbit", "--delta-d", "-1e-6", "--r", "0"], r"(--r\b|\br=)"),
    "omega_negative": (["design", "--c2", "-1", "--omega", "-1"], r"\bomega\b"),
    "omega_nan": (["design", "--c2", "-1", "--omega", "nan"], r"\bomega\b"),
    "delta_d_abc": (["orbit", "--delta-d", "abc"], r"delta[-_]d"),
    "periods_negative": (["simulate", "--delta-d", "-5e-6", "--periods", "-3"], r"\bperiods\b"),
    "pi2_offset": (["design", "--c2", "-1", "--pi2-offset", "7"], r"pi2[-_]offset"),
    "actuator_without_pulse": (["design", "--c2", "-1", "--actuator-bandwidth", "2"],
                               r"pulse_width=0.0 is invalid with an actuator: valid range"),
    "sensor_lead_beyond_T": (["design", "--c2", "-1", "--delta-d", "-5e-6", "--sensor-lead",
                              "1e308"], r"sensor_lead=1e\+308 is invalid: valid range is"),
    "c1_without_c2": (["orbit", "--delta-d", "-1e-6", "--c1", "0.3"], r"\bc1\b"),
    "orbit_positive_delta_d": (["orbit", "--delta-d", "1e-5"], r"delta[-_]d"),
    "continue_positive_start": (["continue", "--from", "1e-3", "--to", "-1e-6"], r"\bstart\b|--from"),
    "continue_points": (["continue", "--from", "-1e-3", "--to", "-1e-6", "--points", "1"],
                        r"\bpoints\b"),
}


def _run(argv, cwd):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "grazing_control.cli", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """Run every command of this module once, a few at a time. Session-scoped: under xdist
    the module's fixture was set up twice in one run (40 s each; the worker tore it down
    after the module's first test), and nothing in it depends on the module's lifetime."""
    tmp = tmp_path_factory.mktemp("cli")
    out_ok = tmp / "ok" / "controller.yaml"
    out_ok.parent.mkdir()
    out_bad = tmp / "bad" / "controller.yaml"
    out_bad.parent.mkdir()
    jobs = {("json", k): v for k, v in JSON_CASES.items()}
    jobs.update({("human", k): v[0] for k, v in HUMAN_CASES.items()})
    jobs.update({("bad", k): v[0] for k, v in BAD_CASES.items()})
    jobs[("out", "ok")] = ["design", "--c2", "-1", "--out", str(out_ok)]
    jobs[("out", "bad")] = ["design", "--c2", "1.5", "--out", str(out_bad)]
    results = _run_forked(jobs, tmp, max(2, min(6, os.cpu_count() or 2)))
    results["paths"] = (out_ok, out_bad)
    return results


def _run_forked(jobs, cwd, workers):
    """{key: CompletedProcess} of ``python -m grazing_control.cli ARGV`` for each job, each
    a process forked from one that has imported the libraries once
    (tests/cli_forkserver.py: ~1.5 s of imports per process, 29 processes; the other
    tests here run the command itself, ``_run``)."""
    keys = list(jobs)
    lines = []
    for i, key in enumerate(keys):
        lines.append(json.dumps({"argv": jobs[key], "cwd": str(cwd),
                                 "stdout": str(cwd / f"job{i}.out"),
                                 "stderr": str(cwd / f"job{i}.err")}))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    server = subprocess.run([sys.executable, str(Path(__file__).with_name("cli_forkserver.py")),
                             str(workers)], input="\n".join(lines) + "\n", env=env,
                            capture_output=True, text=True, timeout=120 * len(keys) / workers)
    assert server.returncode == 0, server.stderr
    codes = {}
    for line in server.stdout.splitlines():
        answer = json.loads(line)
        codes[answer["job"]] = answer["returncode"]
    assert sorted(codes) == list(range(len(keys))), server.stdout
    return {key: subprocess.CompletedProcess(
        ["grazing_control.cli", *jobs[key]], codes[i], (cwd / f"job{i}.out").read_text(),
        (cwd / f"job{i}.err").read_text()) for i, key in enumerate(keys)}


def _json(runs, name):
    r = runs[("json", name)]
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    obj = json.loads(r.stdout)  # exactly one JSON value, nothing else
    assert isinstance(obj, dict)
    assert r.stdout.count("\n") == 1 and r.stdout.endswith("\n")
    return obj


def _pairs(values):
    return [[float(np.real(z)), float(np.imag(z))] for z in values]


def _close(a, b, rel=1e-12, abs_=0.0):
    np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                               rtol=rel, atol=abs_)


# ------------------------------------------------------------------ --json, design
def test_design_through_an_actuator_gives_the_exact_c1_and_its_predicted_spread(runs):
    """--actuator-bandwidth 2 (3x omega) with --pulse-width 0.1 at --delay 3: c1 is
    (P1)'s for the force profile (dynamics.simulation.actuator.actuated_c1), the ideal design's kept
    as c1_ideal; the loop's orbit through the actuator is stable and its predicted
    spread is actuated_design's."""
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.dynamics.simulation.actuator import Actuator, actuated_c1, actuated_design

    d = _json(runs, "design_actuator")
    q = P.with_(delta_d=-5e-6)
    act = Actuator(0.5, 0.0)
    assert d["c1"] == actuated_c1(q, d["c2"], act, pulse_start(q.period, 3.0, 0.1), 0.1)
    assert d["c1_ideal"] == pytest.approx(degenerate_c1(q, d["c2"], 3.0), rel=1e-14)
    a = d["actuator"]
    assert a["time_constant"] == 0.5 and a["bandwidth_over_omega"] == 2.0 / P.omega
    _, orbit, spread = actuated_design(q, d["c2"], 3.0, 0.1, act)
    assert a["spectral_radius"] == pytest.approx(orbit.spectral_radius, rel=1e-9)
    assert a["spectral_radius"] < 1.0
    assert a["spread"] == pytest.approx(list(spread), rel=1e-9)
    assert 0.0 < a["spread_position_only"][0] < a["spread"][0]


def test_design_json_keys_and_values(runs):
    d = _json(runs, "design")
    required = {"c1", "c2", "x_ref", "v_ref", "admissible_c2", "multipliers_limit"}
    assert required <= set(d)
    g = Gains(degenerate_c1(P, -1.0), -1.0)
    assert d["c2"] == -1.0
    assert d["c1"] == pytest.approx(g.c1, rel=1e-14)
    assert (d["x_ref"], d["v_ref"]) == pytest.approx((P.x_ref, P.v_ref), rel=1e-14, abs=1e-300)
    (lo, hi), = admissible_c2(P)
    assert d["admissible_c2"] == pytest.approx([lo, hi], rel=1e-12)
    point = evaluate_design(P, -1.0)
    _close(d["multipliers_limit"], _pairs(point.multipliers_limit), abs_=1e-15)
    assert d["multipliers_limit"][1] == [0.0, 0.0]  # det G = 0 for c2 = -1
    if "gamma1" in d:
        assert d["gamma1"] == pytest.approx(point.gamma1, rel=1e-12)
    if "admissible" in d:
        assert d["admissible"] is True


def test_design_json_for_a_non_admissible_gain(runs):
    d = _json(runs, "design_outside")
    assert d["c2"] == 1.5
    assert d["c1"] == pytest.approx(degenerate_c1(P, 1.5), rel=1e-14)
    assert max(np.hypot(*np.array(d["multipliers_limit"]).T)) > 1.0
    if "admissible" in d:
        assert d["admissible"] is False


# ------------------------------------------------------------------ --json, orbit
@pytest.mark.parametrize("name, dd, gains", [
    ("orbit", -1e-6, None),
    ("orbit_ctrl", -1e-6, Gains(degenerate_c1(P, -1.0), -1.0)),
    ("orbit_gains", -2e-5, Gains(0.1, -0.5)),
])
def test_orbit_json_keys_and_values(runs, name, dd, gains):
    d = _json(runs, name)
    # the spec's keys, plus the method and its cost in seconds (issue 4: --method)
    assert set(d) == {"delta_d", "impact_phase", "v_minus", "section_pi2", "multipliers", "stable",
                      "method", "seconds", "branch"}  # branch: issue 7
    assert d["branch"] == "grazing"
    assert d["method"] == "exact" and d["seconds"] > 0
    o = orbit_11(P.with_(delta_d=dd), gains)
    assert d["delta_d"] == dd
    assert d["impact_phase"] == pytest.approx(o.impact_phase, rel=1e-13)
    assert d["v_minus"] == pytest.approx(o.v_minus, rel=1e-12)
    _close(d["section_pi2"], list(o.pi2))
    _close(d["multipliers"], _pairs(o.multipliers), abs_=1e-14)
    assert d["stable"] is o.stable
    assert len(d["section_pi2"]) == 2 and all(len(z) == 2 for z in d["multipliers"])


# ------------------------------------------------------------------ --json, continue
@pytest.mark.parametrize("name, args, gains", [
    ("continue", (-1e-2, -1e-8, 30), None),
    ("continue_ctrl", (-1e-4, -1e-10, 20), Gains(degenerate_c1(P, -1.0), -1.0)),
])
def test_continue_json_keys_and_values(runs, name, args, gains):
    d = _json(runs, name)
    assert set(d) == {"branch", "bifurcations"}
    start, stop, n = args
    # the command's points: log-spaced in Delta d, as for a model file (issue 32)
    from grazing_control.dynamics.orbits.one_one import continuation_values

    b = continue_11(P, start, stop, gains, points=n, check=True,
                    values=continuation_values(start, stop, n))
    assert len(d["branch"]) == len(b.points) == n
    for row, pt in zip(d["branch"], b.points):
        assert set(row) == {"delta_d", "v_minus", "multipliers", "stable"}
        assert row["delta_d"] == pytest.approx(pt.delta_d, rel=1e-12)
        assert row["v_minus"] == pytest.approx(pt.v_minus, rel=1e-12)
        _close(row["multipliers"], _pairs(pt.multipliers), abs_=1e-14)
        assert row["stable"] is pt.stable
    assert len(d["bifurcations"]) == len(b.bifurcations)
    for row, bf in zip(d["bifurcations"], b.bifurcations):
        assert set(row) == {"type", "delta_d", "multipliers"}
        assert row["type"] == bf.type
        assert row["delta_d"] == pytest.approx(bf.delta_d, rel=1e-12)
        _close(row["multipliers"], _pairs(bf.multipliers), abs_=1e-12)
    if gains is None:
        assert [row["type"] for row in d["bifurcations"]] == ["period-doubling"]
        assert d["bifurcations"][0]["delta_d"] == pytest.approx(-1.005268252976113e-05, rel=1e-10)


# ------------------------------------------------------------------ --json, simulate
def test_simulate_json_keys_and_values(runs):
    d = _json(runs, "simulate")
    assert set(d) == {"pi2", "impacts_per_period"}
    res = simulate(P.with_(delta_d=-5e-6), 25, gains=None, control_after=None)
    assert len(d["pi2"]) == len(d["impacts_per_period"]) == 25  # one entry per period
    assert all(len(s) == 2 for s in d["pi2"])
    _close(d["pi2"], res.pi2, abs_=1e-15)
    assert d["impacts_per_period"] == res.impacts_per_period.tolist()
    assert d["pi2"][0] == pytest.approx([P.x_ref, P.v_ref], rel=1e-15, abs=1e-300)


@pytest.mark.parametrize("name, dd", [("scene5", -5e-6), ("scene9", -9e-6)])
def test_scene_converges_to_the_controlled_orbit(runs, name, dd):
    d = _json(runs, name)
    counts = d["impacts_per_period"]
    pi2 = np.array(d["pi2"])
    assert len(counts) == len(pi2) == 1100
    assert counts[-50:] == [1] * 50
    g = Gains(degenerate_c1(P, -1.0), -1.0)
    o = orbit_11(P.with_(delta_d=dd), g)
    _close(pi2[-1], o.pi2, rel=0.0, abs_=1e-12)
    # before the switch the uncontrolled motion is not the 1/1 orbit (it is unstable there:
    # the PD is at -1.005e-5), after it the samples settle
    assert np.max(np.abs(pi2[900:1000] - o.pi2)) > 1e-4
    assert np.max(np.abs(pi2[-50:] - o.pi2)) < 1e-12


# ------------------------------------------------------------------ design --out
def test_design_out_writes_the_controller_yaml(runs, tmp_path):
    r = runs[("out", "ok")]
    out_ok, _ = runs["paths"]
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    # human-readable report of `design` (no --json) names the file
    assert "c1" in r.stdout and "admissible" in r.stdout and str(out_ok) in r.stdout
    doc = yaml.safe_load(out_ok.read_text())
    params = doc["/**"]["ros__parameters"]
    assert set(params) == {"c1", "c2", "actuation_delay", "x_ref", "v_ref", "zeta", "r", "omega",
                           "pi2_offset"}
    assert params["c1"] == pytest.approx(degenerate_c1(P, -1.0), rel=1e-14)
    assert params["c2"] == -1.0
    ref = tmp_path / "ref.yaml"
    write_controller_yaml(ref, P, Gains(degenerate_c1(P, -1.0), -1.0))
    assert yaml.safe_load(ref.read_text()) == doc
    assert sorted(p.name for p in out_ok.parent.iterdir()) == ["controller.yaml"]


def test_design_out_refuses_a_non_admissible_gain(runs):
    r = runs[("out", "bad")]
    _, out_bad = runs["paths"]
    assert r.returncode == 2
    assert r.stdout == ""
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("grazing: error:")
    assert re.search(r"\bc2\b", lines[0])
    assert "Traceback" not in r.stderr
    assert list(out_bad.parent.iterdir()) == []


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("name", list(BAD_CASES))
def test_bad_input_exits_2_with_one_line_naming_the_parameter(runs, name):
    """Regression (a83d817, fixed in 5d7f72f/39e12ff) for omega_nan, delta_d_abc,
    periods_negative: a value rejected by argparse's type function printed argparse's
    usage block and 'grazing <cmd>: error: ...' (3-5 lines), not one 'grazing: error:'."""
    r = runs[("bad", name)]
    pattern = BAD_CASES[name][1]
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert r.stdout == ""
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("grazing: error: ")
    assert re.search(pattern, lines[0]), lines[0]


# ------------------------------------------------------------------ human-readable
@pytest.mark.parametrize("name", list(HUMAN_CASES))
def test_human_readable_output(runs, name):
    r = runs[("human", name)]
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    words = HUMAN_CASES[name][1]
    for w in words:
        assert w in r.stdout
    with pytest.raises(json.JSONDecodeError):
        json.loads(r.stdout)
    assert len(r.stdout.splitlines()) >= 3


def test_orbit_perturbation_method_agrees_with_exact_near_grazing(runs):
    """--method perturbation answers with the series estimate and reports its cost."""
    exact, fast = _json(runs, "orbit_near"), _json(runs, "orbit_near_perturbation")
    assert fast["method"] == "perturbation" and fast["seconds"] > 0
    lam_e = complex(*exact["multipliers"][0])
    lam_p = complex(*fast["multipliers"][0])
    assert abs(lam_p / lam_e - 1) < 1e-6


def test_grazing_run_drives_the_three_nodes_and_records(tmp_path):
    """`grazing run` starts sim, controller and recorder as processes, waits, stops them."""
    from grazing_control.ros.recording import read_messages

    bag = tmp_path / "bag"
    r = _run(["run", "--periods", "40", "--delta-d", "-5e-6", "--enable-after", "20",
              "--bag", str(bag), "--timeout", "120",
              "--domain-id", str(new_domain())], tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "sim_node=0 controller_node=0 recorder_node=0" in r.stdout
    pi2 = [m for m in read_messages(bag, ["/oscillator/pi2"])]
    assert len(pi2) == 40


def test_grazing_run_reports_a_failed_scene_with_nonzero_status(tmp_path):
    r = _run(["run", "--periods", "5", "--sim-param", "zeta:=2.0", "--timeout", "60"], tmp_path)
    assert r.returncode != 0
    assert "Traceback" not in r.stdout + r.stderr


# ------------------------------------------------------- hardening (issue 7), in-process
def _main(argv, capsys):
    """Run cli.main in this process: (status, stdout, stderr)."""
    from grazing_control import cli

    try:
        status = cli.main(argv)
    except SystemExit as exc:  # argparse errors, --version, --help
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def _strict_json(text):
    """Exactly one JSON object, with no NaN / Infinity (not JSON, though Python writes them)."""
    def refuse(name):
        raise AssertionError(f"non-standard JSON constant {name} in {text[:200]!r}")

    assert text.endswith("\n") and text.count("\n") == 1, text[:300]
    obj = json.loads(text, parse_constant=refuse)
    assert isinstance(obj, dict)
    return obj


def _one_error_line(err):
    assert "Traceback" not in err
    assert err.count("\n") == 1 and err.startswith("grazing: error: "), err
    return err


ISSUE_7_ERRORS = [
    (["orbit", "--delta-d", "0"], "v- = "),
    (["orbit", "--delta-d", "-0"], "v- = "),
    (["orbit", "--delta-d", "-1e-320"], "v- = "),
    (["design", "--c2", "-1", "--omega", "1e308"], "omega="),
    (["design", "--c2", "-1", "--omega", "1e-6"], "omega="),
    (["orbit", "--delta-d", "-1e-3", "--omega", "1e308"], "omega="),
    (["continue", "--from", "0", "--to", "-1e-4", "--omega", "1e308"], "omega="),
    (["simulate", "--delta-d", "-5e-6", "--periods", "1000000000000"], "periods="),
    (["design", "--c2", "1e308"], "not finite"),
    (["orbit", "--delta-d", "-1e-9", "--method", "perturbation", "--omega", "1"], "not near grazing"),
    (["design", "--c2", "-1", "--out", ""], "--out"),
    (["demo", "--out", ""], "--out"),
    (["simulate", "--delta-d", "-5e-6", "--periods", "200", "--c2", "1e308"], "period 1"),
    (["simulate", "--delta-d", "-5e-6", "--periods", "200", "--c2", "-1", "--c1", "1e308"],
     "overflowed"),
    (["simulate", "--delta-d", "-5e-6", "--periods", "200", "--c2", "-1", "--c1", "-1e308"],
     "overflowed"),
    (["simulate", "--delta-d", "-1e-3", "--periods", "3", "--dx0", "0", "--x0", "1"], "--dx0"),
]


@pytest.mark.parametrize("argv,what", ISSUE_7_ERRORS, ids=lambda a: " ".join(a) if isinstance(a, list) else "")
def test_issue_7_inputs_give_one_error_line_and_status_2(argv, what, capsys):
    """Issue 7's tracebacks, hangs and silent NaN: one line naming the problem, status 2,
    nothing on stdout."""
    status, out, err = _main(argv, capsys)
    assert status == 2 and out == ""
    assert what in _one_error_line(err)


def test_issue_7_json_is_valid_and_finite(capsys):
    """`continue --from 0 --to -1e-4 --points 40 --json` printed Infinity (the grazing
    point's multipliers): now null there, valid JSON; `simulate --periods 0` printed
    (nan, nan): now 'none'."""
    status, out, err = _main(["continue", "--from", "0", "--to", "-1e-4", "--points", "40",
                              "--json"], capsys)
    assert status == 0, err
    obj = _strict_json(out)
    grazing = [b for b in obj["bifurcations"] if b["type"] == "grazing"]
    assert grazing and grazing[0]["multipliers"] == [[None, 0.0], [None, 0.0]]
    status, out, err = _main(["simulate", "--delta-d", "-1e-3", "--periods", "0"], capsys)
    assert status == 0 and "nan" not in out and "none (0 periods)" in out
    status, out, err = _main(["simulate", "--delta-d", "-1e-3", "--periods", "0", "--json"], capsys)
    assert status == 0 and _strict_json(out)["pi2"] == []


def test_orbit_says_which_branch_it_is_on(capsys):
    """Issue 7: the far orbit (v- = 1.31 at zeta 0.2, r 0.3, omega 1.5) is labelled."""
    argv = ["orbit", "--zeta", "0.2", "--r", "0.3", "--omega", "1.5", "--delta-d", "-1e-3"]
    status, out, _ = _main(argv + ["--json"], capsys)
    assert status == 0 and _strict_json(out)["branch"] == "grazing past a fold"
    status, out, _ = _main(argv, capsys)
    assert "past a fold" in out and "far from grazing" in out
    status, out, _ = _main(["orbit", "--delta-d", "-1e-6", "--json"], capsys)
    assert _strict_json(out)["branch"] == "grazing"


def test_deviation_coordinates_on_the_command_line(capsys):
    """--dx0/--dv0 give the start as a deviation from X**, exactly: near a tangency the
    physical --x0/--v0 lose ~1e-16 * |x**| on conversion (issue 7)."""
    p = P.with_(delta_d=-1e-9)
    dev = (3e-12, -2e-13)
    status, out, err = _main(["simulate", "--delta-d", "-1e-9", "--periods", "5", "--dx0",
                              repr(dev[0]), "--dv0", repr(dev[1]), "--json"], capsys)
    assert status == 0, err
    core = simulate(p, 5, deviation=dev)
    assert _strict_json(out)["pi2"] == core.pi2.tolist()
    assert (core.pi2_deviation[0] == dev).all()
    # the physical form of the same start is not the same state after rounding
    x0, v0 = p.x_ref + dev[0], p.v_ref + dev[1]
    assert (x0 - p.x_ref, v0 - p.v_ref) != dev


def test_version(capsys):
    from grazing_control import __version__

    status, out, _ = _main(["--version"], capsys)
    assert status == 0 and out.strip() == f"grazing {__version__}"


def test_controller_yaml_is_written_with_the_usual_permissions(tmp_path, capsys):
    """The YAML was written 0600 (mkstemp); now 0666 & ~umask, atomically (rename)."""
    path = tmp_path / "c.yaml"
    old = os.umask(0o022)
    try:
        status, _, err = _main(["design", "--c2", "-1", "--out", str(path)], capsys)
    finally:
        os.umask(old)
    assert status == 0, err
    assert (path.stat().st_mode & 0o777) == 0o644
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left
    old = os.umask(0o077)
    try:
        _main(["design", "--c2", "-1", "--out", str(path)], capsys)
    finally:
        os.umask(old)
    assert (path.stat().st_mode & 0o777) == 0o600


def test_progress_bar_only_on_a_terminal(capsys, monkeypatch):
    """A long simulate shows a tqdm bar on stderr when stderr is a terminal, never with
    --json or when not a terminal (issue 7: 100000 periods printed nothing for 23 s)."""
    argv = ["simulate", "--delta-d", "-1e-3", "--periods", "2500"]
    status, out, err = _main(argv, capsys)
    assert status == 0 and err == ""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    status, out, err = _main(argv, capsys)
    assert status == 0 and "/2500 [" in err and "period/s" in err
    status, out, err = _main(argv + ["--json"], capsys)
    assert status == 0 and err == ""
    _strict_json(out)


def test_demo_json_prints_one_summary_object(tmp_path, capsys):
    status, out, err = _main(["demo", "--offline", "--json", "--out", str(tmp_path / "d")], capsys)
    assert status == 0, err
    obj = _strict_json(out)
    assert obj["exit_code"] == 0 and set(obj["scenes"]) and obj["report"].endswith("report.md")
    assert "report:" in err  # the progress lines went to stderr


_POOL = ["nan", "inf", "-inf", "1e308", "-1e308", "-0", "0", "1e-320", "", "abc", "-1", "1",
         "0.5", "-5e-6", "1e-6", "2", "-1e-3", "0.3", "3", "6.3"]
_COUNTS = ["nan", "inf", "1e308", "-0", "0", "1e-320", "", "-1", "1", "2", "3", "2.5", "1000000000000"]
_GOOD = {"--zeta": ["0.01", "0.2"], "--r": ["0.68", "0.3"], "--omega": ["0.667", "1.5"],
         "--pi2-offset": ["1.57", "3"], "--c1": ["0.1", "-0.3"], "--c2": ["-1", "-0.5", "0.2"],
         "--delta-d": ["-5e-6", "-1e-3", "0.01"], "--from": ["-1e-3", "0"], "--to": ["-1e-6"],
         "--x0": ["0.1"], "--v0": ["-1"], "--dx0": ["1e-9"], "--dv0": ["-1e-9"], "--tol": ["1e-6"],
         "--points": ["5", "8"], "--periods": ["3", "20"], "--control-after": ["1", "0"]}
_COMMANDS = {
    "design": (["--c2"], ["--zeta", "--r", "--omega", "--pi2-offset"], []),
    "orbit": (["--delta-d"], ["--zeta", "--r", "--omega", "--pi2-offset", "--c1", "--c2"], []),
    "continue": (["--from", "--to"], ["--zeta", "--r", "--omega", "--c2"], ["--points"]),
    "simulate": (["--delta-d"], ["--zeta", "--r", "--omega", "--pi2-offset", "--c1", "--c2",
                                 "--x0", "--v0", "--dx0", "--dv0", "--tol"],
                 ["--periods", "--control-after"]),
}


def _fuzz_argv(rng):
    """One seeded argument set of the fuzz: a command of design, orbit, continue and
    simulate, each numeric option (30 % of the time) from the hostile pool."""
    command = rng.choice(sorted(_COMMANDS))
    required, optional, counts = _COMMANDS[command]
    argv = [command]
    for opt in required + rng.sample(optional, rng.randint(0, 3)):
        argv.append(f"{opt}={rng.choice(_POOL if rng.random() < 0.3 else _GOOD[opt])}")
    for opt in counts:
        if rng.random() < 0.7 or opt == "--periods":
            value = rng.choice(_COUNTS[:12] if rng.random() < 0.3 else _GOOD[opt])
            argv.append(f"{opt}={value}")
    if command == "simulate" and rng.random() < 0.3:
        argv.append(f"--fidelity={rng.choice(['exact', 'zdm1', 'zdm2', 'auto'])}")
    if command in ("orbit", "design") and rng.random() < 0.3:
        argv.append("--method=perturbation")
    if rng.random() < 0.5:
        argv.append("--json")
    return argv


def _parsed(parser, argv):
    """The options ``parser`` gives ``argv``, or its exit status and message."""
    import contextlib
    import io

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            return vars(parser.parse_args(argv))
    except SystemExit as exc:
        return exc.code, err.getvalue()


def test_the_parser_main_keeps_parses_as_a_fresh_parser_does():
    """main builds its parser once a process: after thousands of parses of hostile
    argument sets (the fuzz's, seeded), each set's options (or its error) are those a
    freshly built parser gives it."""
    import random

    from grazing_control.cli.commands import _parser, build_parser

    rng = random.Random(8)
    sets = [_fuzz_argv(rng) for _ in range(2000)]
    kept = _parser()
    first = [_parsed(kept, argv) for argv in sets]
    assert sum(isinstance(f, tuple) for f in first) > 20      # errors among them
    again = [_parsed(kept, argv) for argv in sets[::-1]][::-1]
    assert again == first
    fresh = build_parser()
    assert [_parsed(fresh, argv) for argv in sets[::7]] == first[::7]


def test_cli_fuzz_never_a_traceback(capsys):
    """Fuzz (seeded, 400 argument sets): each numeric option (30 % of the time) of design, orbit, continue
    and simulate set to nan, inf, 1e308, -0, 1e-320, '', garbage or ordinary values,
    with and without --json: status 0 with valid, finite JSON (with --json), or status 2
    with exactly one `grazing: error:` line; never a traceback, never NaN."""
    import random

    rng = random.Random(7)
    seen = {0: 0, 2: 0}
    for _ in range(400):
        argv = _fuzz_argv(rng)
        as_json = argv[-1] == "--json"
        status, out, err = _main(argv, capsys)
        assert status in (0, 2), (argv, status, err)
        seen[status] += 1
        if status == 2:
            _one_error_line(err)
            assert out == "", argv
        else:
            assert "Traceback" not in err, argv
            if as_json:
                _strict_json(out)
            else:
                assert not re.search(r"\bnan\b|\binf\b", out.lower()), (argv, out)
    assert seen[0] > 40 and seen[2] > 40


def test_grazing_run_json_prints_one_summary_object(tmp_path):
    """`grazing run --json`: the README says every command takes --json; stdout is one
    JSON object (node output goes to stderr)."""
    r = _run(["run", "--periods", "20", "--delta-d", "-5e-6", "--timeout", "120", "--json",
              "--domain-id", str(new_domain())], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    obj = _strict_json(r.stdout)
    assert obj["ok"] is True and obj["exit_code"] == 0 and obj["sim"] == 0
    assert "finished" in obj["summary"]
    assert obj["reason"] is None and obj["sim_verdict"]["status"] == 0   # issue 27 §1
    assert obj["sim_verdict"]["watchdog"] is None


@pytest.mark.parametrize("delay", [0.0, 0.02, 0.1, 0.25, 0.6])
def test_ctrl_c_at_any_moment_of_the_console_script_is_quiet(delay):
    """The `grazing` console script (grazing_control.cli.console) under SIGINT while it
    imports numpy/scipy, loads the kernel or simulates (``delay`` seconds after numpy's
    core is mapped: its handler is in place; Python's own start before it is Python's to
    report): status 130, one line, no traceback."""
    import signal
    import time

    from console_scripts import script as console_script, wait_until_mapped

    script = console_script("grazing")
    proc = subprocess.Popen([str(script), "simulate", "--delta-d", "-5e-6", "--periods",
                             "5000000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert wait_until_mapped(proc), proc.communicate()
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, (out, err)
    assert "Traceback" not in err and err.strip() == "grazing: interrupted", err


# ------------------------------------------------------------------ issue 20, items 2-3
@pytest.mark.parametrize("argv", [
    ["--zeta", "0.03", "--r", "0.85", "--omega", "0.6655665991362745"],
    ["--zeta", "0.015"],
    ["--zeta", "0.02", "--method", "perturbation"],
])
def test_design_on_the_issue_20_inputs_gives_a_design(argv, capsys, tmp_path):
    """These gave "numerical failure (ZeroDivisionError)" (gamma1's pole at N11 = 1)."""
    out_file = tmp_path / "c.yaml"
    status, out, err = _main(["design", "--c2", "-1", *argv, "--out", str(out_file)], capsys)
    assert status == 0, err
    assert "this c2            : admissible" in out and out_file.exists()


def test_design_prints_the_true_ends_of_the_admissible_set(capsys):
    """`--c2 -4.5 --delay 0.5` printed (-4, 0.2698), the scan window; the set goes on to
    -5.1523011978 where |lambda0| = 1."""
    status, out, err = _main(["design", "--c2", "-4.5", "--delay", "0.5"], capsys)
    assert status == 0, err
    assert "admissible c2      = (-5.152301198, 0.269775247)" in out
    status, out, _ = _main(["design", "--c2", "1", "--delay", "1", "--json"], capsys)
    d = _strict_json(out)
    assert d["admissible_c2"][0] == pytest.approx(-0.3403039074, abs=1e-9)
    assert d["admissible_c2"][1] > 6.0 and d["c2_search_limit"] == 1e6


def test_design_says_beyond_the_search_limit_and_gives_null(capsys, monkeypatch):
    import math

    from grazing_control.dynamics.design import gains as design

    monkeypatch.setattr(design, "admissible_c2",
                        lambda p, *a, **k: [(-math.inf, -0.5), (0.25, math.inf)])
    status, out, err = _main(["design", "--c2", "1"], capsys)
    assert status == 0, err
    assert "(beyond -1e+06, -0.5) U (0.25, beyond +1e+06)" in out
    status, out, err = _main(["design", "--c2", "1", "--json"], capsys)
    d = _strict_json(out)
    assert d["admissible_c2"] == [0.25, None]
    assert d["admissible_c2_sets"]["combined"] == [[None, -0.5], [0.25, None]]
    assert d["c2_search_limit"] == 1e6


# ------------------------------------------------------------------ issue 15 section 3
def test_design_reports_the_noise_gain_of_the_core(capsys):
    """noise_gain in the JSON is dynamics.design.noise.noise_gain about the controlled orbit at
    --delta-d (itself checked against seeded simulations of the exact closed loop in
    tests/test_noise.py and tests/test_tuning.py)."""
    from grazing_control.dynamics.design.noise import noise_gain

    status, out, err = _main(["design", "--c2", "-0.3", "--delta-d", "-9e-6", "--json"], capsys)
    assert status == 0, err
    d = _strict_json(out)
    q = P.with_(delta_d=-9e-6)
    assert d["noise_gain"] == pytest.approx(noise_gain(q, Gains(degenerate_c1(P, -0.3), -0.3)),
                                            rel=1e-12)
    assert d["noise_gain_delta_d"] == -9e-6 and "optimize" not in d
    status, out, _ = _main(["design", "--c2", "-1", "--delta-d", "-5e-6"], capsys)
    assert re.search(r"noise gain\s+= 19\d\.\d", out)
    # c2 = -2.5 is not admissible: no stable orbit, no stationary spread
    status, out, _ = _main(["design", "--c2", "-2.5", "--delta-d", "-5e-6", "--json"], capsys)
    assert status == 0 and _strict_json(out)["noise_gain"] is None


def test_design_optimize_noise(capsys, tmp_path):
    from grazing_control.dynamics.design.tuning import optimize_noise

    path = tmp_path / "c.yaml"
    status, out, err = _main(["design", "--optimize", "noise", "--delay", "0.5", "--delta-d",
                              "-9e-6", "--json", "--out", str(path)], capsys)
    assert status == 0, err
    d = _strict_json(out)
    ref = optimize_noise(P.with_(delta_d=-9e-6), 0.5)
    assert d["c2"] == ref.c2 and d["c1"] == ref.c1 and d["actuation_delay"] == 0.5
    assert d["optimize"]["noise_gain"] == d["noise_gain"] == ref.noise_gain
    assert d["optimize"]["study_noise_gain"] == pytest.approx(ref.study_noise_gain)
    assert d["admissible"] is True
    params = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    assert (params["c1"], params["c2"]) == (ref.c1, ref.c2)
    status, out, _ = _main(["design", "--optimize", "noise"], capsys)
    assert "optimised" in out and "the study's c2 = -1: 19" in out   # at -5e-6 by default
    status, _, err = _main(["design", "--optimize", "noise", "--c2", "1"], capsys)
    assert status == 2 and "--optimize" in err
    status, _, err = _main(["design"], capsys)
    assert status == 2 and "c2" in err
    status, _, err = _main(["design", "--c2", "-1", "--delta-d", "1e-6"], capsys)
    assert status == 2 and "delta_d" in err


def test_the_command_line_starts_without_the_heavy_modules():
    """`grazing --version` (and building the parser of every command) imports neither
    scipy, matplotlib, numba, dask nor rclpy: the figures' build is imported on first use
    (it took 2.9 s under load when every command imported it, issue 19 §4)."""
    from loaded_modules import loaded

    code = ("from grazing_control.cli import main\n"
            "try:\n    main(['--version'])\nexcept SystemExit:\n    pass")
    assert loaded(code, ("scipy", "matplotlib", "numba", "dask", "rclpy",
                         "grazing_control.studies.figures.build"), timeout=60) == []

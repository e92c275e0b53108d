"""The command line against hostile arguments (issue 21 §8): each is refused with one line
naming the parameter and its valid range, status 2, nothing written, no traceback."""

import os
import subprocess
import sys

import pytest

from test_closed_loop import new_domain

CASES = [
    (["simulate", "--delta-d", "-5e-6", "--periods", "100", "--c2", "-1", "--c1", "-1",
      "--delay", "100"], "delay=100.0 is invalid: valid range is 0 <= delay < T"),
    (["simulate", "--delta-d", "-5e-6", "--periods", "100", "--c2", "-1", "--c1", "-1",
      "--delay", "1e300"], "delay=1e+300 is invalid"),
    (["analyze", "bags/scene_5e-6", "--time-scale", "0"], "--time-scale: '0' is invalid"),
    (["robustness", "delay", "--delta-d", "0"], "--delta-d: '0' is invalid: expected a finite number < 0"),
    (["robustness", "delay", "--c2-range", "1", "1"], "c2_range=(1.0, 1.0) is invalid"),
    (["robustness", "faults", "--threshold", "0"], "--threshold: '0' is invalid"),
    (["sweep", "--grid", "delta_d=-2e-5:-1e-5:3", "--scheduler", "bogus"],
     "--scheduler: 'bogus' is invalid: expected an address"),
    (["sweep", "--grid", "delta_d=-2e-5:-1e-5:3", "--scheduler", "tcp://host:99999"],
     "port 1..65535"),
    (["sweep", "--grid", "delta_d=-2e-5:-1e-5:3", "--out", ""], "--out: '' is invalid"),
    # issue 27: analyze wrote its report into the current folder
    (["analyze", "bags/scene_5e-6", "--out", ""], "--out: '' is invalid"),
]


@pytest.mark.parametrize("argv,message", CASES, ids=[" ".join(c[0][:2]) + f" {i}"
                                                     for i, c in enumerate(CASES)])
def test_a_hostile_argument_is_one_line_naming_its_range(argv, message, tmp_path):
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", *argv], cwd=tmp_path
                         if argv[0] != "analyze" else None, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert message in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv", [
    ["design", "--c2", "-1", "--out", "taken"],
    ["rig", "config/rigs/two_mass_beam.yaml", "--model-out", "taken"]], ids=["design", "rig"])
def test_a_file_output_onto_an_existing_folder_is_one_line_and_leaves_nothing(argv, tmp_path):
    """A gain or model file asked for where a folder is: the error names the path, not
    the temporary file the rename failed from (found by hand, 2026-11-28), and no
    temporary file is left beside it."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "taken").mkdir()
    argv = [str(root / a) if a.startswith("config/") else a for a in argv]
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", *argv], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert "'taken' is invalid: it is a folder; expected a file path" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and ".tmp" not in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
    assert not any((tmp_path / "taken").iterdir())


def test_a_sweep_into_a_folder_writes_inside_it(tmp_path):
    (tmp_path / "here").mkdir()
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", "sweep", "--grid",
                          "delta_d=-2e-5:-1e-5:3", "--periods", "20", "--workers", "1",
                          "--out", "here"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in (tmp_path / "here").iterdir()) == ["sweep.npz", "sweep.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here"]


@pytest.mark.parametrize("argv,message", [
    (["run", "--periods", "99999999999999999999999"], "--periods: '99999999999999999999999' is invalid"),
    (["run", "--periods", "0"], "--periods: '0' is invalid"),
    (["run", "--delta-d", "nan"], "--delta-d: 'nan' is invalid"),
])
def test_run_refuses_what_sim_node_cannot_hold(argv, message, tmp_path):
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", *argv], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_a_node_override_of_the_wrong_type_is_refused_not_replaced_by_the_file(tmp_path):
    """`-p zeta:=abc` with a parameter file that sets zeta: rclpy kept the file's value
    silently; the node now refuses the override (status 2, one line naming it)."""
    from grazing_control.ros.launcher import CONFIG_DIR
    for override, message in (("zeta:=abc", "zeta:=abc is invalid: expected a double"),
                              ("max_periods:=99999999999999999999999",
                               "beyond the 64-bit integer range"),
                              ("exit_when_done:=maybe", "expected true or false")):
        out = subprocess.run([sys.executable, "-m", "sim_node.sim_node", "--ros-args",
                              "--params-file", str(CONFIG_DIR / "study.yaml"), "-p", override,
                              "-p", "wait_for_controller:=false"],
                             capture_output=True, text=True, timeout=120,
                             env=dict(os.environ, ROS_DOMAIN_ID=str(new_domain())))
        assert out.returncode == 2, (override, out.stdout, out.stderr)
        assert message in out.stdout + out.stderr, (override, out.stdout, out.stderr)


def test_a_list_of_negative_numbers_in_exponent_form_is_values_not_options():
    from grazing_control.cli.commands import build_parser
    args = build_parser().parse_args(["robustness", "delay", "--delta-d", "-5e-6", "-1E-6",
                                      "-2.5e-7"])
    assert args.delta_d == [-5e-6, -1e-6, -2.5e-7]
    args = build_parser().parse_args(["orbit", "--delta-d", "-1e-10", "--c2", "-.5"])
    assert (args.delta_d, args.c2) == (-1e-10, -0.5)


def test_identify_beyond_the_arcs_a_fit_can_hold_is_one_line_in_little_memory():
    # issue 27: --max-arcs 100000 on a 1300-period bag (1420 arcs) took over 2 GB; the
    # dense Jacobian of the arcs that exist is measured before it is allocated
    import hostile_files

    status, out, err, peak = hostile_files.grazing_measured(
        "identify", "bags/scene_5e-6", "--max-arcs", "100000", timeout=300)
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert "the fit of the 1420 arcs used needs a dense Jacobian" in err and "--max-arcs" in err
    assert peak < 200, peak

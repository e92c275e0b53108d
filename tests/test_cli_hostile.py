"""The command line against hostile arguments (issue 21 §8): each is refused with one line
naming the parameter and its valid range, status 2, nothing written, no traceback."""

import subprocess
import sys

import pytest

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


def test_a_sweep_into_a_folder_writes_inside_it(tmp_path):
    (tmp_path / "here").mkdir()
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", "sweep", "--grid",
                          "delta_d=-2e-5:-1e-5:3", "--periods", "20", "--workers", "1",
                          "--out", "here"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in (tmp_path / "here").iterdir()) == ["sweep.npz", "sweep.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here"]

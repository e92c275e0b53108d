"""benchmarks/suite_cpu.py's summary of two recorded suites: the host's speed factor is
read off the tests that start no process, and divided out of the rest."""

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "suite_cpu.py"


@pytest.fixture(scope="module")
def suite_cpu():
    spec = importlib.util.spec_from_file_location("suite_cpu_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _record(folder: Path, rows) -> Path:
    """One worker's file: (own CPU, children's CPU, node id) per test."""
    folder.mkdir()
    with open(folder / "gw0.tsv", "w") as f:
        for i, (own, kids, nodeid) in enumerate(rows):
            f.write(f"{1000.0 + i:.3f}\t1.000\t{own:.3f}\t{kids:.3f}\t0,0\t{nodeid}\n")
    return folder


def test_the_host_factor_comes_from_the_tests_without_processes(suite_cpu, tmp_path, capsys):
    """The same pure tests 1.5 times slower, the scene's children 1.2 times: with the factor
    1.5 divided out, the children took 0.8 of the baseline's CPU."""
    before = _record(tmp_path / "before", [(10.0, 0.0, "tests/test_a.py::x"),
                                           (30.0, 0.0, "tests/test_b.py::y"),
                                           (2.0, 50.0, "tests/test_scene.py::z")])
    after = _record(tmp_path / "after", [(15.0, 0.0, "tests/test_a.py::x"),
                                         (45.0, 0.0, "tests/test_b.py::y"),
                                         (3.0, 60.0, "tests/test_scene.py::z")])
    assert suite_cpu.main([str(after), "--against", str(before), "--top", "3"]) == 0
    out = capsys.readouterr().out
    assert "the 2 modules that start no process took 40 -> 60 CPU-s (host factor 1.500)" in out
    assert "reaped children: 50 -> 60 CPU-s; with the host factor divided out 40 (-20.0%)" in out
    # 92 -> 123 in all: 123 / 1.5 = 82, -10.9 %
    assert "in-process + children: 92 -> 123 CPU-s; with the host factor divided out 82 (-10.9%)" \
        in out


def test_modules_the_change_moved_are_left_out_of_the_host_factor(suite_cpu, tmp_path,
                                                                  capsys):
    """A change that halved test_b's CPU on a host 1.5 times slower: left in, test_b makes
    the factor 0.94 (a faster host, read wrongly); left out, test_a alone gives 1.5."""
    before = _record(tmp_path / "before", [(10.0, 0.0, "tests/test_a.py::x"),
                                           (30.0, 0.0, "tests/test_b.py::y"),
                                           (2.0, 50.0, "tests/test_scene.py::z")])
    after = _record(tmp_path / "after", [(15.0, 0.0, "tests/test_a.py::x"),
                                         (22.5, 0.0, "tests/test_b.py::y"),
                                         (3.0, 60.0, "tests/test_scene.py::z")])
    assert suite_cpu.main([str(after), "--against", str(before)]) == 0
    assert "(host factor 0.938)" in capsys.readouterr().out
    assert suite_cpu.main([str(after), "--against", str(before),
                           "--changed", "tests/test_b.py"]) == 0
    out = capsys.readouterr().out
    assert ("the 1 modules that start no process, 1 changed ones left out took 10 -> 15 "
            "CPU-s (host factor 1.500)") in out
    with pytest.raises(SystemExit):
        suite_cpu.main([str(after), "--against", str(before),
                        "--changed", "tests/test_a.py", "tests/test_b.py"])
    assert "--changed leaves no module" in capsys.readouterr().err


def test_an_empty_folder_is_refused_by_name(suite_cpu, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    run = _record(tmp_path / "run", [(1.0, 0.0, "tests/test_a.py::x")])
    with pytest.raises(SystemExit):
        suite_cpu.main([str(run), "--against", str(tmp_path / "empty")])
    assert f"no *.tsv in {tmp_path / 'empty'}" in capsys.readouterr().err

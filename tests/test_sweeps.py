"""Tests of grazing_control.studies.sweeps: grids, the per-point runs, period detection, files,
local processes and Dask (a LocalCluster of two worker processes), and `grazing sweep`.

Every point of a sweep is an independent run of simulate's loop, so each is checked
against simulate() itself; local and Dask runs must give bit-identical files.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.studies.sweeps import SweepResult, detect_period, sweep
from grazing_control.studies.sweeps import run as sweep_run

ROOT = Path(__file__).resolve().parents[1]
STUDY = OscillatorParams()
DD = np.array([-1e-3, -2e-5, -9e-6, -5e-6, 1e-6])


# ------------------------------------------------------------------ the grid
def test_points_are_the_grid_product_with_starts_fastest():
    starts = [[0.0, 0.0], [1e-4, -2e-4]]
    res = sweep(STUDY, {"delta_d": DD[:2], "c2": [-1.0, -0.5, 0.0]}, periods=12, transient=4,
                deviation=starts, control_after=3, workers=1)
    assert res.names == ("delta_d", "c2") and res.shape == (2, 3, 2) and res.n_points == 12
    assert res.pi2.shape == (12, 8, 2) and res.impacts_per_period.shape == (12, 8)
    assert res.period.shape == (12,) and res.errors.shape == (12,)
    idx = list(np.ndindex(res.shape))
    for i, (a, b, s) in enumerate(idx):
        assert res.points["delta_d"][i] == DD[a] and res.points["c2"][i] == [-1.0, -0.5, 0.0][b]
        assert np.array_equal(res.starts[i], starts[s])
        # a gridded c2 without c1 takes c1 from the degenerate condition (Eq. 38)
        assert res.c1[i] == degenerate_c1(STUDY.with_(delta_d=DD[a]), res.c2[i])
    assert res.control_after == 3 and res.periods == 12 and res.transient == 4
    assert res.base["zeta"] == STUDY.zeta and "delta_d" not in res.base


@pytest.mark.parametrize("engine", ["kernel", "python"])
def test_each_point_is_simulate_after_the_transient(engine):
    """Uncontrolled and controlled (c2 = -1, c1 of Eq. 38, switched on at sample 30)."""
    for gains in (None, Gains(degenerate_c1(STUDY, -1.0), -1.0)):
        res = sweep(STUDY, {"delta_d": DD}, periods=60, transient=25, gains=gains,
                    control_after=30 if gains else None, workers=1, engine=engine)
        assert res.engine == engine
        for i, dd in enumerate(DD):
            one = simulate(STUDY.with_(delta_d=dd), 60, gains=gains,
                           control_after=30 if gains else None)
            assert np.array_equal(res.pi2_deviation[i], one.pi2_deviation[25:])
            assert np.array_equal(res.impacts_per_period[i], one.impacts_per_period[25:])
            assert np.allclose(res.pi2[i], one.pi2[25:], rtol=0, atol=1e-15)
        if gains is None:
            assert np.all(np.isnan(res.c1)) and res.control_after == -1
        else:
            assert np.all(res.c1 == gains.c1) and res.control_after == 30


@pytest.mark.parametrize("engine", ["kernel", "python"])
def test_a_delayed_kick_is_simulate_with_the_same_gains(engine):
    """Gains.delay is honoured as simulate honours it (the kick acts delay after the
    sample, from the sample control_after on); a delay of T or more is refused."""
    q = STUDY.with_(delta_d=-9e-6)
    gains = Gains(degenerate_c1(q, -1.0, 0.3), -1.0, 0.3)
    res = sweep(q, {"delta_d": [-9e-6, -5e-6]}, periods=50, transient=20, gains=gains,
                control_after=10, workers=1, engine=engine)
    assert res.delay == 0.3
    for i, dd in enumerate((-9e-6, -5e-6)):
        one = simulate(STUDY.with_(delta_d=dd), 50, gains=gains, control_after=10)
        assert np.array_equal(res.pi2_deviation[i], one.pi2_deviation[20:])
        assert np.array_equal(res.impacts_per_period[i], one.impacts_per_period[20:])
    undelayed = sweep(q, {"delta_d": [-9e-6]}, periods=50, transient=20,
                      gains=Gains(gains.c1, -1.0), control_after=10, workers=1, engine=engine)
    assert not np.array_equal(undelayed.pi2_deviation[0], res.pi2_deviation[0])
    with pytest.raises(ParameterError, match=r"delay=.* is invalid: valid range is 0 <= delay"):
        sweep(q, {"delta_d": [-9e-6]}, periods=5, transient=1, workers=1,
              gains=Gains(gains.c1, -1.0, q.period))


def test_kernel_and_python_engines_agree_bit_for_bit(monkeypatch):
    from grazing_control.oscillator import kernel

    g = {"delta_d": np.linspace(-2e-5, -1e-6, 6)}
    monkeypatch.setattr(kernel, "run_point", None)  # the python engine must not use them
    monkeypatch.setattr(kernel, "period_step", None)
    b = sweep(STUDY, g, periods=80, transient=40, workers=1, engine="python")
    monkeypatch.undo()
    a = sweep(STUDY, g, periods=80, transient=40, workers=1, engine="kernel")
    assert a.engine == "kernel" and b.engine == "python"
    assert np.array_equal(a.pi2_deviation, b.pi2_deviation)
    assert np.array_equal(a.impacts_per_period, b.impacts_per_period)
    assert np.array_equal(a.period, b.period)


def test_local_processes_give_the_same_result():
    g = {"delta_d": np.linspace(-2e-5, 0.0, 9)}
    one = sweep(STUDY, g, periods=200, transient=100, workers=1)
    two = sweep(STUDY, g, periods=200, transient=100, workers=2)
    assert one.same_as(two)


# ------------------------------------------------------------ period detection
def test_detect_period_on_constructed_sequences():
    rng = np.random.default_rng(1)
    cycle = rng.normal(size=(3, 2))
    seq = np.tile(cycle, (20, 1))
    assert detect_period(seq) == 3
    assert detect_period(seq + rng.normal(scale=1e-12, size=seq.shape)) == 3  # below tol
    assert detect_period(seq + rng.normal(scale=1e-6, size=seq.shape)) == 0
    assert detect_period(seq + rng.normal(scale=1e-6, size=seq.shape), tol=1e-4) == 3
    assert detect_period(np.tile([[1.0, 2.0]], (10, 1))) == 1
    assert detect_period(rng.normal(size=(100, 2))) == 0  # "chaos"
    assert detect_period(seq[:5]) == 0  # a period must repeat twice in the record
    assert detect_period(seq, max_period=2) == 0
    bad = seq.copy()
    bad[7, 1] = np.nan
    assert detect_period(bad) == -1


def test_detected_periods_of_the_study():
    """-1e-3: the stable 1/1 orbit (and its Pi2 point from shooting); -9e-6: the 2/2
    motion it settles on after ~540 irregular periods; -5e-6: no period (chaotic);
    controlled -5e-6: the controlled 1/1 orbit."""
    gains = Gains(degenerate_c1(STUDY, -1.0), -1.0)
    res = sweep(STUDY, {"delta_d": [-1e-3, -9e-6, -5e-6]}, periods=1000, transient=800,
                workers=1)
    assert res.period.tolist() == [1, 2, 0]
    target = orbit_11(STUDY.with_(delta_d=-1e-3)).pi2
    assert np.max(np.abs(res.pi2[0] - target)) < 1e-10
    assert np.all(res.impacts_per_period[:2] == 1)
    ctl = sweep(STUDY, {"delta_d": [-5e-6]}, periods=600, transient=400, gains=gains,
                control_after=0, workers=1)
    assert ctl.period.tolist() == [1]
    assert np.max(np.abs(ctl.pi2[0] - orbit_11(STUDY.with_(delta_d=-5e-6), gains).pi2)) < 1e-10


# ------------------------------------------------------------- bad points, bad input
def test_a_failing_point_is_reported_and_the_others_run():
    """With the wall at d < x** (Delta d = -1.9) the start is beyond the wall."""
    res = sweep(STUDY, {"delta_d": [-1e-3, -1.9, -5e-6]}, periods=20, transient=10, workers=1)
    assert res.period[1] == -1 and "InitialStateError: state beyond the wall" in res.errors[1]
    assert np.all(np.isnan(res.pi2[1]))
    assert res.errors[0] == res.errors[2] == "" and np.all(np.isfinite(res.pi2[[0, 2]]))


@pytest.mark.parametrize("kwargs,message", [
    ({"grid": {"wall": [1.0]}}, "grid name 'wall' is invalid: valid names are"),
    ({"grid": {"delta_d": []}}, r"grid\['delta_d'\] is invalid"),
    ({"grid": {"delta_d": [0.0, np.nan]}}, r"grid\['delta_d'\] is invalid: valid range is finite"),
    ({"grid": {"r": [0.5, 1.5]}}, r"r=1.5 is invalid: valid range is 0 < r < 1"),
    ({"grid": {}}, "grid is invalid"),
    ({"transient": 10}, r"transient=10 is invalid: valid range is 0 <= transient < periods=10"),
    ({"periods": 0}, r"periods=0 is invalid: valid range is an integer >= 1"),
    ({"deviation": [1.0, 2.0, 3.0]}, "deviation is invalid"),
    ({"workers": 0}, r"workers=0 is invalid: valid range is an integer >= 1"),
    ({"engine": "gpu"}, "engine='gpu' is invalid"),
    ({"period_tol": -1.0}, "period_tol=-1.0 is invalid"),
    ({"grid": {"delta_d": [0.0], "c1": [0.1]}}, "grid has c1 without c2"),
])
def test_invalid_arguments_name_the_parameter(kwargs, message):
    args = {"grid": {"delta_d": [-1e-3]}, "periods": 10, "transient": 5, "workers": 1}
    args.update(kwargs)
    with pytest.raises(ParameterError, match=message):
        sweep(STUDY, **args)


# -------------------------------------------------------------------- files
def test_npz_round_trip(tmp_path):
    res = sweep(STUDY, {"delta_d": DD[:3], "c2": [-1.0]}, periods=30, transient=10,
                deviation=[[0, 0], [1e-5, 0]], workers=1)
    res.to_npz(tmp_path / "s.npz")
    back = SweepResult.from_npz(tmp_path / "s.npz")
    assert back.same_as(res) and back.engine == res.engine
    back.to_npz(tmp_path / "again.npz")  # equal results, byte-identical files
    assert (tmp_path / "again.npz").read_bytes() == (tmp_path / "s.npz").read_bytes()
    with np.load(tmp_path / "s.npz") as f:  # readable without this package
        assert np.array_equal(f["pi2"], res.pi2) and f["period"].shape == (6,)
    np.savez(tmp_path / "other.npz", a=np.zeros(2), meta=np.array('{"format": "x"}'))
    with pytest.raises(ValueError, match="not a sweep file"):
        SweepResult.from_npz(tmp_path / "other.npz")


# ------------------------------------------------------------------------ Dask
def test_dask_local_cluster_gives_the_local_result(tmp_path):
    """Two worker processes on 127.0.0.1, reached by address as `--scheduler` would."""
    distributed = pytest.importorskip("distributed")
    g = {"delta_d": np.linspace(-2e-5, 0.0, 12)}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        on_dask = sweep(STUDY, g, periods=300, transient=100, scheduler=cluster.scheduler_address)
        with distributed.Client(cluster) as client:  # or given a Client
            with_client = sweep(STUDY, g, periods=300, transient=100, scheduler=client)
    local = sweep(STUDY, g, periods=300, transient=100, workers=1)
    assert on_dask.same_as(local) and with_client.same_as(local)
    on_dask.to_npz(tmp_path / "dask.npz")
    local.to_npz(tmp_path / "local.npz")
    assert (tmp_path / "dask.npz").read_bytes() == (tmp_path / "local.npz").read_bytes()


def test_unreachable_scheduler_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(sweep_run, "CONNECT_TIMEOUT", 1.0)
    with pytest.raises(ParameterError, match=r"scheduler='tcp://127.0.0.1:9' is invalid: cannot"):
        sweep(STUDY, {"delta_d": [-1e-3]}, periods=10, transient=5,
              scheduler="tcp://127.0.0.1:9")
    with pytest.raises(ParameterError, match=r"scheduler=42 is invalid: expected an address"):
        sweep(STUDY, {"delta_d": [-1e-3]}, periods=10, transient=5, scheduler=42)


# ------------------------------------------------------------------------- CLI
def _grazing(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "grazing_control.cli", "sweep", *args],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def test_cli_writes_npz_and_png_and_prints_one_json_object(tmp_path):
    out = tmp_path / "d" / "s.npz"
    run = _grazing("--grid", "delta_d=-2e-5:0:8", "--grid", "c2=-1,-0.5", "--periods", "60",
                   "--transient", "40", "--start=-1e-4,0", "--start", "0,0",
                   "--control-after", "50", "--workers", "2", "--out", str(out), "--json")
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary["points"] == 32 and summary["shape"] == [8, 2, 2]
    assert summary["npz"] == str(out) and Path(summary["png"]).stat().st_size > 1000
    assert sum(summary["detected_periods"].values()) == 32 and run.stderr == ""
    res = SweepResult.from_npz(out)
    same = sweep(STUDY, {"delta_d": np.linspace(-2e-5, 0, 8), "c2": [-1.0, -0.5]}, periods=60,
                 transient=40, deviation=[[-1e-4, 0], [0, 0]], control_after=50, workers=1)
    assert res.same_as(same)


def test_cli_human_report(tmp_path):
    run = _grazing("--grid", "delta_d=-1e-3:-1e-7:4:log", "--periods", "40",
                   "--out", str(tmp_path / "h"), "--no-png")
    assert run.returncode == 0, run.stderr
    assert "sweep of 4 points (delta_d), 40 periods each, last 20 kept" in run.stdout
    assert "periods/s" in run.stdout and (tmp_path / "h.npz").exists()
    assert not (tmp_path / "h.png").exists()


@pytest.mark.parametrize("args,message", [
    (["--grid", "delta_d=1:2"], "'delta_d=1:2' is invalid: expected NAME=START:STOP:N"),
    (["--grid", "delta_d=-1:1:5:log"], "a :log range needs START and STOP of one sign"),
    (["--grid", "wall=1,2"], "grid name 'wall' is invalid"),
    (["--grid", "delta_d=-1e-3", "--periods", "10", "--transient", "10"], "transient=10"),
    (["--grid", "delta_d=-1e-3", "--start", "1,x"], "'1,x' is invalid: expected DX,DV"),
    (["--grid", "delta_d=-1e-3", "--control-after", "3"], "--control-after needs the gains"),
    (["--grid", "r=0.5,2"], "r=2.0 is invalid: valid range is 0 < r < 1"),
])
def test_cli_bad_input_is_one_line_and_status_2(args, message, tmp_path):
    run = _grazing(*args, "--out", str(tmp_path / "x.npz"))
    assert run.returncode == 2 and run.stdout == ""
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("grazing: error: ") and message in lines[0]
    assert not (tmp_path / "x.npz").exists()

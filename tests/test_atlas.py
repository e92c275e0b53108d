"""The (omega, Delta d) atlas (issue 18 section 4): `grazing sweep` over two grid axes with
the Lyapunov column (studies.sweeps, dynamics.simulation.lyapunov), identical on the kernel and the
pure-Python core, locally and on a Dask LocalCluster, each point equal to a direct
lyapunov_exact run over the same orbit."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.simulation.lyapunov import lyapunov_exact
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.studies.sweeps import SweepResult, sweep

ROOT = Path(__file__).resolve().parents[1]
STUDY = OscillatorParams()
GRID = {"omega": np.linspace(0.660, 0.674, 3), "delta_d": np.linspace(-1.6e-5, -2e-6, 4)}


def test_each_point_is_the_direct_spectrum_of_its_kept_orbit():
    res = sweep(STUDY, GRID, periods=500, transient=200, workers=1, lyapunov=True)
    assert res.lyapunov.shape == (12, 2)
    for i in range(res.n_points):
        p = STUDY.with_(omega=float(res.points["omega"][i]),
                        delta_d=float(res.points["delta_d"][i]))
        direct = lyapunov_exact(p, (0.0, 0.0), 500, 200)
        assert tuple(res.lyapunov[i]) == direct.exponents
        assert abs(direct.sum_residual) < 1e-10
    # chaos where no period is detected, negative exponents on detected periods
    lmax, per = res.lyapunov[:, 0], res.period
    assert np.all(lmax[per == 0] > 0) and np.all(lmax[per > 0] < 0.05)


def test_controlled_points_switch_the_controller_on_at_the_same_sample():
    g = {"delta_d": np.linspace(-8e-6, -3e-6, 3)}
    gains = Gains(-0.5, -0.6)
    res = sweep(STUDY, g, periods=400, transient=150, gains=gains, control_after=250,
                workers=1, lyapunov=True)
    for i, dd in enumerate(g["delta_d"]):
        direct = lyapunov_exact(STUDY.with_(delta_d=float(dd)), (0.0, 0.0), 400, 150, gains,
                                250)
        assert tuple(res.lyapunov[i]) == direct.exponents


def test_the_python_engine_gives_the_kernels_atlas():
    k = sweep(STUDY, GRID, periods=300, transient=100, workers=1, lyapunov=True,
              engine="kernel")
    py = sweep(STUDY, GRID, periods=300, transient=100, workers=1, lyapunov=True,
               engine="python")
    assert np.array_equal(k.pi2_deviation, py.pi2_deviation)
    assert np.allclose(k.lyapunov, py.lyapunov, rtol=1e-10, atol=1e-12)


def test_an_atlas_on_a_two_worker_local_cluster_equals_the_local_one(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        on_dask = sweep(STUDY, GRID, periods=300, transient=100, lyapunov=True,
                        scheduler=cluster.scheduler_address)
    local = sweep(STUDY, GRID, periods=300, transient=100, lyapunov=True, workers=1)
    assert on_dask.same_as(local)
    on_dask.to_npz(tmp_path / "dask.npz")
    local.to_npz(tmp_path / "local.npz")
    assert (tmp_path / "dask.npz").read_bytes() == (tmp_path / "local.npz").read_bytes()
    back = SweepResult.from_npz(tmp_path / "local.npz")
    assert back.same_as(local) and np.array_equal(back.lyapunov, local.lyapunov)


def test_the_cli_writes_the_column_the_atlas_and_the_summary(tmp_path):
    out = tmp_path / "atlas.npz"
    run = subprocess.run(
        [sys.executable, "-m", "grazing_control.cli", "sweep", "--grid", "omega=0.8:0.86:3",
         "--grid", "delta_d=-1.2e-5:-2e-6:4", "--periods", "300", "--transient", "100",
         "--lyapunov", "--workers", "1", "--out", str(out), "--json"],
        capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert Path(summary["atlas_png"]).stat().st_size > 1000
    res = SweepResult.from_npz(out)
    lm = res.lyapunov[:, 0]
    assert summary["lyapunov_max"]["positive"] == int(np.sum(lm > 0))
    assert summary["lyapunov_max"]["max"] == pytest.approx(float(lm.max()))
    same = sweep(STUDY, {"omega": np.linspace(0.8, 0.86, 3),
                         "delta_d": np.linspace(-1.2e-5, -2e-6, 4)},
                 periods=300, transient=100, workers=1, lyapunov=True)
    assert res.same_as(same)
    assert not np.isnan(lm).any()

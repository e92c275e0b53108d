"""Tests of grazing_control.studies.basins and `grazing basins`.

Every classification is checked against something computed another way: the starts'
motions by simulate() itself with a period found by brute force here, the 1/1 orbit by
impact-phase shooting (orbit_11), a 3/3 cycle by Newton shooting and its multipliers,
the attractors' grouping on constructed records; local processes and a Dask cluster
against the run in this process, bit for bit.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits.orbits import orbit_11, shoot
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.studies.basins import (basins, canonical_cycle, cycle_distance,
                                            default_box, identify, orbit_scale,
                                            reduced_period)

ROOT = Path(__file__).resolve().parents[1]
STUDY = OscillatorParams()
#: Where the stable 1/1 motion coexists with a 3/3 motion (before the period doubling,
#: docs/figures.md: "X** reaches an attractor other than the 1/1 motion").
COEXIST = STUDY.with_(delta_d=-1.25e-5)
BOX = ((-1e-2, 1e-2), (-1e-2, 1e-2))


@pytest.fixture(scope="module")
def coexisting():
    return basins(COEXIST, dx_range=BOX[0], dv_range=BOX[1], nx=13, nv=11, transient=1500,
                  max_period=16, workers=1)


def _brute_period(dev, tol, max_period):
    """The smallest p with every |z_{k+p} - z_k| <= tol, written out as loops."""
    m = len(dev)
    for p in range(1, max_period + 1):
        if 2 * p > m:
            break
        if all(abs(dev[k + p][0] - dev[k][0]) <= tol and abs(dev[k + p][1] - dev[k][1]) <= tol
               for k in range(m - p)):
            return p
    return 0


# --------------------------------------------------------------- identification
def test_identify_groups_cycles_up_to_where_they_were_entered():
    rng = np.random.default_rng(7)
    a3 = rng.normal(size=(3, 2))
    b3 = rng.normal(size=(3, 2))
    one = np.array([[0.5, -0.5]])
    m = 12

    def record(cycle, shift):
        return np.tile(np.roll(cycle, shift, axis=0), (m // len(cycle) + 1, 1))[:m]

    records = np.stack([record(a3, 0), record(a3, 1), record(b3, 0), record(one, 0),
                        rng.normal(size=(m, 2)), record(a3, 2) + 1e-9, np.full((m, 2), np.nan),
                        record(b3, 2)])
    counts = np.ones((8, m), dtype=int)
    counts[2] = counts[7] = 0                     # b3: no impact, so another n/p than a3
    period = np.array([3, 3, 3, 1, 0, 3, -1, 3])
    index, atts = identify(records, counts, period, match_tol=1e-6)
    assert [a.label for a in atts] == ["1/1", "0/3", "3/3", "chaotic", "failed"]
    assert index.tolist() == [2, 2, 1, 0, 3, 2, 4, 1]
    assert [a.starts for a in atts] == [1, 2, 3, 1, 1]
    assert np.array_equal(atts[2].points, canonical_cycle(a3))
    assert atts[2].first == 0 and atts[1].first == 2
    # the same n/p twice: two attractors, numbered in the order of their first start
    index, atts = identify(records[:2] * [[[1.0]], [[2.0]]], counts[:2], period[:2], 1e-6)
    assert [a.label for a in atts] == ["3/3 #1", "3/3 #2"] and index.tolist() == [0, 1]
    # a tolerance above the difference merges them
    near = np.stack([record(a3, 0), record(a3, 1) + 1e-7])
    assert len(identify(near, counts[:2], period[:2], 1e-6)[1]) == 1
    assert len(identify(near, counts[:2], period[:2], 1e-8)[1]) == 2


def test_a_slow_alternating_approach_is_the_short_cycle():
    """A 3-cycle approached along a multiplier -0.965 of P^3: the record repeats to 1e-10
    after 6 samples before it does after 3; at the matching tolerance it is the 3-cycle."""
    rng = np.random.default_rng(5)
    cycle = rng.normal(size=(3, 2))
    k = np.arange(600)
    e = 2e-8 * (-0.965) ** (k // 3)
    dev = cycle[k % 3] + np.column_stack([e, -e])
    from grazing_control.studies.sweeps import detect_period

    record = dev[-128:]
    assert detect_period(record, 1e-10, 64) == 6
    counts = np.ones(6, dtype=int)
    assert reduced_period(record[-6:], counts, 1e-6) == 3
    assert reduced_period(record[-6:], counts, 1e-12) == 6
    assert reduced_period(record[-6:], np.array([1, 1, 1, 1, 1, 2]), 1e-6) == 6  # impacts differ
    index, atts = identify(record[None], np.ones((1, 128), dtype=int), np.array([6]), 1e-6)
    assert [a.label for a in atts] == ["3/3"] and atts[0].points.shape == (3, 2)


def test_a_record_periodic_only_at_match_tol_is_a_slow_start_of_its_cycle():
    """No period at 1e-10 (the alternation about a fixed point decays like 0.995^k), one at
    match_tol: it joins the settled start's 1/1 attractor (whose point is kept), counted
    slow; a record periodic at neither is chaotic."""
    rng = np.random.default_rng(11)
    k = np.arange(128)
    fixed = np.array([1e-3, -1e-3])
    slowly = fixed + 1e-8 * (-0.995) ** k[:, None] * [1.0, 2.0]
    records = np.stack([slowly, np.tile(fixed, (128, 1)), rng.normal(size=(128, 2))])
    from grazing_control.studies.sweeps import detect_period

    period = np.array([detect_period(r, 1e-10, 64) for r in records])
    assert period.tolist() == [0, 1, 0]
    index, atts = identify(records, np.ones((3, 128), dtype=int), period, 1e-6)
    assert [(a.label, a.starts, a.slow, a.first) for a in atts] == [("1/1", 2, 1, 1),
                                                                    ("chaotic", 1, 0, 2)]
    assert np.array_equal(atts[0].points[0], fixed) and index.tolist() == [0, 0, 1]
    # block by block (the slow start alone in the first block): the same result
    from grazing_control.studies.basins.attractors import Grouping

    grouping = Grouping(1e-6)
    for lo, hi in ((0, 1), (1, 3)):
        grouping.add(records[lo:hi], np.ones((hi - lo, 128), dtype=int), period[lo:hi])
    index_b, atts_b = grouping.finish()
    assert np.array_equal(index_b, index) and [(a.label, a.starts, a.slow, a.first)
                                               for a in atts_b] == [("1/1", 2, 1, 1),
                                                                    ("chaotic", 1, 0, 2)]
    assert np.array_equal(atts_b[0].points, atts[0].points)


def test_cycle_distance_is_the_least_over_shifts():
    a = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 5.0]])
    for s in range(3):
        assert cycle_distance(a, np.roll(a, s, axis=0)) == 0.0
    assert cycle_distance(a, a[::-1]) > 0.5  # reversed order is another cycle
    assert cycle_distance(a, a[:2]) == float("inf")


# ------------------------------------------------------ against direct simulation
def test_classification_is_that_of_simulate_from_each_start(coexisting):
    """Each of 20 seeded random starts of the grid: simulate() from it, the period found
    by brute force on the same record, its impacts, and its cycle on the attractor."""
    res = coexisting
    assert {a.label for a in res.attractors} == {"1/1", "3/3"}
    rng = np.random.default_rng(3)
    record = 2 * res.max_period
    for flat in rng.choice(res.n_starts, size=20, replace=False):
        i, j = divmod(int(flat), res.xs.size)
        run = simulate(COEXIST, res.transient + record, deviation=(res.xs[j], res.vs[i]))
        dev = run.pi2_deviation[res.transient:]
        p = _brute_period(dev.tolist(), res.period_tol, res.max_period)
        assert p == res.period[i, j] and p > 0
        # the least divisor q of p after which the last p samples repeat within match_tol
        q = next(q for q in range(1, p + 1) if p % q == 0 and all(
            abs(dev[-p + k + q][c] - dev[-p + k][c]) <= res.match_tol
            for k in range(p - q) for c in (0, 1)))
        att = res.attractors[res.attractor[i, j]]
        assert att.period == q and att.impacts == int(run.impacts_per_period[-q:].sum())
        p = q
        assert cycle_distance(dev[-p:], att.points) <= res.match_tol
        assert np.array_equal(res.final[i, j], dev[-1])
        assert res.mean_impacts[i, j] == run.impacts_per_period[res.transient:].mean()


def test_coexisting_attractors_are_true_stable_orbits(coexisting):
    """1/1: orbit_11's Pi2 point; 3/3: a fixed point of P^3 by Newton shooting with three
    impacts and multipliers inside the unit circle; both reached by a fair share."""
    res = coexisting
    one, three = (next(a for a in res.attractors if a.label == lab) for lab in ("1/1", "3/3"))
    assert min(one.starts, three.starts) > 0.2 * res.n_starts
    exact = orbit_11(COEXIST)
    assert np.max(np.abs(one.points[0] - exact.pi2_deviation)) < 1e-10 and exact.stable
    orbit = shoot(COEXIST, periods=3, deviation=tuple(three.points[0]))
    assert len(orbit.impacts) == 3 and orbit.stable
    assert np.max(np.abs(np.array(orbit.pi2_deviation) - three.points[0])) < 1e-10
    # and the 3/3 cycle's three points are P, P^2 of it (the exact flow, one period each)
    z = three.points[0]
    seen = [z]
    for _ in range(2):
        z = simulate(COEXIST, 2, deviation=tuple(z)).pi2_deviation[1]
        seen.append(z)
    assert cycle_distance(np.array(seen), three.points) < 1e-10


def test_starts_on_two_points_of_one_2_cycle_are_one_attractor():
    """Delta d = -9e-6 (the study's second scene, uncontrolled): every start ends on the
    2/2 motion, entered at either of its points."""
    q = STUDY.with_(delta_d=-9e-6)
    res = basins(q, nx=9, nv=9, transient=1500, max_period=8, workers=1)
    assert [a.label for a in res.attractors] == ["2/2"]
    cycle = res.attractors[0].points
    on = [int(np.argmin(np.max(np.abs(cycle - z), axis=1))) for z in res.final.reshape(-1, 2)]
    assert set(on) == {0, 1}
    orbit = shoot(q, periods=2, deviation=tuple(cycle[0]))
    assert np.max(np.abs(np.array(orbit.pi2_deviation) - cycle[0])) < 1e-10


@pytest.mark.parametrize("delta_d,c2,delay", [(-1e-3, None, 0.0), (-1.25e-5, None, 0.0),
                                               (-5e-6, -1.0, 0.0), (-9e-6, -1.0, 0.4)])
def test_a_start_on_the_1_1_orbit_is_classified_1_1(delta_d, c2, delay):
    """One start exactly on orbit_11's Pi2 point (nx = nv = 1 takes the range's low end),
    no transient: the record is the orbit itself."""
    q = STUDY.with_(delta_d=delta_d)
    gains = None if c2 is None else Gains(degenerate_c1(q, c2, delay), c2, delay)
    dx, dv = orbit_11(q, gains).pi2_deviation
    res = basins(q, dx_range=(dx, dx + 1.0), dv_range=(dv, dv + 1.0), nx=1, nv=1, gains=gains,
                 transient=0, max_period=4, workers=1)
    assert [a.label for a in res.attractors] == ["1/1"] and res.period[0, 0] == 1
    assert np.max(np.abs(res.attractors[0].points[0] - (dx, dv))) < 1e-12
    assert res.delay == delay


def test_control_captures_the_study_scene():
    """Delta d = -5e-6: uncontrolled every start is chaotic; with c2 = -1 (c1 of Eq. 38)
    every start of the same box reaches the controlled 1/1 orbit."""
    q = STUDY.with_(delta_d=-5e-6)
    gains = Gains(degenerate_c1(q, -1.0), -1.0)
    free = basins(q, nx=5, nv=5, transient=800, max_period=16, workers=1)
    ctl = basins(q, nx=5, nv=5, gains=gains, transient=800, max_period=16, workers=1)
    assert np.array_equal(free.xs, ctl.xs) and np.array_equal(free.vs, ctl.vs)
    assert [a.label for a in free.attractors] == ["chaotic"] and np.all(free.period == 0)
    assert [a.label for a in ctl.attractors] == ["1/1"]
    target = orbit_11(q, gains).pi2_deviation
    assert np.max(np.abs(ctl.attractors[0].points[0] - target)) < 1e-10


def test_control_near_the_end_of_the_admissible_set_converges_slowly():
    """c2 = -2 (admissible down to -2.019): the controlled 1/1 orbit's multiplier is -0.995,
    so after 2000 periods the starts are within 1e-7 of it but not periodic to 1e-10; they
    are its slow starts, not chaos."""
    q = STUDY.with_(delta_d=-9e-6)
    gains = Gains(degenerate_c1(q, -2.0), -2.0)
    exact = orbit_11(q, gains)
    assert -1.0 < exact.multipliers[0] < -0.99
    res = basins(q, dx_range=(2e-3, 3e-3), dv_range=(0.0, 1e-3), nx=2, nv=2, gains=gains,
                 transient=2000, max_period=8, workers=1)
    assert res.match_tol == 1e-3 * orbit_scale(q)          # the default, box-independent
    assert [a.label for a in res.attractors] == ["1/1"] and res.attractors[0].slow >= 1
    assert np.any(res.period == 0)
    assert np.max(np.abs(res.final - exact.pi2_deviation)) < res.match_tol


def test_default_box_is_the_1_1_orbit_scale_around_x_star():
    for dd in (-9e-6, 9e-6):
        (xlo, xhi), (vlo, vhi) = default_box(STUDY.with_(delta_d=dd))
        scale = np.max(np.abs(orbit_11(STUDY.with_(delta_d=-9e-6)).pi2_deviation))
        assert xlo == vlo == -xhi == -vhi and xhi == pytest.approx(4 * scale, rel=1e-15)


# ------------------------------------------------------------ where it runs
def test_local_processes_and_dask_give_the_same_result(tmp_path):
    distributed = pytest.importorskip("distributed")
    q = COEXIST
    kw = dict(dx_range=BOX[0], dv_range=BOX[1], nx=6, nv=5, transient=600, max_period=8)
    here = basins(q, workers=1, **kw)
    two = basins(q, workers=2, **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            on_dask = basins(q, scheduler=client, **kw)
    assert here.same_as(two) and here.same_as(on_dask)
    here.to_npz(tmp_path / "here.npz")
    on_dask.to_npz(tmp_path / "dask.npz")
    assert (tmp_path / "here.npz").read_bytes() == (tmp_path / "dask.npz").read_bytes()


def test_blocks_do_not_change_the_result(monkeypatch):
    from grazing_control.studies.basins import run

    kw = dict(dx_range=BOX[0], dv_range=BOX[1], nx=4, nv=3, transient=300, max_period=4,
              workers=1)
    whole = basins(COEXIST, **kw)
    monkeypatch.setattr(run, "BLOCK", 5)
    assert basins(COEXIST, **kw).same_as(whole)
    monkeypatch.setattr(run, "BLOCK_SAMPLES", 3 * 8)   # 3 starts of 8 samples per block
    assert basins(COEXIST, **kw).same_as(whole)


def test_the_python_core_gives_the_kernel_result(monkeypatch):
    """engine='python': the pure-Python reference core, not the kernel (switched off)."""
    from grazing_control.oscillator import kernel

    kw = dict(dx_range=BOX[0], dv_range=BOX[1], nx=2, nv=2, transient=150, max_period=4,
              workers=1)
    compiled = basins(COEXIST, engine="kernel", **kw)
    monkeypatch.setattr(kernel, "run_point", None)
    reference = basins(COEXIST, engine="python", **kw)
    assert reference.engine == "python" and compiled.engine == "kernel"
    assert np.array_equal(reference.final, compiled.final)
    assert np.array_equal(reference.attractor, compiled.attractor)
    assert [a.label for a in reference.attractors] == [a.label for a in compiled.attractors]


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("kwargs,message", [
    ({"nx": 0}, r"nx=0 is invalid: valid range is an integer >= 1"),
    ({"nv": 2.5}, r"nv=2.5 is invalid"),
    ({"nx": 3000, "nv": 3000}, r"nx \* nv = 9000000 is invalid: valid range is at most"),
    ({"dx_range": (1e-3, -1e-3)}, r"dx_range=.* is invalid: valid range is finite low < high"),
    ({"dv_range": (0.0, np.inf)}, r"dv_range=.* is invalid"),
    ({"dv_range": 3.0}, r"dv_range=3.0 is invalid: expected \(low, high\)"),
    ({"transient": -1}, r"transient=-1 is invalid"),
    ({"max_period": 0}, r"max_period=0 is invalid"),
    ({"match_tol": -1.0}, r"match_tol=-1.0 is invalid: valid range is a finite value > 0"),
    ({"period_tol": 0.0}, r"period_tol=0.0 is invalid"),
    ({"control_after": 3}, r"control_after needs the gains"),
    ({"gains": (1.0, 2.0)}, r"gains is invalid: expected a Gains"),
    ({"engine": "gpu"}, r"engine='gpu' is invalid"),
    ({"workers": 0}, r"workers=0 is invalid"),
    ({"gains": Gains(-1.0, -1.0, 1e3)}, r"delay=1000.0 is invalid: valid range is 0 <= delay"),
])
def test_invalid_arguments_name_the_parameter(kwargs, message):
    args = {"dx_range": BOX[0], "dv_range": BOX[1], "nx": 2, "nv": 2, "transient": 2,
            "max_period": 2, "workers": 1}
    args.update(kwargs)
    with pytest.raises(ParameterError, match=message):
        basins(COEXIST, **args)


def test_no_default_box_at_grazing():
    with pytest.raises(ParameterError, match=r"delta_d=0.0 has no default box"):
        basins(STUDY, nx=2, nv=2)


# -------------------------------------------------------------------------- CLI
def _grazing(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "grazing_control.cli", "basins", *args],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def test_cli_writes_the_files_and_the_summary(tmp_path):
    run = _grazing("--delta-d", "-1.25e-5", "--dx=-1e-2:1e-2", "--dv=-1e-2:1e-2", "--nx", "6",
                   "--nv", "5", "--transient", "600", "--max-period", "8", "--workers", "1",
                   "--out", str(tmp_path / "b"), "--json")
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary == json.loads((tmp_path / "b.json").read_text())
    for ext in ("npz", "png", "svg"):
        assert (tmp_path / f"b.{ext}").stat().st_size > 500
    same = basins(COEXIST, dx_range=BOX[0], dv_range=BOX[1], nx=6, nv=5, transient=600,
                  max_period=8, workers=1)
    assert [a["label"] for a in summary["attractors"]] == [a.label for a in same.attractors]
    assert [a["fraction"] for a in summary["attractors"]] == same.fractions()
    assert sum(a["starts"] for a in summary["attractors"]) == 30
    with np.load(tmp_path / "b.npz") as f:   # plain numpy
        assert np.array_equal(f["attractor"], same.attractor)
        assert np.array_equal(f["final"], same.final)


def test_cli_takes_the_scene_from_a_parameter_file(tmp_path):
    """config/study.yaml is the study's first scene (Delta d = -5e-6): chaotic uncontrolled."""
    run = _grazing("--params", str(ROOT / "config" / "study.yaml"), "--nx", "2", "--nv", "2",
                   "--transient", "300", "--max-period", "8", "--workers", "1", "--no-png",
                   "--out", str(tmp_path / "s"))
    assert run.returncode == 0, run.stderr
    assert "basins at Delta d = -5e-06, uncontrolled" in run.stdout and "chaotic" in run.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json", "s.npz"]


@pytest.mark.parametrize("args,message", [
    (["--delta-d", "-1e-5", "--dx", "1:0"], "argument --dx: '1:0' is invalid: expected finite"),
    (["--delta-d", "-1e-5", "--dv=a:b"], "'a:b' is invalid: expected LO:HI"),
    (["--delta-d", "-1e-5", "--control-after", "3"], "--control-after needs the gains"),
    (["--delta-d", "-1e-5", "--c2", "-1", "--delay", "99"], "delay=99.0 is invalid"),
    (["--delta-d", "0"], "delta_d=0.0 has no default box"),
    (["--zeta", "0.02"], "--delta-d is required (or a --params FILE with delta_d)"),
    (["--delta-d", "-1e-5", "--nx", "0"], "argument --nx: '0' is invalid"),
])
def test_cli_bad_input_is_one_line_and_status_2(args, message, tmp_path):
    run = _grazing(*args, "--nx" if "--nx" not in args else "--nv", "2", "--out",
                   str(tmp_path / "x"))
    assert run.returncode == 2 and run.stdout == ""
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("grazing: error: ") and message in lines[0]
    assert not list(tmp_path.iterdir())

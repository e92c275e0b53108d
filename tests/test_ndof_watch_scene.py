"""The model watch of an n-DOF stream scene through the real nodes (issue 32;
ros/model_watch.py, dynamics/estimation/augmented.py (E12)): the two-mass chain at
Delta d = -1e-3 (tests/test_ndof_nodes.py's stream scene) with a sensor bias on x0, the
controller with estimate_bias and a consistency window."""

import math

import numpy as np
import pytest

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.estimation.consistency import ConsistencyMonitor
from grazing_control.recordings.analyze import analyze
from grazing_control.ros.model_watch import WATCH_FIELDS
from grazing_control.ros.recording import read_messages
from test_ndof_nodes import RATE, SIGMA, STREAM_DELAY, stream_scene

BIAS = 1e-4


@pytest.mark.parametrize("wall", [False, True], ids=["bias", "bias_and_wall"])
def test_a_biased_n_dof_stream_scene_publishes_the_bias_the_core_estimates(tmp_path, wall):
    """Lockstep, 40 periods, control from section 8, x0's position with a bias of 1e-4
    (sigma 1e-4, T/200), the controller with estimate_bias and consistency_window 10
    (and track_delta_d): one controller/model_watch row per section (WATCH_FIELDS),
    whose b^ and its standard error (and Delta d^ and its) are the core's
    (AugmentedStreamEstimator over the model file on the recorded samples and
    corrections) to 1e-9 relative, b^ ends within 3 se of the bias (se < 2e-6; measured
    0.23 se), Delta d^ within 3 se of the plant's (NaN when not estimated), the monitor
    finds the model consistent at the end (its verdict the core's monitor's), and the
    corrections are the core's k^T z^ on the same estimates; ``grazing analyze`` of the bag
    reports the last row's b^ (and Delta d^) with their standard errors."""
    n, on = 40, 8
    res, bag, model, design = stream_scene(
        tmp_path, n, on, sensor_bias=BIAS,
        controller={"estimate_bias": True, "consistency_window": 10, "track_delta_d": wall})
    logs = {k: open(v).read() for k, v in res.logs.items()}
    assert res.ok, (res, logs)
    assert "mismatch_sections=0" in logs["controller_node"], logs["controller_node"]
    # every answer in time: none substituted (the monitor's scipy.stats was loaded at
    # the first verdict, 11 s, and the simulator substituted six answers)
    assert "timeouts=0" in logs["sim_node"], logs["sim_node"]
    msgs = {}
    for m in read_messages(bag):
        msgs.setdefault(m.topic, []).append(m.message)

    def stamp(m):
        return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9

    stream = sorted(msgs["/oscillator/state"], key=stamp)
    corr = np.array([a.twist.linear.x for a in sorted(msgs["/controller/velocity_correction"],
                                                      key=stamp)])
    rows = sorted(msgs["/controller/model_watch"], key=stamp)
    assert len(rows) >= n and all(tuple(r.name) == WATCH_FIELDS for r in rows)
    node = np.array([r.position for r in rows[:n]])
    col = {name: i for i, name in enumerate(WATCH_FIELDS)}

    est = AugmentedStreamEstimator(model, SIGMA, "stream", model.period / RATE, bias=True,
                                   wall=wall, coordinate=0)
    monitor, verdict, core, due = ConsistencyMonitor(10), None, [], []
    for s in stream:
        due += est.add_sample(stamp(s), s.position[0], math.nan)
        while due and due[0][0] < n:
            k, _tk, e = due.pop(0)
            if est.innovation is not None:
                verdict = monitor.add(*est.innovation) or verdict
            core.append((est.bias, math.sqrt(est.params_cov[0, 0]),
                         math.nan if verdict is None else float(verdict.status == "mismatch"),
                         est.delta_d, math.sqrt(est.params_cov[1, 1])))
            dv = float(design.gains @ np.array(e.z)) if k >= on else 0.0
            assert abs(corr[k] - dv) <= 1e-12 * max(1.0, abs(dv)), k
            est.set_correction(k, corr[k], STREAM_DELAY)
    core = np.array(core)
    assert core.shape[0] == n
    got = node[:, [col["bias"], col["bias_se"]]]
    assert np.allclose(got, core[:, :2], rtol=1e-9, atol=1e-15), np.abs(got - core[:, :2]).max()
    seen = ~np.isnan(core[:, 2])
    assert seen[-1] and np.array_equal(node[seen, col["mismatch"]], core[seen, 2])
    assert node[-1, col["mismatch"]] == 0.0
    if wall:
        got = node[:, [col["delta_d"], col["delta_d_se"]]]
        assert np.allclose(got, core[:, 3:], rtol=1e-9, atol=1e-15), \
            np.abs(got - core[:, 3:]).max()
        dd, se = node[-1, col["delta_d"]], node[-1, col["delta_d_se"]]
        assert abs(dd - model.delta_d) <= 3.0 * se and se < 1e-6, (dd, se)
    else:
        assert np.all(np.isnan(node[:, col["delta_d"]]))
    b, se = node[-1, col["bias"]], node[-1, col["bias_se"]]
    assert abs(b - BIAS) <= 3.0 * se and se < 2e-6, (b, se)
    # grazing analyze reads the rows as for a 1-DOF bag: the last row's estimates
    last = np.array(rows[-1].position)
    report = analyze([bag], None, figures=False)
    entry = report["bags"][0]
    assert (f"* sensor bias estimate (last section): {last[col['bias']]:.6g} ± "
            f"{last[col['bias_se']]:.3g} (standard error)") in report["markdown"]
    watch = entry["model_watch"]
    assert watch["sections"] == len(rows)
    assert watch["bias"] == [last[col["bias"]], last[col["bias_se"]]]
    assert watch["mismatch_sections"] == int(np.sum([r.position[col["mismatch"]] == 1.0
                                                     for r in rows]))
    assert ("delta_d" in watch) == wall
    if wall:
        assert watch["delta_d"] == [last[col["delta_d"]], last[col["delta_d_se"]]]
    print(f"n-DOF watch scene: bias {b:.6g} +- {se:.2g}, delta_d "
          f"{node[-1, col['delta_d']]:.8g} +- {node[-1, col['delta_d_se']]:.2g}, nis "
          f"{node[-1, col['nis']]:.4g} of {node[-1, col['nis_dof']]:.0f} dof, resets {est.resets}")

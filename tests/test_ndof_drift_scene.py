"""The drifting wall of an n-DOF stream scene through the real nodes (issue 32;
plant/engine.py's ``delta_d_drift`` with a model file, dynamics/estimation/augmented.py
(E8, E12)): the two-mass chain of tests/test_ndof_nodes.py's stream scene, its wall
moving by ``DRIFT`` per period, the controller tracking Delta d (``track_delta_d``)."""

import math

import numpy as np

from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values
from grazing_control.ros.model_watch import WATCH_FIELDS
from grazing_control.ros.recording import read_messages
from test_ndof_nodes import CHAIN, RATE, SIGMA, STREAM_DD, STREAM_DELAY, stream_scene

#: The wall's drift per period and the filter's random walk of Delta d per period.
DRIFT, WALL_NOISE = 1e-6, 4e-6


def test_a_drifting_n_dof_wall_is_the_engines_and_the_controller_tracks_it(tmp_path):
    """Lockstep, 60 periods, control from section 8, x0's position (sigma 1e-4, T/200),
    the wall drifting by 1e-6 per period from Delta d = -1e-3 (6e-5 in all), the
    controller with track_delta_d (wall_noise 4e-6): the recorded Pi2 samples are the
    engine's with the drift and the recorded corrections, bit for bit (the simulator
    ran the drifting wall); the last model_watch row's Delta d^ lies within 3 standard
    errors of the wall of the last period it saw, Delta d + drift (k - 1) (measured
    -0.59 se, se 6.7e-6), and more than 3 standard errors from the wall at the start
    (measured 8.1: the tracking is not vacuous). The default wall_noise (1e-8) is tuned
    for a drift of 5e-10 per period: on this scene it lagged by 4.7e-5, 80 se. grazing
    analyze of the bag re-integrates each period at the drifted wall: its model check
    departs by rounding only (measured 2.2e-15; at the recorded constant Delta d 1.1e-3)."""
    n, on = 60, 8
    res, bag, model, _design = stream_scene(
        tmp_path, n, on, delta_d_drift=DRIFT,
        controller={"track_delta_d": True, "wall_noise": WALL_NOISE})
    logs = {k: open(v).read() for k, v in res.logs.items()}
    assert res.ok, (res, logs)
    assert f"delta_d_drift={DRIFT!r}" in logs["sim_node"], logs["sim_node"]
    msgs = {}
    for m in read_messages(bag):
        msgs.setdefault(m.topic, []).append(m.message)

    def stamp(m):
        return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9

    corr = [a.twist.linear.x for a in sorted(msgs["/controller/velocity_correction"],
                                             key=stamp)]
    pi2 = sorted(msgs["/oscillator/pi2"], key=stamp)
    eng = Engine(settings_from_values(
        {"delta_d": STREAM_DD, "delta_d_drift": DRIFT, "actuation_delay": STREAM_DELAY,
         "sensor_noise": SIGMA, "sensor_velocity": False, "sensor_seed": 7,
         "state_period": model.period / RATE}, str(CHAIN)))
    for k in range(n):
        ev = eng.sample()
        assert np.array_equal(np.array(ev.x + ev.v),
                              np.array(tuple(pi2[k].position) + tuple(pi2[k].velocity))), k
        eng.begin_period(float(corr[k]), STREAM_DELAY)
        eng.end_period()
    assert eng.section.model.delta_d == STREAM_DD + DRIFT * n

    rows = sorted(msgs["/controller/model_watch"], key=stamp)
    assert len(rows) >= n and all(tuple(r.name) == WATCH_FIELDS for r in rows)
    col = {name: i for i, name in enumerate(WATCH_FIELDS)}
    k = n - 1
    last = rows[k].position
    dd, se = last[col["delta_d"]], last[col["delta_d_se"]]
    wall = STREAM_DD + DRIFT * (k - 1)      # the wall of period k - 1, the last one seen
    assert math.isfinite(dd) and 0.0 < se < 1e-5, (dd, se)
    assert abs(dd - wall) <= 3.0 * se, (dd, wall, se)
    assert abs(dd - STREAM_DD) > 3.0 * se, (dd, se)
    print(f"n-DOF drifting wall: section {k}, Delta d^ {dd:.8g} +- {se:.2g}, plant "
          f"{wall:.8g} ({(dd - wall) / se:+.2f} se; {(dd - STREAM_DD) / se:+.1f} se from "
          f"the start)")
    # grazing analyze re-integrates each period at the plant's Delta d of that period
    # (issue 32: at the recorded constant Delta d it departed by 1.1e-3): the report names
    # the drift and the model check reproduces the drifting wall to rounding
    from grazing_control.recordings.analyze import analyze

    report = analyze([bag], tmp_path / "report", figures=False)
    assert f"the plant's wall drifted (delta_d_drift={DRIFT:g} per period)" in \
        report["markdown"], report["markdown"][:2000]
    check = report["bags"][0]["scenes"][0]["model_check"]
    assert check["delta_d_drift"] == DRIFT and check["periods"] >= n - 1, check
    assert check["max_departure"] < 1e-12, check
    print(f"n-DOF drifting wall: model check {check['max_departure']:.2e} over "
          f"{check['periods']} periods")

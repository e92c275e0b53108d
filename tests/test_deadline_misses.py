"""Recorded deadline misses in the analysis and the replay: a correction the simulator
dropped (it arrived after its scheduled actuation time) did not act, so the model check
and the simulator replay apply 0 for it and the recording is reproduced to rounding;
without the miss messages the same bag departs (issue 19 §4)."""

import math

import numpy as np
import pytest

from grazing_control.dynamics.design import degenerate_c1
from grazing_control.dynamics.simulate import period_step
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.recordings.analyze import analyze
from grazing_control.ros.recording import record

from bagtools_helpers import joint_state, string, twist_stamped, vector3_stamped, write_rosbags

DD, DELAY, ON, N = -9e-6, 6.0, 0, 320
MISSES = (25, 60, 61, 200)
_NS = 1_000_000_000


def _scene():
    """A realtime-like scene with scheduled actuation: the plant skips the corrections of
    MISSES (recorded as answered, too late)."""
    p = OscillatorParams(delta_d=DD)
    g = Gains(degenerate_c1(p, -1.0, DELAY), -1.0, DELAY)
    dx, dv = (p.x_ref + 1e-3) - p.x_ref, (p.v_ref - 2e-3) - p.v_ref   # as sim_node's x0, v0
    rows = []
    for k in range(N):
        x, v = p.x_ref + dx, p.v_ref + dv
        u = g.c1 * dx + g.c2 * dv if k >= ON else 0.0
        rows.append((k, x, v, u))
        seg = period_step(p, dx, dv, 0.0 if k in MISSES else u, delay=DELAY)
        dx, dv = seg.dx, seg.dv
    return p, g, rows


def _bag(path, with_misses: bool):
    p, g, rows = _scene()
    msgs = [("/grazing/parameters", "std_msgs/msg/String", 0, string(record.encode(
                "/sim_node", {"delta_d": DD, "mode": "realtime", "time_scale": 1000.0,
                              "actuation_delay": DELAY}))),
            ("/grazing/parameters", "std_msgs/msg/String", 0, string(record.encode(
                "/controller_node", {"c1": g.c1, "c2": g.c2, "enable_after": ON,
                                     "actuation_delay": DELAY, "saturation": math.inf})))]
    for k, x, v, u in rows:
        st = int(round(k * p.period * _NS))
        t = 1_000_000 + 10 * k
        msgs.append(("/oscillator/pi2", "sensor_msgs/msg/JointState", t, joint_state(st, x, v)))
        msgs.append(("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped", t + 1,
                     twist_stamped(st, u)))
        if with_misses and k in MISSES:
            msgs.append(("/oscillator/deadline_miss", "geometry_msgs/msg/Vector3Stamped", t + 2,
                         vector3_stamped(st, float(k), k * p.period + DELAY, 0.004)))
    return write_rosbags(path, msgs)


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("misses")
    return {w: analyze([_bag(tmp / f"bag{w}", w)], tmp / f"out{w}", figures=False)["bags"][0]
            for w in (True, False)}


def test_the_model_check_applies_nothing_for_a_dropped_correction(reports):
    mc = reports[True]["scenes"][0]["model_check"]
    assert mc["dropped_at_deadline_misses"] == len(MISSES)
    assert mc["max_departure"] < 1e-12 and mc["periods_above_1e-12"] == 0


def test_without_the_miss_messages_the_dropped_corrections_show_as_departures(reports):
    mc = reports[False]["scenes"][0]["model_check"]
    assert mc["dropped_at_deadline_misses"] == 0
    assert mc["periods_above_1e-12"] == len(MISSES)


def test_scheduled_actuation_is_not_explained_by_arrival_times(reports):
    rt = reports[True]["scenes"][0]["realtime"]
    assert rt is not None and rt.get("delay_check") is None


def test_the_simulator_replay_zeroes_the_dropped_corrections(tmp_path):
    """Through sim_node (lockstep, scheduled actuation), open loop: every sample of the
    recording is reproduced bit for bit once the dropped corrections are replayed as 0."""
    from grazing_control.recordings.replay import replay_simulator
    from test_closed_loop import new_domain

    bag = _bag(tmp_path / "bag", True)
    res = replay_simulator(bag, tmp_path / "replayed", domain_id=new_domain())
    assert res["samples_replayed"] == N and res["stamps_equal"]
    assert res["bit_identical_samples"] == N, res
    assert any(f"{len(MISSES)} samples had a deadline miss" in n for n in res["notes"])


def test_without_the_miss_messages_the_replay_departs_at_the_first_miss(tmp_path):
    from grazing_control.recordings.replay import replay_simulator
    from test_closed_loop import new_domain

    res = replay_simulator(_bag(tmp_path / "bag", False), tmp_path / "replayed",
                           domain_id=new_domain())
    assert res["first_sample_above_1e-12"] == MISSES[0] + 1, res

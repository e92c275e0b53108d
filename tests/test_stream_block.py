"""The sensor stream in blocks (``stream_message: block``, grazing_control/ros/stream_block.py;
issue 30): the wire format against rclpy's, hostile messages refused, and a lockstep
stream scene in blocks that is the per-sample scene bit for bit, recorded and read back."""

from __future__ import annotations

import math
import random
from pathlib import Path

import numpy as np
import pytest

from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros import launcher, stream_block

from test_closed_loop import Collector, new_domain

pytestmark = pytest.mark.timeout(240)

P = OscillatorParams(delta_d=-5e-6)
RATE, PERIODS, ON = 200, 80, 30      # the rig stream at T/200, as issue 30's scene


def _message(flat, labels=("sample", "sec,nanosec,x,v,cos_tau,sin_tau")):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    n = len(flat) // 6
    m = Float64MultiArray()
    m.layout.dim = [MultiArrayDimension(label=labels[0], size=n, stride=6 * n),
                    MultiArrayDimension(label=labels[1], size=6, stride=6)]
    m.data = list(flat)
    return m


def _rows(rng, n):
    flat = []
    for _ in range(n):
        flat += [float(rng.randrange(0, 2**31)), float(rng.randrange(0, 10**9)),
                 rng.uniform(-3, 3), rng.choice([math.nan, rng.uniform(-3, 3)]),
                 rng.uniform(-1, 1), rng.uniform(-1, 1)]
    return flat


def _same(a, b) -> bool:
    return len(a) == len(b) and all(x == y or (math.isnan(x) and math.isnan(y))
                                    for x, y in zip(a, b))


def test_a_block_is_rclpys_float64multiarray_both_ways():
    """pack() has rclpy's serialized length and rclpy reads it back; read() takes what
    rclpy serializes (its padding is not zeroed: the fields only are compared), on
    seeded random rows of 1 to 40 samples."""
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray

    rng = random.Random(30)
    for n in list(range(1, 12)) + [40]:
        flat = _rows(rng, n)
        ours, theirs = stream_block.pack(flat), serialize_message(_message(flat))
        assert len(ours) == len(theirs)
        assert _same(list(deserialize_message(ours, Float64MultiArray).data), flat)
        assert _same(stream_block.read(theirs), flat) and _same(stream_block.read(ours), flat)
        rows = list(stream_block.rows_of(stream_block.read(ours)))
        assert len(rows) == n and rows[0][:2] == (int(flat[0]), int(flat[1]))
        assert rows[-1][4] == (flat[-2], flat[-1])


@pytest.mark.parametrize("case", ["empty", "garbage", "truncated", "padded", "labels",
                                  "five fields", "fraction of a ns", "negative sec",
                                  "ns of a second", "nan stamp", "big endian"])
def test_a_message_that_is_not_a_block_is_none_never_an_exception(case):
    from rclpy.serialization import serialize_message

    flat = [1.0, 2.0, 0.1, math.nan, 1.0, 0.0, 1.0, 3.0, 0.2, math.nan, 0.9, 0.1]
    good = stream_block.pack(flat)
    data = {"empty": b"", "garbage": b"\x00\x01\x00\x00" + bytes(range(200)),
            "truncated": good[:-8], "padded": good + b"\x00" * 16,
            "labels": serialize_message(_message(flat, ("samples", "t,x,v"))),
            "five fields": stream_block.pack(flat[:5]),
            "fraction of a ns": stream_block.pack([1.0, 2.5] + flat[2:]),
            "negative sec": stream_block.pack([-1.0] + flat[1:]),
            "ns of a second": stream_block.pack([1.0, 1e9] + flat[2:]),
            "nan stamp": stream_block.pack([math.nan] + flat[1:]),
            "big endian": b"\x00\x00\x00\x00" + good[4:]}[case]
    assert stream_block.read(data) is None


def test_a_block_gathers_rows_until_taken():
    b = stream_block.Block()
    assert b.take() is None and len(b) == 0
    b.add(0, 5, 0.5, None, 1.0, 0.0)
    b.add(0, 10, 0.6, -0.1, 0.5, 0.5)
    assert len(b) == 2
    flat = stream_block.read(b.take())
    assert _same(flat, [0.0, 5.0, 0.5, math.nan, 1.0, 0.0, 0.0, 10.0, 0.6, -0.1, 0.5, 0.5])
    assert len(b) == 0 and b.take() is None


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """One lockstep stream scene (position-only sensor at T/200, sigma 1e-4, model
    estimator, control from period ON, recorder on) with a message per sample and the
    same in blocks: {mode: (RunResult, bag)}."""
    tmp = tmp_path_factory.mktemp("stream_block")
    out = {}
    for mode in stream_block.MESSAGES:
        res = launcher.run(
            None, None, tmp / mode / "bag", PERIODS, delta_d=P.delta_d, enable_after=ON,
            mode="lockstep", domain_id=new_domain(), timeout=200,
            sim_overrides={"state_period": P.period / RATE, "sensor_noise": 1e-4,
                           "sensor_velocity": False, "sensor_seed": 7,
                           "stream_message": mode},
            controller_overrides={"pi2_source": "stream", "estimator": "model"},
            log_dir=tmp / mode / "logs")
        out[mode] = (res, tmp / mode / "bag")
    return out


def test_the_stream_in_blocks_is_the_stream_of_samples_bit_for_bit(scenes):
    """Blocks on oscillator/state_block (nothing on oscillator/state): the controller's
    estimates and corrections and the simulator's Pi2 samples are the per-sample scene's
    bit for bit; every block recorded (the recorder's tail check: complete); the bag's
    blocks read back (recordings.reader) are the per-sample bag's stream, stamp for stamp."""
    from grazing_control.recordings import reader
    from grazing_control.ros.recording import read_messages

    got = {}
    for mode, (res, bag) in scenes.items():
        assert res.ok, (res, Path(res.logs["sim_node"]).read_text())
        assert launcher.recorded_losses(bag) == ""
        msgs = {}
        for m in read_messages(bag):
            msgs.setdefault(m.topic, []).append(m.message)
        got[mode] = msgs
    per_sample, blocks = got["sample"], got["block"]
    assert "/oscillator/state_block" not in per_sample and "/oscillator/state" not in blocks
    n = int(math.floor(PERIODS * RATE)) + 1
    assert len(per_sample["/oscillator/state"]) == n
    assert len(blocks["/oscillator/state_block"]) == PERIODS + 1   # t = 0, then a period each
    for topic, fields in (("/controller/velocity_correction", lambda m: (m.twist.linear.x,
                                                                         m.twist.linear.y)),
                          ("/controller/estimate", lambda m: tuple(m.position)
                           + tuple(m.velocity) + tuple(m.effort)),
                          ("/oscillator/pi2", lambda m: (m.position[0], m.velocity[0]))):
        a = np.array([fields(m) for m in per_sample[topic]])
        b = np.array([fields(m) for m in blocks[topic]])
        assert a.shape == b.shape and a.shape[0] >= PERIODS, topic
        np.testing.assert_array_equal(a, b, err_msg=topic)
    assert np.any(np.array([m.twist.linear.x for m in blocks["/controller/velocity_correction"]])
                  != 0.0)
    raw_s = reader.read_raw(scenes["sample"][1])
    raw_b = reader.read_raw(scenes["block"][1])
    s = reader.decode_joint_stream(raw_s, "/oscillator/state")
    b = reader.decode_state_blocks(raw_b, "/oscillator/state_block")
    assert b["ok"].all() and b["stamp"].size == n
    np.testing.assert_array_equal(b["stamp"], s["stamp"])
    for col in ("x", "v", "e0", "e1"):
        np.testing.assert_array_equal(b[col], s[col], err_msg=col)
    assert np.all(np.isnan(b["v"]))           # a position-only sensor


def test_grazing_analyze_and_identify_read_a_bag_in_blocks(scenes, tmp_path):
    """analyze counts the blocks and does not call the stream absent; identify fits the
    same parameters from the blocks as from the samples (the same numbers: the same
    stream)."""
    from grazing_control.recordings.analyze import analyze
    from grazing_control.recordings.identify import load_recording

    rep = analyze([scenes["block"][1]], tmp_path / "report", figures=False)
    used = rep["bags"][0]["topics_used"]
    assert used["state_block"] == "/oscillator/state_block"
    assert "state_block" not in " ".join(rep["bags"][0].get("notes", []))
    rec_s, _, _ = load_recording(scenes["sample"][1], position_only=True)
    rec_b, _, _ = load_recording(scenes["block"][1], position_only=True)
    np.testing.assert_array_equal(rec_b.t, rec_s.t)
    np.testing.assert_array_equal(rec_b.x, rec_s.x)


def test_a_controller_takes_a_block_and_refuses_a_malformed_one(tmp_path):
    """controller_node with stream_message block: a Float64MultiArray of another layout
    and a truncated block are counted malformed (one line each, no crash); a block of a
    period's samples that completes section 1 is answered."""
    from geometry_msgs.msg import TwistStamped
    from std_msgs.msg import Float64MultiArray

    from grazing_control.ros.common import DATA_QOS

    domain = new_domain()
    col = Collector(domain, {"controller/velocity_correction": TwistStamped})
    log = tmp_path / "controller.log"
    proc = launcher.start_node(
        launcher.CONTROLLER_MODULE, [launcher.CONFIG_DIR / "controller.yaml"],
        {"pi2_source": "stream", "estimator": "nearest", "stream_message": "block",
         "delta_d": P.delta_d, "enable_after": 0, "state_period": P.period / 50},
        domain_id=domain, log=log)
    try:
        pub = col.node.create_publisher(Float64MultiArray, stream_block.TOPIC, DATA_QOS)
        assert col.wait_for(lambda: pub.get_subscription_count() > 0 and col.subs[
            "controller/velocity_correction"].get_publisher_count() > 0, 30.0), log.read_text()
        assert col.controller_matched(stream_block.TOPIC), log.read_text()   # its ends too
        pub.publish(_message([1.0] * 6, ("samples", "t,x,v")))
        pub.publish(stream_block.pack([0.0] * 12)[:-8])
        block = stream_block.Block()
        h = P.period / 50
        for j in range(0, 52):
            sec, ns = divmod(int(round(j * h * 1e9)), 10**9)
            psi = P.tau2 + P.omega * j * h - P.lag
            block.add(sec, ns, P.amplitude * math.cos(psi), None, math.cos(P.tau2 + P.omega
                      * j * h), math.sin(P.tau2 + P.omega * j * h))
        pub.publish(block.take())
        assert col.wait_for(lambda: len(col.get("controller/velocity_correction")) >= 1,
                            20.0), log.read_text()
        proc.send_signal(2)
        assert proc.wait(15) == 0
    finally:
        launcher.stop_nodes([proc])
        col.close()
    text = log.read_text()
    assert "Traceback" not in text
    assert "not a stream block" in text, text
    assert "malformed=2" in text, text


@pytest.mark.parametrize("over, message", [
    ({"stream_message": "blocks"}, "stream_message='blocks' is invalid: valid values are "
                                   "sample, block"),
    ({"stream_message": "block", "model_file": str(launcher.CONFIG_DIR / "models" /
                                                   "two_mass_chain.yaml")},
     "stream_message='block' is invalid with model_file=")])
def test_sim_node_refuses_a_stream_message_it_cannot_send(tmp_path, over, message):
    """One line naming the parameter, exit status 2 (the n-DOF stream is not in blocks)."""
    log = tmp_path / "sim.log"
    proc = launcher.start_node(launcher.SIM_MODULE, [launcher.CONFIG_DIR / "study.yaml"], over,
                               domain_id=new_domain(), log=log)
    assert proc.wait(60) == 2
    text = log.read_text()
    assert message in text and "Traceback" not in text, text


def test_the_samples_before_a_section_go_out_before_its_pi2_sample():
    """Realtime: a wake-up's block used to go out at the wake-up's end, after the Pi2
    sample and the period's integration that follows it (issue 30: the section's last
    samples reached the controller 1.09 ms after the Pi2 sample at p50, load 10; 0.10 ms
    now). The block is published before the Pi2 sample, with the samples before t_k only;
    what comes after it goes in the next block."""
    import types

    from grazing_control.plant.engine import Event
    from sim_node.messages import Outputs

    sent = []

    class Pub:
        def __init__(self, topic):
            self.topic = topic

        def publish(self, data):
            sent.append((self.topic, data))

    param = types.SimpleNamespace(value="block")
    node = types.SimpleNamespace(
        get_logger=lambda: types.SimpleNamespace(warning=print), driver=None,
        get_parameter=lambda name: param,
        settings=types.SimpleNamespace(mode="realtime",
                                       sensor=types.SimpleNamespace(velocity=False)),
        pub_state_block=Pub("block"), pub_pi2=Pub("pi2"), pub_clock=Pub("clock"))
    out = Outputs(node)
    for t in (0.9, 0.95):
        out.publish(Event(t, "state", 0.1, -0.2, 0.3))
    out.publish(Event(1.0, "pi2", 0.0, -1.2, 0.3))
    out.publish(Event(1.05, "state", 0.2, -0.1, 0.3))
    out.end_of_wake_up()
    assert [topic for topic, _ in sent] == ["block", "pi2", "block"]
    rows = [list(stream_block.rows_of(stream_block.read(data))) for topic, data in sent
            if topic == "block"]
    from grazing_control.ros import cdr

    assert [[tuple(r[:2]) for r in b] for b in rows] == [
        [cdr.stamp_parts(0.9), cdr.stamp_parts(0.95)], [cdr.stamp_parts(1.05)]]

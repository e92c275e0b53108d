"""bagtools.reader: the columnar MCAP reader agrees with mcap_ros2 and rosbags, message for
message, on the reference bags, on bags of another writer with random layouts (fuzzed),
on every compression, and on files cut at any byte (a killed recorder)."""

import random

import numpy as np
import pytest

from grazing_control.recordings import reader
from grazing_control.ros.recording import BagWriter, read_messages

from bagtools_helpers import BAGS, TYPESTORE, joint_state, twist_stamped, vector3_stamped, \
    write_rosbags


@pytest.mark.parametrize("name", ["scene_5e-6", "scene_9e-6"])
def test_reference_bags_decode_equal_to_mcap_ros2(name):
    raw = reader.read_raw(BAGS / name)
    assert raw.complete and raw.problems == []
    ref = {"/oscillator/pi2": [], "/controller/velocity_correction": [], "/oscillator/impact": []}
    for m in read_messages(BAGS / name, topics=list(ref)):
        ref[m.topic].append(m)
    js = reader.decode_joint_state(raw, "/oscillator/pi2")
    tw = reader.decode_twist_stamped(raw, "/controller/velocity_correction")
    im = reader.decode_vector3_stamped(raw, "/oscillator/impact")
    for cols, msgs in ((js, ref["/oscillator/pi2"]), (tw, ref["/controller/velocity_correction"]),
                       (im, ref["/oscillator/impact"])):
        assert cols["ok"].all() and len(cols["ok"]) == len(msgs)
        stamps = [m.message.header.stamp.sec * 10**9 + m.message.header.stamp.nanosec for m in msgs]
        assert cols["stamp"].tolist() == stamps
        assert cols["log_time"].tolist() == [m.log_time_ns for m in msgs]
    assert js["x"].tolist() == [m.message.position[0] for m in ref["/oscillator/pi2"]]
    assert js["v"].tolist() == [m.message.velocity[0] for m in ref["/oscillator/pi2"]]
    assert tw["dv"].tolist() == [m.message.twist.linear.x
                                 for m in ref["/controller/velocity_correction"]]
    assert im["vz"].tolist() == [m.message.vector.z for m in ref["/oscillator/impact"]]


def test_fuzzed_layouts_of_another_writer_decode_like_rosbags(tmp_path):
    """3000 JointStates with random frame ids, name lists and sequence lengths (every
    alignment case of the CDR layout) written by rosbags: decoded equal to brute force."""
    rng = random.Random(9)
    msgs, truth = [], []
    for k in range(3000):
        frame = "f" * rng.randrange(0, 10)
        count = rng.randrange(0, 4) if rng.random() > 0.02 else rng.randrange(60, 90)
        names = ["n" * rng.randrange(0, 7) for _ in range(count)]
        x = rng.uniform(-1, 1) if rng.random() > 0.05 else None
        v = rng.uniform(-1, 1) if rng.random() > 0.05 else None
        extra = [rng.uniform(-1, 1) for _ in range(rng.randrange(0, 3))]
        stamp = rng.randrange(0, 2**31) * 10**9 + rng.randrange(0, 10**9)
        msgs.append(("/oscillator/pi2", "sensor_msgs/msg/JointState", k,
                     joint_state(stamp, x, v, frame_id=frame, names=names, extra=extra)))
        truth.append((stamp, x, v))
        if k % 3 == 0:
            msgs.append(("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped", k,
                         twist_stamped(stamp, rng.uniform(-1, 1), frame_id=frame)))
        if k % 5 == 0:
            msgs.append(("/extra", "geometry_msgs/msg/Vector3Stamped", k,
                         vector3_stamped(stamp, 1.0, 2.0, 3.0)))
    bag = write_rosbags(tmp_path / "other", msgs)
    raw = reader.read_raw(bag)
    assert raw.complete
    js = reader.decode_joint_state(raw, "/oscillator/pi2")
    assert js["stamp"].tolist() == [s for s, _, _ in truth]
    usable = [x is not None and v is not None for _, x, v in truth]
    assert js["ok"].tolist() == usable
    assert js["x"][js["ok"]].tolist() == [x for (s, x, v), u in zip(truth, usable) if u]
    assert js["v"][js["ok"]].tolist() == [v for (s, x, v), u in zip(truth, usable) if u]
    tw = reader.decode_twist_stamped(raw, "/controller/velocity_correction")
    want = [m[3].twist.linear.x for m in msgs if m[0] == "/controller/velocity_correction"]
    assert tw["ok"].all() and tw["dv"].tolist() == want


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_every_chunk_compression(tmp_path, compression):
    bag = BagWriter(tmp_path / "b", compression=compression, chunk_size=4096).open()
    bag.add_topic("/oscillator/pi2", "sensor_msgs/msg/JointState")
    for k in range(500):
        data = TYPESTORE.serialize_cdr(joint_state(k * 10**9, k * 0.5, -k * 0.25),
                                       "sensor_msgs/msg/JointState")
        bag.write("/oscillator/pi2", bytes(data), 1000 + k)
    bag.close()
    js = reader.decode_joint_state(reader.read_raw(tmp_path / "b"), "/oscillator/pi2")
    assert js["ok"].all() and js["x"].tolist() == [k * 0.5 for k in range(500)]
    assert js["log_time"].tolist() == [1000 + k for k in range(500)]


def test_a_file_cut_anywhere_reads_a_prefix_and_says_so(tmp_path):
    """A killed recorder leaves a file without summary, torn at any byte: never an
    exception, always the first messages, flagged as incomplete."""
    full = (BAGS / "scene_5e-6" / "scene_5e-6_0.mcap").read_bytes()
    ref = reader.decode_joint_state(reader.read_raw(BAGS / "scene_5e-6"), "/oscillator/pi2")
    rng = random.Random(1)
    cuts = sorted(rng.sample(range(9, len(full) - 200), 60)) + [len(full) - 1]
    counts = []
    for i, cut in enumerate(cuts):
        path = tmp_path / f"cut{i}.mcap"
        path.write_bytes(full[:cut])
        raw = reader.read_raw(path)
        js = reader.decode_joint_state(raw, "/oscillator/pi2")
        n = len(js["stamp"])
        assert js["ok"].all()
        if n < len(ref["stamp"]):       # cut inside the data section (not in the summary)
            assert not raw.complete and "no summary" in raw.problems[0]
        assert js["stamp"].tolist() == ref["stamp"][:n].tolist()
        assert js["x"].tolist() == ref["x"][:n].tolist()
        counts.append(n)
    assert counts == sorted(counts) and counts[-1] == len(ref["stamp"])


def test_malformed_message_bytes_are_flagged_never_read_past_their_end(tmp_path):
    rng = np.random.default_rng(5)
    good = bytes(TYPESTORE.serialize_cdr(joint_state(7, 0.5, 0.25), "sensor_msgs/msg/JointState"))
    bag = BagWriter(tmp_path / "b", chunk_size=2048).open()
    bag.add_topic("/oscillator/pi2", "sensor_msgs/msg/JointState")
    payloads = []
    for k in range(2000):
        kind = k % 4
        if kind == 0:
            data = good
        elif kind == 1:
            data = good[:rng.integers(0, len(good))]           # truncated
        elif kind == 2:
            data = bytes(rng.integers(0, 256, rng.integers(0, 80), dtype=np.uint8))
        else:                                                  # huge lengths inside
            b = bytearray(good)
            b[12:16] = (0xFFFFFFF0).to_bytes(4, "little")
            data = bytes(b)
        payloads.append(data)
        bag.write("/oscillator/pi2", data, k)
    bag.close()
    js = reader.decode_joint_state(reader.read_raw(tmp_path / "b"), "/oscillator/pi2")
    ok = js["ok"]
    assert ok[0::4].all() and not ok[3::4].any()
    assert (js["x"][ok] == 0.5).all() and (js["v"][ok] == 0.25).all()


def test_not_an_mcap_file_is_refused_with_a_reason(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"not a bag at all")
    with pytest.raises(reader.BagReadError, match="not an MCAP file"):
        reader.read_raw(tmp_path / "x.mcap")
    (tmp_path / "empty").mkdir()
    with pytest.raises(reader.BagReadError, match="no .mcap file"):
        reader.read_raw(tmp_path / "empty")
    with pytest.raises(reader.BagReadError, match="no such bag"):
        reader.read_raw(tmp_path / "missing")


def test_corrupted_bytes_anywhere_give_a_result_or_a_one_line_error(tmp_path):
    """Seeded fuzzing: 150 copies of a bag with random bytes changed (records, lengths,
    chunk data): the analysis loader either reads it (a corrupt chunk is skipped and named)
    or refuses it with a ValueError; never another exception, never a hang."""
    from mcap.reader import make_reader

    from grazing_control.recordings.scenes import load

    clean = tmp_path / "clean"
    with open(BAGS / "scene_9e-6" / "scene_9e-6_0.mcap", "rb") as fh, \
            BagWriter(clean, compression="none", chunk_size=4096) as w:
        for schema, channel, msg in make_reader(fh).iter_messages():
            if not w.has_topic(channel.topic):
                w.add_topic(channel.topic, schema.name)
            w.write(channel.topic, msg.data, msg.log_time)
    full = (clean / "clean_0.mcap").read_bytes()
    rng = random.Random(11)
    path = tmp_path / "fuzz.mcap"
    outcomes = {"read": 0, "refused": 0, "chunk skipped": 0}
    for _ in range(150):
        b = bytearray(full)
        for _ in range(rng.randrange(1, 8)):
            b[rng.randrange(8, len(b))] = rng.randrange(256)
        path.write_bytes(bytes(b))
        try:
            data = load(path)
        except ValueError as exc:
            assert "\n" not in str(exc)
            outcomes["refused"] += 1
            continue
        outcomes["read"] += 1
        outcomes["chunk skipped"] += any("corrupt" in p for p in data.problems)
    assert outcomes["read"] > 50 and outcomes["chunk skipped"] > 25, outcomes


def test_a_file_compressed_as_a_whole_is_read(tmp_path):
    """rosbag2's "file" compression mode writes <bag>_0.mcap.zstd."""
    import zstandard

    data = (BAGS / "scene_5e-6" / "scene_5e-6_0.mcap").read_bytes()
    (tmp_path / "whole").mkdir()
    (tmp_path / "whole" / "whole_0.mcap.zstd").write_bytes(
        zstandard.ZstdCompressor().compress(data))
    js = reader.decode_joint_state(reader.read_raw(tmp_path / "whole"), "/oscillator/pi2")
    ref = reader.decode_joint_state(reader.read_raw(BAGS / "scene_5e-6"), "/oscillator/pi2")
    assert js["x"].tolist() == ref["x"].tolist() and len(ref["x"]) == 1300

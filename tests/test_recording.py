"""Tests of grazing_control.ros.recording: rosbag2-style MCAP bags without ROS.

Bags are written with :class:`BagWriter` from messages serialized by
``mcap_ros2``'s CDR encoder, then read back with two independent readers
(``mcap_ros2``'s decoder and ``rosbags``) and compared field by field with
the ``rclpy`` message objects they were made from.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistStamped, Vector3Stamped
from mcap.reader import SeekingReader, breakup_chunk
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory
from mcap.records import Schema
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_types_from_msg
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from grazing_control.ros.recording import (BagWriter, DEFAULT_CHUNK_SIZE, bag_file,
                                           message_definition, message_to_dict,
                                           qos_profile_dict, qos_profiles_yaml, read_messages,
                                           read_messages_rosbags, read_metadata,
                                           type_description_hash)

REPO = Path(__file__).resolve().parents[1]

# The project's topics (docs/recording.md) and a message factory for each.
TOPICS = {
    "/oscillator/state": "sensor_msgs/msg/JointState",
    "/oscillator/impact": "geometry_msgs/msg/Vector3Stamped",
    "/oscillator/pi1": "sensor_msgs/msg/JointState",
    "/oscillator/pi2": "sensor_msgs/msg/JointState",
    "/controller/velocity_correction": "geometry_msgs/msg/TwistStamped",
    "/clock": "rosgraph_msgs/msg/Clock",
}


def _stamp(i):
    return Time(sec=i // 1000, nanosec=(i % 1000) * 1_000_000)


def make_message(msg_type, i):
    """A message of `msg_type` whose every field depends on `i`."""
    if msg_type == "sensor_msgs/msg/JointState":
        msg = JointState(name=["mass"], position=[0.001 * i], velocity=[-0.5 + i / 3],
                         effort=[(-1.0) ** i])
    elif msg_type == "geometry_msgs/msg/Vector3Stamped":
        msg = Vector3Stamped()
        msg.vector.x, msg.vector.y, msg.vector.z = -0.1 * i, 0.08 * i, (i % 6) * 1.0
    elif msg_type == "geometry_msgs/msg/TwistStamped":
        msg = TwistStamped()
        msg.twist.linear.x = 1e-6 * i
    elif msg_type == "rosgraph_msgs/msg/Clock":
        return Clock(clock=_stamp(i))
    else:
        raise ValueError(msg_type)
    msg.header.stamp = _stamp(i)
    msg.header.frame_id = f"frame{i % 3}"
    return msg


_ENCODERS = {}


def encode(msg_type, msg):
    """CDR bytes of an rclpy message, by mcap_ros2's encoder from our schema."""
    if msg_type not in _ENCODERS:
        _ENCODERS[msg_type] = serialize_dynamic(msg_type, message_definition(msg_type))[msg_type]
    return _ENCODERS[msg_type](msg)


def write_bag(bag_dir, n_per_topic, **kwargs):
    """Write `n_per_topic` messages on each project topic, interleaved.

    Returns the list of (topic, type, log_time_ns, rclpy message) in write order.
    """
    written = []
    qos = [qos_profile_dict(history="keep_all", reliability="reliable")]
    with BagWriter(bag_dir, **kwargs) as bag:
        for topic, msg_type in TOPICS.items():
            bag.add_topic(topic, msg_type, qos)
        t = 1_700_000_000_000_000_000
        for i in range(n_per_topic):
            for topic, msg_type in TOPICS.items():
                t += 1000
                msg = make_message(msg_type, i)
                bag.write(topic, encode(msg_type, msg), t, t - 10, sequence=i + 1)
                written.append((topic, msg_type, t, msg))
    return written


def assert_same_messages(got, expected):
    assert len(got) == len(expected)
    for g, (topic, msg_type, t, msg) in zip(got, expected):
        assert (g.topic, g.type, g.log_time_ns) == (topic, msg_type, t)
        assert message_to_dict(g.message) == message_to_dict(msg)


# ---------------------------------------------------------------- schemas


@pytest.mark.parametrize("msg_type", sorted(set(TOPICS.values())))
def test_schema_text_parses_with_both_readers(msg_type):
    text = message_definition(msg_type)
    decoder = DecoderFactory().decoder_for(
        "cdr", Schema(id=1, name=msg_type, encoding="ros2msg", data=text.encode()))
    msg = make_message(msg_type, 7)
    assert message_to_dict(decoder(encode(msg_type, msg))) == message_to_dict(msg)
    types = get_types_from_msg(text, msg_type)
    assert msg_type in types


def test_schema_text_layout_follows_rosbag2():
    text = message_definition("geometry_msgs/msg/TwistStamped")
    share = Path(sys.prefix) / "share"
    main = (share / "geometry_msgs" / "msg" / "TwistStamped.msg").read_text()
    assert text.startswith(main)
    sep = "\n" + "=" * 80 + "\nMSG: "
    headers = [part.split("\n", 1)[0] for part in text.split(sep)[1:]]
    # depth first, dependencies of one message in sorted order, each once
    assert headers == ["geometry_msgs/Twist", "geometry_msgs/Vector3",
                       "std_msgs/Header", "builtin_interfaces/Time"]
    assert len(text.split(sep)) == 5


def test_type_description_hash_is_rihs01():
    h = type_description_hash("sensor_msgs/msg/JointState")
    assert h.startswith("RIHS01_") and len(h) == len("RIHS01_") + 64
    assert type_description_hash("sensor_msgs/JointState") == h


def test_unknown_type_is_a_lookup_error():
    with pytest.raises(LookupError, match="NoSuchMsg"):
        message_definition("sensor_msgs/msg/NoSuchMsg")
    with pytest.raises(ValueError):
        message_definition("JointState")


@pytest.fixture
def fake_package(tmp_path, monkeypatch):
    """A package `fake_msgs` found through the ament index only."""
    prefix = tmp_path / "prefix"
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages"
    marker.mkdir(parents=True)
    (marker / "fake_msgs").write_text("")
    msg_dir = prefix / "share" / "fake_msgs" / "msg"
    msg_dir.mkdir(parents=True)
    (msg_dir / "Thing.msg").write_text(
        "# A comment that mentions std_msgs/String and Part\n"
        "uint8 MODE_A=1  # a constant\n"
        'string GREETING="hi # not a comment"\n'
        "Header header   # bare Header: std_msgs/Header\n"
        "Part[] parts    # same package\n"
        "geometry_msgs/Vector3[3] corners\n"
        "geometry_msgs/Point origin\n"
        "string<=8 label\n"
        "float64[<=4] weights\n")
    (msg_dir / "Part.msg").write_text("builtin_interfaces/Time stamp\nfloat64 value\n")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    return prefix


def test_nested_types_in_every_form(fake_package):
    text = message_definition("fake_msgs/msg/Thing")
    headers = [line[5:] for line in text.splitlines() if line.startswith("MSG: ")]
    assert headers == ["fake_msgs/Part", "builtin_interfaces/Time", "geometry_msgs/Point",
                       "geometry_msgs/Vector3", "std_msgs/Header"]
    assert "std_msgs/String" not in headers        # comments are not fields
    types = get_types_from_msg(text, "fake_msgs/msg/Thing")
    assert {"fake_msgs/msg/Thing", "fake_msgs/msg/Part", "std_msgs/msg/Header"} <= set(types)
    decoder = DecoderFactory().decoder_for(
        "cdr", Schema(id=1, name="fake_msgs/msg/Thing", encoding="ros2msg", data=text.encode()))
    assert decoder is not None


def test_recording_module_does_not_import_rclpy():
    code = ("import sys, grazing_control.ros.recording as r; "
            "r.message_definition('sensor_msgs/msg/JointState'); "
            "sys.exit('rclpy' in sys.modules)")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    assert subprocess.run([sys.executable, "-c", code], env=env).returncode == 0


# ------------------------------------------------------------ round trip


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_round_trip_with_both_readers(tmp_path, compression):
    bag = tmp_path / "run"
    written = write_bag(bag, 300, compression=compression, chunk_size=8 * 1024)
    assert_same_messages(list(read_messages(bag)), written)
    assert_same_messages(list(read_messages_rosbags(bag)), written)


def test_topic_filter(tmp_path):
    written = write_bag(tmp_path / "run", 20)
    want = ["/oscillator/pi2", "/clock"]
    expected = [w for w in written if w[0] in want]
    assert_same_messages(list(read_messages(tmp_path / "run", topics=want)), expected)
    assert_same_messages(list(read_messages_rosbags(tmp_path / "run", topics=want)), expected)


def test_bytes_are_stored_verbatim(tmp_path):
    """rclpy-serialized bytes go in and come out unchanged."""
    msgs = [make_message("sensor_msgs/msg/JointState", i) for i in range(50)]
    data = [serialize_message(m) for m in msgs]
    with BagWriter(tmp_path / "bag") as bag:
        bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
        for i, d in enumerate(data):
            bag.write("/oscillator/state", d, 1000 + i)
    with open(bag_file(tmp_path / "bag"), "rb") as f:
        raw = [m.data for _, _, m in SeekingReader(f).iter_messages()]
    assert raw == data
    back = [deserialize_message(d, JointState) for d in raw]
    assert [message_to_dict(m) for m in back] == [message_to_dict(m) for m in msgs]
    decoded = [m.message for m in read_messages(tmp_path / "bag")]
    assert [message_to_dict(m) for m in decoded] == [message_to_dict(m) for m in msgs]


def test_metadata_yaml(tmp_path):
    bag = tmp_path / "run"
    written = write_bag(bag, 10, custom_data={"scene": "dd=-5e-6"})
    info = read_metadata(bag)
    assert info["version"] == 9
    assert info["storage_identifier"] == "mcap"
    assert info["ros_distro"] == "jazzy"
    assert info["relative_file_paths"] == ["run_0.mcap"]
    assert (bag / "run_0.mcap").is_file()
    assert info["message_count"] == len(written) == 60
    t0, t1 = written[0][2], written[-1][2]
    assert info["starting_time"] == {"nanoseconds_since_epoch": t0}
    assert info["duration"] == {"nanoseconds": t1 - t0}
    assert info["files"] == [{"path": "run_0.mcap",
                              "starting_time": {"nanoseconds_since_epoch": t0},
                              "duration": {"nanoseconds": t1 - t0}, "message_count": 60}]
    assert info["compression_format"] == "" and info["compression_mode"] == ""
    assert info["custom_data"] == {"scene": "dd=-5e-6"}
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert set(topics) == set(TOPICS)
    for name, entry in topics.items():
        meta = entry["topic_metadata"]
        assert entry["message_count"] == 10
        assert meta["type"] == TOPICS[name]
        assert meta["serialization_format"] == "cdr"
        assert meta["type_description_hash"] == type_description_hash(TOPICS[name])
        (qos,) = meta["offered_qos_profiles"]
        assert qos["history"] == "keep_all" and qos["reliability"] == "reliable"
        assert qos["deadline"] == {"sec": 0, "nsec": 0}


def test_mcap_follows_ros2_profile(tmp_path):
    write_bag(tmp_path / "run", 10)
    with open(bag_file(tmp_path / "run"), "rb") as f:
        reader = SeekingReader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert summary.statistics.message_count == 60
    assert summary.statistics.channel_count == 6
    assert summary.statistics.schema_count == 4         # one schema per type
    assert summary.chunk_indexes
    assert metadata["rosbag2"]["ROS_DISTRO"] == "jazzy"
    assert yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])["message_count"] == 60
    for schema in summary.schemas.values():
        assert schema.encoding == "ros2msg"
        assert schema.data.decode() == message_definition(schema.name)
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr"
        assert schema.name == TOPICS[channel.topic]
        qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert qos == [qos_profile_dict(history="keep_all", reliability="reliable")]
        assert channel.metadata["topic_type_hash"] == type_description_hash(schema.name)
        assert summary.statistics.channel_message_counts[channel.id] == 10


def test_qos_yaml_round_trip():
    profiles = [qos_profile_dict(history="keep_last", depth=7, deadline_ns=None),
                qos_profile_dict(durability="transient_local", lifespan_ns=1_500_000_000)]
    text = qos_profiles_yaml(profiles)
    assert yaml.safe_load(text) == profiles
    assert profiles[0]["deadline"] == {"sec": 9223372036, "nsec": 854775807}
    assert profiles[1]["lifespan"] == {"sec": 1, "nsec": 500_000_000}
    assert qos_profiles_yaml([]) == ""


# ------------------------------------------------------ crash behaviour


def _messages_of_complete_chunks(path, cut):
    """Number of messages in the chunks that end before byte `cut`."""
    with open(path, "rb") as f:
        indexes = SeekingReader(f).get_summary().chunk_indexes
        count = 0
        for index in indexes:
            if index.chunk_start_offset + index.chunk_length > cut:
                continue
            f.seek(index.chunk_start_offset)
            chunk = next(StreamReader(f, skip_magic=True, emit_chunks=True).records)
            assert isinstance(chunk, Chunk)
            count += sum(isinstance(r, Message) for r in breakup_chunk(chunk))
    return count


@pytest.mark.parametrize("fraction", [0.0, 0.13, 0.5, 0.77, 0.999])
def test_truncated_file_yields_complete_chunks(tmp_path, fraction):
    written = write_bag(tmp_path / "run", 400, chunk_size=4 * 1024)
    path = bag_file(tmp_path / "run")
    data = path.read_bytes()
    cut = max(int(len(data) * fraction), 8)
    expected_count = _messages_of_complete_chunks(path, cut)
    cut_dir = tmp_path / "cut"
    cut_dir.mkdir()
    (cut_dir / "cut_0.mcap").write_bytes(data[:cut])   # no metadata.yaml, as after a crash
    got = list(read_messages(cut_dir))
    assert len(got) == expected_count
    if fraction >= 0.5:
        assert expected_count > len(written) // 3
    assert_same_messages(got, written[:expected_count])


def test_readable_while_recording(tmp_path):
    """A recorder that dies leaves every complete chunk on disk."""
    bag = BagWriter(tmp_path / "run", chunk_size=2 * 1024).open()
    bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
    msgs = [make_message("sensor_msgs/msg/JointState", i) for i in range(500)]
    for i, msg in enumerate(msgs):
        bag.write("/oscillator/state", encode("sensor_msgs/msg/JointState", msg), 10 + i)
    assert not (tmp_path / "run" / "metadata.yaml").exists()
    got = list(read_messages(tmp_path / "run"))       # no summary, no metadata yet
    assert 0.8 * len(msgs) < len(got) < len(msgs)
    assert [message_to_dict(m.message) for m in got] == \
        [message_to_dict(m) for m in msgs[:len(got)]]
    bag.close()
    assert len(list(read_messages(tmp_path / "run"))) == len(msgs)


# --------------------------------------------------------------- errors


def test_writer_refuses_misuse(tmp_path):
    with pytest.raises(ValueError, match="compression"):
        BagWriter(tmp_path / "a", compression="gzip")
    with pytest.raises(ValueError, match="chunk_size"):
        BagWriter(tmp_path / "a", chunk_size=0)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    with pytest.raises(FileExistsError):
        BagWriter(tmp_path / "full").open()
    bag = BagWriter(tmp_path / "b")
    with pytest.raises(RuntimeError, match="not opened"):
        bag.write("/clock", b"", 0)
    bag.open()
    bag.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    with pytest.raises(ValueError, match="already added"):
        bag.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    with pytest.raises(ValueError, match="not added"):
        bag.write("/other", b"", 0)
    with pytest.raises(LookupError):
        bag.add_topic("/x", "sensor_msgs/msg/NoSuchMsg")
    bag.close()
    bag.close()                                         # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        bag.write("/clock", b"", 0)


def test_a_write_refused_adds_nothing(tmp_path):
    """Thousands of seeded writes, a third of them hostile (data that is not bytes, times
    out of [0, 2**64), NaN, a sequence that is no number): each refused one raises an
    error naming its parameter and leaves the bag as it was; the bag reads back exactly
    the accepted messages, in order, and counts them."""
    import math
    import random

    rng = random.Random(11)
    bag = BagWriter(tmp_path / "fuzz", chunk_size=4096).open()
    bag.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    bag.add_topic("/oscillator/impact", "geometry_msgs/msg/Vector3Stamped")
    hostile = {
        "data": ["text", None, 12, 3.5, ["b"]],
        "log_time_ns": [-1, 2**64, 2**70, math.nan, math.inf, "soon", None],
        "publish_time_ns": [-7, 2**64, math.nan, "x"],
        "sequence": ["x", math.nan, None],
    }
    accepted = []
    for i in range(3000):
        topic = rng.choice(["/clock", "/oscillator/impact"])
        args = {"data": rng.randbytes(rng.randrange(0, 64)), "log_time_ns": 10**18 + i,
                "publish_time_ns": rng.choice([None, 10**18 + i - 5]),
                "sequence": rng.randrange(0, 2**40)}
        bad = rng.choice(list(hostile)) if rng.random() < 0.33 else None
        if bad:
            args[bad] = rng.choice(hostile[bad])
            with pytest.raises((TypeError, ValueError), match=bad):
                bag.write(topic, **args)
        else:
            bag.write(topic, **args)
            accepted.append((topic, args["data"], args["log_time_ns"]))
    counts = bag.message_counts
    bag.close()
    assert counts == {t: sum(1 for a in accepted if a[0] == t)
                      for t in ("/clock", "/oscillator/impact")}
    with open(bag_file(tmp_path / "fuzz"), "rb") as fh:
        reader = SeekingReader(fh)
        got = [(c.topic, bytes(m.data), m.log_time)
               for _, c, m in reader.iter_messages(log_time_order=False)]
    assert got == accepted


def test_empty_bag_is_valid(tmp_path):
    with BagWriter(tmp_path / "empty") as bag:
        bag.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    info = read_metadata(tmp_path / "empty")
    assert info["message_count"] == 0
    assert info["topics_with_message_count"][0]["message_count"] == 0
    assert list(read_messages(tmp_path / "empty")) == []
    assert list(read_messages_rosbags(tmp_path / "empty")) == []


def _example_bag(tmp_path, keep=None):
    """A copy of the example bag (bags/scene_9e-6) in ``tmp_path``: (bag directory, its
    .mcap). With ``keep``, its metadata.yaml removed and the .mcap cut to that fraction of
    its size, as a recorder killed part way leaves it."""
    import shutil

    bag = tmp_path / "scene_9e-6"
    shutil.copytree(Path(__file__).resolve().parents[1] / "bags" / "scene_9e-6", bag)
    f = bag / "scene_9e-6_0.mcap"
    if keep is not None:
        (bag / "metadata.yaml").unlink()
        f.write_bytes(f.read_bytes()[: int(f.stat().st_size * keep)])
    return bag, f


@pytest.mark.parametrize("text", ["", "just text\n", "- a\n- list\n",
                                  "rosbag2_bagfile_information: 3\n",
                                  "rosbag2_bagfile_information:\n  relative_file_paths: 7\n"])
def test_a_broken_metadata_yaml_is_named_and_reindex_recovers_the_bag(tmp_path, text):
    """A metadata.yaml cut short by a full disk (empty) or not rosbag2's: read_metadata
    names the file (the last one is a mapping, with a file list that is none); the
    readers and reindex take the directory's own .mcap, and reindex writes a good
    metadata.yaml."""
    from grazing_control.ros.recording import reindex
    from grazing_control.support.files import YamlFileError

    src = Path(__file__).resolve().parents[1] / "bags" / "scene_9e-6"
    bag, _ = _example_bag(tmp_path)
    (bag / "metadata.yaml").write_text(text)
    if "relative_file_paths" in text:
        assert read_metadata(bag) == {"relative_file_paths": 7}
    else:
        with pytest.raises(YamlFileError, match="metadata.yaml"):
            read_metadata(bag)
    assert bag_file(bag) == bag / "scene_9e-6_0.mcap"
    count = read_metadata(src)["message_count"]
    assert sum(1 for _ in read_messages(bag)) == count
    res = reindex(bag)
    assert res.had_summary and res.message_count == count
    assert read_metadata(bag)["message_count"] == count


def test_reindex_without_room_says_what_to_do_and_leaves_the_bag(tmp_path):
    """A reindex whose copy does not fit (here a file size limit: EFBIG, as ENOSPC on a
    full disk) names the bag and the remedy, and leaves the bag and its directory as
    they were."""
    bag, f = _example_bag(tmp_path, keep=0.5)
    before = f.read_bytes()
    limit = len(before) // 10
    code = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
        "from grazing_control.ros.recording import reindex\n"
        "try:\n"
        f"    reindex({str(bag)!r})\n"
        "except OSError as exc:\n"
        "    print(exc)\n"
        "    sys.exit(3)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[1], timeout=120)
    assert out.returncode == 3, out.stderr[-2000:]
    assert str(bag) in out.stdout and "File too large" in out.stdout
    assert "the bag is unchanged" in out.stdout and "copy the bag directory" in out.stdout
    assert f.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene_9e-6"]
    assert sorted(p.name for p in bag.iterdir()) == ["scene_9e-6_0.mcap"]


def test_default_chunk_size_is_moderate():
    assert 16 * 1024 <= DEFAULT_CHUNK_SIZE <= 1024 * 1024


def test_reindex_recovers_a_truncated_bag_for_every_reader(tmp_path):
    """The complete chunks of a cut file, as the partial reader sees them, become a bag
    with a summary and metadata.yaml (reindex); a complete bag is left as it was."""
    import shutil

    from grazing_control.ros.recording import reindex

    src = Path(__file__).resolve().parents[1] / "bags" / "scene_9e-6"
    bag, _ = _example_bag(tmp_path, keep=1 / 3)
    partial = [(m.topic, m.log_time_ns, message_to_dict(m.message)) for m in read_messages(bag)]
    res = reindex(bag)
    assert not res.had_summary and res.dropped_bytes > 0 and res.message_count == len(partial)
    for read in (read_messages, read_messages_rosbags):
        assert [(m.topic, m.log_time_ns, message_to_dict(m.message)) for m in read(bag)] \
            == partial
    whole = tmp_path / "whole"
    shutil.copytree(src, whole)
    res = reindex(whole)
    assert res.had_summary and res.message_count == read_metadata(src)["message_count"]

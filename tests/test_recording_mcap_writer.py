"""McapWriter (grazing_control/ros/recording/mcap_writer.py): the recorder's MCAP writer.

Its truth is the ``mcap`` library's own writer: for the same calls, with the options the
bag writer uses, both must produce the same bytes. The scenes are random (seeded):
schemas and channels registered between messages, log times out of order, empty and
large messages (as bytes, bytearray, or memoryviews of bytes and of 8-byte items),
chunks from a few records to many, every compression, metadata between chunks.
"""

import array
import io
import random

import pytest
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.writer import CompressionType, IndexType, Writer

from grazing_control.ros.recording.mcap_writer import McapWriter

_TYPES = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4,
          "zstd": CompressionType.ZSTD}


def _scene(rng):
    """A random sequence of writer calls: (method, kwargs)."""
    calls, schemas, channels = [], 0, 0
    for _ in range(rng.randrange(0, 400)):
        roll = rng.random()
        if roll < 0.03 or channels == 0 and roll < 0.3:
            schemas += 1
            calls.append(("register_schema", dict(
                name=f"pkg/msg/T{schemas}", encoding="ros2msg",
                data=rng.randbytes(rng.randrange(0, 200)))))
        elif roll < 0.07 or channels == 0:
            channels += 1
            calls.append(("register_channel", dict(
                topic=f"/topic{channels}", message_encoding="cdr",
                schema_id=rng.randrange(0, schemas + 1),
                metadata={f"k{i}": rng.choice(["", "v", "qos: x"]) for i in
                          range(rng.randrange(0, 3))})))
        elif roll < 0.08:
            calls.append(("add_metadata", dict(
                name=rng.choice(["rosbag2", "m"]), data={"a": str(rng.random())})))
        else:
            data = rng.randbytes(8 * rng.choice([0, 1, 2, rng.randrange(0, 400)]))
            data = rng.choice([data, bytearray(data), memoryview(data),
                               memoryview(array.array("d", data)),     # 8-byte items
                               data[:rng.randrange(0, len(data) + 1)]])
            calls.append(("add_message", dict(
                channel_id=rng.randrange(1, channels + 1),
                log_time=rng.choice([rng.randrange(0, 2**63), rng.randrange(10**9, 10**9 + 10**6)]),
                data=data,
                publish_time=rng.randrange(0, 2**64),
                sequence=rng.randrange(0, 2**32))))
    return calls


def _write(make, calls):
    out = io.BytesIO()
    writer = make(out)
    writer.start(profile="ros2", library="test")
    for method, kwargs in calls:
        getattr(writer, method)(**kwargs)
    writer.finish()
    return out.getvalue()


@pytest.mark.parametrize("seed", range(40))
def test_writes_the_bytes_of_the_mcap_librarys_writer(seed):
    rng = random.Random(seed)
    for _ in range(10):
        calls = _scene(rng)
        compression = rng.choice(list(_TYPES))
        chunk_size = rng.choice([1, 64, 1000, 20_000, 1024 * 1024])
        ours = _write(lambda out: McapWriter(out, chunk_size=chunk_size,
                                             compression=compression), calls)
        theirs = _write(lambda out: Writer(
            out, chunk_size=chunk_size, compression=_TYPES[compression],
            index_types=IndexType.ALL, use_statistics=True, use_summary_offsets=True),
            calls)
        assert ours == theirs, (seed, compression, chunk_size, len(calls))


def test_readers_get_every_message_back():
    rng = random.Random(7)
    calls = [("register_schema", dict(name="std_msgs/msg/String", encoding="ros2msg",
                                      data=b"string data")),
             ("register_channel", dict(topic="/a", message_encoding="cdr", schema_id=1)),
             ("register_channel", dict(topic="/b", message_encoding="cdr", schema_id=1))]
    sent = []
    for i in range(5000):
        message = dict(channel_id=rng.choice([1, 2]), log_time=10**18 + rng.randrange(10**9),
                       data=rng.randbytes(rng.randrange(0, 100)), publish_time=i, sequence=i)
        calls.append(("add_message", message))
        sent.append((message["channel_id"], message["log_time"], message["data"], i))
    data = _write(lambda out: McapWriter(out, chunk_size=4096, compression="zstd"), calls)
    for reader in (SeekingReader(io.BytesIO(data)), NonSeekingReader(io.BytesIO(data))):
        got = [(c.id, m.log_time, m.data, m.sequence)
               for _, c, m in reader.iter_messages(log_time_order=False)]
        assert sorted(got, key=lambda r: r[3]) == sent
    summary = SeekingReader(io.BytesIO(data)).get_summary()
    assert summary.statistics.message_count == 5000
    assert summary.statistics.channel_message_counts == {
        c: sum(1 for s in sent if s[0] == c) for c in (1, 2)}
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 10


def test_refuses_an_unknown_compression():
    with pytest.raises(ValueError, match="compression must be one of none, lz4, zstd"):
        McapWriter(io.BytesIO(), compression="gzip")

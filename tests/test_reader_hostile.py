"""recordings.reader against hostile files: decompression bombs are refused within a fixed
memory budget before their output exists, special files are refused before they are
opened, and every length field of the structural records (Schema, Channel, Metadata; at
the top level and inside a chunk whose CRC is right) gives a result or one BagReadError
line, never another exception (seeded fuzzing of thousands of files)."""

import os
import random
import struct
import subprocess
import sys
import zlib

import hostile_files
import pytest

from grazing_control.recordings import reader
from grazing_control.recordings.scenes import load
from hostile_files import MAGIC, m, rec, s


def header():
    return rec(0x01, s("ros2") + s("test"))


def schema(sid=1, name="std_msgs/msg/Float64"):
    return rec(0x03, struct.pack("<H", sid) + s(name) + s("ros2msg") + s(b"float64 data"))


def channel(cid=1, sid=1, topic="/oscillator/latency"):
    return rec(0x04, struct.pack("<HH", cid, sid) + s(topic) + s("cdr")
               + m([("offered_qos_profiles", "")]))


def message(cid, seq, t, value):
    data = b"\x00\x01\x00\x00" + struct.pack("<d", value)
    return rec(0x05, struct.pack("<HIQQ", cid, seq, t, t) + data)


def metadata():
    return rec(0x0C, s("rosbag2") + m([("serialized_metadata", "x")]))


def chunk(records: bytes, compression="", payload=None, size=None):
    payload = records if payload is None else payload
    size = len(records) if size is None else size
    return rec(0x06, struct.pack("<QQQI", 0, 10, size, zlib.crc32(records)) + s(compression)
               + struct.pack("<Q", len(payload)) + payload)


def mcap(*records):
    return MAGIC + header() + b"".join(records) + rec(0x0F, struct.pack("<I", 0)) \
        + rec(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC


def write(tmp_path, data, name="b"):
    folder = tmp_path / name
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}_0.mcap"
    path.write_bytes(data)
    return folder


@pytest.fixture
def small_budget(monkeypatch):
    monkeypatch.setenv("GRAZING_BAG_MAX_BYTES", str(1 << 20))


def test_a_well_formed_hand_written_file_is_read(tmp_path):
    inner = schema() + channel() + b"".join(message(1, k, k, k * 0.5) for k in range(5))
    raw = reader.read_raw(write(tmp_path, mcap(chunk(inner), metadata())))
    assert raw.complete and raw.problems == []
    assert reader.decode_float64(raw, "/oscillator/latency")["data"].tolist() == \
        [k * 0.5 for k in range(5)]
    assert raw.metadata == [("rosbag2", {"serialized_metadata": "x"})]


def test_a_zstd_chunk_bomb_is_refused_before_its_output_is_allocated(tmp_path, small_budget):
    import zstandard
    zeros = bytes(8 << 20)
    bomb = zstandard.ZstdCompressor(level=19).compress(zeros)
    assert len(bomb) < 2000
    honest = write(tmp_path, mcap(chunk(zeros, "zstd", bomb)), "honest")
    with pytest.raises(reader.BagReadError, match="decompression bomb"):
        reader.read_raw(honest)
    # a chunk that lies about its size is cut at the size it declares: a skipped chunk
    liar = write(tmp_path, mcap(chunk(zeros[:100], "zstd", bomb)), "liar")
    raw = reader.read_raw(liar)
    assert any("more than the 100 bytes" in p for p in raw.problems)


def test_an_lz4_chunk_bomb_is_refused_too(tmp_path, small_budget):
    lz4 = pytest.importorskip("lz4.frame")
    zeros = bytes(8 << 20)
    bomb = lz4.compress(zeros)
    with pytest.raises(reader.BagReadError, match="decompression bomb"):
        reader.read_raw(write(tmp_path, mcap(chunk(zeros, "lz4", bomb)), "honest"))
    raw = reader.read_raw(write(tmp_path, mcap(chunk(zeros[:64], "lz4", bomb)), "liar"))
    assert any("more than the 64 bytes" in p for p in raw.problems)


def test_the_budget_counts_every_chunk_of_a_file(tmp_path, small_budget):
    import zstandard
    part = bytes(300_000)
    data = mcap(*[chunk(part, "zstd", zstandard.ZstdCompressor().compress(part))
                  for _ in range(5)])
    with pytest.raises(reader.BagReadError, match="budget"):
        reader.read_raw(write(tmp_path, data))


def test_a_whole_file_zstd_bomb_is_refused(tmp_path, small_budget):
    import zstandard
    c = zstandard.ZstdCompressor(level=19).compressobj()
    body = c.compress(mcap()) + b"".join(c.compress(bytes(1 << 20)) for _ in range(8)) \
        + c.flush()
    folder = tmp_path / "whole"
    folder.mkdir()
    (folder / "whole_0.mcap.zstd").write_bytes(body)
    with pytest.raises(reader.BagReadError, match="decompression bomb"):
        reader.read_raw(folder)


def test_the_budget_variable_is_validated(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAZING_BAG_MAX_BYTES", "-3")
    with pytest.raises(reader.BagReadError, match="GRAZING_BAG_MAX_BYTES.*positive integer"):
        reader.read_raw(write(tmp_path, mcap()))


def test_a_fifo_named_like_a_bag_is_refused_without_blocking(tmp_path):
    """Opening a FIFO waits for a writer forever; the reader checks the type first. Run in
    a child process so that a regression fails the test instead of hanging it."""
    folder = tmp_path / "x"
    folder.mkdir()
    os.mkfifo(folder / "x_0.mcap")
    code = ("import sys\nfrom grazing_control.recordings import reader\n"
            "try:\n    reader.read_raw(sys.argv[1])\n"
            "except reader.BagReadError as e:\n    print(e); sys.exit(2)\n")
    for target in (folder, folder / "x_0.mcap"):
        out = subprocess.run([sys.executable, "-c", code, str(target)], capture_output=True,
                             text=True, timeout=60)
        assert out.returncode == 2, out.stderr
        assert "regular file" in out.stdout or "no such bag" in out.stdout


# ------------------------------------------------------------------ length-field fuzzing
def _length_fields(record: bytes):
    """Offsets (inside ``record``) of every uint32 length field of a structural record."""
    op = record[0]
    p = 9 + {0x03: 2, 0x04: 4, 0x0C: 0}[op]
    fields = []
    strings = {0x03: 3, 0x04: 2, 0x0C: 1}[op]
    for _ in range(strings):
        fields.append(p)
        p += 4 + struct.unpack_from("<I", record, p)[0]
    if op in (0x04, 0x0C):                                # the map and its strings
        fields.append(p)
        stop = p + 4 + struct.unpack_from("<I", record, p)[0]
        p += 4
        while p < stop:
            fields.append(p)
            p += 4 + struct.unpack_from("<I", record, p)[0]
    return fields


def _corrupt(record: bytes, rng) -> bytes:
    b = bytearray(record)
    at = rng.choice(_length_fields(record))
    room = len(record) - at - 4
    value = rng.choice([room + 1, room + rng.randrange(1, 1000), 2 ** 32 - 1,
                        rng.randrange(2 ** 32), rng.randrange(room + 1)])
    b[at:at + 4] = struct.pack("<I", value)
    return bytes(b)


def test_every_length_field_gives_a_result_or_one_line(tmp_path):
    """3000 seeded files: one Schema, Channel or Metadata record with a length field set
    beyond (or inside) its record, at the top level or inside a chunk with a correct CRC."""
    rng = random.Random(2026)
    msgs = b"".join(message(1, k, k, 0.25 * k) for k in range(3))
    outcomes = {"read": 0, "refused": 0}
    folder = tmp_path / "f"
    folder.mkdir()
    path = folder / "f_0.mcap"
    for case in range(3000):
        parts = [schema(), channel(), metadata()]
        i = rng.randrange(3)
        parts[i] = _corrupt(parts[i], rng)
        body = parts[0] + parts[1] + msgs
        data = mcap(chunk(body), parts[2]) if case % 2 else mcap(body, parts[2])
        path.write_bytes(data)
        try:
            load(folder) if case % 10 == 0 else reader.read_raw(folder)
        except ValueError as exc:               # BagReadError is a ValueError
            assert "\n" not in str(exc)
            outcomes["refused"] += 1
            continue
        outcomes["read"] += 1
    assert outcomes["refused"] > 1000 and outcomes["read"] > 100, outcomes


def test_a_crafted_length_field_through_the_command_line_is_one_line_status_2(tmp_path):
    bad = bytearray(channel())
    bad[13:17] = struct.pack("<I", 2 ** 31)                    # the topic string's length
    folder = write(tmp_path, mcap(chunk(schema() + bytes(bad) + message(1, 0, 0, 1.0))))
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", "analyze", str(folder)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert "Traceback" not in out.stderr and "malformed" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_a_bomb_is_refused_by_its_ratio_to_the_file_without_any_setting(tmp_path, monkeypatch):
    # no GRAZING_BAG_MAX_BYTES: a small file may inflate to max(64 MiB, 50 x its size)
    monkeypatch.delenv("GRAZING_BAG_MAX_BYTES", raising=False)
    import zstandard
    assert reader.max_bytes(1000) == 64 << 20
    assert reader.max_bytes(4 << 20) == 50 * (4 << 20)
    assert reader.MAX_BYTES == 256 << 20
    assert reader.max_bytes(1 << 40) == reader.MAX_BYTES
    tiny = zstandard.ZstdCompressor().compress(b"")
    liar = write(tmp_path, mcap(chunk(b"", "zstd", tiny, size=100 << 20)))
    with pytest.raises(reader.BagReadError, match="104857600 uncompressed bytes.*bomb"):
        reader.read_raw(liar)


def test_zeros_inside_a_chunk_end_it_as_a_reserved_opcode(tmp_path, monkeypatch):
    # a zero-filled chunk within the budget is 9-byte "records" of opcode 0: reserved by
    # the MCAP spec, so the chunk's records end there (one problem), not after 1e6 steps
    monkeypatch.setenv("GRAZING_BAG_MAX_BYTES", str(1 << 30))
    import zstandard
    inner = schema() + channel() + message(1, 0, 0, 1.5) + bytes(8 << 20)
    data = mcap(chunk(inner, "zstd", zstandard.ZstdCompressor().compress(inner)))
    raw = reader.read_raw(write(tmp_path, data))
    assert reader.decode_float64(raw, "/oscillator/latency")["data"].tolist() == [1.5]
    assert any("ends inside a record" in p for p in raw.problems)


def test_reindex_refuses_a_bomb_and_a_fifo_and_leaves_the_file_as_it_was(tmp_path, monkeypatch):
    monkeypatch.delenv("GRAZING_BAG_MAX_BYTES", raising=False)
    import zstandard
    from grazing_control.ros.recording.recovery import reindex
    tiny = zstandard.ZstdCompressor().compress(bytes(1 << 20))
    folder = write(tmp_path, mcap(chunk(b"", "zstd", tiny, size=1 << 30)), "bomb")
    before = (folder / "bomb_0.mcap").read_bytes()
    with pytest.raises(reader.BagReadError, match="decompression budget"):
        reindex(folder)
    assert (folder / "bomb_0.mcap").read_bytes() == before
    fifo = tmp_path / "fifo"
    fifo.mkdir()
    os.mkfifo(fifo / "fifo_0.mcap")
    with pytest.raises(reader.BagReadError, match="not a regular file"):
        reindex(fifo)


def test_reindex_keeps_the_records_before_zeros_and_recovers_the_rest(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAZING_BAG_MAX_BYTES", str(1 << 30))
    import zstandard
    from grazing_control.ros.recording.recovery import reindex
    good = schema() + channel() + b"".join(message(1, k, k, k * 0.25) for k in range(4))
    zeros = good + bytes(4 << 20)
    data = mcap(chunk(zeros, "zstd", zstandard.ZstdCompressor().compress(zeros)))
    result = reindex(write(tmp_path, data, "z"))
    assert result.message_count == 4
    raw = reader.read_raw(tmp_path / "z")
    assert reader.decode_float64(raw, "/oscillator/latency")["data"].tolist() == \
        [k * 0.25 for k in range(4)]


# --- bombs within the budget rule, through the command line: one line, bounded memory
# (issue 27: a 5.4 MB file with one honest 1 GiB chunk took 2.1-3.4 GB and 6-39 s)

def _pi2_record():
    from bagtools_helpers import TYPESTORE, joint_state
    cdr = TYPESTORE.serialize_cdr(joint_state(1_000_000_000, 0.1, 0.2),
                                  "sensor_msgs/msg/JointState")
    return hostile_files.message(bytes(cdr))


@pytest.mark.parametrize("kind", ["zstd", "lz4"])
def test_a_gib_chunk_in_a_padded_file_is_refused_at_once_in_little_memory(tmp_path, kind,
                                                                          monkeypatch):
    monkeypatch.delenv("GRAZING_BAG_MAX_BYTES", raising=False)
    size = (1 << 30) - (1 << 20)
    bag = hostile_files.bomb_bag(tmp_path / "bomb", size, kind=kind, file_size=size // 200 + 1)
    status, _, err, peak = hostile_files.grazing_measured("analyze", bag, "--out",
                                                          tmp_path / "out")
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert str(bag) in err and "decompression bomb" in err
    assert peak - hostile_files.analyze_floor_mb(kind) < 100, peak  # before: 2.1-3.4 GB


@pytest.mark.parametrize("kind", ["zstd", "lz4"])
def test_a_zero_filled_chunk_within_the_budget_costs_one_piece(tmp_path, kind, monkeypatch):
    # a tiny file may always inflate to MIN_BYTES (64 MiB): the zeros are never kept
    monkeypatch.delenv("GRAZING_BAG_MAX_BYTES", raising=False)
    bag = hostile_files.bomb_bag(tmp_path / "zeros", reader.bounded.MIN_BYTES - 4096,
                                 kind=kind, prefix=hostile_files.definitions())
    raw = reader.read_raw(bag)
    assert len(raw.pool) == raw.path.stat().st_size         # the file only: no zeros kept
    assert any("ends inside a record" in p for p in raw.problems)
    status, _, err, peak = hostile_files.grazing_measured("analyze", bag, "--out",
                                                          tmp_path / "out")
    assert status == 2 and len(err.strip().splitlines()) == 1 and "/oscillator/pi2" in err
    # one decompressed piece of 64 MiB (67 MB) above the floor, never two; before: 64 MiB
    # of zeros held twice (190 MB, about 150 above the floor)
    assert peak - hostile_files.analyze_floor_mb(kind) < 1.5 * 67.1, peak


def test_valid_records_within_the_budget_stay_within_the_memory_bound(tmp_path, monkeypatch):
    # 64 MiB of copies of one valid Pi2 record: read, decoded, refused for their stamps;
    # the documented bound (bounded.py): about 3 x the records plus the interpreter
    monkeypatch.delenv("GRAZING_BAG_MAX_BYTES", raising=False)
    block = _pi2_record()
    n = (reader.bounded.MIN_BYTES - 4096) // len(block)
    bag = hostile_files.bomb_bag(tmp_path / "pi2", n * len(block), kind="zstd", block=block,
                                 prefix=hostile_files.definitions())
    status, _, err, peak = hostile_files.grazing_measured("analyze", bag, "--out",
                                                          tmp_path / "out")
    assert status == 2 and len(err.strip().splitlines()) == 1 and "duplicate stamps" in err
    assert peak - hostile_files.analyze_floor_mb("zstd") < 20 + 3.2 * 67.1, peak

"""Hostile inputs for the command line, and a command's peak memory.

MCAP records by hand (:func:`rec`, :func:`s`, :func:`m`: tests/test_reader_hostile.py
builds its files with them) and :func:`bomb_bag`, decompression bombs within the
reader's budget rule, written without holding their output: a bag of one padding
Metadata record (so that the file is large enough for the budget to admit the chunk:
recordings/reader.max_bytes) and one honest chunk, CRC-correct, whose records are
``block`` repeated until ``size`` bytes: zeros, or copies of a valid message record on a
real topic. The chunk is compressed as a stream, so building a 1 GiB bomb
costs the compressed size in memory, not the GiB.

Memory bounds are stated above :func:`analyze_floor_mb`, the peak of the same command on a
4 KiB chunk on the same machine: the interpreter and its libraries differ between
machines by tens of MB (a fresh CI clone measured 122.8 MB where this machine measures
101.7 MB for the same bag), the excess over the floor is what the reader costs.
"""

import functools
import json
import pathlib
import struct
import subprocess
import sys
import tempfile
import zlib

MAGIC = b"\x89MCAP0\r\n"


def rec(op, body):
    return struct.pack("<BQ", op, len(body)) + body


def s(text):
    b = text.encode() if isinstance(text, str) else text
    return struct.pack("<I", len(b)) + b


def m(pairs):
    body = b"".join(s(k) + s(v) for k, v in pairs)
    return struct.pack("<I", len(body)) + body


def definitions(topic="/oscillator/pi2", type_name="sensor_msgs/msg/JointState"):
    """Schema 1 and channel 1 for ``topic``."""
    return (rec(0x03, struct.pack("<H", 1) + s(type_name) + s("ros2msg") + s(b""))
            + rec(0x04, struct.pack("<HH", 1, 1) + s(topic) + s("cdr")
                  + m([("offered_qos_profiles", "")])))


def message(cdr: bytes, cid=1, t=0):
    return rec(0x05, struct.pack("<HIQQ", cid, 0, t, t) + cdr)


def _compress(kind, block, size):
    """(compressed bytes, crc32) of ``block`` repeated to ``size`` bytes, streamed."""
    if kind == "zstd":
        import zstandard
        c = zstandard.ZstdCompressor(level=3).compressobj()
        finish = c.flush
    else:
        import lz4.frame
        c = lz4.frame.LZ4FrameCompressor()
        head = c.begin()
        finish = c.flush
    out, crc, left = ([] if kind == "zstd" else [head]), 0, size
    piece = block * max(1, (1 << 20) // len(block))
    while left > 0:
        p = piece[:left]
        crc = zlib.crc32(p, crc)
        out.append(c.compress(p))
        left -= len(p)
    out.append(finish())
    return b"".join(out), crc


def bomb_bag(folder, size, *, kind="zstd", block=b"\0" * 4096, prefix=b"", file_size=0):
    """Write ``folder/<name>_0.mcap``: ``prefix`` (top-level records), a padding record
    that makes the file at least ``file_size`` bytes, and one chunk of ``block`` repeated
    to ``size`` bytes (compressed with ``kind``). Returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    payload, crc = _compress(kind, block, size)
    chunk = rec(0x06, struct.pack("<QQQI", 0, 10, size, crc) + s(kind)
                + struct.pack("<Q", len(payload)) + payload)
    head = MAGIC + rec(0x01, s("ros2") + s("bomb")) + prefix
    tail = rec(0x0F, struct.pack("<I", 0)) + rec(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    pad = max(0, file_size - len(head) - len(chunk) - len(tail) - 30)
    padding = rec(0x0C, s("padding") + m([("x", "p" * pad)])) if pad else b""
    path = folder / f"{folder.name}_0.mcap"
    path.write_bytes(head + padding + chunk + tail)
    return folder


_MEASURE = """
import json, resource, subprocess, sys
r = subprocess.run(sys.argv[1:], capture_output=True, text=True, stdin=subprocess.DEVNULL)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps([r.returncode, r.stdout, r.stderr, peak]))
"""


def grazing_measured(*args, timeout=120):
    """Run ``python -m grazing_control.cli *args`` in a child of its own; return
    (status, stdout, stderr, peak resident memory in MB) of that command alone."""
    out = subprocess.run([sys.executable, "-c", _MEASURE, sys.executable, "-m",
                          "grazing_control.cli", *map(str, args)],
                         capture_output=True, text=True, timeout=timeout)
    status, stdout, stderr, peak_kb = json.loads(out.stdout)
    return status, stdout, stderr, peak_kb / 1024


@functools.lru_cache(maxsize=None)
def analyze_floor_mb(kind="zstd"):
    """Peak memory (MB) of ``grazing analyze`` refusing a bag whose chunk is 4 KiB of
    zeros (the same definitions, the same one-line error): the cost of the interpreter,
    its libraries and the analysis, with nothing worth measuring decompressed."""
    folder = pathlib.Path(tempfile.mkdtemp(prefix="grazing-floor-"))
    bag = bomb_bag(folder / "floor", 4096, kind=kind, prefix=definitions())
    status, _, err, peak = grazing_measured("analyze", bag, "--out", folder / "out")
    assert status == 2 and "/oscillator/pi2" in err, err
    return peak

"""Columnar reading of a rosbag2 MCAP file: stream the records, decode only what is needed.

The analysis needs a few numbers of each message (a stamp, a position, a velocity), not
message objects. This reader streams the file record by record from its start (MCAP
specification, "Records"): it never needs the summary, so a file whose recorder was
killed (no summary, no ``metadata.yaml``, a torn last record) is read up to its last
complete record, and a file written by any other writer (rosbag2, rosbags, the
``mcap`` library) is read the same way. Chunks are decompressed (zstd, lz4 or none) and
appended to one byte pool after the file's own bytes, piece by piece as they inflate
(:func:`grazing_control.ros.recording.bounded.pieces`), keeping only complete records; each
message is kept as its offset into the pool (an int64 array per channel). The pool is at
most the file plus the decompression budget (the memory bound: bounded.py).

CDR decoding is vectorised: for all messages of a channel at once, the offsets of the
fields follow the plain little-endian CDR layout of the ROS 2 type (strings and
sequences carry a uint32 length; primitives are aligned to their size relative to the
start of the body, after the 4-byte encapsulation header), computed with numpy from the
lengths read out of the pool. A message too short for its layout is marked invalid (it
is counted, never decoded from beyond its end).

Supported decodes: ``sensor_msgs/msg/JointState`` (stamp, position[0], velocity[0]; as a
state stream position[i], velocity[i] of any coordinate i, effort[0], effort[1], velocity
possibly empty),
``geometry_msgs/msg/TwistStamped`` (stamp, linear.x), ``geometry_msgs/msg/Vector3Stamped``
(stamp, vector), ``std_msgs/msg/Float64``, ``std_msgs/msg/String``, and the stream in
blocks (``std_msgs/msg/Float64MultiArray`` of grazing_control.ros.stream_block, one message
at a time: a block's length varies).
"""

from __future__ import annotations

import os
import struct
from array import array
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grazing_control.ros.recording import bounded  # noqa: F401  (the memory bound)
from grazing_control.ros.recording.bounded import (  # noqa: F401  (re-exported)
    MAX_BYTES, BagReadError, check_size as _check_size, max_bytes, pieces as _pieces,
    read_zstd as _read_zstd, regular_file as _regular_file)

__all__ = ["BagReadError", "Channel", "RawBag", "read_raw", "bag_path", "decode_stamped",
           "decode_joint_state", "decode_joint_states", "joint_count", "decode_estimate", "decode_joint_stream", "decode_state_blocks", "decode_twist_stamped",
           "decode_vector3_stamped", "decode_time_reference",
           "decode_float64", "decode_strings", "serialized"]

MAGIC = b"\x89MCAP0\r\n"
_ZSTD_FRAME = b"\x28\xb5\x2f\xfd"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_METADATA, _OP_DATA_END = 0x0C, 0x0F
_REC = struct.Struct("<BQ")
_MSG = struct.Struct("<BQH")
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")


class _Malformed(ValueError):
    """A length field points beyond the end of its record."""


@dataclass
class Channel:
    """One MCAP channel (a topic) and the pool offsets of its message records."""

    id: int
    topic: str
    type: str
    encoding: str
    metadata: dict
    records: array = field(default_factory=lambda: array("q"), repr=False)


@dataclass
class RawBag:
    """What :func:`read_raw` found: channels with message offsets into one byte pool.

    Attributes
    ----------
    path : the MCAP file.
    pool : np.ndarray of uint8, the file's bytes (its top-level records), then the
        decompressed records of every chunk.
    channels : dict topic -> Channel.
    metadata : list of (name, dict) MCAP Metadata records.
    complete : True if the data section ended with DataEnd/Footer (a clean close).
    problems : list of str, what was cut or skipped (torn tail, bad chunk).
    """

    path: Path
    pool: np.ndarray
    channels: dict
    metadata: list
    complete: bool
    problems: list
    #: every message record of the file (all channels, read or not)
    message_count: int = 0

    def offsets(self, topic: str) -> np.ndarray:
        """Pool offsets (int64) of the message records of ``topic``, in file order."""
        ch = self.channels.get(topic)
        return np.array(ch.records if ch else [], dtype=np.int64)

    def count(self, topic: str) -> int:
        ch = self.channels.get(topic)
        return len(ch.records) if ch else 0


def bag_path(bag) -> Path:
    """The MCAP file of a bag directory (metadata.yaml's file, else its single .mcap)."""
    bag = Path(bag)
    if bag.is_file():
        return bag
    if not bag.is_dir():
        raise BagReadError(f"{bag}: no such bag directory or .mcap file")
    meta = bag / "metadata.yaml"
    if meta.is_file():
        from grazing_control.support.files import YamlFileError, read_yaml_file
        try:
            info = read_yaml_file(meta)["rosbag2_bagfile_information"]
            files = [f for f in info.get("relative_file_paths", [])
                     if str(f).endswith((".mcap", ".mcap.zstd"))]
        except (KeyError, TypeError, AttributeError, YamlFileError):
            files = []
        if len(files) == 1 and (bag / files[0]).is_file():
            return bag / files[0]
        if len(files) > 1:
            raise BagReadError(f"{bag}: split bags ({len(files)} files) are not supported: "
                               "give one .mcap file")
    found = sorted(bag.glob("*.mcap")) or sorted(bag.glob("*.mcap.zstd"))
    if len(found) != 1:
        what = "no .mcap file" if not found else f"{len(found)} .mcap files"
        raise BagReadError(f"{bag}: {what} in the directory (need exactly one; "
                           "a .db3 bag must be converted to MCAP)")
    return found[0]


def _u32(buf, p, end):
    if p + 4 > end:
        raise _Malformed(f"a length field at byte {p} runs past its record's end {end}")
    return _U32.unpack_from(buf, p)[0]


def _string(buf, p, end):
    """An MCAP string (uint32 length + UTF-8) at ``p`` inside a record ending at ``end``."""
    n = _u32(buf, p, end)
    if p + 4 + n > end:
        raise _Malformed(f"a string of {n} bytes at byte {p} runs past its record's end {end}")
    return bytes(buf[p + 4:p + 4 + n]).decode("utf-8", "replace"), p + 4 + n


def _map(buf, p, end):
    """An MCAP map<string, string> (uint32 byte length + pairs) inside a record."""
    n = _u32(buf, p, end)
    p += 4
    stop = p + n
    if stop > end:
        raise _Malformed(f"a map of {n} bytes at byte {p - 4} runs past its record's end {end}")
    out = {}
    while p < stop:
        k, p = _string(buf, p, stop)
        v, p = _string(buf, p, stop)
        out[k] = v
    return out, stop


class _Scan:
    def __init__(self, wanted):
        self.wanted = wanted
        self.schemas = {}            # id -> (name, encoding)
        self.channels = {}           # id -> Channel
        self.by_id_records = {}      # id -> list (only wanted channels)
        self.metadata = []
        self.pool = bytearray()       # the file, then every chunk's records
        self.problems = []
        self.messages = 0            # every message record, wanted or not
        self.budget = max_bytes()

    def records(self, buf, start, end, top):
        """Walk records in buf[start:end]; return (stop_reason, position reached)."""
        p = start
        by_id = self.by_id_records
        unpack_msg = _MSG.unpack_from
        while p + 9 <= end:
            op, ln, cid = unpack_msg(buf, p) if p + 11 <= end else (*_REC.unpack_from(buf, p), 0)
            q = p + 9 + ln
            if q > end:
                return "torn", p
            if op == _OP_MESSAGE:
                self.messages += 1
                lst = by_id.get(cid)
                if lst is not None:
                    lst.append(p)
                elif cid not in self.channels and not top:
                    self.problems.append(f"message on unknown channel {cid} skipped")
            elif op == _OP_CHUNK and top:
                self.chunk(buf, p + 9, q)
            elif op in (_OP_SCHEMA, _OP_CHANNEL, _OP_METADATA):
                try:
                    self.definition(buf, op, p + 9, q)
                except (_Malformed, struct.error) as exc:
                    kind = {_OP_SCHEMA: "Schema", _OP_CHANNEL: "Channel",
                            _OP_METADATA: "Metadata"}[op]
                    where = "" if top else " of a chunk"
                    raise BagReadError(f"a {kind} record at byte {p}{where} is malformed "
                                       f"({exc})") from None
            elif op in (_OP_DATA_END, _OP_FOOTER) and top:
                return "end", q
            elif op == 0:       # reserved (MCAP spec): zeros, not records (a zero-filled bomb)
                return "zero", p
            p = q
        return ("torn" if p < end else "eof"), p

    def definition(self, buf, op, p, end):
        """Read a Schema, Channel or Metadata record's body ``buf[p:end]`` (bounded)."""
        if op == _OP_SCHEMA:
            if p + 2 > end:
                raise _Malformed("no schema id")
            (sid,) = _U16.unpack_from(buf, p)
            name, r = _string(buf, p + 2, end)
            enc, r = _string(buf, r, end)
            if r + 4 + _u32(buf, r, end) > end:
                raise _Malformed(f"the schema data at byte {r} runs past its record's end {end}")
            self.schemas[sid] = (name, enc)
        elif op == _OP_CHANNEL:
            if p + 4 > end:
                raise _Malformed("no channel and schema ids")
            cid, sid = struct.unpack_from("<HH", buf, p)
            if cid not in self.channels:
                topic, r = _string(buf, p + 4, end)
                enc, r = _string(buf, r, end)
                meta, _ = _map(buf, r, end)
                name = self.schemas.get(sid, ("", ""))[0]
                ch = Channel(cid, topic, name, enc, meta)
                self.channels[cid] = ch
                if self.wanted is None or topic in self.wanted:
                    self.by_id_records[cid] = ch.records
        else:
            name, r = _string(buf, p, end)
            meta, _ = _map(buf, r, end)
            self.metadata.append((name, meta))

    def chunk(self, buf, p, end):
        """Read the Chunk record whose body is ``buf[p:end]``.

        Twice streamed, never held whole: a first pass checks the size and CRC of the
        inflated records (a corrupt chunk is skipped, said in problems), a second appends
        them to the pool piece by piece and walks them as they come, stopping at the first
        zero opcode or torn record (a zero-filled bomb costs one piece, not its size).
        """
        try:
            _t0, _t1, size, crc = struct.unpack_from("<QQQI", buf, p)
            kind, r = _string(buf, p + 28, end)
            (n,) = _U64.unpack_from(buf, r)
            if r + 8 + n > end:
                raise _Malformed(f"records of {n} bytes run past the chunk's end")
            data = bytes(buf[r + 8:r + 8 + n])
            if kind:
                _check_size(size, self.budget)
            got, check = 0, 0
            for piece in _pieces(kind, data, size) if kind else (data,):
                got += len(piece)
                check = zlib.crc32(piece, check)
            if got > size:
                raise ValueError(f"more than the {size} bytes the chunk header says")
            if got < size:
                raise ValueError(f"{got} bytes, the chunk header says {size}")
            if crc and check != crc:
                raise ValueError("CRC mismatch")
        except BagReadError:
            raise
        except Exception as exc:      # a corrupt chunk: skip it, say so
            self.problems.append(f"chunk at byte {p - 9} skipped (corrupt): "
                                 f"{type(exc).__name__}: {exc}")
            return
        self.budget -= size
        pool = self.pool
        pos = len(pool)
        stop = pos + size
        for piece in _pieces(kind, data, size) if kind else (data,):
            pool += piece
            reason, pos = self.records(pool, pos, len(pool), False)
            if reason == "zero" or (reason == "torn" and _runs_past(pool, pos, stop)):
                break
        if pos < stop:
            self.problems.append(f"chunk at byte {p - 9} ends inside a record")
        del pool[pos:]        # zeros or a torn record: not records, not kept


def _runs_past(pool, pos, stop) -> bool:
    """Whether the record at ``pos`` (its header whole or cut) cannot end by ``stop``."""
    if pos + 9 > len(pool):
        return pos + 9 > stop
    return pos + 9 + _REC.unpack_from(pool, pos)[1] > stop


#: A file without summary that changed less than this many seconds ago may still be
#: being written (a recorder that flushes a chunk at least every few seconds).
WRITING_AGE = 30.0


def _age(path: Path) -> float:
    import time
    try:
        return max(0.0, time.time() - os.stat(path).st_mtime)
    except OSError:
        return float("inf")


def read_raw(bag, topics=None) -> RawBag:
    """Stream an MCAP file (or a bag directory's file) into a :class:`RawBag`.

    Parameters
    ----------
    bag : path of a bag directory or of an .mcap file.
    topics : iterable of str, optional
        Keep message offsets only for these topics (all channels are listed anyway).

    Raises
    ------
    BagReadError
        Not a regular file, not an MCAP file, an unsupported chunk compression, a Schema,
        Channel or Metadata record whose length fields run past its end, or more
        decompressed bytes than :func:`max_bytes` allows (the memory bound).
    """
    path = _regular_file(bag_path(bag))
    cap = max_bytes()
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size > cap:
            raise BagReadError(f"{path}: {size} bytes, beyond the {cap} bytes a bag may have "
                               "(the analysis's memory bound); GRAZING_BAG_MAX_BYTES raises "
                               "the limit")
        data = bytearray(size)
        data[fh.readinto(data):] = b""
    scan = _Scan(None if topics is None else set(topics))
    scan.budget = max_bytes(len(data))
    if data.startswith(_ZSTD_FRAME):     # rosbag2 "file" compression mode: a .mcap.zstd
        import zstandard
        try:
            data = _read_zstd(data, scan.budget)
        except zstandard.ZstdError as exc:
            raise BagReadError(f"{path}: a zstd-compressed file that does not decompress "
                               f"({exc})") from None
        if len(data) > scan.budget:
            raise BagReadError(f"{path}: the zstd-compressed file decompresses to more than "
                               f"{scan.budget} bytes (a decompression bomb?); "
                               "GRAZING_BAG_MAX_BYTES raises the limit")
        scan.budget -= len(data)
    if not data.startswith(MAGIC):
        raise BagReadError(f"{path}: not an MCAP file (bad magic bytes)")
    # top-level messages (unchunked files) point into the file itself: it goes first
    scan.pool = data
    size = len(data)
    try:
        reason, stop = scan.records(data, len(MAGIC), size, True)
    except BagReadError as exc:
        raise BagReadError(f"{path}: {exc}") from None
    problems = scan.problems
    if reason != "end":
        age = _age(path)
        why = (f"still being written? it changed {age:.1f} s ago" if age < WRITING_AGE
               else "recorder killed?")
        problems.insert(0, f"the file has no summary ({why}): read up to byte "
                           f"{stop} of {size}" + (", the rest is a torn record"
                                                  if stop < size else ""))
    pool = np.frombuffer(scan.pool, dtype=np.uint8)
    channels = {}
    for ch in scan.channels.values():
        if ch.topic in channels:           # two channels on one topic (two types): merge
            merged = channels[ch.topic].records
            merged[:] = array("q", sorted(merged + ch.records))
        else:
            channels[ch.topic] = ch
    return RawBag(path, pool, channels, scan.metadata, reason == "end", problems,
                  scan.messages)


# ----------------------------------------------------------------- vectorised CDR
_R = {n: np.arange(n, dtype=np.int64) for n in (4, 8)}
#: A sequence<string> longer than this is walked per message (see _Body.skip_strings).
_MANY = 64


def _gather(pool, off, n, dtype, ok, end):
    """Values of ``dtype`` (n bytes) at pool offsets ``off``; ``ok`` narrowed in place."""
    ok &= off + n <= end
    safe = np.where(ok, off, 0)
    return pool[safe[:, None] + _R[n]].view(dtype)[:, 0]


def _align(pos, n):
    return (pos + (n - 1)) & ~np.int64(n - 1)


class _Body:
    """Message records at pool offsets: times, CDR body start and end, validity."""

    def __init__(self, pool, rec):
        self.pool = pool
        rec = np.asarray(rec, dtype=np.int64)
        if rec.size == 0:
            z = np.zeros(0, np.int64)
            self.log_time = self.publish_time = self.sequence = z
            self.body = self.end = z
            self.ok = np.zeros(0, bool)
            return
        ok = np.ones(rec.size, bool)
        big = np.full(rec.size, np.iinfo(np.int64).max)
        length = _gather(pool, rec + 1, 8, "<u8", ok, big).astype(np.int64)
        self.end = rec + 9 + length
        self.sequence = _gather(pool, rec + 11, 4, "<u4", ok, self.end).astype(np.int64)
        self.log_time = _gather(pool, rec + 15, 8, "<u8", ok, self.end).astype(np.int64)
        self.publish_time = _gather(pool, rec + 23, 8, "<u8", ok, self.end).astype(np.int64)
        data = rec + 31
        enc = _gather(pool, data, 4, "<u4", ok, self.end)
        # encapsulation: 00 01 (CDR_LE) or 00 03 (PL_CDR_LE); big endian is refused
        ok &= ((enc & 0xFFFF) == 0x0100) | ((enc & 0xFFFF) == 0x0300)
        self.body = data + 4
        self.ok = ok

    def u32(self, pos):
        return _gather(self.pool, self.body + pos, 4, "<u4", self.ok, self.end).astype(np.int64)

    def i32(self, pos):
        return _gather(self.pool, self.body + pos, 4, "<i4", self.ok, self.end).astype(np.int64)

    def f64(self, pos):
        return _gather(self.pool, self.body + pos, 8, "<f8", self.ok, self.end)

    def header(self):
        """(stamp ns as int64, position after header) of std_msgs/Header at the body start."""
        sec = self.i32(np.zeros_like(self.body))
        nsec = self.u32(np.full_like(self.body, 4))
        flen = self.u32(np.full_like(self.body, 8))
        self.ok &= flen <= self.end - self.body
        return sec * 1_000_000_000 + nsec, 12 + np.where(self.ok, flen, 0)

    def skip_strings(self, pos):
        """Position after a sequence<string> at ``pos``.

        Vectorised over the messages, one step per string; a message with more than
        ``_MANY`` strings is walked on its own (bounded by its length).
        """
        pos = _align(pos, 4)
        n = self.u32(pos)
        self.ok &= n <= (self.end - self.body) // 4
        n = np.where(self.ok, n, 0)
        pos = pos + 4
        many = np.flatnonzero(n > _MANY)
        for i in many.tolist():
            pos[i] = self._walk_strings(i, int(pos[i]), int(n[i]))
        n[many] = 0
        for j in range(int(n.max()) if n.size else 0):
            on = self.ok & (n > j)
            pj = _align(pos, 4)
            ln = self.u32(np.where(on, pj, 0))
            pos = np.where(on & self.ok, pj + 4 + ln, pos)
        return pos

    def _walk_strings(self, i, pos, n):
        end = int(self.end[i] - self.body[i])
        base = int(self.body[i])
        for _ in range(n):
            pos = (pos + 3) & ~3
            if pos + 4 > end:
                self.ok[i] = False
                return 0
            ln = int(self.pool[base + pos:base + pos + 4].view("<u4")[0])
            pos += 4 + ln
            if pos > end:
                self.ok[i] = False
                return 0
        return pos

    def first_double(self, pos):
        """(seq[0] or NaN, count, position after) of a sequence<double> at ``pos``."""
        return self.nth_double(pos, 0)

    def nth_double(self, pos, j: int):
        """(seq[j] or NaN, count, position after) of a sequence<double> at ``pos``."""
        pos = _align(pos, 4)
        n = np.where(self.ok, self.u32(pos), 0)
        self.ok &= n <= self.end - self.body
        pos = pos + 4
        p8 = _align(pos, 8)
        has = n > j
        val = np.where(has, self.f64(np.where(has, p8 + 8 * j, 0)), np.nan)
        return val, n, np.where(n > 0, p8 + 8 * n, pos)


def decode_stamped(bag: RawBag, topic: str):
    """(_Body, stamp ns, position after header) for a message type starting with a Header."""
    b = _Body(bag.pool, bag.offsets(topic))
    stamp, pos = b.header()
    return b, stamp, pos


def decode_joint_state(bag: RawBag, topic: str) -> dict:
    """JointState columns: stamp_ns, x = position[0], v = velocity[0], times, ok."""
    b, stamp, pos = decode_stamped(bag, topic)
    pos = b.skip_strings(pos)
    x, nx, pos = b.first_double(pos)
    v, nv, pos = b.first_double(pos)
    b.ok &= (nx > 0) & (nv > 0)
    return _columns(b, stamp=stamp, x=x, v=v)


def joint_count(bag: RawBag, topic: str) -> int:
    """The largest position count of the JointState messages on ``topic`` (0 if none):
    1 for the 1-DOF scenes, n for an n-DOF scene (issue 17)."""
    b, _stamp, pos = decode_stamped(bag, topic)
    pos = _align(b.skip_strings(pos), 4)
    n = np.where(b.ok, b.u32(pos), 0)
    n = n[b.ok & (n <= b.end - b.body)]
    return int(n.max()) if n.size else 0


def decode_joint_states(bag: RawBag, topic: str, n: int) -> dict:
    """JointState columns of an n-DOF scene (issue 17): stamp_ns, x (N, n) = position,
    v (N, n) = velocity, times, ok (ok: exactly n positions and n velocities)."""
    b, stamp, pos = decode_stamped(bag, topic)
    pos = b.skip_strings(pos)
    cols = []
    for _ in range(2):                  # position, velocity
        pos = _align(pos, 4)
        count = np.where(b.ok, b.u32(pos), 0)
        b.ok &= count == n
        p8 = _align(pos + 4, 8)
        cols.append(np.column_stack([np.where(b.ok, b.f64(np.where(b.ok, p8 + 8 * j, 0)),
                                              np.nan) for j in range(n)])
                    if n else np.zeros((b.ok.size, 0)))
        pos = np.where(b.ok, p8 + 8 * n, pos)
    return _columns(b, stamp=stamp, x=cols[0], v=cols[1])


def decode_estimate(bag: RawBag, topic: str) -> dict:
    """The controller's estimate (JointState, effort [var x, cov xv, var v]): columns
    stamp_ns, x, v, var_x, cov_xv, var_v, times, ok (ok needs the three efforts)."""
    b, stamp, pos = decode_stamped(bag, topic)
    pos = b.skip_strings(pos)
    x, nx, pos = b.first_double(pos)
    v, nv, pos = b.first_double(pos)
    var_x, ne, pos8 = b.first_double(pos)
    b.ok &= (nx > 0) & (nv > 0) & (ne >= 3)
    start = np.where(b.ok, pos8 - 8 * ne, 0)
    cov_xv = np.where(b.ok, b.f64(start + 8), np.nan)
    var_v = np.where(b.ok, b.f64(start + 16), np.nan)
    return _columns(b, stamp=stamp, x=x, v=v, var_x=var_x, cov_xv=cov_xv, var_v=var_v)


def decode_joint_stream(bag: RawBag, topic: str, coordinate: int = 0) -> dict:
    """A sensor's state stream (docs/nodes.md, "The sensor stream"): stamp_ns,
    x = position[coordinate], v = velocity[coordinate] (NaN where the velocity is empty:
    a position-only sensor), e0, e1 = effort[0], effort[1] (the phase reference cos tau,
    sin tau; NaN where absent), times, ok (a message without that position is not ok).
    ``coordinate`` > 0: an n-DOF scene's stream, one position per coordinate (issue 32)."""
    b, stamp, pos = decode_stamped(bag, topic)
    pos = b.skip_strings(pos)
    x, nx, pos = b.nth_double(pos, coordinate)
    v, nv, pos = b.nth_double(pos, coordinate)
    pe = _align(pos, 4)
    ne = np.where(b.ok, b.u32(pe), 0)
    b.ok &= ne <= b.end - b.body
    p8 = _align(pe + 4, 8)
    has1, has2 = ne > 0, ne > 1
    e0 = np.where(has1, b.f64(np.where(has1, p8, 0)), np.nan)
    e1 = np.where(has2, b.f64(np.where(has2, p8 + 8, 0)), np.nan)
    b.ok &= nx > coordinate
    return _columns(b, stamp=stamp, x=x, v=np.where(nv > coordinate, v, np.nan), e0=e0, e1=e1)


def decode_state_blocks(bag: RawBag, topic: str, coordinate: int = 0) -> dict:
    """The state stream in blocks (``oscillator/state_block``, sim_node's
    ``stream_message:=block``; grazing_control.ros.stream_block), expanded into one row
    per sample with :func:`decode_joint_stream`'s columns: stamp_ns, x = position of
    ``coordinate``, v its velocity (NaN: a position-only sensor), e0, e1 (cos tau,
    sin tau), times (its block's), ok; and ``masses``, the n of each sample's block (an
    n-DOF scene's rows carry n positions and n velocities, issue 32). A message that is
    not a block is one row, not ok, masses 0; a block without that coordinate (masses
    <= coordinate) gives rows that are not ok."""
    from grazing_control.ros.stream_block import read as read_block

    b = _Body(bag.pool, bag.offsets(topic))
    cols, owner, masses = [], [], []
    for i in range(b.body.size):
        rows = None
        if b.ok[i]:
            rows = read_block(bag.pool[int(b.body[i]) - 4:int(b.end[i])].tobytes())
        if rows is None:
            cols.append(np.zeros((1, 6)))
            owner.append(np.full(1, i))
            masses.append(np.zeros(1, np.int64))
            continue
        n, w = rows.masses, 4 + 2 * rows.masses
        a = np.array(rows.flat, dtype=float).reshape(-1, w)
        c = min(coordinate, n - 1)       # a block without the coordinate: rows not ok
        cols.append(a[:, [0, 1, 2 + c, 2 + n + c, w - 2, w - 1]])
        owner.append(np.full(len(a), i))
        masses.append(np.full(len(a), n, np.int64))
    a = np.concatenate(cols) if cols else np.zeros((0, 6))
    owner = np.concatenate(owner).astype(np.int64) if owner else np.zeros(0, np.int64)
    masses = np.concatenate(masses) if masses else np.zeros(0, np.int64)
    ok = masses > coordinate
    return {"log_time": b.log_time[owner], "publish_time": b.publish_time[owner],
            "sequence": b.sequence[owner], "ok": ok, "masses": masses,
            "stamp": a[:, 0].astype(np.int64) * 1_000_000_000 + a[:, 1].astype(np.int64),
            "x": a[:, 2], "v": a[:, 3], "e0": a[:, 4], "e1": a[:, 5]}


def serialized(bag: RawBag, topic: str) -> dict:
    """The messages of ``topic`` as recorded: columns log_time, publish_time, sequence,
    ok (the record whole, little-endian CDR) and ``data``, a list of each message's
    serialized bytes (encapsulation header and body, what rclpy publishes and a raw
    subscription receives; b"" where not ok), in file order."""
    b = _Body(bag.pool, bag.offsets(topic))
    data = [bag.pool[int(s) - 4:int(e)].tobytes() if ok else b""
            for s, e, ok in zip(b.body, b.end, b.ok)]
    return _columns(b, data=data)


def decode_twist_stamped(bag: RawBag, topic: str) -> dict:
    """TwistStamped columns: stamp_ns, dv = twist.linear.x, dv_next = twist.linear.y (the
    predicted next correction; NaN: none, 0.0 in bags from before the prediction), times,
    ok."""
    b, stamp, pos = decode_stamped(bag, topic)
    dv = b.f64(_align(pos, 8))
    dv_next = b.f64(_align(pos, 8) + 8)
    return _columns(b, stamp=stamp, dv=dv, dv_next=dv_next)


def decode_vector3_stamped(bag: RawBag, topic: str) -> dict:
    """Vector3Stamped columns: stamp_ns, vx, vy, vz, times, ok."""
    b, stamp, pos = decode_stamped(bag, topic)
    p = _align(pos, 8)
    return _columns(b, stamp=stamp, vx=b.f64(p), vy=b.f64(p + 8), vz=b.f64(p + 16))


def decode_time_reference(bag: RawBag, topic: str) -> dict:
    """sensor_msgs/TimeReference columns: stamp_ns (header.stamp: ROS time), time_ref_ns
    (the rig clock, docs/driver_contract.md), times, ok (the source string is skipped)."""
    b, stamp, pos = decode_stamped(bag, topic)
    p = _align(pos, 4)
    sec, nsec = b.i32(p), b.u32(p + 4)
    return _columns(b, stamp=stamp, time_ref=sec * 1_000_000_000 + nsec)


def decode_float64(bag: RawBag, topic: str) -> dict:
    """std_msgs/Float64 columns: data, times, ok."""
    b = _Body(bag.pool, bag.offsets(topic))
    return _columns(b, data=b.f64(np.zeros_like(b.body)))


def decode_strings(bag: RawBag, topic: str) -> list:
    """std_msgs/String messages as (log_time_ns, text), in file order (few messages)."""
    b = _Body(bag.pool, bag.offsets(topic))
    n = b.u32(np.zeros_like(b.body))
    out = []
    for i in np.flatnonzero(b.ok & (n <= b.end - b.body - 4)):
        s = int(b.body[i]) + 4
        raw = bag.pool[s:s + int(n[i])].tobytes().rstrip(b"\0")
        out.append((int(b.log_time[i]), raw.decode("utf-8", "replace")))
    return out


def decode_values(bag: RawBag, topic: str, n: int) -> dict:
    """JointState rows of ``n`` named values in ``position`` (the controller's
    controller/model_watch, grazing_control.ros.model_watch.WATCH_FIELDS in order):
    stamp_ns, values (N, n), times, ok (ok: exactly n positions)."""
    b, stamp, pos = decode_stamped(bag, topic)
    pos = _align(b.skip_strings(pos), 4)
    count = np.where(b.ok, b.u32(pos), 0)
    b.ok &= count == n
    p8 = _align(pos + 4, 8)
    values = np.column_stack([np.where(b.ok, b.f64(np.where(b.ok, p8 + 8 * j, 0)), np.nan)
                              for j in range(n)])
    return _columns(b, stamp=stamp, values=values)


def _columns(b: _Body, **cols) -> dict:
    out = {"log_time": b.log_time, "publish_time": b.publish_time, "sequence": b.sequence,
           "ok": b.ok.copy()}
    out.update(cols)
    return out

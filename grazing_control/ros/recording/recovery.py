"""Recovery of a bag whose recorder died: ``grazing bag reindex``, like ``ros2 bag reindex``.
"""


import errno
import io
import os
import struct
import zlib
from pathlib import Path
from typing import NamedTuple

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader

from .bounded import decompress, max_bytes, regular_file
from grazing_control.support.files import YamlFileError

from .reading import _has_summary, bag_file, read_metadata
from .schemas import DEFAULT_CHUNK_SIZE
from .writer import BagWriter


_RECORD = struct.Struct("<BQ")
_OP_CHUNK = 0x06


def _parse(data: bytes) -> list:
    """The whole records of ``data`` (no magic) parsed by mcap's stream reader, a chunk as a
    Chunk record (never inflated there: :func:`_records` does it, bounded).

    mcap's reader reads on to a footer: the end of ``data`` ends the list.
    """
    out = []
    records = StreamReader(io.BytesIO(data), skip_magic=True, emit_chunks=True,
                           validate_crcs=False).records
    try:
        for record in records:
            out.append(record)
    except EndOfFile:
        pass
    return out


def _whole_records(data: bytes) -> bytes:
    """The prefix of a chunk's records up to a torn record or a reserved opcode 0 (zeros)."""
    p, n = 0, len(data)
    while p + _RECORD.size <= n:
        op, length = _RECORD.unpack_from(data, p)
        if op == 0 or p + _RECORD.size + length > n:
            break
        p += _RECORD.size + length
    return data[:p]


def _records(stream, budget: int):
    """Yield (record, end offset, bytes inflated) for every complete record of ``stream``.

    The file is walked record by record from its magic; a chunk is inflated within what
    is left of the decompression budget (:func:`.bounded.decompress`: a bomb, honest or
    lying about its size, never costs more), its CRC checked, and its inner records
    yielded in order. The walk stops quietly where the file ends inside a record or a
    record is malformed (a killed recorder's torn tail); a chunk beyond the budget raises
    :class:`.bounded.BagReadError`.
    """
    while True:
        start = stream.tell()
        head = stream.read(_RECORD.size)
        if len(head) < _RECORD.size:
            return
        op, length = _RECORD.unpack(head)
        if op == 0:         # reserved (MCAP spec): zeros, not records
            return
        body = stream.read(length) if length <= budget + (1 << 20) else b""
        if len(body) < length:
            return
        end = start + _RECORD.size + length
        try:
            parsed = _parse(head + body)
        except (McapError, EOFError, ValueError, struct.error):
            return
        if not parsed:
            return
        record = parsed[0]
        if op != _OP_CHUNK or not isinstance(record, Chunk):
            yield record, end, 0
            continue
        try:
            inner = decompress(record.compression, record.data, record.uncompressed_size,
                               budget)
        except ValueError as exc:
            if type(exc) is not ValueError:     # BagReadError: over the budget
                raise
            return
        if record.uncompressed_crc and zlib.crc32(inner) != record.uncompressed_crc:
            return
        try:
            records = _parse(_whole_records(bytes(inner)))
        except (McapError, EOFError, ValueError, struct.error):
            return
        yield None, end, len(inner) if record.compression else 0
        for r in records:
            if r is not None:
                yield r, end, 0


# --------------------------------------------------------------------------
# Recovery
# --------------------------------------------------------------------------

#: A write that failed for want of room (a full file system, a quota, a file size limit).
_NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def _no_room(exc: OSError, bag_dir: Path, size: int) -> OSError:
    """The error of a reindex that found no room for its copy: what to do about it."""
    return OSError(exc.errno, f"{bag_dir}: {exc.strerror}: reindex writes the recovered "
                              f"bag next to it (up to {size} bytes) before it replaces it, "
                              "and the bag is unchanged; free space on its file system, or "
                              "copy the bag directory to one with room and reindex the copy")


class ReindexResult(NamedTuple):
    """What :func:`reindex` recovered."""

    path: Path               # the rewritten .mcap file
    message_count: int       # messages recovered
    topics: dict             # topic -> messages recovered
    had_summary: bool        # the file was complete before
    dropped_bytes: int       # bytes after the last complete record (an unfinished chunk)


def reindex(bag_dir: str | os.PathLike, *, compression: str = "zstd",
            chunk_size: int = DEFAULT_CHUNK_SIZE) -> ReindexResult:
    """Rewrite a bag's MCAP file with a summary and write its ``metadata.yaml``.

    The recovery of a recording whose recorder died (SIGKILL, power loss), like
    ``ros2 bag reindex``: the file is read sequentially, every message of every
    complete chunk is kept (with its log time, publish time and sequence number), its
    schemas and channels (with ``offered_qos_profiles`` and ``topic_type_hash``) as
    recorded, and what follows the last complete record (the chunk being filled) is
    dropped. A new file with chunk indexes, statistics and the ``rosbag2`` metadata
    record is written next to it and renamed over it, then ``metadata.yaml``: mcap's
    seeking reader, ``mcap_ros2``, ``rosbags`` and ``ros2 bag`` then open it. A
    complete bag is rewritten the same way (its messages unchanged).

    Parameters
    ----------
    bag_dir : str or Path
        The bag directory (with one ``.mcap`` file; ``metadata.yaml`` may be missing).
    compression, chunk_size
        Of the rewritten file (:class:`BagWriter`).

    Returns
    -------
    ReindexResult

    Raises
    ------
    FileNotFoundError, ValueError
        No bag there, or a file that is not MCAP at all.
    """
    import shutil
    import tempfile

    bag_dir = Path(bag_dir)
    if not bag_dir.is_dir():
        raise FileNotFoundError(f"{bag_dir}: no such bag directory")
    path = regular_file(bag_file(bag_dir))
    size = path.stat().st_size
    with open(path, "rb") as stream:
        had_summary = _has_summary(stream)
        stream.seek(0)
        if stream.read(8) != b"\x89MCAP0\r\n":
            raise ValueError(f"{path}: not an MCAP file")
        schemas, channels, messages = {}, {}, []
        end = 8
        budget = max_bytes(size)
        for record, end_of_record, inflated in _records(stream, budget):
            budget -= inflated
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                messages.append(record)
            elif isinstance(record, (DataEnd, Footer)):
                break
            end = end_of_record
    custom = {}
    try:
        custom = dict(read_metadata(bag_dir).get("custom_data") or {})
    except (YamlFileError, KeyError, TypeError):
        pass
    try:
        tmp_root = Path(tempfile.mkdtemp(prefix=f".{bag_dir.name}.reindex-",
                                         dir=bag_dir.parent))
    except OSError as exc:
        raise _no_room(exc, bag_dir, size) if exc.errno in _NO_ROOM else exc
    try:
        writer = BagWriter(tmp_root / bag_dir.name, compression=compression,
                           chunk_size=chunk_size, custom_data=custom)
        writer.path = writer.bag_dir / path.name
        writer.open()
        names = {}
        for channel in sorted(channels.values(), key=lambda c: c.id):
            schema = schemas.get(channel.schema_id)
            if schema is None or channel.topic in names.values():
                continue
            writer.add_topic(channel.topic, schema.name,
                             channel.metadata.get("offered_qos_profiles", ""),
                             type_hash=channel.metadata.get("topic_type_hash", ""),
                             schema_data=schema.data)
            names[channel.id] = channel.topic
        for m in messages:
            topic = names.get(m.channel_id)
            if topic is not None:
                writer.write(topic, m.data, m.log_time, m.publish_time, m.sequence)
        writer.close()
        os.replace(writer.path, path)
        os.replace(writer.bag_dir / "metadata.yaml", bag_dir / "metadata.yaml")
    except OSError as exc:
        if exc.errno in _NO_ROOM:
            raise _no_room(exc, bag_dir, size) from exc
        raise
    finally:
        shutil.rmtree(tmp_root, ignore_errors=True)
    counts = dict(writer.message_counts)
    return ReindexResult(path, sum(counts.values()), counts, had_summary,
                         0 if had_summary else max(0, size - end))

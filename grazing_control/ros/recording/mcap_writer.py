"""An MCAP writer whose message path is one pack: the recorder's per-message cost (issue 30).

It writes the same file as ``mcap.writer.Writer`` with chunking, every index, statistics
and summary offsets (the options :class:`~.writer.BagWriter` uses), byte for byte
(tests/test_recording_mcap_writer.py holds it to that over random scenes). The
difference is where the time goes. ``mcap``'s writer builds a ``Message`` record object
per message and writes its five fields through five calls, then a tuple into the
chunk's message index and the statistics by attribute (about 4 µs a message here);
this one packs a message's header with one precompiled ``struct`` call into the chunk's
``bytearray`` and appends its log time and offset to a flat list (docs/benchmarks.md,
"The recorder's writer"). Per-chunk work (the statistics' times and counts, the message
indexes, each packed in one call) is done when the chunk is finished.

Records (MCAP specification, https://mcap.dev/spec): a record is opcode (uint8), length
(uint64) and body. A Message's body is channel id (uint16), sequence (uint32), log time
and publish time (uint64) and the data; a Message Index's is channel id (uint16), the
byte length of its entries (uint32) and the (log time, offset) pairs (uint64 each), the
offset counted from the start of the chunk's uncompressed records. Every other record is
written with ``mcap.records``' own classes.
"""

import struct
import zlib
from collections import defaultdict
from typing import IO, Dict

from mcap.data_stream import RecordBuilder
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.opcode import Opcode

#: The magic at the start and the end of an MCAP file (not imported from ``mcap.writer``,
#: whose import takes 26 ms, most of it importlib.metadata's, on a node's start-up)
MCAP0_MAGIC = b"\x89MCAP0\r\n"

_MESSAGE_OPCODE = int(Opcode.MESSAGE)
_MESSAGE = struct.Struct("<BQHIQQ")     # opcode, length, channel, sequence, log, publish
_MESSAGE_BODY = 2 + 4 + 8 + 8           # the body's fixed part
_COMPRESSORS = ("none", "lz4", "zstd")


class McapWriter:
    """Chunked MCAP writer (``mcap.writer.Writer``'s subset that a recorder uses).

    Parameters
    ----------
    stream : binary file object
        Written to with ``write`` and ``tell``; not closed by :meth:`finish`.
    chunk_size : int
        A chunk is finished once its uncompressed records exceed this many bytes.
    compression : {"zstd", "lz4", "none"}

    Notes
    -----
    Like ``mcap``'s writer (the same defaults): schemas and channels are written into
    the open chunk and repeated in the summary; every chunk is followed by its message
    indexes; the summary has statistics, chunk indexes, an (empty) attachment index
    group, metadata indexes and summary offsets; CRCs of chunks and of the summary, no
    data section CRC. Not thread-safe.
    """

    def __init__(self, stream: IO[bytes], *, chunk_size: int = 1024 * 1024,
                 compression: str = "zstd"):
        if compression not in _COMPRESSORS:
            raise ValueError(f"compression must be one of {', '.join(_COMPRESSORS)}, "
                             f"not {compression!r}")
        self._compress = _compressor(compression)
        self._compression = "" if compression == "none" else compression
        self._stream = stream
        self._chunk_size = int(chunk_size)
        self._chunk = bytearray()
        self._index: Dict[int, list] = {}       # channel id -> [log, offset, log, ...]
        self._schemas: Dict[int, Schema] = {}
        self._channels: Dict[int, Channel] = {}
        self._chunk_indexes: list = []
        self._metadata_indexes: list = []
        self._counts: Dict[int, int] = defaultdict(int)
        self._message_count = 0
        self._start_time = 0
        self._end_time = 0
        self._chunk_count = 0
        self._metadata_count = 0

    # -- the file's records ---------------------------------------------------

    def start(self, profile: str = "", library: str = "") -> None:
        """Write the magic and the Header record."""
        records = RecordBuilder()
        Header(profile, library).write(records)
        self._stream.write(MCAP0_MAGIC + records.end())

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A Schema record in the open chunk; return its id (1, 2, ...)."""
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas[schema.id] = schema
        self._into_chunk(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: Dict[str, str] | None = None) -> int:
        """A Channel record in the open chunk; return its id (1, 2, ...)."""
        channel = Channel(id=len(self._channels) + 1, topic=topic,
                          message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata or {}))
        self._channels[channel.id] = channel
        self._into_chunk(channel)
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        """A Message record in the open chunk (the hot path: one pack, three appends).

        A field out of its range (struct.error) or data that is not a contiguous
        bytes-like object (TypeError) adds nothing: the chunk is as it was."""
        chunk = self._chunk
        offset = len(chunk)
        # len() counts bytes of bytes and bytearray only (a memoryview counts its items)
        size = len(data) if type(data) is bytes else memoryview(data).nbytes
        chunk += _MESSAGE.pack(_MESSAGE_OPCODE, _MESSAGE_BODY + size, channel_id,
                               sequence, log_time, publish_time)
        try:
            chunk += data
        except Exception:           # not a contiguous buffer: the header goes too
            del chunk[offset:]
            raise
        index = self._index.get(channel_id)
        if index is None:
            index = self._index[channel_id] = []
        index.append(log_time)
        index.append(offset)
        if len(chunk) > self._chunk_size:
            self._finish_chunk()

    def add_metadata(self, name: str, data: Dict[str, str]) -> None:
        """A Metadata record after the open chunk's records (and its index)."""
        records = RecordBuilder()
        Metadata(name=name, metadata=data).write(records)
        record = records.end()
        self._metadata_count += 1
        self._metadata_indexes.append(
            MetadataIndex(offset=self._stream.tell(), length=len(record), name=name))
        self._stream.write(record)

    def finish(self) -> None:
        """The last chunk, Data End, the summary, the Footer and the closing magic."""
        self._finish_chunk()
        records = RecordBuilder()
        DataEnd(0).write(records)
        self._stream.write(records.end())
        summary_start = self._stream.tell()
        summary = RecordBuilder()
        offsets = []

        def group(opcode, items):
            start = summary.count
            for item in items:
                item.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode,
                                         group_start=summary_start + start,
                                         group_length=summary.count - start))

        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(Opcode.STATISTICS, [self._statistics()])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, [])
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start,
                                     offset_start), zlib.crc32(data))
        footer = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=offset_start,
               summary_crc=crc).write(footer)
        self._stream.write(data + footer.end() + MCAP0_MAGIC)

    # -- what was written -------------------------------------------------------

    def message_counts(self) -> Dict[int, int]:
        """Messages added per channel id, the open chunk's included."""
        counts = dict(self._counts)
        for channel_id, index in self._index.items():
            counts[channel_id] = counts.get(channel_id, 0) + len(index) // 2
        return counts

    def message_times(self) -> tuple[int, int] | None:
        """(earliest, latest) log time of the messages added, or None if there is none."""
        times = [t for index in self._index.values() for t in index[::2]]
        if self._message_count:
            times += [self._start_time, self._end_time]
        return (min(times), max(times)) if times else None

    # -- chunks ---------------------------------------------------------------

    def _into_chunk(self, record) -> None:
        records = RecordBuilder()
        record.write(records)
        self._chunk += records.end()
        if len(self._chunk) > self._chunk_size:
            self._finish_chunk()

    def _finish_chunk(self) -> None:
        """Write the open chunk (if it holds a message) and its message indexes."""
        if not self._index:
            return          # schemas and channels alone: kept for the next chunk
        data = bytes(self._chunk)
        start = min(min(index[::2]) for index in self._index.values())
        end = max(max(index[::2]) for index in self._index.values())
        compressed = self._compress(data)
        records = RecordBuilder()
        Chunk(compression=self._compression, data=compressed, message_start_time=start,
              message_end_time=end, uncompressed_crc=zlib.crc32(data),
              uncompressed_size=len(data)).write(records)
        chunk_record = records.end()
        chunk_offset = self._stream.tell()
        index_start = chunk_offset + len(chunk_record)
        index_records, index_offsets, position = [], {}, index_start
        for channel_id, index in self._index.items():
            index_offsets[channel_id] = position
            index_records.append(struct.pack(
                f"<BQHI{len(index)}Q", Opcode.MESSAGE_INDEX, 2 + 4 + 8 * len(index),
                channel_id, 8 * len(index), *index))
            position += len(index_records[-1])
            self._counts[channel_id] += len(index) // 2
        self._stream.write(chunk_record + b"".join(index_records))
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_offset,
            chunk_length=len(chunk_record), message_index_offsets=index_offsets,
            message_index_length=position - index_start,
            compression=self._compression, compressed_size=len(compressed),
            uncompressed_size=len(data)))
        self._start_time = start if self._message_count == 0 else min(self._start_time, start)
        self._end_time = max(self._end_time, end)
        self._message_count += sum(len(index) for index in self._index.values()) // 2
        self._chunk_count += 1
        self._chunk = bytearray()
        self._index = {}

    def _statistics(self) -> Statistics:
        return Statistics(
            attachment_count=0, channel_count=len(self._channels),
            channel_message_counts=dict(self._counts), chunk_count=self._chunk_count,
            message_count=self._message_count, metadata_count=self._metadata_count,
            message_start_time=self._start_time, message_end_time=self._end_time,
            schema_count=len(self._schemas))


def _compressor(name: str):
    if name == "zstd":
        import zstandard
        return zstandard.compress
    if name == "lz4":
        import lz4.frame
        return lz4.frame.compress
    return lambda data: data

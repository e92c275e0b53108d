"""Recovery of a bag whose recorder died: ``grazing bag reindex``, like ``ros2 bag reindex``.
"""


import os
import struct
from pathlib import Path
from typing import NamedTuple

import yaml
from mcap.exceptions import McapError
from mcap.records import Channel, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader

from .reading import _has_summary, bag_file, read_metadata
from .schemas import DEFAULT_CHUNK_SIZE
from .writer import BagWriter


# --------------------------------------------------------------------------
# Recovery
# --------------------------------------------------------------------------

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
    path = bag_file(bag_dir)
    size = path.stat().st_size
    with open(path, "rb") as stream:
        had_summary = _has_summary(stream)
        head = stream.read(8)
        stream.seek(0)
        if head != b"\x89MCAP0\r\n":
            raise ValueError(f"{path}: not an MCAP file")
        schemas, channels, messages = {}, {}, []
        end = 8
        reader = StreamReader(stream, validate_crcs=True)
        try:
            for record in reader.records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
                elif isinstance(record, (DataEnd, Footer)):
                    break
                end = stream.tell()
        except (McapError, EOFError, ValueError, struct.error):
            pass    # the file ends inside a record: keep what came before it
    custom = {}
    try:
        custom = dict(read_metadata(bag_dir).get("custom_data") or {})
    except (OSError, KeyError, TypeError, yaml.YAMLError):
        pass
    tmp_root = Path(tempfile.mkdtemp(prefix=f".{bag_dir.name}.reindex-", dir=bag_dir.parent))
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
    finally:
        shutil.rmtree(tmp_root, ignore_errors=True)
    counts = dict(writer.message_counts)
    return ReindexResult(path, sum(counts.values()), counts, had_summary,
                         0 if had_summary else max(0, size - end))

"""Reading a bag back: with the ``mcap`` ROS 2 decoder, or with ``rosbags`` (a second,
independent reader), also a file whose recorder died (no summary).
"""


import os
import struct
from pathlib import Path
from typing import Any, Iterable, Iterator, NamedTuple

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader


from .schemas import *  # noqa: F403
# --------------------------------------------------------------------------
# Readers
# --------------------------------------------------------------------------

class BagMessage(NamedTuple):
    """One recorded message, decoded."""

    topic: str
    type: str
    log_time_ns: int
    message: Any


def read_metadata(bag_dir: str | os.PathLike) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag's ``metadata.yaml``, read
    within the limits of a parameter file (:func:`grazing_control.support.files.read_yaml_file`:
    a YamlFileError, a ValueError naming the file, beyond them or for a missing file;
    a YamlFileError also for a file that is no rosbag2 metadata: empty, or without a
    ``rosbag2_bagfile_information`` mapping)."""
    from grazing_control.support.files import YamlFileError, read_yaml_file

    path = Path(bag_dir) / "metadata.yaml"
    doc = read_yaml_file(path)
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise YamlFileError(f"{path}: not a rosbag2 metadata.yaml (no "
                            "rosbag2_bagfile_information mapping)")
    return info


def bag_file(bag_dir: str | os.PathLike) -> Path:
    """The MCAP file of a bag directory (or the path itself if it is a file).

    Taken from ``metadata.yaml`` if present, else the single ``*.mcap`` in the
    directory (a recorder that died leaves no ``metadata.yaml``; one cut short by a full
    disk can leave it empty or unreadable, and then the directory's own file is taken
    too, as by :func:`grazing_control.recordings.reader.bag_path`).
    """
    from grazing_control.support.files import YamlFileError

    bag_dir = Path(bag_dir)
    if bag_dir.is_file():
        return bag_dir
    if (bag_dir / "metadata.yaml").is_file():
        try:
            files = read_metadata(bag_dir).get("relative_file_paths")
        except YamlFileError:
            files = None
        if isinstance(files, list) and files:
            if len(files) > 1:
                raise ValueError(f"{bag_dir}: expected one file, metadata lists {files}")
            if isinstance(files[0], str):
                return bag_dir / files[0]
    files = sorted(bag_dir.glob("*.mcap"))
    if len(files) != 1:
        raise FileNotFoundError(f"{bag_dir}: expected one .mcap file, found {len(files)}")
    return files[0]


def read_messages(
    bag_dir: str | os.PathLike,
    topics: Iterable[str] | None = None,
) -> Iterator[BagMessage]:
    """Decoded messages of a bag, in log-time order, with ``mcap_ros2``.

    A file without a valid summary (the recorder died) is read sequentially
    up to its last complete chunk; what follows is ignored.

    Parameters
    ----------
    bag_dir : str or Path
        Bag directory (or ``.mcap`` file).
    topics : iterable of str, optional
        Only these topics.

    Yields
    ------
    BagMessage
        ``(topic, type, log_time_ns, message)``; `message` is a
        ``mcap_ros2`` dynamic message (attributes named like the fields).
    """
    from mcap_ros2.decoder import DecoderFactory

    topics = None if topics is None else list(topics)
    path = bag_file(bag_dir)
    with open(path, "rb") as stream:
        decoders = [DecoderFactory()]
        if _has_summary(stream):
            reader = SeekingReader(stream, decoder_factories=decoders)
            for schema, channel, record, decoded in reader.iter_decoded_messages(
                    topics=topics, log_time_order=True):
                yield BagMessage(channel.topic, schema.name, record.log_time, decoded)
        else:
            yield from _read_partial(stream, topics, decoders[0])


def _has_summary(stream) -> bool:
    """Whether an MCAP stream ends with a valid footer and summary."""
    try:
        summary = SeekingReader(stream).get_summary()
    except (McapError, ValueError, OSError, EOFError, struct.error):
        summary = None
    finally:
        stream.seek(0)
    return summary is not None and bool(summary.chunk_indexes)


def _read_partial(stream, topics, decoder_factory) -> Iterator[BagMessage]:
    """Messages of a truncated MCAP, up to the last complete chunk, by log time."""
    reader = NonSeekingReader(stream)
    found = []
    try:
        for schema, channel, msg in reader.iter_messages(
                topics=topics, log_time_order=False):
            found.append((schema, channel, msg))
    except (McapError, EOFError, ValueError, struct.error):
        pass    # the file ends inside a record: keep what came before it
    found.sort(key=lambda item: item[2].log_time)
    for schema, channel, msg in found:
        decode = decoder_factory.decoder_for(channel.message_encoding, schema)
        yield BagMessage(channel.topic, schema.name, msg.log_time, decode(msg.data))


def read_messages_rosbags(
    bag_dir: str | os.PathLike,
    topics: Iterable[str] | None = None,
) -> Iterator[BagMessage]:
    """Decoded messages of a complete bag, in log-time order, with ``rosbags``.

    An independent reader: ``rosbags`` parses ``metadata.yaml`` and the MCAP
    file itself, builds its types from the bag's ``ros2msg`` schemas and
    deserializes the CDR data. Used to cross-check :func:`read_messages`.

    Yields
    ------
    BagMessage
        `message` is a ``rosbags`` dataclass; arrays of numbers are numpy
        arrays.
    """
    from rosbags.highlevel import AnyReader

    wanted = None if topics is None else set(topics)
    with AnyReader([Path(bag_dir)]) as reader:
        connections = [c for c in reader.connections
                       if wanted is None or c.topic in wanted]
        for connection, timestamp, raw in reader.messages(connections=connections):
            yield BagMessage(connection.topic, connection.msgtype, timestamp,
                             reader.deserialize(raw, connection.msgtype))


def message_to_dict(message: Any) -> Any:
    """Plain Python value of a decoded message (dicts, lists, numbers, str).

    Works for ``mcap_ros2`` dynamic messages, ``rosbags`` dataclasses and
    ``rclpy`` message objects, so that the three can be compared; numpy
    arrays and ``array.array`` become lists, ``bytes`` become lists of int.
    """
    if isinstance(message, (str, bool, int, float)) or message is None:
        return message
    if isinstance(message, (bytes, bytearray)):
        return list(message)
    if hasattr(message, "tolist"):                       # numpy array or scalar
        return message.tolist()
    if isinstance(message, (list, tuple)) or type(message).__name__ == "array":
        return [message_to_dict(v) for v in message]
    names = _field_names(message)
    return {name: message_to_dict(getattr(message, name)) for name in names}


def _field_names(message: Any) -> list[str]:
    import dataclasses
    if dataclasses.is_dataclass(message):               # rosbags
        return [f.name for f in dataclasses.fields(message)
                if not f.name.startswith("_")]
    if hasattr(message, "get_fields_and_field_types"):  # rclpy
        return list(message.get_fields_and_field_types())
    slots = getattr(type(message), "__slots__", None)   # mcap_ros2
    if slots is not None:
        return [s for s in slots if not s.startswith("_")]
    raise TypeError(f"cannot convert {type(message).__name__} to a dict")




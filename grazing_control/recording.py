"""Recording ROS 2 topics to rosbag2-style MCAP bags, and reading them back.

This module is the recording layer of the project (see ``docs/recording.md``).
It writes what ``ros2 bag record -s mcap`` writes, on top of the ``mcap``
library, without ROS: the recorder node (``grazing_control.nodes.recorder_node``)
is a thin adapter that feeds it serialized CDR bytes, and the analysis reads
the bags back with :func:`read_messages`.

A bag is a directory::

    <bag_dir>/
        <bag_dir name>_0.mcap   MCAP, profile ``ros2``, zstd/lz4-compressed chunks
        metadata.yaml           rosbag2 metadata, version 9 (ROS 2 Jazzy)

The MCAP file follows the ``ros2`` profile of the MCAP specification as
rosbag2's ``mcap`` storage plugin writes it:

* one Schema per message type, named like ``sensor_msgs/msg/JointState``,
  encoding ``ros2msg``, whose data is the ``.msg`` text followed by every
  nested definition (see :func:`message_definition`);
* one Channel per topic, message encoding ``cdr``, with the channel metadata
  keys ``offered_qos_profiles`` (a YAML list of QoS profiles, see
  :func:`qos_profiles_yaml`) and ``topic_type_hash`` (the ``RIHS01_`` type
  description hash);
* Message records with ``log_time`` = receive time and ``publish_time`` =
  source (send) time, in nanoseconds;
* chunks with message indexes; at :meth:`BagWriter.close`, a ``rosbag2``
  Metadata record (``serialized_metadata``, ``ROS_DISTRO``) and the summary
  (schemas, channels, Statistics, chunk and metadata indexes).

Chunks are written to the operating system as soon as they are complete, so
a recorder that dies before :meth:`BagWriter.close` leaves a file that
:func:`read_messages` still reads up to its last complete chunk.

Examples
--------
>>> with BagWriter("/tmp/run1") as bag:                  # doctest: +SKIP
...     bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
...     bag.write("/oscillator/state", cdr_bytes, receive_time_ns)
>>> for m in read_messages("/tmp/run1"):                 # doctest: +SKIP
...     print(m.topic, m.log_time_ns, m.message.position)
"""

from __future__ import annotations

import json
import os
import re
import struct
import sys
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, NamedTuple, Sequence

import yaml
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Channel, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, IndexType, Writer

__all__ = [
    "BagMessage",
    "BagWriter",
    "COMPRESSIONS",
    "DEFAULT_CHUNK_SIZE",
    "METADATA_VERSION",
    "ROS_DISTRO",
    "bag_file",
    "message_definition",
    "message_to_dict",
    "qos_profile_dict",
    "qos_profiles_yaml",
    "read_messages",
    "read_messages_rosbags",
    "read_metadata",
    "reindex",
    "type_description_hash",
]

#: ROS 2 distribution written to ``metadata.yaml`` and the MCAP metadata.
ROS_DISTRO = "jazzy"

#: rosbag2 metadata format version written by ROS 2 Jazzy.
METADATA_VERSION = 9

#: Chunk compressions accepted by :class:`BagWriter`.
COMPRESSIONS = ("zstd", "lz4", "none")

#: Uncompressed chunk size in bytes. Small enough that a crash loses little
#: (at most one chunk), large enough that compression and indexes stay cheap.
DEFAULT_CHUNK_SIZE = 256 * 1024

#: Line between the definitions of a ``ros2msg`` schema (rosbag2 convention).
SCHEMA_SEPARATOR = "=" * 80

_COMPRESSION_TYPES = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}

_PRIMITIVE_TYPES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 "
    "int64 uint64 string wstring".split()
)

# The type of a field or constant: the first word of a non-comment line,
# without its array suffix ("[]", "[3]", "[<=3]") or string bound ("<=8").
_FIELD_TYPE = re.compile(r"^\s*([A-Za-z][A-Za-z0-9_/]*)(?:<=\d+)?(?:\[[^\]]*\])?\s+\S")

_TYPE_NAME = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)$")

# rosbag2's "infinite" duration (RMW_DURATION_INFINITE), as sec/nsec.
_INFINITE_NS = 9223372036854775807


# --------------------------------------------------------------------------
# Message definitions (ros2msg schemas)
# --------------------------------------------------------------------------

def _split_type(msg_type: str) -> tuple[str, str]:
    """Split ``pkg/msg/Type`` or ``pkg/Type`` into ``(pkg, Type)``."""
    match = _TYPE_NAME.match(msg_type)
    if match is None:
        raise ValueError(
            f"not a message type name: {msg_type!r} (expected 'pkg/msg/Type')")
    return match.group(1), match.group(2)


def _share_dirs(package: str) -> list[Path]:
    """Candidate ``share/<package>`` directories, ament index first.

    The ament index (``AMENT_PREFIX_PATH``) is what a sourced ROS install or a
    colcon workspace provides; ``sys.prefix/share`` is where the PyPI wheels
    of the ROS interfaces put their files inside a virtual environment.
    """
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory
        dirs.append(Path(get_package_share_directory(package)))
    except (ImportError, LookupError, OSError, ValueError):
        pass
    dirs.append(Path(sys.prefix) / "share" / package)
    return dirs


def _interface_file(msg_type: str, suffix: str) -> Path:
    """Path of the ``.msg`` (or ``.json``) file that defines `msg_type`."""
    package, name = _split_type(msg_type)
    for share in _share_dirs(package):
        path = share / "msg" / f"{name}{suffix}"
        if path.is_file():
            return path
    raise LookupError(
        f"no {name}{suffix} for {msg_type!r} in the ament index or under "
        f"{Path(sys.prefix) / 'share' / package / 'msg'}")


def _dependencies(text: str, package: str) -> list[str]:
    """Nested message types of a ``.msg`` text, as sorted ``pkg/Type`` names.

    A type without a package is in `package`; a bare ``Header`` that is not
    a message of `package` is ``std_msgs/Header`` (the ROS 1 convention that
    some definitions still follow).
    """
    found = set()
    for line in text.splitlines():
        match = _FIELD_TYPE.match(line)
        if match is None or match.group(1) in _PRIMITIVE_TYPES:
            continue
        name = match.group(1)
        if "/" in name:
            found.add("/".join(_split_type(name)))
        elif name == "Header" and not _has_msg(f"{package}/{name}"):
            found.add("std_msgs/Header")
        else:
            found.add(f"{package}/{name}")
    return sorted(found)


def _has_msg(msg_type: str) -> bool:
    try:
        _interface_file(msg_type, ".msg")
    except LookupError:
        return False
    return True


def message_definition(msg_type: str) -> str:
    """Full ``ros2msg`` text of a message type, as rosbag2 stores it.

    The text of the type's ``.msg`` file comes first, unchanged; then, for
    each nested type in depth-first order (each once), a separator line of
    80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text. This is
    the schema data of rosbag2's MCAP storage and what ``mcap_ros2``,
    ``rosbags`` and Foxglove parse.

    Parameters
    ----------
    msg_type : str
        Message type, ``pkg/msg/Type`` (or ``pkg/Type``).

    Returns
    -------
    str
        The concatenated definition.

    Raises
    ------
    LookupError
        If the ``.msg`` file of the type or of a nested type is not found.
        Files are looked up in the ament index, then in ``sys.prefix/share``.

    Examples
    --------
    >>> print(message_definition("geometry_msgs/msg/Vector3Stamped"))  # doctest: +SKIP
    # This represents a Vector3 with reference coordinate frame and timestamp
    ...
    std_msgs/Header header
    Vector3 vector
    ================================================================================
    MSG: geometry_msgs/Vector3
    ...
    """
    seen: set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth > 64:
            raise RecursionError(f"message definition of {msg_type!r} nests too deep")
        package, _ = _split_type(name)
        text = _interface_file(name, ".msg").read_text(encoding="utf-8")
        parts = [text]
        for dep in _dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                parts.append(f"\n{SCHEMA_SEPARATOR}\nMSG: {dep}\n")
                parts.append(append(dep, depth + 1))
        return "".join(parts)

    return append(msg_type, 0)


def type_description_hash(msg_type: str) -> str:
    """``RIHS01_...`` type description hash of a message type (REP 2011).

    Read from the ``.json`` type description that rosidl installs next to the
    ``.msg`` file. Returns ``""`` if it is not installed (rosbag2 then writes
    an empty hash too).
    """
    package, name = _split_type(msg_type)
    try:
        path = _interface_file(msg_type, ".json")
        hashes = json.loads(path.read_text(encoding="utf-8"))["type_hashes"]
    except (LookupError, OSError, ValueError):
        return ""
    full = f"{package}/msg/{name}"
    return next((h["hash_string"] for h in hashes if h["type_name"] == full), "")


def _full_type(msg_type: str) -> str:
    package, name = _split_type(msg_type)
    return f"{package}/msg/{name}"


# --------------------------------------------------------------------------
# QoS profiles, as rosbag2 (Jazzy, metadata version 9) writes them
# --------------------------------------------------------------------------

def _duration(ns: int | None) -> dict[str, int]:
    ns = _INFINITE_NS if ns is None else int(ns)
    sec, nsec = divmod(ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def qos_profile_dict(
    *,
    history: str = "keep_all",
    depth: int = 0,
    reliability: str = "reliable",
    durability: str = "volatile",
    deadline_ns: int | None = 0,
    lifespan_ns: int | None = 0,
    liveliness: str = "automatic",
    liveliness_lease_duration_ns: int | None = 0,
    avoid_ros_namespace_conventions: bool = False,
) -> dict[str, Any]:
    """One QoS profile as a mapping in rosbag2's (version 9) layout.

    Parameters
    ----------
    history, reliability, durability, liveliness : str
        Policy names as ``rmw`` prints them: ``keep_last``/``keep_all``,
        ``reliable``/``best_effort``, ``volatile``/``transient_local``,
        ``automatic``/``manual_by_topic`` (``system_default`` and ``unknown``
        are valid for all).
    depth : int
        History depth (0 with ``keep_all``).
    deadline_ns, lifespan_ns, liveliness_lease_duration_ns : int or None
        Durations in nanoseconds; 0 is the rmw default, None is infinite.
    avoid_ros_namespace_conventions : bool
        As in ``rmw_qos_profile_t``.

    Returns
    -------
    dict
        Keys ``history, depth, reliability, durability, deadline, lifespan,
        liveliness, liveliness_lease_duration, avoid_ros_namespace_conventions``;
        durations as ``{sec, nsec}``.
    """
    return {
        "history": history,
        "depth": int(depth),
        "reliability": reliability,
        "durability": durability,
        "deadline": _duration(deadline_ns),
        "lifespan": _duration(lifespan_ns),
        "liveliness": liveliness,
        "liveliness_lease_duration": _duration(liveliness_lease_duration_ns),
        "avoid_ros_namespace_conventions": bool(avoid_ros_namespace_conventions),
    }


def qos_profiles_yaml(profiles: Iterable[Mapping[str, Any]]) -> str:
    """Serialize QoS profiles to the YAML string of ``offered_qos_profiles``.

    This is the value of the MCAP channel metadata key; ``metadata.yaml``
    (version 9) holds the same list as YAML structure rather than a string.
    """
    profiles = [dict(p) for p in profiles]
    if not profiles:
        return ""
    return yaml.safe_dump(profiles, sort_keys=False, default_flow_style=False).strip()


# --------------------------------------------------------------------------
# Writer
# --------------------------------------------------------------------------

class _FlushingStream:
    """Binary file whose every write reaches the operating system at once.

    The MCAP writer writes a whole chunk (and its message indexes) at a
    time, so flushing each write costs nothing per message and leaves the
    file complete up to its last chunk if the process dies.
    """

    def __init__(self, path: Path):
        self._file = open(path, "xb")

    def write(self, data: bytes) -> int:
        n = self._file.write(data)
        self._file.flush()
        return n

    def tell(self) -> int:
        return self._file.tell()

    def close(self) -> None:
        self._file.close()


class _Topic(NamedTuple):
    channel_id: int
    msg_type: str
    qos_profiles: list
    type_hash: str


class BagWriter:
    """Writer of a rosbag2-style MCAP bag directory.

    Lifecycle: :meth:`open`, then :meth:`add_topic` for each topic (at any
    time before its first message), :meth:`write` for each serialized
    message, and :meth:`close`, which completes the MCAP summary and writes
    ``metadata.yaml``. Also a context manager (open on enter, close on exit).

    Parameters
    ----------
    bag_dir : str or Path
        Bag directory; created if missing, refused if not empty.
    compression : {"zstd", "lz4", "none"}
        Chunk compression.
    chunk_size : int
        Uncompressed chunk size in bytes at which a chunk is written.
    custom_data : mapping of str to str, optional
        ``custom_data`` of ``metadata.yaml``.

    Attributes
    ----------
    bag_dir : Path
    path : Path
        The ``.mcap`` file, ``<bag_dir>/<bag_dir name>_0.mcap``.
    message_counts : dict of str to int
        Messages written per topic.

    Notes
    -----
    Not thread-safe: call it from one thread (the recorder node uses a
    single-threaded executor).
    """

    def __init__(
        self,
        bag_dir: str | os.PathLike,
        *,
        compression: str = "zstd",
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        custom_data: Mapping[str, str] | None = None,
    ):
        if compression not in _COMPRESSION_TYPES:
            raise ValueError(
                f"compression must be one of {', '.join(COMPRESSIONS)}, "
                f"not {compression!r}")
        if int(chunk_size) <= 0:
            raise ValueError(f"chunk_size must be positive, not {chunk_size!r}")
        self.bag_dir = Path(bag_dir)
        self.path = self.bag_dir / f"{self.bag_dir.name}_0.mcap"
        self.compression = compression
        self.chunk_size = int(chunk_size)
        self.custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self.message_counts: dict[str, int] = {}
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        self._stream: _FlushingStream | None = None
        self._writer: Writer | None = None
        self._start_ns: int | None = None
        self._end_ns = 0
        self._closed = False

    # -- lifecycle ---------------------------------------------------------

    def open(self) -> "BagWriter":
        """Create the bag directory and the MCAP file; write the header."""
        if self._writer is not None or self._closed:
            raise RuntimeError(f"bag {self.bag_dir} was already opened")
        self.bag_dir.mkdir(parents=True, exist_ok=True)
        if any(self.bag_dir.iterdir()):
            raise FileExistsError(f"bag directory {self.bag_dir} is not empty")
        self._stream = _FlushingStream(self.path)
        self._writer = Writer(
            self._stream,
            chunk_size=self.chunk_size,
            compression=_COMPRESSION_TYPES[self.compression],
            index_types=IndexType.ALL,
            use_statistics=True,
            use_summary_offsets=True,
        )
        self._writer.start(profile="ros2", library=_library_identifier())
        return self

    def add_topic(
        self,
        name: str,
        msg_type: str,
        offered_qos_profiles: str | Sequence[Mapping[str, Any]] = "",
        *,
        type_hash: str | None = None,
        schema_data: bytes | None = None,
    ) -> int:
        """Register a topic: a channel, and its type's schema if new.

        Parameters
        ----------
        name : str
            Fully qualified topic name, e.g. ``/oscillator/state``.
        msg_type : str
            ``pkg/msg/Type``; its definition must be installed
            (:func:`message_definition`).
        offered_qos_profiles : str or sequence of mapping
            QoS profiles of the publishers, as the YAML string of
            :func:`qos_profiles_yaml` or as mappings of :func:`qos_profile_dict`.
        type_hash : str, optional
            ``RIHS01_`` hash; looked up with :func:`type_description_hash`
            if not given.
        schema_data : bytes, optional
            The ``ros2msg`` schema text; :func:`message_definition` of the
            installed type if not given (:func:`reindex` passes the recorded
            one, so that a bag is recovered where its types are not installed).

        Returns
        -------
        int
            The MCAP channel id.
        """
        writer = self._require_open()
        if name in self._topics:
            raise ValueError(f"topic {name} was already added")
        msg_type = _full_type(msg_type)
        if isinstance(offered_qos_profiles, str):
            qos_text = offered_qos_profiles
            qos_list = (yaml.safe_load(qos_text) or []) if qos_text else []
        else:
            qos_list = [dict(p) for p in offered_qos_profiles]
            qos_text = qos_profiles_yaml(qos_list)
        if type_hash is None:
            type_hash = type_description_hash(msg_type)
        schema_id = self._schemas.get(msg_type)
        if schema_id is None:
            schema_id = writer.register_schema(
                name=msg_type,
                encoding=SchemaEncoding.ROS2,
                data=(message_definition(msg_type).encode("utf-8") if schema_data is None
                      else bytes(schema_data)),
            )
            self._schemas[msg_type] = schema_id
        channel_id = writer.register_channel(
            topic=name,
            message_encoding=MessageEncoding.CDR,
            schema_id=schema_id,
            metadata={"offered_qos_profiles": qos_text, "topic_type_hash": type_hash},
        )
        self._topics[name] = _Topic(channel_id, msg_type, qos_list, type_hash)
        self.message_counts[name] = 0
        return channel_id

    def has_topic(self, name: str) -> bool:
        """Whether :meth:`add_topic` was called for `name`."""
        return name in self._topics

    def write(
        self,
        topic: str,
        data: bytes,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        sequence: int = 0,
    ) -> None:
        """Write one serialized (CDR) message, as it is.

        Parameters
        ----------
        topic : str
            A topic registered with :meth:`add_topic`.
        data : bytes
            The CDR-serialized message (encapsulation header included), as
            ``rclpy`` delivers it to a ``raw=True`` subscription.
        log_time_ns : int
            Receive time, nanoseconds.
        publish_time_ns : int, optional
            Send time, nanoseconds; `log_time_ns` if not given.
        sequence : int
            Publisher's sequence number (kept modulo 2**32), 0 if unknown.
        """
        writer = self._require_open()
        try:
            channel_id = self._topics[topic].channel_id
        except KeyError:
            raise ValueError(f"topic {topic} was not added to the bag") from None
        log_time_ns = int(log_time_ns)
        writer.add_message(
            channel_id=channel_id,
            log_time=log_time_ns,
            data=data,
            publish_time=log_time_ns if publish_time_ns is None else int(publish_time_ns),
            sequence=int(sequence) & 0xFFFFFFFF,
        )
        self.message_counts[topic] += 1
        if self._start_ns is None or log_time_ns < self._start_ns:
            self._start_ns = log_time_ns
        if log_time_ns > self._end_ns:
            self._end_ns = log_time_ns

    def close(self) -> dict[str, Any]:
        """Write the last chunk and the summary, close the file, write metadata.

        Safe to call more than once; does nothing if the bag was never opened.

        Returns
        -------
        dict
            The ``rosbag2_bagfile_information`` mapping written to
            ``metadata.yaml`` (empty if the bag was never opened).
        """
        if self._writer is None:
            return {}
        info = self.metadata()
        serialized = yaml.safe_dump(info, sort_keys=False, default_flow_style=False)
        self._writer.add_metadata(
            "rosbag2", {"serialized_metadata": serialized, "ROS_DISTRO": ROS_DISTRO})
        self._writer.finish()
        self._stream.close()
        self._writer = None
        self._stream = None
        self._closed = True
        _write_text_atomic(
            self.bag_dir / "metadata.yaml",
            yaml.safe_dump({"rosbag2_bagfile_information": info},
                           sort_keys=False, default_flow_style=False))
        return info

    def abandon(self) -> None:
        """Close the file without finishing it (after a failed write: disk full).

        The file keeps every chunk written so far (readable by :func:`read_messages`;
        :func:`reindex` makes it a complete bag); no ``metadata.yaml`` is written.
        """
        if self._stream is not None:
            try:
                self._stream.close()
            except OSError:
                pass    # the unflushed rest of a chunk: lost either way
        self._writer = None
        self._stream = None
        self._closed = True

    def __enter__(self) -> "BagWriter":
        return self.open()

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- metadata ----------------------------------------------------------

    def metadata(self) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` mapping (version 9) so far."""
        start = self._start_ns or 0
        duration = self._end_ns - start if self._start_ns is not None else 0
        count = sum(self.message_counts.values())
        return {
            "version": METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": name,
                        "type": topic.msg_type,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": topic.qos_profiles,
                        "type_description_hash": topic.type_hash,
                    },
                    "message_count": self.message_counts[name],
                }
                for name, topic in self._topics.items()
            ],
            # rosbag2 reports compression inside the MCAP storage as none.
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [
                {
                    "path": self.path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": count,
                }
            ],
            "custom_data": dict(self.custom_data) or None,
            "ros_distro": ROS_DISTRO,
        }

    def _require_open(self) -> Writer:
        if self._writer is None:
            state = "closed" if self._closed else "not opened"
            raise RuntimeError(f"bag {self.bag_dir} is {state}")
        return self._writer


def _library_identifier() -> str:
    from mcap.writer import LIBRARY_IDENTIFIER
    return f"grazing_control.recording {LIBRARY_IDENTIFIER}"


def _write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


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
    """The ``rosbag2_bagfile_information`` mapping of a bag's ``metadata.yaml``."""
    text = (Path(bag_dir) / "metadata.yaml").read_text(encoding="utf-8")
    return yaml.safe_load(text)["rosbag2_bagfile_information"]


def bag_file(bag_dir: str | os.PathLike) -> Path:
    """The MCAP file of a bag directory (or the path itself if it is a file).

    Taken from ``metadata.yaml`` if present, else the single ``*.mcap`` in the
    directory (a recorder that died leaves no ``metadata.yaml``).
    """
    bag_dir = Path(bag_dir)
    if bag_dir.is_file():
        return bag_dir
    if (bag_dir / "metadata.yaml").is_file():
        files = read_metadata(bag_dir)["relative_file_paths"]
        if len(files) != 1:
            raise ValueError(f"{bag_dir}: expected one file, metadata lists {files}")
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

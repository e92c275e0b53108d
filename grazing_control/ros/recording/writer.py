"""The bag writer: what ``ros2 bag record -s mcap`` writes, with :class:`.McapWriter`
(the ``mcap`` library's file, byte for byte, at a fraction of its cost per message).

Chunks reach the operating system as soon as they are complete, so a recorder that
dies before :meth:`BagWriter.close` leaves a file that the readers still read up to
its last complete chunk (docs/recording.md).
"""


import os
import struct
from pathlib import Path
from typing import Any, Mapping, NamedTuple, Sequence

import yaml
from mcap.well_known import MessageEncoding, SchemaEncoding

from .mcap_writer import McapWriter
from .schemas import (COMPRESSIONS, DEFAULT_CHUNK_SIZE, METADATA_VERSION, ROS_DISTRO, _full_type,
                      message_definition, qos_profiles_yaml, type_description_hash)


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
        if compression not in COMPRESSIONS:
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
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        self._stream: _FlushingStream | None = None
        self._writer: McapWriter | None = None
        self._counts: dict[int, int] = {}           # per channel id, once closed
        self._times: tuple[int, int] | None = None  # first and last log time, once closed
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
        self._writer = McapWriter(self._stream, chunk_size=self.chunk_size,
                                  compression=self.compression)
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
        writer = self._writer
        if writer is None:
            self._require_open()
        entry = self._topics.get(topic)
        if entry is None:
            raise ValueError(f"topic {topic} was not added to the bag")
        try:
            log_ns = int(log_time_ns)
            writer.add_message(entry.channel_id, log_ns, data,
                               log_ns if publish_time_ns is None else int(publish_time_ns),
                               int(sequence) & 0xFFFFFFFF)
        except (TypeError, ValueError, OverflowError, struct.error):
            _check_message(data, log_time_ns, publish_time_ns, sequence)
            raise

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written per topic."""
        counts = self._counts if self._writer is None else self._writer.message_counts()
        return {name: counts.get(topic.channel_id, 0) for name, topic in self._topics.items()}

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
        self._keep_tallies()
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
        if self._writer is not None:
            self._keep_tallies()
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
        times = self._times if self._writer is None else self._writer.message_times()
        start, duration = (times[0], times[1] - times[0]) if times else (0, 0)
        counts = self.message_counts
        count = sum(counts.values())
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
                    "message_count": counts[name],
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

    def _keep_tallies(self) -> None:
        """The counts and times of what was written, kept for after the writer is gone."""
        self._counts, self._times = self._writer.message_counts(), self._writer.message_times()

    def _require_open(self) -> McapWriter:
        if self._writer is None:
            state = "closed" if self._closed else "not opened"
            raise RuntimeError(f"bag {self.bag_dir} is {state}")
        return self._writer


def _check_message(data, log_time_ns, publish_time_ns, sequence) -> None:
    """The error that names what :meth:`BagWriter.write` could not write (nothing was)."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"data must be the serialized message as bytes, not "
                        f"{type(data).__name__}: nothing was written")
    times = [("log_time_ns", log_time_ns)]
    if publish_time_ns is not None:         # None: the log time
        times.append(("publish_time_ns", publish_time_ns))
    for name, value in [*times, ("sequence", sequence)]:
        try:
            whole = int(value)
        except (TypeError, ValueError, OverflowError):
            whole = None
        if whole is None or (name != "sequence" and not 0 <= whole < 2**64):
            limits = "an integer" if name == "sequence" else "nanoseconds in [0, 2**64)"
            raise ValueError(f"{name}={value!r} is invalid: valid range is {limits}; "
                             "nothing was written")


def _library_identifier() -> str:
    """The Header's ``library``: this writer (mcap_writer.McapWriter)."""
    return "grazing_control.ros.recording"


def _write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)



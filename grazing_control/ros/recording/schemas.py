"""What a rosbag2 MCAP bag declares: constants, ros2msg schemas, type hashes, QoS profiles.

rosbag2 (Jazzy, metadata version 9) names schemas like ``sensor_msgs/msg/JointState``,
encoding ``ros2msg``: the ``.msg`` text followed by every nested definition
(:func:`message_definition`), and keeps the offered QoS in the channel metadata key
``offered_qos_profiles`` (:func:`qos_profiles_yaml`); docs/recording.md.
"""


import json
import re
import sys
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml


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



"""The nodes' hot messages in their wire format (XCDR1, little endian), without rclpy.

``Publisher.publish(msg)`` converts the Python message to its C struct field by field
before the middleware serializes it; for the simulator's small messages that conversion
is 40-60 % of the publisher's CPU (benchmarks/bench_publish.py: 10-16 us per JointState
with one remote reader, 6.3-6.7 us for the same message published as bytes with
``publish(bytes)``; docs/benchmarks.md, "Batching and packed messages"). The simulator
and the controller publish the messages of every period as bytes packed here, and each
reads the other's messages from the bytes it receives.

The layouts are those of ``rclpy.serialization.serialize_message`` for the messages as
the nodes fill them (one joint named ``mass``, empty ``frame_id``), padding zeroed:
tests/test_cdr.py checks every encoder against rclpy's serializer and every decoder
against its deserializer on thousands of seeded random values. A message of another
shape (another publisher's JointState with two joints, say) is not this layout:
:func:`read_sample` returns None and the caller uses rclpy's deserializer.

CDR in brief: a 4-byte encapsulation header (00 01 00 00: CDR, little endian), then the
fields in order, each aligned to its own size counted from the end of the header; a
string is a uint32 length (with the terminating NUL) and its bytes; a sequence a uint32
count and its elements.
"""

from __future__ import annotations

import math
import struct

__all__ = ["NAME", "joint_state", "vector3_stamped", "twist_stamped", "wrench_stamped", "clock",
           "float64",
           "estimate_state", "read_sample", "read_state", "read_twist_stamped", "stamp_parts",
           "rig_sample_masses", "read_joints"]

_HEADER = b"\x00\x01\x00\x00"
_NS = 1_000_000_000
#: The joint name of the oscillator's JointState messages.
NAME = "mass"

# sensor_msgs/JointState: stamp, frame_id "", name ["mass"], position [x], velocity [v],
# effort [e]. Offsets after the header: 0 sec, 4 nanosec, 8 len 1, 12 NUL + 3 pad,
# 16 count 1, 20 len 5, 24 "mass" NUL + 3 pad, 32 count 1, 36 pad, 40 x, 48 count 1,
# 52 pad, 56 v, 64 count 1, 68 pad, 72 e.
_JOINT_STATE = struct.Struct("<4siII4sII8sI4xdI4xdI4xd")
_FRAME = b"\x00\x00\x00\x00"
_MASS = b"mass\x00\x00\x00\x00"
# name = ["mass"]: count 1, length 5, "mass" NUL (the padding after it is not compared)
_ONE_MASS = b"\x01\x00\x00\x00\x05\x00\x00\x00mass\x00"
# the controller's estimate: the same with effort [var x, cov xv, var v] (3 doubles).
_ESTIMATE = struct.Struct("<4siII4sII8sI4xdI4xdI4xddd")
# geometry_msgs/Vector3Stamped: stamp, frame_id "", then x, y, z at 16, 24, 32.
_VECTOR3_STAMPED = struct.Struct("<4siII4sddd")
# geometry_msgs/TwistStamped: stamp, frame_id "", linear x y z, angular x y z.
_TWIST_STAMPED = struct.Struct("<4siII4sdddddd")
# geometry_msgs/WrenchStamped: stamp, frame_id "mass" (length 5, NUL, 7 padding bytes to
# the doubles at payload offset 24), force x y z, torque x y z.
_WRENCH_STAMPED = struct.Struct("<4siII12sdddddd")
_MASS_FRAME = b"mass\x00" + bytes(7)
# rosgraph_msgs/Clock: one builtin_interfaces/Time.
_CLOCK = struct.Struct("<4siI")
# std_msgs/Float64.
_FLOAT64 = struct.Struct("<4sd")


def stamp_parts(t: float) -> tuple:
    """(sec, nanosec) of a simulation time t >= 0 in seconds, rounded to 1 ns (the
    same numbers as ``nodes.common.stamp_from_seconds``)."""
    ns = int(round(t * 1e9))
    return ns // _NS, ns % _NS


def joint_state(sec: int, nanosec: int, x: float, v: float, effort: float) -> bytes:
    """sensor_msgs/JointState: joint ``mass`` at (x, v), effort ``effort``."""
    return _JOINT_STATE.pack(_HEADER, sec, nanosec, 1, _FRAME, 1, 5, _MASS, 1, x, 1, v, 1,
                             effort)


_STREAM_XV = struct.Struct("<4siII4sII8sI4xdI4xdI4xdd")
_STREAM_X = struct.Struct("<4siII4sII8sI4xdIIdd")


def stream_sample(sec: int, nanosec: int, x: float, v: float | None, cos_tau: float,
                  sin_tau: float) -> bytes:
    """sensor_msgs/JointState of the state stream (``oscillator/state``): joint ``mass``,
    position [x], velocity [v] or empty (``v`` None: a position-only sensor), effort
    [cos tau, sin tau] (the shaker's phase reference, tau recoverable)."""
    if v is None:
        return _STREAM_X.pack(_HEADER, sec, nanosec, 1, _FRAME, 1, 5, _MASS, 1, x, 0, 2,
                              cos_tau, sin_tau)
    return _STREAM_XV.pack(_HEADER, sec, nanosec, 1, _FRAME, 1, 5, _MASS, 1, x, 1, v, 2,
                           cos_tau, sin_tau)


_RIG_XV = struct.Struct("<4siII4sII8sI4xdI4xdI")
_RIG_X = struct.Struct("<4siII4sII8sI4xdII")


def rig_sample(sec: int, nanosec: int, x: float, v: float | None) -> bytes:
    """sensor_msgs/JointState of ``rig/sensor`` (docs/driver_contract.md): joint
    ``mass``, position [x] (m), velocity [v] (m/s) or empty (``v`` None: a position-only
    sensor), effort empty; read back by :func:`read_state`."""
    if v is None:
        return _RIG_X.pack(_HEADER, sec, nanosec, 1, _FRAME, 1, 5, _MASS, 1, x, 0, 0)
    return _RIG_XV.pack(_HEADER, sec, nanosec, 1, _FRAME, 1, 5, _MASS, 1, x, 1, v, 0)


def _align(body: bytearray, n: int) -> None:
    """Pad ``body`` (the bytes after the encapsulation header) to a multiple of n."""
    body.extend(bytes(-len(body) % n))


def rig_sample_masses(sec: int, nanosec: int, names, positions, velocities=None) -> bytes:
    """sensor_msgs/JointState of ``rig/sensor`` of a rig of n masses (docs/driver_contract.md,
    "A rig of n masses"): empty frame_id, joints ``names`` (``mass<i>``), positions (m),
    velocities (m/s) or empty (None: a position-only sensor), effort empty; read back by
    :func:`read_joints`."""
    body = bytearray(struct.pack("<iII", sec, nanosec, 1))
    body.extend(b"\x00")
    _align(body, 4)
    body.extend(struct.pack("<I", len(names)))
    for name in names:
        _align(body, 4)
        raw = name.encode() + b"\x00"
        body.extend(struct.pack("<I", len(raw)))
        body.extend(raw)
    for values in (positions, () if velocities is None else velocities, ()):
        _align(body, 4)
        body.extend(struct.pack("<I", len(values)))
        if values:
            _align(body, 8)
            body.extend(struct.pack(f"<{len(values)}d", *values))
    return _HEADER + bytes(body)


def _double_sequences(data: bytes, pos: int):
    """(the three float64 sequences position, velocity, effort from ``pos`` on, the
    offset after them), or (None, pos) where the bytes end first. Each count is aligned
    to 4 and its doubles to 8, counted from the body start (after the header)."""
    n = len(data)
    values = []
    for _ in range(3):
        pos = 4 + ((pos - 4 + 3) & ~3)
        if pos + 4 > n:
            return None, pos
        (count,) = struct.unpack_from("<I", data, pos)
        pos += 4
        if count:
            pos = 4 + ((pos - 4 + 7) & ~7)
            if count > (n - pos) // 8:
                return None, pos
            values.append(struct.unpack_from(f"<{count}d", data, pos))
            pos += 8 * count
        else:
            values.append(())
    return values, pos


def read_joints(data: bytes):
    """(sec, nanosec, names, positions, velocities) of a JointState with an empty frame_id
    and no effort (:func:`rig_sample_masses`' layout; names a tuple of str, positions and
    velocities tuples of floats, velocities empty where none); None for anything else
    (the caller then uses rclpy's deserializer). Never raises."""
    n = len(data)
    if n < 24 or data[:4] != _HEADER:
        return None
    try:
        sec, nanosec, flen = struct.unpack_from("<iII", data, 4)
        if flen != 1 or data[16] != 0:
            return None
        pos = 20                                   # body offset 16: the name count
        (count,) = struct.unpack_from("<I", data, pos)
        pos += 4
        if count > (n - pos) // 5:
            return None
        names = []
        for _ in range(count):
            pos = 4 + ((pos - 4 + 3) & ~3)
            (length,) = struct.unpack_from("<I", data, pos)
            pos += 4
            if length < 1 or pos + length > n or data[pos + length - 1] != 0:
                return None
            names.append(data[pos:pos + length - 1].decode())
            pos += length
        values, pos = _double_sequences(data, pos)
    except (struct.error, UnicodeDecodeError):
        return None
    if values is None or not pos <= n <= pos + 8 or values[2]:
        return None
    return sec, nanosec, tuple(names), values[0], values[1]


def vector3_stamped(sec: int, nanosec: int, x: float, y: float, z: float) -> bytes:
    """geometry_msgs/Vector3Stamped with an empty frame_id."""
    return _VECTOR3_STAMPED.pack(_HEADER, sec, nanosec, 1, _FRAME, x, y, z)


def estimate_state(sec: int, nanosec: int, x: float, v: float, var_x: float, cov_xv: float,
                   var_v: float) -> bytes:
    """sensor_msgs/JointState of the controller's Pi2 estimate: joint ``mass`` at (x, v),
    effort [var x, cov xv, var v] (its covariance)."""
    return _ESTIMATE.pack(_HEADER, sec, nanosec, 1, _FRAME, 1, 5, _MASS, 1, x, 1, v, 3,
                          var_x, cov_xv, var_v)


def twist_stamped(sec: int, nanosec: int, linear_x: float,
                  linear_y: float = math.nan) -> bytes:
    """geometry_msgs/TwistStamped: twist.linear.x = ``linear_x`` (the correction),
    twist.linear.y = ``linear_y`` (the correction predicted for the next sample, NaN:
    none), every other component 0."""
    return _TWIST_STAMPED.pack(_HEADER, sec, nanosec, 1, _FRAME, linear_x, linear_y, 0.0,
                               0.0, 0.0, 0.0)


def wrench_stamped(sec: int, nanosec: int, force: tuple, torque: tuple) -> bytes:
    """geometry_msgs/WrenchStamped in frame ``mass`` (the rig's rig/force_pulse: a
    serialized publish, 0.1 ms sooner out than building the rclpy message in the rig
    scene, docs/benchmarks.md)."""
    return _WRENCH_STAMPED.pack(_HEADER, sec, nanosec, 5, _MASS_FRAME, *force, *torque)


def clock(sec: int, nanosec: int) -> bytes:
    """rosgraph_msgs/Clock."""
    return _CLOCK.pack(_HEADER, sec, nanosec)


def float64(value: float) -> bytes:
    """std_msgs/Float64."""
    return _FLOAT64.pack(_HEADER, value)


def read_sample(data: bytes):
    """(sec, nanosec, x, v) of a JointState in the simulator's layout, else None.

    None for anything else (other lengths, joint names, counts or byte order): the
    caller then deserializes it with rclpy and applies its own checks.
    """
    if len(data) != _JOINT_STATE.size:
        return None
    (head, sec, nanosec, flen, frame, names, nlen, name, npos, x, nvel, v, neff,
     _effort) = _JOINT_STATE.unpack(data)
    if (head != _HEADER or flen != 1 or frame[0] != 0 or names != 1 or nlen != 5
            or name[:5] != _MASS[:5] or npos != 1 or nvel != 1 or neff != 1):
        return None
    return sec, nanosec, x, v


def read_state(data: bytes):
    """(sec, nanosec, x, v, effort) of a stream sample: a JointState with an empty
    frame_id and the one joint ``mass``, one position, one velocity or none (v is then
    NaN: a position-only sensor), any number of efforts (a tuple: [cos tau, sin tau],
    or today's [cos tau]); None for anything else (the caller then uses rclpy's
    deserializer). Never raises."""
    n = len(data)
    if n < 40 or data[:4] != _HEADER:
        return None
    sec, nanosec, flen = struct.unpack_from("<iII", data, 4)
    if flen != 1 or data[16] != 0 or data[20:33] != _ONE_MASS:
        return None
    values, pos = _double_sequences(data, 36)  # body offset 32: the position count
    if values is None:
        return None
    # rclpy's serializer may leave up to 8 bytes of padding after the last field
    if not pos <= n <= pos + 8 or len(values[0]) != 1 or len(values[1]) > 1:
        return None
    v = values[1][0] if values[1] else math.nan
    return sec, nanosec, values[0][0], v, values[2]


def read_twist_stamped(data: bytes):
    """(sec, nanosec, linear.x, linear.y) of a TwistStamped with an empty frame_id,
    else None. linear.y is the predicted next correction (NaN: none; bags from before
    the prediction carry 0.0 there)."""
    if len(data) != _TWIST_STAMPED.size:
        return None
    head, sec, nanosec, flen, frame, lx, ly, *_rest = _TWIST_STAMPED.unpack(data)
    if head != _HEADER or flen != 1 or frame[0] != 0:
        return None
    return sec, nanosec, lx, ly

"""The sensor stream in blocks: many samples per message, as a DAQ driver publishes (issue 30).

One message per sample costs the middleware its per-message work for each of them: at
200 samples per period and time_scale 1000, 21,000 messages a second through the
simulator, the controller and the recorder. With ``stream_message: block`` the
simulator publishes the samples that one wake-up of its loop makes (a lockstep period,
or ``stream_block`` of wall time in realtime; a Pi2 sample ends the block, which goes
out before it) as one message on
``oscillator/state_block`` instead of one message each on ``oscillator/state``; the
controller's stream estimator and the recorder take them, and the bag readers expand
them back into samples (docs/nodes.md, "The stream in blocks").

Message: ``std_msgs/Float64MultiArray``, a row per sample in time order, each row what
the per-sample JointState of ``oscillator/state`` carries:

    layout.dim[0]  label "sample", size n (samples), stride 6 n
    layout.dim[1]  label "sec,nanosec,x,v,cos_tau,sin_tau", size 6, stride 6
    layout.data_offset 0
    data           n rows of (stamp sec, stamp nanosec, x, v, cos tau, sin tau)

stamp sec and nanosec: the sample's simulation time as the JointState's header.stamp
(integers, exact in a double); x, v: position and velocity as measured (v NaN: a
position-only sensor, the JointState's empty velocity); cos tau, sin tau: the shaker's
phase reference. A reader computes the same ``t = sec + nanosec 1e-9`` from a row as from
the per-sample message, so the controller's estimates are the same bit for bit.

:func:`pack` and :func:`read` are the wire format (XCDR1, little endian, as
:mod:`grazing_control.ros.cdr`; tests/test_stream_block.py checks them against rclpy's
serializer); :class:`Block` gathers a wake-up's rows.
"""

from __future__ import annotations

import math
import struct

__all__ = ["TOPIC", "TYPE", "FIELDS", "MESSAGES", "Block", "check_message", "pack", "read",
           "rows_of"]

#: The topic and type of the stream in blocks (relative name, as oscillator/state).
TOPIC = "oscillator/state_block"
TYPE = "std_msgs/msg/Float64MultiArray"
#: The columns of a row.
FIELDS = ("sec", "nanosec", "x", "v", "cos_tau", "sin_tau")
#: The values of the nodes' ``stream_message`` parameter: a message per sample on
#: oscillator/state, or blocks on oscillator/state_block.
MESSAGES = ("sample", "block")



def check_message(value) -> str | None:
    """Why ``value`` is not a valid ``stream_message`` (one line), or None."""
    if value in MESSAGES:
        return None
    return (f"stream_message={value!r} is invalid: valid values are "
            f"{', '.join(MESSAGES)}")


_HEADER = b"\x00\x01\x00\x00"
_NS = 1_000_000_000


def _string(text: str) -> bytes:
    """A CDR string without its padding: length (with the NUL), bytes, NUL."""
    raw = text.encode() + b"\x00"
    return struct.pack("<I", len(raw)) + raw


def _pad(pos: int, n: int) -> bytes:
    return b"\x00" * (-pos % n)


# the fixed parts around the two sizes: count 2, label 0 | size, stride | label 1, 6, 6,
# data_offset 0 | data count | padding to 8 | doubles. The padding is zeroed here; rclpy
# leaves whatever was in its buffer there, so a reader compares the fields only.
_DIM0 = struct.pack("<I", 2) + _string("sample")
_POS_SIZES = len(_DIM0) + len(_pad(len(_DIM0), 4))          # body offset of dim[0].size
_LABEL1 = _string(",".join(FIELDS))
_POS_LABEL1 = _POS_SIZES + 8
_POS_REST = _POS_LABEL1 + len(_LABEL1) + len(_pad(_POS_LABEL1 + len(_LABEL1), 4))
_REST = struct.pack("<III", 6, 6, 0)                        # size, stride, data_offset
_POS_COUNT = _POS_REST + len(_REST)                         # body offset of the count
_POS_DATA = _POS_COUNT + 4 + len(_pad(_POS_COUNT + 4, 8))   # of the first double
_PREFIX0 = _DIM0 + _pad(len(_DIM0), 4)
_PREFIX1 = (_LABEL1 + _pad(_POS_LABEL1 + len(_LABEL1), 4) + _REST)
_PREFIX2 = _pad(_POS_COUNT + 4, 8)


def pack(flat) -> bytes:
    """The serialized Float64MultiArray of the rows in ``flat`` (a flat sequence of
    6 n floats, row after row)."""
    m = len(flat)
    n = m // 6
    return b"".join((_HEADER, _PREFIX0, struct.pack("<II", n, 6 * n), _PREFIX1,
                     struct.pack("<I", m), _PREFIX2, struct.pack(f"<{m}d", *flat)))


def read(data: bytes):
    """The rows of a block as a tuple of floats (6 n, row after row), or None for any
    other message (another layout, labels or sizes, a stamp that is not a non-negative
    integer sec and a nanosec in [0, 1e9), a length that does not fit). Never raises."""
    try:
        size = len(data)
        if (size < 4 + _POS_DATA or data[:4] != _HEADER
                or data[4:4 + len(_DIM0)] != _DIM0):
            return None
        n, stride = struct.unpack_from("<II", data, 4 + _POS_SIZES)
        if (stride != 6 * n
                or data[4 + _POS_LABEL1:4 + _POS_LABEL1 + len(_LABEL1)] != _LABEL1
                or data[4 + _POS_REST:4 + _POS_COUNT] != _REST
                or struct.unpack_from("<I", data, 4 + _POS_COUNT)[0] != 6 * n):
            return None
        end = 4 + _POS_DATA + 48 * n
        if not end <= size <= end + 8:           # rclpy may pad the end
            return None
        flat = struct.unpack_from(f"<{6 * n}d", data, 4 + _POS_DATA)
    except (struct.error, TypeError):
        return None
    for i in range(0, 6 * n, 6):
        sec, ns = flat[i], flat[i + 1]
        if not (0.0 <= sec < 2**31 and sec == int(sec) and 0.0 <= ns < _NS and ns == int(ns)):
            return None
    return flat


def rows_of(flat):
    """(sec, nanosec, x, v, (cos tau, sin tau)) of each row of :func:`read`'s result, the
    tuple :func:`grazing_control.ros.cdr.read_state` gives for one sample."""
    for i in range(0, len(flat), 6):
        yield (int(flat[i]), int(flat[i + 1]), flat[i + 2], flat[i + 3],
               (flat[i + 4], flat[i + 5]))


class Block:
    """The rows of the samples one wake-up makes; :meth:`take` empties it into a message."""

    def __init__(self):
        self._flat = []

    def add(self, sec: int, nanosec: int, x: float, v: float | None, cos_tau: float,
            sin_tau: float) -> None:
        """A sample; ``v`` None: a position-only sensor (NaN in the row)."""
        self._flat.extend((float(sec), float(nanosec), x, math.nan if v is None else v,
                           cos_tau, sin_tau))

    def __len__(self) -> int:
        return len(self._flat) // 6

    def take(self) -> bytes | None:
        """The gathered rows as one serialized message (None when there are none)."""
        if not self._flat:
            return None
        data = pack(self._flat)
        self._flat = []
        return data

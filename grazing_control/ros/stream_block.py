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
the per-sample JointState of ``oscillator/state`` carries; a scene of n masses (a model
file, a rig of n masses: issue 32) has rows of w = 4 + 2 n columns:

    layout.dim[0]  label "sample", size N (samples), stride w N
    layout.dim[1]  label naming the w columns, size w, stride w
    layout.data_offset 0
    data           N rows of (stamp sec, stamp nanosec, x0 .. x{n-1}, v0 .. v{n-1},
                   cos tau, sin tau)

The label of dim[1] is ``sec,nanosec,x,v,cos_tau,sin_tau`` for one mass (the 1-DOF
format of issue 30, unchanged byte for byte) and
``sec,nanosec,x0,..,x{n-1},v0,..,v{n-1},cos_tau,sin_tau`` for n > 1 (``x0,x1,v0,v1`` for
two). stamp sec and nanosec: the sample's simulation time as the JointState's
header.stamp (integers, exact in a double); x_i, v_i: the positions and velocities as
measured, the JointState's position and velocity (v_i NaN: a position-only sensor, the
JointState's empty velocity); cos tau, sin tau: the shaker's phase reference, its effort.
A reader computes the same ``t = sec + nanosec 1e-9`` from a row as from the per-sample
message and takes the same coordinate, so the controller's estimates are the same bit
for bit.

:func:`pack` and :func:`read` are the wire format (XCDR1, little endian, as
:mod:`grazing_control.ros.cdr`; tests/test_stream_block.py checks them against rclpy's
serializer for n = 1, 2, 3 and on seeded hostile bytes). :func:`read` is strict: the
labels, every size and stride, the data count, the message's length and every stamp
must be those of a block of n masses, else it returns None (it never raises), so that a
node counts anything else as malformed. :class:`Block` gathers a wake-up's rows;
:func:`samples` gives a row as the controller takes one sample.
"""

from __future__ import annotations

import math
import struct
from functools import lru_cache
from typing import NamedTuple

__all__ = ["TOPIC", "TYPE", "FIELDS", "MESSAGES", "Block", "Rows", "check_message",
           "columns", "pack", "read", "samples"]

#: The topic and type of the stream in blocks (relative name, as oscillator/state).
TOPIC = "oscillator/state_block"
TYPE = "std_msgs/msg/Float64MultiArray"
#: The columns of a row of one mass (the 1-DOF format; :func:`columns` for n masses).
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


def columns(masses: int) -> tuple:
    """The names of the 4 + 2 n columns of a row of n = ``masses`` masses, dim[1]'s label
    (joined by commas): :data:`FIELDS` for one mass, else sec, nanosec, x0 .. x{n-1},
    v0 .. v{n-1}, cos_tau, sin_tau."""
    if masses == 1:
        return FIELDS
    return (("sec", "nanosec") + tuple(f"x{i}" for i in range(masses))
            + tuple(f"v{i}" for i in range(masses)) + ("cos_tau", "sin_tau"))


_HEADER = b"\x00\x01\x00\x00"
_NS = 1_000_000_000
_U32 = struct.Struct("<I")


def _string(text: str) -> bytes:
    """A CDR string without its padding: length (with the NUL), bytes, NUL."""
    raw = text.encode() + b"\x00"
    return _U32.pack(len(raw)) + raw


def _pad(pos: int, n: int) -> bytes:
    return b"\x00" * (-pos % n)


# The body (after the 4-byte header): dim count 2, dim[0] label "sample" | its size,
# stride | dim[1] label | its size, stride, data_offset 0 | data count | padding to 8 |
# the doubles. Offsets count from the body's start (CDR aligns to them). The padding is
# zeroed here; rclpy leaves whatever was in its buffer there, so a reader compares the
# fields only.
_DIM0 = _U32.pack(2) + _string("sample")
_PREFIX0 = _DIM0 + _pad(len(_DIM0), 4)
_POS_SIZES = len(_PREFIX0)                 # body offset of dim[0]'s size and stride
_POS_LABEL1 = _POS_SIZES + 8               # of dim[1]'s label


class _Layout(NamedTuple):
    """The fixed parts of a block of n masses (body offsets)."""

    width: int          # the columns of a row, 4 + 2 n
    label: bytes        # dim[1]'s label as a CDR string (length, text, NUL)
    rest: bytes         # dim[1]'s size and stride, data_offset 0
    pos_rest: int       # where ``rest`` starts
    pos_count: int      # where the data count is
    pos_data: int       # where the first double is
    middle: bytes       # what pack writes between dim[0]'s stride and the data count
    pad_data: bytes     # and between the count and the doubles


@lru_cache(maxsize=8)
def _layout(masses: int) -> _Layout:
    width = 4 + 2 * masses
    label = _string(",".join(columns(masses)))
    after = _POS_LABEL1 + len(label)
    rest = struct.pack("<III", width, width, 0)
    pos_rest = after + len(_pad(after, 4))
    pos_count = pos_rest + len(rest)
    pad_data = _pad(pos_count + 4, 8)
    return _Layout(width, label, rest, pos_rest, pos_count, pos_count + 4 + len(pad_data),
                   label + _pad(after, 4) + rest, pad_data)


def pack(flat, masses: int = 1) -> bytes:
    """The serialized Float64MultiArray of the rows in ``flat`` (a flat sequence of N rows
    of 4 + 2 ``masses`` floats, row after row; one mass: issue 30's 6 columns)."""
    if not (isinstance(masses, int) and masses >= 1):
        raise ValueError(f"masses={masses!r} is invalid: valid values are integers >= 1")
    lay = _layout(masses)
    m = len(flat)
    rows = m // lay.width
    return b"".join((_HEADER, _PREFIX0, struct.pack("<II", rows, lay.width * rows),
                     lay.middle, _U32.pack(m), lay.pad_data, struct.pack(f"<{m}d", *flat)))


class Rows(NamedTuple):
    """A block as :func:`read` gives it: the rows' ``masses`` n and ``flat``, its N rows
    of 4 + 2 n floats, row after row (:func:`samples` reads them)."""

    masses: int
    flat: tuple

    @property
    def count(self) -> int:
        """The number of rows."""
        return len(self.flat) // (4 + 2 * self.masses)


def read(data: bytes) -> Rows | None:
    """The rows of a block, or None for any other message: another layout, a dim[1] whose
    size is not 4 + 2 n for some n >= 1 or whose label does not name those columns
    (:func:`columns`), a dim[0] stride, data_offset or data count that is not the rows',
    a length that does not fit, a stamp that is not a non-negative integer sec below
    2^31 and an integer nanosec in [0, 1e9). Never raises."""
    try:
        size = len(data)
        if (size < 4 + _POS_LABEL1 + 4 or data[:4] != _HEADER
                or data[4:4 + len(_DIM0)] != _DIM0):
            return None
        rows, stride = struct.unpack_from("<II", data, 4 + _POS_SIZES)
        length = _U32.unpack_from(data, 4 + _POS_LABEL1)[0]
        after = _POS_LABEL1 + 4 + length
        if 4 + after + len(_pad(after, 4)) + 4 > size:
            return None
        width = _U32.unpack_from(data, 4 + after + len(_pad(after, 4)))[0]
        masses = (width - 4) // 2
        # the label of n masses is longer than 6 n bytes: a width that the label's length
        # cannot name is refused before a label is made for it
        if width < 6 or width % 2 or 6 * masses > length:
            return None
        lay = _layout(masses)
        if (data[4 + _POS_LABEL1:4 + _POS_LABEL1 + len(lay.label)] != lay.label
                or data[4 + lay.pos_rest:4 + lay.pos_count] != lay.rest
                or stride != width * rows
                or _U32.unpack_from(data, 4 + lay.pos_count)[0] != width * rows):
            return None
        end = 4 + lay.pos_data + 8 * width * rows
        if not end <= size <= end + 8:           # rclpy may pad the end
            return None
        flat = struct.unpack_from(f"<{width * rows}d", data, 4 + lay.pos_data)
    except (struct.error, TypeError):
        return None
    for i in range(0, width * rows, width):
        sec, ns = flat[i], flat[i + 1]
        if not (0.0 <= sec < 2**31 and sec == int(sec) and 0.0 <= ns < _NS and ns == int(ns)):
            return None
    return Rows(masses, flat)


def samples(rows: Rows, coordinate: int = 0, first: int = 0, end: int | None = None) -> list:
    """(sec, nanosec, x, v, (cos tau, sin tau)) of each row of ``rows`` from row
    ``first`` up to ``end`` (None: the last): the position
    and velocity of coordinate ``coordinate`` (v NaN: none), the tuple the controller
    takes from one per-sample message (:func:`grazing_control.ros.cdr.read_state`; an
    n-DOF JointState's position[c] and velocity[c], NaN where it has no velocity)."""
    n, flat = rows
    if not 0 <= coordinate < n:
        raise ValueError(f"coordinate={coordinate!r} is invalid: valid values are 0..{n - 1}"
                         f" (a block of {n} masses)")
    w, ix, iv = 4 + 2 * n, 2 + coordinate, 2 + n + coordinate
    return [(int(flat[i]), int(flat[i + 1]), flat[i + ix], flat[i + iv],
             (flat[i + w - 2], flat[i + w - 1]))
            for i in range(first * w, len(flat) if end is None else min(end * w, len(flat)), w)]


class Block:
    """The rows of the samples one wake-up makes; :meth:`take` empties it into a message."""

    def __init__(self):
        self._flat = []
        self.masses = 0          # the rows' n (0: none yet)

    def add(self, sec: int, nanosec: int, x, v, cos_tau: float, sin_tau: float) -> None:
        """A sample: ``x`` its n positions, ``v`` its n velocities (None: a position-only
        sensor, NaN in the row). ValueError for a sample of another n than the rows
        gathered (the block's rows have one width)."""
        n = len(x)
        if n != self.masses:
            if self._flat:
                raise ValueError(f"a sample of {n} masses in a block of {self.masses}")
            self.masses = n
        if v is not None and len(v) != n:
            raise ValueError(f"{len(v)} velocities for {n} positions")
        flat = self._flat
        flat += (float(sec), float(nanosec))
        flat += x
        flat += (math.nan,) * n if v is None else v
        flat += (cos_tau, sin_tau)

    def __len__(self) -> int:
        return len(self._flat) // (4 + 2 * self.masses) if self.masses else 0

    def take(self) -> bytes | None:
        """The gathered rows as one serialized message (None when there are none)."""
        if not self._flat:
            return None
        data = pack(self._flat, self.masses)
        self._flat = []
        return data

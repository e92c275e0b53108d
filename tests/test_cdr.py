"""grazing_control.ros.cdr against rclpy's own serializer and deserializer.

Differential: thousands of seeded random values (finite, huge, tiny, signed zeros,
inf, nan; stamps up to 2^31 - 1 s) give the bytes rclpy's serializer gives, except in
the alignment padding (which rclpy leaves uninitialised and cdr zeroes), and rclpy
deserializes them to the same fields; the decoders read rclpy's bytes back and refuse
every other layout.
"""

import math
import struct

import numpy as np
import pytest

pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from grazing_control.ros import cdr  # noqa: E402
from grazing_control.ros.common import stamp_from_seconds  # noqa: E402

N = 3000


def _padding(*ranges):
    """Absolute byte positions of alignment padding (payload offsets + the 4-byte header)."""
    return {4 + i for a, b in ranges for i in range(a, b)}


PAD = {
    "joint_state": _padding((13, 16), (29, 32), (36, 40), (52, 56), (68, 72)),
    "vector3_stamped": _padding((13, 16)),
    "twist_stamped": _padding((13, 16)),
    "wrench_stamped": _padding((17, 24)),
    "clock": set(),
    "float64": set(),
}


def _values(rng, n):
    """Random doubles of every kind the simulator can produce, and the edge cases."""
    special = [0.0, -0.0, math.inf, -math.inf, math.nan, 5e-324, -5e-324, 1.7976931348623157e308,
               2.2250738585072014e-308, 1e-300, -1e300]
    out = list(rng.normal(size=n // 2) * 10.0 ** rng.integers(-20, 20, size=n // 2))
    out += list(rng.uniform(-1e3, 1e3, size=n - n // 2 - len(special))) + special
    return out


def _stamps(rng, n):
    secs = list(rng.integers(0, 2**31 - 1, size=n - 3)) + [0, 2**31 - 1, 1]
    nsecs = list(rng.integers(0, 10**9, size=n - 3)) + [0, 10**9 - 1, 999_999_999]
    return [(int(s), int(ns)) for s, ns in zip(secs, nsecs)]


def _same_bytes_but_padding(ours, theirs, pad):
    assert len(ours) == len(theirs)
    diff = {i for i, (a, b) in enumerate(zip(ours, theirs)) if a != b}
    assert diff <= pad, sorted(diff - pad)
    assert all(ours[i] == 0 for i in pad)


def _equal(a, b):
    return a == b or (math.isnan(a) and math.isnan(b))


def test_joint_state_bytes_are_rclpys():
    rng = np.random.default_rng(1)
    xs, vs, es = _values(rng, N), _values(rng, N), _values(rng, N)
    rng.shuffle(vs)
    for (sec, ns), x, v, e in zip(_stamps(rng, N), xs, vs, es):
        ours = cdr.joint_state(sec, ns, x, v, e)
        msg = JointState(name=["mass"], position=[x], velocity=[v], effort=[e])
        msg.header.stamp = Time(sec=sec, nanosec=ns)
        _same_bytes_but_padding(ours, serialize_message(msg), PAD["joint_state"])
        back = deserialize_message(ours, JointState)
        assert back.name == ["mass"] and back.header.frame_id == ""
        assert (back.header.stamp.sec, back.header.stamp.nanosec) == (sec, ns)
        assert all(_equal(a, b) for a, b in
                   ((back.position[0], x), (back.velocity[0], v), (back.effort[0], e)))
        # and the decoder reads rclpy's bytes (garbage in the padding included)
        got = cdr.read_sample(serialize_message(msg))
        assert got[:2] == (sec, ns) and _equal(got[2], x) and _equal(got[3], v)


def test_vector3_twist_wrench_clock_and_float64_bytes_are_rclpys():
    rng = np.random.default_rng(2)
    vals = _values(rng, N)
    for (sec, ns), a, b, c in zip(_stamps(rng, N), vals, vals[1:] + vals[:1], vals[::-1]):
        stamp = Time(sec=sec, nanosec=ns)
        m = Vector3Stamped()
        m.header.stamp = stamp
        m.vector.x, m.vector.y, m.vector.z = a, b, c
        _same_bytes_but_padding(cdr.vector3_stamped(sec, ns, a, b, c), serialize_message(m),
                                PAD["vector3_stamped"])
        t = TwistStamped()
        t.header.stamp = stamp
        t.twist.linear.x = a
        t.twist.linear.y = b
        _same_bytes_but_padding(cdr.twist_stamped(sec, ns, a, b), serialize_message(t),
                                PAD["twist_stamped"])
        got = cdr.read_twist_stamped(serialize_message(t))
        assert got[:2] == (sec, ns) and _equal(got[2], a) and _equal(got[3], b)
        w = WrenchStamped()
        w.header.stamp = stamp
        w.header.frame_id = "mass"
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = a, b, c
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = c, a, b
        _same_bytes_but_padding(cdr.wrench_stamped(sec, ns, (a, b, c), (c, a, b)),
                                serialize_message(w), PAD["wrench_stamped"])
        assert cdr.clock(sec, ns) == serialize_message(Clock(clock=stamp))
        assert cdr.float64(a) == serialize_message(Float64(data=a)) or math.isnan(a)


@pytest.mark.parametrize("t", [0.0, 1e-9, 0.4999999999, 9.418185242872688, 12243.640812,
                               188363.705, 2**31 - 1.5])
def test_stamp_parts_are_stamp_from_seconds(t):
    """Both round t * 1e9 (the float product, as the stamps always did) to the nearest
    nanosecond, half to even: checked against exact rational arithmetic."""
    from fractions import Fraction

    stamp = stamp_from_seconds(t)
    assert cdr.stamp_parts(t) == (stamp.sec, stamp.nanosec)
    ns = round(Fraction(t * 1e9))
    assert cdr.stamp_parts(t) == divmod(ns, 10**9)


def test_decoders_refuse_every_other_layout():
    """Another publisher's JointState (two joints, no name, a frame_id, no velocity), a
    truncated or padded buffer, big endian, random bytes: None (the caller then uses
    rclpy's deserializer and its own checks), never an exception or a wrong sample."""
    def js(**kw):
        m = JointState(**kw)
        m.header.stamp = Time(sec=3, nanosec=4)
        return serialize_message(m)

    others = [js(name=["a", "b"], position=[1.0, 2.0], velocity=[1.0, 2.0], effort=[0.0, 0.0]),
              js(position=[1.0], velocity=[2.0], effort=[3.0]),
              js(name=["mass"], position=[1.0], velocity=[], effort=[3.0]),
              js(name=["mass"], position=[1.0], velocity=[2.0]),
              js(name=["mast"], position=[1.0], velocity=[2.0], effort=[3.0])]
    m = JointState(name=["mass"], position=[1.0], velocity=[2.0], effort=[3.0])
    m.header.frame_id = "x"
    others.append(serialize_message(m))
    good = cdr.joint_state(3, 4, 1.0, 2.0, 3.0)
    others += [good[:-1], good + b"\x00", b"\x00\x00" + good[2:], b""]
    assert cdr.read_sample(good) == (3, 4, 1.0, 2.0)
    for data in others:
        assert cdr.read_sample(data) is None
    rng = np.random.default_rng(3)
    for _ in range(N):
        data = bytes(rng.integers(0, 256, size=len(good), dtype=np.uint8))
        got = cdr.read_sample(data)
        assert got is None or data[:4] == b"\x00\x01\x00\x00"
        data = bytes(rng.integers(0, 256, size=int(rng.integers(0, 100)), dtype=np.uint8))
        cdr.read_twist_stamped(data)   # never raises
    t = TwistStamped()
    t.header.frame_id = "map"
    assert cdr.read_twist_stamped(serialize_message(t)) is None
    assert cdr.read_twist_stamped(struct.pack("<4s", b"\x00\x01\x00\x00")) is None


def test_a_correction_without_prediction_carries_nan_and_old_answers_still_decode():
    """linear.y defaults to NaN (no prediction); an answer from before the prediction
    (linear.y = 0, what every old bag holds) decodes with its 0.0."""
    got = cdr.read_twist_stamped(cdr.twist_stamped(1, 2, 0.5))
    assert got[:3] == (1, 2, 0.5) and math.isnan(got[3])
    t = TwistStamped()
    t.twist.linear.x = 0.25
    assert cdr.read_twist_stamped(serialize_message(t)) == (0, 0, 0.25, 0.0)


def test_the_estimate_deserializes_to_its_fields():
    rng = np.random.default_rng(5)
    vals = _values(rng, 500)
    for (sec, ns), a, b, c, d, e in zip(_stamps(rng, 500), vals, vals[1:], vals[2:],
                                        vals[3:], vals[4:]):
        m = deserialize_message(cdr.estimate_state(sec, ns, a, b, c, d, e), JointState)
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (sec, ns)
        assert list(m.name) == ["mass"] and m.header.frame_id == ""
        got = [m.position[0], m.velocity[0], *m.effort]
        assert len(got) == 5 and all(_equal(x, y) for x, y in zip(got, (a, b, c, d, e)))


def test_stream_samples_of_every_sensor_layout_read_as_rclpy_wrote_them():
    """read_state on rclpy's bytes: velocity carried or not (position-only sensor), effort
    [cos tau, sin tau], today's [cos tau], none, or more; random values and stamps."""
    rng = np.random.default_rng(6)
    vals = _values(rng, N)
    for i, ((sec, ns), x) in enumerate(zip(_stamps(rng, N), vals)):
        v = [vals[-i]] if i % 2 else []
        eff = [float(e) for e in rng.normal(size=i % 4)]
        m = JointState(name=["mass"], position=[x], velocity=v, effort=eff)
        m.header.stamp = Time(sec=sec, nanosec=ns)
        got = cdr.read_state(serialize_message(m))
        assert got[:2] == (sec, ns) and _equal(got[2], x)
        assert _equal(got[3], v[0]) if v else math.isnan(got[3])
        assert got[4] == tuple(eff)
    assert cdr.read_state(cdr.joint_state(3, 4, 1.0, 2.0, 0.5)) == (3, 4, 1.0, 2.0, (0.5,))


def test_the_stream_reader_refuses_other_layouts_and_never_raises():
    def js(**kw):
        return serialize_message(JointState(**kw))

    for data in (js(name=["a", "b"], position=[1.0, 2.0]), js(position=[1.0]),
                 js(name=["mass"], position=[]), js(name=["mass"], position=[1.0, 2.0]),
                 js(name=["mass"], position=[1.0], velocity=[1.0, 2.0]),
                 js(name=["mast"], position=[1.0]), b"", b"\x00\x01\x00\x00"):
        assert cdr.read_state(data) is None
    good = cdr.joint_state(3, 4, 1.0, 2.0, 0.5)
    assert cdr.read_state(good[:-1]) is None and cdr.read_state(good + bytes(9)) is None
    rng = np.random.default_rng(8)
    for _ in range(N):
        data = bytearray(good)
        for j in rng.integers(0, len(good), size=3):
            data[j] = int(rng.integers(0, 256))
        cdr.read_state(bytes(data))                   # never raises
        cdr.read_state(bytes(rng.integers(0, 256, size=int(rng.integers(0, 120)),
                                          dtype=np.uint8)))


def test_rig_sensor_of_n_masses_round_trips_through_rclpy():
    """cdr.rig_sample_masses (the simulated rig's rig/sensor of n masses) deserializes with
    rclpy to the message it packs, and cdr.read_joints reads rclpy's serialization of it
    back exactly, over 1000 seeded random messages of 1-12 joints with and without
    velocities; another shape (an effort, a frame_id, cut bytes) is None."""
    rng = np.random.default_rng(32)
    for _ in range(1000):
        k = int(rng.integers(1, 13))
        names = [f"mass{i}" for i in rng.permutation(12)[:k]]
        pos = [float(x) for x in rng.normal(size=k) * 10 ** rng.uniform(-9, 3)]
        vel = None if rng.random() < 0.5 else [float(x) for x in rng.normal(size=k)]
        sec, ns = int(rng.integers(0, 2**31 - 1)), int(rng.integers(0, 10**9))
        msg = JointState(name=names, position=pos, velocity=vel or [])
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, ns
        assert deserialize_message(cdr.rig_sample_masses(sec, ns, names, pos, vel),
                                   JointState) == msg
        data = serialize_message(msg)
        assert cdr.read_joints(data) == (sec, ns, tuple(names), tuple(pos), tuple(vel or ()))
        assert cdr.read_joints(data[:len(data) // 2]) is None
    other = JointState(name=["mass1"], position=[1.0], effort=[0.5])
    assert cdr.read_joints(serialize_message(other)) is None
    other = JointState(name=["mass1"], position=[1.0])
    other.header.frame_id = "rig"
    assert cdr.read_joints(serialize_message(other)) is None

"""Bags for the bagtools tests, written by an independent writer (rosbags' rosbag2 Writer,
MCAP storage) with the package's topics, or by the project's BagWriter."""

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
BAGS = Path(__file__).resolve().parent.parent / "bags"
_NS = 1_000_000_000


def _types():
    t = TYPESTORE.types
    return (t["sensor_msgs/msg/JointState"], t["std_msgs/msg/Header"],
            t["builtin_interfaces/msg/Time"], t["geometry_msgs/msg/TwistStamped"],
            t["geometry_msgs/msg/Twist"], t["geometry_msgs/msg/Vector3"],
            t["geometry_msgs/msg/Vector3Stamped"], t["std_msgs/msg/String"])


def joint_state(stamp_ns, x, v, *, frame_id="", names=("mass",), extra=()):
    JointState, Header, Time, *_ = _types()
    pos = np.array([x, *extra], float) if x is not None else np.zeros(0)
    vel = np.array([v, *extra], float) if v is not None else np.zeros(0)
    return JointState(header=Header(stamp=Time(sec=int(stamp_ns // _NS), nanosec=int(stamp_ns % _NS)),
                                    frame_id=frame_id),
                      name=list(names), position=pos, velocity=vel, effort=np.zeros(0))


def masses_joint_state(stamp_ns, x, v):
    """An n-DOF scene's JointState (sim_node's layout): one joint per coordinate, named
    mass0 .. mass{n-1}, positions ``x`` and velocities ``v``, no effort."""
    JointState, Header, Time, *_ = _types()
    return JointState(header=Header(stamp=Time(sec=int(stamp_ns // _NS), nanosec=int(stamp_ns % _NS)),
                                    frame_id=""),
                      name=[f"mass{i}" for i in range(len(x))], position=np.array(x, float),
                      velocity=np.array(v, float), effort=np.zeros(0))


def twist_stamped(stamp_ns, dv, frame_id=""):
    _, Header, Time, TwistStamped, Twist, Vector3, *_ = _types()
    return TwistStamped(header=Header(stamp=Time(sec=int(stamp_ns // _NS), nanosec=int(stamp_ns % _NS)),
                                      frame_id=frame_id),
                        twist=Twist(linear=Vector3(x=dv, y=0.0, z=0.0),
                                    angular=Vector3(x=0.0, y=0.0, z=0.0)))


def vector3_stamped(stamp_ns, a, b, c):
    _, Header, Time, _, _, Vector3, Vector3Stamped, _ = _types()
    return Vector3Stamped(header=Header(stamp=Time(sec=int(stamp_ns // _NS), nanosec=int(stamp_ns % _NS)),
                                        frame_id=""), vector=Vector3(x=a, y=b, z=c))


def string(text):
    return _types()[7](data=text)


def write_rosbags(path, messages):
    """messages: (topic, msgtype, log_time_ns, message) in order -> an MCAP rosbag2 bag."""
    conns = {}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for topic, msgtype, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=TYPESTORE)
            w.write(conns[topic], int(t), TYPESTORE.serialize_cdr(msg, msgtype))
    return Path(path)


def scene_messages(bag_dir, topics=None, *, with_impacts=True):
    """The Pi2 samples, corrections and impacts of a bag as rosbags messages (re-written)."""
    from grazing_control.recordings.analysis import scene_from_bag

    topics = topics or {"pi2": "/oscillator/pi2", "correction": "/controller/velocity_correction",
                        "impact": "/oscillator/impact"}
    s = scene_from_bag(bag_dir)
    out = []
    stamps = np.round(s.t * 1e9).astype(np.int64)
    imp_t = np.round(s.impacts[:, 0] * 1e9).astype(np.int64)
    j = 0
    for k, st in enumerate(stamps):
        t = 1_000_000 + 10 * k
        out.append((topics["pi2"], "sensor_msgs/msg/JointState", t,
                    joint_state(st, s.pi2[k, 0], s.pi2[k, 1])))
        out.append((topics["correction"], "geometry_msgs/msg/TwistStamped", t + 1,
                    twist_stamped(st, s.correction[k])))
        nxt = stamps[k + 1] if k + 1 < len(stamps) else np.iinfo(np.int64).max
        while with_impacts and j < len(imp_t) and imp_t[j] < nxt:
            out.append((topics["impact"], "geometry_msgs/msg/Vector3Stamped", t + 2,
                        vector3_stamped(imp_t[j], *s.impacts[j, 1:])))
            j += 1
    return out, s

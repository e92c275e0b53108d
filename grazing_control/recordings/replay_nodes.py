"""The rclpy side of ``grazing replay``: this process's session and the node replayed.

What the controller replays (:mod:`.replay`'s of Pi2 samples, :mod:`.stream_replay`'s of
a sensor stream) and the simulator replay share: a ROS domain of their own (claimed as
``grazing run`` claims one), a context, node and executor in this process, the replayed
node started as a process by :mod:`grazing_control.ros.launcher` with a parameter file
written for it, the output bag (:class:`grazing_control.ros.recording.BagWriter`), and
:class:`ControllerRun`, a real controller_node with its answers recorded as they come.
rclpy is imported only when these run.
"""

from __future__ import annotations

import struct
import tempfile
import time
from pathlib import Path

import yaml

from grazing_control.ros.recording.record import encode

__all__ = ["ControllerRun", "Session", "bag_writer", "claim", "close", "params_file", "qos",
           "start_process", "stamp_of"]

_NS = 1_000_000_000


def params_file(values, node, tmp: Path) -> Path:
    """A parameter file for ``node`` with ``values`` in ``tmp`` (a Path: itself)."""
    if isinstance(values, Path):
        return values
    path = tmp / f"{node}.yaml"
    clean = {k: (float(v) if isinstance(v, float) else v) for k, v in values.items()
             if isinstance(v, (bool, int, float, str, list))}
    # keyed /** like every parameter file of the package (applies under any node name)
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": clean}}, sort_keys=False))
    return path


class Session:
    """rclpy context, one node, one executor in this process, on ``domain_id``."""

    def __init__(self, domain_id: int, name: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from grazing_control.ros.launcher import use_profile_here

        use_profile_here()
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin(self, seconds: float) -> None:
        self.executor.spin_once(timeout_sec=seconds)

    def until(self, due: float) -> None:
        """Spin until the monotonic time ``due`` (steps of at most 10 ms)."""
        while time.monotonic() < due:
            self.spin(max(0.0, min(due - time.monotonic(), 0.01)))

    def wait_for(self, ready, timeout: float, proc=None) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if ready():
                return True
            if proc is not None and proc.poll() is not None:
                return False
            self.spin(0.02)
        return ready()

    def close(self) -> None:
        self.node.destroy_node()
        self.executor.shutdown()
        self.rclpy.try_shutdown(context=self.context)


def qos(depth=100_000, latched=False):
    """Reliable, volatile, keep last ``depth``; ``latched``: transient local, keep all."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST if not latched else HistoryPolicy.KEEP_ALL,
                      depth=depth if not latched else 0, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


def stamp_of(raw: bytes) -> int:
    """The header stamp (ns) of a serialized stamped message."""
    sec, nsec = struct.unpack_from("<iI", raw, 4)
    return sec * _NS + nsec


def start_process(module, params_file, overrides, domain_id, log):
    """The node ``module`` as a process on ``domain_id`` (launcher.start_node)."""
    from grazing_control.ros.launcher import start_node

    return start_node(module, [params_file] if params_file else [], overrides,
                      domain_id=domain_id, log=log)


def claim(domain_id):
    """The replay's ROS domain and the lock that keeps it: ``domain_id`` if given, else a
    free one claimed as ``grazing run`` does (:func:`grazing_control.ros.launcher.claim_domain`)."""
    if domain_id is not None:
        return int(domain_id), None
    from grazing_control.ros.launcher import claim_domain

    return claim_domain()


def close(proc, session, writer, lock) -> None:
    """Stop the replayed node, close the in-process session, the bag and the domain lock."""
    from grazing_control.ros.launcher import stop_nodes

    try:
        if proc is not None:
            stop_nodes([proc], grace=5.0)
        if session is not None:
            session.close()
        writer.close()
    finally:
        if lock is not None:
            lock.close()


def bag_writer(out: Path):
    """The output bag OUT, opened (ValueError if it exists and is not empty)."""
    from grazing_control.ros.recording import BagWriter

    if out.exists() and any(out.iterdir()):
        raise ValueError(f"--bag {out}: the directory exists and is not empty")
    return BagWriter(out, custom_data={"log_time": "received_timestamp",
                                       "written_by": "grazing replay"}).open()


class ControllerRun:
    """A real controller_node replayed against (:func:`.replay.replay_controller`,
    :func:`.stream_replay.replay_stream`).

    On entry: the output bag OUT, a claimed ROS domain, this process's session with its
    subscriptions to the controller's answers (``controller/velocity_correction``, each
    written to OUT on arrival and kept by stamp in :attr:`answers`), its estimates
    (``controller/estimate``, with ``estimates``, kept in :attr:`estimates`) and its
    parameter record. :meth:`publisher` makes the replay's publishers, :meth:`start`
    starts the controller with ``values`` and waits until it reads every one of them,
    :meth:`wait_answer` waits for one answer, :meth:`finish` writes the parameter records
    and the replay's own; on exit the controller, the session, OUT and the domain lock
    are closed."""

    def __init__(self, out, *, domain_id=None, log_dir=None, estimates=False):
        self.out = Path(out)
        self.log = (Path(log_dir) if log_dir else self.out).parent / \
            f"{self.out.name}_controller.log"
        self.estimates_wanted = estimates
        self.answers, self.estimates, self._records = {}, {}, []
        self.proc = self.session = None
        self.writer = bag_writer(self.out)
        self.domain_id, self.lock = claim(domain_id)

    def __enter__(self):
        from geometry_msgs.msg import TwistStamped
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String

        self._tmp = tempfile.TemporaryDirectory(prefix="grazing_replay_")
        try:
            self.session = Session(self.domain_id, "grazing_replay")
            node = self.session.node
            # transient local, as the recorder's: the controller's writers keep their
            # history (common.REPLAY_QOS), and an answer published before its writer had
            # matched this reader still comes; a volatile reader lost it (discovery is
            # not symmetric: this side saw the writer, the writer not yet this reader; the
            # first answer of a replay missing in a fresh clone's suite, 2026-11-29)
            self.sub = node.create_subscription(
                TwistStamped, "controller/velocity_correction",
                lambda m: self._on_output(m, "/controller/velocity_correction",
                                          "geometry_msgs/msg/TwistStamped", self.answers),
                qos(latched=True), raw=True)
            if self.estimates_wanted:
                node.create_subscription(
                    JointState, "controller/estimate",
                    lambda m: self._on_output(m, "/controller/estimate",
                                              "sensor_msgs/msg/JointState", self.estimates),
                    qos(latched=True), raw=True)
            node.create_subscription(
                String, "grazing/parameters",
                lambda m: self._records.append((m, time.time_ns())), qos(latched=True),
                raw=True)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc) -> None:
        try:
            close(self.proc, self.session, self.writer, self.lock)
        finally:
            self._tmp.cleanup()

    def offered(self, topic: str) -> list:
        """The QoS its publishers offer, as the recorder stores it (rosbag2's
        offered_qos_profiles)."""
        from grazing_control.ros.recording.topics import qos_to_dict

        return [qos_to_dict(i.qos_profile)
                for i in self.session.node.get_publishers_info_by_topic(topic)]

    def _on_output(self, msg_raw: bytes, topic: str, kind: str, into: dict) -> None:
        recv = time.time_ns()
        into.setdefault(stamp_of(msg_raw), (msg_raw, recv))
        if not self.writer.has_topic(topic):
            self.writer.add_topic(topic, kind, self.offered(topic))
        self.writer.write(topic, msg_raw, recv)

    def publisher(self, kind, topic: str):
        """A publisher of this replay (reliable, keep last 100000)."""
        return self.session.node.create_publisher(kind, topic, qos())

    def start(self, values, publishers) -> None:
        """Start controller_node with ``values``; RuntimeError (one line, its log named)
        unless it reads every one of ``publishers`` and answers within 30 s."""
        from grazing_control.ros.launcher import CONTROLLER_MODULE

        self.proc = start_process(CONTROLLER_MODULE,
                           params_file(values, "controller_node", Path(self._tmp.name)),
                           {}, self.domain_id, self.log)
        if not self.session.wait_for(
                lambda: all(p.get_subscription_count() >= 1 for p in publishers)
                and self.sub.get_publisher_count() >= 1, 30.0, self.proc):
            raise RuntimeError(f"controller_node did not start (exit status "
                               f"{self.proc.poll()}); see {self.log}")
        self.session.wait_for(lambda: False, 0.3)

    def wait_answer(self, stamp: int, timeout: float) -> bool:
        """Spin until the answer stamped ``stamp`` (ns) came, at most ``timeout`` s;
        RuntimeError if the controller exits."""
        end = time.monotonic() + timeout
        while stamp not in self.answers and time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f"controller_node exited with status {self.proc.poll()}")
            self.session.spin(0.05)
        return stamp in self.answers

    def collect_late(self, stamps, timeout: float) -> None:
        """Spin until every answer stamped in ``stamps`` came, while they still come: a
        wait of at most ``timeout`` s after the last one that did (a controller stalled
        past a sample's wait answers it later; its answers belong in OUT)."""
        stamps, got = set(stamps), -1
        while got < len(self.answers):
            got = len(self.answers)
            if self.session.wait_for(lambda: stamps <= self.answers.keys(), timeout):
                return

    def finish(self, record: dict) -> None:
        """The parameter records received and the replay's own (``record``: what was
        replayed, how) to OUT."""
        from rclpy.serialization import serialize_message
        from std_msgs.msg import String

        self.session.wait_for(lambda: False, 0.2)
        self.writer.add_topic("/grazing/parameters", "std_msgs/msg/String",
                              self.offered("/grazing/parameters"))
        for data_, t in self._records:
            self.writer.write("/grazing/parameters", data_, t)
        own = String(data=encode("/grazing_replay", {**record,
                                                     "domain_id": self.domain_id}))
        self.writer.write("/grazing/parameters", bytes(serialize_message(own)),
                          time.time_ns())

"""A small diagnostic updater: each node's state on ``/diagnostics`` at about 1 Hz.

diagnostic_updater (the C++/Python package of ros/diagnostics) is not on PyPI; this is
its core in a few lines, with the same shape: an :class:`Updater` owned by a node, tasks
added with :meth:`Updater.add` (a name and a callable filling a
:class:`DiagnosticStatusWrapper` with ``summary(level, message)`` and ``add(key,
value)``), published as one ``diagnostic_msgs/DiagnosticArray`` per period on the
absolute topic ``/diagnostics`` (what rqt_robot_monitor, Foxglove's diagnostics panels
and diagnostic_aggregator read), each status named ``"<namespace>/<node>: <task>"``
(``"sim_node: scene"`` in the root namespace) with the hardware id
``grazing_control/<namespace>/<node>``, so that two scenes in two namespaces stay apart
in a monitor. A task that raises gives an ERROR status naming the exception instead of
stopping the node.

The period is wall time (a steady clock) whatever ``use_sim_time`` says: a timer on the
node's ROS clock followed the simulation, 499 arrays per wall second in a fast lockstep
scene and none while the simulated clock stood (issue 27 §2). The header stamp is the
node's ROS time, as ROS stamps are.

The per-sample cost is nothing: the nodes keep counters and latency lists they already
had, and the tasks summarise them in the 1 Hz timer.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType

__all__ = ["OK", "WARN", "ERROR", "STALE", "DiagnosticStatusWrapper", "Updater", "level_of",
           "qualified_name"]

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)
_RANK = {OK: 0, WARN: 1, ERROR: 2, STALE: 3}
TOPIC = "/diagnostics"


def level_of(value: float, warn: float, error: float):
    """OK below ``warn``, WARN from it, ERROR from ``error`` (a threshold <= 0 is off)."""
    if error > 0 and value >= error:
        return ERROR
    if warn > 0 and value >= warn:
        return WARN
    return OK


class DiagnosticStatusWrapper:
    """diagnostic_updater.DiagnosticStatusWrapper: a level, a message and key/values."""

    def __init__(self, name: str = "", hardware_id: str = ""):
        self.name, self.hardware_id = name, hardware_id
        self.level, self.message = OK, ""
        self.values: list = []

    def summary(self, level, message: str) -> None:
        self.level, self.message = level, message

    def merge_summary(self, level, message: str) -> None:
        """Keep the worse level; join the messages of the worst (diagnostic_updater's
        mergeSummary)."""
        if _RANK[level] > _RANK[self.level]:
            self.level, self.message = level, message
        elif _RANK[level] == _RANK[self.level] and level != OK and message:
            self.message = f"{self.message}; {message}" if self.message else message

    def add(self, key: str, value) -> None:
        self.values.append(KeyValue(key=str(key), value=f"{value:.6g}"
                                    if isinstance(value, float) else str(value)))

    def to_msg(self) -> DiagnosticStatus:
        return DiagnosticStatus(level=self.level, name=self.name, message=self.message,
                                hardware_id=self.hardware_id, values=list(self.values))


def qualified_name(node) -> str:
    """The node's name with its namespace, without the leading slash: ``sim_node`` in the
    root namespace, ``a/sim_node`` in ``/a``."""
    return node.get_fully_qualified_name().lstrip("/")


class Updater:
    """diagnostic_updater.Updater: tasks run every ``period`` wall seconds (a steady
    clock, also under use_sim_time), one array published. ``hardware_id`` None:
    ``grazing_control/<namespace>/<node>``."""

    def __init__(self, node, period: float = 1.0, hardware_id: str | None = None):
        self.node = node
        self.hardware_id = (f"grazing_control/{qualified_name(node)}" if hardware_id is None
                            else hardware_id)
        self.tasks: list = []
        self.publisher = node.create_publisher(DiagnosticArray, TOPIC, 10)
        self.timer = (node.create_timer(period, self.update,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
                      if period > 0 else None)

    def set_hardware_id(self, hardware_id: str) -> None:
        self.hardware_id = hardware_id

    def add(self, name: str, task) -> None:
        """``task(stat)`` fills the DiagnosticStatusWrapper ``stat`` (returns it or None)."""
        self.tasks.append((name, task))

    def statuses(self) -> list:
        out = []
        for name, task in self.tasks:
            stat = DiagnosticStatusWrapper(f"{qualified_name(self.node)}: {name}",
                                           self.hardware_id)
            try:
                stat = task(stat) or stat
            except Exception as exc:      # a task's bug is a status, never a crash
                stat.summary(ERROR, f"diagnostic task failed: {type(exc).__name__}: {exc}")
            out.append(stat.to_msg())
        return out

    def update(self) -> None:
        msg = DiagnosticArray(status=self.statuses())
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.publisher.publish(msg)

    force_update = update


class SceneWindow:
    """The simulator's state over the last diagnostics period, from the loop's counters.

    ``status(stat, loop, counts, wall, thresholds)`` fills ``stat``: periods and simulated
    time, the pace (simulated seconds per wall second over the window, from the loop's
    ``progress``, against ``time_scale`` in realtime), corrections applied / late / lost / predicted (a
    prediction acted for a missing answer, as the node's summary), deadline misses and
    answer timeouts in the window, the latency and sample-lag p50/p99 of the window.
    Levels (thresholds, 0 = off): misses + timeouts + lost in the window >=
    ``misses_warn`` / ``misses_error``; latency p99 >= ``latency_warn`` / ``latency_error``
    (seconds); realtime pace below ``pace_warn`` x time_scale: WARN.
    """

    def __init__(self):
        self.last = None            # (wall, k, t, missed+timeouts+lost, n latencies, n lags)

    def status(self, stat, loop, counts: dict, wall: float, th: dict, realtime: bool,
               time_scale: float):
        import numpy as np

        if loop is None:
            stat.summary(OK, "waiting to start")
            return stat
        eng, stats = loop.engine, loop.stats
        bad = counts["missed"] + counts["timeouts"] + stats["lost"]
        # the pace from the loop's progress (realtime: its last wake-up), not from the last
        # sample's time, which moves a forcing period at a time (plant.loop.Loop.progress)
        now = (wall, eng.k, loop.progress, bad, len(loop.latencies), len(loop.lags))
        # the first status of a running scene sets the window's start: the pace of the
        # time before it (start-up, waiting for the controller) would read as a crawl
        first = self.last is None
        prev = now if first else self.last
        self.last = now
        dwall = now[0] - prev[0]
        stat.summary(OK, "finished" if loop.finished else "running")
        stat.add("periods", eng.k)
        stat.add("simulated time", float(eng.t))
        stat.add("corrections applied", stats["applied"])
        stat.add("late", stats["late"])
        stat.add("lost", stats["lost"])
        stat.add("predicted", stats["predicted"])
        if realtime:       # the plant's clock paused for the simulator's stalls
            stat.add("plant paused", stats.get("paused", 0))
            stat.add("plant paused ms", float(getattr(loop, "paused", 0.0) * 1e3))
        stat.add("deadline misses", counts["missed"])
        stat.add("answer timeouts", counts["timeouts"])
        stat.add("ignored", counts["ignored"])
        stat.add("malformed", counts["malformed"])
        window_bad = now[3] - prev[3]
        stat.add("misses+timeouts+lost in window", window_bad)
        lvl = level_of(window_bad, th["misses_warn"], th["misses_error"])
        if lvl != OK:
            stat.merge_summary(lvl, f"{window_bad} missed/timed-out/lost corrections in "
                                    f"{dwall:.2f} s")
        if dwall > 0 and not loop.finished:
            pace = (now[2] - prev[2]) / dwall
            stat.add("pace (sim s per wall s)", float(pace))
            stat.add("periods per wall s", float((now[1] - prev[1]) / dwall))
            if realtime:
                stat.add("time_scale", float(time_scale))
                if th["pace_warn"] > 0 and pace < th["pace_warn"] * time_scale:
                    stat.merge_summary(WARN, f"pace {pace:.4g} below {th['pace_warn']:g} x "
                                             f"time_scale {time_scale:g}")
        for name, values, start, key in (("latency", loop.latencies, prev[4], "latency"),
                                         ("sample lag", loop.lags, prev[5], None)):
            window = np.asarray(values[start:], dtype=float)
            if window.size:
                p50, p99 = np.percentile(window, (50, 99))
                stat.add(f"{name} p50 ms", float(p50 * 1e3))
                stat.add(f"{name} p99 ms", float(p99 * 1e3))
                if key:
                    lvl = level_of(p99, th["latency_warn"], th["latency_error"])
                    if lvl != OK:
                        stat.merge_summary(lvl, f"latency p99 {p99 * 1e3:.3g} ms")
        return stat

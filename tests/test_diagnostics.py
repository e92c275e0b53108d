"""ros.diagnostics: each node's state on /diagnostics at ~1 Hz (issue 19 §2), an updater
with diagnostic_updater's shape; levels that follow the thresholds, checked on a real
realtime scene read by a subscriber in another process's domain."""

import threading
import time
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from grazing_control.ros import launcher
from grazing_control.ros.diagnostics import (ERROR, OK, WARN, DiagnosticStatusWrapper,
                                             SceneWindow, Updater, level_of)
from test_closed_loop import CONTROLLER, NO_WATCHDOG, STUDY, new_domain


def test_levels_and_the_merged_summary():
    assert [level_of(v, 1.0, 5.0) for v in (0.5, 1.0, 4.9, 5.0)] == [OK, WARN, WARN, ERROR]
    assert level_of(100.0, 0.0, 0.0) == OK                    # thresholds off
    s = DiagnosticStatusWrapper("n: t", "hw")
    s.summary(OK, "running")
    s.merge_summary(WARN, "a")
    s.merge_summary(WARN, "b")
    s.merge_summary(OK, "fine")
    assert (s.level, s.message) == (WARN, "a; b")
    s.merge_summary(ERROR, "c")
    s.add("x", 0.1234567891)
    s.add("n", 3)
    msg = s.to_msg()
    assert (msg.level, msg.message, msg.name, msg.hardware_id) == (ERROR, "c", "n: t", "hw")
    assert [(kv.key, kv.value) for kv in msg.values] == [("x", "0.123457"), ("n", "3")]


def test_the_capture_rule_warns_once_it_has_held_back_its_patience():
    """controller_status.diagnose_capture: where it switched on; while held back the
    closest approach with the radius and the sections held, OK until CAPTURE_PATIENCE
    sections, then WARN naming the closest approach (docs/theory_capture.md)."""
    from types import SimpleNamespace

    from grazing_control.dynamics.design.capture import CAPTURE_PATIENCE, CaptureRule
    from grazing_control.ros.controller_status import diagnose_capture

    def status(rule):
        s = DiagnosticStatusWrapper("c", "hw")
        s.summary(OK, "controlling")
        diagnose_capture(rule, s)
        m = s.to_msg()
        return m.level, m.message, {kv.key: kv.value for kv in m.values}

    rule = CaptureRule((0.0, 0.0), 0.05)
    assert status(rule) == (OK, "controlling", {"captured at section": "not yet"})
    far = SimpleNamespace(z=(0.9, 0.0), cov=[[1.0, 0.0], [0.0, 1.0]])
    for k in range(CAPTURE_PATIENCE - 1):
        rule(k, far)
    level, _, values = status(rule)
    assert level == OK and values["capture closest approach"] == \
        f"0.9 (radius 0.05, {CAPTURE_PATIENCE - 1} sections held)"
    rule(CAPTURE_PATIENCE, far)
    level, message, _ = status(rule)
    assert level == WARN and "no closer than 0.9 to the orbit in 100 sections" in message
    rule(CAPTURE_PATIENCE + 1, SimpleNamespace(z=(0.01, 0.0), cov=far.cov))
    assert status(rule) == (OK, "controlling", {"captured at section": "101"})


def test_a_failing_task_is_an_error_status_not_a_crash():
    ctx = Context()
    rclpy.init(context=ctx, domain_id=new_domain())
    try:
        node = rclpy.create_node("diag_unit", context=ctx)
        up = Updater(node, period=0.0)
        up.add("good", lambda st: st.summary(OK, "fine"))
        up.add("bad", lambda st: 1 / 0)
        good, bad = up.statuses()
        assert (good.name, good.level, good.message) == ("diag_unit: good", OK, "fine")
        assert bad.level == ERROR and "ZeroDivisionError" in bad.message
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_names_and_hardware_ids_carry_the_namespace():
    """Two scenes in two namespaces must not merge in a monitor (issue 27 §2)."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=new_domain())
    try:
        for ns, prefix in (("", ""), ("a", "a/"), ("/b/c", "b/c/")):
            node = rclpy.create_node("diag_ns", namespace=ns, context=ctx)
            up = Updater(node, period=0.0)
            up.add("task", lambda st: st.summary(OK, "fine"))
            (status,) = up.statuses()
            assert status.name == f"{prefix}diag_ns: task"
            assert status.hardware_id == f"grazing_control/{prefix}diag_ns"
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_the_period_is_wall_time_under_use_sim_time():
    """Under use_sim_time the updater's timer follows the wall clock: it fires while the
    simulated clock stands (a ROS-clock timer never did) and no faster than its period
    while /clock runs 10^5 times faster than the wall (a ROS-clock timer fired at the
    executor's pace: 499 arrays/s in lockstep). Counted, not timed: the bound is the
    number of periods in the wall time the test happened to take."""
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock as ClockMsg

    ctx = Context()
    rclpy.init(context=ctx, domain_id=new_domain())
    try:
        node = rclpy.create_node("diag_sim", context=ctx, parameter_overrides=[
            Parameter("use_sim_time", Parameter.Type.BOOL, True)])
        clock_node = rclpy.create_node("diag_clock", context=ctx)
        pub = clock_node.create_publisher(ClockMsg, "/clock", 10)
        period = 0.2
        up = Updater(node, period=period)
        calls = []
        up.add("count", lambda st: calls.append(time.monotonic()))
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(clock_node)

        def spin_until(n, fast_clock):
            t0, sim = time.monotonic(), 0
            while len(calls) < n and time.monotonic() - t0 < 30.0:
                if fast_clock:
                    sim += 20_000_000_000          # 20 s of simulation per message
                    msg = ClockMsg()
                    msg.clock.sec, msg.clock.nanosec = divmod(sim, 1_000_000_000)
                    pub.publish(msg)
                ex.spin_once(timeout_sec=0.001)
            return time.monotonic() - t0

        spin_until(3, fast_clock=False)             # no /clock at all: time stands at 0
        assert len(calls) >= 3
        start = len(calls)
        wall = spin_until(start + 3, fast_clock=True)
        assert len(calls) - start <= wall / period + 2, (len(calls) - start, wall)
        node.destroy_node()
        clock_node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_the_simulators_status_carries_predicted():
    from types import SimpleNamespace

    loop = SimpleNamespace(engine=SimpleNamespace(k=10, t=94.2), progress=94.2, finished=False,
                           stats={"applied": 7, "late": 1, "lost": 0, "predicted": 2},
                           latencies=[1e-3] * 7, lags=[0.0] * 10)
    counts = {"missed": 3, "timeouts": 0, "ignored": 0, "malformed": 0}
    th = {"misses_warn": 1, "misses_error": 10, "latency_warn": 0.0, "latency_error": 0.0,
          "pace_warn": 0.0}
    stat = SceneWindow().status(DiagnosticStatusWrapper("s", "h"), loop, counts, 1.0, th,
                                True, 1000.0)
    assert ("predicted", "2") in [(kv.key, kv.value) for kv in stat.to_msg().values]


def test_a_realtime_loop_on_pace_reads_its_pace_in_every_window():
    """A window's pace is the loop's progress over the window's wall time, not the last
    sample's time: a realtime loop that keeps pace exactly (a test clock moved to each
    wake-up) at time_scale 250, a period 37.7 ms of wall time, read in windows of 0.26 s
    (a timer's period is never a whole number of periods): each window reads 250 within
    a wake-up's CLOCK_TICK, OK with pace_warn 0.9. The last sample's time read 6 periods
    in most windows, a pace of 217 and a WARN, 7 in some, 253 (a 0.25 s window of a
    scene at load read 151 on a fresh clone, 2026-11-28; docs/benchmarks.md)."""
    from test_plant_loops import Clock, Recorder, settings

    from grazing_control.plant.engine import Engine
    from grazing_control.plant.realtime import CLOCK_TICK, Realtime

    scale, window = 250.0, 0.26
    clock = Clock()
    loop = Realtime(Engine(settings(mode="realtime", time_scale=scale, max_periods=400,
                                    **NO_WATCHDOG)), Recorder(), clock)    # no answers
    loop.start()
    diag = SceneWindow()
    th = {"misses_warn": 0, "misses_error": 0, "latency_warn": 0.0, "latency_error": 0.0,
          "pace_warn": 0.9}
    counts = {"missed": 0, "timeouts": 0, "ignored": 0, "malformed": 0}
    paces, levels = [], set()
    next_status = clock.now
    while len(paces) < 20 and not loop.finished:
        if clock.now >= next_status:
            stat = diag.status(DiagnosticStatusWrapper("s", "h"), loop, counts, clock.now, th,
                               True, scale)
            values = {kv.key: kv.value for kv in stat.to_msg().values}
            if "pace (sim s per wall s)" in values:
                paces.append(float(values["pace (sim s per wall s)"]))
                levels.add(stat.level)
            next_status += window
        clock.now = min(clock.now + loop.wake_in(loop.now()), next_status)
        loop.tick()
    assert len(paces) == 20, paces
    assert max(abs(pace / scale - 1.0) for pace in paces) <= CLOCK_TICK / window, paces
    assert levels == {OK}


def test_the_controller_warns_of_no_answer_only_while_simulation_time_runs():
    """Under use_sim_time a diagnostics period in which the simulated clock stood (the
    scene over, not started) expected no sample: no WARN "no sample answered"; one in
    which it ran and nothing was answered still warns (issue 27 §2)."""
    from rclpy.parameter import Parameter
    from rclpy.time import Time

    from grazing_control.ros.controller_node import ControllerNode

    ctx = Context()
    rclpy.init(context=ctx, domain_id=new_domain())
    try:
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("use_sim_time", Parameter.Type.BOOL, True),
            Parameter("diagnostics_period", Parameter.Type.DOUBLE, 0.0)])
        clock = node.get_clock()
        clock.set_ros_time_override(Time(seconds=10, clock_type=clock.clock_type))

        def status():
            st = node._diagnose(DiagnosticStatusWrapper("c", "h"))
            return st.level, st.message

        node.answered = 5
        assert status()[0] == OK
        assert status() == (OK, "answering (control off)")      # clock stood: nothing due
        clock.set_ros_time_override(Time(seconds=20, clock_type=clock.clock_type))
        assert status() == (WARN, "no sample answered in the last period")
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


class Probe:
    """Keeps every status on /diagnostics of a domain. ``peer``: also subscribe to the
    scene's data topics, so that a simulator started with ``wait_for_subscribers`` 2
    (the recorder and this probe) starts only once the probe has discovered it: a status
    published right after the start (a watchdog that trips at once) is not published
    before the probe has matched the simulator."""

    def __init__(self, domain, peer=False):
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node("diag_probe", context=self.ctx)
        self.msgs, self.stamps, self.lock = [], [], threading.Lock()
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._keep, 100)
        if peer:
            from geometry_msgs.msg import TwistStamped, Vector3Stamped
            from rosgraph_msgs.msg import Clock
            from sensor_msgs.msg import JointState
            from std_msgs.msg import Float64

            for topic, kind in (("oscillator/pi2", JointState), ("oscillator/pi1", JointState),
                                ("oscillator/state", JointState),
                                ("oscillator/impact", Vector3Stamped), ("/clock", Clock),
                                ("oscillator/latency", Float64),
                                ("controller/velocity_correction", TwistStamped)):
                self.node.create_subscription(kind, topic, lambda m: None, 10)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _keep(self, m):
        stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        with self.lock:
            self.msgs.extend(m.status)
            self.stamps.extend([stamp] * len(m.status))

    def _spin(self):
        while rclpy.ok(context=self.ctx):
            try:
                self.ex.spin_once(timeout_sec=0.1)
            except Exception:
                return

    def statuses(self, name):
        with self.lock:
            return [s for s in self.msgs if s.name == name]

    def stamped(self, name):
        """(header stamp, status) of each status of ``name``, in arrival order."""
        with self.lock:
            return [(t, s) for t, s in zip(self.stamps, self.msgs) if s.name == name]

    def close(self):
        rclpy.shutdown(context=self.ctx)
        self.thread.join(5)


def _raise_the_latency_warning_once_running(probe, done):
    """Once two statuses of the running scene carried a latency (OK: the warning off),
    set the simulator's diag_latency_warn to 1e-9 (every latency reaches it: WARN from
    the next status on). Returns (wall time the request went, wall time its answer came,
    whether it was taken), or None if the scene ended first."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    while not done.is_set():
        running = [s for s in probe.statuses("sim_node: scene")
                   if any(kv.key == "latency p99 ms" for kv in s.values)]
        if len(running) >= 2:
            break
        time.sleep(0.05)
    else:
        return None
    client = AsyncParameterClient(probe.node, "sim_node")
    if not client.wait_for_services(5.0):      # a request before the match may be lost
        return None
    sent = time.time()
    fut = client.set_parameters([Parameter("diag_latency_warn", value=1e-9)])
    while not fut.done() and not done.is_set():
        time.sleep(0.01)
    ok = fut.done() and fut.result().results[0].successful
    return sent, time.time(), ok


@pytest.mark.realtime
def test_a_realtime_scene_reports_its_state_and_follows_a_live_latency_threshold(tmp_path):
    """One realtime scene (160 periods at x250, 6.0 s of wall time, a status a second;
    the first running one has no latency window, two more OK ones, the change, one WARN
    at least: 4 s, 2 s to spare):
    the simulator's and the controller's statuses, their keys; with diag_latency_warn 0
    (off) every running status is OK; diag_latency_warn changed to 1e-9 while the scene
    runs (the thresholds may change at any time, docs/nodes.md), every status after the
    change was answered is a WARN naming the latency p99. (Two scenes before, one per
    threshold: 10.7 s each in the realtime group.) Statuses are told apart by their
    stamps (the node's ROS time, the wall clock): before the request went, after its
    answer came; one computed in between may be either."""
    domain = new_domain()
    probe = Probe(domain)
    done = threading.Event()
    change = []
    switcher = threading.Thread(
        target=lambda: change.append(_raise_the_latency_warning_once_running(probe, done)),
        daemon=True)
    switcher.start()
    try:
        res = launcher.run(STUDY, CONTROLLER, None, 160, domain_id=domain,
                           sim_overrides={"mode": "realtime", "time_scale": 250.0,
                                          "diag_latency_warn": 0.0,
                                          "diag_latency_error": 0.0},
                           log_dir=tmp_path / "logs")
        done.set()
        switcher.join(10)
        assert res.ok, (res, Path(res.logs["sim_node"]).read_text()[-1500:])
        assert change and change[0] is not None and change[0][2], change
        sent, answered_at = change[0][:2]
        sim = probe.statuses("sim_node: scene")
        ctl = probe.statuses("controller_node: controller")
        assert len(sim) >= 3 and len(ctl) >= 3, (len(sim), len(ctl))
        running = [s for s in probe.stamped("sim_node: scene") if s[1].message
                   != "waiting to start" and any(kv.key == "latency p99 ms" for kv in s[1].values)]
        before = [s for t, s in running if t < sent]
        after = [s for t, s in running if t > answered_at]
        assert len(before) >= 2 and after, ([(t - sent, s.level) for t, s in running])
        print(f"\n{len(before)} OK statuses before the change, {len(after)} WARN after")
        assert {s.level for s in before} == {OK}, [(s.level, s.message) for s in before]
        assert {s.level for s in after} == {WARN}, [(s.level, s.message) for s in after]
        assert all("latency p99" in s.message for s in after)
        for s in (before[-1], after[-1]):
            keys = {kv.key for kv in s.values}
            assert {"periods", "deadline misses", "pace (sim s per wall s)", "time_scale",
                    "latency p50 ms", "sample lag p99 ms"} <= keys
        answered = [int(dict((kv.key, kv.value) for kv in s.values)["answered"]) for s in ctl]
        assert answered == sorted(answered) and answered[-1] > 0
        log = Path(res.logs["sim_node"]).read_text()
        assert "parameter changed: diag_latency_warn 0.0 -> 1e-09" in log   # logged
    finally:
        done.set()
        probe.close()

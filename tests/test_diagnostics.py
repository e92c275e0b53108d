"""ros.diagnostics: each node's state on /diagnostics at ~1 Hz (issue 19 §2), an updater
with diagnostic_updater's shape; levels that follow the thresholds, checked on a real
realtime scene read by a subscriber in another process's domain."""

import threading
import time

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from grazing_control.ros import launcher
from grazing_control.ros.diagnostics import (ERROR, OK, WARN, DiagnosticStatusWrapper,
                                             Updater, level_of)
from test_closed_loop import CONTROLLER, STUDY, new_domain


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


class Probe:
    def __init__(self, domain):
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node("diag_probe", context=self.ctx)
        self.msgs, self.lock = [], threading.Lock()
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._keep, 100)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _keep(self, m):
        with self.lock:
            self.msgs.extend(m.status)

    def _spin(self):
        while rclpy.ok(context=self.ctx):
            try:
                self.ex.spin_once(timeout_sec=0.1)
            except Exception:
                return

    def statuses(self, name):
        with self.lock:
            return [s for s in self.msgs if s.name == name]

    def close(self):
        rclpy.shutdown(context=self.ctx)
        self.thread.join(5)


@pytest.mark.parametrize("latency_warn, expect", [(0.0, OK), (1e-9, WARN)])
def test_a_realtime_scene_reports_its_state_and_the_latency_threshold(tmp_path, latency_warn,
                                                                        expect):
    domain = new_domain()
    probe = Probe(domain)
    try:
        res = launcher.run(STUDY, CONTROLLER, None, 200, domain_id=domain,
                           sim_overrides={"mode": "realtime", "time_scale": 250.0,
                                          "diag_latency_warn": latency_warn,
                                          "diag_latency_error": 0.0},
                           log_dir=tmp_path / "logs")
        assert res.ok, res
        time.sleep(1.5)
        sim = probe.statuses("sim_node: scene")
        ctl = probe.statuses("controller_node: controller")
        assert len(sim) >= 3 and len(ctl) >= 3, (len(sim), len(ctl))
        running = [s for s in sim if s.message != "waiting to start" and
                   any(kv.key == "latency p99 ms" for kv in s.values)]
        assert running, [s.message for s in sim]
        assert {s.level for s in running} == {expect}, [(s.level, s.message) for s in running]
        if expect == WARN:
            assert all("latency p99" in s.message for s in running)
        keys = {kv.key for kv in running[-1].values}
        assert {"periods", "deadline misses", "pace (sim s per wall s)", "time_scale",
                "latency p50 ms", "sample lag p99 ms"} <= keys
        answered = [int(dict((kv.key, kv.value) for kv in s.values)["answered"]) for s in ctl]
        assert answered == sorted(answered) and answered[-1] > 0
    finally:
        probe.close()

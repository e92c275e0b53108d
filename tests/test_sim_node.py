"""sim_node: its engine without ROS, then the node over Fast DDS in its own process.

The node tests act as the controller themselves (a subscription on oscillator/pi2 in
the test process answers on controller/velocity_correction), so they control exactly
what the simulator receives: late, malformed or foreign answers, held answers while a
parameter is set or a reset is requested.
"""

from __future__ import annotations

import math
import re
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from grazing_control.ros import launcher
from grazing_control.ros import cdr
from grazing_control.ros.common import DATA_QOS, seconds_from_stamp, stamp_key
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values
from test_closed_loop import STUDY, Collector, new_domain, stamps, xv

BASE = dict(zeta=0.01, r=0.68, omega=OscillatorParams().omega, delta_d=-5e-6, tau0=0.0,
            pi2_offset=math.pi / 2, x0=math.nan, v0=math.nan, mode="lockstep",
            time_scale=1.0, state_period=1.0, answer_timeout=1.0, max_periods=0,
            fidelity="exact", noise=0.0, seed=0)


def settings(**kw):
    return settings_from_values({**BASE, **kw})


# ============================================================ engine, no middleware
def test_settings_refuse_invalid_values_with_a_reason():
    for kw, text in [({"zeta": 2.0}, "zeta=2.0 is invalid"), ({"r": 1.0}, "r=1.0"),
                     ({"mode": "fast"}, "mode='fast'"), ({"fidelity": "rk45"}, "rk45"),
                     ({"x0": 5.0}, "x0=5.0"), ({"time_scale": 0.0}, "time_scale"),
                     ({"noise": -1.0}, "noise"), ({"v0": math.inf}, "v0"),
                     ({"seed": -1}, "seed=-1")]:
        with pytest.raises(ParameterError, match=re.escape(text)):
            settings(**kw)


def test_engine_reproduces_simulate_and_events_are_ordered():
    s = settings()
    eng = Engine(s)
    ref = simulate(s.params, 50)
    got, pi1 = [eng.sample()], 0
    for _ in range(50):
        events = eng.begin_period(0.0)
        assert [e.t for e in events] == sorted(e.t for e in events)
        pi1 += sum(e.kind == "pi1" for e in events)
        got.append(eng.end_period()[0])
    assert pi1 == 50
    np.testing.assert_array_equal([(e.x, e.v) for e in got[:50]], ref.pi2)
    assert got[50].t == 50 * s.params.period


def test_split_without_correction_keeps_the_trajectory():
    s = settings(delta_d=-1e-3)
    a, b = Engine(s), Engine(s)
    for _ in range(5):
        a.begin_period(0.0)
        b.begin_period(0.0)
        b.split(b.seg.ts + 0.3, 0.0)
        ea, eb = a.end_period()[0], b.end_period()[0]
        assert ea.x == pytest.approx(eb.x, abs=1e-12) and ea.v == pytest.approx(eb.v, abs=1e-12)


def test_noise_is_reproducible_from_the_seed():
    runs = []
    for _ in range(2):
        eng = Engine(settings(noise=1e-4, seed=7))
        runs.append([eng.sample().v] + [(eng.begin_period(0.0), eng.end_period()[0].v)[1]
                                        for _ in range(5)])
    assert runs[0] == runs[1]
    assert runs[0][1] != simulate(settings().params, 2).pi2[1, 1]


def test_pending_parameters_apply_at_the_next_sample_only():
    eng = Engine(settings())
    eng.begin_period(0.0)
    eng.pending = settings(delta_d=-9e-6).params
    assert eng.p.delta_d == -5e-6           # the running period keeps the old model
    eng.end_period()
    assert eng.p.delta_d == -9e-6 and eng.pending is None


# =========================================================== the node, over DDS
def sim_cmd(domain, **over):
    return (launcher.node_command(launcher.SIM_MODULE, [STUDY], over),
            launcher.node_env(domain))


def test_invalid_parameter_at_start_exits_nonzero_with_one_line():
    domain = new_domain()
    cases = {"zeta": ("2.0", "zeta=2.0 is invalid"), "r": ("1.0", "r=1.0 is invalid"),
             "fidelity": ("rk45", "fidelity='rk45' is invalid"),
             "x0": ("5.0", "x0=5.0 is invalid"), "mode": ("fast", "mode='fast' is invalid"),
             "omega": ("1", "expected type DOUBLE"),
             # issue 32: it ran until Delta d overflowed mid-scene; |drift| <= d* = 1.8015
             "delta_d_drift": ("1e308", "delta_d_drift=1e+308 is invalid: Parameter "
                               "delta_d_drift out of range Min: -1.801498314953796, Max: "
                               "1.801498314953796")}
    procs = {}
    for name, (value, _) in cases.items():
        cmd, env = sim_cmd(domain)
        procs[name] = subprocess.Popen(cmd + ["-p", f"{name}:={value}"], env=env,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                       text=True)
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=30)
        lines = [ln for ln in (out + err).splitlines() if ln.strip()]
        assert proc.returncode == 2, (name, out, err)
        assert len(lines) == 1 and "Traceback" not in err, (name, lines)
        assert cases[name][1] in lines[0] and "[ERROR]" in lines[0], lines[0]


class Answerer:
    """The test as the controller: answers every Pi2 sample with dv = 0 unless held."""

    def __init__(self, collector: Collector, extra=None):
        self.c = collector
        self.pub = collector.node.create_publisher(
            TwistStamped, "controller/velocity_correction", DATA_QOS)
        self.samples = []
        self.hold_at = None          # sample index (counted in arrival order) to hold
        self.held = None
        self.extra = extra           # called with (msg) before the real answer
        self.lock = threading.Lock()
        collector.node.create_subscription(JointState, "oscillator/pi2", self.on_sample,
                                           DATA_QOS)

    def on_sample(self, msg):
        with self.lock:
            self.samples.append(msg)
            if self.hold_at is not None and len(self.samples) - 1 == self.hold_at:
                self.held = msg
                return
        if self.extra:
            self.extra(self.pub, msg)
        self.answer(msg)

    frame_id = ""                    # "": the controller's layout; else rclpy decodes it

    def answer(self, msg, dv=0.0):
        out = TwistStamped()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = self.frame_id
        out.twist.linear.x = dv
        self.pub.publish(out)

    def wait_held(self, timeout=20.0):
        assert self.c.wait_for(lambda: self.held is not None, timeout), len(self.samples)
        return self.held


def call(collector, future, timeout=10.0):
    assert collector.wait_for(future.done, timeout)
    return future.result()


def summary(log_text):
    m = re.search(r"summary: (.*)", log_text)
    assert m, log_text
    return dict(re.findall(r"(\w+)=([^\s]+)", m.group(1)))


@pytest.fixture
def node_env(tmp_path):
    """(domain, collector, start) where start(**overrides) runs sim_node in the domain."""
    domain = new_domain()
    collector = Collector(domain)
    procs = []

    def start(**over):
        log = tmp_path / f"sim{len(procs)}.log"
        over = {"wait_for_controller": False, "wait_for_subscribers": 1, **over}
        proc = launcher.start_node(launcher.SIM_MODULE, [STUDY], over, domain_id=domain,
                                   log=log)
        procs.append(proc)
        return proc, log

    yield domain, collector, start
    launcher.stop_nodes(procs)
    collector.close()


def test_malformed_and_foreign_corrections_are_ignored(node_env):
    domain, collector, start = node_env

    def junk(pub, msg):
        bad = TwistStamped()
        bad.header.stamp = msg.header.stamp
        bad.twist.linear.x = math.nan
        pub.publish(bad)                          # NaN: malformed
        foreign = TwistStamped()
        foreign.header.stamp.sec = msg.header.stamp.sec + 1
        foreign.twist.linear.x = 0.5
        pub.publish(foreign)                      # another stamp: foreign
        # bytes no TwistStamped decodes from (a truncated answer for this very sample)
        pub.publish(cdr.twist_stamped(msg.header.stamp.sec, msg.header.stamp.nanosec,
                                      0.5)[:int(rng.integers(1, 60))])

    rng = np.random.default_rng(8)
    answerer = Answerer(collector, junk)
    answerer.frame_id = "rig"     # the real answers in another layout: decoded by rclpy
    n = 20
    proc, log = start(max_periods=n, exit_when_done=True, answer_timeout=10.0)
    assert proc.wait(30) == 0, log.read_text()
    s = summary(log.read_text())
    assert (s["applied"], s["malformed"], s["ignored"], s["timeouts"]) == \
        (str(n), str(2 * n), str(n), "0")
    assert "Traceback" not in log.read_text()
    ref = simulate(OscillatorParams(delta_d=-5e-6), n)
    np.testing.assert_array_equal(xv(collector.get("oscillator/pi2")), ref.pi2)


def test_no_answer_times_out_and_applies_none(node_env):
    domain, collector, start = node_env
    proc, log = start(max_periods=5, exit_when_done=True, answer_timeout=0.05)
    assert proc.wait(30) == 0, log.read_text()
    assert summary(log.read_text())["timeouts"] == "5"
    ref = simulate(OscillatorParams(delta_d=-5e-6), 5)
    np.testing.assert_array_equal(xv(collector.get("oscillator/pi2")), ref.pi2)
    assert collector.wait_for(lambda: len(collector.get("done")) == 1, 5.0)


def test_runtime_parameters_validated_and_applied_at_the_next_sample(node_env):
    domain, collector, start = node_env
    ans = Answerer(collector)
    ans.hold_at = 5
    proc, log = start(max_periods=12, exit_when_done=True, answer_timeout=30.0,
                      live_changes=True)
    held = ans.wait_held()
    client = AsyncParameterClient(collector.node, "sim_node")
    assert client.wait_for_services(10.0)
    # invalid values: rejected with the reason, old values kept
    for name, value, text in [("zeta", 2.0, "zeta"), ("r", 1.0, "r=1.0 is invalid"),
                              ("fidelity", "rk45", "rk45"), ("mode", "realtime", "read-only"),
                              ("x0", 9.0, "x0=9.0")]:
        res = call(collector, client.set_parameters([Parameter(name, value=value)]))
        assert not res.results[0].successful and text in res.results[0].reason, res
    got = call(collector, client.get_parameters(["zeta", "r", "fidelity", "mode"]))
    assert [v.double_value for v in got.values[:2]] == [0.01, 0.68]
    assert [v.string_value for v in got.values[2:]] == ["exact", "lockstep"]
    # a valid change of the model during period 5: period 5 runs with the old model,
    # the new one from sample 6 on
    res = call(collector, client.set_parameters([Parameter("delta_d", value=-9e-6)]))
    assert res.results[0].successful
    ans.answer(held)
    assert proc.wait(30) == 0, log.read_text()
    got = xv(ans.samples)
    old = simulate(OscillatorParams(delta_d=-5e-6), 7)
    np.testing.assert_array_equal(got[:7], old.pi2)
    new = simulate(OscillatorParams(delta_d=-9e-6), 6, deviation=old.pi2_deviation[6])
    np.testing.assert_array_equal(got[6:], new.pi2)


def test_parameters_are_read_only_while_the_scene_runs_by_default(node_env):
    """Without live_changes a running scene refuses every change, naming the option, and
    logs the attempt (anyone on the domain can call the parameter services)."""
    domain, collector, start = node_env
    ans = Answerer(collector)
    ans.hold_at = 3
    proc, log = start(max_periods=6, exit_when_done=True, answer_timeout=30.0)
    held = ans.wait_held()
    client = AsyncParameterClient(collector.node, "sim_node")
    assert client.wait_for_services(10.0)
    for name, value in (("delta_d", 1e300), ("max_periods", 0), ("zeta", 0.02)):
        res = call(collector, client.set_parameters([Parameter(name, value=value)]))
        assert not res.results[0].successful and "live_changes" in res.results[0].reason
    ans.answer(held)
    assert proc.wait(30) == 0, log.read_text()
    got = xv(ans.samples)
    np.testing.assert_array_equal(got, simulate(OscillatorParams(delta_d=-5e-6),
                                                len(got)).pi2)
    assert "parameter change refused while the scene runs: delta_d" in log.read_text()


def test_live_changes_with_absurd_consequences_are_refused_and_nothing_is_applied(node_env):
    """With live_changes a change is still refused when its consequences are absurd for
    the running scene (plant.settings.check_live_change): the wall beyond the motion's
    reach, an unbounded scene, a tenfold jump of a model parameter, noise larger than the
    motion, use_sim_time (the simulator publishes /clock); the reason names the parameter
    and the range, and a refused request with a valid value beside it applies neither (the
    run stays the core's simulate)."""
    domain, collector, start = node_env
    ans = Answerer(collector)
    ans.hold_at = 3
    proc, log = start(max_periods=6, exit_when_done=True, answer_timeout=30.0,
                      live_changes=True, history_depth=5000)
    held = ans.wait_held()
    client = AsyncParameterClient(collector.node, "sim_node")
    assert client.wait_for_services(10.0)
    for params, text in (
            ([Parameter("delta_d", value=1e300)], "delta_d=1e+300 is invalid while the scene"),
            ([Parameter("delta_d", value=-3.0)], "[-"),
            ([Parameter("max_periods", value=0)], "not 0: the scene was bounded"),
            ([Parameter("max_periods", value=2)], "valid range is > 3"),
            ([Parameter("omega", value=7.0)], "within a factor 2"),
            ([Parameter("noise", value=5.0)], "noise=5.0 is invalid while the scene runs"),
            # a third party's use_sim_time froze a realtime scene (issue 27): the
            # simulator is the source of /clock
            ([Parameter("use_sim_time", value=True)], "use_sim_time=true is invalid for "
                                                      "sim_node: valid is false only"),
            ([Parameter("zeta", value=0.011), Parameter("delta_d", value=1e300)], "delta_d")):
        res = call(collector, client.set_parameters_atomically(params))
        assert not res.result.successful and text in res.result.reason, res
    got = call(collector, client.get_parameters(["delta_d", "zeta", "max_periods"]))
    assert got.values[0].double_value == -5e-6 and got.values[1].double_value == 0.01
    assert got.values[2].integer_value == 6
    ans.answer(held)
    assert proc.wait(30) == 0, log.read_text()
    np.testing.assert_array_equal(xv(ans.samples),
                                  simulate(OscillatorParams(delta_d=-5e-6), 6).pi2)
    assert "parameter change refused: delta_d=1e+300" in log.read_text()
    assert "parameter change refused: use_sim_time=true is invalid" in log.read_text()


def test_check_live_change_over_fuzzed_changes():
    """Seeded: 3000 random changes of one parameter; refused exactly by the documented
    rule, and an accepted change never makes the next period fail."""
    import random

    from grazing_control.plant.settings import (LIVE_FACTOR, check_live_change, default_values,
                                                settings_from_values)
    rng = random.Random(2126)
    base = default_values() | {"delta_d": -5e-6, "max_periods": 100}
    old = settings_from_values(base)
    a = old.params.amplitude
    for _ in range(3000):
        name = rng.choice(["delta_d", "zeta", "omega", "r", "noise", "max_periods"])
        value = {"delta_d": lambda: rng.choice([-1, 1]) * 10 ** rng.uniform(-8, 3),
                 "zeta": lambda: rng.uniform(0.001, 0.999),
                 "omega": lambda: 10 ** rng.uniform(-1.5, 1.5),
                 "r": lambda: rng.uniform(0.01, 1.0),
                 "noise": lambda: 10 ** rng.uniform(-8, 2),
                 "max_periods": lambda: rng.randrange(0, 200)}[name]()
        try:
            new = settings_from_values(base | {name: value})
        except ParameterError:
            continue
        o = base[name]
        expect_ok = {"delta_d": -a <= value <= a,
                     "zeta": o / LIVE_FACTOR <= value <= o * LIVE_FACTOR,
                     "omega": o / LIVE_FACTOR <= value <= o * LIVE_FACTOR,
                     "r": o / LIVE_FACTOR <= value <= o * LIVE_FACTOR,
                     "noise": value <= a,
                     "max_periods": value > 50}[name]
        try:
            check_live_change(old, new, 50)
            ok = True
        except ParameterError as exc:
            ok = False
            assert str(exc).startswith(f"{name}=") and "valid range" in str(exc)
        assert ok == expect_ok, (name, value)


def test_a_stray_publisher_on_the_correction_topic_is_counted_not_fatal(node_env):
    """`ros2 topic pub --once /controller/velocity_correction ...` from a bystander (a
    second publisher without this package's parameter record) once ended the scene with
    status 1 ("not isolated"): now it is logged once as a bystander, its message is
    counted as ignored, and the scene finishes with status 0 and the core's samples."""
    domain, collector, start = node_env
    ans = Answerer(collector)
    ans.hold_at = 4
    proc, log = start(max_periods=10, exit_when_done=True, answer_timeout=30.0)
    held = ans.wait_held()
    stray = collector.node.create_publisher(TwistStamped, "controller/velocity_correction",
                                            DATA_QOS)     # a second publisher, no record
    msg = TwistStamped()
    msg.header.stamp.sec = 123456
    msg.twist.linear.x = 0.25
    deadline = 20.0
    assert collector.wait_for(lambda: stray.get_subscription_count() > 0, deadline)
    stray.publish(msg)
    assert collector.wait_for(lambda: "a bystander" in log.read_text(), deadline), \
        log.read_text()
    # the bystander is logged when it is discovered, its message counted when it arrives:
    # the scene is released only after both (it could finish first: ignored=0, a rerun)
    assert collector.wait_for(lambda: "correction ignored (1 so far)" in log.read_text(),
                              deadline), log.read_text()
    ans.answer(held)
    assert proc.wait(30) == 0, log.read_text()
    text = log.read_text()
    assert "not isolated" not in text and text.count("a bystander") == 1
    assert re.search(r"ignored=1\b", text), text
    np.testing.assert_array_equal(xv(ans.samples),
                                  simulate(OscillatorParams(delta_d=-5e-6), 10).pi2)


def test_reset_restarts_from_the_initial_state(node_env):
    domain, collector, start = node_env
    ans = Answerer(collector)
    ans.hold_at = 8
    proc, log = start(max_periods=12, exit_when_done=True, answer_timeout=30.0,
                      x0=-0.5, v0=-1.0)
    ans.wait_held()
    client = collector.node.create_client(Trigger, "sim_node/reset")
    assert client.wait_for_service(10.0)
    res = call(collector, client.call_async(Trigger.Request()))
    assert res.success, res
    assert proc.wait(30) == 0, log.read_text()
    keys = [stamp_key(m.header.stamp) for m in ans.samples]
    assert len(keys) == 9 + 12 and keys[9] == (0, 0)
    got = xv(ans.samples)
    np.testing.assert_array_equal(got[9:18], got[:9])
    ref = simulate(OscillatorParams(delta_d=-5e-6), 12, x0=-0.5, v0=-1.0)
    np.testing.assert_array_equal(got[9:], ref.pi2)
    assert stamps(ans.samples)[-1] == pytest.approx(11 * OscillatorParams().period, abs=1e-9)


# ================================================== the rig: sensor stream and pulse
def test_stream_controller_position_only_sensor_and_pulse_through_the_node(node_env):
    """A controller that reads only oscillator/state (issue 15 §1): the simulator starts
    for it (wait_for_controller), sends the stream's sample at t = 0 with sample 0, and
    the stream is the sensor's (position only: velocity empty; effort [cos tau, sin tau]);
    the run with a force pulse is the core's pulse_step loop bit for bit."""
    from grazing_control.dynamics.simulation.actuation import pulse_step
    from grazing_control.plant.sensor import SensorModel

    domain, collector, start = node_env
    p = OscillatorParams(delta_d=-5e-6)
    T, n, delay, w, sigma = p.period, 12, 3.0, 0.5, 1e-4
    pub = collector.node.create_publisher(TwistStamped, "controller/velocity_correction",
                                          DATA_QOS)
    dvs = [2e-3 * ((k % 3) - 1) for k in range(n)]

    def on_state(msg):                 # answer sample k on the stream's sample at t_k
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        k = round(t / T)
        if abs(t - k * T) < 1e-6 and k < n:
            out = TwistStamped()
            out.header.stamp.sec, out.header.stamp.nanosec = cdr.stamp_parts(k * T)
            out.twist.linear.x = dvs[k]
            pub.publish(out)

    collector.node.create_subscription(JointState, "oscillator/state", on_state, DATA_QOS)
    proc, log = start(max_periods=n, exit_when_done=True, answer_timeout=10.0,
                      wait_for_controller=True, start_timeout=20.0, state_period=T / 200,
                      sensor_noise=sigma, sensor_velocity=False, sensor_seed=3,
                      actuation_delay=delay, pulse_width=w)
    assert proc.wait(60) == 0, log.read_text()
    text = log.read_text()
    assert "start_timeout" not in text and summary(text)["timeouts"] == "0", text
    # the ground truth on oscillator/pi2: the core's pulse loop with the answers
    dx = dv = 0.0
    ref = []
    for k in range(n):
        ref.append((p.x_ref + dx, p.v_ref + dv))
        seg = pulse_step(p, dx, dv, dvs[k], start=delay - w / 2, width=w)
        dx, dv = seg.dx, seg.dv
    np.testing.assert_array_equal(xv(collector.get("oscillator/pi2")), ref)
    # the stream: every grid sample from t = 0, position only, the phase reference
    m = n * 200 + 1                                      # t = 0 .. t_n, both included
    assert collector.wait_for(lambda: len(collector.get("oscillator/state")) == m, 5.0)
    states = collector.get("oscillator/state")
    t = stamps(states)
    np.testing.assert_allclose(t, np.arange(m) * T / 200, rtol=0, atol=1e-9)
    assert all(len(m.velocity) == 0 and len(m.position) == 1 for m in states)
    tau = np.array([math.atan2(m.effort[1], m.effort[0]) for m in states]) % (2 * math.pi)
    want = (p.tau2 + p.omega * t) % (2 * math.pi)
    assert np.abs(np.angle(np.exp(1j * (tau - want)))).max() < 1e-9
    # sample j is the true state (the engine with an exact sensor) + the sensor's draw j
    eng = Engine(settings(delta_d=-5e-6, state_period=T / 200, actuation_delay=delay,
                          pulse_width=w))
    true = eng.initial_states()
    for k in range(n):
        true += [e for e in eng.begin_period(dvs[k], delay) if e.kind == "state"]
        eng.end_period()
    e = SensorModel(noise=sigma, seed=3).draws(0, m)[:, 0] * sigma
    x = np.array([s.position[0] for s in states])
    np.testing.assert_allclose(x, [s.x for s in true] + e, rtol=0, atol=1e-12)


def test_a_pulse_through_the_first_order_actuator_is_the_cores_map_through_the_node(node_env):
    """actuator_bandwidth 3x the forcing frequency and a latency (issue 29 section 4):
    the samples on oscillator/pi2 are the core's 3-state map (dynamics.simulation.actuator.
    actuated_step, the force carried from period to period) bit for bit, with the
    node's answers acting through it."""
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.dynamics.simulation.actuator import Actuator, actuated_step

    domain, collector, start = node_env
    p = OscillatorParams(delta_d=-5e-6)
    T, n, delay, w = p.period, 10, 3.0, 0.1
    act = Actuator(1.0 / (3.0 * p.omega), 0.2)
    dvs = [2e-3 * ((k % 3) - 1) for k in range(n)]

    class Fixed(Answerer):
        def answer(self, msg, dv=0.0):
            k = round((msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9) / T)
            super().answer(msg, dvs[k] if k < n else 0.0)

    ans = Fixed(collector)
    proc, log = start(max_periods=n, exit_when_done=True, answer_timeout=30.0,
                      actuation_delay=delay, pulse_width=w, actuator_bandwidth=3.0 * p.omega,
                      actuator_latency=0.2)
    assert proc.wait(60) == 0, log.read_text()
    text = log.read_text()
    assert summary(text)["timeouts"] == "0" and "actuator_bandwidth=" in text, text
    z, ref = (0.0, 0.0, 0.0), []
    for k in range(n):
        ref.append((p.x_ref + z[0], p.v_ref + z[1]))
        *z, _imps = actuated_step(p, *z, dvs[k], start=pulse_start(T, delay, w), width=w,
                                  actuator=act)
    np.testing.assert_array_equal(xv(ans.samples), ref)


def test_stream_sample_writer_is_the_rclpy_layout():
    """rclpy decodes cdr.stream_sample's bytes to the stream's JointState (with and
    without velocity: the alignment of the effort differs)."""
    from rclpy.serialization import deserialize_message

    for v in (None, -1.25):
        data = cdr.stream_sample(3, 500, 0.5, v, 0.6, 0.8)
        msg = deserialize_message(data, JointState)
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == \
            (3, 500, "")
        assert (list(msg.name), list(msg.position), list(msg.velocity), list(msg.effort)) \
            == (["mass"], [0.5], [] if v is None else [v], [0.6, 0.8])


# ============================================================ miss-tolerant actuation
def test_read_answer_takes_the_prediction_from_linear_y():
    from rclpy.serialization import serialize_message
    from sim_node.messages import read_answer

    msg = TwistStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 7, 9
    msg.twist.linear.x, msg.twist.linear.y = 1.5e-3, math.nan
    key, dv, pred = read_answer(bytes(serialize_message(msg))[:68])
    assert (key, dv) == ((7, 9), 1.5e-3) and math.isnan(pred)
    msg.twist.linear.y = -2.5e-3
    assert read_answer(bytes(serialize_message(msg))[:68]) == ((7, 9), 1.5e-3, -2.5e-3)
    assert read_answer(cdr.twist_stamped(7, 9, 1.0, 0.5)) == ((7, 9), 1.0, 0.5)
    assert read_answer(b"\x00" * 10) is None


def test_lost_answers_are_replaced_by_their_predictions_through_the_node(node_env):
    """Issue 16 §3 through the node: lockstep, loss 0.05 (seed 7), the test as a
    controller that sends its prediction in twist.linear.y; the published Pi2 samples
    are the engine's lockstep loop with the same answers bit for bit (its spread about
    the orbit <= 1e-10, tests/test_plant_loops.py), every loss after the first
    controlled answer is counted as predicted."""
    from grazing_control.dynamics.design.gains import degenerate_c1
    from test_plant_loops import lossy_lockstep, predicting_controller

    domain, collector, start = node_env
    n, on, seed = 700, 100, 7
    c1 = degenerate_c1(OscillatorParams(delta_d=-5e-6), -1.0)
    ctl = predicting_controller(c1, -1.0, 0.0)
    pub = collector.node.create_publisher(TwistStamped, "controller/velocity_correction",
                                          DATA_QOS)
    count = [0]

    def on_sample(msg):
        k, count[0] = count[0], count[0] + 1
        out = TwistStamped()
        out.header.stamp = msg.header.stamp
        out.twist.linear.x, out.twist.linear.y = (
            ctl(msg.position[0], msg.velocity[0]) if k >= on else (0.0, math.nan))
        pub.publish(out)

    collector.node.create_subscription(JointState, "oscillator/pi2", on_sample, DATA_QOS)
    substituted = []
    collector.node.create_subscription(TwistStamped, "oscillator/substituted",
                                       substituted.append, DATA_QOS)
    proc, log = start(max_periods=n, exit_when_done=True, answer_timeout=10.0,
                      state_period=0.0, loss=0.05, seed=seed)
    assert proc.wait(60) == 0, log.read_text()
    got = xv(collector.get("oscillator/pi2"))
    ref, loop = lossy_lockstep("predict", n, on, 0.05, seed)
    np.testing.assert_array_equal(got, ref)
    s = summary(log.read_text())
    assert (s["lost"], s["predicted"]) == (str(loop.stats["lost"]),
                                           str(loop.stats["predicted"]))
    assert loop.stats["predicted"] > 20
    # each substitution published with its sample's stamp and the prediction that acted
    assert collector.wait_for(lambda: len(substituted) == loop.stats["predicted"], 5.0)
    ks = [round(seconds_from_stamp(m.header.stamp) / OscillatorParams().period)
          for m in substituted]
    assert ks == [k for k, _, _ in loop.sink.substitutions]
    assert [m.twist.linear.x for m in substituted] == [dv for _, _, dv in
                                                       loop.sink.substitutions]


def test_scheduling_options_warn_where_refused_and_bad_ones_stop_the_start(node_env):
    """thread_priority, cpu_affinity, lock_memory (ros.scheduling): applied or refused
    with a warning, never a crash; an invalid cpu_affinity is one line, status 2."""
    domain, collector, start = node_env
    proc, log = start(max_periods=3, exit_when_done=True, answer_timeout=0.05,
                      thread_priority=10, cpu_affinity="0,1", lock_memory=True)
    assert proc.wait(30) == 0, log.read_text()
    text = log.read_text()
    at = {}
    for option, applied in (("thread_priority=10", "SCHED_FIFO priority 10"),
                            ("cpu_affinity=[0, 1]", "CPU affinity [0, 1]"),
                            ("lock_memory", "memory locked")):
        assert applied in text or f"{option} not applied" in text, (option, text)
        at[option] = text.find(applied) if applied in text else text.find(option)
    # the priority once the start-up is done (its CPU work not under SCHED_FIFO): after
    # the affinity and the memory lock, with the start (ros.scheduling.raise_node_priority)
    assert at["cpu_affinity=[0, 1]"] < at["thread_priority=10"], text
    assert at["lock_memory"] < at["thread_priority=10"], text
    assert "Traceback" not in text
    cmd, env = sim_cmd(domain)
    bad = subprocess.run(cmd + ["-p", "cpu_affinity:=zero"], env=env, capture_output=True,
                         text=True, timeout=30)
    lines = [ln for ln in (bad.stdout + bad.stderr).splitlines() if ln.strip()]
    assert bad.returncode == 2 and len(lines) == 1, lines
    assert "cpu_affinity='zero' is invalid" in lines[0]


def test_a_controller_designed_for_another_delay_is_refused_and_a_restart_accepted(tmp_path):
    """The gains are designed for one actuation delay (docs/theory_delay.md): a controller
    whose parameter record says actuation_delay=3.0 and a simulator applying 0.0 (the
    launch file once gave the simulator no delay) make the simulator refuse to start,
    naming both and the fix, with status 1; the same delay on both starts the scene,
    and a simulator restarted against the same controller runs too."""
    import time

    root = Path(__file__).resolve().parents[1]
    for sim_delay, expect in ((0.0, 1), (3.0, 0)):
        domain = new_domain()
        procs = []
        try:
            procs.append(launcher.start_node(
                launcher.CONTROLLER_MODULE, [root / "config" / "controller.yaml"],
                {"actuation_delay": 3.0}, domain_id=domain, log=tmp_path / "ctl.log"))
            sim = launcher.start_node(
                launcher.SIM_MODULE, [STUDY], {"max_periods": 30, "exit_when_done": True,
                                               "actuation_delay": sim_delay},
                domain_id=domain, log=tmp_path / f"sim{sim_delay}.log")
            procs.append(sim)
            assert sim.wait(60) == expect
            text = (tmp_path / f"sim{sim_delay}.log").read_text()
            if expect:
                assert ("not starting: /controller_node was designed for actuation_delay=3.0, "
                        "this simulator applies actuation_delay=0.0") in text, text
                assert "-p actuation_delay:=3.0" in text and "Traceback" not in text
            else:
                assert "summary: periods=30 " in text, text
                # a simulator restarted 1 s after the first exited (issue 27 §2): the
                # first left the graph on exit, so the controller accepts the second
                # (it counted the exited one's publisher for the 20 s of its lease:
                # "2 publishers on /oscillator/pi2 ... not isolated", status 1); the
                # second lacks a recorder and says which peers it started without
                time.sleep(1.0)
                again = launcher.start_node(
                    launcher.SIM_MODULE, [STUDY], {
                        "max_periods": 30, "exit_when_done": True, "actuation_delay": 3.0,
                        "wait_for_recorder": True, "wait_for_subscribers": 1,
                        "start_timeout": 2.0}, domain_id=domain, log=tmp_path / "again.log")
                procs.append(again)
                assert again.wait(60) == 0, (tmp_path / "again.log").read_text()
                text = (tmp_path / "again.log").read_text()
                assert "summary: periods=30 " in text, text
                line = re.search(r"starting after start_timeout=\d+\.\d s without: the "
                                 r"recorder's True on /recorder/ready .*", text)
                assert line, text
                # the peers it started without, each named: the recorder's subscribers,
                # the controller's when it had not discovered this node in the 2 s (1 of
                # about 15 runs under load: "0 subscriber(s) of 2"), and the controller's
                # own ends when its report came (its answers reach this node, not the
                # recorder the test lacks)
                assert re.search(r"the controller and 1 recorder\(s\) subscribed to "
                                 r"/oscillator/pi2 or /oscillator/state \([01] subscriber"
                                 r"\(s\) of 2\)", line.group(0)), line.group(0)
                assert "a subscriber of /oscillator/impact (0 of 1)" in line.group(0)
                assert procs[0].poll() is None, (tmp_path / "ctl.log").read_text()
                assert "not isolated" not in (tmp_path / "ctl.log").read_text()
        finally:
            launcher.stop_nodes(procs)


def test_the_design_delay_is_read_from_the_controller_parameter_file(tmp_path):
    """launcher.design_delay: what `grazing run` and the launch file give the simulator."""
    f = tmp_path / "d6.yaml"
    f.write_text("/**:\n  ros__parameters:\n    c1: -1.0\n    c2: -1.0\n"
                 "    actuation_delay: 6.0\n")
    assert launcher.design_delay(str(f)) == 6.0
    f.write_text("/**:\n  ros__parameters:\n    c1: -1.0\n")
    assert launcher.design_delay(str(f)) is None
    assert launcher.design_delay(str(tmp_path / "missing.yaml")) is None
    assert launcher.design_delay({"actuation_delay": 2}) == 2.0


def test_the_scene_guard_keeps_every_latched_record_not_only_the_last():
    """The start handshake's record condition (issue 27 §1: scenes waited their whole
    start_timeout). The simulator publishes its own parameter record before its guard
    subscribes; the guard's reader then gets that record and the controller's from the
    writers' histories. At depth 1 the one delivered last replaced the other before the
    executor took it (a loaded machine: the executor busy), so the controller's record
    was read by the middleware and never by the guard. Here the executor takes nothing
    until both records are in, as under load: the guard must still see its controller,
    and a guard of another scene names every record it read."""
    import time

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from grazing_control.ros.common import publish_parameter_record
    from grazing_control.ros.scene import SceneGuard

    context = Context()
    rclpy.init(context=context, domain_id=new_domain())
    try:
        def node(name, **params):
            return rclpy.create_node(
                name, context=context, automatically_declare_parameters_from_overrides=True,
                parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])

        publish_parameter_record(node("controller_node", scene="T", c2=-1.0))
        sim = node("sim_node", scene="T")
        publish_parameter_record(sim)          # as sim_node: its own record first
        guard, other = SceneGuard(sim, "T"), SceneGuard(sim, "U")
        record = next(s for s in sim.subscriptions if s.topic_name.endswith("parameters"))
        end = time.monotonic() + 20
        while record.get_publisher_count() < 2 and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(0.5)                        # both histories delivered, nothing taken
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(sim)
        while len(other.seen) < 2 and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.1)
        assert guard.own_controller and guard.missing_controller() is None, guard.seen
        assert other.missing_controller() == (
            "the parameter record of a controller of this scene (scene U) on "
            "/grazing/parameters; records read: /controller_node (scene T), "
            "/sim_node (scene T)")
    finally:
        context.try_shutdown()

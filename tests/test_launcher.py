"""launcher: scene isolation, failing fast, Ctrl-C, and its arguments (real processes).

Every scene here is cheap (a few hundred lockstep periods). Two scenes started at once
must give two clean bags; two scenes forced onto one domain must both fail loudly.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter

import numpy as np
import pytest

from grazing_control.ros import launcher
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros.recording import read_messages
from grazing_control.dynamics.simulation.simulate import simulate
from test_closed_loop import CONTROLLER, ROOT, STUDY, new_domain

GRAZING = [sys.executable, "-c", "import sys; from grazing_control.cli import main; "
           "sys.exit(main())"]


def grazing(*args, **kw):
    return subprocess.Popen(GRAZING + list(args), env=launcher.node_env(), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)


def test_the_controller_takes_how_the_plant_acts_in_a_plain_scene():
    """A pulse (and its actuator) given to the simulator alone reaches the controller,
    whose estimator and prediction model it (a stream controller modelled a kick where
    the plant pushed for 0.1); its own value wins; a model or rig file's come with its
    gains and are not overridden."""
    from grazing_control.ros import controller_node, scene_nodes

    assert scene_nodes.ACTUATION_KEYS == controller_node.PULSE_KEYS
    plant = {"pulse_width": 0.1, "force_limit": 2.0, "actuator_bandwidth": 3.0}
    over = scene_nodes.scene_overrides(None, sim_overrides=plant)["controller_node"]
    assert {k: over[k] for k in plant} == plant and "actuator_latency" not in over
    over = scene_nodes.scene_overrides(None, sim_overrides=plant,
                                       controller_overrides={"pulse_width": 0.2})
    assert over["controller_node"]["pulse_width"] == 0.2
    assert over["sim_node"]["pulse_width"] == 0.1
    for files in ({"model": "config/models/two_mass_scene.yaml"},
                  {"rig": "config/rigs/lab_20hz.yaml"}):
        over = scene_nodes.scene_overrides(None, sim_overrides=plant, **files)
        assert not set(plant) & set(over["controller_node"]), files


def test_a_failed_scenes_reason_quotes_the_nodes_last_error(tmp_path):
    """With --log-dir a node's output is not on the terminal: the reason line quotes its
    last error (a refused parameter with its valid range), not only its exit status."""
    log = tmp_path / "sim_node.log"
    log.write_text("[INFO] [1.0] [sim_node]: starting\n"
                   "[ERROR] [2.0] [sim_node]: time_scale=-3.0 is invalid: valid range is "
                   "time_scale > 0\n[INFO] [3.0] [sim_node]: bye\n")
    quiet = tmp_path / "controller_node.log"
    quiet.write_text("[INFO] [1.0] [controller_node]: fine\n")
    res = launcher.RunResult(sim=2, controller=1, recorder=None, bag_dir=None, wall=0.3,
                             logs={"sim_node": str(log), "controller_node": str(quiet)})
    assert launcher.failure_reason(res) == (
        "sim_node exited with status 2 (time_scale=-3.0 is invalid: valid range is "
        "time_scale > 0); controller_node exited with status 1")
    res.logs = {}                           # the nodes' output on the terminal
    assert launcher.failure_reason(res, early=["controller_node"]) == (   # the refusal first
        "sim_node exited with status 2; controller_node exited early with status 1")


def test_a_node_refused_at_start_leads_the_reason_before_what_followed_from_it():
    """A simulator that refused a parameter (status 2) never published its tail, so the
    recording lost it too: the reason names the refusal first (it named the recording's
    loss first, and the refusal after it, without the refused value when the log was the
    terminal's). A simulator that wrote its own reason (a feasibility refusal) keeps it."""
    res = launcher.RunResult(sim=2, controller=0, recorder=1, bag_dir=None, wall=6.9,
                             lost="/sim_node's tail (no published record)")
    assert launcher.failure_reason(res) == (
        "sim_node exited with status 2; the recording lost messages: /sim_node's tail (no "
        "published record); recorder_node exited with status 1")
    res.sim_verdict = {"reason": "feasibility: refused"}
    assert launcher.failure_reason(res).startswith("sim_node: feasibility: refused; the "
                                                   "recording lost"), res


def test_a_node_killed_in_the_scene_leads_the_reason_before_the_recordings_loss():
    """A controller killed mid-scene (SIGKILL) never published its tail: the reason names
    the kill first, then the loss and the recorder's failure that followed from it (it
    named the loss first, 2026-12-01, by hand)."""
    res = launcher.RunResult(sim=0, controller=-9, recorder=1, bag_dir=None, wall=6.1,
                             lost="/controller_node's tail (no published record)")
    assert launcher.failure_reason(res, early=["controller_node"]) == (
        "controller_node exited early with status -9; the recording lost messages: "
        "/controller_node's tail (no published record); recorder_node exited with status 1")


def test_a_node_that_left_before_the_simulator_fails_the_scene_whatever_its_status():
    """A controller stopped by a SIGTERM of its own exits 0, and the simulator, stopped
    with it, exits 0 too: the scene is not ok (status 1), and the reason names the node
    that left early."""
    res = launcher.RunResult(sim=0, controller=0, recorder=0, bag_dir=None, wall=4.0)
    assert res.ok and res.exit_code == 0
    res.early = ("controller_node",)
    assert not res.ok and res.exit_code == 1 and str(res).startswith("scene failed in 4.0 s")
    assert launcher.failure_reason(res, res.early) == (
        "controller_node exited early with status 0")


def test_the_last_line_says_the_simulators_numbers_misses_and_pauses_included():
    """The scene's line carries what the simulator's summary says (its verdict): the
    periods and their pace, the corrections applied, missed and late, and the plant's
    pauses where it paused; nothing where there is no summary (a node killed)."""
    line = ("summary: periods=3000 t=28274.3 impacts=3001 applied=1999 late=2 missed=3 "
            "lost=0 predicted=3 timeouts=0 ignored=0 malformed=0 wall=28.300s rate=106.1 "
            "periods/s paused=8 paused_ms=12.345 longest_pause_ms=3.020 latency_ms p50=-1.3")
    res = launcher.RunResult(sim=0, controller=0, recorder=None, bag_dir=None, wall=30.04,
                             sim_verdict={"summary": line})
    assert str(res).startswith(
        "scene finished in 30.0 s (3000 periods at 106.1 periods/s, 1999 applied, 3 missed,"
        " 2 late, the plant's clock paused 8 times (12.345 ms in all)): exit status "
        "sim_node=0 controller_node=0")
    res.sim_verdict = {"summary": line.split(" paused=")[0]}     # a scene that never paused
    assert "(3000 periods at 106.1 periods/s, 1999 applied, 3 missed, 2 late): " in str(res)
    for verdict in (None, {}, {"summary": None}, {"summary": "garbage= x"}):
        res.sim_verdict = verdict
        assert str(res).startswith("scene finished in 30.0 s: exit status sim_node=0")


# ------------------------------------------------------------------------ domains
def test_claimed_domains_are_distinct_and_not_in_use():
    import rclpy
    from rclpy.context import Context

    held = [launcher.claim_domain() for _ in range(3)]
    ids = [d for d, _ in held]
    assert len(set(ids)) == 3 and all(1 <= d <= launcher.MAX_DOMAIN_ID for d in ids)
    # a domain with a DDS participant on this host is not free
    context = Context()
    rclpy.init(context=context, domain_id=ids[0])
    node = rclpy.create_node("occupant", context=context)
    try:
        held[0][1].close()                    # released, but a participant uses it
        assert ids[0] not in {launcher.claim_domain(exclude=ids[1:])[0] for _ in range(1)}
        assert not launcher._discovery_port_free(ids[0])
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        for _, lock in held[1:]:
            lock.close()


@pytest.mark.parametrize("args, text", [
    (["--domain-id", "-1"], "--domain-id: '-1' is invalid: valid range is an integer 0..232"),
    (["--domain-id", "233"], "valid range is an integer 0..232"),
    (["--timeout", "nan"], "--timeout: 'nan' is invalid"),
    (["--timeout", "0"], "--timeout: '0' is invalid"),
])
def test_run_refuses_bad_domain_and_timeout(args, text):
    proc = grazing("run", "--periods", "5", *args)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and text in err and len(err.strip().splitlines()) == 1, err


# ---------------------------------------------------------------------- isolation
def scene_is_clean(bag, n, on):
    """Every sample once, on its grid, equal to the core's; every answer once."""
    counts = Counter()
    pi2, stamps = [], []
    for m in read_messages(bag):
        counts[m.topic] += 1
        if m.topic == "/oscillator/pi2":
            pi2.append((m.message.position[0], m.message.velocity[0]))
            stamps.append(m.message.header.stamp.sec * 10**9 + m.message.header.stamp.nanosec)
    p = OscillatorParams(delta_d=-5e-6)
    ref = simulate(p, n, gains=Gains(degenerate_c1(p, -1.0), -1.0), control_after=on)
    assert counts["/oscillator/pi2"] == n and counts["/controller/velocity_correction"] == n
    np.testing.assert_array_equal(stamps, [round(k * p.period * 1e9) for k in range(n)])
    np.testing.assert_allclose(pi2, ref.pi2, rtol=1e-9, atol=1e-12)


def test_two_scenes_at_once_give_two_clean_bags(tmp_path):
    n, on = 200, 100
    procs = [grazing("run", "--periods", str(n), "--enable-after", str(on), "--bag",
                     str(tmp_path / f"bag{i}"), "--timeout", "120") for i in range(2)]
    outs = [p.communicate(timeout=180) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, out + err
    domains = {out.split("ROS_DOMAIN_ID=")[1].split(";")[0].split()[0] for out, _ in outs}
    assert len(domains) == 2, outs
    for i in range(2):
        scene_is_clean(tmp_path / f"bag{i}", n, on)


def test_two_scenes_on_one_domain_never_both_succeed(tmp_path):
    """Forced onto one domain, the simulators see each other's simulator or controller
    and the controllers each other's simulator: the node that sees the other scene
    refuses (or stops) with an error and a nonzero status; a scene that finishes had no
    foreign answer (ignored=0) and lost none (applied=3000)."""
    domain = str(new_domain())
    procs = [grazing("run", "--periods", "3000", "--domain-id", domain, "--sim-param",
                     "state_period:=0.0", "--timeout", "120", "--log-dir",
                     str(tmp_path / f"logs{i}")) for i in range(2)]
    for p in procs:
        p.communicate(timeout=180)
    logs = [(tmp_path / f"logs{i}" / "sim_node.log").read_text() for i in range(2)]
    ctl = [(tmp_path / f"logs{i}" / "controller_node.log").read_text() for i in range(2)]
    failed = [i for i, p in enumerate(procs) if p.returncode != 0]
    assert failed, logs
    for i in failed:
        assert any("[ERROR]" in text and "the scene is not isolated" in text
                   for text in (logs[i], ctl[i])), (logs[i], ctl[i])
    for i in set(range(2)) - set(failed):
        assert "ignored=0 " in logs[i] and "applied=3000 " in logs[i], logs[i]


# ----------------------------------------------------------------- failing, Ctrl-C
def test_a_node_refusing_to_start_stops_the_scene_at_once(tmp_path):
    res = launcher.run(STUDY, CONTROLLER, tmp_path / "bag", 50, domain_id=new_domain(),
                       controller_overrides={"saturation": -1.0}, log_dir=tmp_path)
    assert res.controller == 2 and res.sim is not None and not res.ok
    # the simulator was stopped by the launcher's SIGTERM, not left to its start_timeout:
    # -15 while Python still imports, 0 once run_node's handlers are in (quietly while
    # it initialises, with an "(interrupted)" summary once the node exists)
    log = (tmp_path / "sim_node.log").read_text()
    assert res.sim in (-15, 0), (res.sim, log)
    assert "start_timeout" not in log and "periods=1" not in log and res.wall < 10.0
    print(f"scene stopped after {res.wall:.1f} s")


@pytest.mark.parametrize("delay", [0.0, 0.3, 1.0])
def test_ctrl_c_early_in_grazing_run_is_quiet(tmp_path, delay):
    """The terminal's Ctrl-C (SIGINT to the whole foreground group) while the nodes are
    still starting (``delay`` s after the launcher started them): status 130 and no
    traceback, on the terminal or in a node's log. (Before the launcher runs, while the
    `grazing` process itself imports its modules, Python's own traceback remains.)"""
    logs = tmp_path / "logs"
    proc = grazing("run", "--periods", "100", "--bag", str(tmp_path / "bag"), "--log-dir",
                   str(logs), start_new_session=True)
    end = time.monotonic() + 60
    while not (logs / "sim_node.log").exists() and time.monotonic() < end:
        time.sleep(0.005)                         # the launcher has started the nodes
    time.sleep(delay)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, out + err
    texts = [out, err] + [f.read_text() for f in logs.glob("*.log")]
    assert not any("Traceback" in t or "Fatal Python error" in t for t in texts), texts


@pytest.mark.parametrize("node", ["recorder_node", "controller_node", "sim_node"])
def test_a_ctrl_c_while_a_node_starts_stops_that_node_too(tmp_path, monkeypatch, node):
    """The Ctrl-C that lands after a node process exists but before its handle is the
    launcher's (inside ``subprocess.Popen``'s wait for the exec, or the zygote's reply):
    held until the handle is had, then acted on: that node stopped too, and nothing
    started after it. Before, it was left running (a Ctrl-C right at the start, about
    once in a few hundred; the suite's no_process_outlives_its_test caught it)."""
    made = {}
    real = launcher._spawn_node
    names = {launcher.RECORDER_MODULE: "recorder_node", launcher.SIM_MODULE: "sim_node",
             launcher.CONTROLLER_MODULE: "controller_node"}

    def spawned_then_interrupted(command, env, streams):
        proc = real(command, env, streams)
        name = names[command[3]]
        made[name] = proc
        if name == node:
            os.kill(os.getpid(), signal.SIGINT)     # the terminal's Ctrl-C, right now
            time.sleep(0.05)                         # (delivered before the handle is back)
        return proc

    monkeypatch.setattr(launcher, "_spawn_node", spawned_then_interrupted)
    res = launcher.run(STUDY, CONTROLLER, tmp_path / "bag", 50, log_dir=tmp_path / "logs",
                       timeout=60)
    assert res.interrupted and node in made
    assert all(p.poll() is not None for p in made.values()), \
        {n: p.poll() for n, p in made.items()}
    order = ["recorder_node", "controller_node", "sim_node"]
    assert not any(n in made for n in order[order.index(node) + 1:])    # none after it


def test_repeated_recorded_scenes_lose_no_correction(tmp_path):
    """The start race: the simulator starts only once the recorder matched every topic
    (recorder/ready), the corrections are transient local, and the recorder checks the
    sequence numbers (require_complete): every run records every sample and answer."""
    n = 40
    for i in range(3):
        bag = tmp_path / f"bag{i}"
        res = launcher.run(STUDY, CONTROLLER, bag, n, controller_overrides={"enable_after": 20},
                           log_dir=tmp_path / f"logs{i}", timeout=120)
        assert res.ok, (res, (tmp_path / f"logs{i}" / "recorder_node.log").read_text())
        counts = Counter(m.topic for m in read_messages(bag))
        assert counts["/oscillator/pi2"] == n and counts["/controller/velocity_correction"] == n
        assert "missed" not in (tmp_path / f"logs{i}" / "recorder_node.log").read_text()
        assert launcher.recorded_status(bag) == 0      # the closed record
        # each node said what it published (issue 27): the bag holds all of it
        assert counts["/grazing/published"] == 2 and res.lost == ""
        assert "no published record" not in (tmp_path / f"logs{i}" /
                                              "recorder_node.log").read_text()


def test_the_recorders_closed_record_is_read_from_the_bag(tmp_path):
    """A bag's metadata.yaml carries the recorder's status (written last, on close): a
    recorder killed after closing is judged by it; no record (killed before closing, or
    not a bag) gives None, and the exit status counts."""
    import yaml

    assert launcher.recorded_status(tmp_path) is None
    for status in (0, 1):
        info = {"rosbag2_bagfile_information": {"custom_data": {"recorder_status": str(status)}}}
        (tmp_path / "metadata.yaml").write_text(yaml.safe_dump(info))
        assert launcher.recorded_status(tmp_path) == status
    (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information: {custom_data: null}")
    assert launcher.recorded_status(tmp_path) is None
    (tmp_path / "metadata.yaml").write_text("{{{")
    assert launcher.recorded_status(tmp_path) is None


def test_the_nodes_get_the_packages_fastdds_profile_unless_one_is_given(monkeypatch):
    """Issue 30: a node waits at exit until its messages are acknowledged, and a Fast DDS
    reader acknowledges when a heartbeat asks (default every 3 s): 2.2 s of a scene's
    end. The launcher gives the nodes the package's profile (a 5 ms heartbeat: a lockstep
    simulator waits for a substitution's acknowledgement, sim_node/messages.py) under
    both of Fast DDS's names for it, and leaves a profile the user named alone."""
    import xml.etree.ElementTree as ET

    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        monkeypatch.delenv(name, raising=False)
    env = launcher.node_env()
    profile = str(launcher.FASTDDS_PROFILE)
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == env["FASTDDS_DEFAULT_PROFILES_FILE"] == profile
    ns = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    writer = ET.parse(profile).getroot().find("p:data_writer", ns)
    assert writer.get("is_default_profile") == "true"
    for name in ("heartbeatPeriod", "nackSupressionDuration"):
        duration = writer.find(f"p:times/p:{name}", ns)
        assert (duration.find("p:sec", ns).text, duration.find("p:nanosec", ns).text) == ("0", "5000000")
    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        monkeypatch.setenv(name, "/elsewhere/profile.xml")
        env = launcher.node_env()
        assert env[name] == "/elsewhere/profile.xml"
        assert all(env.get(n) in (None, "/elsewhere/profile.xml") for n in (
            "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"))
        monkeypatch.delenv(name)


#: A participant and a publisher under the profile in FASTRTPS_DEFAULT_PROFILES_FILE.
_PARTICIPANT = """
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("profile_check")
node.create_publisher(String, "profile_check", 10)
node.destroy_node()
rclpy.shutdown()
print("made")
"""


def test_fast_dds_reads_the_nodes_profile_without_an_error(tmp_path):
    """Fast DDS drops a profile it cannot parse, with an XMLPARSER error on its console
    (standard output) and nothing else: a misspelt element would silently give the nodes Fast DDS's defaults.
    The package's profile is read cleanly; the same profile with one element misspelt
    (nackSuppressionDuration) is not, which is what this check would see."""
    def console_of(profile):
        env = launcher.node_env(domain_id=new_domain())
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(profile)
        done = subprocess.run([sys.executable, "-c", _PARTICIPANT], env=env, capture_output=True,
                              text=True, timeout=60)
        assert done.returncode == 0 and "made" in done.stdout, done.stderr
        return done.stdout + done.stderr

    assert "XMLPARSER" not in console_of(launcher.FASTDDS_PROFILE)
    misspelt = tmp_path / "misspelt.xml"
    misspelt.write_text(launcher.FASTDDS_PROFILE.read_text().replace(
        "nackSupressionDuration>", "nackSuppressionDuration>"))
    assert "XMLPARSER" in console_of(misspelt)


def test_this_process_gets_the_nodes_profile_unless_one_is_given(monkeypatch):
    """use_profile_here: a replay's session and a test's nodes get the nodes' profile
    (before their process's first participant); a profile the user named stays."""
    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        monkeypatch.delenv(name, raising=False)
    launcher.use_profile_here()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(launcher.FASTDDS_PROFILE)
    assert os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] == str(launcher.FASTDDS_PROFILE)
    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        monkeypatch.delenv(name)
    monkeypatch.setenv("FASTDDS_DEFAULT_PROFILES_FILE", "/elsewhere/profile.xml")
    launcher.use_profile_here()
    assert os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] == "/elsewhere/profile.xml"
    assert "FASTRTPS_DEFAULT_PROFILES_FILE" not in os.environ


def _processes_mentioning(text: str) -> list:
    """PIDs of live processes whose command line contains ``text``."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/cmdline", "rb") as f:
                    if text.encode() in f.read():
                        found.append(int(entry))
            except OSError:
                pass
    return found


def _nodes_of_launcher(pid: int) -> list:
    """(PID, command line) of the live processes started by the launcher ``pid``: those
    whose environment at exec holds GRAZING_LAUNCHER_PID=pid (launcher.py sets it for
    every node it starts; /proc/N/environ keeps it after the bootstrap pops it)."""
    mark = f"GRAZING_LAUNCHER_PID={pid}".encode()
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/environ", "rb") as f:
                    if mark in f.read().split(b"\0"):
                        with open(f"/proc/{entry}/cmdline", "rb") as c:
                            found.append((int(entry), c.read().replace(b"\0", b" ")[:160]))
            except OSError:
                pass
    return found


def test_nodes_stop_and_the_bag_closes_when_the_launcher_is_killed(tmp_path):
    """SIGKILL to `grazing run` (no chance to stop its nodes): every node gets SIGTERM from
    the kernel (PR_SET_PDEATHSIG, set by the bootstrap after exec), ends, and the recorder
    closes its bag (metadata.yaml written). Every node the launcher started is waited for,
    not only the recorder (a simulator still ending at the test's end was left to the
    teardown's cleanup once, on a slow host)."""
    bag = tmp_path / "bag"
    proc = grazing("run", "--periods", "1000000", "--bag", str(bag), "--log-dir",
                   str(tmp_path / "logs"), start_new_session=True)
    end = time.monotonic() + 60
    while not list(bag.glob("*.mcap")) and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(1.0)
    assert _processes_mentioning(str(bag)), "the recorder is not running"
    assert len(_nodes_of_launcher(proc.pid)) == 3, _nodes_of_launcher(proc.pid)
    proc.kill()
    proc.communicate(timeout=30)
    end = time.monotonic() + 20
    while _nodes_of_launcher(proc.pid) and time.monotonic() < end:
        time.sleep(0.1)
    assert not _nodes_of_launcher(proc.pid)
    assert not _processes_mentioning(str(bag))
    assert (bag / "metadata.yaml").is_file()


# ------------------------------------------------------- one source for the node set
def test_grazing_run_and_the_launch_file_take_the_nodes_from_one_description(tmp_path,
                                                                              monkeypatch):
    """`grazing run` starts exactly the nodes and overrides of scene_nodes.scene_overrides
    (captured instead of started), and the launch file builds its nodes from the same
    function with no parameter of its own beyond launch's (use_sim_time): the two cannot
    drift apart again (they had: the design delay, the token, the failure handling)."""
    import ast

    from grazing_control.ros import scene_nodes

    started = []

    class Done:
        returncode = 0

        def poll(self):
            return 0

        def wait(self, timeout=None):
            return 0

    def fake_start(module, params, overrides, **kw):
        started.append((module, dict(overrides)))
        return Done()

    monkeypatch.setattr(launcher, "start_node", fake_start)
    monkeypatch.setattr(launcher, "stop_nodes", lambda procs, grace=15.0: None)
    monkeypatch.setattr(scene_nodes, "new_token", lambda: "tok")
    design = tmp_path / "d6.yaml"
    design.write_text("/**:\n  ros__parameters:\n    c1: -1.0\n    c2: -1.0\n"
                      "    actuation_delay: 6.0\n")
    res = launcher.run(STUDY, design, tmp_path / "bag", 50, delta_d=-9e-6, enable_after=10,
                       domain_id=new_domain(), live=0)
    assert res.sim == res.controller == res.recorder == res.live == 0
    want = scene_nodes.scene_overrides(design, periods=50, delta_d=-9e-6, enable_after=10,
                                       bag=tmp_path / "bag", token="tok", live=0)
    modules = {"sim_node": launcher.SIM_MODULE, "controller_node": launcher.CONTROLLER_MODULE,
               "recorder_node": launcher.RECORDER_MODULE, "live_node": launcher.LIVE_MODULE}
    # grazing run alone adds the simulator's verdict_file (its reason for grazing run's
    # JSON, issue 27 §1): ros2 launch reports the exit statuses itself
    verdict = started[[m for m, _ in started].index(launcher.SIM_MODULE)][1].pop("verdict_file")
    assert verdict.endswith("sim_node.verdict.json")
    assert started == [(modules[n], want[n]) for n in scene_nodes.NODES]
    assert want["live_node"] == {"port": 0}
    assert want["sim_node"]["actuation_delay"] == 6.0 and want["controller_node"]["scene"] \
        == want["sim_node"]["scene"] == "tok"
    # the launch file: nodes from scene_overrides over NODES, no parameter names of its own
    source = (ROOT / "launch" / "grazing_control.launch.py").read_text()
    tree = ast.parse(source)
    calls = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call)
             and isinstance(n.func, ast.Name)}
    assert {"scene_overrides", "Node"} <= calls
    literals = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
                and isinstance(n.value, str)}
    arguments = {n.args[0].value for n in ast.walk(tree) if isinstance(n, ast.Call)
                 and getattr(n.func, "id", "") == "DeclareLaunchArgument"}
    assert {"delta_d", "max_periods", "enable_after", "bag", "controller_params",
            "live"} <= arguments          # live:= as grazing run --live (issue 27 §2)
    every = set().union(*(set(v) for v in want.values() if v))
    assert not (every & (literals - arguments)), every & (literals - arguments)


# ------------------------------------------------------------ the real launch file
#: Two scenes of launch/grazing_control.launch.py included in one LaunchService under
#: the namespaces a and b, each recording (argv: the output folder, periods).
TWO_SCENES = """
import os, sys
from launch import LaunchDescription, LaunchService
from launch.actions import GroupAction, IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch_ros.actions import PushRosNamespace
out, periods, src = sys.argv[1], sys.argv[2], sys.argv[3]
ls = LaunchService()
ls.include_launch_description(LaunchDescription([GroupAction([
    PushRosNamespace(ns), IncludeLaunchDescription(PythonLaunchDescriptionSource(src),
        launch_arguments={"max_periods": periods, "bag": os.path.join(out, ns)}.items())])
    for ns in ("a", "b")]))
print("launch status", ls.run(), flush=True)
"""


def _ament_prefix(root) -> str:
    """A minimal ament prefix of this checkout: the package's marker, share/ (config and
    launch linked to the source tree) and lib/grazing_control/ (the console scripts)."""
    from console_scripts import script

    (root / "share/ament_index/resource_index/packages").mkdir(parents=True)
    (root / "share/ament_index/resource_index/packages/grazing_control").touch()
    (root / "share/grazing_control").mkdir()
    for folder in ("config", "launch"):
        (root / "share/grazing_control" / folder).symlink_to(ROOT / folder)
    (root / "lib/grazing_control").mkdir(parents=True)
    for name in ("sim_node", "controller_node", "recorder_node", "live_node"):
        (root / "lib/grazing_control" / name).symlink_to(script(name))
    return str(root)


def test_two_scenes_included_in_one_launch_both_start_at_once(tmp_path):
    """ros2 launch with the launch file included twice (namespaces a and b, bags): both
    scenes start when their peers are matched, neither waits its start_timeout (scene a
    did, 3 of 3 runs, issue 27 §2: the simulator's depth-1 reader of the parameter
    records lost its controller's record), and each bag holds its scene. Needs launch
    and launch_ros (a ROS install, or docs/ros_build.md §4)."""
    pytest.importorskip("launch_ros", reason="launch_ros is not installed (no ROS install; "
                        "docs/ros_build.md §4 installs it from source)")
    env = dict(launcher.node_env(new_domain()))
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(filter(None, [
        _ament_prefix(tmp_path / "prefix"), env.get("AMENT_PREFIX_PATH")]))
    done = subprocess.run([sys.executable, "-c", TWO_SCENES, str(tmp_path), "40",
                           str(ROOT / "launch" / "grazing_control.launch.py")], env=env,
                          capture_output=True, text=True, timeout=240)
    out = done.stdout + done.stderr
    assert "launch status 0" in out, out[-4000:]
    assert "start_timeout" not in out and out.count("start conditions met after") == 2, out
    for ns in ("a", "b"):
        counts = Counter(m.topic for m in read_messages(tmp_path / ns))
        assert counts[f"/{ns}/oscillator/pi2"] == 40, (ns, counts)
        assert counts[f"/{ns}/controller/velocity_correction"] == 40, (ns, counts)
def test_grazing_run_fails_naming_the_messages_its_recording_lost(tmp_path, monkeypatch,
                                                                  capsys):
    """Issue 27: the recorder lost the last corrections of a scene and `grazing run` said
    ok. Here the recorder (tests/lossy_recorder.py: the package's recorder_node, which
    drops every correction after the 40th as if it had been stopped before taking them)
    records a real scene; the controller's published record says how many it published,
    so the recorder's closed record names the tail it lacks, the run fails and says what
    was lost, and `grazing analyze` names it as a problem."""
    import json

    from grazing_control import cli
    from grazing_control.recordings.analyze import analyze

    monkeypatch.setattr(launcher, "RECORDER_MODULE", "lossy_recorder")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]))
    bag, logs = tmp_path / "bag", tmp_path / "logs"
    code = cli.main(["run", "--periods", "50", "--enable-after", "20", "--bag", str(bag),
                     "--log-dir", str(logs), "--timeout", "120", "--json"])
    out = capsys.readouterr()
    summary = json.loads(out.out)
    answered = Counter(m.topic for m in read_messages(bag))["/controller/velocity_correction"]
    assert answered == 40
    lost = f"/controller/velocity_correction {50 - 40}"     # samples 0..49 answered
    assert code == 1 and not summary["ok"] and summary["lost"] == lost, summary
    assert summary["recorder"] == 1 and summary["sim"] == summary["controller"] == 0
    assert f"the recording lost messages: {lost}" in summary["summary"]
    assert f"missed: {lost}" in (logs / "recorder_node.log").read_text()
    problems = analyze([bag], None, figures=False)["bags"][0]["problems"]
    assert any("10 of the 50 messages controller_node published are not in the bag" in p
               for p in problems), problems


def test_the_nodes_get_one_blas_thread_unless_one_is_given(monkeypatch):
    """A node's matrices are small; OpenBLAS's thread pool spinning beside the other
    processes of a scene cost more than the work on a loaded 2-core machine."""
    for name in launcher.BLAS_THREADS:
        monkeypatch.delenv(name, raising=False)
    env = launcher.node_env()
    assert all(env[name] == "1" for name in launcher.BLAS_THREADS)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")
    assert launcher.node_env()["OPENBLAS_NUM_THREADS"] == "4"


def test_a_controller_given_its_own_rig_or_model_file_keeps_it():
    """A model-error scene: `grazing run --rig PLANT --controller-param rig_file:=OTHER`
    designs the controller on OTHER; the launcher overwrote it with PLANT without a word."""
    from grazing_control.ros import scene_nodes

    for key, kw in (("rig_file", "rig"), ("model_file", "model")):
        over = scene_nodes.scene_overrides(None, controller_overrides={key: "/other.yaml"},
                                           **{kw: "plant.yaml"})
        assert over["sim_node"][key] == os.path.abspath("plant.yaml")
        assert over["controller_node"][key] == "/other.yaml"
        over = scene_nodes.scene_overrides(None, **{kw: "plant.yaml"})
        assert over["controller_node"][key] == os.path.abspath("plant.yaml")


def test_grazing_run_refuses_a_non_empty_bag_folder_before_any_node_starts(tmp_path):
    """The recorder refuses a folder that is not empty (status 2), but only after every
    node had started (the scene failed with status 1 half a second later): the command
    line now says so at once, in one line naming --bag, and starts nothing."""
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "old.mcap").write_bytes(b"")
    done = subprocess.run([sys.executable, "-m", "grazing_control.cli", "run", "--periods",
                           "5", "--bag", str(bag)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and done.stdout == "", done.stderr
    assert done.stderr.count("\n") == 1
    assert f"--bag {bag} is invalid: the folder is not empty" in done.stderr
    assert [p.name for p in bag.iterdir()] == ["old.mcap"]

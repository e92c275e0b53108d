"""nodes.common: the command line of every node, checked before rcl sees it.

Pure parsing first (no ROS), then the node processes over Fast DDS: a bad command line
is one [ERROR] line and exit status 2, ``--help`` prints the usage, an unknown ``-p``
name is refused, and a parameter file keyed for another node name is warned about.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import pytest

from grazing_control.ros import launcher
from grazing_control.ros.common import StartupError
from grazing_control.ros.node_arguments import (NodeArguments, node_key_matches,
                                                parse_node_arguments)
from test_closed_loop import CONTROLLER, STUDY, new_domain


# ====================================================================== no ROS
def test_arguments_are_parsed_like_rcl(tmp_path):
    got = parse_node_arguments(["node", "--ros-args", "-p", "zeta:=0.1", "--params-file",
                                str(STUDY), "-r", "__ns:=/a", "--log-level", "warn",
                                "--disable-rosout-logs", "--", "--ros-args", "-p", "r:=0.5"])
    assert isinstance(got, NodeArguments) and not got.help
    assert got.params == {"zeta": "0.1", "r": "0.5"}
    assert [p for p, _ in got.params_files] == [str(STUDY)]
    assert got.params_files[0][1]["/**"]["zeta"] == 0.01
    assert parse_node_arguments(["node", "--help"]).help


@pytest.mark.parametrize("args, text", [
    (["stray"], "unexpected argument 'stray'"),
    (["--ros-args", "-p", "zeta"], "-p 'zeta' is invalid: write -p name:=value"),
    (["--ros-args", "-p", ":=1"], "write -p name:=value"),
    (["--ros-args", "--foo"], "unknown ROS argument '--foo'"),
    (["--ros-args", "-p"], "needs a value"),
    (["--ros-args", "--params-file", "/nonexistent.yaml"], "cannot be read"),
])
def test_bad_arguments_are_refused_with_a_reason(args, text):
    with pytest.raises(StartupError, match=text.replace("(", r"\(")):
        parse_node_arguments(["node"] + args)


@pytest.mark.parametrize("content, text", [
    ("a: [1, 2\n", "is not valid YAML"),
    ("- 1\n- 2\n", "is not a ROS parameter file"),
    ("/sim_node:\n  zeta: 0.1\n", "key '/sim_node'"),
    ("", "is not a ROS parameter file"),
])
def test_malformed_parameter_files_are_refused(tmp_path, content, text):
    path = tmp_path / "p.yaml"
    path.write_text(content)
    with pytest.raises(StartupError, match=text):
        parse_node_arguments(["node", "--ros-args", "--params-file", str(path)])


@pytest.mark.parametrize("key, name, applies", [
    ("/**", "/sim_node", True), ("/**", "/a/b/sim_node", True),
    ("/sim_node", "/sim_node", True), ("sim_node", "/sim_node", True),
    ("/sim_node", "/ns/sim_node", False), ("/sim_node", "/other", False),
    ("/*", "/sim_node", True), ("/*", "/ns/sim_node", False),
    ("/ns/*", "/ns/sim_node", True), ("/**/sim_node", "/x/y/sim_node", True),
    ("/**/sim_node", "/x/controller_node", False),
])
def test_parameter_file_keys_match_as_rcl_does(key, name, applies):
    assert node_key_matches(key, name) is applies


# ================================================================ the processes
def run_node(module, *args, timeout=30):
    cmd = launcher.node_command(module)[:-1] + list(args)      # without --ros-args
    return subprocess.run(cmd, env=launcher.node_env(new_domain()), capture_output=True,
                          text=True, timeout=timeout)


def test_help_prints_usage_and_exits_0():
    for module, name in ((launcher.SIM_MODULE, "sim_node"),
                         (launcher.CONTROLLER_MODULE, "controller_node"),
                         (launcher.RECORDER_MODULE, "recorder_node")):
        done = run_node(module, "--help")
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith(f"usage: {name}") and "Traceback" not in done.stderr


@pytest.mark.parametrize("args, text", [
    (["--ros-args", "--params-file", "/nonexistent.yaml"], "cannot be read"),
    (["--ros-args", "--params-file", __file__], "is not valid YAML"),
    (["--ros-args", "-p", "zeta"], "-p 'zeta' is invalid"),
    (["--ros-args", "--foo"], "unknown ROS argument '--foo'"),
    (["extra"], "unexpected argument 'extra'"),
])
def test_bad_command_line_is_one_error_line_and_status_2(args, text):
    done = run_node(launcher.SIM_MODULE, *args)
    lines = [ln for ln in (done.stdout + done.stderr).splitlines() if ln.strip()]
    assert done.returncode == 2 and len(lines) == 1, lines
    assert "[ERROR]" in lines[0] and text in lines[0], lines


def test_unknown_parameter_name_is_refused():
    done = run_node(launcher.CONTROLLER_MODULE, "--ros-args", "--params-file",
                    str(CONTROLLER), "-p", "c3:=1.0")
    out = done.stdout + done.stderr
    assert done.returncode == 2 and "unknown parameter c3 for controller_node" in out, out
    assert "Traceback" not in out and "summary" not in out


def test_parameter_file_for_another_node_name_is_warned(tmp_path):
    """Under a namespace a '/controller_node:' file is ignored by rcl: said, twice (the
    file, and the gains left at 0); the shipped '/**' file applies, without a warning;
    with another actuation_delay than its design's, its c1 is said not to be Eq. 38's."""
    old = tmp_path / "old.yaml"
    old.write_text(CONTROLLER.read_text().replace("/**:", "/controller_node:"))
    outputs = {}
    for name, path, delay in (("old", old, {}), ("shipped", CONTROLLER, {}),
                              ("delayed", CONTROLLER, {"actuation_delay": 1.0})):
        cmd = launcher.node_command(launcher.CONTROLLER_MODULE, [path],
                                    {"enable_after": -1, **delay}) + ["-r", "__ns:=/scene2"]
        proc = subprocess.Popen(cmd, env=launcher.node_env(new_domain()), text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        guard = threading.Timer(30.0, proc.kill)      # never hang on a missing line
        guard.start()
        try:
            out = ""
            for line in proc.stdout:
                out += line
                if "summary" in line or ("enable_after=" in line and name != "old"):
                    break
                if "no key applies" in line:      # checked right after the node is built
                    break
            time.sleep(0.5)                       # anything logged after its start
        finally:
            launcher.stop_nodes([proc])
            guard.cancel()
        outputs[name] = out + proc.stdout.read()
    assert "no key applies to this node (/scene2/controller_node): '/controller_node'" \
        in outputs["old"], outputs["old"]
    assert "c1 and c2 not given" in outputs["old"] and "c1 = c2 = 0" in outputs["old"]
    assert "WARN" not in outputs["shipped"] and "c1=-1.02060145554" in outputs["shipped"]
    assert "is not the degenerate gain of c2=-1.0 at actuation_delay=1.0" in \
        outputs["delayed"], outputs["delayed"]


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_a_signal_during_a_realtime_scene_ends_it_quietly(signum):
    """Ctrl-C or SIGTERM at a random moment of a realtime simulator (EventsExecutor, the
    tick timer busy): the summary marked '(interrupted)', status 0, no '[FATAL] Exception
    in ... callback' and no stack, every time (it was 8 of 8 with the handler raising)."""
    import random
    import signal as signals

    rng = random.Random(19)
    for _ in range(4):
        cmd = launcher.node_command(launcher.SIM_MODULE, [STUDY], {
            "mode": "realtime", "time_scale": 100.0, "max_periods": 0,
            "wait_for_controller": False})
        proc = subprocess.Popen(cmd, env=launcher.node_env(new_domain()), text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            for line in proc.stdout:                # started: the settings line
                if "mode=realtime" in line:
                    break
            time.sleep(rng.uniform(0.5, 2.0))
            proc.send_signal(getattr(signals, signum))
            out, _ = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 0, out
        assert "(interrupted)" in out and "FATAL" not in out and "Error occurred" not in out, out


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.3])
def test_ctrl_c_while_a_node_imports_is_quiet(delay):
    """SIGINT right after the ``sim_node`` console script started, while it still imports
    rclpy and the layers below (``delay`` s after numpy's core is mapped; ``ros2 launch``
    stopped while its nodes start): status 0 and no traceback (issue 27 §2: the console
    script imported the node module before any handler existed, a KeyboardInterrupt
    traceback and status -2)."""
    import signal as signals

    from console_scripts import script, wait_until_mapped

    proc = subprocess.Popen([str(script("sim_node")), "--ros-args", "-p",
                             "wait_for_controller:=false", "-p", "max_periods:=0"],
                            env=launcher.node_env(new_domain()), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        assert wait_until_mapped(proc), proc.communicate()
        time.sleep(delay)
        proc.send_signal(signals.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out
    assert "Traceback" not in out and "KeyboardInterrupt" not in out, out


def test_security_enforced_without_the_plugins_is_refused(tmp_path):
    """SROS2 (docs/nodes.md, 'Who may talk to a scene'): the wheels' Fast DDS has no
    security plugins, so a node asked to enforce security refuses to start with one line
    and status 2, instead of running unsecured or with a traceback. If a future wheel
    carries the plugins, this fails: then test that an enclave-less participant cannot
    reach a secured scene."""
    import os

    (tmp_path / "enclaves" / "grazing" / "controller_node").mkdir(parents=True)
    env = dict(launcher.node_env(new_domain()), ROS_SECURITY_KEYSTORE=str(tmp_path),
               ROS_SECURITY_ENABLE="true", ROS_SECURITY_STRATEGY="Enforce")
    cmd = launcher.node_command(launcher.CONTROLLER_MODULE, [CONTROLLER], {}) + [
        "--enclave", "/grazing/controller_node"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=60)
    out = done.stdout + done.stderr
    assert done.returncode == 2, out
    assert "doesn't have the security libraries" in out and "Traceback" not in out, out
    assert os.path.isdir(tmp_path / "enclaves")


def test_the_nodes_import_no_solver_they_do_not_use():
    """Issue 30: every node imported scipy.optimize (0.25 s of a scene's start) through
    plant.settings -> dynamics.simulation.fidelity -> dynamics.maps.zdm, for a root finder that only the
    zdm analysis calls; it is imported where it is used. Imports only: no node starts."""
    from loaded_modules import loaded

    code = ("import sim_node.sim_node, grazing_control.ros.controller_node, "
            "grazing_control.ros.recorder_node")
    assert loaded(code, ("scipy.optimize", "scipy.integrate", "numba"),
                  env=launcher.node_env()) == []


def test_settle_heap_freezes_what_start_up_made_and_records_the_pauses(monkeypatch):
    """The objects alive when a node starts to spin are out of the cyclic collector's
    reach (a full collection walked them all while the scene ran: 31 ms in sim_node,
    docs/rig_scene.md); GRAZING_GC=keep leaves the collector alone; GRAZING_GC_PAUSES
    records each collection."""
    import gc

    from grazing_control.ros import common

    gc.unfreeze()
    monkeypatch.setenv(common.GC_ENV, "keep")
    monkeypatch.delenv(common.GC_PAUSES_ENV, raising=False)
    assert common.settle_heap() is None and gc.get_freeze_count() == 0
    monkeypatch.delenv(common.GC_ENV)
    monkeypatch.setenv(common.GC_PAUSES_ENV, "1")
    try:
        pauses = common.settle_heap()
        assert gc.get_freeze_count() > 1000
        gc.collect(0)
        assert pauses.count[0] >= 1 and pauses.max[0] > 0.0
        assert pauses.summary().startswith("cpu_s=") and "gen2 n=" in pauses.summary()
    finally:
        gc.callbacks.remove(pauses)
        gc.unfreeze()


def test_safe_points_run_the_collections_there_and_not_in_between(monkeypatch):
    """Issue 30: the stream controller's young collections fell inside its section
    estimates (23 of 1000 at T/200 x1000, ~0.1-1.2 ms each). With SafePoints the
    allocations between two safe points trigger none (up to the fallback); the call runs
    the one the default thresholds ask for (gen 0; gen 1 every twelfth; gen 2 after
    eleven of those), and the cycles are freed there. GRAZING_GC=keep: nothing changes."""
    import gc

    from grazing_control.ros import common

    class Cycle:
        def __init__(self):
            self.me = self

    before = gc.get_threshold()
    monkeypatch.setattr(common.SafePoints, "_open", 0)   # whatever ran in this process
    gc.set_threshold(700, 10, 10)                          # CPython's defaults
    thresholds = gc.get_threshold()
    runs = []

    def record(phase, info):
        if phase == "stop":
            runs.append((info["generation"], info["collected"]))

    monkeypatch.setenv(common.GC_ENV, "keep")
    common.SafePoints()()
    assert gc.get_threshold() == thresholds
    monkeypatch.delenv(common.GC_ENV)
    gc.collect()
    gc.callbacks.append(record)
    try:
        collect = common.SafePoints()
        assert gc.get_threshold() == (common.SAFE_POINT_FALLBACK, *thresholds[1:])
        collect()                       # nothing allocated: nothing due
        assert runs == []
        gens = []
        for _ in range(140):
            for _ in range(thresholds[0] + 50):
                Cycle()
            assert runs == []           # the allocations trigger none
            collect()
            (gen, collected), = runs
            assert collected >= thresholds[0] // 2   # the cycles freed here
            gens.append(gen)
            runs.clear()
        # as CPython's own: gen 1 once gen 0 ran more than 10 times since, gen 2 once
        # gen 1 ran more than 10 times
        assert gens.index(1) == 11 and gens[12:24].count(1) == 1
        assert gens.index(2) == 12 * 11 and gens.count(2) == 1
        collect.close()                 # the node destroyed: the thresholds as they were
        assert gc.get_threshold() == thresholds
    finally:
        gc.callbacks.remove(record)
        gc.set_threshold(*before)


@pytest.mark.parametrize("order", ["the first closed first", "the first closed last"])
def test_two_safe_points_in_one_process_put_the_thresholds_back(order, monkeypatch):
    """Two stream controllers in one process (a composed scene, or a test's two in-process
    nodes): each SafePoints counts from the thresholds before the first, and the last one
    closed puts them back, in either order. Before, the second read the raised trigger as
    the default and, closed last, left it raised for good: a later test in the same
    worker saw a collection at 100,000 allocations (a fresh clone's failure, 3 runs)."""
    import gc

    from grazing_control.ros import common

    monkeypatch.delenv(common.GC_ENV, raising=False)
    monkeypatch.setattr(common.SafePoints, "_open", 0)
    before = gc.get_threshold()
    try:
        gc.set_threshold(700, 10, 10)
        a, b = common.SafePoints(), common.SafePoints()
        assert a.thresholds == b.thresholds == (700, 10, 10)
        assert gc.get_threshold() == (common.SAFE_POINT_FALLBACK, 10, 10)
        first, last = (a, b) if order.endswith("first") else (b, a)
        first.close()
        assert gc.get_threshold() == (common.SAFE_POINT_FALLBACK, 10, 10)   # one still open
        last.close()
        last.close()                                                       # once only
        assert gc.get_threshold() == (700, 10, 10) and common.SafePoints._open == 0
    finally:
        gc.set_threshold(*before)


#: A node whose start fails, with a stop signal landing while the failure is reported.
_SIGNAL_WHILE_REFUSING = r"""
import os, signal, sys
from grazing_control.ros import common
from grazing_control.oscillator.params import ParameterError

report = common._startup_message
def signalled(exc):
    os.kill(os.getpid(), int(sys.argv[1]))     # the launcher stopping the scene, now
    return report(exc)
common._startup_message = signalled

def refuse():
    raise ParameterError("state_period=-1.0 is invalid: valid range is state_period >= 0")

sys.exit(common.run_node(refuse, ["x"], "controller_node"))
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_while_a_refused_start_is_reported_is_quiet(signum):
    """A node refusing to start (a bad parameter) logs one line and returns status 2, also
    when a stop signal lands while it reports it: a launcher stops the other nodes as
    soon as one of them exits (`grazing run --sim-param state_period:=-1.0` printed the
    controller's KeyboardInterrupt traceback and status -2 in 2 of 6 runs)."""
    done = subprocess.run([sys.executable, "-c", _SIGNAL_WHILE_REFUSING, str(int(signum))],
                          env=launcher.node_env(new_domain()), capture_output=True,
                          text=True, timeout=60)
    lines = [ln for ln in (done.stdout + done.stderr).splitlines() if ln.strip()]
    assert done.returncode == 2 and len(lines) == 1, lines
    assert "[ERROR]" in lines[0] and "state_period=-1.0 is invalid" in lines[0], lines


def _segments(pid: int) -> list:
    """The DDS participants' shared-memory segments that process ``pid`` has mapped."""
    import re

    with open(f"/proc/{pid}/maps") as fh:
        return sorted(set(re.findall(r"/dev/shm/fastrtps_[0-9a-f]{16}\b", fh.read())))


@pytest.mark.parametrize("module", [launcher.SIM_MODULE, launcher.CONTROLLER_MODULE])
def test_a_node_leaves_no_shared_memory_behind(module, tmp_path):
    """A node's process ends through os._exit (run_node's fast exit); leave_graph destroys
    its context first, so its DDS participant's shared-memory segment is deleted. Before,
    every simulator and controller left one in /dev/shm (549 KB each: 13,000 segments,
    6.8 GB of this machine's memory after two days of suites)."""
    from pathlib import Path

    log = tmp_path / "node.log"
    proc = launcher.start_node(module, [CONTROLLER if module == launcher.CONTROLLER_MODULE
                                        else STUDY], {"delta_d": -5e-6},
                               domain_id=new_domain(), log=log)
    try:
        deadline = time.monotonic() + 30.0
        segments = []
        while not segments and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
            segments = _segments(proc.pid)
        assert segments, log.read_text()         # it has one (Fast DDS's SHM transport)
        time.sleep(0.5)                           # started: its handlers are installed
        proc.send_signal(signal.SIGINT)
        assert proc.wait(20) == 0, log.read_text()
    finally:
        launcher.stop_nodes([proc])
    assert not [s for s in segments if Path(s).exists()], segments

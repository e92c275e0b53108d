"""The node zygote (grazing_control/ros/node_zygote.py): a node forked from it is, to
its owner and to itself, the process that ``launcher.start_node`` spawns; what it cannot
make so it refuses, and the node is spawned."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from grazing_control.ros import launcher, node_zygote

TESTS = Path(__file__).resolve().parent
PROBE = "node_zygote_probe"


def _env(**extra):
    env = launcher.node_env()
    env["PYTHONPATH"] = os.pathsep.join([str(TESTS), env["PYTHONPATH"]])
    return {**env, **extra}


@pytest.fixture(scope="module")
def zygote():
    z = node_zygote.NodeZygote(_env(), [PROBE, launcher.CONTROLLER_MODULE])
    yield z
    z.close()


def _threads_of_a_process_that_imports_rclpy() -> int:
    out = subprocess.run([sys.executable, "-c", "import os, rclpy; "
                          "print(len(os.listdir('/proc/self/task')))"],
                         env=_env(), capture_output=True, text=True, check=True).stdout
    return int(out)


def _read_json(path: Path, timeout: float = 30.0) -> dict:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        lines = path.read_text().splitlines() if path.exists() else []
        if lines:
            return json.loads(lines[0])
        time.sleep(0.02)
    raise AssertionError(f"{path}: nothing in {timeout} s")


def _probe(zygote, tmp_path, name="probe", **env):
    out = tmp_path / f"{name}.out"
    with open(out, "wb") as f:
        node = zygote.spawn(launcher.node_command(PROBE, (), {"x": 1.5}),
                            _env(GRAZING_LAUNCHER_PID=str(os.getpid()), **env),
                            stdin=subprocess.DEVNULL, stdout=f, stderr=subprocess.STDOUT,
                            cwd=str(tmp_path))
    return node, out


def test_a_forked_node_is_its_owners_child_as_a_spawned_one(zygote, tmp_path):
    node, out = _probe(zygote, tmp_path, ROS_DOMAIN_ID="17")
    assert isinstance(node, node_zygote.ForkedNode)
    seen = _read_json(out)
    assert seen["pid"] == node.pid
    assert seen["ppid"] == os.getpid()                 # reparented to its owner
    assert seen["pgid"] == node.pid                    # a process group of its own
    assert seen["name"] == "__main__"                  # run as python -m runs it
    assert seen["argv"] == ["--ros-args", "-p", "x:=1.5"]
    assert seen["path0"] == ""                         # as python -c BOOTSTRAP has it
    assert seen["cwd"] == str(tmp_path)
    assert seen["cmdline"][3:] == [PROBE, "--ros-args", "-p", "x:=1.5"]   # what ps shows
    assert seen["domain"] == "17"                      # the request's environment
    assert seen["launcher_pid"] is None                # popped, as BOOTSTRAP does
    assert seen["pdeathsig"] == signal.SIGTERM
    assert not seen["sigint_default"]                  # BOOTSTRAP's quiet Ctrl-C
    assert seen["stdin"] == os.devnull
    assert seen["rclpy_before"]                        # imported once, in the zygote
    # inspect's map of module files, which rclpy's logger reads at each log call, filled in
    # the zygote: only what the node imported itself is left to its first log line
    assert seen["modules"] > 500 and seen["unmapped"] == ["__main__"], seen["unmapped"]
    # the tracer's listener threads, which rclpy's C library starts, started again in the
    # node (node_zygote.TracerForkHooks), as a spawned process that imports rclpy has them
    assert seen["threads"] == _threads_of_a_process_that_imports_rclpy()
    assert seen["blocked"] == 0                        # the fork protocol's mask undone
    assert node.poll() is None
    node.terminate()
    assert node.wait(10) == 0
    assert "to stderr" in out.read_text()              # stderr into the same file


def test_two_forked_nodes_draw_different_random_numbers(zygote, tmp_path):
    """numpy's legacy global generator is reseeded in each node (a fork copies the
    zygote's state; a spawned node seeds its own)."""
    a, out_a = _probe(zygote, tmp_path, "a")
    b, out_b = _probe(zygote, tmp_path, "b")
    try:
        assert _read_json(out_a)["draw"] != _read_json(out_b)["draw"]
    finally:
        launcher.stop_nodes([a, b])


def test_signals_and_statuses_read_as_popen_reads_them(zygote, tmp_path):
    node, out = _probe(zygote, tmp_path)
    _read_json(out)
    with pytest.raises(subprocess.TimeoutExpired):
        node.wait(0.2)
    node.kill()
    assert node.wait(10) == -signal.SIGKILL
    node.terminate()                                   # after the end: nothing happens
    assert node.returncode == -signal.SIGKILL


@pytest.mark.parametrize("name, value", [("OPENBLAS_NUM_THREADS", "4"),
                                         ("NUMBA_DISABLE_JIT", "1"),
                                         ("PYTHONPATH", "/elsewhere")])
def test_an_environment_read_at_import_is_refused(zygote, tmp_path, name, value):
    node, _ = _probe(zygote, tmp_path, **{name: value})
    assert node is None


def test_another_interpreter_and_pipes_are_refused(zygote):
    command = launcher.node_command(PROBE)
    assert zygote.spawn(["/usr/bin/python3", *command[1:]], _env()) is None
    assert zygote.spawn(command, _env(), stdout=subprocess.PIPE) is None


def test_start_node_spawns_when_the_zygote_is_gone(monkeypatch, tmp_path):
    """The owner's zygote killed: the next node is spawned (subprocess.Popen) and runs."""
    z = node_zygote.NodeZygote(launcher.node_env(), [launcher.CONTROLLER_MODULE])
    monkeypatch.setitem(node_zygote._owned, os.getpid(), z)
    z.proc.kill()
    z.proc.wait()
    log = tmp_path / "controller.log"
    proc = launcher.start_node(launcher.CONTROLLER_MODULE,
                               [launcher.CONFIG_DIR / "controller.yaml"], {},
                               domain_id=launcher.MAX_DOMAIN_ID, log=log)
    try:
        assert isinstance(proc, subprocess.Popen)
        assert z.broken
        end = time.monotonic() + 60
        while "c1=" not in log.read_text() and time.monotonic() < end:
            time.sleep(0.05)
        assert "c1=" in log.read_text()
    finally:
        launcher.stop_nodes([proc])
    assert proc.returncode == 0


OWNER = """
import os, sys, time
from grazing_control.ros import launcher, node_zygote
node_zygote.enable()
proc = launcher.start_node(launcher.CONTROLLER_MODULE, [launcher.CONFIG_DIR / "controller.yaml"],
                           {}, domain_id=launcher.MAX_DOMAIN_ID, log=sys.argv[1])
print(type(proc).__name__, proc.pid, node_zygote._owned[os.getpid()].proc.pid, flush=True)
time.sleep(600)
"""


def test_a_killed_owner_takes_its_nodes_and_zygote_with_it(tmp_path):
    """SIGKILL to the owner: its forked node gets SIGTERM (PR_SET_PDEATHSIG, set once the
    node is the owner's child) and ends with its summary; the zygote ends too."""
    log = tmp_path / "controller.log"
    owner = subprocess.Popen([sys.executable, "-c", OWNER, str(log)], env=launcher.node_env(),
                             stdout=subprocess.PIPE, text=True)
    kind, node, zygote = owner.stdout.readline().split()
    assert kind == "ForkedNode"
    end = time.monotonic() + 60
    while "c1=" not in log.read_text() and time.monotonic() < end:
        time.sleep(0.05)
    owner.kill()
    owner.wait()
    end = time.monotonic() + 30
    alive = [int(node), int(zygote)]
    while alive and time.monotonic() < end:
        alive = [p for p in alive if Path(f"/proc/{p}").exists()
                 and "Z" not in Path(f"/proc/{p}/stat").read_text().split(")")[1][:3]]
        time.sleep(0.05)
    assert not alive
    assert "summary:" in log.read_text()


def test_an_owner_that_is_no_subreaper_is_refused_at_once_and_the_zygote_goes_on(zygote,
                                                                                  tmp_path):
    """The node reparented elsewhere (its owner no longer a child subreaper): it says so as
    soon as its middle process has gone, the zygote's answer is a refusal (the owner then
    spawns), and the next request, with the owner a subreaper again, is forked."""
    node_zygote._prctl(36, 0)                          # PR_SET_CHILD_SUBREAPER off
    try:
        t0 = time.monotonic()
        refused, _ = _probe(zygote, tmp_path, "refused")
        took = time.monotonic() - t0
    finally:
        node_zygote._prctl(36, 1)
    assert refused is None and took < 5.0, took       # not SPAWN_TIMEOUT (30 s)
    assert not zygote.broken
    node, out = _probe(zygote, tmp_path, "after")
    try:
        assert _read_json(out)["ppid"] == os.getpid()
    finally:
        launcher.stop_nodes([node])


def test_a_ctrl_c_is_the_owners_the_zygote_neither_gets_it_nor_dies_of_it(zygote, tmp_path):
    """The zygote has a process group of its own (a terminal's Ctrl-C reached it in the
    launcher's group and printed a KeyboardInterrupt traceback, found by hand) and
    ignores SIGINT; a node forked after one is a node as before."""
    assert os.getpgid(zygote.proc.pid) == zygote.proc.pid
    zygote.proc.send_signal(signal.SIGINT)
    time.sleep(0.5)
    assert zygote.proc.poll() is None
    node, out = _probe(zygote, tmp_path, "after_sigint")
    try:
        seen = _read_json(out)
        assert seen["ppid"] == os.getpid() and not seen["sigint_default"]
    finally:
        launcher.stop_nodes([node])


ENDING_OWNER = """
import os, sys
from grazing_control.ros import launcher, node_zygote
node_zygote.enable()
zygote = node_zygote.owner_zygote(launcher.node_env(), [sys.argv[1]])
print(zygote.proc.pid, flush=True)
"""


def test_an_owner_that_exits_has_ended_its_zygote_before_it_is_gone(zygote):
    """An owner that exits normally (a ``grazing run`` after its scene, or its Ctrl-C)
    ends its zygote and waits for it: once the owner's status is in, no trace of the
    zygote is left, alive or as a zombie reparented to the subreaper above (this test's
    process, as the suite's worker is; the worker's check for processes left behind saw
    a zygote still exiting after test_ctrl_c_early_in_grazing_run_is_quiet, 2026-12-01)."""
    owner = subprocess.run([sys.executable, "-c", ENDING_OWNER, PROBE], env=_env(),
                           capture_output=True, text=True, timeout=120)
    assert owner.returncode == 0, owner.stderr
    pid = int(owner.stdout.split()[0])
    left = Path(f"/proc/{pid}").exists()
    if left:                                      # reap it: a zombie of this process
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
    assert not left, f"the zygote {pid} outlived its owner"

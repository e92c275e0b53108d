"""Real-time scheduling of a node's process (grazing_control.ros.scheduling): applied where
the process may, a warning naming the option and the privilege where it may not, never
an exception from the operating system's refusal."""

import errno
import os
import subprocess
import sys

import pytest

from grazing_control.ros import scheduling
from grazing_control.ros.scheduling import apply_scheduling, parse_cpus


def test_cpu_lists():
    assert parse_cpus("") == ()
    assert parse_cpus("0,2-3") == (0, 2, 3)
    assert parse_cpus(" 1 , 1 ") == (1,)
    for bad in ("a", "3-1", "-1", "1-"):
        with pytest.raises(ValueError, match="cpu_affinity=.* is invalid"):
            parse_cpus(bad)


@pytest.mark.parametrize("priority", [-1, 100, 1.5, True])
def test_priority_outside_its_range_is_refused(priority):
    with pytest.raises(ValueError, match="thread_priority=.* is invalid"):
        apply_scheduling(priority)


def test_nothing_asked_nothing_done():
    assert apply_scheduling() == ((), ())


@pytest.mark.skipif(os.geteuid() != 0, reason="needs the privilege to be granted")
def test_applied_in_a_process_that_may():
    """In a child process (this one must not become real-time): policy, affinity and
    locked memory as the kernel reports them afterwards; the policy for every thread,
    those that existed before too (the middleware's receive threads, created with the
    node), not only the calling one."""
    code = ("import os, threading; from grazing_control.ros.scheduling import apply_scheduling as a; "
            "ev = threading.Event(); t = threading.Thread(target=ev.wait); t.start(); "
            "r = a(5, (0,), True); print(r.applied, r.warnings); "
            "tids = [int(x) for x in os.listdir('/proc/self/task')]; "
            "print(os.sched_getscheduler(0) == os.SCHED_FIFO, os.sched_getparam(0).sched_priority, "
            "sorted(os.sched_getaffinity(0)), "
            "[l for l in open('/proc/self/status') if l.startswith('VmLck')][0].split()[1] != '0', "
            "len(tids) >= 2 and all(os.sched_getscheduler(x) == os.SCHED_FIFO for x in tids)); "
            "ev.set(); t.join()")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True).stdout.splitlines()
    assert out[-1] == "True 5 [0] True True", out


def test_refusals_are_warnings(monkeypatch):
    def refuse(*args):
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "sched_setaffinity", refuse)
    monkeypatch.setattr(scheduling, "_mlockall", lambda: errno.EPERM)
    r = apply_scheduling(10, (0, 1), True)
    assert r.applied == ()
    assert len(r.warnings) == 3
    assert "thread_priority=10 not applied (Operation not permitted)" in r.warnings[0]
    assert "CAP_SYS_NICE" in r.warnings[0]
    assert "cpu_affinity=[0, 1] not applied" in r.warnings[1]
    assert "lock_memory not applied" in r.warnings[2] and "CAP_IPC_LOCK" in r.warnings[2]


def test_the_controller_node_takes_the_scheduling_parameters():
    """controller_node as sim_node: the three options applied (root here) or each refused
    with a warning naming it, the priority once its start-up is done (after the affinity
    and the memory lock: its start-up's CPU work not under SCHED_FIFO); a malformed one is
    one line, status 2."""
    import subprocess
    import threading

    from grazing_control.ros import launcher
    from test_closed_loop import CONTROLLER, new_domain

    cmd = launcher.node_command(launcher.CONTROLLER_MODULE, [CONTROLLER], {
        "thread_priority": 20, "lock_memory": True, "cpu_affinity": "0"})
    proc = subprocess.Popen(cmd, env=launcher.node_env(new_domain()), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    timer = threading.Timer(60.0, proc.kill)      # a node that never says it: the test fails
    timer.start()
    lines = []
    try:
        for line in proc.stdout:                  # up to the end of its start-up
            lines.append(line)
            if " c1=" in line:
                break
    finally:
        timer.cancel()
        launcher.stop_nodes([proc])
    out = "".join(lines) + proc.stdout.read()
    said = [i for i, ln in enumerate(lines) if "SCHED_FIFO priority 20" in ln
            or "thread_priority=20 not applied" in ln]
    pinned = [i for i, ln in enumerate(lines) if "CPU affinity [0]" in ln
              or "cpu_affinity=[0] not applied" in ln]
    assert said and pinned and pinned[0] < said[0], out
    assert "Traceback" not in out
    bad = subprocess.run(launcher.node_command(launcher.CONTROLLER_MODULE, [CONTROLLER],
                                               {"thread_priority": 120}),
                         env=launcher.node_env(new_domain()), capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "thread_priority" in bad.stdout + bad.stderr

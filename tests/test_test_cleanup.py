"""The suite's own promise: a test that fails leaves no process behind (conftest.py,
``no_process_outlives_its_test``), so a failed scene test cannot leak a running launcher
into the rest of the run."""

import subprocess
import sys
from pathlib import Path

import psutil

CONFTEST = Path(__file__).with_name("conftest.py")

LEAKING_TESTS = '''
import subprocess, sys

def test_leaks_a_process_group_then_fails(tmp_path_factory):
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"],
                         start_new_session=True)
    open(PIDFILE, "w").write(str(p.pid))
    assert False, "a failing assertion before the test could stop its process"
'''


def test_a_failing_test_leaves_no_process_running(tmp_path):
    pidfile = tmp_path / "pid"
    (tmp_path / "conftest.py").write_text(CONFTEST.read_text())
    (tmp_path / "test_leak.py").write_text(f"PIDFILE = {str(pidfile)!r}\n" + LEAKING_TESTS)
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          str(tmp_path / "test_leak.py")], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert "1 failed" in out.stdout, out.stdout + out.stderr
    assert "left 1 process(es) running" in out.stdout, out.stdout
    pid = int(pidfile.read_text())
    assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE


def test_the_descendants_read_from_the_kernels_lists_are_psutils_over_random_trees():
    """conftest's ``_descendants`` (the per-thread children lists) against psutil's
    recursive ``children`` (every process's stat file), over seeded random trees: a
    Python process starts shells from its main thread and from a thread of its own (a
    child started by another thread is on that thread's list), each shell a random
    number of sleeps and then one itself (``exec``: no process of the tree exits while
    it is read). Each tree is read from its root: the worker's other children (the node
    zygote, the processes of a test that are still exiting) change under the two reads
    (the suite's first run of this test compared the worker's whole tree and failed)."""
    import random
    import time

    from conftest import _descendants

    root = ("import subprocess, sys, threading, time\n"
            "shells = sys.argv[1:]\n"
            "def spawn(cmd):\n"
            "    subprocess.Popen(['sh', '-c', cmd])\n"
            "for i, cmd in enumerate(shells):\n"
            "    if i % 2:\n"
            "        t = threading.Thread(target=spawn, args=(cmd,)); t.start(); t.join()\n"
            "    else:\n"
            "        spawn(cmd)\n"
            "time.sleep(20)\n")
    rng = random.Random(5)
    for _ in range(4):
        shells = ["sleep 20 & " * rng.randint(0, 3) + "exec sleep 20"
                  for _ in range(rng.randint(1, 4))]
        expected = sum(cmd.count("sleep") for cmd in shells)
        proc = subprocess.Popen([sys.executable, "-c", root, *shells])
        try:
            deadline = time.monotonic() + 30
            while len(mine := _descendants(proc.pid)) < expected:
                assert time.monotonic() < deadline, (mine, shells)
                time.sleep(0.05)
            time.sleep(0.1)     # each shell's exec done (its pid kept)
            mine = _descendants(proc.pid)
            assert len(mine) == expected, (mine, shells)
            assert sorted(mine) == sorted(
                c.pid for c in psutil.Process(proc.pid).children(recursive=True)), shells
        finally:
            for p in psutil.Process(proc.pid).children(recursive=True):
                p.kill()
            proc.kill()
            proc.wait()

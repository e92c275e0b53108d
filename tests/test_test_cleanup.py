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

"""support.signals: a stop set from a signal handler ends a waiting loop every time (the
threading.Event pattern it replaces deadlocks when the signal lands inside wait)."""

import random
import signal
import subprocess
import sys
import time

from grazing_control.support.signals import SignalStop

CHILD = """
import signal, sys
from grazing_control.support.signals import SignalStop
stop = SignalStop()
signal.signal(signal.SIGTERM, stop.set)
print("ready", flush=True)
n = 0
while not stop.wait(0.0002 * (n % 3)):   # short and zero timeouts: signals land inside wait
    n += 1
stop.close()
print("stopped", n, flush=True)
"""


def test_a_signal_during_a_wait_always_ends_the_loop():
    """120 processes, each signalled at a random moment of its busy wait loop: all end
    within seconds (a deadlock would leave them waiting forever)."""
    rng = random.Random(21)
    procs = []
    for _ in range(120):
        p = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
        procs.append(p)
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        time.sleep(rng.uniform(0.0, 0.01))
        p.send_signal(signal.SIGTERM)
    stuck = []
    deadline = time.monotonic() + 30.0
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            stuck.append(p.pid)
            p.kill()
            p.wait()
    assert stuck == []
    assert all(p.returncode == 0 for p in procs)


def test_wait_returns_at_its_timeout_without_a_signal_and_at_once_with_one():
    stop = SignalStop()
    try:
        t0 = time.monotonic()
        assert stop.wait(0.05) is False
        assert time.monotonic() - t0 >= 0.04
        stop.set()
        t0 = time.monotonic()
        assert stop.wait(10.0) is True and stop.is_set()
        assert time.monotonic() - t0 < 1.0
    finally:
        stop.close()

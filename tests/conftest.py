"""Session set-up shared by every test module."""

import pytest

from grazing_control.oscillator import kernel


@pytest.fixture(scope="session", autouse=True)
def compiled_kernel():
    """Compile the numba kernel (or load its on-disk cache) once, before any test: in a
    fresh checkout the first compilation takes 5-20 s, which a node test's startup
    timeouts must not absorb."""
    if kernel.use_kernel():
        kernel.warm_up()


# Processes a test leaves behind (a launcher and its scene after a failed assertion, a
# node whose test timed out) are ended here, also when the test failed: no test may leak
# a process into the next ones (issue 19: an unbounded scene ran on for 14 minutes).
# multiprocessing's own helpers (resource tracker, forkserver) live for the session.
_SESSION_HELPERS = ("multiprocessing.resource_tracker", "multiprocessing.forkserver")


def _leftover_processes():
    import psutil

    found = []
    for child in psutil.Process().children(recursive=True):
        try:
            if child.status() == psutil.STATUS_ZOMBIE:
                continue
            cmdline = " ".join(child.cmdline())
        except psutil.Error:
            continue
        if not any(h in cmdline for h in _SESSION_HELPERS):
            found.append(child)
    return found


@pytest.fixture(autouse=True)
def no_process_outlives_its_test(request):
    yield
    import psutil

    left = _leftover_processes()
    if not left:
        return
    names = []
    for proc in left:
        try:
            names.append(" ".join(proc.cmdline())[:120])
            proc.terminate()
        except psutil.Error:
            pass
    _, alive = psutil.wait_procs(left, timeout=10)
    for proc in alive:
        try:
            proc.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(alive, timeout=5)
    import warnings
    warnings.warn(f"{request.node.nodeid} left {len(left)} process(es) running, ended "
                  f"at teardown: {names}", stacklevel=1)

"""Session set-up shared by every test module, and how the suite uses both cores.

`make test` runs pytest on two workers (pytest-xdist, ``-n 2 --dist loadgroup``). The
modules that start node processes or DDS participants (:data:`SCENE_MODULES`) form one
group, run by one worker in collection order, one scene at a time as before; every other
test (the numerical core, bags written in-process, the command line without nodes) is
shared out to the other worker beside them. Within the scene group the modules with
realtime scenes come last (:data:`REALTIME_MODULES`), so that they run when the other
worker, which has less to do, is idle: a realtime deadline is measured on a machine
that runs one scene and nothing else of the suite.
"""

from pathlib import Path

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


#: Test modules that start node processes (simulator, controller, recorder, live view,
#: launcher, replay, colcon) or DDS participants: one xdist group, one scene at a time.
SCENE_MODULES = frozenset({
    "test_actuation", "test_bagtools_analyze", "test_bagtools_replay", "test_cli",
    "test_cli_hostile", "test_closed_loop", "test_controller_node", "test_deadline_misses",
    "test_demo",
    "test_diagnostics", "test_fidelity", "test_identify", "test_launcher",
    "test_live_node", "test_ndof_nodes", "test_node_common", "test_packaging",
    "test_recorder_node", "test_recording", "test_scheduling", "test_signals",
    "test_sim_node", "test_test_cleanup",
})

#: Scene modules with realtime (wall-clock paced) scenes: last in the scene group.
REALTIME_MODULES = ("test_node_common", "test_diagnostics", "test_deadline_misses",
                    "test_bagtools_replay",
                    "test_live_node", "test_ndof_nodes", "test_actuation")


def pytest_collection_modifyitems(config, items):
    """Put the scene modules in one xdist group, the realtime ones last (module order
    kept within each, so that module-scoped scenes are set up once)."""
    here = Path(__file__).parent
    missing = sorted(m for m in SCENE_MODULES | set(REALTIME_MODULES)
                     if not (here / f"{m}.py").exists())
    if missing:
        raise pytest.UsageError(f"tests/conftest.py names test modules that do not exist: "
                                f"{missing}")
    group = pytest.mark.xdist_group("scenes")
    for item in items:
        if item.path.stem in SCENE_MODULES:
            item.add_marker(group)

    def late(item):
        stem = item.path.stem
        return REALTIME_MODULES.index(stem) + 1 if stem in REALTIME_MODULES else 0

    items.sort(key=late)        # stable: collection order within each rank

"""Session set-up shared by every test module, and how the suite uses both cores.

`make test` runs pytest on three workers over the two cores (pytest-xdist, ``-n 3 --dist
loadgroup``: the scenes' waits leave cores idle that a third worker fills, Makefile). Each
module that starts node processes or DDS participants (:data:`SCENE_MODULES`) is an
xdist group of its own (``scene:<module>``): one worker runs all of it, in collection
order, so that its module-scoped scene (or tests/test_cli.py's session-scoped commands)
is set up once; several such modules may run at once, one on each worker. The tests of a
module that share a module- or class-scoped fixture of that module (a fit, a sweep,
figures) are a group too (``shared:<module>``): split, the fixture was computed on both
workers. Every other test (the numerical core, bags written in-process, the command line
without nodes) is shared out to whichever worker is free. The controller hands out the
work in the order of the items (``--no-loadscope-reorder``; xdist's default puts the
groups with most tests first, and the realtime group then came first): the groups first,
then the single tests, which fill the workers up to about the same end (:func:`_rank`).
The tests marked ``realtime`` (their assertions hold only if the scene's answers meet
wall-clock deadlines) are in the FIFO group (``scene:fifo``, :data:`FIFO_SCENE_MODULES`),
which goes out first: a realtime scene runs its simulator and controller under
SCHED_FIFO (ros/scene_nodes.py, as a rig scene does), so the other workers' CPU-bound
tests do not delay its answers, and the group runs one such scene at a time (two at once
delayed each other on the two cores). Before, each realtime test waited at the end of
the suite until every other worker had been idle for 2 s: 50-65 s with one core mostly
idle (a CPU-bound test beside a realtime scene under normal scheduling made its answers
miss: 12 of 40 where 4 is the bound). A realtime scene whose assertions do not depend on
meeting deadlines (one that misses by design, a refused start, a signal) is not marked,
and runs with ``thread_priority`` 0 beside the rest. A module whose module-scoped scene
is realtime marks the whole module (``pytestmark``), so that the scene is set up once.

The groups are made here (:class:`GroupMender`). Found on 2026-11-28: with the pinned
pytest 9.2 and pytest-xdist 3.8 the ``xdist_group`` marks were inert: xdist's worker
turns them into a node-id suffix (``<nodeid>@<group>``) by setting ``item._nodeid``,
which pytest 9 no longer reads (its node id is ``item._id``), and it did so before this
conftest had marked anything; so ``--dist loadgroup`` scheduled like ``--dist load``: a
module's tests were split over both workers and its scene (tests/test_cli.py's
commands: 40-87 s) set up on each. tests/test_suite_layout.py
checks that a grouped test's node id carries its group.
"""

import os
import signal
import tempfile
from pathlib import Path

import pytest

from grazing_control.oscillator import kernel
from grazing_control.ros.launcher import use_profile_here

# A suite started with SIGINT ignored (a background job of a non-interactive shell, nohup)
# passes the ignore on to every process it starts, and Python installs no Ctrl-C handler
# of its own in a process that starts with SIGINT ignored: the tests that send one (the
# launcher's, the console script's, the kernel's) saw the scene run to its end, exit 0
# where 130 is the contract (2026-11-29, six tests of a suite run as `( make test & )`).
# The processes the tests start get Python's default handling back.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# The tests' own participants (their nodes, the replays' sessions) get the nodes' Fast DDS
# profile before the first of them exists (launcher.use_profile_here): a reliable writer
# then asks for acknowledgements every 50 ms, not every 3 s.
use_profile_here()


@pytest.fixture(scope="session", autouse=True)
def compiled_kernel():
    """Compile the numba kernels and the stream estimator's compiled model filters (or load
    their on-disk cache) once, before any test: in a fresh checkout the first compilation
    takes 5-20 s, which a node test's startup timeouts must not absorb. Each of the three
    pieces under a file lock of its own (:func:`_compiled_once`): the first worker to take
    it compiles and writes numba's cache, the others then load it (on a fresh clone the
    three workers compiled at once, 12.7-13.4 s each on the two cores, 2026-11-28). The
    1-DOF kernel and the n-DOF search are independent, and the workers take them in
    opposite orders, so that both compile at once on the two cores (one lock for all:
    about 13 + 10 s of the suite's start with the other workers waiting)."""
    if kernel.use_kernel():
        from grazing_control.dynamics.estimation.stream import warm_up_all

        pieces = [("kernel", kernel.warm_up), ("modal", kernel.warm_up_modal)]
        worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
        if worker[2:].isdigit() and int(worker[2:]) % 2 == 1:
            pieces.reverse()
        for name, compile_it in pieces:
            _compiled_once(name, compile_it)
        # the compiled model filters, 1-2 s each the first time: compiled_flow, and
        # with a model file compiled_modal_flow (an n-DOF controller loads them at start)
        _compiled_once("filters", warm_up_all)
    # the node zygote of this worker (ros/node_zygote.py): the nodes that the tests
    # start in this process are forked from it, not spawned, and share its imports
    # (0.4-0.55 s of CPU a node, several hundred nodes in the suite); started here, once
    # the kernels' cache is written, so that no test's timeouts absorb its start
    from grazing_control.ros import launcher, node_zygote

    node_zygote.enable()
    node_zygote.owner_zygote(launcher.node_env(), launcher.MODULES.values())


def _compiled_once(name: str, compile_it) -> None:
    """``compile_it()`` under the file lock ``grazing-compile-<name>.lock``: one worker
    compiles, the others wait and then load numba's cache."""
    import fcntl

    with open(Path(tempfile.gettempdir()) / f"grazing-compile-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        compile_it()


def _thread_scheduling(tid: int) -> tuple:
    """(policy, real-time priority, nice, CPUs) of one thread of this process."""
    return (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority,
            os.getpriority(os.PRIO_PROCESS, tid), frozenset(os.sched_getaffinity(tid)))


def _locked_kib() -> int:
    """The memory this process has locked (kB; /proc/self/status VmLck)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmLck:"):
                return int(line.split()[1])
    return 0


@pytest.fixture(autouse=True)
def scheduling_is_restored():
    """A node's scheduling options act on the whole process that builds it (ros/scheduling.py:
    SCHED_FIFO for every thread, CPU affinity, mlockall; ros/live_node.py: SCHED_IDLE for
    every thread), and some tests build nodes in the worker itself
    (tests/test_node_parameters.py's range ends: ``thread_priority`` 99, then the live
    view's ``idle``). Left so, the worker ran the rest of the suite under SCHED_IDLE, and
    so did every process it started after: on a fresh clone (2026-11-30) it got 13.7 s of
    CPU in 214 s of a pure computation while the two other workers had the cores, and a
    scene it started then waits behind every other test. Each test gets back the worker
    thread's policy, priority, nice and CPUs on every thread of the process, and unlocked
    memory if it started so."""
    if not hasattr(os, "sched_getscheduler") or not os.path.isdir("/proc/self/task"):
        yield
        return
    import threading

    before = _thread_scheduling(threading.get_native_id())
    locked = _locked_kib()
    yield
    policy, priority, nice, cpus = before
    refused = []
    for tid in (int(t) for t in os.listdir("/proc/self/task")):
        try:
            if _thread_scheduling(tid) == before:
                continue
            os.sched_setscheduler(tid, policy, os.sched_param(priority))
            os.setpriority(os.PRIO_PROCESS, tid, nice)
            os.sched_setaffinity(tid, cpus)
        except ProcessLookupError:
            pass                            # a thread that ended meanwhile
        except PermissionError as exc:      # nice back down without CAP_SYS_NICE
            refused.append(f"thread {tid}: {exc.strerror}")
    if refused:
        import warnings

        warnings.warn(f"the worker's scheduling could not be restored after this test "
                      f"({'; '.join(refused[:3])}): the tests after it run slower",
                      stacklevel=1)
    if _locked_kib() and not locked:
        import ctypes

        ctypes.CDLL(None).munlockall()


@pytest.fixture(autouse=True)
def environment_is_restored():
    """The worker's environment as each test found it. dask's LocalCluster (tests/
    test_atlas.py) sets PYTHONHASHSEED, MALLOC_TRIM_THRESHOLD_ and __DASK_PARENT_PID in
    the process that makes it, and keeps them: every process the worker started after it
    had that hash seed, and its node zygote (ros/node_zygote.py) refused every node,
    whose environment then differed from the zygote's in variables read at import time,
    so each was spawned again with its imports (0.4-0.55 s of CPU a node at normal
    speed; found on a fresh clone, 2026-11-30)."""
    own = "PYTEST_CURRENT_TEST"            # pytest's, set for each phase of the test
    before = {k: v for k, v in os.environ.items() if k != own}
    yield
    if {k: v for k, v in os.environ.items() if k != own} != before:
        current = os.environ.get(own)
        os.environ.clear()
        os.environ.update(before)
        if current is not None:
            os.environ[own] = current


@pytest.fixture(autouse=True)
def mpmath_precision_is_restored():
    """mpmath's working precision is global: the reference modules set 50 digits at
    import, and a test that set it to 20 without restoring it (tests/reference_hertz.py
    before) made 118 tests that ran after it on the same worker fail against their
    references. Each test gets back the precision it started with."""
    import mpmath

    prec = mpmath.mp.prec
    yield
    mpmath.mp.prec = prec


# Processes a test leaves behind (a launcher and its scene after a failed assertion, a
# node whose test timed out) are ended here, also when the test failed: no test may leak
# a process into the next ones (issue 19: an unbounded scene ran on for 14 minutes).
# multiprocessing's own helpers (resource tracker, forkserver) live for the session.
_SESSION_HELPERS = ("multiprocessing.resource_tracker", "multiprocessing.forkserver",
                    "grazing_control.ros.node_zygote")


def _descendants(pid: int) -> list[int] | None:
    """Every descendant of ``pid``, from the kernel's per-thread lists of children
    (/proc/PID/task/TID/children): a few reads, where psutil's ``children`` read the
    stat file of every process on the host after each test (1.1 % of the workers' CPU
    in a suite's profile, 2026-11-30). None where the kernel has no such lists."""
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        try:
            threads = os.listdir(f"/proc/{parent}/task")
        except OSError:             # gone meanwhile
            continue
        for tid in threads:
            try:
                with open(f"/proc/{parent}/task/{tid}/children", "rb") as f:
                    kids = [int(k) for k in f.read().split()]
            except FileNotFoundError:
                if parent == pid and not os.path.exists(f"/proc/{pid}/task/{tid}"):
                    continue        # the thread ended meanwhile
                if parent == pid:
                    return None     # no CONFIG_PROC_CHILDREN
                continue
            except OSError:
                continue
            found += kids
            todo += kids
    return found


def _leftover_processes():
    import psutil

    pids = _descendants(os.getpid())
    children = psutil.Process().children(recursive=True) if pids is None else pids
    found = []
    for child in children:
        try:
            child = child if pids is None else psutil.Process(child)
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
    "test_actuation", "test_answer_port", "test_bagtools_analyze", "test_bagtools_replay", "test_cli",
    "test_cli_hostile", "test_closed_loop", "test_composed", "test_contact_plant",
    "test_controller_node", "test_deadline_misses",
    "test_demo", "test_diagnostics", "test_fidelity", "test_identify", "test_launcher",
    "test_live_node", "test_message_wait", "test_ndof_identify", "test_ndof_nodes",
    "test_ndof_watch_scene",
    "test_ndof_drift_scene",
    "test_node_common",
    "test_node_zygote", "test_packaging",
    "test_parameter_files_hostile",
    "test_recorder_node", "test_recording", "test_reidentify_ndof_scene",
    "test_rig_drivers", "test_rig_masses_scene",
    "test_rig_scene", "test_rig_stop", "test_rig_wrong_model",
    "test_scheduling",
    "test_signals",
    "test_sim_node", "test_stall_pause_scene", "test_stop_fidelity", "test_stop_selection",
    "test_stream_block",
    "test_stream_replay",
    "test_test_cleanup",
})

#: Scene modules whose simulator and controller run under SCHED_FIFO (a rig scene's
#: thread_priority, ros/scene_nodes.py): one group, so that two such scenes never run at
#: once on the two cores (a FIFO process waits only for FIFO ones: with a helper's rig
#: scene beside test_rig_stop's, its simulator's sample 3 went out 4.2 s late, the
#: watchdog ended the scene, 2026-11-28).
#: test_scheduling and test_sim_node start nodes under SCHED_FIFO with locked memory
#: (their scheduling options' tests), and test_signals starts 120 busy processes at once:
#: on two fresh clones a rig scene beside them (test_signals' storm in both) had its
#: simulator's sample 6-7 go out 3.1-3.5 s late (rerun once each, 2026-11-28).
FIFO_SCENE_MODULES = frozenset({"test_rig_masses_scene", "test_rig_scene", "test_rig_stop",
                                "test_rig_wrong_model", "test_scheduling", "test_signals",
                                "test_sim_node"})


def pytest_configure(config):
    config.pluginmanager.register(GroupMender(), "grazing-group-mender")
    config.addinivalue_line(
        "markers", "realtime: a realtime scene whose assertions need its answers to meet "
                   "wall-clock deadlines: its nodes under SCHED_FIFO, in the FIFO group "
                   "(conftest.py)")


def is_realtime(item) -> bool:
    return item.get_closest_marker("realtime") is not None


def _shares_a_module_fixture(item) -> bool:
    """The test uses a module- or class-scoped fixture of its own module (a fit, a
    sweep, figures computed once for the module's tests): split over both workers, that
    fixture was computed on each (tests/test_actuator.py's: 83.9 s and 83.7 s of setup,
    one on each worker, at load 13; docs/benchmarks.md, "The suite")."""
    module = item.getparent(pytest.Module).nodeid
    for defs in item._fixtureinfo.name2fixturedefs.values():
        for d in defs:
            # where the fixture is defined: its node (pytest 9; baseid, the node id as
            # a string, is deprecated)
            where = d.node.nodeid if getattr(d, "node", None) is not None else d.baseid
            if d.scope in ("module", "class") and (where or "").startswith(module):
                return True
    return False


#: The group of the scenes under SCHED_FIFO (rig scenes, realtime tests, the scheduling
#: options' tests): one worker, one scene at a time.
FIFO_GROUP = "scene:fifo"


def xdist_group(item) -> str | None:
    """The xdist group of a test: :data:`FIFO_GROUP` (:data:`FIFO_SCENE_MODULES` and the
    tests marked realtime), ``scene:<module>``, ``shared:<module>``
    (:func:`_shares_a_module_fixture`) or none."""
    if is_realtime(item) or item.path.stem in FIFO_SCENE_MODULES:
        return FIFO_GROUP
    if item.path.stem in SCENE_MODULES:
        return f"scene:{item.path.stem}"
    if _shares_a_module_fixture(item):
        return f"shared:{item.path.stem}"
    return None


def _rank(item) -> int:
    """The order in which the controller hands out the work: the FIFO group first (the
    longest one worker runs alone, 100-200 s), then the other groups (a group is one
    unit, up to ~100 s: handed out late, as test_stop_selection's was in collection
    order, it kept one worker busy while the others were done), then the single tests
    (they fill the workers up to about the same end)."""
    group = xdist_group(item)
    if group == FIFO_GROUP:
        return 0
    return 1 if group is not None else 2


def pytest_collection_modifyitems(config, items):
    """Mark each test with its xdist group (:func:`xdist_group`); the FIFO group first,
    then the other groups, then the single tests (:func:`_rank`; collection order kept
    within each, so that module-scoped scenes are set up once)."""
    for item in items:
        group = xdist_group(item)
        if group is not None:
            item.add_marker(pytest.mark.xdist_group(group))
    items.sort(key=_rank)              # stable: collection order within each rank


class GroupMender:
    """On an xdist worker with ``--dist loadgroup``: suffix each grouped test's node id
    with ``@<group>`` (``_id``, what pytest 9 reads), as xdist 3.8 means to and pytest 8
    let it: the controller's ``loadgroup`` scheduling reads the group from the suffix.
    (xdist's own suffix, ``item._nodeid``, is lost, and came before this conftest's marks
    anyway: this hook runs last.)"""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, config, items):
        from _pytest.nodeid import coerce_node_id

        if getattr(config, "workerinput", None) is None or not config.getvalue("loadgroup"):
            return
        for item in items:
            group = xdist_group(item)
            if group is not None and not item.nodeid.endswith("@" + group):
                item._id = coerce_node_id(f"{item.nodeid}@{group}")

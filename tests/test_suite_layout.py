"""How `make test` shares the suite between its workers (tests/conftest.py) names real
modules, every module that starts a node process is a scene module, and the groups take
effect."""

import re
from pathlib import Path

import conftest
import pytest

HERE = Path(__file__).parent

#: What a module calls when it starts node processes or a scene (launcher, console
#: scripts, `grazing run`, ros2 launch, colcon).
STARTS_NODES = re.compile(r"launcher\.run\(|start_node\(|run_(rig_)?scene\(|node_command\(|"
                          r"script\(\"(sim|controller|recorder|live)_node\"\)|"
                          r"\[\"run\"|colcon")


def test_the_scene_group_names_existing_modules():
    modules = {p.stem for p in HERE.glob("test_*.py")}
    assert conftest.SCENE_MODULES <= modules, conftest.SCENE_MODULES - modules


def test_the_realtime_tests_are_scene_tests():
    """A test marked realtime runs its nodes under SCHED_FIFO in the FIFO group: it must
    be a scene module's, and the marker must be in use."""
    marked = {p.stem for p in HERE.glob("test_*.py")
              if p.stem != "test_suite_layout" and "pytest.mark.realtime" in p.read_text()}
    assert marked, "no test is marked realtime: the marker no longer matches the tests"
    assert marked <= conftest.SCENE_MODULES, marked - conftest.SCENE_MODULES


def test_every_module_that_starts_nodes_is_in_the_scene_group():
    """A module that starts nodes and is not a scene module would have its tests split
    over both workers, its module-scoped scene set up on each."""
    starts = {p.stem for p in HERE.glob("test_*.py")
              if p.stem != "test_suite_layout" and STARTS_NODES.search(p.read_text())}
    assert starts, "the pattern finds no module: it no longer matches the tests"
    assert starts <= conftest.SCENE_MODULES, starts - conftest.SCENE_MODULES


#: A thread_priority of 1..99 given to a node, in a test's source.
FIFO_PRIORITY = re.compile(r"thread_priority[\"']?\s*(:=|:|=)\s*[1-9]")
#: A scene in realtime mode, in a test's source (launcher, grazing run).
REALTIME_SCENE = re.compile(r"[\"']mode[\"']: [\"']realtime|mode=[\"']realtime|"
                            r"[\"']--mode[\"'], [\"']realtime|mode:=realtime")


def test_the_rig_scenes_share_one_worker():
    """A rig scene runs its simulator and controller under SCHED_FIFO, and so do the
    scheduling options' tests: every module that launches one (``rig=``) or sets a
    thread_priority of 1..99 is in conftest.FIFO_SCENE_MODULES, one group, one worker."""
    rig = {p.stem for p in HERE.glob("test_*.py") if p.stem != "test_suite_layout"
           and (re.search(r"run_rig_scene\(|\brig=str\(", p.read_text())
                or FIFO_PRIORITY.search(p.read_text()) and STARTS_NODES.search(p.read_text()))}
    assert rig, "the pattern finds no module: it no longer matches the tests"
    assert rig <= conftest.FIFO_SCENE_MODULES <= conftest.SCENE_MODULES, rig


#: Scene modules that name the realtime mode but start no realtime scene through
#: scene_nodes (no default priority), and why.
NO_REALTIME_SCENE = {
    "test_contact_plant": "the realtime loop's settings in the core, no node",
    "test_node_common": "a simulator started alone (launcher.node_command): no scene"}


def test_a_realtime_scene_outside_the_fifo_group_is_told_not_to_use_it():
    """A realtime scene runs its nodes under SCHED_FIFO unless told otherwise
    (ros/scene_nodes.py): a scene module outside the FIFO group that starts one either
    marks its tests realtime (they run in the FIFO group) or gives thread_priority 0
    (misses by design, a refused start: beside the other scenes). Only a module's text
    is read: a module with both kinds must say 0 where it starts the unmarked ones."""
    modules = {p.stem: p.read_text() for p in HERE.glob("test_*.py")
               if p.stem in conftest.SCENE_MODULES - conftest.FIFO_SCENE_MODULES
               and p.stem not in NO_REALTIME_SCENE}
    realtime = {m for m, text in modules.items() if REALTIME_SCENE.search(text)}
    assert realtime, "the pattern finds no module: it no longer matches the tests"
    told = {m for m in realtime if "pytest.mark.realtime" in modules[m]
            or re.search(r"thread_priority[\"']?\s*(:=|:|=)\s*0\b", modules[m])}
    assert realtime <= told, realtime - told


def test_a_grouped_test_carries_its_group_in_its_node_id(request):
    """Under xdist (``make test``) a scene module's test id ends with ``@scene:<module>``:
    the controller schedules the group as one unit (conftest.GroupMender; with pytest 9.2
    and xdist 3.8 the suffix was lost and the groups were inert). Without xdist no
    suffix is made; this module is no scene module, so it checks a sibling's item."""
    assert conftest.xdist_group(request.node) is None
    items = [i for i in request.session.items if conftest.xdist_group(i) is not None]
    if getattr(request.config, "workerinput", None) is None:
        assert all("@" not in i.nodeid for i in items)
        return
    assert items, "no grouped test was collected beside this one"
    for item in items:
        assert item.nodeid.endswith("@" + conftest.xdist_group(item)), item.nodeid


@pytest.fixture(scope="module")
def computed_once():
    """A module-scoped fixture of this module, as a fit or a sweep is elsewhere."""
    return object()


def test_the_tests_sharing_a_module_fixture_are_one_group_and_the_groups_come_first(
        request, computed_once):
    """A test that uses a module-scoped fixture of its module is grouped with the
    module's other such tests (``shared:<module>``: the fixture computed on one worker,
    not on both); the items are in the order the controller hands them out: the groups,
    the FIFO group first, then the other groups, then the single tests (conftest._rank)."""
    assert conftest.xdist_group(request.node) == "shared:test_suite_layout"
    ranks = [conftest._rank(i) for i in request.session.items]
    assert ranks == sorted(ranks), ranks


@pytest.fixture(scope="class")
def worker():
    """The worker's scheduling before a class's first test, and what that test applied."""
    import threading

    return {"before": conftest._thread_scheduling(threading.get_native_id()),
            "locked": conftest._locked_kib(), "applied": ()}


class TestANodeBuiltInTheWorkerLeavesItsSchedulingBehind:
    """A node's scheduling options change the process that builds it (conftest.py,
    ``scheduling_is_restored``): the next test runs as the worker ran before. The two
    tests share a class fixture, so one worker runs both, in this order."""

    def test_the_live_views_idle_priority_and_a_rig_nodes_options_are_applied(self, worker):
        import os

        from grazing_control.ros.live_node import lower_priority
        from grazing_control.ros.scheduling import apply_scheduling

        cpus = sorted(os.sched_getaffinity(0))
        worker["applied"] = apply_scheduling(cpus=cpus[:1], lock_memory=True).applied
        lower_priority("idle")
        tids = [int(t) for t in os.listdir("/proc/self/task")]
        assert all(os.sched_getscheduler(t) == os.SCHED_IDLE for t in tids)

    def test_the_next_test_runs_as_the_worker_ran_before(self, worker):
        import os

        tids = [int(t) for t in os.listdir("/proc/self/task")]
        now = {t: conftest._thread_scheduling(t) for t in tids}
        assert all(s == worker["before"] for s in now.values()), (worker["before"], now)
        if "memory locked (mlockall)" in worker["applied"] and not worker["locked"]:
            assert conftest._locked_kib() == 0


class TestATestLeavesTheEnvironmentAsItFoundIt:
    """What a library sets in ``os.environ`` during a test (dask's LocalCluster:
    PYTHONHASHSEED, MALLOC_TRIM_THRESHOLD_, ...) is gone for the next test (conftest.py,
    ``environment_is_restored``), so the worker's node zygote still takes its nodes. One
    worker runs both tests, in this order (a class fixture)."""

    def test_a_test_sets_and_removes_variables(self, worker):
        import os

        worker["environment"] = {k: v for k, v in os.environ.items()
                                 if k != "PYTEST_CURRENT_TEST"}
        os.environ["PYTHONHASHSEED"] = "6640"
        os.environ["__DASK_PARENT_PID"] = str(os.getpid())
        os.environ.pop("HOME", None)

    def test_the_next_test_has_the_environment_of_the_one_before(self, worker):
        import os

        assert {k: v for k, v in os.environ.items()
                if k != "PYTEST_CURRENT_TEST"} == worker["environment"]

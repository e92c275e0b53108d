"""The scene's node parameters (grazing_control/ros/scene_nodes.py): who runs under
SCHED_FIFO. A scene about deadlines (realtime, or a rig's) runs its simulator and its
controller under SCHED_FIFO unless told otherwise; a lockstep scene leaves scheduling
alone."""

import pytest

from grazing_control.ros.scene_nodes import REALTIME_THREAD_PRIORITY, scene_overrides

RIG = "config/rigs/acceptance.yaml"


def _priorities(**kwargs):
    over = scene_overrides(None, periods=10, **kwargs)
    return (over["sim_node"].get("thread_priority"),
            over["controller_node"].get("thread_priority"))


@pytest.mark.parametrize("how", [{"mode": "realtime"},
                                 {"sim_overrides": {"mode": "realtime"}},
                                 {"rig": RIG}])
def test_a_realtime_or_rig_scene_runs_both_nodes_under_sched_fifo(how):
    assert REALTIME_THREAD_PRIORITY in range(1, 100)
    assert _priorities(**how) == (REALTIME_THREAD_PRIORITY, REALTIME_THREAD_PRIORITY)


@pytest.mark.parametrize("how", [{}, {"mode": "lockstep"},
                                 {"sim_overrides": {"mode": "lockstep"}}])
def test_a_lockstep_scene_leaves_scheduling_alone(how):
    assert _priorities(**how) == (None, None)


@pytest.mark.parametrize("how", [{"mode": "realtime"}, {"rig": RIG}])
def test_the_controllers_zero_turns_it_off_for_both_and_the_simulators_own_wins(how):
    assert _priorities(**how, controller_overrides={"thread_priority": 0}) == (0, 0)
    assert _priorities(**how, sim_overrides={"thread_priority": 7}) == (
        7, REALTIME_THREAD_PRIORITY)
    assert _priorities(**how, controller_overrides={"thread_priority": 20}) == (20, 20)

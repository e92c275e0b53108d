"""When sim_node starts (sim_node/start.py): what its start line tells."""


def test_a_realtime_scene_says_at_its_start_how_long_it_will_take():
    """`grazing run --mode realtime --periods 50` at time_scale 1 took 471 s of wall time
    and said so nowhere: the start line now gives max_periods x T / time_scale; a
    lockstep or an unbounded scene says nothing of it."""
    from types import SimpleNamespace as S

    from sim_node.start import wall_time

    T = 9.418185242872688
    line = wall_time(S(mode="realtime", max_periods=50, time_scale=1.0), T)
    assert line == ", 50 periods at time_scale 1: about 471 s of wall time", line
    assert "about 0.471 s" in wall_time(S(mode="realtime", max_periods=50, time_scale=1000.0), T)
    assert wall_time(S(mode="lockstep", max_periods=50, time_scale=1.0), T) == ""
    assert wall_time(S(mode="realtime", max_periods=0, time_scale=1.0), T) == ""

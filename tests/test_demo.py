"""demo: its bags are replaced, not refused, on a second run (``make demo`` twice).

Through the real nodes with a cheap scene (100 periods) instead of the study's 1300,
so that the test takes seconds: the second run replaces the first run's bag; a run
that fails leaves the previous bag as it was.
"""

from __future__ import annotations

from grazing_control.studies import demo
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros.recording import read_metadata
from test_closed_loop import CONTROLLER


def test_second_run_replaces_the_bag_and_a_failed_run_keeps_it(tmp_path):
    p = OscillatorParams(delta_d=-5e-6)
    bag = tmp_path / "bags" / "scene_5e-6"
    demo._run_nodes(p, CONTROLLER, bag, 60)
    first = read_metadata(bag)
    demo._run_nodes(p, CONTROLLER, bag, 80)            # used to fail: bag not empty
    second = read_metadata(bag)
    assert (first["message_count"], second["message_count"]) != (0, 0)
    pi2 = {e["topic_metadata"]["name"]: e["message_count"]
           for e in second["topics_with_message_count"]}["/oscillator/pi2"]
    assert pi2 == 80 and sorted(f.name for f in bag.iterdir()) == \
        ["metadata.yaml", "scene_5e-6_0.mcap"]
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    saturation: -1.0\n")
    try:
        demo._run_nodes(p, bad, bag, 50)
    except RuntimeError as exc:
        assert "controller_node=2" in str(exc)
    else:
        raise AssertionError("a refused controller must fail the scene")
    assert read_metadata(bag) == second                   # the previous bag, untouched
    assert [f.name for f in bag.parent.iterdir()] == ["scene_5e-6"]   # no leftovers

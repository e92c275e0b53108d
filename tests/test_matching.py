"""ros/matching.py: the controller says what its own ends matched; the simulator starts
only once both ends of each match are made (sim_node.start.missing_matches)."""

from __future__ import annotations

import random
import string
from types import SimpleNamespace

from grazing_control.ros.matching import MATCHED_TOPIC, parse_report, report_text
from sim_node.start import missing_matches


def test_a_report_reads_back_as_its_counts():
    for counts in [{"answers": 0},
                   {"answers": 2, "/oscillator/pi2": 1},
                   {"answers": 10**6, "/ns/rig/sensor": 1, "/rig/phase": 0}]:
        assert parse_report(report_text(counts)) == counts


def test_any_other_text_is_no_report():
    """Fuzz: 5000 seeded strings (and near misses of the format) parse to None, never
    raise; only the exact form is a report."""
    rng = random.Random(30)
    near = ["outputs=1", "/rig/phase=1", "answers=x", "answers=-1", "answers=1  /rig/phase=1",
            "answers=1 ", "answers=1 answers=2", "answers=1 rig/phase=1",
            "answers=1 /rig phase=1", "answers=1 /rig/phase=1 /rig/phase=1",
            "", None, 3, b"answers=1"]
    for text in near:
        assert parse_report(text) is None, text
    alphabet = string.printable + "é\x00"
    for _ in range(5000):
        text = "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 40)))
        got = parse_report(text)
        assert got is None or report_text(got) == text


class _Pub:
    def __init__(self, topic, readers):
        self.topic_name, self.readers = topic, readers

    def get_subscription_count(self):
        return self.readers


def _sim(report, reporting=1, readers=2, miss_readers=1):
    """A simulator's side as missing_matches reads it: lockstep, no stream, Pi2 read by
    ``readers``, deadline_miss (not among the recorded_publishers) by ``miss_readers``."""
    pi2, miss = _Pub("/oscillator/pi2", readers), _Pub("/oscillator/deadline_miss",
                                                       miss_readers)
    others = [_Pub(t, 1) for t in ("/oscillator/impact", "/oscillator/pi1", "/clock",
                                   "/oscillator/state")]
    return SimpleNamespace(controller_matched=report,
                           resolve_topic_name=lambda topic: "/" + topic,
                           count_publishers=lambda topic: reporting,
                           published=SimpleNamespace(publishers=[pi2, miss, *others]),
                           pub_impact=others[0], pub_pi1=others[1], pub_pi2=pi2,
                           pub_clock=others[2], pub_state=others[3], driver=None,
                           settings=SimpleNamespace(state_period=0.0, mode="lockstep"))


def test_the_simulator_waits_for_both_ends_of_the_controller():
    ok = {"answers": 2, "/oscillator/pi2": 1}
    # no report and nobody to send one: a controller of another package, not asked
    assert missing_matches(_sim(None, reporting=0), 1) is None
    # a controller of this package that has not reported yet: wait for it
    assert MATCHED_TOPIC in missing_matches(_sim(None), 1)
    # its answers short of this node and the recorder
    assert "answers=1" in missing_matches(_sim({**ok, "answers": 1}), 1)
    # a topic it reads: matched at its end but not yet by this node's writer to it
    # and the recorder, or the other way round
    assert "this node's writer 1 of 2" in missing_matches(_sim(ok, readers=1), 1)
    assert "its reader 0 publisher(s)" in missing_matches(_sim({**ok, "/oscillator/pi2": 0}), 1)
    # a topic of this node it does not read is not asked (state has 1 reader of 2)
    assert missing_matches(_sim(ok), 1) is None
    # a topic it reads that the recorders are not asked to read: its reader alone
    on_miss = {**ok, "/oscillator/deadline_miss": 1}
    assert missing_matches(_sim(on_miss, miss_readers=1), 1) is None
    assert "deadline_miss" in missing_matches(_sim(on_miss, miss_readers=0), 1)
    # without recorders (n = 0): the controller and this node alone
    assert missing_matches(_sim({"answers": 1, "/oscillator/pi2": 1}, readers=1), 0) is None
    # every lack named, as one item of the start's list (items are joined by "; ")
    worst = missing_matches(_sim({"answers": 0, "/oscillator/pi2": 0}, readers=0), 1)
    assert ";" not in worst and "answers=0" in worst and "/oscillator/pi2" in worst


"""ros/matching.py: the controller says what its own ends matched; the simulator starts
only once both ends of each match are made (sim_node.start.missing_matches)."""

from __future__ import annotations

import random
import string
from types import SimpleNamespace

from grazing_control.ros.matching import MATCHED_TOPIC, parse_report, report_text
from sim_node.start import missing_matches


def test_a_report_reads_back_as_its_counts():
    for inputs, answers in [(0, 0), (1, 1), (3, 12), (10**6, 7)]:
        assert parse_report(report_text(inputs, answers)) == (inputs, answers)


def test_any_other_text_is_no_report():
    """Fuzz: 5000 seeded strings (and near misses of the format) parse to None, never
    raise; only the exact form is a report."""
    rng = random.Random(30)
    near = ["inputs=1", "answers=1 inputs=1", "inputs=-1 answers=1", "inputs=1 answers=x",
            "inputs=1  answers=1", "", None, 3, b"inputs=1 answers=1", "inputs=1 answers=1 z"]
    for text in near:
        assert parse_report(text) is None, text
    alphabet = string.printable + "é\x00"
    for _ in range(5000):
        text = "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 30)))
        got = parse_report(text)
        assert got is None or report_text(*got) == text.strip()


def _sim(report, publishers):
    return SimpleNamespace(controller_matched=report,
                           resolve_topic_name=lambda topic: "/" + topic,
                           count_publishers=lambda topic: publishers)


def test_the_simulator_waits_for_both_ends_of_the_controller():
    # no report and nobody to send one: a controller of another package, not asked
    assert missing_matches(_sim(None, 0), 0) is None
    # a controller of this package that has not reported yet: wait for it
    assert MATCHED_TOPIC in missing_matches(_sim(None, 1), 0)
    # its inputs not matched yet, or its answers not to this node and the n recorders
    assert "inputs=0" in missing_matches(_sim((0, 1), 1), 0)
    assert "answers=1" in missing_matches(_sim((1, 1), 1), 1)
    assert "2 reader(s)" in missing_matches(_sim((1, 1), 1), 1)
    # matched both ways: nothing missing
    assert missing_matches(_sim((1, 2), 1), 1) is None
    assert missing_matches(_sim((2, 5), 1), 1) is None

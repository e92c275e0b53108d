"""The controller's half of the start handshake: what its own ends have matched.

Each end of a DDS match sees it on its own: a subscription that counts a publisher
(``get_publisher_count``) says nothing of whether that publisher has matched it back,
and a message published before *both* ends matched can be lost for good (a volatile
writer sends nothing to a reader it has not matched yet; Fast DDS's volatile reader
that matches a writer late skips what that writer sent before). The simulator checks
its own ends before the start (sim_node.start.missing); what only the controller can
see, it says on ``controller/matched`` (std_msgs/String, latched): the least number of
publishers any of its input subscriptions has matched, and the number of subscriptions
its answer publisher has matched, as ``inputs=<k> answers=<m>`` (:func:`report_text`).
The simulator waits for ``inputs >= 1`` and ``answers >= n + 1`` (itself and n
recorders); a test that plays the simulator waits for the same (tests/test_closed_loop
``Collector.controller_matched``). Measured under load before this (issue 30, CI): a
controller's first answers, or the first stream sample, lost in 3 scenes of a suite run.

The counts are polled (:data:`MATCH_CHECK`) between the executor's waits rather than
taken from matched-event callbacks: each event handler is one more entity in every wait
of the answer path.
"""

from __future__ import annotations

import re

from std_msgs.msg import String

from .common import LATCHED_QOS

__all__ = ["MATCHED_TOPIC", "MATCH_CHECK", "MatchReport", "parse_report", "report_text"]

#: Latched topic on which controller_node says what its ends have matched.
MATCHED_TOPIC = "controller/matched"

#: Wall seconds between two looks at the match counts (a few us each).
MATCH_CHECK = 0.02

_REPORT = re.compile(r"inputs=(\d+) answers=(\d+)")


def report_text(inputs: int, answers: int) -> str:
    """The report's text: ``inputs=<k> answers=<m>``."""
    return f"inputs={int(inputs)} answers={int(answers)}"


def parse_report(text: str) -> tuple[int, int] | None:
    """(inputs, answers) of a report's text, None for any other text."""
    m = _REPORT.fullmatch(text.strip()) if isinstance(text, str) else None
    return (int(m.group(1)), int(m.group(2))) if m else None


class MatchReport:
    """Publishes the match counts of ``inputs`` (subscriptions) and ``answers`` (the
    publisher the simulator reads) whenever they change, looking at most every
    :data:`MATCH_CHECK` s (:meth:`poll`, from the node's spin loop). Made before the
    node's data endpoints, so that a peer that has discovered the answer publisher has
    discovered this one too (one ordered discovery stream of publications); the ends
    are named with :meth:`watch` once they exist."""

    def __init__(self, node):
        self.pub = node.create_publisher(String, MATCHED_TOPIC, LATCHED_QOS)
        self.inputs = []
        self.answers = None
        self.last = None
        self._next = 0.0

    def watch(self, inputs, answers) -> None:
        """The input subscriptions and the answer publisher whose matches are said."""
        self.inputs, self.answers = list(inputs), answers

    def counts(self) -> tuple[int, int]:
        """(least publishers matched over the inputs, subscriptions the answers matched)."""
        inputs = min((sub.get_publisher_count() for sub in self.inputs), default=0)
        return inputs, self.answers.get_subscription_count()

    def poll(self, now: float) -> None:
        """Look at the counts when due (``now``: time.monotonic()); publish a change."""
        if now < self._next or self.answers is None:
            return
        self._next = now + MATCH_CHECK
        counts = self.counts()
        if counts != self.last:
            self.last = counts
            self.pub.publish(String(data=report_text(*counts)))

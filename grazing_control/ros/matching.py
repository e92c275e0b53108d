"""The controller's half of the start handshake: what its own ends have matched.

Each end of a DDS match sees it on its own: a subscription that counts a publisher
(``get_publisher_count``) says nothing of whether that publisher has matched it back,
and a message published before *both* ends matched can be lost for good (a volatile
writer sends nothing to a reader it has not matched yet; Fast DDS's volatile reader
that matches a writer late skips what that writer sent before). The simulator checks
its own ends before the start (sim_node.start.missing_matches); what only the
controller can see, it says on ``controller/matched`` (std_msgs/String, latched), as
``key=count`` words (:func:`report_text`):

* ``answers``: the subscriptions its answer publisher has matched (the simulator and
  the n subscribers of every data topic that ``wait_for_subscribers`` asks for: the
  recorders);
* one word per topic it reads, by its fully qualified name (``/oscillator/pi2=1``): the
  publishers that subscription has matched.

The simulator waits for ``answers >= n + 1`` and, on each topic it publishes that the
controller reads, a publisher matched at the controller's end and ``n + 1`` readers at
its own; a test that plays the simulator
waits for the same on the topics it publishes (tests/test_closed_loop
``Collector.controller_matched``). Measured under load before this (issue 30, CI): a
controller's first answers, or the first stream sample, lost in the tests that play
the simulator.

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

#: The words every report has.
REQUIRED = ("answers",)

_WORD = re.compile(r"(answers|/[A-Za-z0-9_/~]+)=(\d+)")


def report_text(counts: dict) -> str:
    """The report's text: ``answers=<m> /topic=<k> ...`` (``counts``: those words to their
    counts)."""
    return " ".join(f"{k}={int(v)}" for k, v in counts.items())


def parse_report(text) -> dict | None:
    """{word: count} of a report's text; None for any other text (a word of another
    form, a repeated word, or ``answers`` missing)."""
    if not isinstance(text, str):
        return None
    out = {}
    for word in text.split(" "):
        m = _WORD.fullmatch(word)
        if m is None or m.group(1) in out:
            return None
        out[m.group(1)] = int(m.group(2))
    return out if all(k in out for k in REQUIRED) else None


class MatchReport:
    """Publishes the match counts (module docstring) whenever they change, looking at
    most every :data:`MATCH_CHECK` s (:meth:`poll`, from the node's spin loop). Made
    before the node's data endpoints, so that a peer that has discovered the answer
    publisher has discovered this one too (one ordered discovery stream of
    publications); the ends are named with :meth:`watch` once they exist."""

    def __init__(self, node):
        self.pub = node.create_publisher(String, MATCHED_TOPIC, LATCHED_QOS)
        self.inputs = []
        self.answers = None
        self.last = None
        self._next = 0.0

    def watch(self, inputs, answers) -> None:
        """The subscriptions of the topics read (``inputs``) and the answer publisher
        whose matches are said."""
        self.inputs, self.answers = list(inputs), answers

    def counts(self) -> dict:
        """The report's words and their counts (module docstring)."""
        counts = {"answers": self.answers.get_subscription_count()}
        for sub in self.inputs:
            counts[sub.topic_name] = sub.get_publisher_count()
        return counts

    def poll(self, now: float) -> None:
        """Look at the counts when due (``now``: time.monotonic()); publish a change."""
        if now < self._next or self.answers is None:
            return
        self._next = now + MATCH_CHECK
        counts = self.counts()
        if counts != self.last:
            self.last = counts
            self.pub.publish(String(data=report_text(counts)))

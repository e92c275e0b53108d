"""What a node published: counted publishers and the published record it leaves at exit.

A recorder that falls behind (a loaded machine, issue 27) may still be taking the last
messages of a scene when the scene ends; if it stops then, the bag lacks its tail, and a
tail is invisible to the check by sequence numbers (a gap needs a later message). So each
node of the package counts what it publishes on its recorded topics (:class:`Counted`)
and, when it stops, says so on ``grazing/published``
(:func:`grazing_control.ros.recording.record.encode_published`, reliable, transient
local) and waits until every reliable reader has acknowledged its messages
(:func:`close_publishers`). The recorder waits for those counts before it closes and
names what is missing (ros/recorder_node.py); the analysis compares the bag with them
(docs/recording.md, "Completeness").
"""

from __future__ import annotations

import time

from rclpy.duration import Duration

from .common import LATCHED_QOS
from .recording.record import PUBLISHED_TOPIC, encode_published

__all__ = ["ACK_TIMEOUT", "Counted", "PublishedRecord", "close_publishers"]

#: Wall seconds a node waits at exit for every reliable reader to acknowledge every
#: message (a recorder that lags behind gets the rest from the node's history).
ACK_TIMEOUT = 10.0


class Counted:
    """A publisher that counts its messages (``count``); everything else is the wrapped
    rclpy publisher's (``topic_name``, ``wait_for_all_acked``, ...)."""

    def __init__(self, publisher):
        self._publisher = publisher
        self.count = 0

    def publish(self, msg) -> None:
        self._publisher.publish(msg)
        self.count += 1

    def __getattr__(self, name):
        return getattr(self._publisher, name)


class PublishedRecord:
    """The node's ``grazing/published`` publisher and the counted publishers it reports."""

    def __init__(self, node, publishers):
        from std_msgs.msg import String

        self.node = node
        self.publishers = list(publishers)
        self._msg = String
        self.pub = node.create_publisher(String, PUBLISHED_TOPIC, LATCHED_QOS)
        self.sent = False

    def counts(self) -> dict:
        """Fully qualified topic -> messages published on it."""
        return {p.topic_name: p.count for p in self.publishers}

    def publish(self) -> None:
        self.pub.publish(self._msg(data=encode_published(
            self.node.get_fully_qualified_name(), self.counts())))
        self.sent = True


def close_publishers(record: PublishedRecord, timeout: float, also=(),
                     warn: bool = True) -> list:
    """Publish the record, then wait (``timeout`` wall seconds at most in all) until every
    reliable reader has acknowledged every message of the counted publishers, of the
    record and of the publishers ``also``. Returns the topics not acknowledged in time
    (logged in one warning if ``warn``)."""
    record.publish()
    end = time.monotonic() + timeout
    late = []
    for pub in [*record.publishers, record.pub, *also]:
        left = max(0.0, end - time.monotonic())
        if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
            late.append(pub.topic_name)
    if late and warn:
        record.node.get_logger().warning(
            f"not every message acknowledged at exit within {timeout:g} s: {', '.join(late)} "
            "(a reader that lags, or one that has gone)")
    return late

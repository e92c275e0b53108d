"""What a node published: counted publishers and the published record it leaves at exit.

A recorder that falls behind (a loaded machine, issue 27) may still be taking the last
messages of a scene when the scene ends; if it stops then, the bag lacks its tail, and a
tail is invisible to the check by sequence numbers (a gap needs a later message). So each
node of the package counts what it publishes on its recorded topics (:class:`Counted`)
and, when it stops, says so on ``grazing/published``
(:func:`grazing_control.ros.recording.record.encode_published`, reliable, transient
local) and waits until its messages are safe (:func:`close_publishers`): every reliable
reader has acknowledged them, or a recorder has said on ``recorder/complete`` that it holds
them all (:class:`RecorderConfirmation`). The recorder waits for those counts before it
closes and names what is missing (ros/recorder_node.py); the analysis compares the bag
with them (docs/recording.md, "Completeness").
"""

from __future__ import annotations

import time

from rclpy.duration import Duration

from .common import LATCHED_QOS
from .recording.record import PUBLISHED_TOPIC, encode_published

__all__ = ["ACK_TIMEOUT", "COMPLETE_TOPIC", "Counted", "PublishedRecord", "close_publishers",
           "RecorderConfirmation"]

#: Latched topic (std_msgs/String, a JSON list of node names) on which recorder_node says
#: whose published records it holds in full: a node that waits for it waits for the
#: recorder, not for every reader (a simulator that has gone stays matched for its DDS
#: lease, 20 s, and would make wait_for_all_acked time out).
COMPLETE_TOPIC = "recorder/complete"

#: Wall seconds a node waits at exit for every reliable reader to acknowledge every
#: message (a recorder that lags behind gets the rest from the node's history).
ACK_TIMEOUT = 10.0
#: Wall seconds a node stays after the recorder's confirmation: its reader acknowledges the
#: confirmation at the writer's next heartbeat (fastdds_profile.xml: every 5 ms; three of
#: them here), and the recorder's close waits for that acknowledgement
#: (recorder_node.CONFIRM_ACK_TIMEOUT, 1 s) from a reader that stays matched there after
#: its process has exited (issue 30).
ACK_LINGER = 0.015


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


class RecorderConfirmation:
    """Whether recorder_node has said (on :data:`COMPLETE_TOPIC`) that it holds everything
    this node said it published; subscribed at start, so the latched answer is there."""

    def __init__(self, node):
        from std_msgs.msg import String

        self.node = node
        self.confirmed = False
        self.linger = ACK_LINGER      # 0: the recorder is in this process (composed.py)
        node.create_subscription(String, COMPLETE_TOPIC, self._on_complete, LATCHED_QOS)

    def _on_complete(self, msg) -> None:
        import json

        try:
            names = json.loads(msg.data)
        except ValueError:
            return
        if isinstance(names, list) and self.node.get_fully_qualified_name() in names:
            self.confirmed = True

    def wait(self, timeout: float) -> bool:
        """Spin the node's executor until confirmed, ``timeout`` wall seconds at most;
        confirmed, stay ``linger`` s (:data:`ACK_LINGER`) for the acknowledgement."""
        end = time.monotonic() + timeout
        executor = self.node.executor
        while not self.confirmed and time.monotonic() < end and executor is not None:
            executor.spin_once(timeout_sec=0.05)
        if self.confirmed and self.linger > 0.0:
            time.sleep(self.linger)
        return self.confirmed


def close_publishers(record: PublishedRecord, timeout: float, also=(),
                     warn: bool = True, recorder: RecorderConfirmation | None = None) -> list:
    """Publish the record, then wait (``timeout`` wall seconds at most in all) until every
    reliable reader has acknowledged every message of the counted publishers, of the
    record and of the publishers ``also``, or, with ``recorder``, until the recorder says
    it holds them all. Returns the topics not acknowledged in time (logged in one warning
    if ``warn``)."""
    record.publish()
    if recorder is not None:
        if recorder.wait(timeout):
            return []
        late = [p.topic_name for p in record.publishers]
        if warn:
            record.node.get_logger().warning(
                f"the recorder did not confirm within {timeout:g} s that it holds every "
                f"message of {', '.join(late)} (it will name what it lacks)")
        return late
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

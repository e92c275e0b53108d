"""recorder_node with a loss injected, for the tests of what a loss does to a run.

``python -m lossy_recorder --ros-args ...`` (tests/ on PYTHONPATH) runs the package's
recorder_node, except that every correction after the first ``GRAZING_TEST_KEEP``
(default 40) is taken from the middleware and not recorded: the tail of the topic is
lost as it was when the recorder was stopped before it had taken them (issue 27). The
recorder's own check must find it.

The loss is known here, so nothing waits for it by a timeout: the double confirms a node
(``recorder/complete``) and ends its stopped wait (``settle``) once it has *taken* every
message the node's published record counts, dropped ones included, where the recorder
waits until it has *recorded* them (the controller's ACK_TIMEOUT, 10 s, and the
recorder's close_timeout, 5 s, were 15 s of the scene's 22). What it recorded, what it
names as missed and its exit status are the recorder's own (``missed``, ``tails``).
"""

import os
import sys
import time

import rclpy

from grazing_control.ros import recorder_node

KEEP = int(os.environ.get("GRAZING_TEST_KEEP", "40"))
_record = recorder_node.RecorderNode._record
_confirm = recorder_node.RecorderNode.confirm
_settle = recorder_node.RecorderNode.settle


def _lossy_record(self, topic, data, info):
    taken = self.__dict__.setdefault("_taken_seq", {})
    sequence = info.get("publication_sequence_number") or 0
    if sequence < 2**63:
        taken[topic] = max(taken.get(topic, 0), sequence)
    if topic.endswith("/controller/velocity_correction"):
        self._kept = getattr(self, "_kept", 0) + 1
        if self._kept > KEEP:
            return
    _record(self, topic, data, info)


def _all_taken(self, counts):
    """Every message of ``counts`` (a published record) taken, recorded or dropped."""
    taken = getattr(self, "_taken_seq", {})
    return all(taken.get(t, 0) >= n for t, n in counts.items()
               if t in self._types and t not in self._interleaved)


def _lossy_confirm(self):
    """The recorder's confirmation, by what was taken (the node need not wait out the
    loss: the recorder names it)."""
    saved = self._last_seq
    self._last_seq = {**saved, **{t: max(s, saved.get(t, 0))
                                  for t, s in getattr(self, "_taken_seq", {}).items()}}
    try:
        _confirm(self)
    finally:
        self._last_seq = saved


def _lossy_settle(self, executor, timeout):
    """Wait as the recorder does, until every published record has come and every count
    in it is taken (not recorded: the dropped tail never will be), then the recorder's
    own settle once (its drain and confirmation, no wait: its timeout is used up)."""
    end = time.monotonic() + timeout
    self.drain()
    while (self.failed is None and (self.unannounced() or not all(
            _all_taken(self, c) for c in self._published.values()))
           and time.monotonic() < end and rclpy.ok()):
        executor.spin_once(timeout_sec=0.02)
        self.drain()
        self.confirm()
    _settle(self, executor, 0.0)


recorder_node.RecorderNode._record = _lossy_record
recorder_node.RecorderNode.confirm = _lossy_confirm
recorder_node.RecorderNode.settle = _lossy_settle

if __name__ == "__main__":
    sys.exit(recorder_node.main())

"""The answers of a scheduled realtime scene, taken at each wake-up with the instant the
middleware received them.

A scheduled answer acts at its section's deadline t_k + delta; what counts is whether it
had *arrived* by then, as a rig's DAQ has a command in its buffer whatever its host
program was doing. Taken through the executor, an answer is judged when its callback
runs: the simulator, held off its core for a few milliseconds (measured in the rig scene:
the Pi2 sample went out 2-3 ms late and its deadline was acted 1.2 ms after it), woke up,
advanced its loop past the deadline and acted the prediction there, with the answer that
had come 1.7-3.5 ms before the deadline still queued behind (docs/rig_scene.md,
"Deadlines by arrival"). rclpy's EventsExecutor does not hand a callback the message's
info (a (msg, info) callback raises "SystemError: null argument to internal routine"),
so the port's subscription belongs to a hidden node of the same context that no executor
spins, and :meth:`AnswerPort.take` takes what waits, each message with the middleware's
reception timestamp (``received_timestamp``, the system clock) turned into the loop's
clock (``time.monotonic``). The loop then advances to each arrival before recording it
(:meth:`grazing_control.plant.realtime.Realtime.answer`): the deadline is judged by the
arrival, and the simulator wakes at every deadline anyway (its timer is armed for it).
"""

from __future__ import annotations

import time

from rclpy.node import Node

__all__ = ["AnswerPort"]


def arrival(received_ns: int, mono: float, real_ns: int) -> float:
    """The loop-clock instant of a reception stamped ``received_ns`` (system clock), read
    at ``mono`` / ``real_ns`` (both clocks at one instant); never later than ``mono`` (a
    stamp ahead of the clock, or none, is taken as now)."""
    if received_ns <= 0:
        return mono
    return mono - max(real_ns - received_ns, 0) * 1e-9


class AnswerPort:
    """A raw subscription to ``topic`` on a hidden node (``_<node>_answers``, same
    context and namespace, the topic resolved by ``node``), taken only by :meth:`take`."""

    def __init__(self, node: Node, msg_type, topic: str, qos, event_callbacks=None):
        self.node = node
        self._hidden = Node(f"_{node.get_name()}_answers", namespace=node.get_namespace(),
                            context=node.context, start_parameter_services=False,
                            enable_rosout=False)
        self.topic_name = node.resolve_topic_name(topic)
        self._sub = self._hidden.create_subscription(
            msg_type, self.topic_name, _never, qos, raw=True,
            event_callbacks=event_callbacks)
        self._type = msg_type

    def get_publisher_count(self) -> int:
        return self._sub.get_publisher_count()

    def take(self):
        """Every answer waiting, in order of arrival: (serialized message, arrival in the
        loop's clock)."""
        sub = self._sub
        if sub is None:
            return
        while True:
            with sub.handle:
                taken = sub.handle.take_message(self._type, True)
            if taken is None:
                return
            data, info = taken
            yield data, arrival(int(info.get("received_timestamp") or 0), time.monotonic(),
                                time.time_ns())

    def destroy(self) -> None:
        """No more answers: the subscription's end is announced (as the node's own would
        be at destroy_subscription)."""
        if self._sub is not None:
            self._hidden.destroy_subscription(self._sub)
            self._sub = None
            self._hidden.destroy_node()


def _never(_msg) -> None:       # no executor spins the hidden node
    raise AssertionError("AnswerPort's subscription is taken, never spun")

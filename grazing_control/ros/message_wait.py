"""Wait until a message is queued on any of some subscriptions: a wait set of them alone.

An rclpy executor's ``spin_once`` builds its wait set in Python on every call, over
every subscription, timer, service, guard condition and waitable of its nodes (each
subscription's QoS event handlers included): 1-2.5 ms of CPU on this 2-core machine
for the recorder's topics, its largest cost per wake-up (issue 30). A recorder that
woke through it once per message burnt 45 % of a core on a ``time_scale`` 1 scene's
~200 messages per second (``/clock`` at 150 Hz, the plant's pause events), where the
messages themselves cost a few percent (docs/benchmarks.md, "The recorder between
messages"). :func:`wait_for_messages` waits on the subscriptions alone, through the
same rcl wait set the executor uses (``_rclpy.WaitSet``), and takes nothing: the caller
takes the messages (``take_message``) and spins its executor for its timers, services
and events on a cadence of its own.
"""

from __future__ import annotations

import time
from contextlib import ExitStack

from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

__all__ = ["take_queued", "wait_for_messages"]


def wait_for_messages(subscriptions, context, timeout: float) -> bool:
    """Block until a message is queued on one of ``subscriptions`` (rclpy Subscription
    objects of ``context``) or ``timeout`` seconds have passed (<= 0: look and return at
    once). True where one is ready. A subscription destroyed meanwhile is left out; none
    left (or a context shut down): False at once."""
    with ExitStack() as stack:
        handles = []
        for sub in subscriptions:
            try:
                stack.enter_context(sub.handle)
                handles.append(sub.handle)
            except InvalidHandle:
                pass
        if not handles or not context.ok():
            return False
        stack.enter_context(context.handle)
        wait_set = _rclpy.WaitSet(len(handles), 0, 0, 0, 0, 0, context.handle)
        wait_set.clear_entities()
        for handle in handles:
            wait_set.add_subscription(handle)
        wait_set.wait(max(0, int(timeout * 1e9)))
        return bool(wait_set.get_ready_entities("subscription"))


def take_queued(executor, subscriptions, context, timeout: float) -> None:
    """Spin ``executor`` until none of ``subscriptions`` has a message queued, ``timeout``
    wall seconds at most: what has arrived is taken, nothing waited for. A node that
    stops takes its last inputs this way before its published record counts what it
    answered (a controller left them queued, took them while it waited for the
    recorder, after the record, and the bag without its last answer was confirmed
    complete: docs/benchmarks.md, "The last fresh clone, and a race")."""
    end = time.monotonic() + timeout
    while (executor is not None and time.monotonic() < end
           and wait_for_messages(subscriptions, context, 0.0)):
        executor.spin_once(timeout_sec=0.0)

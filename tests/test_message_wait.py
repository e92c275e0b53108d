"""ros/message_wait.py: a wait on some subscriptions alone, through rcl's wait set.

Real rclpy in this process, on a DDS domain of its own: the wait ends when a message is
queued (and leaves it to be taken), runs out its timeout otherwise, and leaves out a
subscription destroyed meanwhile."""

import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from grazing_control.ros.message_wait import take_queued, wait_for_messages

from test_closed_loop import new_domain

QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def node():
    context = Context()
    rclpy.init(context=context, domain_id=new_domain())
    node = rclpy.create_node("message_wait_probe", context=context)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def _matched(pub, deadline=10.0):
    end = time.monotonic() + deadline
    while pub.get_subscription_count() < 1:
        assert time.monotonic() < end, "the publisher never matched"
        time.sleep(0.01)


def test_with_nothing_queued_it_waits_out_its_timeout(node):
    sub = node.create_subscription(String, "quiet", lambda m: None, QOS)
    for timeout in (0.0, 0.05, 0.2):
        start = time.monotonic()
        assert wait_for_messages([sub], node.context, timeout) is False
        took = time.monotonic() - start
        assert timeout - 1e-3 <= took < timeout + 0.1, (timeout, took)
    assert wait_for_messages([sub], node.context, -1.0) is False     # <= 0: at once


def test_a_queued_message_ends_the_wait_and_stays_to_be_taken(node):
    subs = [node.create_subscription(String, name, lambda m: None, QOS)
            for name in ("first", "second", "third")]
    pub = node.create_publisher(String, "second", QOS)
    _matched(pub)
    pub.publish(String(data="hello"))
    start = time.monotonic()
    assert wait_for_messages(subs, node.context, 5.0) is True
    assert time.monotonic() - start < 1.0
    with subs[1].handle:
        taken = subs[1].handle.take_message(String, False)
    assert taken is not None and taken[0].data == "hello"
    assert wait_for_messages(subs, node.context, 0.05) is False      # taken: none left


def test_a_destroyed_subscription_is_left_out(node):
    gone = node.create_subscription(String, "gone", lambda m: None, QOS)
    kept = node.create_subscription(String, "kept", lambda m: None, QOS)
    node.destroy_subscription(gone)
    pub = node.create_publisher(String, "kept", QOS)
    _matched(pub)
    pub.publish(String(data="x"))
    assert wait_for_messages([gone, kept], node.context, 5.0) is True
    start = time.monotonic()
    assert wait_for_messages([gone], node.context, 5.0) is False     # none left: at once
    assert time.monotonic() - start < 0.5


@pytest.mark.parametrize("executor_kind", ["events", "single_threaded"])
def test_take_queued_runs_the_callbacks_of_what_has_arrived_and_no_more(node, executor_kind):
    """A stopping node takes its last inputs (the controller's last stream samples,
    before its published record): every queued message through its callback, on the
    nodes' executors both, and then it returns, waiting for nothing more."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor

    got = []
    sub = node.create_subscription(String, "inputs", lambda m: got.append(m.data), QOS)
    kind = EventsExecutor if executor_kind == "events" else SingleThreadedExecutor
    executor = kind(context=node.context)
    executor.add_node(node)
    try:
        pub = node.create_publisher(String, "inputs", QOS)
        _matched(pub)
        sent = [str(i) for i in range(50)]
        for data in sent:
            pub.publish(String(data=data))
        end = time.monotonic() + 5.0
        while not wait_for_messages([sub], node.context, 0.0):
            assert time.monotonic() < end
        time.sleep(0.2)                      # all 50 delivered to the reader
        start = time.monotonic()
        take_queued(executor, [sub], node.context, 5.0)
        assert got == sent and time.monotonic() - start < 2.0
        assert wait_for_messages([sub], node.context, 0.0) is False
        start = time.monotonic()
        take_queued(executor, [sub], node.context, 5.0)       # nothing queued: at once
        assert time.monotonic() - start < 0.5
    finally:
        executor.shutdown()

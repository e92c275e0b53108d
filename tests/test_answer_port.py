"""sim_node.answer_port: a scheduled scene's answers, taken at each wake-up with the
instant the middleware received them (the deadline is judged by it: test_plant_loops,
test_a_scheduled_answer_is_judged_by_its_arrival_not_by_when_the_loop_takes_it)."""

import time

import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.serialization import deserialize_message

from grazing_control.ros.common import DATA_QOS
from sim_node.answer_port import AnswerPort, arrival
from test_closed_loop import new_domain


def test_arrival_is_the_reception_in_the_loops_clock_and_never_in_the_future():
    # received 2.5 ms before the pair of clock reads: 2.5 ms before mono
    assert arrival(1_000_000_000, 50.0, 1_002_500_000) == 50.0 - 2.5e-3
    assert arrival(1_003_000_000, 50.0, 1_002_500_000) == 50.0   # stamp ahead: now
    assert arrival(0, 50.0, 1_002_500_000) == 50.0                 # no stamp: now


def test_the_port_takes_what_arrived_in_order_with_its_arrival_beside_a_spinning_node():
    """A node spun by the EventsExecutor (as sim_node is) and the port on its hidden node:
    the executor never takes the port's messages; take() gives each one, in order, with
    an arrival between its publication and the take."""
    context = Context()
    rclpy.init(context=context, domain_id=new_domain())
    try:
        node = rclpy.create_node("sim_node", context=context)
        port = AnswerPort(node, WrenchStamped, "rig/force_pulse", DATA_QOS)
        pub = node.create_publisher(WrenchStamped, "rig/force_pulse", DATA_QOS)
        executor = EventsExecutor(context=context)
        executor.add_node(node)
        end = time.monotonic() + 10.0
        while port.get_publisher_count() < 1 and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
        assert port.topic_name == "/rig/force_pulse"
        assert "_sim_node_answers" in node.get_node_names()      # hidden: "_" first
        sent = []
        for i in range(5):
            msg = WrenchStamped()
            msg.wrench.force.x = float(i)
            sent.append(time.monotonic())
            pub.publish(msg)
            executor.spin_once(timeout_sec=0.005)
        got, deadline = [], time.monotonic() + 10.0
        while len(got) < 5 and time.monotonic() < deadline:
            got.extend(port.take())
            time.sleep(0.01)
        taken = time.monotonic()
        assert [deserialize_message(d, WrenchStamped).wrench.force.x for d, _ in got] == \
            [0.0, 1.0, 2.0, 3.0, 4.0]
        for (_, arrived), out in zip(got, sent):
            assert out - 1e-3 <= arrived <= taken       # the clocks agree to the read pair
        assert list(port.take()) == []
        port.destroy()
        assert list(port.take()) == []
        assert "_sim_node_answers" not in node.get_node_names()
    finally:
        rclpy.shutdown(context=context)

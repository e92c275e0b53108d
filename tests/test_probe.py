"""sim_node/probe.py: the round trips to the controller before a realtime start."""

from rclpy.task import Future

from sim_node.probe import RESEND, RoundTrips


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class Client:
    """The service client's side the probe uses: ready, and each request's future (real
    rclpy futures, completed by the test as a server's answers would be)."""

    def __init__(self):
        self.futures = []

    def service_is_ready(self):
        return True

    def call_async(self, _request):
        self.futures.append(Future())
        return self.futures[-1]


class Node:
    def __init__(self):
        self.client = Client()
        self.destroyed = False

    def create_client(self, _kind, _name):
        return self.client

    def destroy_client(self, _client):
        self.destroyed = True


def test_a_lost_first_answer_is_asked_again_and_every_answer_timed_from_its_request():
    """The first answer of a new client lost (its response writer unmatched): the
    request goes again after RESEND and the check measures the round trips, where it
    had waited out its timeout and refused a feasible scene ("answered none of 1
    requests in 5.11 s", a suite run, 2026-11-29); a late answer to the first request
    is a round trip of its own length."""
    clock, node = Clock(), Node()
    probe = RoundTrips(node, "/controller_node", 3, 5.0, clock=clock)
    assert not probe.poll() and probe.asked == 1
    clock.now = RESEND / 2
    assert not probe.poll() and probe.asked == 1          # not yet: no resend
    clock.now = RESEND + 0.01
    assert not probe.poll() and probe.asked == 2          # the lost one asked again
    clock.now += 0.001
    node.client.futures[1].set_result(object())           # its answer: 1 ms
    assert probe.asked == 3 and abs(probe.times[0] - 0.001) < 1e-12     # and the next asked
    clock.now += 0.002
    node.client.futures[0].set_result(object())           # the first, late: its own length
    assert abs(probe.times[1] - clock.now) < 1e-12 and probe.asked == 3
    clock.now += 0.0005
    node.client.futures[2].set_result(object())
    assert probe.poll() and node.destroyed and len(probe.times) == 3
    assert abs(probe.times[2] - 0.0025) < 1e-12


def test_answers_in_time_are_asked_one_after_the_other_without_a_resend():
    clock, node = Clock(), Node()
    probe = RoundTrips(node, "/controller_node", 4, 5.0, clock=clock)
    probe.poll()
    for k in range(4):
        clock.now += 0.001
        assert not probe.poll()
        node.client.futures[k].set_result(object())
    assert probe.asked == 4 and probe.done and len(probe.times) == 4


def test_nothing_answered_is_over_at_the_timeout():
    clock, node = Clock(), Node()
    probe = RoundTrips(node, "/controller_node", 3, 5.0, clock=clock)
    while clock.now <= 5.0:
        assert not probe.poll()
        clock.now += 0.1
    assert probe.poll() and probe.times == [] and probe.asked == 10 and node.destroyed

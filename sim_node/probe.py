"""sim_node's round trips to the controller's process before a realtime scene starts.

The check before the start (:mod:`grazing_control.plant.feasibility`) compares the
controller's answer latency with the scene's budget. Nothing may be published on the
scene's topics before the start (the recorder records them), so the round trip is
measured on a service every rclpy node serves from the same executor that answers its
samples: the controller's ``get_parameters`` (rcl_interfaces/srv/GetParameters, one
parameter asked). A request goes out when the previous answer came back; each round
trip is the wall time from the request to the answer's callback in this node, the path
of a sample and its answer through both processes' executors and the middleware.
"""

from __future__ import annotations

import time

from rcl_interfaces.srv import GetParameters

__all__ = ["RoundTrips", "controller_name"]


def controller_name(node, topic: str, package_nodes: set):
    """The fully qualified name of the controller publishing on ``topic`` (one of this
    package's nodes, ``package_nodes``: (namespace, name) pairs), or None."""
    for info in node.get_publishers_info_by_topic(topic):
        if (info.node_namespace, info.node_name) in package_nodes:
            ns = info.node_namespace.rstrip("/")
            return f"{ns}/{info.node_name}"
    return None


#: Wall seconds a request waits for its answer before it is sent again (the first
#: answer of a new client can be lost: the server's response writer had not matched the
#: client's reader yet, and a volatile writer sends nothing to an unmatched reader; a
#: suite run saw "answered none of 1 requests in 5.11 s" and refused a feasible scene,
#: 2026-11-29). Far above any budget the check passes (milliseconds).
RESEND = 0.5


class RoundTrips:
    """``count`` GetParameters round trips to the node ``target``, one after the other,
    within ``timeout`` wall seconds; :meth:`poll` (from a timer) says when it is over.
    A request unanswered for RESEND seconds is sent again; each answer is timed from its
    own request (a late answer to an earlier one is a slow round trip, measured as such).

    ``times``: the round trips measured (wall seconds); ``asked``: requests sent.
    """

    def __init__(self, node, target: str, count: int, timeout: float,
                 clock=time.monotonic):
        self.node, self.count, self.clock = node, count, clock
        self.client = node.create_client(GetParameters, f"{target}/get_parameters")
        self.deadline = clock() + timeout
        self.times: list = []
        self.asked = 0
        self.sent = None             # when the newest request went out
        self.pending = {}            # id(future) -> when its request went out, unanswered
        self.done = False

    def poll(self) -> bool:
        """Send the first request once the service is there, and again a request
        unanswered for RESEND seconds; True when every round trip is measured or the time
        is up."""
        if not self.done and self.clock() > self.deadline:
            self._close()
        if not self.done and self.sent is None and self.client.service_is_ready():
            self._ask()
        elif not self.done and self.pending and self.clock() - self.sent > RESEND:
            self._ask()
        return self.done

    def _ask(self) -> None:
        self.asked += 1
        self.sent = self.clock()
        future = self.client.call_async(GetParameters.Request(names=["actuation_delay"]))
        self.pending[id(future)] = self.sent
        future.add_done_callback(self._answered)

    def _answered(self, future) -> None:
        sent = self.pending.pop(id(future), None)
        if self.done or sent is None:
            return
        self.times.append(self.clock() - sent)
        if len(self.times) >= self.count:
            self._close()
        elif sent == self.sent:          # the newest answered (not a late earlier one)
            self._ask()

    def _close(self) -> None:
        self.done = True
        self.node.destroy_client(self.client)

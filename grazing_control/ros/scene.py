"""Which scene a node belongs to: a token shared by the nodes of one scene.

Two scenes forced onto one ROS domain and namespace (``grazing run --domain-id``) see each
other's topics. The simulator's start condition "a controller is matched" was then met
by the *other* scene's controller while its own was still starting: it started, and lost
the answers to its first samples (measured 2 of 25 forced pairs, docs/nodes.md). With a
token (parameter ``scene``, set by ``grazing run`` to the same random value on every node
it starts), each node's parameter record (``grazing/parameters``, transient local)
names its scene: the simulator starts only once the record of a controller of its own
scene has arrived, and a record of another scene is an intruder (the scene is not
isolated: refused, as for two simulators on one topic). An empty token (``ros2 run``)
checks nothing.

The records are read with :data:`~grazing_control.ros.common.RECORDS_QOS` (keep last
1000), not the writers' depth 1: a reader's depth holds the samples of every writer
together, and at depth 1 the simulator's own record, delivered after its controller's,
replaced it before the executor took it; the simulator then waited its whole
start_timeout (5 of 6 loaded scenes, issue 27; docs/nodes.md, "Start handshake").
"""

from __future__ import annotations

import math

from std_msgs.msg import String

from grazing_control.ros.recording.record import TOPIC, decode

from .common import RECORDS_QOS

__all__ = ["SceneGuard", "SCENE_PARAMETER_DOC"]

SCENE_PARAMETER_DOC = ("token naming this scene (grazing run sets one): the simulator "
                       "starts with a controller of the same scene only, and a node of "
                       "another scene on the domain stops the scene; '' = no check")


class SceneGuard:
    """Reads the parameter records of the domain and sorts them by scene token."""

    def __init__(self, node, token: str):
        self.token = token
        self.own_controller = False
        self.foreign = set()                # "node (scene token)" of other scenes
        #: node name -> its scene token ('' without one), of every record read: what the
        #: start wait names when this scene's controller is missing
        self.seen = {}
        #: node name -> the actuation_delay its gains were designed for, from the records
        #: of this scene's controllers (any controller's when there is no token)
        self.controller_delays = {}
        #: node name -> (c1, c2) of those controllers with a 1-DOF law (the check of a
        #: realtime scene acting on arrival, plant.feasibility.arrival_delay)
        self.controller_gains = {}
        self.topic = node.resolve_topic_name(TOPIC)
        # every node's latched record, not only the last to arrive (RECORDS_QOS)
        node.create_subscription(String, TOPIC, self._on_record, RECORDS_QOS)

    def _on_record(self, msg) -> None:
        try:
            name, params = decode(msg.data)
        except (ValueError, TypeError, RecursionError):
            return
        other = params.get("scene") if isinstance(params, dict) else None
        if len(self.seen) < 32 or str(name) in self.seen:    # bounded: names are anyone's
            self.seen[str(name)] = other if isinstance(other, str) else ""
        if self.token and isinstance(other, str) and other and other != self.token:
            self.foreign.add(f"{name} (scene {other})")
            return
        if not isinstance(params, dict) or ("c2" not in params and str(name).rsplit("/", 1)[-1] != "controller_node"):
            return
        delay = params.get("actuation_delay")
        if isinstance(delay, (int, float)) and not isinstance(delay, bool):
            self.controller_delays[str(name)] = float(delay)
        c1, c2 = params.get("c1"), params.get("c2")
        if all(isinstance(c, float) and math.isfinite(c) for c in (c1, c2)) \
                and not params.get("model_file") and not params.get("rig_file"):
            self.controller_gains[str(name)] = (c1, c2)
        if self.token and other == self.token:
            self.own_controller = True

    def delay_mismatch(self, delay: float) -> str | None:
        """Why the simulator's ``actuation_delay`` differs from a controller's design, or
        None: the gains are designed for one delay (docs/theory_delay.md) and the
        simulator must apply that one (issue 19 §3)."""
        for name, d in sorted(self.controller_delays.items()):
            if d != delay:
                return (f"{name} was designed for actuation_delay={d!r}, this simulator applies "
                        f"actuation_delay={delay!r}: give both nodes the same delay (the "
                        f"controller's parameter file, or -p actuation_delay:={d!r})")
        return None

    def missing_controller(self) -> str | None:
        """What the start still waits for from the records, or None: with a token, the
        record of a controller of this scene (naming the records read so far)."""
        if not self.token or self.own_controller:
            return None
        seen = ", ".join(f"{n} (scene {t or 'none'})" for n, t in sorted(self.seen.items()))
        return (f"the parameter record of a controller of this scene (scene {self.token}) on "
                f"{self.topic}; records read: {seen or 'none'}")

    def intruders(self) -> list:
        """One line per node of another scene seen on the domain."""
        if not self.foreign:
            return []
        return [f"node(s) of another scene on this domain: {', '.join(sorted(self.foreign))}"]

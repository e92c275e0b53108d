"""When sim_node starts: the start handshake's conditions, the scene's isolation, and
the feasibility check before a realtime start (docs/nodes.md, "Start handshake")."""

from __future__ import annotations

import time

from grazing_control.oscillator import kernel
from grazing_control.plant.feasibility import ROUND_TRIPS, check, sustained_rate
from grazing_control.ros.common import READY_TOPIC
from grazing_control.ros.matching import MATCHED_TOPIC
from grazing_control.ros.recording.record import TOPIC as RECORD_TOPIC
from grazing_control.ros.scheduling import raise_node_priority

from sim_node.probe import RoundTrips, controller_name

#: Wall seconds the round trips to the controller before a realtime start may take.
PROBE_TIMEOUT = 5.0
#: Wall seconds the start conditions must hold before the start: for the ends that no
#: condition sees (a controller of another package; the controller's ends are its report's,
#: missing_matches). Without it the start was no sooner in bench_scene_overhead.py
#: (the handshake 0.34 s both ways, medians of 5: the kernel's load is the longer wait).
SETTLE = 0.2


def due(node) -> bool:
    """Whether the scene starts now (the start timer's call, every 20 ms until it does).

    The conditions of :func:`missing` have held for SETTLE seconds, or ``start_timeout``
    has passed without them (a warning names what is missing); the kernel's warm-up
    thread (compiling, or loading numba's cache) has finished, and its error, if any,
    is raised here; the node's thread_priority applies from here
    (ros.scheduling.raise_node_priority); a realtime start is :func:`feasible`. The node's ``created``,
    ``ready_since`` and ``warming`` hold the wait between calls.
    """
    waited = time.monotonic() - node.created
    loading = node.warming is not None and node.warming.is_alive()
    absent = missing(node)
    if absent:
        node.ready_since = None
        if waited < node.get_parameter("start_timeout").value or loading:
            return False
        node.get_logger().warning(
            f"starting after start_timeout={waited:.1f} s without: {'; '.join(absent)}")
    elif node.ready_since is None:
        node.ready_since = time.monotonic()     # let both ends of every match settle
        return False
    elif time.monotonic() - node.ready_since < SETTLE:
        return False
    if loading:
        return False
    if node.warming is not None:
        node.warming = None
        kernel.warm_up()            # at once when loaded; raises what the load raised
    raise_node_priority(node)       # the start-up done: SCHED_FIFO from the probe on
    if not feasible(node):
        return False
    if not absent:
        node.get_logger().info(f"start conditions met after {waited:.1f} s: starting"
                               + wall_time(node.settings, node.engine.p.period))
    return True


def wall_time(settings, period: float) -> str:
    """What a realtime scene of max_periods will take on the wall clock (", 50 periods
    at time_scale 1: about 471 s of wall time"), '' for lockstep or an unbounded scene."""
    if settings.mode != "realtime" or settings.max_periods <= 0:
        return ""
    return (f", {settings.max_periods} periods at time_scale {settings.time_scale:g}: "
            f"about {settings.max_periods * period / settings.time_scale:.3g} s of wall time")


def intruders(node) -> list:
    """Other simulators or controllers on this scene's topics.

    A simulator or a controller of this package publishes its parameter record
    (``grazing/parameters``): only publishers whose node does count. Any other
    publisher on the scene's topics (a stray ``ros2 topic pub --once``) is a bystander:
    logged once, its messages counted as ignored (or malformed) like any input that
    answers no waiting sample, and the scene goes on (issue 19 §4).
    """
    found = []
    nodes = {(i.node_namespace, i.node_name) for i in
             node.get_publishers_info_by_topic(node.resolve_topic_name(RECORD_TOPIC))}
    for topic, what, own in ((node.pub_pi2.topic_name, "another simulator", 1),
                             (node.sub_correction.topic_name, "more than one controller",
                              0)):
        infos = node.get_publishers_info_by_topic(topic)
        ours = [i for i in infos if (i.node_namespace, i.node_name) in nodes]
        if len(ours) > 1:
            found.append(f"{len(ours) - own} other publisher(s) of this package on "
                         f"{topic} ({what})" if own else
                         f"{len(ours)} controllers publish on {topic} ({what})")
        if node.loop is None:        # a controller's record may not be discovered yet
            continue
        strays = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos
                        if (i.node_namespace, i.node_name) not in nodes
                        and i.node_name != node.get_name())
        for name in strays:
            if (topic, name) not in node.strays:
                node.strays.add((topic, name))
                node.get_logger().warning(
                    f"a publisher that is not a node of this package on {topic}: "
                    f"{name} (a bystander: its messages are counted, the scene goes on)")
    return found + node.scene.intruders()


def check_isolation(node) -> None:
    """Refuse to start, or stop, when another scene shares this one's topics.

    Two simulators (or two controllers) on the same topics corrupt each other's
    samples, answers and recordings: the scene is stopped with an error (exit status
    1) instead of reporting success. Checked every ISOLATION_CHECK wall seconds.
    """
    if node.refused or (node.loop is not None and node.loop.finished):
        return
    found = intruders(node)
    why = node.scene.delay_mismatch(node.settings.actuation_delay)
    if why is None and found:
        why = (f"{'; '.join(found)}: the scene is not isolated (another scene on this "
               "ROS_DOMAIN_ID and namespace?)")
    if why is not None:
        if node.loop is None:
            node.reason = f"not starting: {why}"
            node.get_logger().error(f"not starting: {why}")
            node.exit_code = 1
            node.refused = True
            node.exit_now = True
            node.destroy_timer(node.start_timer)
        else:
            node.fail(RuntimeError(why))
        return
    if (node.loop is not None and node.recorder_ready
            and node.get_parameter("wait_for_recorder").value
            and node.count_publishers(node.resolve_topic_name(READY_TOPIC)) == 0):
        # the recorder that matched every topic before the start has left the graph
        node.fail(RuntimeError("the recorder (recorder/ready) has gone: the scene's "
                                "recording is lost (recorder_node killed?)"))


def missing(node) -> list:
    """What the start still waits for, one phrase per missing peer ([]: ready).

    The conditions (docs/nodes.md, "Start handshake"): with ``wait_for_recorder`` the
    recorder's ``recorder/ready``; with ``wait_for_controller`` a controller
    subscribed to the samples (Pi2 or the stream) and publishing corrections and,
    with a scene token, the parameter record of a controller of this scene; with
    ``wait_for_subscribers`` n, n subscribers (besides the controller) on every data
    topic of this scene. A scene that refuses to start (another scene's node, a
    controller designed for another delay) is :func:`check_isolation`'s.
    """
    refused = intruders(node) + [why for why in (
        node.scene.delay_mismatch(node.settings.actuation_delay),) if why]
    if refused:                          # _check_isolation refuses to start
        return refused
    missing = []
    if node.get_parameter("wait_for_recorder").value and not node.recorder_ready:
        missing.append(f"the recorder's True on {node.resolve_topic_name(READY_TOPIC)} "
                       "(recorder_node not running, or not matched to every topic yet)")
    n = node.get_parameter("wait_for_subscribers").value
    if node.get_parameter("wait_for_controller").value:
        samples = max(node.pub_pi2.get_subscription_count(),    # a controller reads
                      node.pub_state.get_subscription_count(),  # Pi2 or the stream
                      node.pub_state_block.get_subscription_count())
        if node.driver is not None:         # a rig's controller: the SI stream, phase
            samples = min(node.driver.pub_sensor.get_subscription_count(),
                          node.driver.pub_phase.get_subscription_count())
        if samples < n + 1:
            topics = (f"{node.pub_pi2.topic_name} or {node.pub_state.topic_name}"
                      if node.driver is None else
                      f"{node.driver.pub_sensor.topic_name} and "
                      f"{node.driver.pub_phase.topic_name}")
            missing.append(f"the controller{f' and {n} recorder(s)' if n else ''} "
                           f"subscribed to {topics} ({samples} subscriber(s) of {n + 1})")
        if node.sub_correction.get_publisher_count() < 1:
            missing.append(f"a controller publishing {node.sub_correction.topic_name}")
        why = node.scene.missing_controller()
        if why is not None:
            missing.append(why)
        why = missing_matches(node, n)
        if why is not None:
            missing.append(why)
    if n > 0:
        for pub in recorded_publishers(node):
            have = pub.get_subscription_count()
            if have < n:
                missing.append(f"a subscriber of {pub.topic_name} ({have} of {n})")
        topic = node.sub_correction.topic_name
        have = node.count_subscribers(topic)
        if have < n + 1:
            missing.append(f"a recorder subscribed to {topic} ({have} subscriber(s) of "
                           f"{n + 1}, this node's own included)")
    return missing


def recorded_publishers(node) -> list:
    """This node's data publishers that ``wait_for_subscribers`` n asks n subscribers of
    (the recorders'): the impacts, Pi1, Pi2, /clock, the stream (per sample or in
    blocks) when on, the latency in realtime, a simulated rig's topics."""
    pubs = [node.pub_impact, node.pub_pi1, node.pub_pi2, node.pub_clock]
    if node.settings.state_period > 0.0:
        pubs.append(node.pub_state if node.out.block is None else node.pub_state_block)
    if node.settings.mode == "realtime":     # the latency of every sample is recorded
        pubs.append(node.pub_latency)
    if node.driver is not None:
        pubs.extend(node.driver.publishers)
    return pubs


def missing_matches(node, n: int) -> str | None:
    """What the controller's own ends, and this node's ends towards it, still lack
    (ros/matching.py), or None. From its report on controller/matched: its answers
    matched to this node and the ``n`` recorders, and on each topic of this node that it
    reads, a publisher matched at its end and at this node's writer the controller's
    reader and, on a topic of :func:`recorded_publishers`, the n recorders'. Asked of a
    controller of this package (one that publishes the report; another controller's ends
    are not seen)."""
    report = node.controller_matched
    topic = node.resolve_topic_name(MATCHED_TOPIC)
    if report is None:
        if node.count_publishers(topic) == 0:
            return None
        return f"the controller's report of its matches on {topic}"
    lacking = []                          # one phrase each, without ";" (missing's list)
    if report["answers"] < n + 1:
        lacking.append(f"its answers matched to {n + 1} reader(s) "
                       f"(answers={report['answers']})")
    recorded = {pub.topic_name for pub in recorded_publishers(node)}
    for pub in node.published.publishers:
        read = report.get(pub.topic_name)
        if read is None:
            continue                       # a topic of this node the controller ignores
        have, want = pub.get_subscription_count(), 1 + (n if pub.topic_name in recorded
                                                        else 0)
        if read < 1 or have < want:
            lacking.append(f"{pub.topic_name} matched at both ends (its reader {read} "
                           f"publisher(s) and this node's writer {have} of {want} "
                           "reader(s))")
    if not lacking:
        return None
    return f"the controller's ends ({topic}): " + ", ".join(lacking)


def feasible(node) -> bool:
    """Realtime: the check before the start (plant.feasibility); True when the scene
    may start now, False while the round trips are measured or when it is refused.

    The controller's round trips (sim_node.probe) while nothing of the scene is
    published, then the simulation rate of a copy of the engine with every event
    serialised; the verdict is logged, published as an event record, and with
    ``feasibility`` refuse an infeasible scene ends here with exit status 2."""
    s = node.settings
    if s.mode != "realtime" or s.feasibility == "off" or node.feasibility is not None:
        return True
    if node.probe is False:     # the controller of this package answering, if any
        nodes = {(i.node_namespace, i.node_name) for i in
                 node.get_publishers_info_by_topic(node.resolve_topic_name(RECORD_TOPIC))}
        target = controller_name(node, node.sub_correction.topic_name, nodes)
        node.probe = (RoundTrips(node, target, ROUND_TRIPS, PROBE_TIMEOUT)
                       if target else None)
        node.probe_start = time.monotonic()
    probe = node.probe
    if probe is not None and not probe.poll():
        return False
    period = node.engine.p.period
    sustained, _ = sustained_rate(type(node.engine)(s), node.out.serialise)
    waited = time.monotonic() - node.probe_start
    note = None
    if probe is None:
        note = "no controller of this package found: its round trip is not measured"
    elif not probe.asked:
        note = (f"the controller's get_parameters service did not appear in "
                f"{waited:.3g} s: its round trip is not measured")
    gains = [(name, c1, c2) for name, (c1, c2) in sorted(node.scene.controller_gains.items())]
    verdict = check(s, period, probe.times if probe else (), sustained,
                    probe.asked if probe else 0, waited, note, plant=node.engine.p,
                    gains=gains)
    node.feasibility = verdict
    node.event("feasibility", level=verdict.level, line=verdict.line, **verdict.numbers)
    log = node.get_logger()
    if verdict.level == "refuse" and s.feasibility == "refuse":
        node.reason = verdict.line
        log.error(f"not starting: {verdict.line} (feasibility:=warn starts anyway)")
        node.exit_code = 2
        node.refused = True
        node.exit_now = True
        node.destroy_timer(node.start_timer)
        return False
    (log.info if verdict.level == "ok" else log.warning)(verdict.line)
    return True

"""``grazing replay`` of a stream scene: the recorded sensor stream through a real controller.

A controller with ``pi2_source`` stream (docs/nodes.md, "Stream mode") does not read
``oscillator/pi2``: it estimates each section's state from the sensor stream and answers
it. Its replay publishes what such a controller reads (ros/controller_node.py), the
recorded messages with their recorded bytes, to a controller_node started with the
recorded parameters (or ``--controller-params``):

* the stream: ``oscillator/state`` (sensor_msgs/JointState, a sample each) or, with
  ``stream_message`` block, ``oscillator/state_block`` (std_msgs/Float64MultiArray,
  :mod:`grazing_control.ros.stream_block`);
* ``oscillator/impact`` (geometry_msgs/Vector3Stamped) where ``impact_source`` is topic,
  and ``oscillator/deadline_miss`` (Vector3Stamped) and ``oscillator/substituted``
  (TwistStamped): what acted where an answer came too late, which the model filter
  integrates (with a sample per message or in blocks alike).

Order and waiting (:func:`schedule`). The messages go out in the order the simulator
published them, rebuilt from their stamps: the stream (a block at its first sample's
stamp) and the impacts in time order, each section's answer awaited (as the lockstep
Pi2 replay awaits each sample's) after every message stamped at or before its section,
and what acted instead of an answer (``deadline_miss``, ``substituted``, stamped with
the section) after that answer, where the simulator sent it. Not the recorder's log
order: that is the order in which the recorder took its topics, one subscription each,
and a recorder behind the stream logged the impacts late (measured, a lockstep scene
with the simulator and the controller under SCHED_FIFO on a loaded machine: six
impacts and a substitution logged 5 to 43 time units after stream samples stamped
later; replayed in that order, 6 of 16 answers differed). The controller's events
executor takes its messages in the order they arrive, so it reads them in that
interleaving as far as the middleware delivers one process's messages on several
topics in the order they were published (DDS promises it per topic only; an impact or
a substitution is read at the next section's answer, the stream's messages up to that
section's last sample later; measured: every replay of tests/test_stream_replay.py's
scene with both, and of 60 periods with 59 impacts or 11 substitutions, gave every
answer again). But not always: run three at a time, 5 of 54 replays took a
substitution after the sample that made the next section due (2026-11-29). So each
impact and substitution is now published and then waited for until the controller's
reader has acknowledged it, before the stream goes on. An acknowledgement comes when a
heartbeat asks, which is every 5 ms in the nodes' profile (this process gets it too:
``launcher.use_profile_here``); at Fast DDS's 3 s it cost about 1.5 s each. Afterwards:
1 of 149. With ``--rate R`` the messages go out in that order at their recorded log times
scaled by R instead, without waiting.

OUT gets the messages published, the answers and estimates as they came, the parameter
records (the controller's, this replay's own), and the recording's Pi2 samples, copied
at their logged place (never published: the controller does not read them) so that the
answers are matched to their samples by stamp as in any bag. The answers are compared
with the recorded corrections (:func:`grazing_control.recordings.replay.
compare_corrections`: bit for bit, else the difference report) and the estimates with
the recorded ``controller/estimate`` messages, bytes for bytes.

A bag without what the controller needs (the stream topic of its ``stream_message``, or
``oscillator/impact`` with ``impact_source`` topic) is refused in one line before
anything starts (:func:`check`).

A realtime scene's bag replays the same way, as fast as the controller answers: a
stream controller's answers depend on the samples' stamps, not on their arrival times,
so only where a deadline miss or a substitution reached the controller relative to the
stream can differ (the recorder's order is its own arrival order, not the controller's).
"""

from __future__ import annotations

import time
import numpy as np

from . import reader
from .scenes import DEFAULT_TOPICS, load

__all__ = ["INPUTS", "check", "inputs_of", "schedule", "recorded_lag", "compare_messages",
           "replay_stream"]

#: Role (recordings.scenes.DEFAULT_TOPICS) -> the message class a stream controller reads
#: it as (module, name).
INPUTS = {"state": ("sensor_msgs.msg", "JointState"),
          "state_block": ("std_msgs.msg", "Float64MultiArray"),
          "impact": ("geometry_msgs.msg", "Vector3Stamped"),
          "deadline_miss": ("geometry_msgs.msg", "Vector3Stamped"),
          "substituted": ("geometry_msgs.msg", "TwistStamped")}


def inputs_of(values: dict) -> tuple:
    """(the stream's role, every role a stream controller with ``values`` reads, the
    stream's first): ros/controller_node.py's subscriptions in stream mode (the stream
    per sample, or in blocks with ``stream_message`` block)."""
    stream = "state_block" if values.get("stream_message") == "block" else "state"
    roles = [stream] + (["impact"] if values.get("impact_source") == "topic" else [])
    return stream, tuple(roles + ["deadline_miss", "substituted"])


def check(data, values: dict, notes: list) -> None:
    """Refuse (ValueError, one line) a bag whose stream controller cannot be replayed: a
    rig scene's (grazing replay-rig), one without its Pi2 samples or corrections, without
    its stream topic's messages, or without the impacts it reads; note what is
    replayed as absent (the deadline misses and substitutions where not recorded)."""
    if values.get("rig_file"):
        raise ValueError(f"{data.path}: a rig scene's bag (its controller reads rig/sensor "
                         "through rig_file): replay it with grazing replay-rig")
    stream, roles = inputs_of(values)
    if "pi2" not in data.present or "correction" not in data.present:
        raise ValueError(f"{data.path}: no Pi2 samples or no corrections recorded "
                         f"({data.topics['pi2']}, {data.topics['correction']}): nothing to "
                         "match the controller's answers to")
    want = {"stream_message": values.get("stream_message", "sample"),
            "impact_source": values.get("impact_source", "stream")}
    for role in roles:
        topic = data.topics[role]
        recorded = role in data.present
        if role == stream and (not recorded or not _count(data, topic)):
            raise ValueError(
                f"{data.path}: its controller reads the sensor stream (pi2_source stream, "
                f"stream_message {want['stream_message']}) on {topic}, which the bag "
                f"{'has no message of' if recorded else 'did not record'}: the controller "
                "cannot be replayed (--no-controller replays the simulator)")
        if role == "impact" and not recorded:
            raise ValueError(
                f"{data.path}: its controller reads the impacts (impact_source topic) on "
                f"{topic}, which the bag did not record: the controller cannot be replayed "
                "(--no-controller replays the simulator)")
        if not recorded:
            notes.append(f"{topic} not recorded: replayed as if none came")
    if values.get("reidentify"):
        notes.append("the controller re-identifies its model in a worker thread "
                     "(reidentify): where a refit finished is timing: bit-identical answers "
                     "are not guaranteed")


def _count(data, topic: str) -> int:
    return reader.read_raw(data.path, [topic]).count(topic)


def _first_stamp(role: str, data: bytes) -> int:
    """The stamp (ns) of a stream message's first sample (a block's first row)."""
    if role == "state_block":
        from grazing_control.ros.stream_block import read

        rows = read(data)
        if rows is None or not rows.flat:
            return -1
        return int(rows.flat[0]) * 1_000_000_000 + int(rows.flat[1])
    from .replay_nodes import stamp_of

    return stamp_of(data)


#: Where a message goes among those of its stamp (:func:`schedule`): the stream and the
#: impacts before the section's answer is awaited, what acted instead of an answer after.
_BEFORE_ANSWER, _ANSWER, _AFTER_ANSWER = 0, 1, 2
#: The roles published after their section's answer (its stamp is the section's).
ACTED_ROLES = ("deadline_miss", "substituted")


def schedule(items: list, answers: list, stream_role: str) -> list:
    """The replay's steps (module docstring, "Order and waiting"): the order in which the
    simulator published, rebuilt from the stamps.

    ``items``: (log_ns, role, data) of the recorded messages to publish or copy;
    ``answers``: (log_ns, stamp_ns) of the recorded corrections. Returns the steps in
    order: ("message", role, data, log_ns) or ("answer", stamp_ns). Each message goes
    at its stamp (a ``stream_role`` message's: its first sample's), the answer of each
    section once, after every stream message, impact and Pi2 sample stamped at or before
    it and before what acted there instead (:data:`ACTED_ROLES`, stamped with the
    section). A stream message the recorder logged before an answer goes before that
    answer too, whatever its stamp: the controller may have needed it to answer (the
    first sample after the section; the stream is one topic, taken in order, so its log
    order is the controller's). On equal keys: log order, then the order of ``items``."""
    import bisect

    from .replay_nodes import stamp_of

    by_log = sorted(answers)
    logs = [log for log, _stamp in by_log]
    keyed = []
    for i, (log, role, data) in enumerate(items):
        if role == stream_role:
            stamp = _first_stamp(role, data)
            after = bisect.bisect_right(logs, log)     # the first answer logged after it
            if after < len(by_log):
                stamp = min(stamp, by_log[after][1])
        else:
            stamp = stamp_of(data)
        rank = _AFTER_ANSWER if role in ACTED_ROLES else _BEFORE_ANSWER
        keyed.append(((stamp, rank, log, i), ("message", role, data, log)))
    for stamp in {stamp for _log, stamp in answers}:
        keyed.append(((stamp, _ANSWER, 0, 0), ("answer", stamp)))
    keyed.sort(key=lambda k: k[0])
    return [step for _key, step in keyed]


def recorded_lag(items: list, answers: list, stream_role: str) -> tuple:
    """(messages, stamp ns): how far behind the stream the recorded controller answered
    at most: the ``stream_role`` messages (of :func:`schedule`'s ``items``) logged
    before an answer (``answers``) whose first sample is after its section, and that
    section's stamp (0, None: never behind)."""
    stream = sorted((it[0], _first_stamp(it[1], it[2])) for it in items
                    if it[1] == stream_role)
    logs = np.array([m[0] for m in stream], dtype=np.int64)
    firsts = np.sort(np.array([m[1] for m in stream], dtype=np.int64))
    worst = (0, None)
    for log, stamp in answers:
        behind = int(np.searchsorted(logs, log) - np.searchsorted(firsts, stamp, "right"))
        worst = max(worst, (behind, stamp), key=lambda w: w[0])
    return worst


def compare_messages(recorded: dict, replayed: dict) -> dict:
    """Two sets of messages (stamp ns -> serialized message) compared bytes for bytes:
    counts and the first differing stamp."""
    both = sorted(set(recorded) & set(replayed))
    differ = [k for k in both if recorded[k] != replayed[k]]
    return {"recorded": len(recorded), "replayed": len(replayed),
            "bit_identical": len(both) - len(differ), "differing": len(differ),
            "missing_in_replay": len(set(recorded) - set(replayed)),
            "first_differing_stamp_ns": differ[0] if differ else None}


def _recorded(data, topic: str) -> dict:
    """stamp ns -> the first recorded message of ``topic`` with that stamp."""
    cols = reader.serialized(reader.read_raw(data.path, [topic]), topic)
    return _by_stamp(cols["data"], cols["ok"])


def _by_stamp(messages, ok=None) -> dict:
    from .replay_nodes import stamp_of

    out = {}
    for i, m in enumerate(messages):
        if ok is None or ok[i]:
            out.setdefault(stamp_of(m), m)
    return out


def _recorded_items(data, roles) -> tuple:
    """(items, answers) of :func:`schedule` from the bag: the input roles' and
    the Pi2 samples' messages, the corrections' log times and stamps."""
    topics = [data.topics[r] for r in roles + ("pi2", "correction")]
    raw = reader.read_raw(data.path, topics)
    items = []
    for role in [r for r in roles if r in data.present] + ["pi2"]:
        cols = reader.serialized(raw, data.topics[role])
        keep = np.flatnonzero(cols["ok"]).tolist()
        items += [(int(cols["log_time"][i]), role, cols["data"][i]) for i in keep]
    corr = reader.decode_twist_stamped(raw, data.topics["correction"])
    ok = corr["ok"]
    answers = list(zip(corr["log_time"][ok].tolist(), corr["stamp"][ok].tolist()))
    return items, answers


def _message_class(role: str):
    import importlib

    module, name = INPUTS[role]
    return getattr(importlib.import_module(module), name)


def replay_stream(data, values: dict, source: str, notes: list, out, *, setup=None,
                  rate=None, domain_id=None, answer_timeout: float = 2.0,
                  log_dir=None) -> dict:
    """Replay a stream scene's bag (``data``, :func:`load`) through a controller_node with
    ``values`` (``source``: where they came from; ``notes`` extended); compare (module
    docstring). Returns what :func:`grazing_control.recordings.replay.replay_controller`
    returns, with ``stream`` (what was published) and ``estimates`` (their comparison).
    ValueError for a bag that cannot be replayed (:func:`check`), RuntimeError if the
    controller does not start or exits."""
    from rclpy.duration import Duration

    from .replay import compare_corrections
    from .replay_nodes import ControllerRun

    check(data, values, notes)
    stream_role, roles = inputs_of(values)
    sim = (data.parameters.get("nodes", {}).get("sim_node") or [{}])[0]
    if sim.get("mode") == "realtime":
        pace = ("as fast as the controller answers" if rate is None else
                f"at the recorded timing x{rate:g}")
        notes.append(f"a realtime scene, replayed {pace}: its answers depend on the "
                     "samples' stamps; where a deadline miss or a substitution came "
                     "relative to the stream is the recorder's order")
    items, answers = _recorded_items(data, roles)
    corrections = data.topics["correction"]
    estimates = corrections.rsplit("/", 1)[0] + "/estimate"
    steps = schedule(items, answers, stream_role)
    published = {r: 0 for r in roles}
    waited = missing = 0
    with ControllerRun(out, domain_id=domain_id, log_dir=log_dir, estimates=True) as run:
        pubs = {r: run.publisher(_message_class(r), DEFAULT_TOPICS[r][1:]) for r in roles}
        run.start(values, list(pubs.values()))
        for r in roles:
            run.writer.add_topic(DEFAULT_TOPICS[r], _type_name(r),
                                 run.offered(DEFAULT_TOPICS[r]))
        pi2_meta = reader.read_raw(data.path, [data.present["pi2"]]).channels[
            data.present["pi2"]].metadata.get("offered_qos_profiles", "")
        run.writer.add_topic(DEFAULT_TOPICS["pi2"], "sensor_msgs/msg/JointState", pi2_meta)
        t0, log0 = time.monotonic(), min((it[0] for it in items), default=0)
        for step in steps:
            if step[0] == "answer":
                if rate is None:
                    waited += 1
                    missing += not run.wait_answer(step[1], answer_timeout)
                continue
            role, msg, log = step[1:]
            if role == "pi2":           # copied, not published: the controller reads none
                run.writer.write(DEFAULT_TOPICS["pi2"], msg, time.time_ns())
                continue
            if rate is not None:
                run.session.until(t0 + (log - log0) / 1e9 / rate)
            pubs[role].publish(msg)
            if role != stream_role and rate is None:
                # Topics keep no order between them at a reader: a substitution published
                # before the next period's stream reached the controller after the
                # sample that made the next section due (1 in about 10 replays with
                # three at once, 2026-11-29). The stream goes on once it has it.
                pubs[role].wait_for_all_acked(Duration(seconds=answer_timeout))
            run.writer.write(DEFAULT_TOPICS[role], msg, time.time_ns())
            published[role] += 1
        run.collect_late([a[1] for a in answers], answer_timeout)   # the late ones
        run.finish({"source_bag": str(data.path), "gains_source": source,
                    "rate": "as fast as possible" if rate is None else rate,
                    "replayed": "the sensor stream (pi2_source stream)"})
    lag = recorded_lag(items, answers, stream_role)
    res = {"gains_source": source, "notes": notes, "domain_id": run.domain_id,
           "samples_published": published[stream_role], "answers": len(run.answers),
           "stream": {"topic": DEFAULT_TOPICS[stream_role], "published": published,
                      "answers_awaited": waited, "answers_not_in_time": missing,
                      "recorded_lag_messages": lag[0], "recorded_lag_stamp_ns": lag[1]},
           "comparison": compare_corrections(data, load(out), setup),
           # every answer (correction and predicted next correction) and estimate by
           # stamp, the section after the last Pi2 sample's too
           "answers_bytes": compare_messages(_recorded(data, corrections),
                                             {k: m for k, (m, _t) in run.answers.items()}),
           "estimates": compare_messages(_recorded(data, estimates),
                                         {k: m for k, (m, _t) in run.estimates.items()})}
    from grazing_control.ros.common import DATA_QOS

    if lag[0] > DATA_QOS.depth and not res["comparison"].get("all_bit_identical"):
        res["why"] = (f"the recorded controller answered section t = {lag[1] / 1e9:.9g} "
                      f"{lag[0]} stream messages behind the stream, more than its "
                      f"subscription keeps ({DATA_QOS.depth}): it lost samples the recorder "
                      "kept, and its answers are not those of the recorded stream from "
                      "there (a realtime scene faster than the controller)")
    return res


def _type_name(role: str) -> str:
    module, name = INPUTS[role]
    return f"{module.split('.')[0]}/msg/{name}"

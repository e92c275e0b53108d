"""From a recording to scenes: the columns of the package's topics, split and matched.

:func:`load` reads one bag (directory or bare .mcap, by :mod:`.reader`), decodes the
topics the analysis uses (names remappable), splits the Pi2 samples into scenes (a
simulator reset starts a new scene at t = 0), matches each correction to the sample it
answers by the stamp (spec ros.md), and collects the parameter record
(:mod:`.record`). What it cannot use is said in ``notes``/``problems``, never silently
dropped. Two simulators on one topic leave duplicate sample stamps: refused
(:class:`DuplicateStampsError`), since their samples cannot be told apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .analysis import Scene
from . import reader
from grazing_control.ros.recording.record import run_parameters

__all__ = ["DEFAULT_TOPICS", "EXPECTED_TYPES", "DuplicateStampsError", "SceneData", "BagData",
           "load", "parse_topic_option", "parse_topic_options"]

#: Role -> default topic name (the names the nodes publish in the root namespace).
DEFAULT_TOPICS = {
    "pi2": "/oscillator/pi2",
    "correction": "/controller/velocity_correction",
    "impact": "/oscillator/impact",
    "pi1": "/oscillator/pi1",
    "state": "/oscillator/state",
    "state_block": "/oscillator/state_block",
    "latency": "/oscillator/latency",
    "deadline_miss": "/oscillator/deadline_miss",
    "substituted": "/oscillator/substituted",
    "enabled": "/controller/enabled",
    "parameters": "/grazing/parameters",
    "published": "/grazing/published",
}

#: Role -> the message type the analysis can decode (None: any type, counted only).
EXPECTED_TYPES = {
    "pi2": "sensor_msgs/msg/JointState",
    "correction": "geometry_msgs/msg/TwistStamped",
    "impact": "geometry_msgs/msg/Vector3Stamped",
    "pi1": "sensor_msgs/msg/JointState",
    "state": "sensor_msgs/msg/JointState",
    "state_block": "std_msgs/msg/Float64MultiArray",
    "latency": "std_msgs/msg/Float64",
    "deadline_miss": None,
    "substituted": "geometry_msgs/msg/TwistStamped",
    "enabled": "std_msgs/msg/Bool",
    "parameters": "std_msgs/msg/String",
    "published": "std_msgs/msg/String",
}

#: Roles not needed by the analysis: listed as present or absent, not decoded.
_COUNTED_ONLY = ("pi1", "state", "state_block")

_NS = 1_000_000_000


class DuplicateStampsError(ValueError):
    """Pi2 samples with equal stamps in one scene: more than one simulator on the topic."""


def parse_topic_option(values) -> dict:
    """``["pi2=/rig/pi2", ...]`` -> role -> topic (ValueError naming a bad entry)."""
    topics = dict(DEFAULT_TOPICS)
    for text in values or ():
        role, sep, name = text.partition("=")
        if not sep or not name:
            raise ValueError(f"--topic {text!r} is invalid: expected ROLE=/topic/name")
        if role not in DEFAULT_TOPICS:
            raise ValueError(f"--topic {text!r} is invalid: ROLE must be one of "
                             f"{', '.join(DEFAULT_TOPICS)}")
        topics[role] = name if name.startswith("/") else "/" + name
    return topics


def parse_topic_options(values, n_bags: int) -> list:
    """``--topic [N:]ROLE=TOPIC`` for ``n_bags`` bags -> one role -> topic dict per bag.

    Without ``N:`` a remap applies to every bag; with it (1-based, in the order the bags
    are given) to bag N only, so a rig's bag can be compared with a package bag
    (``--topic 2:pi2=/rig/pi2``). A per-bag remap wins over an all-bags one.
    """
    common, per = [], [[] for _ in range(n_bags)]
    for text in values or ():
        head, colon, rest = text.partition(":")
        if colon and head.isdigit() and "=" not in head:
            k = int(head)
            if not 1 <= k <= n_bags:
                raise ValueError(f"--topic {text!r} is invalid: bag number {k} is not in "
                                 f"1..{n_bags} (the bags in the order given)")
            parse_topic_option([rest])               # validated alone first
            per[k - 1].append(rest)
        else:
            parse_topic_option([text])
            common.append(text)
    return [parse_topic_option(common + own) for own in per]


@dataclass
class SceneData:
    """One scene of a bag: the analysis Scene plus the wall-clock columns of its messages.

    ``stamp_ns``: sample stamps (int64 ns); ``pi2_pub_ns`` / ``pi2_log_ns``: their
    publish (source) and log (receive) times; ``answered``: whether a correction for the
    sample was recorded; ``corr_pub_ns``: its publish time (-1 if none); ``latency_s``:
    the simulator's own latency messages (realtime), ``deadline_misses``: messages on
    the deadline-miss topic in this scene's time span, ``missed_stamp_ns``: the stamps of
    the samples they name (their corrections were not applied).
    """

    index: int
    scene: Scene
    stamp_ns: np.ndarray
    pi2_pub_ns: np.ndarray
    pi2_log_ns: np.ndarray
    answered: np.ndarray
    corr_pub_ns: np.ndarray
    duplicate_answers: int = 0
    conflicting_answers: int = 0
    unmatched_answers: int = 0
    latency_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    deadline_misses: int | None = None
    #: stamps (int64 ns) of the samples whose correction the simulator did not apply
    #: (its deadline-miss messages; the correction arrived too late or never)
    missed_stamp_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: stamp (int64 ns) -> the predicted correction the simulator applied in place of a
    #: missing answer (``oscillator/substituted``, on_miss predict)
    substituted: dict = field(default_factory=dict)
    #: realtime: the plant's pauses for the simulator's stalls (its ``paused`` event
    #: records, plant.realtime.Realtime.resume), rows (the simulation time up to which
    #: everything had gone out before the pause, wall seconds), in time order
    pauses: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    #: a rig scene off the rig's grid (:func:`.rig_acts.apply_acts`): each pulse's start,
    #: model time after its section (NaN: the rig's own instant), the rig's count of late
    #: answers and of rig/applied per status; None otherwise
    pulse_starts: np.ndarray | None = None
    rig_late: int | None = None
    rig_status: dict | None = None


@dataclass
class BagData:
    """A bag read for the analysis (see :func:`load`)."""

    path: Path
    file: Path
    complete: bool
    topics: dict
    present: dict
    scenes: list
    parameters: dict
    notes: list
    problems: list
    message_count: int        # every message record of the file
    messages_read: int = 0    # those on the topics the analysis reads
    joints: int = 1           # coordinates per Pi2 sample (n of an n-DOF scene; its Scene.pi2
    #                           is then (N, 2n): x_0 .. x_{n-1}, v_0 .. v_{n-1})


def _scene_index(starts_log, log):
    return np.clip(np.searchsorted(starts_log, log, side="right") - 1, 0, None)


def _namespace(channels, topics) -> str | None:
    """The namespace of a scene recorded under one (``/a/oscillator/pi2``: ``/a``) when the
    Pi2 topic is the default one, absent, and present under exactly one namespace; else
    None (a bag of two namespaced scenes needs ``--topic``)."""
    pi2 = topics["pi2"]
    if pi2 != DEFAULT_TOPICS["pi2"] or pi2 in channels:
        return None
    found = [t[:-len(pi2)] for t in channels if t.endswith(pi2) and t != pi2
             and t[:-len(pi2)].startswith("/")]
    return found[0] if len(found) == 1 else None


def published_problems(raw, present: dict, topics: dict, parameters: dict, notes: list) -> list:
    """Messages the nodes published that the bag lacks (issue 27), as problems.

    Each node of the package says, when it stops, how many messages it published on each
    topic (``grazing/published``, :func:`grazing_control.ros.recording.record.
    decode_published`); a topic that the analysis reads holding fewer is named with the
    number lost. A node with a parameter record but no published record (a bag recorded
    before the record existed, or a node killed) is a note: the tail is not checked.
    """
    from grazing_control.ros.recording.record import decode_published

    out, published = [], {}
    if "published" in present:
        for _t, text in reader.decode_strings(raw, present["published"]):
            try:
                node, counts = decode_published(text)
            except ValueError:
                out.append(f"a message on {present['published']} is not a published record: "
                           "ignored")
                continue
            published[node.rsplit("/", 1)[-1] or node] = counts
    read = {name for role, name in topics.items() if role not in _COUNTED_ONLY}
    for node, counts in sorted(published.items()):
        for topic, n in sorted(counts.items()):
            have = raw.count(topic)
            if topic in read and have < n:
                out.append(f"{topic}: {n - have} of the {n} messages {node} published are "
                           f"not in the bag (lost in the recording)")
    silent = sorted(set(parameters.get("nodes", {})) - set(published))
    if silent:
        notes.append(f"no published record from {', '.join(silent)}: whether the bag holds "
                     "every message it published (its tail) is not checked")
    return out


def load(bag, topics: dict | None = None) -> BagData:
    """Read one bag for the analysis.

    Parameters
    ----------
    bag : path of a rosbag2 directory or of a bare .mcap file.
    topics : role -> topic name (default :data:`DEFAULT_TOPICS`).

    Raises
    ------
    reader.BagReadError
        Not an MCAP bag, or no usable Pi2 topic.
    DuplicateStampsError
        Equal Pi2 stamps within a scene (two simulators on one topic).
    """
    topics = dict(DEFAULT_TOPICS if topics is None else topics)
    path = Path(bag)
    raw = reader.read_raw(path, topics=[topics[r] for r in topics if r not in _COUNTED_ONLY])
    notes, problems = [], list(raw.problems)
    present = {}
    for role, name in topics.items():
        ch = raw.channels.get(name)
        if ch is None:
            continue
        want = EXPECTED_TYPES[role]
        if want is not None and ch.type != want:
            problems.append(f"topic {name} ({role}) has type {ch.type or '?'}, expected {want}: "
                            "not used")
            continue
        if ch.encoding != "cdr":
            problems.append(f"topic {name} ({role}) has message encoding {ch.encoding!r}, "
                            "expected 'cdr': not used")
            continue
        present[role] = name
    known = set(topics.values())
    extra = sorted(t for t in raw.channels if t not in known
                   and not t.endswith("/grazing/rig"))     # the rig: read by .rig_record
    if extra:
        notes.append(f"other topics not used by the analysis: {', '.join(extra)}")
    missing = [f"{topics[r]} ({r})" for r in topics if r not in present
               and r not in ("deadline_miss", "substituted", "enabled", "published",
                             "state_block")]
    if missing:
        notes.append(f"absent: {', '.join(missing)}")
    if "pi2" not in present:
        ns = _namespace(raw.channels, topics)
        if ns is not None:      # a scene launched under a namespace: its topics, all of them
            renamed = {r: (ns + t if t == DEFAULT_TOPICS.get(r) else t)
                       for r, t in topics.items()}
            data = load(bag, renamed)
            data.notes.insert(0, f"the scene's topics are under the namespace {ns} (the only "
                                 f"one with {topics['pi2']}): read from there")
            return data
        available = ", ".join(f"{t} [{c.type}]" for t, c in sorted(raw.channels.items())) or "none"
        raise reader.BagReadError(
            f"{path}: no usable Pi2 sample topic {topics['pi2']} (sensor_msgs/msg/JointState); "
            f"topics in the bag: {available}. Remap with --topic pi2=/your/topic"
            + "".join(f"; {msg}" for msg in problems if "(pi2)" in msg))

    pi2 = reader.decode_joint_state(raw, present["pi2"])
    joints = reader.joint_count(raw, present["pi2"])
    if joints > 1:           # an n-DOF scene (issue 17): every coordinate, x (N, n), v (N, n)
        pi2 = reader.decode_joint_states(raw, present["pi2"], joints)
    bad = int(np.count_nonzero(~pi2["ok"]))
    if bad:
        problems.append(f"{bad} malformed Pi2 messages (too short, no position/velocity, "
                        "or big-endian CDR): not used")
    order = np.argsort(pi2["log_time"], kind="stable")
    order = order[pi2["ok"][order]]
    finite = np.all(np.isfinite(np.column_stack([pi2["x"][order], pi2["v"][order]])), axis=1)
    if not finite.all():
        bad_t = pi2["stamp"][order][~finite] / _NS
        problems.append(f"{int(np.count_nonzero(~finite))} Pi2 samples with a non-finite state "
                        f"(first at t = {bad_t[0]:.9g} s): not used")
        order = order[finite]
    stamp = pi2["stamp"][order]
    x, v = pi2["x"][order], pi2["v"][order]
    pub, log = pi2["publish_time"][order], pi2["log_time"][order]
    if stamp.size == 0:
        raise reader.BagReadError(f"{path}: {present['pi2']} holds no usable Pi2 sample")

    # scenes: a reset publishes sample 0 at t = 0 again
    starts = np.flatnonzero(stamp == 0)
    starts = np.concatenate([[0], starts[starts > 0]]).astype(np.int64)
    bounds = list(starts) + [stamp.size]
    for a, b in zip(bounds[:-1], bounds[1:]):
        d = np.diff(stamp[a:b])
        if d.size and np.any(d <= 0):
            dup = int(np.count_nonzero(d == 0))
            back = int(np.count_nonzero(d < 0))
            seg = stamp[a:b]
            uniq, counts = np.unique(seg, return_counts=True)
            first = uniq[counts > 1][0] if np.any(counts > 1) else seg[1:][d < 0][0]
            raise DuplicateStampsError(
                f"{path}: {present['pi2']} has {int(np.sum(counts[counts > 1]))} samples with "
                f"duplicate stamps ({dup} repeated, {back} going back; first at t = "
                f"{first / _NS:.9g} s): more than one simulator publishes on this topic, and "
                "their samples cannot be told apart. Record each scene on its own ROS domain "
                "(`grazing run --domain-id`) or remap one simulator's topics")
    starts_log = log[starts]

    parameters = {"nodes": {}, "events": [], "rejected": 0}
    if "parameters" in present:
        parameters = run_parameters(reader.decode_strings(raw, present["parameters"]))
        if parameters["rejected"]:
            problems.append(f"{parameters['rejected']} messages on {present['parameters']} are "
                            "not parameter records: ignored")
        for ev in parameters["events"]:          # the simulator's watchdog, feasibility
            if ev["event"] == "watchdog":
                problems.append(f"the simulator's watchdog tripped ({ev.get('kind')}) at "
                                f"sample {ev.get('k')}, t = {ev.get('t')}: {ev.get('reason')}; "
                                "no correction acted from there and the scene ended")
            elif ev["event"] == "feasibility" and ev.get("level") != "ok":
                notes.append(f"feasibility check before the start: {ev.get('line')}")

    problems += published_problems(raw, present, topics, parameters, notes)

    corr = None
    if "correction" in present:
        corr = reader.decode_twist_stamped(raw, present["correction"])
        badc = int(np.count_nonzero(~corr["ok"]))
        if badc:
            problems.append(f"{badc} malformed corrections: not used")
        co = np.argsort(corr["log_time"], kind="stable")
        nonfinite = int(np.count_nonzero(corr["ok"][co] & ~np.isfinite(corr["dv"][co])))
        if nonfinite:
            problems.append(f"{nonfinite} of {co.size} corrections are not finite numbers: "
                            "not used (the samples they answer count as unanswered)")
        co = co[corr["ok"][co] & np.isfinite(corr["dv"][co])]
        corr = {k: (val[co] if isinstance(val, np.ndarray) else val) for k, val in corr.items()}
        corr["scene"] = _scene_index(starts_log, corr["log_time"])
    else:
        notes.append("no corrections recorded: every sample is treated as uncorrected")
    imp = None
    if "impact" in present:
        imp = reader.decode_vector3_stamped(raw, present["impact"])
        ok = imp["ok"]
        imp = {k: (val[ok] if isinstance(val, np.ndarray) else val) for k, val in imp.items()}
        imp["scene"] = _scene_index(starts_log, imp["log_time"])
    lat = None
    if "latency" in present:
        lat = reader.decode_float64(raw, present["latency"])
        lat["scene"] = _scene_index(starts_log, lat["log_time"])
    if "enabled" in present:            # ~/enable calls: the explicit switch, recorded
        en = reader._Body(raw.pool, raw.offsets(present["enabled"]))
        ok = en.ok & (en.end - en.body >= 1)
        flags = raw.pool[np.where(ok, en.body, 0)] != 0
        for t_log, on in zip(en.log_time[ok].tolist(), flags[ok].tolist()):
            k = int(np.searchsorted(log, t_log, side="right")) - 1
            what = (f"~/enable switched the control {'on' if on else 'off'} during the run "
                    f"(after sample {max(k, 0)}, log time {t_log / _NS:.6f} s)")
            (notes if on else problems).append(
                what if on else what + ": from there on the corrections are not the "
                "designed controller's")
    sub = None
    if "substituted" in present:        # the predictions that acted at misses (on_miss)
        sub = reader.decode_twist_stamped(raw, present["substituted"])
        ok = sub["ok"] & np.isfinite(sub["dv"])
        sub = {"stamp": sub["stamp"][ok], "dv": sub["dv"][ok],
               "scene": _scene_index(starts_log, sub["log_time"][ok])}
    dl_scene = dl_stamp = None
    if "deadline_miss" in present:
        dl = reader.decode_vector3_stamped(raw, present["deadline_miss"])
        dl_scene = _scene_index(starts_log, dl["log_time"])
        dl_stamp = np.where(dl["ok"], dl["stamp"], -1)

    paused = [ev for ev in parameters["events"] if ev["event"] == "paused"
              and isinstance(ev.get("t"), float) and isinstance(ev.get("seconds"), float)]
    paused_scene = _scene_index(starts_log, np.array([ev["log_time_ns"] for ev in paused],
                                                     dtype=np.int64))

    scenes = []
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        st = stamp[a:b]
        t = st / _NS
        dv = np.zeros(b - a)
        answered = np.zeros(b - a, bool)
        corr_pub = np.full(b - a, -1, np.int64)
        dup = conflict = unmatched = 0
        if corr is not None:
            m = corr["scene"] == i
            cst, cdv, cpub = corr["stamp"][m], corr["dv"][m], corr["publish_time"][m]
            if cst.size:
                uniq, first, counts = np.unique(cst, return_index=True, return_counts=True)
                dup = int(np.sum(counts - 1))
                if dup:
                    # the same stamp answered twice with different values: two controllers
                    for s_ in uniq[counts > 1]:
                        if np.unique(cdv[cst == s_]).size > 1:
                            conflict += 1
                pos = np.searchsorted(st, uniq)
                hit = (pos < st.size) & (st[np.minimum(pos, st.size - 1)] == uniq)
                unmatched = int(np.count_nonzero(~hit))
                k = pos[hit]
                dv[k] = cdv[first[hit]]
                answered[k] = True
                corr_pub[k] = cpub[first[hit]]
        impacts = np.zeros((0, 4))
        if imp is not None:
            m = imp["scene"] == i
            it = imp["stamp"][m] / _NS
            impacts = np.column_stack([it, imp["vx"][m], imp["vy"][m], imp["vz"][m]])
            impacts = impacts[np.argsort(impacts[:, 0], kind="stable")]
        sd = SceneData(i, Scene(t, np.column_stack([x[a:b], v[a:b]]), dv, impacts), st,
                       pub[a:b], log[a:b], answered, corr_pub, dup, conflict, unmatched)
        if lat is not None:
            sd.latency_s = lat["data"][(lat["scene"] == i) & lat["ok"]]
        if dl_scene is not None:
            sd.deadline_misses = int(np.count_nonzero(dl_scene == i))
            missed = dl_stamp[(dl_scene == i) & (dl_stamp >= 0)]
            sd.missed_stamp_ns = np.unique(missed[np.isin(missed, st)])
        rows = [(ev["t"], ev["seconds"]) for ev, s in zip(paused, paused_scene) if s == i]
        if rows:
            sd.pauses = np.array(sorted(rows), dtype=float)
        if sub is not None:
            m = sub["scene"] == i
            sd.substituted = dict(zip(sub["stamp"][m].tolist(), sub["dv"][m].tolist()))
        scenes.append(sd)
    if len(scenes) > 1:
        notes.append(f"{len(scenes)} scenes (the simulator was reset {len(scenes) - 1} times)")
    if not raw.complete:
        notes.append("the file was not closed cleanly (no summary): read by streaming up to "
                     "its last complete record")
    read = sum(len(c.records) for c in raw.channels.values())
    return BagData(path, raw.path, raw.complete, topics, present, scenes, parameters, notes,
                   problems, raw.message_count, read, max(joints, 1))

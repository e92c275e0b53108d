"""The parameter record: a node's parameters as JSON, so that a recording describes itself.

Each node publishes its parameters on ``grazing/parameters`` (std_msgs/String, reliable,
transient local, depth 1) at start and again after every accepted change; the recorder
records that topic by default (docs/analysis.md, "Parameter record"). The text is one JSON
object::

    {"record": "grazing_control/parameters", "version": 1, "node": "/sim_node",
     "parameters": {"delta_d": -5e-06, "mode": "lockstep", ...}}

Non-finite numbers are written as the strings "nan", "inf", "-inf" (strict JSON).

The published record (issue 27): when a node stops it says how many messages it published
on each of its recorded topics, on ``grazing/published`` (std_msgs/String, reliable,
transient local, depth 1)::

    {"record": "grazing_control/published", "version": 1, "node": "/controller_node",
     "topics": {"/controller/velocity_correction": 1501, "/controller/estimate": 1501}}

so that a recording can be checked for completeness up to its last message: the recorder
waits for those counts before it closes and reports what is still missing; the analysis
names a topic the bag holds fewer messages of than its publisher published.

The same topic carries the simulator's **events** (issue 27 §1), so that a recording says
how its scene ended without a topic of its own: the realtime watchdog's trip and the
verdict of the check before the start (plant.watchdog, plant.feasibility)::

    {"record": "grazing_control/event", "version": 1, "node": "/sim_node",
     "event": "watchdog", "kind": "misses", "k": 24, "t": 226.04, "reason": "25 of ..."}

This module has no ROS dependency: the nodes call :func:`encode`,
:func:`encode_published` and :func:`encode_event`, the analysis :func:`decode`,
:func:`run_parameters`, :func:`decode_published` and :func:`decode_event`.
"""

from __future__ import annotations

import json
import math

__all__ = ["TOPIC", "KIND", "EVENT_KIND", "encode", "encode_event", "decode",
           "decode_event", "run_parameters", "PUBLISHED_TOPIC", "PUBLISHED_KIND",
           "encode_published", "decode_published"]

#: Relative topic name of the record (``/grazing/parameters`` in the root namespace).
TOPIC = "grazing/parameters"
#: Value of the "record" key, so that a foreign String on the topic is recognised.
KIND = "grazing_control/parameters"
VERSION = 1
#: Relative topic name of the published record (module docstring).
PUBLISHED_TOPIC = "grazing/published"
#: Value of its "record" key.
PUBLISHED_KIND = "grazing_control/published"
#: Value of the "record" key of an event record (the watchdog, the feasibility check).
EVENT_KIND = "grazing_control/event"


def _plain(value):
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    return value


def _number(value):
    if isinstance(value, str) and value in ("nan", "inf", "-inf"):
        return float(value)
    return value


def encode(node: str, parameters: dict) -> str:
    """The JSON text of one record (``node``: its fully qualified name)."""
    body = {k: _plain(v) for k, v in sorted(parameters.items())}
    return json.dumps({"record": KIND, "version": VERSION, "node": node, "parameters": body},
                      allow_nan=False, separators=(",", ":"))


def encode_event(node: str, event: str, **fields) -> str:
    """The JSON text of one event record: ``event`` ('watchdog', 'feasibility') and its
    ``fields`` (plain values)."""
    body = {k: _plain(v) for k, v in fields.items()}
    return json.dumps({"record": EVENT_KIND, "version": VERSION, "node": node,
                       "event": str(event), **body}, allow_nan=False, separators=(",", ":"))


def decode_event(text: str) -> dict:
    """The fields of an event record's text (node, event, ...); ValueError if it is not
    one."""
    try:
        obj = json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        raise ValueError("not JSON") from None
    if not isinstance(obj, dict) or obj.get("record") != EVENT_KIND or not isinstance(
            obj.get("event"), str):
        raise ValueError("not a grazing_control event record")
    return {k: _number(v) for k, v in obj.items() if k not in ("record", "version")}


def decode(text: str):
    """(node, parameters) of a record's text; ValueError if it is not one."""
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not JSON ({exc.msg})") from None
    except RecursionError:              # a hostile, deeply nested text
        raise ValueError("JSON nested too deeply") from None
    if not isinstance(obj, dict) or obj.get("record") != KIND:
        raise ValueError("not a grazing_control parameter record")
    params = obj.get("parameters")
    if not isinstance(params, dict):
        raise ValueError("parameter record without a 'parameters' object")
    return str(obj.get("node", "")), {k: _number(v) for k, v in params.items()}


def run_parameters(records) -> dict:
    """Per node short name ("sim_node", "controller_node"): the records in time order.

    ``records``: (log_time_ns, text) pairs. Returns ``{"nodes": {name: [params, ...]},
    "events": [event, ...], "rejected": n}`` where the first entry of each list is the
    parameters at start and the others are later changes; ``events`` the event records
    (:func:`decode_event`) in time order, each with its ``log_time_ns``.
    """
    nodes, rejected, events = {}, 0, []
    for log_ns, text in sorted(records, key=lambda r: r[0]):
        try:
            node, params = decode(text)
        except ValueError:
            try:
                events.append({**decode_event(text), "log_time_ns": log_ns})
            except ValueError:
                rejected += 1
            continue
        name = node.rsplit("/", 1)[-1] or node
        seq = nodes.setdefault(name, [])
        if not seq or seq[-1] != params:
            seq.append(params)
    return {"nodes": nodes, "events": events, "rejected": rejected}


def encode_published(node: str, counts: dict) -> str:
    """The JSON text of a published record: ``counts`` = fully qualified topic -> number
    of messages the node published on it."""
    body = {str(k): int(v) for k, v in sorted(counts.items())}
    return json.dumps({"record": PUBLISHED_KIND, "version": VERSION, "node": node,
                       "topics": body}, separators=(",", ":"))


def decode_published(text: str):
    """(node, {topic: count}) of a published record's text; ValueError if it is not one
    (not JSON, another record, a count that is not an integer >= 0)."""
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not JSON ({exc.msg})") from None
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None
    if not isinstance(obj, dict) or obj.get("record") != PUBLISHED_KIND:
        raise ValueError("not a grazing_control published record")
    topics = obj.get("topics")
    if not isinstance(topics, dict) or not all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in topics.values()):
        raise ValueError("published record without a 'topics' object of counts >= 0")
    return str(obj.get("node", "")), {str(k): v for k, v in topics.items()}

"""How a scene ended, in one line: the simulator's verdict file and what the launcher saw.

:func:`grazing_control.ros.launcher.run` reads the simulator's ``verdict_file`` (its own
reason: the realtime watchdog's trip, a refused feasibility check, a stopped simulation)
and, for a scene that failed, puts :func:`failure_reason` in ``RunResult.reason``;
:func:`scene_numbers` gives the simulator's numbers for the last line of every scene.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["read_verdict", "failure_reason", "scene_numbers"]


def read_verdict(path: Path):
    """sim_node's ``verdict_file`` (a JSON object), or None when it wrote none (killed,
    refused at start) or it is unreadable."""
    import json

    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return obj if isinstance(obj, dict) else None


def failure_reason(res, early=None, timeout=None) -> str:
    """Why the scene ``res`` (a ``launcher.RunResult``) failed, in one line: the
    simulator's own reason (the watchdog's trip, the feasibility refusal, a stopped
    simulation: its verdict_file), else what the launcher saw (a timeout, an
    interruption, a node that left early or failed, with its last error line). A node
    that refused to start (exit status 2: a parameter out of its range) comes first, and
    a node that left early (killed) before what followed from it (the recording that
    lost that node's tail).
    ``early``: the nodes that left early (default: ``res.early``)."""
    if early is None:
        early = getattr(res, "early", ())
    verdict = res.sim_verdict or {}
    # (a simulator that wrote its own reason, a feasibility refusal, is told by it below)
    refused = [name for name, attr in _FIELD.items()
               if getattr(res, attr) == REFUSED and name not in early
               and not (name == "sim_node" and verdict.get("reason"))]
    parts = [f"{name} exited with status {REFUSED}" + _said(res.logs.get(name))
             for name in refused]
    if verdict.get("reason") and res.sim != 0:
        parts.append(f"sim_node: {verdict['reason']}")
    for name in early:
        parts.append(f"{name} exited early with status {getattr(res, _FIELD[name])}"
                     + _said(res.logs.get(name)))
    if res.timed_out:
        parts.append(f"timed out after {timeout:g} s" if timeout else "timed out")
    if res.interrupted:
        parts.append("interrupted")
    if res.lost:
        parts.append(f"the recording lost messages: {res.lost}")
    for name, attr in _FIELD.items():
        code = getattr(res, attr)
        if code not in (None, 0) and name not in early and name not in refused and not (
                name == "sim_node" and parts and verdict.get("reason")):
            parts.append(f"{name} exited with status {code}" + _said(res.logs.get(name)))
    return "; ".join(parts) or "unknown"


def scene_numbers(verdict) -> str:
    """What the simulator's summary line (in its verdict) says of the run, in words for
    ``grazing run``'s last line: the periods and their pace, the corrections applied, the
    deadlines missed and the answers late, and the plant's pauses where there were any
    (a realtime scene that missed or paused says so where the user looks, not only in
    the simulator's log); '' without a summary."""
    line = str((verdict or {}).get("summary") or "")
    words = dict(w.split("=", 1) for w in line.split() if "=" in w)
    if "periods" not in words:
        return ""
    text = f"{words['periods']} periods"
    if "rate" in words:
        text += f" at {words['rate']} periods/s"
    text += ", " + ", ".join(f"{words[k]} {k}" for k in ("applied", "missed", "late")
                             if k in words)
    if "paused" in words:
        text += (f", the plant's clock paused {words['paused']} times "
                 f"({words.get('paused_ms', '?')} ms in all)")
    return text


def _said(log) -> str:
    """`` (its last error line)`` from a node's log file (--log-dir; without one its
    output is the terminal's, where the line already is), '' if it logged none: the
    refused parameter behind an exit status 2, with its valid range."""
    try:
        lines = Path(log).read_text(errors="replace").splitlines() if log else []
    except OSError:
        return ""
    for line in reversed(lines):
        if line.startswith("[ERROR]") and "]: " in line:
            said = line.split("]: ", 1)[1].strip()
            return f" ({said[:300]}{'...' if len(said) > 300 else ''})"
    return ""


#: The exit status of a node that refused to start (common.StartupError).
REFUSED = 2

_FIELD = {"sim_node": "sim", "controller_node": "controller", "recorder_node": "recorder",
          "live_node": "live"}

"""What sim_node says about its scene: the summary line, its /diagnostics task and the
verdict file that ``grazing run`` reads."""

from __future__ import annotations

import time

from grazing_control.plant.loop import Loop
from grazing_control.ros.diagnostics import ERROR, WARN


def diagnose(node, stat):
    """The scene's diagnostics task (ros.diagnostics.SceneWindow), thresholds read now
    (they may change while the scene runs)."""
    out = node.out
    counts = {"missed": out.misses.count, "timeouts": out.timeout.count,
              "ignored": out.ignored.count, "malformed": out.malformed.count}
    th = {k: node.get_parameter(f"diag_{k}").value for k in
          ("misses_warn", "misses_error", "latency_warn", "latency_error", "pace_warn")}
    stat = node.window.status(stat, node.loop, counts, time.monotonic(), th,
                               node.settings.mode == "realtime", node.settings.time_scale)
    if node.feasibility is not None:
        stat.add("feasibility", node.feasibility.level)
    if node.trip is not None:
        stat.add("watchdog", node.trip.kind)
        stat.merge_summary(ERROR, f"watchdog tripped at sample {node.trip.k}: "
                                  f"{node.trip.reason}; not actuating")
    elif node.feasibility is not None and node.feasibility.level == "refuse":
        # refused: the node ends with status 2; started anyway (feasibility:=warn): a
        # warning, as asked, until the watchdog says what it cost
        warned = node.get_parameter("feasibility").value == "warn"
        stat.merge_summary(WARN if warned else ERROR, node.feasibility.line)
    return stat


def summary(node) -> str:
    """One line: periods, impacts, corrections, ignored input, rate, latency."""
    wall = time.monotonic() - node.wall_start if node.wall_start else 0.0
    out = node.out
    counts = {"missed": out.misses.count, "timeouts": out.timeout.count,
              "ignored": out.ignored.count, "malformed": out.malformed.count}
    text = (node.loop or Loop(node.engine, out)).summary(wall, counts)
    return text + (node.driver.summary() if node.driver is not None else "")


def verdict(node) -> dict:
    """How the scene ended, for ``verdict_file`` (grazing run's JSON)."""
    trip, fe = node.trip, node.feasibility
    return {"node": node.get_fully_qualified_name(), "status": node.exit_code,
            "finished": bool(node.loop is not None and node.loop.finished),
            "reason": node.reason, "summary": node.summary_line or summary(node),
            "watchdog": None if trip is None else trip._asdict(),
            # where the realtime loop missed (the first MISSES_KEPT) and paused longest
            "misses": node.out.missed, "longest_pause": node.out.longest_pause,
            "feasibility": None if fe is None else {"level": fe.level, "line": fe.line,
                                                    **fe.numbers}}


def write_verdict(path: str, verdict: dict) -> None:
    """Write ``verdict`` as one JSON object to ``path`` (whole or not at all: a file next
    to it renamed over it); an error is one line on stderr, never a crash at exit."""
    import json
    import os
    import sys

    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(verdict, f, default=str)
        os.replace(tmp, path)
    except OSError as exc:
        print(f"sim_node: verdict_file={path!r}: {exc.strerror or exc}", file=sys.stderr)

"""The rig stream at T/200 in realtime x1000: a message per sample against blocks (issue 30).

The scene of docs/nodes.md, "Realtime with a fast sensor stream": realtime at
``--scale`` (default 1000: a period is 9.4 ms of wall time), a position-only sensor at
200 samples per period (21,000 samples a second at x1000), sigma 1e-4, pulse width 0.1
at the actuation delay 3 (scheduled actuation: the correction of section k acts at
t_k + 3 if it has arrived; a deadline miss otherwise), the gains of ``grazing design
--optimize noise --delay 3``, the controller estimating each section from the stream
(``pi2_source:=stream``, model filter, answering after the section), the recorder on,
``--periods`` periods, control from ``--enable-after``. The watchdog and the feasibility
refusal are off so that every scene runs to its end and its misses are counted, not
cut short.

Variants, alternating in one run so that each sees the same load (``--variants``):
``sample`` (a JointState per sample on oscillator/state, the baseline), ``block``
(``stream_message:=block``: a Float64MultiArray per wake-up on oscillator/state_block),
and either of them composed (``+composed``: ``grazing run --compose``, the three nodes in
one process), or under SCHED_FIFO (``+fifo``: the simulator's and the controller's
thread_priority 50, as a rig scene runs them; ``+fifo+pinned``: and the simulator on CPU
0, the controller on CPU 1, their cpu_affinity; ``+fifo+wall``: the plant's clock pinned
to the wall clock, ``stall_pause:=0``, where by default a stall of the simulator pauses
it, plant.realtime); ``+tick<ms>`` on any of them sets the simulator's ``stream_block``
(the wall time a block gathers, default STREAM_TICK 0.5 ms: ``block+fifo+tick1`` gathers
1 ms). From the simulator's summary: periods
per second against the requested (106.2 at x1000), deadline misses and late answers
(sections whose correction was not there at t_k + 3), the answer latency (a section's
last sample published -> its answer received), the sample lag (how late a sample went
out), p50/p99/max, and the plant's pauses (count and longest, ms); and the CPU time of
the scene's processes (the three nodes, their start and end included: the children's
``getrusage``; not measured for a baseline's scenes).

With ``--baseline DIR`` (a git worktree of an older commit) each variant also runs on
that checkout (its own bench_stream_blocks.scene in a fresh interpreter, the launcher
putting that checkout on the nodes' PYTHONPATH), the two alternating scene by scene
(rows ``base:<variant>``).

Run: ``.venv/bin/python benchmarks/bench_stream_blocks.py --reps 2`` (about 40 s a scene).
As a rig controller answers (``answer_lead`` = the budget less half the pulse, 3 - 0.1/2,
under SCHED_FIFO, in blocks): ``--variants block+fifo --answer-lead 2.95``.
Results in docs/benchmarks.md ("The stream in blocks", "T/200's misses").
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_closed_loop import summary  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.ros import launcher  # noqa: E402

DD, SIGMA, RATE, DELAY, WIDTH = -5e-6, 1e-4, 200, 3.0, 0.1
#: Every watchdog check off and the feasibility check a warning: the scene runs to its end.
FREE_RUNNING = {"watchdog_misses": 0, "watchdog_pace": 0.0, "watchdog_lag": 0.0,
                "watchdog_excursion": 0.0, "feasibility": "warn"}
VARIANTS = ("sample", "block", "sample+composed", "block+composed", "sample+fifo",
            "block+fifo", "block+fifo+pinned", "block+fifo+wall")
#: ``+fifo``: the simulator and the controller under SCHED_FIFO at this priority (their
#: thread_priority, ros/scheduling.py; what a rig scene runs them with, scene_nodes.py)
FIFO_PRIORITY = 50


def design(out: Path) -> Path:
    """The least-noise gains for the delay (``grazing design ... --out``)."""
    yaml = out / "controller.yaml"
    subprocess.run([sys.executable, "-m", "grazing_control.cli", "design", "--optimize",
                    "noise", f"--delta-d={DD}", "--delay", str(DELAY), "--out", str(yaml)],
                   check=True, capture_output=True, cwd=ROOT)
    return yaml


def stream_tick(variant: str) -> float | None:
    """The ``+tick<ms>`` of a variant in seconds (None: none; ValueError: not a positive
    number of ms)."""
    ticks = [m[4:] for m in variant.split("+")[1:] if m.startswith("tick")]
    if not ticks:
        return None
    ms = float(ticks[-1])
    if not ms > 0.0:
        raise ValueError(ticks[-1])
    return ms * 1e-3


def valid(variant: str) -> bool:
    """A variant of VARIANTS, with or without a ``+tick<ms>``."""
    try:
        stream_tick(variant)
    except ValueError:
        return False
    return "+".join(m for m in variant.split("+") if not m.startswith("tick")) in VARIANTS


def scene(variant: str, controller: Path, periods: int, enable_after: int, scale: float,
          tmp: Path, answer_lead: float = 0.0) -> dict:
    message, *mods = variant.split("+")
    tick = stream_tick(variant)
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    composed = "composed" in mods
    priority = FIFO_PRIORITY if "fifo" in mods else 0
    # +pinned: the simulator on CPU 0, the controller on CPU 1 (their cpu_affinity)
    sim_cpus, controller_cpus = ("0", "1") if "pinned" in mods else ("", "")
    p = OscillatorParams(delta_d=DD)
    res = launcher.run(
        None, str(controller), tmp / "bag", periods, delta_d=DD, enable_after=enable_after,
        mode="realtime",
        timeout=max(120.0, 4 * periods * p.period / scale),
        sim_overrides={"time_scale": scale, "state_period": p.period / RATE,
                       "sensor_noise": SIGMA, "sensor_velocity": False,
                       "pulse_width": WIDTH, "stream_message": message, **FREE_RUNNING,
                       "thread_priority": priority, "cpu_affinity": sim_cpus,
                       **({"stall_pause": 0.0} if "wall" in mods else {}),
                       **({"stream_block": tick} if tick is not None else {})},
        controller_overrides={"pi2_source": "stream", "estimator": "model",
                              "answer_lead": answer_lead, "thread_priority": priority,
                              "cpu_affinity": controller_cpus},
        log_dir=tmp / "logs", compose=bool(composed))
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        s = summary(Path(res.logs["sim_node"]))
    except (RuntimeError, OSError):
        return {"failed": str(res)}
    nan3 = (float("nan"),) * 3          # no answer measured
    return {"rate": float(s["rate"]), "periods": int(s["periods"]),
            "missed": int(s["missed"]), "late": int(s["late"]),
            "predicted": int(s.get("predicted", 0)), "latency": s.get("latency", nan3),
            "lag": s.get("sample_lag", nan3), "ok": res.ok,
            "paused": int(s.get("paused", 0)),
            "longest_pause": float(s.get("longest_pause_ms", 0.0)),
            "answered": _answered(Path(res.logs["controller_node"])),
            "cpu": (used.ru_utime + used.ru_stime) - (cpu.ru_utime + cpu.ru_stime)}


#: One scene of a baseline checkout (run with it as the working directory): prints the
#: scene's row as JSON.
BASELINE_SCENE = r"""
import json, sys
from pathlib import Path
sys.path[:0] = [".", "benchmarks"]
import bench_stream_blocks as b
a = json.loads(sys.argv[1])
r = b.scene(a["variant"], Path(a["controller"]), a["periods"], a["enable_after"], a["scale"],
            Path(a["tmp"]), a["answer_lead"])
print(json.dumps(r))
"""


def baseline_scene(root: Path, variant: str, controller: Path, periods: int,
                   enable_after: int, scale: float, tmp: Path, answer_lead: float) -> dict:
    """:func:`scene` of the checkout ``root``, in a fresh interpreter there."""
    import json

    arg = json.dumps({"variant": variant, "controller": str(controller), "periods": periods,
                      "enable_after": enable_after, "scale": scale, "tmp": str(tmp),
                      "answer_lead": answer_lead})
    out = subprocess.run([sys.executable, "-c", BASELINE_SCENE, arg], cwd=root,
                         capture_output=True, text=True)
    if out.returncode != 0:
        return {"failed": f"baseline exit {out.returncode}: {out.stderr.strip()[-300:]}"}
    r = json.loads(out.stdout.strip().splitlines()[-1])
    if "failed" not in r:
        r["latency"], r["lag"] = tuple(r["latency"]), tuple(r["lag"])
    return r


def _answered(log: Path) -> int:
    """The controller's answered= count (its summary), -1 when absent."""
    import re

    m = re.search(r"\[controller_node\]: summary: answered=(\d+)", log.read_text())
    return int(m.group(1)) if m else -1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=2, help="scenes per variant (default 2)")
    ap.add_argument("--periods", type=int, default=3000)
    ap.add_argument("--enable-after", type=int, default=1000)
    ap.add_argument("--scale", type=float, default=1000.0)
    ap.add_argument("--answer-lead", type=float, default=0.0,
                    help="the controller's answer_lead (simulation time; default 0: answer "
                         "with the section's last sample)")
    ap.add_argument("--variants", default="sample,block",
                    help=f"comma-separated, of {', '.join(VARIANTS)} (default sample,block)")
    ap.add_argument("--baseline", type=Path, default=None,
                    help="an older checkout (git worktree) run beside this one, alternating")
    args = ap.parse_args(argv)
    variants = args.variants.split(",")
    bad = [v for v in variants if not valid(v)]
    if bad:
        ap.error(f"--variants {','.join(bad)}: valid are {', '.join(VARIANTS)}, each with "
                 "an optional +tick<ms> (a positive number)")
    if args.baseline is not None:
        if not (args.baseline / "benchmarks" / "bench_stream_blocks.py").is_file():
            ap.error(f"--baseline {args.baseline}: not a checkout with "
                     "benchmarks/bench_stream_blocks.py")
        variants = [w for v in variants for w in (f"base:{v}", v)]
    p = OscillatorParams(delta_d=DD)
    print(f"realtime x{args.scale:g}, stream at T/{RATE} ({RATE * args.scale / p.period:.0f} "
          f"samples/s wall), {args.periods} periods, control from {args.enable_after}, "
          f"answer_lead {args.answer_lead:g}, "
          f"recorder on; {os.cpu_count()} CPUs, load %.2f %.2f %.2f" % os.getloadavg())
    rows = {v: [] for v in variants}
    with tempfile.TemporaryDirectory(prefix="bench_stream_blocks_") as tmp:
        controller = design(Path(tmp))
        for rep in range(args.reps):
            for v in variants:
                load = "%.2f %.2f %.2f" % os.getloadavg()
                with tempfile.TemporaryDirectory(dir=tmp) as one:
                    if v.startswith("base:"):
                        r = baseline_scene(args.baseline.resolve(), v[5:], controller,
                                           args.periods, args.enable_after, args.scale,
                                           Path(one), args.answer_lead)
                    else:
                        r = scene(v, controller, args.periods, args.enable_after,
                                  args.scale, Path(one), args.answer_lead)
                rows[v].append(r)
                if "failed" in r:
                    print(f"{v:21s} rep {rep}: FAILED {r['failed']} (load {load})", flush=True)
                    continue
                lat, lag = r["latency"], r["lag"]
                print(f"{v:21s} rep {rep}: {r['periods']} periods"
                      f"{'' if r['ok'] else ' (the scene failed: timed out)'} at "
                      f"{r['rate']:.1f} periods/s, answered {r['answered']}, missed {r['missed']} "
                      f"late {r['late']} predicted {r['predicted']}, latency p50/p99/max "
                      f"{lat[0]:.2f}/{lat[1]:.2f}/{lat[2]:.2f} ms, sample lag p50/p99/max "
                      f"{lag[0]:.2f}/{lag[1]:.2f}/{lag[2]:.2f} ms, plant paused "
                      f"{r.get('paused', 0)} (longest {r.get('longest_pause', 0.0):.2f} ms)"
                      + (f", CPU {r['cpu']:.1f} s" if "cpu" in r else "")
                      + f" (load {load})", flush=True)
    print(f"\nmedians over {args.reps} scenes (requested {args.scale / p.period:.1f} periods/s)")
    print(f"{'variant':21s} {'periods/s':>9s} {'missed':>7s} {'late':>5s} {'lat p50':>8s} "
          f"{'lat p99':>8s} {'lag p99':>8s}  {'missed/base':>11s} {'CPU s':>6s}")
    base = None
    for v, rs in rows.items():
        ok = [r for r in rs if "failed" not in r]
        if not ok:
            print(f"{v:21s} every scene failed")
            continue
        med = {k: statistics.median(r[k] for r in ok) for k in ("rate", "missed", "late")}
        lat = [statistics.median(r["latency"][i] for r in ok) for i in range(3)]
        lag = statistics.median(r["lag"][1] for r in ok)
        base = med["missed"] if base is None else base
        ratio = f"{med['missed'] / base:11.2f}" if base else f"{'-':>11s}"
        cpu = (f"{statistics.median(r['cpu'] for r in ok):6.1f}"
               if all("cpu" in r for r in ok) else f"{'-':>6s}")
        print(f"{v:21s} {med['rate']:9.1f} {med['missed']:7.0f} {med['late']:5.0f} "
              f"{lat[0]:8.2f} {lat[1]:8.2f} {lag:8.2f}  {ratio} {cpu}")
    print("load at the end %.2f %.2f %.2f" % os.getloadavg())
    return 0


if __name__ == "__main__":
    sys.exit(main())

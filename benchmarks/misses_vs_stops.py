"""Each deadline miss of the T/200 scene beside the machine's own stops at that instant
(issue 30).

``bench_machine_stalls.py`` counts how often this machine stops a process with nothing
of the package running; this script asks whether the misses that are left in the
realtime T/200 scene are those stops. While ``--reps`` scenes of ``bench_stream_blocks``
run (``--variant``, default block+fifo; ``--answer-lead``), one monitor per CPU, pinned
to it and under SCHED_FIFO 99 (above the scene's nodes at 50, so that they cannot delay
it), sleeps 1 ms at a time and writes down every wake-up more than ``--stop`` ms
(default 1.5) later than asked: an instant when that CPU ran nothing, not even a thread
at the highest priority (the hypervisor held the virtual CPU, or the kernel ran with
interrupts off). After each wake-up it also times a fixed unit of work (~40 us here): one
that takes more than ``--slow`` (default 3) times its median is a CPU that ran, but
slowly (the host's contention: the stop's measure does not see it). Each monitor costs
about 5 % of its CPU.

Each missed section (the scene's bag, ``oscillator/deadline_miss``: k, its actuation
time and how long after its sample went out it was declared, logged at the recorder's
reception, wall clock) is printed with the stops that overlap the ``--window`` ms
(default 12: longer than the answer's whole budget) before it was logged, on either CPU:
one that began earlier and lasted into the window counts, and with the slow units of
work in the window. A miss with neither is the scene's own. Under each, from the bag
(:func:`whose`): how late its Pi2 sample went out against the sections before it (the
plant's recorded pauses taken out: late, the simulator's), when its answer was published
from that sample (late with the sample on time: the controller's), and the plant's
pauses near it.

Run: ``.venv/bin/python benchmarks/misses_vs_stops.py --reps 3`` (about 45 s a scene).
Results in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

import bench_stream_blocks as scenes  # noqa: E402

#: One monitor: pinned to CPU argv[1], SCHED_FIFO 99, a line "<wall ns> <late ns>" to
#: argv[3] for every wake-up more than argv[2] ns late, until its stdin closes. After each
#: wake-up it times a fixed piece of work (``UNIT``, about 40 us, calibrated over its first
#: 2000 wake-ups); one that takes more than argv[4] times the calibrated median is written
#: as "S <wall ns> <ratio>": an instant when this CPU ran, but slowly (what the host did to
#: it: the stop's measure does not see it).
MONITOR = r"""
import os, select, sys, time
cpu, limit, out, slow = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], float(sys.argv[4])
os.sched_setaffinity(0, {cpu})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))
poll = select.poll(); poll.register(sys.stdin.fileno(), select.POLLIN | select.POLLHUP)
UNIT = range(2000)
units, median = [], None
with open(out, "w", buffering=1) as f:
    while True:
        t0 = time.monotonic_ns(); w0 = time.time_ns()
        if poll.poll(1):          # 1 ms, or stdin closed: the end
            break
        t1 = time.monotonic_ns()
        late = t1 - t0 - 1_000_000
        if late > limit:
            f.write(f"{w0} {late}\n")
        sum(UNIT)
        unit = time.monotonic_ns() - t1
        if median is None:
            units.append(unit)
            if len(units) == 2000:
                median = sorted(units)[1000]
        elif unit > slow * median:
            f.write(f"S {time.time_ns()} {unit / median:.2f}\n")
"""


def monitors(tmp: Path, stop_ms: float, slow: float = 3.0):
    """One monitor per CPU: (processes, their output files)."""
    procs, files = [], []
    for cpu in sorted(os.sched_getaffinity(0)):
        out = tmp / f"stops{cpu}.txt"
        procs.append(subprocess.Popen(
            [sys.executable, "-c", MONITOR, str(cpu), str(int(stop_ms * 1e6)), str(out),
             str(slow)],
            stdin=subprocess.PIPE))
        files.append((cpu, out))
    return procs, files


def read_stops(files) -> tuple:
    """(stops, slow units): (cpu, start wall ns, length ns) of every stop written, and
    (cpu, wall ns, ratio to the median) of every slow unit of work."""
    stops, slow = [], []
    for cpu, out in files:
        if out.is_file():
            for line in out.read_text().split("\n"):
                if line.startswith("S "):
                    _, w, ratio = line.split()
                    slow.append((cpu, int(w), float(ratio)))
                elif line:
                    w, late = map(int, line.split())
                    stops.append((cpu, w, late + 1_000_000))
    return sorted(stops, key=lambda s: s[1]), sorted(slow, key=lambda s: s[1])


def read_misses(bag: Path) -> list:
    """(k, actuation time, waited s, logged wall ns) of each miss in the scene's bag."""
    from grazing_control.ros.recording import read_messages

    if not bag.exists():
        return []
    return [(int(m.message.vector.x), m.message.vector.y, m.message.vector.z, m.log_time_ns)
            for m in read_messages(bag, ["/oscillator/deadline_miss"])]


def whose(bag: Path, k: int) -> str:
    """Whose miss section ``k`` was, from the bag's publish times: its Pi2 sample's lag
    (its publish time against the median over the 100 sections before it, less the
    plant's pauses recorded between them: a sample gone out late is the simulator's), its
    answer's publish time from that sample (late, with the sample on time: the
    controller's), and the plant's pauses recorded within a period of it."""
    import numpy as np

    from grazing_control.recordings import reader
    from grazing_control.recordings.scenes import DEFAULT_TOPICS, load

    data = load(bag)
    topics = [DEFAULT_TOPICS[r] for r in ("pi2", "correction", "deadline_miss")]
    raw = reader.read_raw(bag, topics)
    pi2 = reader.decode_stamped(raw, DEFAULT_TOPICS["pi2"])[1].astype(np.int64)
    pub = reader.serialized(raw, DEFAULT_TOPICS["pi2"])["publish_time"].astype(np.int64)
    corr = reader.decode_twist_stamped(raw, DEFAULT_TOPICS["correction"])
    miss = reader.decode_vector3_stamped(raw, DEFAULT_TOPICS["deadline_miss"])
    stamps = [int(st) for st, x in zip(miss["stamp"], miss["vx"]) if int(round(x)) == k]
    pauses = [(ev["t"], ev["seconds"]) for ev in data.parameters["events"]
              if ev.get("event") == "paused"]
    at = np.flatnonzero(pi2 == stamps[0]) if stamps else np.array([], int)
    if not at.size:
        return "no Pi2 sample of it recorded"
    i = int(at[0])
    scale = (pub[1:] - pub[:-1]).astype(float) / np.maximum(pi2[1:] - pi2[:-1], 1)
    ratio = float(np.median(scale))            # wall ns per simulation ns (1 / time_scale)
    t_k = pi2[i] * 1e-9
    before = [j for j in range(max(0, i - 100), i)]
    if not before:
        return "the first section"
    paused_since = [sum(sec for t, sec in pauses if pi2[j] * 1e-9 < t <= t_k) for j in before]
    lags = [(pub[i] - pub[j]) - (pi2[i] - pi2[j]) * ratio - ps * 1e9
            for j, ps in zip(before, paused_since)]
    lag = float(np.median(lags)) * 1e-6
    answered = [int(p) for p, st in zip(corr["publish_time"], corr["stamp"]) if st == pi2[i]]
    answer = f"{(answered[0] - pub[i]) * 1e-6:+.2f} ms" if answered else "none"
    near = [(t, sec) for t, sec in pauses if abs(t - t_k) < 9.5]
    return (f"its sample out {lag:+.2f} ms against the sections before; answer published "
            f"{answer} from it; plant pauses within a period: "
            + (", ".join(f"{sec * 1e3:.2f} ms" for _t, sec in near) or "none"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--periods", type=int, default=3000)
    ap.add_argument("--enable-after", type=int, default=1000)
    ap.add_argument("--variant", default="block+fifo",
                    help="a variant of bench_stream_blocks, or several separated by commas "
                         "(alternating scene by scene): " + ", ".join(scenes.VARIANTS))
    ap.add_argument("--answer-lead", type=float, default=0.0)
    ap.add_argument("--stop", type=float, default=1.5,
                    help="ms a monitor's wake-up must be late to count as a stop")
    ap.add_argument("--slow", type=float, default=3.0,
                    help="a monitor's unit of work this many times its median counts as slow")
    ap.add_argument("--window", type=float, default=12.0,
                    help="ms before a miss was logged in which its stops are looked for")
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep each scene's bag, logs and stops under this directory")
    args = ap.parse_args(argv)
    variants = args.variant.split(",")
    for v in variants:
        if v not in scenes.VARIANTS:
            ap.error(f"--variant {v!r} is invalid: valid are {', '.join(scenes.VARIANTS)}")
    if os.geteuid() != 0:
        ap.error("the monitors run under SCHED_FIFO 99: run as root")
    print(f"{args.reps} scenes of {args.periods} periods ({args.variant}, answer_lead "
          f"{args.answer_lead:g}), monitors on CPUs {sorted(os.sched_getaffinity(0))} "
          f"(stops > {args.stop:g} ms), load "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    explained = total = 0
    with tempfile.TemporaryDirectory(prefix="misses_vs_stops_") as tmp:
        tmp = Path(tmp) if args.keep is None else args.keep
        tmp.mkdir(parents=True, exist_ok=True)
        controller = scenes.design(tmp)
        for rep, variant in ((r, v) for r in range(args.reps) for v in variants):
            one = tmp / f"scene{rep}-{variant}"
            one.mkdir()
            procs, files = monitors(one, args.stop)
            t0 = time.time_ns()
            try:
                r = scenes.scene(variant, controller, args.periods, args.enable_after,
                                 1000.0, one, args.answer_lead)
            finally:
                for p in procs:
                    p.stdin.close()
                for p in procs:
                    p.wait(timeout=10)
            seconds = (time.time_ns() - t0) * 1e-9
            stops, slow = read_stops(files)
            misses = read_misses(one / "bag")
            long2 = sum(1 for s in stops if s[2] > 2e6)
            print(f"\nscene {rep} ({variant}): {r.get('missed')} missed, {r.get('late')} "
                  f"late, plant paused {r.get('paused')} (longest "
                  f"{r.get('longest_pause', 0):.2f} ms); "
                  f"{len(stops)} stops over {args.stop:g} ms in {seconds:.0f} s "
                  f"({long2} over 2 ms, longest "
                  f"{max((s[2] for s in stops), default=0) * 1e-6:.2f} ms); {len(slow)} "
                  f"units of work over {args.slow:g}x their median", flush=True)
            for k, t, waited, logged in misses:
                # a stop that overlaps the window: one that began before it and
                # lasted into it counts (at stop 46 only the stops that began in it did)
                near = [s for s in stops
                        if s[1] <= logged + 0.5e6 and s[1] + s[2] >= logged - args.window * 1e6]
                total += 1
                explained += bool(near)
                what = ", ".join(f"CPU {c} {(w - logged) * 1e-6:+.2f} ms for {n * 1e-6:.2f} ms"
                                 for c, w, n in near) or "none"
                spell = [u for u in slow
                         if logged - args.window * 1e6 <= u[1] <= logged + 0.5e6]
                slowest = ", ".join(f"CPU {c} {r:.1f}x"
                                    for c, r in sorted({c: max(u[2] for u in spell
                                                               if u[0] == c)
                                                        for c, _w, _r in spell}.items()))
                print(f"  section {k} (logged {logged * 1e-9:.6f}): declared "
                      f"{waited * 1e3:.2f} ms after its sample went out; stops before it: "
                      f"{what}; slow units in the window: {len(spell)}"
                      f"{f' (the slowest: {slowest})' if spell else ''}", flush=True)
                try:
                    print(f"    {whose(one / 'bag', k)}", flush=True)
                except Exception as exc:        # a bag the reader refuses: said, not fatal
                    print(f"    (not read from the bag: {type(exc).__name__}: {exc})")
    print(f"\n{explained} of {total} misses with a stop of the machine in the "
          f"{args.window:g} ms before them")
    return 0


if __name__ == "__main__":
    sys.exit(main())

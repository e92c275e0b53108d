"""How often this machine stops a running process: a floor under every deadline (issue 30).

One busy loop per CPU (each pinned to its CPU, SCHED_OTHER: a SCHED_FIFO loop that never
sleeps is throttled by the kernel's real-time limit, sched_rt_runtime_us), reading the
monotonic clock as fast as Python can (~0.25 us an iteration) for ``--seconds``; a gap
between two reads longer than 0.5, 1, 2, 3 ms is a time the process did not run: another
thread of the machine, the kernel, or the hypervisor took the CPU. Nothing else of the
package runs, so what it counts is the machine's, not the scene's.

A realtime answer misses its deadline when such a stop, longer than its slack, falls
inside its critical path (the block with the section's last sample -> the answer out:
about 1 ms of a controller's work at T/200 x1000, with 2.95 ms of budget). At a rate of
r stops a second longer than the slack, a scene of N sections with a critical path of c
seconds expects about N r c misses (printed for the T/200 scene's numbers).

Run: ``.venv/bin/python benchmarks/bench_machine_stalls.py --seconds 20``. Results in
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

#: Gap thresholds, ms.
LIMITS = (0.5, 1.0, 2.0, 3.0)

LOOP = r"""
import json, os, sys, time
os.sched_setaffinity(0, {int(sys.argv[1])})
end = time.perf_counter_ns() + int(float(sys.argv[2]) * 1e9)
last = time.perf_counter_ns()
gaps = []
n = 0
while last < end:
    now = time.perf_counter_ns()
    if now - last > 200_000:
        gaps.append(now - last)
    last = now
    n += 1
print(json.dumps({"loops": n, "gaps": gaps}))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--critical-path", type=float, default=1.0,
                    help="ms of a section's answer path (default 1.0, T/200 x1000)")
    ap.add_argument("--sections", type=int, default=3000)
    args = ap.parse_args(argv)
    cpus = sorted(os.sched_getaffinity(0))
    print(f"busy loops on CPUs {cpus}, {args.seconds:g} s, load "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    procs = [subprocess.Popen([sys.executable, "-c", LOOP, str(c), str(args.seconds)],
                              stdout=subprocess.PIPE, text=True) for c in cpus]
    rates = []
    for cpu, proc in zip(cpus, procs):
        out = json.loads(proc.communicate()[0])
        gaps = [g / 1e6 for g in out["gaps"]]
        counts = {lim: sum(g > lim for g in gaps) for lim in LIMITS}
        rates.append(counts[2.0] / args.seconds)
        print(f"CPU {cpu}: {out['loops'] / args.seconds / 1e6:.1f} M reads/s; stops longer "
              f"than " + ", ".join(f"{lim:g} ms: {counts[lim]}" for lim in LIMITS)
              + f"; longest {max(gaps, default=0.0):.2f} ms")
    rate = sum(rates) / len(rates)
    print(f"stops longer than 2 ms: {rate:.2f} a second a CPU; a scene of {args.sections} "
          f"sections with a {args.critical_path:g} ms critical path expects about "
          f"{args.sections * rate * args.critical_path * 1e-3:.1f} of them inside it")
    print(f"load at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{time.strftime('%H:%M:%S')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

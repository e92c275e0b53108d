"""A Fig. 1(a)-sized bifurcation diagram by direct simulation: time, periods/s, scaling.

The diagram of the study's Fig. 1(a): ``--points`` values of Delta d (default 2000,
from -2e-5 to 2e-6: the 1/1 branch, its period doubling near -1.005e-5, the irregular
motion near grazing and the non-impacting side), ``--periods`` periods each (2000),
the first ``--transient`` (1000) dropped, from X** on Pi2, uncontrolled.

Side by side in one process:

* ``kernel, N workers``  grazing_control.studies.sweeps.sweep on N local processes (default 2,
  this machine's cores) and on 1, for the scaling; wall-clock seconds of the call
  (process pool start included; the kernel is loaded from numba's cache first, timed
  apart);
* ``python``  the same sweep through the pure-Python core, on every ``--python-every``-th
  point only (default 100), extrapolated to the whole grid by periods per CPU-second.

On a shared machine wall-clock times depend on the other jobs: the CPU seconds of the
process and its workers are reported too, and CPU / workers estimates the wall time on
that many idle cores.

Checks that the 1- and 2-worker results are bit-identical and writes the diagram to
benchmarks/out/sweep_fig1a.png.

Run: ``PYTHONPATH=. python benchmarks/bench_sweep.py [--points 2000 --periods 2000]``
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from grazing_control.oscillator import kernel  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.studies.sweeps import sweep  # noqa: E402
from grazing_control.studies.sweeps.plot import diagram  # noqa: E402


def timed(fn):
    """(wall seconds, result); cpu_seconds holds the CPU time of this process and its
    reaped children (the pool's workers) over the call."""
    global cpu_seconds
    r0, c0 = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = fn()
    wall = time.perf_counter() - t0
    r1, c1 = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_seconds = sum(b.ru_utime + b.ru_stime - a.ru_utime - a.ru_stime
                      for a, b in ((r0, r1), (c0, c1)))
    return wall, out


cpu_seconds = 0.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2000)
    ap.add_argument("--periods", type=int, default=2000)
    ap.add_argument("--transient", type=int, default=1000)
    ap.add_argument("--range", type=float, nargs=2, default=(-2e-5, 2e-6), metavar=("FROM", "TO"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--python-every", type=int, default=100)
    args = ap.parse_args(argv)
    p = OscillatorParams()
    grid = {"delta_d": np.linspace(args.range[0], args.range[1], args.points)}
    total = args.points * args.periods
    t_load, _ = timed(kernel.warm_up)
    runs, cpu = {}, {}
    for workers in (args.workers, 1):
        runs[workers] = timed(lambda: sweep(p, grid, periods=args.periods,
                                            transient=args.transient, workers=workers))
        cpu[workers] = cpu_seconds
    sub = {"delta_d": grid["delta_d"][::args.python_every]}
    timed(lambda: sweep(p, sub, periods=args.periods, transient=args.transient, workers=1,
                        engine="python"))
    py_rate = sub["delta_d"].size * args.periods / cpu_seconds  # per CPU-second
    (t_n, res_n), (t_1, res_1) = runs[args.workers], runs[1]
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    diagram(res_n, out / "sweep_fig1a.png")
    periods, counts = np.unique(res_n.period, return_counts=True)
    print(f"diagram: {args.points} values of Delta d in [{args.range[0]:g}, {args.range[1]:g}] x "
          f"{args.periods} periods ({args.transient} transient) = {total:.3g} periods")
    print(f"kernel load (numba cache)        : {t_load:.2f} s (before the runs, once)")
    print(f"kernel, {args.workers} workers               : {t_n:.2f} s, "
          f"{total / t_n:.3g} periods/s (CPU {cpu[args.workers]:.2f} s: "
          f"{total / cpu[args.workers]:.3g} periods per CPU-second)")
    print(f"kernel, 1 worker                 : {t_1:.2f} s, {total / t_1:.3g} periods/s "
          f"(CPU {cpu[1]:.2f} s: {total / cpu[1]:.3g} periods per CPU-second)")
    print(f"on {args.workers} idle cores (CPU / workers)  : "
          f"{cpu[args.workers] / args.workers:.2f} s "
          "(an estimate where the machine is shared)")
    print(f"scaling 1 -> {args.workers} workers            : {t_1 / t_n:.2f}x")
    print(f"python core ({sub['delta_d'].size} points)         : {py_rate:.3g} periods per "
          f"CPU-second -> {total / py_rate:.0f} CPU-s for the diagram "
          f"({(total / py_rate) / cpu[1]:.0f}x the kernel's {cpu[1]:.1f} CPU-s)")
    print(f"1 and {args.workers} workers bit-identical    : {res_1.same_as(res_n)}")
    print("detected periods                 : " + ", ".join(
        f"{int(k)}: {int(c)}" for k, c in zip(periods, counts)))
    print(f"diagram written to {out / 'sweep_fig1a.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The (omega, Delta d) atlas of lambda_max and the detected period: points/s, 1 vs 2
workers, the Lyapunov column's cost, and the time of the 1000 x 1000 x 2000 atlas.

Side by side in one process, on the same grid (``--omega`` x ``--delta-d`` points,
``--periods`` periods each, the first half dropped, from X** on Pi2, uncontrolled):

* ``sweep, 1 worker``            the baseline: grazing_control.studies.sweeps.sweep, no Lyapunov;
* ``sweep + lyapunov, 1 worker`` the atlas on one local process;
* ``sweep + lyapunov, 2 workers`` the atlas on two (this machine's cores).

Prints wall seconds, points/s, CPU seconds, the ratios (the Lyapunov column against the
baseline; 2 workers against 1) and the expected wall time of the issue's atlas
(1000 x 1000 points x 2000 periods = 2e9 periods) on N workers from the measured
points per CPU-second (a Dask worker runs the same run_chunk). Checks that the 1- and
2-worker atlases are bit-identical. The atlas picture goes to benchmarks/out/atlas.png.

Run: ``PYTHONPATH=. python benchmarks/bench_atlas.py [--omega 20 --delta-d 20 --periods 2000]``
"""

from __future__ import annotations

import argparse
import os
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
from grazing_control.studies.sweeps.plot import atlas  # noqa: E402


def timed(fn):
    """(wall s, cpu s of this process and its reaped children, result)."""
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = fn()
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = sum(b.ru_utime + b.ru_stime - a.ru_utime - a.ru_stime for a, b in ((r0, r1), (c0, c1)))
    return wall, cpu, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--omega", type=int, default=20)
    ap.add_argument("--delta-d", type=int, default=20)
    ap.add_argument("--periods", type=int, default=2000)
    a = ap.parse_args()
    grid = {"omega": np.linspace(0.655, 0.68, a.omega),
            "delta_d": np.linspace(-2e-5, -1e-7, a.delta_d)}
    n = a.omega * a.delta_d
    p = OscillatorParams()
    kw = dict(periods=a.periods, transient=a.periods // 2)
    kernel.warm_up()
    sweep(p, {"delta_d": [-5e-6]}, periods=20, transient=10, workers=1, lyapunov=True)
    rows = []
    base = timed(lambda: sweep(p, grid, workers=1, **kw))
    one = timed(lambda: sweep(p, grid, workers=1, lyapunov=True, **kw))
    two = timed(lambda: sweep(p, grid, workers=2, lyapunov=True, **kw))
    assert one[2].same_as(two[2]), "1- and 2-worker atlases differ"
    for name, (wall, cpu, _r) in (("sweep, 1 worker (baseline)", base),
                                  ("sweep + lyapunov, 1 worker", one),
                                  ("sweep + lyapunov, 2 workers", two)):
        rows.append((name, wall, n / wall, cpu))
    load = os.getloadavg()
    print(f"atlas benchmark: {a.omega} x {a.delta_d} = {n} points x {a.periods} periods "
          f"(omega 0.655..0.68, Delta d -2e-5..-1e-7), python {sys.version.split()[0]}, "
          f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"    {'run':32s} {'wall s':>8s} {'points/s':>10s} {'cpu s':>8s}")
    for name, wall, rate, cpu in rows:
        print(f"    {name:32s} {wall:8.2f} {rate:10.1f} {cpu:8.2f}")
    print(f"    Lyapunov column / baseline (1 worker, wall): {one[0] / base[0]:.3f}")
    print(f"    2 workers / 1 worker speed-up (wall):        {one[0] / two[0]:.3f}")
    per_cpu = n / one[1]                      # atlas points per CPU-second, one worker
    big = 1000 * 1000 * 2000 / a.periods      # the atlas in units of these points
    for workers in (1, 2, 16, 64, 256):
        print(f"    1000 x 1000 x 2000 on {workers:4d} workers: "
              f"{big / per_cpu / workers / 60:9.1f} min (from {per_cpu:.1f} points per "
              f"CPU-second, perfect scaling)")
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    print(f"    atlas picture: {atlas(two[2], out / 'atlas.png')}")


if __name__ == "__main__":
    main()

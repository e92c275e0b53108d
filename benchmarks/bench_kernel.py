"""Compiled exact kernel vs the pure-Python reference path: periods per second per core.

Side by side in one process, on the study's scenes (parameters of the study, start at
X** on Pi2):

* ``reference``  grazing_control.dynamics.simulation.simulate.simulate with GRAZING_KERNEL=python: the
                 pure-Python core (impact.advance period by period);
* ``kernel``     grazing_control.oscillator.kernel.simulate_exact: the same loop compiled by numba
                 (the default path of simulate);
* ``sweep``      grazing_control.oscillator.kernel.run_point: the kernel's loop as a sweep runs it
                 (no per-impact records, only counts).

Scenes: Delta d = -1e-3 (settles on the stable 1/1 orbit), -9e-6 and -5e-6 uncontrolled
(irregular near-grazing motion, many low-velocity impacts and misses), and -9e-6, -5e-6
with the study's controller from the first sample (c2 = -1, c1 of Eq. 38).

Reported per scene:

* periods per second per core: periods / CPU seconds (time.process_time, best of
  ``--repeat`` runs), the reference over ``--periods-ref`` periods, the kernel over
  ``--periods`` periods, and the ratio kernel / reference;
* agreement with the reference over its ``--periods-ref`` periods: whether the Pi2
  samples and impact counts are bit-identical, else the first period that differs;
* missed impacts against the 50-digit mpmath reference (tests/reference.py) over the
  first ``--mpmath`` periods (10 for the chaotic scenes, where any two correct
  simulators part after ~25 periods): reference impacts the kernel did not produce.

And, each in a fresh process: the import of numba and the kernel, the first call with
an empty cache (compilation of every specialisation), and the first call with the
cache written by it (what every later process pays).

Run: ``PYTHONPATH=. python benchmarks/bench_kernel.py [--periods 200000]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from grazing_control.oscillator import kernel  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate  # noqa: E402

STUDY = OscillatorParams()
SCENES = [  # name, delta_d, controlled, chaotic (compare fewer periods with mpmath)
    ("-1e-3", -1e-3, False, False),
    ("-9e-6", -9e-6, False, True),
    ("-5e-6", -5e-6, False, True),
    ("-9e-6 controlled", -9e-6, True, False),
    ("-5e-6 controlled", -5e-6, True, False),
]

_WARM = ("import time, json; t0 = time.perf_counter(); from grazing_control.oscillator import kernel; "
         "w = kernel.warm_up(); w['total'] = time.perf_counter() - t0; print(json.dumps(w))")


def compile_times():
    """Import, first call with an empty cache, first call with the cache: fresh processes."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(REPO)}
        out = []
        for _ in range(2):
            run = subprocess.run([sys.executable, "-c", _WARM], env=env, capture_output=True,
                                 text=True, check=True)
            out.append(json.loads(run.stdout))
    return {"compile": out[0], "cached": out[1]}


def cpu_time(fn, repeat):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def missed_vs_mpmath(p, gains, periods, counts):
    """Reference impacts (50 digits) the kernel did not produce, period by period."""
    from reference import RefModel

    ref = RefModel.from_params(p)
    run = ref.simulate(periods, gains=None if gains is None else (gains.c1, gains.c2),
                       control_after=0)
    return int(sum(max(0, a - b) for a, b in zip(run.counts, counts[:periods]))), \
        int(sum(run.counts))


def bench_scene(name, dd, controlled, chaotic, args):
    p = STUDY.with_(delta_d=dd)
    gains = Gains(degenerate_c1(p, -1.0), -1.0) if controlled else None
    after = 0 if controlled else None
    os.environ[kernel.ENV] = "python"
    t_ref, ref = cpu_time(lambda: simulate(p, args.periods_ref, gains=gains, control_after=after),
                          1)
    os.environ[kernel.ENV] = "numba"
    t_k, (dev, _corr, counts, imps, _end) = cpu_time(
        lambda: kernel.simulate_exact(p, args.periods, 0.0, 0.0, gains, after), args.repeat)
    c1, c2 = (gains.c1, gains.c2) if gains else (np.nan, np.nan)
    t_s, _ = cpu_time(lambda: kernel.run_point(p, args.periods, args.periods - 1, 0.0, 0.0, c1,
                                               c2, 0), args.repeat)
    n = args.periods_ref
    same = (np.array_equal(dev[:n], ref.pi2_deviation) and
            np.array_equal(counts[:n], ref.impacts_per_period))
    first = None
    if not same:
        bad = np.nonzero(np.any(dev[:n] != ref.pi2_deviation, axis=1)
                         | (counts[:n] != ref.impacts_per_period))[0]
        first = int(bad[0])
    m = 10 if chaotic else args.mpmath
    missed, ref_impacts = missed_vs_mpmath(p, gains, m, counts) if args.mpmath else (None, None)
    return {
        "scene": name, "reference_per_s": n / t_ref, "kernel_per_s": args.periods / t_k,
        "sweep_per_s": args.periods / t_s, "ratio": (args.periods / t_k) / (n / t_ref),
        "impacts_per_period": float(counts.mean()), "bit_identical": same,
        "first_difference": first, "mpmath_periods": m, "mpmath_impacts": ref_impacts,
        "missed_vs_mpmath": missed,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=200000, help="kernel periods per scene")
    ap.add_argument("--periods-ref", type=int, default=2000, help="reference periods per scene")
    ap.add_argument("--repeat", type=int, default=3, help="kernel runs per scene (best kept)")
    ap.add_argument("--mpmath", type=int, default=20,
                    help="periods compared with mpmath (10 on chaotic scenes; 0: skip)")
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    args = ap.parse_args(argv)
    times = compile_times()
    kernel.warm_up()
    rows = [bench_scene(*scene, args) for scene in SCENES]
    if args.json:
        print(json.dumps({"compile": times, "scenes": rows}, indent=1))
        return 0
    c, w = times["compile"], times["cached"]
    print(f"numba import + kernel modules : {c['import']:.2f} s (fresh cache), "
          f"{w['import']:.2f} s (cached)")
    print(f"first call, empty cache       : {c['first_call']:.2f} s (compiles every function)")
    print(f"first call, cache written     : {w['first_call']:.2f} s (loads the machine code)")
    print()
    print(f"| scene (Δd) | reference periods/s | kernel periods/s | sweep loop periods/s "
          f"| kernel / reference | impacts/period | bit-identical over {args.periods_ref} "
          f"| missed vs mpmath |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        ident = "yes" if r["bit_identical"] else f"no (from period {r['first_difference']})"
        missed = "-" if r["missed_vs_mpmath"] is None else \
            f"{r['missed_vs_mpmath']} of {r['mpmath_impacts']} ({r['mpmath_periods']} periods)"
        print(f"| {r['scene']} | {r['reference_per_s']:.3g} | {r['kernel_per_s']:.3g} | "
              f"{r['sweep_per_s']:.3g} | {r['ratio']:.0f}x | {r['impacts_per_period']:.3f} | "
              f"{ident} | {missed} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

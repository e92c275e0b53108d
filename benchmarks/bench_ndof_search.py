"""The n-DOF certified event search, pure against compiled, side by side (issue 32).

:func:`grazing_control.oscillator.ndof.impact.next_impact` and ``advance`` on the two-mass
rig's model (config/rigs/two_mass_beam.yaml, Delta d of the file) from seeded starts:
near X** (deviations 1e-12 .. 1e-3 d*, the controlled rig's sections: most periods hit the
wall near grazing) and large transients (0.1 .. 1 d*), each from the Pi2 phase for one
period, the window of a filter's trajectory. Each call runs with the pure search
(GRAZING_KERNEL=python, bench_stream_estimator.search_path) and with the compiled one
(oscillator/kernel/compiled_modal.py, loaded by kernel.warm_up_modal), interleaved call
by call in one process; printed per
function: µs per call (median over the calls, each timed ``--repeat`` times), the
ratio pure/compiled, the impacts found, and whether the two gave the same floats (they
must: tests/test_ndof_compiled.py).

    .venv/bin/python benchmarks/bench_ndof_search.py [--starts 400] [--repeat 5]

Results in docs/benchmarks.md ("The n-DOF event search compiled").
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from grazing_control.oscillator import kernel
from grazing_control.oscillator.ndof import impact as ndof_impact
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.plant.rig import load_rig

from bench_stream_estimator import search_path

ROOT = Path(__file__).resolve().parents[1]


def starts(flow: NdofFlow, count: int, seed: int = 3):
    """``count`` seeded Pi2 deviations: three in four near X**, one in four a transient."""
    rng = np.random.default_rng(seed)
    n2 = 2 * flow.n
    out = []
    for j in range(count):
        size = 10 ** rng.uniform(-12, -3) if j % 4 else 10 ** rng.uniform(-1, 0)
        z = size * flow.d_star * rng.normal(size=n2)
        if flow.gap(flow.tau2, z) < 0.0:
            out.append(z)
    return out


def timed(call, repeat: int):
    """(result, the least of ``repeat`` times, s)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = call()
        best = min(best, time.perf_counter() - t0)
    return out, best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    if not kernel.use_kernel():
        print("the kernel is not in use (numba missing or GRAZING_KERNEL=python)")
        return 1
    loaded = kernel.warm_up_modal()
    model = load_rig(ROOT / "config" / "rigs" / "two_mass_beam.yaml").model()
    flow = NdofFlow.of(model)
    zs = starts(flow, args.starts)
    period, tau = model.period, flow.tau2
    calls = {
        "next_impact": lambda z: ndof_impact.next_impact(flow, tau, z, period),
        "advance": lambda z: ndof_impact.advance(flow, tau, z, period),
    }
    print(f"two-mass rig (Delta d = {model.delta_d:g}), {len(zs)} starts from Pi2, one period "
          f"each; compiled search loaded in {loaded:.2f} s; load %.2f %.2f %.2f"
          % os.getloadavg())
    same = True
    for name, call in calls.items():
        times = {False: [], True: []}
        results = {False: [], True: []}
        for z in zs:
            for compiled in (False, True):
                with search_path(compiled):
                    out, t = timed(lambda: call(z), args.repeat)
                times[compiled].append(t)
                results[compiled].append(out)
        if name == "advance":
            key = [(s.z.tobytes(), s.tau, s.impacts) for s in results[False]]
            alike = key == [(s.z.tobytes(), s.tau, s.impacts) for s in results[True]]
            hits = sum(len(s.impacts) for s in results[False])
        else:
            alike = results[False] == results[True]
            hits = sum(h is not None for h in results[False])
        same &= alike
        pure, comp = (np.median(times[c]) * 1e6 for c in (False, True))
        print(f"{name:12s} pure {pure:8.1f} µs  compiled {comp:7.1f} µs  ratio "
              f"{pure / comp:5.1f}x  ({hits} impacts; the same floats: {alike})")
    print("load at the end %.2f %.2f %.2f" % os.getloadavg())
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

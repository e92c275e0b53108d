"""The n-DOF certified event search, flow with impacts and model filter's period, pure
against compiled, side by side (issue 32).

:func:`grazing_control.oscillator.ndof.impact.next_impact` and ``advance`` on the two-mass
rig's model (config/rigs/two_mass_beam.yaml, Delta d of the file) from seeded starts:
near X** (deviations 1e-12 .. 1e-3 d*, the controlled rig's sections: most periods hit the
wall near grazing) and large transients (0.1 .. 1 d*), each from the Pi2 phase for one
period, the window of a filter's trajectory; and ``trajectory``, one period of the model
filter from each start (:func:`grazing_control.dynamics.estimation.motion.modal_trajectory`
with the rig controller's pulse, delay and samples, 500 a period, a seeded correction of
0 .. 1e-3 d* omega). Each call runs with the pure path
(GRAZING_KERNEL=python, bench_stream_estimator.search_path; ``kernel=False`` for the
trajectory) and with the compiled one (oscillator/kernel/compiled_modal.py, loaded by
kernel.warm_up_modal; ``kernel=True``), interleaved call by call in one process; the
trajectory also as main's kernel path before the compiled advance (``kernel=True`` with
kernel.modal_advance and kernel.modal_events off: the compiled search and samples, the
events in Python). Printed per function: µs per call (median over the calls, each timed
``--repeat`` times), the ratio pure/compiled, the impacts found, and whether the paths
gave the same floats (they must: tests/test_ndof_compiled.py).

    .venv/bin/python benchmarks/bench_ndof_search.py [--starts 400] [--repeat 5]

Results in docs/benchmarks.md ("The n-DOF event search compiled", "The n-DOF model
filter's period compiled").
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from pathlib import Path

import numpy as np

from grazing_control.dynamics.estimation import motion
from grazing_control.oscillator import kernel
from grazing_control.oscillator.ndof import impact as ndof_impact
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.plant.rig import load_rig

from bench_stream_estimator import masses_scene, search_path

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


@contextlib.contextmanager
def events_in_python():
    """main's kernel path before the compiled advance: kernel.modal_advance and
    kernel.modal_events off (the compiled search and samples stay)."""
    saved = kernel.modal_advance, kernel.modal_events
    kernel.modal_advance = kernel.modal_events = lambda: None
    try:
        yield
    finally:
        kernel.modal_advance, kernel.modal_events = saved


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
    _rig, ndof, _pulse, _rate, v, kw = masses_scene()
    samples = np.arange(1, round(period / kw["sample_period"]) + 1) * kw["sample_period"]
    corrections = np.random.default_rng(5).uniform(-1e-3, 1e-3, len(zs)) * flow.d_star * model.omega
    dv = dict(zip((z.tobytes() for z in zs), corrections))

    def trajectory(z, compiled):
        return motion.modal_trajectory(model, z, samples, dv[z.tobytes()],
                                       v["actuation_delay"], period, kw["pulse_width"],
                                       kw["force_limit"], kernel=compiled)

    calls = {
        "next_impact": lambda z, c: ndof_impact.next_impact(flow, tau, z, period),
        "advance": lambda z, c: ndof_impact.advance(flow, tau, z, period),
        "trajectory": trajectory,
    }
    print(f"two-mass rig (Delta d = {model.delta_d:g}), {len(zs)} starts from Pi2, one period "
          f"each; compiled search loaded in {loaded:.2f} s; load %.2f %.2f %.2f"
          % os.getloadavg())
    same = True
    for name, call in calls.items():
        paths = (False, True, "main") if name == "trajectory" else (False, True)
        times = {c: [] for c in paths}
        results = {c: [] for c in paths}
        for z in zs:
            for compiled in paths:
                with search_path(compiled), (events_in_python() if compiled == "main"
                                             else contextlib.nullcontext()):
                    out, t = timed(lambda: call(z, bool(compiled)), args.repeat)
                times[compiled].append(t)
                results[compiled].append(out)
        if name == "advance":
            keys = {c: [(s.z.tobytes(), s.tau, s.impacts) for s in results[c]] for c in paths}
            hits = sum(len(s.impacts) for s in results[False])
        elif name == "trajectory":
            keys = {c: [[np.asarray(a).tobytes() for a in r[:4]] + [r[4]] for r in results[c]]
                    for c in paths}
            hits = sum(len(r[4]) for r in results[False])
        else:
            keys = results
            hits = sum(h is not None for h in results[False])
        alike = all(keys[c] == keys[False] for c in paths)
        same &= alike
        pure, comp = (np.median(times[c]) * 1e6 for c in (False, True))
        print(f"{name:12s} pure {pure:8.1f} µs  compiled {comp:7.1f} µs  ratio "
              f"{pure / comp:5.1f}x  ({hits} impacts; the same floats: {alike})")
        if "main" in paths:
            before = np.median(times["main"]) * 1e6
            print(f"{'':12s} main's kernel path (compiled search and samples) {before:7.1f} µs, "
                  f"ratio to compiled {before / comp:5.1f}x")
    print("load at the end %.2f %.2f %.2f" % os.getloadavg())
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

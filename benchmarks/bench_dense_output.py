"""Dense output of a segment: the Python states_between against the compiled one.

Side by side in one process (issue 30), on the same segments and sample times:

* ``python``    grazing_control.dynamics.simulation.simulate.core_states_between: the
                per-sample Python loop (flow.propagate, flow.to_physical), the reference;
* ``compiled``  grazing_control.oscillator.kernel.states_between: the same operations
                compiled by numba, its wrapper included (the impact list packed into rows);
* ``dispatch``  simulate.states_between as callers (plant.engine.Engine._events) call it:
                the kernel's path behind ``GRAZING_KERNEL``'s check.

Segments: one forcing period from Pi2 as the simulator node runs it (the study's model
near grazing, Delta d = -5e-6, from states around X**, and the rig-like -1e-3 scene),
and segments of random models from states near the wall (0, 1 or several impacts,
sticking ones included), ``--samples`` equally spaced sample times each (200: a rig
scene's stream of T/200). Every segment's outputs are checked bit for bit equal first.

Reported: microseconds per call (median over ``--repeats`` passes over all segments, each
pass timed with time.perf_counter) for each path, and the ratio python / compiled. Then
the simulator's engine (plant.engine.Engine, Delta d = -5e-6, state_period = T / 200, no
correction) over ``--engine-periods`` periods, begin_period + end_period per period, with
its states_between the Python one and the dispatching one (the default): milliseconds a
period (median of ``--repeats`` runs), and whether the events are the same.

Run: ``.venv/bin/python benchmarks/bench_dense_output.py [--segments 400] [--samples 200]
[--repeats 7] [--engine-periods 300]``
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from grazing_control.dynamics.simulation.simulate import (core_states_between,  # noqa: E402
                                                          states_between)
from grazing_control.oscillator import kernel  # noqa: E402
from grazing_control.oscillator.flow import to_deviation  # noqa: E402
from grazing_control.oscillator.impact import (ImpactCapError, InitialStateError,  # noqa: E402
                                               advance)
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402


def segments(n, samples, seed=30):
    """``n`` segments (p, tau0, dx, dv, impacts, times): a third Pi2 periods of the study
    near grazing and of the -1e-3 scene, the rest random models from near the wall."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        kind = len(out) % 3
        if kind < 2:
            p = OscillatorParams(delta_d=-5e-6 if kind == 0 else -1e-3)
            tau = p.tau2
            dx, dv = rng.normal(size=2) * 10.0 ** rng.uniform(-7, -3)
            duration = p.period
        else:
            p = OscillatorParams.from_d(rng.uniform(-0.5, 1.5), zeta=rng.uniform(0.005, 0.3),
                                        r=rng.uniform(0.05, 0.95), omega=rng.uniform(0.3, 3.0))
            tau = rng.uniform(0, 2 * math.pi)
            dx, dv = to_deviation(p, tau, p.d, [0.0, 0.1, -0.1, 1.0][rng.integers(4)])
            duration = rng.uniform(0.5, 2.0) * p.period
        try:
            seg = advance(p, tau, dx, dv, duration)
        except (ImpactCapError, InitialStateError):
            continue
        times = np.arange(1, samples + 1) * (duration / samples)
        out.append((p, float(tau), float(dx), float(dv), seg.impacts, times))
    return out


def timed(fn, cases, repeats):
    """Median over ``repeats`` passes of the seconds per call of ``fn`` over ``cases``."""
    passes = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for case in cases:
            fn(*case)
        passes.append((time.perf_counter() - t0) / len(cases))
    return statistics.median(passes)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=400)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--engine-periods", type=int, default=300)
    args = ap.parse_args(argv)
    if not kernel.use_kernel():
        sys.exit("the kernel is not in use (GRAZING_KERNEL=python, or no numba)")
    t0 = time.perf_counter()
    kernel.warm_up()
    print(f"kernel loaded in {time.perf_counter() - t0:.2f} s")
    cases = segments(args.segments, args.samples)
    counts = [len(c[4]) for c in cases]
    sticking = sum(any(i.sticking for i in c[4]) for c in cases)
    for case in cases:   # bit for bit first
        ref, got = core_states_between(*case), kernel.states_between(*case)
        assert ref.tobytes() == got.tobytes(), case[:4]
    print(f"{len(cases)} segments x {args.samples} samples: impacts per segment "
          f"0: {counts.count(0)}, 1: {counts.count(1)}, >1: {sum(c > 1 for c in counts)} "
          f"(sticking: {sticking}); all bit for bit equal")
    py = timed(core_states_between, cases, args.repeats)
    comp = timed(kernel.states_between, cases, args.repeats)
    disp = timed(states_between, cases, args.repeats)
    print(f"python    {1e6 * py:9.1f} us/call")
    print(f"compiled  {1e6 * comp:9.1f} us/call")
    print(f"dispatch  {1e6 * disp:9.1f} us/call (simulate.states_between, the kernel's path)")
    print(f"ratio python / compiled: {py / comp:.1f}x, python / dispatch: {py / disp:.1f}x "
          f"(medians of {args.repeats} passes)")
    engine(args.engine_periods, args.repeats)


def engine(periods, repeats):
    """The engine's ms a period with the Python dense output and with the dispatching one."""
    from grazing_control.plant import engine as engine_module
    from grazing_control.plant.settings import settings_from_values

    p = OscillatorParams(delta_d=-5e-6)
    s = settings_from_values({"delta_d": p.delta_d, "state_period": p.period / 200})

    def run(dense):
        engine_module.states_between = dense
        eng = engine_module.Engine(s)
        events = []
        t0 = time.perf_counter()
        for _ in range(periods):
            events += eng.begin_period(0.0)
            eng.end_period()
        return time.perf_counter() - t0, events

    try:
        res = {name: [run(fn) for _ in range(repeats)]
               for name, fn in (("python", core_states_between), ("dispatch", states_between))}
    finally:
        engine_module.states_between = states_between
    same = res["python"][0][1] == res["dispatch"][0][1]
    ms = {name: 1e3 * statistics.median(r[0] for r in runs) / periods
          for name, runs in res.items()}
    print(f"engine, {periods} periods of T/200 states ({len(res['python'][0][1])} events): "
          f"python {ms['python']:.3f} ms a period, dispatch {ms['dispatch']:.3f} ms a period "
          f"({ms['python'] / ms['dispatch']:.1f}x); events the same: {same}")


if __name__ == "__main__":
    main()

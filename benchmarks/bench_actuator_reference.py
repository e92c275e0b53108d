"""The plant through a first-order actuator against an independent integration, over
thousands of seeded periods (issue 29 section 4).

Each case (tests/test_plant_actuator.py's ``seeded_case``: bandwidth 0.5x..30x the
forcing frequency, latency 0..0.5, a pulse of width 0..0.2 or an impulse centred at
2.5..3.5, a force carried from the period before, a state and a correction near X**) is
one period of sim_node's engine (plant.engine.Engine with actuator_bandwidth,
actuator_latency, the state stream at T/40) and of DOP853 of (x, v, f) at rtol 1e-13
with event location at the wall (tests/reference_actuator.py). Reported: the largest
differences of the impact times and velocities, the stream's (x, v) and the next
sample's (x, v, f); the cases whose impact count differs; how many cases have an impact
while the force's transient is above 1 % of its pulse. A case whose impact count
differs is rerun with the solver's max_step 2e-3 (at 0.05 a shallow impact, in and out
of the wall within one step, escapes its event location).

    .venv/bin/python benchmarks/bench_actuator_reference.py --cases 2000
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from grazing_control.dynamics.simulation.actuation import pulse_start  # noqa: E402
from grazing_control.oscillator.flow import to_physical  # noqa: E402
from test_plant_actuator import P, run_case, seeded_case  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--first-seed", type=int, default=1000)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    worst = {"impact t": 0.0, "impact v-": 0.0, "stream (x, v)": 0.0, "next (x, v, f)": 0.0}
    count_differs, retried, transient, impacts = [], [], 0, 0
    for seed in range(a.first_seed, a.first_seed + a.cases):
        case = seeded_case(seed)
        e, events, states, (end, ref_imps, dense) = run_case(case, P.period / 40)
        imps = [ev for ev in events if ev.kind == "impact"]
        if len(imps) != len(ref_imps):    # a shallow impact inside one solver step
            retried.append(seed)
            e, events, states, (end, ref_imps, dense) = run_case(case, P.period / 40, 2e-3)
            imps = [ev for ev in events if ev.kind == "impact"]
        impacts += len(imps)
        if len(imps) != len(ref_imps):
            count_differs.append(seed)
            continue
        if imps:
            worst["impact t"] = max(worst["impact t"], max(
                abs(ev.t - t) for ev, (t, _) in zip(imps, ref_imps)))
            worst["impact v-"] = max(worst["impact v-"], max(
                abs(ev.x - v) for ev, (_, v) in zip(imps, ref_imps)))
        if states:
            worst["stream (x, v)"] = max(worst["stream (x, v)"], float(np.max(np.abs(
                np.array([(ev.x, ev.v) for ev in states]) - dense))))
        x1, v1 = to_physical(P, P.tau2, e.dx, e.dv)
        worst["next (x, v, f)"] = max(worst["next (x, v, f)"],
                                      float(np.max(np.abs(np.array([x1, v1, e.force]) - end))))
        off = (pulse_start(P.period, case["delay"], case["width"]) + case["latency"]
               + case["width"])
        tau_a = e.settings.actuator.time_constant
        transient += any(0.0 < ev.t - off < tau_a * math.log(100.0) for ev in imps)
    print(f"{a.cases} cases (seeds {a.first_seed}..{a.first_seed + a.cases - 1}), "
          f"{impacts} impacts, {transient} cases with an impact during the force's "
          f"transient; impact count differs in {len(count_differs)} {count_differs[:10]} "
          f"(with DOP853's max_step 0.05: in {len(retried)}, rerun at 2e-3)")
    for name, value in worst.items():
        print(f"  largest |engine - DOP853| {name}: {value:.3g}")
    print(f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()

"""The perturbation route's admissible c2 sets (dynamics/maps/perturbation.py,
``admissible_c2_perturbation``), this tree against a baseline's, side by side in one
process on seeded models: CPU, ratio and whether every set is the same, float for float.

The baseline is a checkout (``git worktree add --detach /tmp/base-pert <rev>``): its
perturbation.py is loaded beside this tree's (the rest of the package is this tree's).
Each model (zeta, r, omega, Delta d of 0, -0, -1e-5 or 1e-4; a third with a delay),
condition set and ZDM order is run by both, in turn first, on a scan of 121 points.

    .venv/bin/python benchmarks/bench_perturbation_design.py --baseline /tmp/base-pert \\
        [--models 60]
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import baseline_module  # noqa: E402


def main(argv=None) -> int:
    from grazing_control.dynamics.maps import perturbation

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--models", type=int, default=60)
    args = ap.parse_args(argv)
    base = baseline_module.load(args.baseline, "grazing_control.dynamics.maps.perturbation")
    rng = random.Random(5)
    cpu = {"baseline": 0.0, "this": 0.0}
    same = count = 0
    for i in range(args.models):
        p = baseline_module.random_oscillator(rng, with_delta_d=True)
        if p is None:
            continue
        delay = rng.choice([0.0, 0.0, rng.uniform(0, 1.0)])
        conditions = rng.choice(["combined", "impacting", "non-impacting"])
        order = rng.choice([1, 2])
        out = {}
        pair = (("baseline", base), ("this", perturbation))
        for name, module in pair if i % 2 == 0 else pair[::-1]:
            t0 = time.process_time()
            try:
                out[name] = module.admissible_c2_perturbation(
                    p, n=121, zdm_order=order, delay=delay, conditions=conditions)
            except (ValueError, ArithmeticError) as exc:
                out[name] = repr(exc)
            cpu[name] += time.process_time() - t0
        same += out["baseline"] == out["this"]
        count += 1
    baseline_module.report("admissible_c2_perturbation", count, "models", cpu, same, "sets")
    return 0


if __name__ == "__main__":
    sys.exit(main())

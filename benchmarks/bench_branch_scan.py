"""The 1/1 branch's scan over the impact phase (dynamics/orbits/orbits.py, ``_branch_scan``:
Delta d, v- and Delta d's rounding bound on the 241-point psi grid, what every
``orbit_11`` of a new oscillator or gains starts from), this tree against a baseline's,
side by side in one process on seeded oscillators and gains (none, without and with a
delay), both sides, with and without the bound: CPU, ratio, and whether every scan is
the same, float for float.

The baseline is a checkout (``git worktree add --detach /tmp/base-orb <rev>``): its
orbits.py is loaded beside this tree's.

    .venv/bin/python benchmarks/bench_branch_scan.py --baseline /tmp/base-orb [--models 60]
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
    from grazing_control.dynamics.orbits import orbits
    from grazing_control.oscillator.control import Gains

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--models", type=int, default=60)
    args = ap.parse_args(argv)
    base = baseline_module.load(args.baseline, "grazing_control.dynamics.orbits.orbits")
    rng = random.Random(3)
    cpu = {"baseline": 0.0, "this": 0.0}
    same = count = 0
    for i in range(args.models):
        p = baseline_module.random_oscillator(rng)
        if p is None:
            continue
        gains = rng.choice([None, Gains(rng.uniform(-2, 2), rng.uniform(-2, 0.5)),
                            Gains(rng.uniform(-2, 2), rng.uniform(-2, 0.5), rng.uniform(0, 2))])
        key = (p.zeta, p.r, p.omega, p.tau0, p.pi2_offset)
        for sign in (-1.0, 1.0):
            for rounding in (False, True):
                out = {}
                pair = (("baseline", base), ("this", orbits))
                for name, module in pair if count % 2 == 0 else pair[::-1]:
                    t0 = time.process_time()
                    out[name] = module._branch_scan.__wrapped__(key, gains, sign, rounding)
                    cpu[name] += time.process_time() - t0
                same += repr(out["baseline"]) == repr(out["this"])
                count += 1
    baseline_module.report("_branch_scan", count, "scans", cpu, same, "scans")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The impact times found in the sampled wall coordinate (dynamics/estimation/
sampled_impacts.py, ``impacts_from_samples``), this tree against a baseline's, side by
side in one process on tests/test_sampled_impacts.py's seeded random two-mass scenes
(8 periods at T/200, sigma 1e-4): CPU, ratio, and whether the times found are the
same, float for float.

The baseline is a checkout (``git worktree add --detach /tmp/base-si <rev>``): its
sampled_impacts.py is loaded beside this tree's.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_sampled_impacts.py \\
        --baseline /tmp/base-si [--scenes 20]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import baseline_module  # noqa: E402


def main(argv=None) -> int:
    import test_sampled_impacts as scenes

    from grazing_control.dynamics.estimation import sampled_impacts

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--scenes", type=int, default=20)
    args = ap.parse_args(argv)
    base = baseline_module.load(args.baseline,
                                "grazing_control.dynamics.estimation.sampled_impacts")
    rng = np.random.default_rng(32)
    cpu = {"baseline": 0.0, "this": 0.0}
    same = 0
    for i in range(args.scenes):
        t, x, kicks, _times, _speeds, _h = scenes._random_scene(rng)
        out = {}
        pair = (("baseline", base), ("this", sampled_impacts))
        for name, module in pair if i % 2 == 0 else pair[::-1]:
            t0 = time.process_time()
            out[name] = module.impacts_from_samples(t, x, kicks, sigma=scenes.SIGMA)
            cpu[name] += time.process_time() - t0
        same += out["baseline"].shape == out["this"].shape and bool(
            np.array_equal(out["baseline"], out["this"]))
    baseline_module.report("impacts_from_samples", args.scenes, "scenes", cpu, same, "times")
    return 0


if __name__ == "__main__":
    sys.exit(main())

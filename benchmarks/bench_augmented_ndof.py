"""The n-DOF augmented filter's closed loop (tests/test_augmented_ndof.py's two-mass chain,
x0's position at T/200, the wall's Delta d estimated while the plant's walks), with the
wall moved by ``NdofModel.with_clearance`` (the matrices shared, the flow reused)
against the route before, ``dataclasses.replace`` (the model validated again, its flow
built again at every linearisation), side by side in one process: the same seeded
loops in turn first, CPU per route, the ratio, and whether the loops' outputs are the
same, float for float.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_augmented_ndof.py \\
        [--periods 80] [--rounds 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def replaced(p, delta_d: float):
    """The route before: with_wall by dataclasses.replace."""
    return p if delta_d == p.delta_d else dataclasses.replace(p, delta_d=delta_d)


def main(argv=None) -> int:
    import test_augmented_ndof as chain
    from test_augmented_covariance import (DELAY, MC_SIGMA, MC_WALK, MODEL, RATE, T,
                                           ModalMap, evaluate_design, find_periodic)

    from grazing_control.dynamics.estimation import augmented

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=80)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    chain.SIGMA = MC_SIGMA
    gains = evaluate_design(MODEL, -0.22, DELAY).gains
    target = find_periodic(ModalMap(MODEL, gains, DELAY),
                           np.array([-0.04, 0.03, -0.05, 0.03])).state
    routes = {"replace (before)": replaced, "with_clearance": augmented.with_wall}
    cpu = dict.fromkeys(routes, 0.0)
    same = 0
    for seed in range(args.rounds):
        rng = np.random.default_rng(100 + seed)
        walk = MODEL.delta_d + np.concatenate(
            [[0.0], np.cumsum(MC_WALK * rng.standard_normal(args.periods))])
        plants = [dataclasses.replace(MODEL, delta_d=float(w)) for w in walk]
        out = {}
        names = list(routes) if seed % 2 == 0 else list(routes)[::-1]
        for name in names:
            augmented.with_wall = routes[name]
            est = augmented.AugmentedStreamEstimator(
                MODEL, MC_SIGMA, "stream", T / RATE, bias=False, wall=True,
                wall_noise=MC_WALK, floor=0.0)
            t0 = time.process_time()
            out[name] = chain.closed_loop((gains, target), est, args.periods,
                                          plant=lambda k: plants[k], seed=seed)
            cpu[name] += time.process_time() - t0
        a, b = out.values()
        same += all(np.array_equal(x, y) for x, y in zip(a[:3], b[:3]))
    before, after = cpu.values()
    print(f"n-DOF augmented closed loop: {args.rounds} loops of {args.periods} periods, "
          f"CPU replace {before:.2f} s, with_clearance {after:.2f} s, ratio "
          f"{before / after:.2f}; the same outputs float for float: {same} of {args.rounds}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

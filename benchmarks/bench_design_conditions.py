"""The design's admissible c2 sets (dynamics/design/gains.py, ``admissible_c2``) with the
conditions evaluated from the degenerate design's c2-free matrices
(``_Degenerate.at``: c1, N_g and det G without forming ``Gains``), against the route
before, which formed ``Gains`` and took ``gain_determinant`` at every c2, side by side
in one process on seeded models (half of them with a delay), each of the three
condition sets: CPU and ratio, and whether every set is the same, float for float.

    .venv/bin/python benchmarks/bench_design_conditions.py --models 30
"""

from __future__ import annotations

import argparse
import math
import random
import time

from grazing_control.dynamics.design import gains as design
from grazing_control.oscillator.control import Gains, gain_determinant
from grazing_control.oscillator.params import OscillatorParams


def values_forming_gains(p, c2, delay, family):
    """``gains._values`` as it was: Gains, then the design's N_g and det G from it."""
    q, beta, degenerate = family
    g = Gains(degenerate.c1(c2), c2, delay)
    n11, _n12, _n21, n22 = degenerate.period_matrix(g)
    r = p.r
    n22c = q + 1.0
    det_n = math.exp(-2.0 * p.zeta * p.period) * gain_determinant(g, p.zeta)
    tr_n = n11 + n22
    det0 = r * r * det_n
    big_p = -r * (n11 + n22c) * q + (1.0 + r) * (n11 - n22c) * beta
    limit = (1.0 - det0, (1.0 + det0) * q * q - big_p * q, (1.0 + det0) * q * q + big_p * q)
    d = (n11 - 1.0) * beta
    existence = d * (0.5 * d + (1.0 + r) * (n22c - n11))
    free = (1.0 - det_n, 1.0 + det_n - tr_n, 1.0 + det_n + tr_n)
    return design.ConditionValues(limit, existence, free)


def sets(cases):
    out = []
    for p, delay in cases:
        for conditions in ("combined", "impacting", "non-impacting"):
            out.append(design.admissible_c2(p, delay=delay, conditions=conditions))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=int, default=30)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    rng = random.Random(7)
    cases = []
    for _ in range(a.models):
        p = OscillatorParams(delta_d=-1e-5, zeta=rng.uniform(0.01, 0.1), r=rng.uniform(0.5, 0.9))
        cases.append((p, 0.0 if rng.random() < 0.5 else rng.uniform(0.0, design.max_design_delay(p))))
    now = design._values
    cpu = {"c2-free matrices": [], "forming Gains": []}
    results = {}
    for _ in range(a.rounds):
        for label, values in (("forming Gains", values_forming_gains), ("c2-free matrices", now)):
            design._values = values
            try:
                t0 = time.process_time()
                results[label] = sets(cases)
                cpu[label].append(time.process_time() - t0)
            finally:
                design._values = now
    same = results["c2-free matrices"] == results["forming Gains"]
    before, after = min(cpu["forming Gains"]), min(cpu["c2-free matrices"])
    print(f"{a.models} models x 3 condition sets, best of {a.rounds}: forming Gains "
          f"{before:.3f} CPU-s, c2-free matrices {after:.3f} CPU-s, ratio {before / after:.2f}; "
          f"the same sets float for float: {same}")


if __name__ == "__main__":
    main()

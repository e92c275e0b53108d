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


class FormingGains:
    """The degenerate design as ``gains._values`` read it before: at each c2 a ``Gains``
    (its validation), N_g through ``gain_matrix`` and det G through
    ``gain_determinant`` (each forming b_delta again), and exp(-2 zeta T) again."""

    def __init__(self, degenerate):
        self.d = degenerate

    @property
    def decay(self):
        return math.exp(-2.0 * self.d.p.zeta * self.d.p.period)

    def at(self, c2):
        g = Gains(self.d.c1(c2), c2, self.d.delay)
        return g.c1, self.d.period_matrix(g), gain_determinant(g, self.d.p.zeta)


def family_forming_gains(p, delay):
    q, beta, degenerate = NOW(p, delay)
    return q, beta, FormingGains(degenerate)


NOW = design._n22_family


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
    cpu = {"c2-free matrices": [], "forming Gains": []}
    results = {}
    for _ in range(a.rounds):
        for label, family in (("forming Gains", family_forming_gains), ("c2-free matrices", NOW)):
            design._n22_family = family
            try:
                t0 = time.process_time()
                results[label] = sets(cases)
                cpu[label].append(time.process_time() - t0)
            finally:
                design._n22_family = NOW
    same = results["c2-free matrices"] == results["forming Gains"]
    before, after = min(cpu["forming Gains"]), min(cpu["c2-free matrices"])
    print(f"{a.models} models x 3 condition sets, best of {a.rounds}: forming Gains "
          f"{before:.3f} CPU-s, c2-free matrices {after:.3f} CPU-s, ratio {before / after:.2f}; "
          f"the same sets float for float: {same}")


if __name__ == "__main__":
    main()

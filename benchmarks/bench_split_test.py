"""The split test of the impact detection (E6): every split at once against one pair of
least-squares fits per split, side by side (issue 30).

``detect_impact`` tries each split of a period's position samples near the wall: one
arc through all of them against two arcs split between samples m - 1 and m. It fitted
the two arcs of each split with ``np.linalg.lstsq`` (49 splits, 98 fits, at 200 samples a
period on the controlled orbit: 2 ms, the arc fit's whole section at T/200 x1000, which
missed its deadline in every scene). ``section_state.split_rss`` takes every split's
sums from prefix and suffix sums of the normal equations in one pass. This script runs
both on the same seeded noisy periods of the controlled orbit (Delta d = -5e-6, sigma
1e-4, 200 samples a period), checks that they find the same impact times, and prints
the median time of a call of each and their ratio.

Run: ``.venv/bin/python benchmarks/bench_split_test.py`` (a few seconds). Results in
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.dynamics.estimation.motion import phi_rows, trajectory  # noqa: E402
from grazing_control.dynamics.estimation.section_state import (  # noqa: E402
    detect_impact, unkick)
from grazing_control.dynamics.orbits.orbits import orbit_11  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402


def detect_impact_per_split(p, s, y, sigma, min_side=3, threshold=25.0):
    """The split test as it was: two np.linalg.lstsq fits per split (the reference)."""
    def rss(a, b):
        z, *_ = np.linalg.lstsq(a, b, rcond=None)
        r = b - a @ z
        return float(r @ r)

    n = s.size
    psi = p.tau2 + p.omega * s - p.lag
    gap = y - p.delta_d - 2.0 * p.amplitude * np.sin(0.5 * psi) ** 2
    hstep = float(np.max(np.diff(s)))
    near = gap > -(6.0 * sigma + 2.0 * hstep + hstep * hstep)
    cands = [m for m in range(min_side, n - min_side + 1) if near[max(m - 2, 0):m + 2].any()]
    if not cands:
        return None
    phi_x = phi_rows(p.zeta, s)[:, 0, :]
    whole = rss(phi_x, y)
    best, best_m = whole, None
    for m in cands:
        r = rss(phi_x[:m], y[:m]) + rss(phi_x[m:], y[m:])
        if r < best:
            best, best_m = r, m
    if best_m is None or whole - best <= threshold * sigma * sigma:
        return None
    return best_m


def periods(n: int, rate: int, seed: int = 30):
    """Seeded noisy periods of the controlled orbit (deviations, the kick taken out)."""
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(degenerate_c1(p, -0.3), -0.3)
    z0 = np.array(orbit_11(p, g).pi2_deviation)
    rng = np.random.default_rng(seed)
    s = np.arange(1, rate + 1) * p.period / rate
    out = []
    for _ in range(n):
        z = z0 + rng.uniform(-1e-3, 1e-3, 2) * np.abs(z0)
        dv = g.c1 * z[0] + g.c2 * z[1]
        dev = trajectory(p, z, s, dv)[0]
        y, _w = unkick(p, s, dev[:, 0] + 1e-4 * rng.standard_normal(s.size),
                       np.full(s.size, math.nan), [(0.0, dv)])
        out.append((s, y))
    return p, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=200)
    ap.add_argument("--rate", type=int, default=200, help="samples a period (default 200)")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    p, data = periods(args.periods, args.rate)
    sigma = 1e-4
    found = [detect_impact(p, s, y, sigma) for s, y in data]
    split = [detect_impact_per_split(p, s, y, sigma) for s, y in data]
    same = all((f is None) == (m is None) and (f is None or s[m - 1] <= f <= s[m])
               for f, m, (s, _y) in zip(found, split, data))
    timing = {"per split": [], "all at once": []}
    for _ in range(args.repeat):            # alternating, the same periods
        for name, fn in (("per split", detect_impact_per_split),
                         ("all at once", detect_impact)):
            t0 = time.perf_counter()
            for s, y in data:
                fn(p, s, y, sigma)
            timing[name].append((time.perf_counter() - t0) / len(data))
    med = {k: statistics.median(v) for k, v in timing.items()}
    print(f"{args.periods} periods, {args.rate} samples a period, sigma {sigma:g}: impact "
          f"found in {sum(f is not None for f in found)}, the same split in both: {same}")
    for name, t in med.items():
        print(f"{name:12s} {t * 1e3:8.3f} ms a call (median of {args.repeat})")
    print(f"per split / all at once: {med['per split'] / med['all at once']:.1f}x")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

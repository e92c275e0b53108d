"""The split test of the impact detection (E6): every split's sums at once against one
pair of least-squares fits per split, side by side (issue 30).

``detect_impact`` tries each split of a period's position samples near the wall: one
arc through all of them against two arcs split between samples m - 1 and m. It fitted
the two arcs of each split with ``np.linalg.lstsq`` (``section_state.split_rss_by_fits``,
kept as the reference: 49 splits, 98 fits at 200 samples a period on the controlled
orbit, 2 ms, the arc fit's whole section at T/200 x1000, which missed its deadline in
every scene). ``section_state.split_rss`` takes every split's sums from prefix and
suffix sums of the normal equations in one pass. This script runs both on the candidate
splits of the same seeded noisy periods of the controlled orbit (Delta d = -5e-6, sigma
1e-4, 200 samples a period), checks that they pick the same split, and prints the median
time of each and their ratio, then the time of a whole ``detect_impact`` call.

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
    detect_impact, split_rss, split_rss_by_fits, unkick)
from grazing_control.dynamics.orbits.orbits import orbit_11  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402


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


def candidates(p, s, y, sigma: float) -> np.ndarray:
    """The splits detect_impact tries: next to a sample within reach of the wall."""
    psi = p.tau2 + p.omega * s - p.lag
    gap = y - p.delta_d - 2.0 * p.amplitude * np.sin(0.5 * psi) ** 2
    h = float(np.max(np.diff(s)))
    near = gap > -(6.0 * sigma + 2.0 * h + h * h)
    return np.array([m for m in range(3, s.size - 2) if near[max(m - 2, 0):m + 2].any()])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=200)
    ap.add_argument("--rate", type=int, default=200, help="samples a period (default 200)")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    p, data = periods(args.periods, args.rate)
    sigma = 1e-4
    cases = []
    for s, y in data:
        phi_x = phi_rows(p.zeta, s)[:, 0, :]
        r = y - phi_x @ np.linalg.lstsq(phi_x, y, rcond=None)[0]
        cases.append((phi_x, y, r, candidates(p, s, y, sigma)))
    same = all(np.argmin(split_rss(phi_x, r, m)) == np.argmin(split_rss_by_fits(phi_x, y, m))
               for phi_x, y, r, m in cases)
    timing = {"by fits": [], "at once": [], "detect_impact": []}
    for _ in range(args.repeat):            # alternating, the same periods
        t0 = time.perf_counter()
        for phi_x, y, _r, m in cases:
            split_rss_by_fits(phi_x, y, m)
        t1 = time.perf_counter()
        for phi_x, _y, r, m in cases:
            split_rss(phi_x, r, m)
        t2 = time.perf_counter()
        for s, y in data:
            detect_impact(p, s, y, sigma)
        t3 = time.perf_counter()
        for name, dt in (("by fits", t1 - t0), ("at once", t2 - t1),
                         ("detect_impact", t3 - t2)):
            timing[name].append(dt / len(cases))
    med = {k: statistics.median(v) for k, v in timing.items()}
    splits = statistics.median(len(m) for *_x, m in cases)
    print(f"{args.periods} periods, {args.rate} samples a period, sigma {sigma:g}, a median "
          f"of {splits:g} splits tried a period; the same best split both ways: {same}")
    for name, t in med.items():
        print(f"{name:14s} {t * 1e3:8.3f} ms a period (median of {args.repeat})")
    print(f"the split sums, by fits / at once: {med['by fits'] / med['at once']:.1f}x")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

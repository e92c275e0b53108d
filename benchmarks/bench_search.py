"""Evaluations of the closed form per forcing period: the impact search before and after
issue 10's two changes, side by side in one process.

The search's cost is its evaluations of g, v, g'' (one exp and three sin/cos pairs each,
``impact._Eval.__call__``). Counted on the pure-Python core (the kernel performs the same
evaluations, bit for bit), on the study's scenes from X**:

* ``before``: the root refinement before issue 10 (:func:`_bracket_before`, kept here
  as the baseline: Newton from the bracket's midpoint, the far end closed by bisection)
  and no phase exclusion;
* ``bracket``: today's refinement (secant start, a 2-ulp step past the root once Newton
  has converged from one side), no phase exclusion;
* ``now``: today's search (the refinement and the windows far from the wall skipped).

Also printed: whether ``bracket`` and ``now`` give the same Pi2 samples bit for bit
(they must: the exclusion only skips windows where nothing can be found), and CPU time
per period of the three on the pure-Python core.

Run: ``PYTHONPATH=. python benchmarks/bench_search.py [--periods 300]``
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ["GRAZING_KERNEL"] = "python"

from grazing_control.oscillator import impact  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate  # noqa: E402

SCENES = [("-1e-3", -1e-3, False), ("-9e-6", -9e-6, False), ("-5e-6", -5e-6, False),
          ("-9e-6 controlled", -9e-6, True), ("-5e-6 controlled", -5e-6, True)]


def _bracket_before(f, lo, hi, which, sign, flo=None, fhi=None):
    """impact._bracket as it was before issue 10 (the end values are not used)."""
    x = 0.5 * (lo + hi)
    while hi - lo > 4.0 * math.ulp(hi):
        vals = f(x)
        fx = sign * vals[which]
        if fx >= 0.0:
            hi = x
        else:
            lo = x
        dfx = sign * vals[which + 1]
        xn = x - fx / dfx if dfx > 0.0 else lo
        if not lo < xn < hi:
            xn = 0.5 * (lo + hi)
        if xn == x:
            xn = 0.5 * (lo + hi)
            if xn == x:
                break
        x = xn
    return hi


def run(variant, p, gains, periods):
    """(evaluations per period, CPU s per period, Pi2 samples) of one variant."""
    calls = [0]
    evaluate = impact._Eval.__call__
    saved = impact._bracket, impact._danger_halfwidth

    def counted(self, h):
        calls[0] += 1
        return evaluate(self, h)

    impact._Eval.__call__ = counted
    if variant == "before":
        impact._bracket = _bracket_before
    if variant in ("before", "bracket"):
        impact._danger_halfwidth = lambda f, horizon: None
    try:
        t0 = time.process_time()
        r = simulate(p, periods, gains=gains, control_after=0 if gains else None)
        cpu = time.process_time() - t0
    finally:
        impact._Eval.__call__ = evaluate
        impact._bracket, impact._danger_halfwidth = saved
    return calls[0] / periods, cpu / periods, r.pi2


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--periods", type=int, default=300)
    args = ap.parse_args(argv)
    print(f"evaluations of the closed form per period, pure-Python core, {args.periods} "
          "periods from X** per scene")
    print(f"{'scene':18s} {'before':>7s} {'bracket':>8s} {'now':>6s} {'ratio':>6s} "
          f"{'us/period before':>17s} {'now':>6s}  same Pi2 (bracket, now)")
    for name, dd, controlled in SCENES:
        p = OscillatorParams(delta_d=dd)
        gains = Gains(degenerate_c1(p, -1.0), -1.0) if controlled else None
        out = {v: run(v, p, gains, args.periods) for v in ("before", "bracket", "now")}
        same = np.array_equal(out["bracket"][2], out["now"][2])
        print(f"{name:18s} {out['before'][0]:7.1f} {out['bracket'][0]:8.1f} "
              f"{out['now'][0]:6.1f} {out['before'][0] / out['now'][0]:5.2f}x "
              f"{out['before'][1] * 1e6:17.1f} {out['now'][1] * 1e6:6.1f}  {same}")


if __name__ == "__main__":
    main()

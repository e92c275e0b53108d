"""Cost of one Pi2 estimate from the sensor stream, per estimator, against the nearest.

One position-only stream (sigma = 1e-4, the controlled 1/1 orbit at Delta d = -5e-6,
c2 = -0.3) at 50 and 200 samples per period is fed to a StreamEstimator per estimator
(grazing_control.dynamics.estimation.stream), sample by sample as the controller node does; the
CPU time of the whole feed divided by the number of sections is the cost of one Pi2
estimate, including the per-sample bookkeeping. All in one process, the nearest
estimator as the baseline of the ratio, best of --repeat runs. Also the prediction of
the next correction (one exact period, issue 16 section 3) on its own.

Usage:  .venv/bin/python benchmarks/bench_estimation.py [--periods 200] [--repeat 3]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.estimation.motion import trajectory
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.estimation.stream import StreamEstimator, predict_section
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel


def stream(p, g, periods, rate, sigma=1e-4):
    """(t, x~) of a recorded position-only stream on the controlled orbit, and the
    corrections of each section."""
    z = one_one.orbit(p, g).state
    h = p.period / rate
    dv = g.c1 * z[0] + g.c2 * z[1]
    s = np.arange(1, rate + 1) * h
    dev = trajectory(p, z, s, dv)[0]
    psi = p.tau2 + p.omega * s - p.lag
    x_period = p.amplitude * np.cos(psi) + dev[:, 0]
    x = np.concatenate([[p.x_ref + z[0]], np.tile(x_period, periods)])
    t = np.arange(x.size) * h
    xm, _ = SensorModel(noise=sigma, velocity=False, seed=1).measure(0, x, x)
    return t, xm, dv


def feed(p, estimator, t, xm, dv, sigma=1e-4):
    """CPU seconds to feed the stream, and the number of sections estimated."""
    est = StreamEstimator(p, estimator, sigma, "stream", t[1] - t[0])
    n = 0
    t0 = time.process_time()
    for ti, xi in zip(t.tolist(), xm.tolist()):
        for k, _tk, _e in est.add_sample(ti, xi, math.nan):
            est.set_correction(k, dv)
            n += 1
    return time.process_time() - t0, n


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(degenerate_c1(p, -0.3), -0.3)
    print(f"Pi2 estimate cost, {a.periods} periods, best of {a.repeat} (CPU time)")
    print("| samples/period | estimator | ms per estimate | ratio to nearest |")
    print("|---|---|---|---|")
    for rate in (50, 200):
        t, xm, dv = stream(p, g, a.periods, rate)
        base = None
        for e in ("nearest", "arc", "model"):
            best = min(feed(p, e, t, xm, dv) for _ in range(a.repeat))
            per = best[0] / best[1]
            base = per if base is None else base
            print(f"| {rate} | {e} | {1e3 * per:.3f} | {per / base:.1f} |")
    z = one_one.orbit(p, g).state
    n = 2000
    t0 = time.process_time()
    for _ in range(n):
        predict_section(p, z, g.c1 * z[0] + g.c2 * z[1])
    print(f"prediction of the next correction (one exact period): "
          f"{1e3 * (time.process_time() - t0) / n:.3f} ms")


if __name__ == "__main__":
    main()

"""Speed: CPU per period of the core's closed loop with the plain model filter and the
augmented one (issue 29), 3 x 300 periods each, the minimum (docs/benchmarks.md,
"The augmented filter").

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_augmented.py
"""

import os
import time

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.estimation.stream import simulate_stream
from grazing_control.dynamics.design.tuning import optimize_noise
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

P = OscillatorParams(delta_d=-5e-6)
SIGMA, RATE, PERIODS, REPS = 1e-4, 200, 300, 3


def main():
    g = optimize_noise(P, 3.0).gains()
    z = one_one.orbit(P, g).state
    sensor = SensorModel(noise=SIGMA, velocity=False, seed=1)
    h = P.period / RATE
    cases = (("plain model filter", lambda: None),
             ("augmented, bias and wall off",
              lambda: AugmentedStreamEstimator(P, SIGMA, "stream", h, bias=False, wall=False)),
             ("augmented, bias and Delta d",
              lambda: AugmentedStreamEstimator(P, SIGMA, "stream", h)))
    for name, make in cases:
        times = []
        for _ in range(REPS):
            t0 = time.process_time()
            simulate_stream(P, g, sensor.measure, PERIODS, RATE, sigma=SIGMA, deviation=z,
                            stream_estimator=make())
            times.append((time.process_time() - t0) / PERIODS * 1e3)
        print(f"{name}: {min(times):.2f} ms CPU per period (min of {REPS} x {PERIODS})")
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()

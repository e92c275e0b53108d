"""Speed: CPU per period of the core's closed loop with the plain model filter and the
augmented one (issue 29), 3 x 300 periods each, the minimum (docs/benchmarks.md,
"The augmented filter").

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_augmented.py
"""

import time, os, numpy as np
from grazing_control.dynamics.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.orbits import orbit_11
from grazing_control.dynamics.stream import simulate_stream
from grazing_control.dynamics.tuning import optimize_noise
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel
P = OscillatorParams(delta_d=-5e-6); g = optimize_noise(P, 3.0).gains(); z = orbit_11(P, g).pi2_deviation
sensor = SensorModel(noise=1e-4, velocity=False, seed=1)
for name, mk in [("plain", lambda: None), ("augmented off", lambda: AugmentedStreamEstimator(P, 1e-4, "stream", P.period/200, bias=False, wall=False)), ("augmented b+Δd", lambda: AugmentedStreamEstimator(P, 1e-4, "stream", P.period/200))]:
    ts=[]
    for rep in range(3):
        t=time.process_time(); simulate_stream(P, g, sensor.measure, 300, 200, deviation=z, stream_estimator=mk()); ts.append((time.process_time()-t)/300*1e3)
    print(f"{name}: {min(ts):.2f} ms CPU per period (min of 3 x 300)")
print("load", os.getloadavg())

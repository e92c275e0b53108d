"""How far the controlled orbit sits from its own when the controller's zeta is off
(issue 29 section 3: the precision a re-identification needs; docs/theory_reidentification.md
section 5).

The core loop (`dynamics.stream.simulate_stream`, no nodes): the benchmarks' scene
(Delta d = -5e-6, position only, T/200, sigma 1e-4, delay 3, c2 of `grazing design
--optimize noise --delay 3`), the controller's model with zeta + dz and the wall where the
plant's is (Delta d = d - a(omega; zeta + dz)), c1 of that model's degenerate design, the
augmented filter tracking Delta d (``--no-track``: the plain model filter), started on
the plant's controlled orbit: the mean Pi2 x of periods 300-600 less that orbit's.

    .venv/bin/python benchmarks/reidentify_sensitivity.py --dzeta 0 5e-5 1e-4 2.2e-4
"""

import argparse

import numpy as np

from grazing_control.dynamics.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.design import degenerate_c1
from grazing_control.dynamics.orbits import orbit_11
from grazing_control.dynamics.stream import StreamEstimator, simulate_stream
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

C2, DELAY, RATE = -0.0060746847760492625, 3.0, 200


def offset(dz: float, track: bool, seed: int) -> tuple:
    p = OscillatorParams(delta_d=-5e-6)
    m = p.with_(zeta=p.zeta + dz, delta_d=0.0)
    model = m.with_(delta_d=p.d - m.d_star)
    g = Gains(degenerate_c1(model, C2, DELAY), C2, DELAY)
    orbit = orbit_11(p, g).pi2_deviation
    h = p.period / RATE
    est = (AugmentedStreamEstimator(model, 1e-4, "stream", h, bias=False, wall=True,
                                    wall_std=5e-6) if track
           else StreamEstimator(model, "model", 1e-4, "stream", h))
    run = simulate_stream(p, g, SensorModel(noise=1e-4, velocity=False, seed=seed).measure,
                          600, RATE, stream_estimator=est, deviation=tuple(orbit))
    return float(np.mean(run.truth[300:, 0]) - orbit[0]), run.resets


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dzeta", type=float, nargs="+", default=[0.0, 5e-5, 1e-4, 2.2e-4])
    ap.add_argument("--no-track", action="store_true")
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args(argv)
    for dz in a.dzeta:
        off, resets = offset(dz, not a.no_track, a.seed)
        print(f"zeta + {dz:g}: orbit offset {off:.3g} (filter resets {resets})", flush=True)


if __name__ == "__main__":
    main()

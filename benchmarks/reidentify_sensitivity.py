"""How far the controlled orbit sits from its own when the controller's zeta is off
(issue 29 section 3: the precision a re-identification needs; docs/theory_reidentification.md
section 5).

The core loop (`dynamics.estimation.stream.simulate_stream`, no nodes): the benchmarks' scene
(Delta d = -5e-6, position only, T/200, sigma 1e-4, delay 3, c2 of `grazing design
--optimize noise --delay 3`), the controller's model with zeta + dz and the wall where the
plant's is (Delta d = d - a(omega; zeta + dz)), c1 of that model's degenerate design, the
augmented filter tracking Delta d (``--no-track``: the plain model filter), started on
the plant's controlled orbit: the mean Pi2 x of periods 300-600 less that orbit's.

    .venv/bin/python benchmarks/reidentify_sensitivity.py --dzeta 0 5e-5 1e-4 2.2e-4

``--refit N``: instead, the loop under the issue's wrong model (zeta + 5 %, Delta d + 10 %,
the plain model filter, control from period 20) for 60 + N periods, and `identify` on its
last N periods (the samples, the plant's impact times, the kicks; position only) three
ways: from the data alone (the ARX initial guess), from the running zeta with the units
free, and with the units held (what the controller's refit does,
dynamics.estimation.reidentification.UNITS): zeta and the wall's error with standard errors.

    .venv/bin/python benchmarks/reidentify_sensitivity.py --refit 20
"""

import argparse

import numpy as np

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.estimation.stream import StreamEstimator, simulate_stream
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

C2, DELAY, RATE = -0.0060746847760492625, 3.0, 200


def offset(dz: float, track: bool, seed: int) -> tuple:
    p = OscillatorParams(delta_d=-5e-6)
    m = p.with_(zeta=p.zeta + dz, delta_d=0.0)
    model = m.with_(delta_d=p.d - m.d_star)
    g = Gains(degenerate_c1(model, C2, DELAY), C2, DELAY)
    orbit = one_one.orbit(p, g).state
    h = p.period / RATE
    est = (AugmentedStreamEstimator(model, 1e-4, "stream", h, bias=False, wall=True,
                                    wall_std=5e-6) if track
           else StreamEstimator(model, "model", 1e-4, "stream", h))
    run = simulate_stream(p, g, SensorModel(noise=1e-4, velocity=False, seed=seed).measure,
                          600, RATE, stream_estimator=est, deviation=tuple(orbit))
    return float(np.mean(run.truth[300:, 0]) - orbit[0]), run.resets


def refits(n: int, seed: int) -> None:
    import math

    from grazing_control.dynamics.identification import Recording, identify
    from grazing_control.dynamics.estimation.reidentification import UNITS

    p = OscillatorParams(delta_d=-5e-6)
    wrong = p.with_(zeta=1.05 * p.zeta, delta_d=1.1 * p.delta_d)
    g = Gains(degenerate_c1(p, C2, DELAY), C2, DELAY)
    h = p.period / RATE
    sensor = SensorModel(noise=1e-4, velocity=False, seed=seed)
    got = {"t": [], "x": [], "impacts": []}

    def measure(j0, x, v):
        xm, vm = sensor.measure(j0, x, v)
        got["t"].extend(((j0 + np.arange(len(x))) * h).tolist())
        got["x"].extend(xm.tolist())
        return xm, vm

    class Keep(StreamEstimator):
        def add_impact(self, t):
            got["impacts"].append(t)
            super().add_impact(t)

    periods = 60 + n
    run = simulate_stream(p, g, measure, periods, RATE, control_after=20,
                          stream_estimator=Keep(wrong, "model", 1e-4, "stream", h))
    t, x = np.array(got["t"]), np.array(got["x"])
    t0 = (periods - n) * p.period
    keep = t > t0
    t, x = t[keep], x[keep]
    imp = np.array(got["impacts"])
    imp = imp[imp > t0]
    kicks = np.array([k * p.period + DELAY for k in range(periods) if run.corrections[k]])
    kicks = kicks[kicks > t0]
    nan = np.full(imp.size, math.nan)
    rec = Recording(t, x, np.full(t.size, math.nan), np.cos(p.omega * t), np.sin(p.omega * t),
                    imp, nan, nan.copy(), kicks)
    for name, kw in (("from the data", {}), ("running zeta, units free",
                                            {"prior": (wrong.zeta, 1.0)}),
                     ("running zeta, units held", {"prior": (wrong.zeta, 1.0),
                                                   "fixed": UNITS})):
        try:
            ident = identify(rec, max_arcs=None, **kw)
        except ValueError as exc:
            print(f"{name}: {exc}", flush=True)
            continue
        m, se = ident.model, ident.stderr
        print(f"{name}: zeta {m.zeta:.6g} +- {se['zeta']:.2g} (true {p.zeta}), wall "
              f"{m.d - p.d:+.3g} +- {se['d']:.2g} off, units ({m.natural_frequency:.6g}, "
              f"{m.forcing_amplitude:.6g}), residual {ident.sigma:.3g}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dzeta", type=float, nargs="+", default=[0.0, 5e-5, 1e-4, 2.2e-4])
    ap.add_argument("--no-track", action="store_true")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--refit", type=int, default=0, metavar="N")
    a = ap.parse_args(argv)
    if a.refit:
        refits(a.refit, a.seed)
        return
    for dz in a.dzeta:
        off, resets = offset(dz, not a.no_track, a.seed)
        print(f"zeta + {dz:g}: orbit offset {off:.3g} (filter resets {resets})", flush=True)


if __name__ == "__main__":
    main()

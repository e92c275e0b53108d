"""Issue 29 in the core: bias, drift, mismatch detection and capture, measured by seeded
Monte Carlo on the closed loop of grazing_control.dynamics.estimation.stream.simulate_stream.

Issue 29's measurement: position-only SensorModel stream, sigma 1e-4, 200 samples per
period, Delta d = -5e-6, the least-noise gains with delay 3 (``grazing design --optimize
noise --delay 3``), started on the controlled orbit. Parts (``--part``):

``bias``      bias 1e-4, the augmented filter: the orbit's offset after 100 periods and
              the normalised bias error (b^ - b) / se at the end, per seed.
``drift``     Delta d drifting linearly by 20 % over 2000 periods against no drift: one
              impact per period, spread about the moving orbit, Delta d tracking error.
``alarm``     the consistency monitor (window 10, alpha 1e-3) under the right model: the
              false alarms per evaluated window, and per disjoint window.
``detect``    the controller's model at zeta +5 %, Delta d +10 %: the detection time
              (first mismatch verdict) per seed, plain and augmented filter.
``power``     other model errors (zeta +2 %, -5 %, Delta d +10 %, -20 %, r +2 %): the
              first mismatch verdict per seed within 80 periods (None: not seen).
``capture``   capture time and largest correction against the starting distance for the
              rule, the ramp and switching on at once (study gains c2 = -1 and the
              least-noise gains); writes out/watchful/capture.png.

    .venv/bin/python benchmarks/watchful_core.py --part bias --seeds 40 --workers 2
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.design.capture import CaptureRule, GainRamp, capture_time
from grazing_control.dynamics.estimation.consistency import ConsistencyMonitor
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.estimation.section_state import estimate_covariance
from grazing_control.dynamics.design.noise import noise_covariance
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.estimation.stream import simulate_stream
from grazing_control.dynamics.design.tuning import optimize_noise
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

P = OscillatorParams(delta_d=-5e-6)
SIGMA, RATE = 1e-4, 200
OUT = Path(__file__).parent / "out" / "watchful"


def _design():
    g = optimize_noise(P, 3.0).gains()
    return g, one_one.orbit(P, g).state


def _estimator(model=P, **kwargs):
    return AugmentedStreamEstimator(model, SIGMA, "stream", P.period / RATE, **kwargs)


def bias_one(seed, periods=300):
    g, z = _design()
    est = _estimator()
    run = simulate_stream(P, g, SensorModel(noise=SIGMA, velocity=False, bias=1e-4,
                                            seed=seed).measure,
                          periods, RATE, sigma=SIGMA, deviation=z, stream_estimator=est)
    offset = float(np.mean(run.truth[100:, 0] - z[0]))
    se = math.sqrt(est.state.cov[2, 2])
    return seed, offset, (est.bias - 1e-4) / se, se, int(np.min(run.impacts_per_period[1:]))


def drift_one(args):
    frac, seed, augmented, n = args
    g, z = _design()

    def wall(k):
        return P.delta_d * (1.0 + frac * min(k, n) / n)
    ks = np.linspace(0, n, 21)
    targets = np.array([one_one.orbit(P, g, wall(k)).state for k in ks])
    tx = np.interp(np.arange(n), ks, targets[:, 0])
    seen = []
    est = _estimator(bias=False) if augmented else None
    run = simulate_stream(P, g, SensorModel(noise=SIGMA, velocity=False, seed=seed).measure,
                          n, RATE, sigma=SIGMA, deviation=z, stream_estimator=est,
                          plant_at=lambda k: P.with_(delta_d=wall(k)),
                          observe=lambda k, e: seen.append(getattr(e, "delta_d", math.nan)))
    err = run.truth[200:, 0] - tx[200:]
    track = np.array(seen[200:]) - [wall(k) for k in range(200, n)]
    return (frac, seed, augmented, float(np.sqrt(np.mean(err ** 2))), float(np.mean(err)),
            int(np.min(run.impacts_per_period[1:])), int(np.max(run.impacts_per_period[1:])),
            float(np.sqrt(np.nanmean(track ** 2))), float(np.abs(track[-1])), run.resets)


def _verdicts(model, seed, periods, **kwargs):
    g, z = _design()
    est = _estimator(model, **kwargs)
    mon = ConsistencyMonitor(window=10, false_alarm=1e-3)
    out = []

    def observe(k, e):
        out.append(mon.add(*e.innovation) if e.innovation is not None else None)
    simulate_stream(P, g, SensorModel(noise=SIGMA, velocity=False, seed=seed).measure,
                    periods, RATE, sigma=SIGMA, deviation=z, stream_estimator=est,
                    observe=observe)
    return out


def alarm_one(args):
    seed, periods = args
    vs = [v for v in _verdicts(P, seed, periods)[20:] if v is not None and v.periods == 10]
    disjoint = vs[::10]
    return (seed, len(vs), sum(v.status == "mismatch" for v in vs), len(disjoint),
            sum(v.status == "mismatch" for v in disjoint),
            sum("nis" in v.failing for v in vs), sum("mean" in v.failing for v in vs))


def detect_one(args):
    seed, augmented = args
    wrong = P.with_(zeta=P.zeta * 1.05, delta_d=P.delta_d * 1.1)
    kwargs = {} if augmented else {"bias": False, "wall": False}
    vs = _verdicts(wrong, seed, 80, **kwargs)
    first = next((v.k for v in vs if v is not None and v.status == "mismatch"), None)
    return seed, augmented, first


POWER_CASES = {"zeta +2 %": {"zeta": 1.02}, "zeta -5 %": {"zeta": 0.95},
               "Delta d +10 %": {"delta_d": 1.1}, "Delta d -20 %": {"delta_d": 0.8},
               "r +2 %": {"r": 1.02}}


def power_one(args):
    name, seed, augmented = args
    model = P.with_(**{k: getattr(P, k) * f for k, f in POWER_CASES[name].items()})
    kwargs = {} if augmented else {"bias": False, "wall": False}
    vs = _verdicts(model, 100 + seed, 80, **kwargs)
    return name, augmented, next((v.k for v in vs if v is not None and v.status == "mismatch"),
                                 None)


def capture_one(args):
    gains_name, mode, dist, seed = args
    if gains_name == "study":
        g = Gains(degenerate_c1(P, -1.0, 0.0), -1.0, 0.0)
    else:
        g = _design()[0]
    z = one_one.orbit(P, g).state
    cov = noise_covariance(P, g, estimate_covariance(P, g, RATE)) * SIGMA ** 2
    band = 5.0 * math.sqrt(np.trace(cov))
    switch = {"now": None, "rule": CaptureRule.for_wall(z, P.delta_d),
              "ramp": GainRamp(20)}[mode]
    try:
        run = simulate_stream(P, g, SensorModel(noise=SIGMA, velocity=False, seed=seed).measure,
                              300, RATE, sigma=SIGMA, deviation=z + np.array([dist, 0.0]),
                              switch=switch)
    except (ValueError, ArithmeticError, RuntimeError):
        return args, None, math.nan
    return args, capture_time(run.truth, run.impacts_per_period, z, band), \
        float(np.max(np.abs(run.corrections)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("bias", "drift", "alarm", "detect", "power", "capture"),
                    required=True)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--periods", type=int, default=1000, help="alarm: periods per seed")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        if args.part == "bias":
            rows = list(pool.map(bias_one, range(args.seeds)))
            off = np.array([r[1] for r in rows])
            zn = np.array([r[2] for r in rows])
            print(f"bias 1e-4, {args.seeds} seeds x 300 periods: |offset| max "
                  f"{np.max(np.abs(off)):.2e}"
                  f" mean {np.mean(off):.2e}; (b^-b)/se: mean {np.mean(zn):.3f}, rms "
                  f"{np.sqrt(np.mean(zn ** 2)):.3f}, |.|>3: {np.sum(np.abs(zn) > 3)}, "
                  f"se {np.median([r[3] for r in rows]):.2e}, min impacts/period "
                  f"{min(r[4] for r in rows)}")
        elif args.part == "drift":
            cases = [(f, s, a, 2000) for s in range(args.seeds) for f, a in
                     ((0.0, True), (0.2, True), (0.2, False))]
            for r in pool.map(drift_one, cases):
                print("drift %.1f seed %d %s: rms %.3e mean %.2e impacts %d..%d, "
                      "Delta d error rms %.2e last %.2e, resets %d"
                      % (r[0], r[1], "augmented" if r[2] else "plain", *r[3:]))
        elif args.part == "alarm":
            rows = list(pool.map(alarm_one, [(s, args.periods) for s in range(args.seeds)]))
            n, k = sum(r[1] for r in rows), sum(r[2] for r in rows)
            nd, kd = sum(r[3] for r in rows), sum(r[4] for r in rows)
            print(f"right model, window 10, alpha 1e-3: {k} of {n} sliding windows "
                  f"({k / n:.2e}), {kd} of {nd} disjoint windows ({kd / nd:.2e}, binomial "
                  f"sd {math.sqrt(nd * 1e-3) / nd:.1e}); nis {sum(r[5] for r in rows)}, "
                  f"mean {sum(r[6] for r in rows)}")
        elif args.part == "detect":
            rows = list(pool.map(detect_one, [(s, a) for s in range(args.seeds)
                                              for a in (False, True)]))
            for a in (False, True):
                t = [r[2] for r in rows if r[1] == a]
                ok = [x for x in t if x is not None]
                print(f"{'augmented' if a else 'plain'}: detected {len(ok)} of {len(t)}; "
                      f"periods: min {min(ok)} median {np.median(ok):.0f} max {max(ok)}; "
                      f"{sorted(ok)}")
        elif args.part == "power":
            rows = list(pool.map(power_one, [(n, s, a) for n in POWER_CASES for a in (False, True)
                                             for s in range(args.seeds)]))
            for n in POWER_CASES:
                for a in (False, True):
                    print(f"{n:14s} {'augmented' if a else 'plain':9s}: first verdict "
                          f"{[r[2] for r in rows if r[0] == n and r[1] == a]}")
        else:
            dists = (1e-4, 1e-3, 3e-3, 1e-2, 2e-2, 4.5e-2)
            cases = [(gn, m, d, s) for gn in ("study", "least") for m in ("now", "rule", "ramp")
                     for d in dists for s in range(args.seeds)]
            res = list(pool.map(capture_one, cases))
            table = {}
            for (gn, m, d, _s), ct, peak in res:
                table.setdefault((gn, m, d), []).append((ct, peak))
            for key, vals in sorted(table.items()):
                cts = [c for c, _ in vals if c is not None]
                print(f"{key[0]:6s} {key[1]:5s} {key[2]:.0e}: capture median "
                      f"{np.median(cts) if cts else math.nan:.0f} max "
                      f"{max(cts) if cts else math.nan} ({len(cts)}/{len(vals)}), peak "
                      f"correction {np.median([p for _, p in vals]):.2e}")
            _chart(table, dists)
    print(f"{time.perf_counter() - t0:.1f} s")


def _chart(table, dists):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, gn in zip(axes, ("study", "least")):
        for m, style in (("now", "o-"), ("rule", "s--"), ("ramp", "^:")):
            med = [np.median([c for c, _ in table[(gn, m, d)] if c is not None] or [np.nan])
                   for d in dists]
            ax.semilogx(dists, med, style, label=m)
        ax.set_xlabel("starting distance |x - x**|")
        ax.set_ylabel("capture time (periods, median)")
        ax.set_title(f"{gn} gains")
        ax.legend()
    OUT.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(OUT / "capture.png", dpi=120)
    print(f"wrote {OUT / 'capture.png'}")


if __name__ == "__main__":
    main()

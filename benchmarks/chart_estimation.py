"""Chart: the Pi2 spread against the sensor noise and rate, per estimator and gain.

The closed loop of the core (grazing_control.dynamics.estimation.stream.simulate_stream: exact
plant, position-only SensorModel stream, the estimator, Eq. 28) at Delta d = -5e-6,
started on the controlled 1/1 orbit, for sigma in 1e-6 .. 1e-3, 50 and 200 samples per
period, the estimators nearest / arc / model and c2 = -1 (the study), -0.3 and 0.007
(about the noise-optimal choice), several seeds. The spread is the RMS of the Pi2
position about the exact orbit over the last 2/3 of the run, the median over the
seeds; a run whose plant leaves the 1/1 motion (less than 99 % of its periods with one
impact) is counted as lost. Writes out/estimation/spread.png and a markdown table
(docs/theory_estimation.md, "Measured").

    .venv/bin/python benchmarks/chart_estimation.py --seeds 4 --periods 600 --workers 2
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.estimation.stream import simulate_stream
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.sensor import SensorModel

SIGMAS = (1e-6, 1e-5, 1e-4, 1e-3)
RATES = (50, 200)
ESTIMATORS = ("nearest", "arc", "model")
C2S = (-1.0, -0.3, 0.007)


def one(args):
    delta_d, c2, sigma, rate, estimator, seed, periods = args
    p = OscillatorParams(delta_d=delta_d)
    g = Gains(degenerate_c1(p, c2), c2)
    z = one_one.orbit(p, g).state
    try:
        run = simulate_stream(p, g, SensorModel(noise=sigma, velocity=False, seed=seed).measure,
                              periods, rate, estimator=estimator, sigma=sigma, deviation=z)
    except (ValueError, ArithmeticError, RuntimeError):
        return args, math.inf, 0.0
    last = slice(periods // 3, None)
    spread = float(np.sqrt(np.mean((run.truth[last, 0] - z[0]) ** 2)))
    one_impact = float(np.mean(run.impacts_per_period[last] == 1))
    return args, spread, one_impact


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--periods", type=int, default=600)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--delta-d", type=float, default=-5e-6)
    ap.add_argument("--out", default="out/estimation")
    a = ap.parse_args(argv)
    jobs = [(a.delta_d, c2, s, r, e, seed, a.periods) for c2, s, r, e, seed in
            itertools.product(C2S, SIGMAS, RATES, ESTIMATORS, range(a.seeds))]
    t0 = time.time()
    with ProcessPoolExecutor(a.workers) as ex:
        results = list(ex.map(one, jobs, chunksize=4))
    table = {}
    for args, spread, one_imp in results:
        key = args[1:5]
        lost = one_imp < 0.99
        table.setdefault(key, []).append(math.inf if lost else spread)
    med = {k: float(np.median(v)) for k, v in table.items()}
    lost = {k: sum(math.isinf(x) for x in v) for k, v in table.items()}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()
    fig, axes = plt.subplots(1, len(C2S), figsize=(5 * len(C2S), 4), sharey=True)
    for ax, c2 in zip(axes, C2S):
        for (e, r), style in zip(itertools.product(ESTIMATORS, RATES),
                                 ["C0--", "C0-", "C1--", "C1-", "C2--", "C2-"]):
            ys = [med[(c2, s, r, e)] for s in SIGMAS]
            ys = [y if math.isfinite(y) else np.nan for y in ys]
            ax.loglog(SIGMAS, ys, style, marker="o", label=f"{e}, {r}/T")
        ax.set_title(f"c2 = {c2}")
        ax.set_xlabel("sensor noise σ (position only)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("Π2 spread about the orbit (median of seeds)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Δd = {a.delta_d:g}: Π2 spread vs σ, sensor rate and estimator "
                 "(missing point: 1/1 motion lost)")
    save_png(fig, out / "spread.png")
    lines = ["| c2 | rate | estimator | " + " | ".join(f"σ = {s:g}" for s in SIGMAS) + " |",
             "|---|---|---|" + "---|" * len(SIGMAS)]
    for c2, r, e in itertools.product(C2S, RATES, ESTIMATORS):
        cells = []
        for s in SIGMAS:
            m, n_lost = med[(c2, s, r, e)], lost[(c2, s, r, e)]
            cells.append(("lost" if not math.isfinite(m) else f"{m:.2g}")
                         + (f" ({n_lost}/{a.seeds} lost)" if 0 < n_lost and math.isfinite(m)
                            else ""))
        lines.append(f"| {c2:g} | {r} | {e} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    (out / "spread.md").write_text(text)
    print(text)
    print(f"{len(jobs)} runs in {time.time() - t0:.0f} s; figure {out / 'spread.png'}")


if __name__ == "__main__":
    main()

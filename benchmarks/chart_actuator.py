"""Chart: the loop's margin against the actuator's bandwidth (issue 29 section 4).

The controlled 1/1 orbit of the loop closed through a first-order actuator
(grazing_control.dynamics.simulation.actuator: exact 3-state period map (dx, dv, f), fixed point by
Newton, continued from 30x down to 1x the forcing frequency) at Delta d = -5e-6, pulse
width 0.1 centred at delta = 3, the least-noise gains of ``grazing design --optimize
noise --delay 3``; for each bandwidth ratio N (tau_a = 1 / (N omega)):

- ``naive``: those gains, the actuator ignored;
- ``equivalent delay``: c1 from the degenerate condition at delta + tau_a (+ latency),
  c2 kept, the command still centred at delta (docs/theory_pulse.md section 6);
- ``exact N_g``: c1 from N_g,12 = 0 with the actuator's force profile
  (actuator.actuated_c1, docs/theory_pulse.md (P1)), c2 kept.

Plotted: the spectral radius of the controlled limit map (3x3 Jacobian; the margin is 1
minus it), the noise gain sqrt(Sigma_xx) per unit sigma with the model filter's
position-only covariance at 200 samples per period (the design's predicted spread
through the actuator), and the orbit's offset from X** (the kick design's controlled
orbit, one_one.orbit); 10x and 3x marked. With ``--measured`` (the JSON of
``bench_watchful_nodes.py --part actuator --measured``) the spreads measured through
the real nodes (std of the Pi2 x about its mean per sigma) are marked on the noise gain.
Writes out/actuator/margin.png and prints the table (docs/theory_pulse.md section 7).

    .venv/bin/python benchmarks/chart_actuator.py --points 25 --latency 0 \
        [--measured benchmarks/out/actuator/nodes.json]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from grazing_control.dynamics.simulation.actuation import pulse_orbit
from grazing_control.dynamics.simulation.actuation import pulse_start
from grazing_control.dynamics.simulation.actuator import (actuated_c1, actuated_orbit,
                                               bandwidth_actuator, equivalent_delay)
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.estimation.section_state import estimate_covariance
from grazing_control.dynamics.design.noise import noise_gain
from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.orbits.orbits import OrbitNotFound
from grazing_control.dynamics.design.tuning import optimize_noise
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

OUT = Path(__file__).parent / "out" / "actuator"
MARKS = (10.0, 3.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--delta-d", type=float, default=-5e-6)
    ap.add_argument("--delay", type=float, default=3.0)
    ap.add_argument("--width", type=float, default=0.1)
    ap.add_argument("--latency", type=float, default=0.0, help="actuator latency (model time)")
    ap.add_argument("--points", type=int, default=25)
    ap.add_argument("--measured", type=Path, help="bench_watchful_nodes.py --part actuator "
                    "--measured's JSON: the nodes' spreads, marked")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    p = OscillatorParams(delta_d=args.delta_d)
    g = optimize_noise(p, args.delay).gains()
    r = estimate_covariance(p, g, 200)
    ideal = pulse_orbit(p, g, args.width)
    target = one_one.orbit(p, g).state
    start = pulse_start(p.period, g.delay, args.width)
    print(f"gains {g}; ideal pulse: spectral radius {np.max(np.abs(ideal.multipliers)):.6f}, "
          f"kick noise gain {noise_gain(p, g, r):.4f}")
    ratios = sorted(set(np.round(np.geomspace(30.0, 1.0, args.points), 6)) | set(MARKS),
                    reverse=True)
    rows = {"naive": [], "equivalent delay": [], "exact N_g": []}
    guesses = dict.fromkeys(rows)
    for n in ratios:
        act = bandwidth_actuator(p, n, args.latency)
        de = g.delay + equivalent_delay(act)
        designs = (("naive", g),
                   ("equivalent delay", Gains(degenerate_c1(p, g.c2, de), g.c2, de)),
                   ("exact N_g", Gains(actuated_c1(p, g.c2, act, start, args.width), g.c2,
                                       g.delay)))
        for name, gains in designs:
            try:
                o = actuated_orbit(p, gains, args.width, act, command_delay=g.delay,
                                   guess=guesses[name])
            except (OrbitNotFound, ValueError, ArithmeticError) as exc:
                rows[name].append((n, math.nan, math.nan, math.nan))
                guesses[name] = None
                print(f"{n:6.2f} {name:16s} no orbit ({str(exc)[:60]})")
                continue
            guesses[name] = o.state
            rho = o.spectral_radius
            ng = math.sqrt(o.noise_covariance(gains, r)[0, 0]) if rho < 1.0 else math.inf
            shift = o.state[0] - target[0]
            rows[name].append((n, rho, ng, shift))
            print(f"{n:6.2f} {name:16s} rho {rho:.5f} noise gain {ng:.4f} x - x** {shift:+.2e}")
    _chart(rows, np.max(np.abs(ideal.multipliers)), args)
    print(f"{time.perf_counter() - t0:.1f} s")


def _chart(rows, ideal_rho, args):
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for name, style in (("naive", "o-"), ("equivalent delay", "s--"), ("exact N_g", "^:")):
        a = np.array(rows[name], dtype=float)
        axes[0].semilogx(a[:, 0], a[:, 1], style, label=name)
        axes[1].semilogx(a[:, 0], a[:, 2], style, label=name)
        axes[2].semilogx(a[:, 0], np.abs(a[:, 3]), style, label=name)
    if args.measured is not None:
        import json
        for row in json.loads(args.measured.read_text()):
            style = "k*" if row["design"] == "exact N_g" else "kx"
            axes[1].semilogx(row["ratio"], row["std_per_sigma"], style, ms=10,
                             label=f"nodes, {row['design']}")
        handles, labels = axes[1].get_legend_handles_labels()
        keep = {lab: h for h, lab in zip(handles, labels)}
        axes[1].legend(keep.values(), keep.keys())
    axes[0].axhline(ideal_rho, color="gray", lw=0.8, label="ideal pulse")
    axes[0].axhline(1.0, color="red", lw=0.8)
    axes[0].set_ylim(0.55, 1.5)
    for ax, label in zip(axes, ("spectral radius (margin = 1 - it)",
                                "noise gain (std x per sigma)", "|x - x**| of the orbit")):
        for m in MARKS:
            ax.axvline(m, color="k", ls=":", lw=0.8)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("actuator bandwidth / forcing frequency")
        ax.set_ylabel(label)
        if ax is not axes[1] or args.measured is None:
            ax.legend()
    axes[2].set_yscale("log")
    fig.suptitle(f"first-order actuator, latency {args.latency}, pulse {args.width} at "
                 f"delta {args.delay}, Delta d {args.delta_d}")
    OUT.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(OUT / "margin.png", dpi=120)
    print(f"wrote {OUT / 'margin.png'}")


if __name__ == "__main__":
    main()

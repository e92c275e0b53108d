"""Exact event-driven simulator vs scipy.integrate.solve_ivp with event location.

Side by side in one process, on the same scenes (study parameters, start at X** on
Pi2, ``--periods`` forcing periods):

* ``exact``       grazing_control.dynamics.simulation.simulate.simulate: closed-form flow between impacts,
                  certified impact detection (the project's engine);
* ``DOP853 / RK45 at rtol 1e-6, 1e-9, 1e-12`` (atol = 1e-3 rtol): solve_ivp on
  x'' + 2 zeta x' + x = cos(omega t + tau2) in physical coordinates with a terminal
  event x - d = 0 (direction +1); at each event the impact law v+ = -r v- is applied
  and the integration restarts on the wall. The Pi2 samples are taken with t_eval
  (the method's dense output). An event reported within 1e-12 T of a restart would be
  the wall itself; it is skipped by flowing 1e-9 T without events (counted as
  ``skips``; with x set exactly to d and v+ < 0 it does not occur).

Reported per method and scene:

* CPU seconds per forcing period (time.process_time, best of ``--repeat`` runs for
  the exact simulator, one run for solve_ivp);
* the largest Pi2 error max(|x - x_ref|, |v - v_ref|) against the 50-digit mpmath
  reference of tests/reference.py over the compared periods;
* impacts: found / reference over the compared periods, and ``missed`` (per period,
  reference impacts the method did not produce).

Scenes: Delta d = -1e-3 (near grazing, settles on a stable 1/1 orbit; all periods are
compared) and Delta d = -5e-6 uncontrolled, which is chaotic: rounding-level
differences grow by ~x4 per period on average, so two *correct* simulators part after
~25 periods; there only the first ``--chaotic-compare`` periods (default 10) are
compared, impact counts included.

The speed ratio is exact vs the fastest solve_ivp setting that reaches the exact
simulator's Pi2 error (to within a factor 10) with no missed impact, or, if none does,
vs the most accurate setting.

Run: ``PYTHONPATH=. python benchmarks/bench_exact_vs_solve_ivp.py [--periods 50]``
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate  # noqa: E402
from reference import RefModel  # noqa: E402

METHODS = [(m, rtol) for m in ("DOP853", "RK45") for rtol in (1e-6, 1e-9, 1e-12)]


def run_exact(p: OscillatorParams, periods: int):
    res = simulate(p, periods)
    counts = list(res.impacts_per_period)
    return res.pi2, counts


def run_solve_ivp(p: OscillatorParams, periods: int, method: str, rtol: float):
    """Event-driven solve_ivp run from X**: Pi2 samples (periods, 2) and impacts per period."""
    zeta, omega, tau0, d, r = p.zeta, p.omega, p.tau2, p.d, p.r
    T = p.period
    t_end = periods * T
    atol = rtol * 1e-3

    def rhs(t, y):
        return [y[1], math.cos(omega * t + tau0) - 2.0 * zeta * y[1] - y[0]]

    def wall(t, y):
        return y[0] - d

    wall.terminal = True
    wall.direction = 1.0

    sample_t = np.arange(periods) * T
    samples = np.full((periods, 2), np.nan)
    samples[0] = (p.x_ref, p.v_ref)
    impact_t = []
    t, y = 0.0, np.array([p.x_ref, p.v_ref])
    skips = 0
    while t < t_end:
        t_eval = sample_t[(sample_t > t) & (sample_t <= t_end)]
        sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol,
                        events=wall, t_eval=t_eval)
        for ts, ys in zip(sol.t, np.reshape(sol.y, (2, -1)).T):
            k = int(round(ts / T))
            if abs(ts - k * T) < 1e-9 * T and k < periods:
                samples[k] = ys
        if sol.status != 1:
            break
        te, ye = sol.t_events[0][0], sol.y_events[0][0]
        if te - t < 1e-12 * T:  # the wall we restarted on: flow a little without events
            skips += 1
            step = solve_ivp(rhs, (te, te + 1e-9 * T), ye, method=method, rtol=rtol, atol=atol)
            t, y = step.t[-1], step.y[:, -1]
            continue
        impact_t.append(te)
        t, y = te, np.array([d, -r * ye[1]])
    counts = np.bincount((np.array(impact_t) // T).astype(int), minlength=periods)[:periods]
    return samples, list(counts), skips


def compare(samples, counts, ref_pi2, ref_counts, n):
    err = 0.0
    for k in range(n):
        x, v = ref_pi2[k]
        err = max(err, abs(float(x - samples[k][0])), abs(float(v - samples[k][1])))
    found = int(sum(counts[:n]))
    expected = int(sum(ref_counts[:n]))
    missed = int(sum(max(0, a - b) for a, b in zip(ref_counts[:n], counts[:n])))
    return err, found, expected, missed


def bench_scene(p, periods, n_compare, repeat):
    ref = RefModel.from_params(p)
    t0 = time.perf_counter()
    run = ref.simulate(periods)
    ref_seconds = time.perf_counter() - t0
    rows = []
    best = math.inf
    for _ in range(repeat):
        c0 = time.process_time()
        pi2, counts = run_exact(p, periods)
        best = min(best, time.process_time() - c0)
    rows.append(("exact", None, best / periods, *compare(pi2, counts, run.pi2, run.counts,
                                                         n_compare), 0))
    for method, rtol in METHODS:
        c0 = time.process_time()
        samples, counts, skips = run_solve_ivp(p, periods, method, rtol)
        sec = time.process_time() - c0
        rows.append((method, rtol, sec / periods,
                     *compare(samples, counts, run.pi2, run.counts, n_compare), skips))
    return rows, ref_seconds


def speed_ratio(rows):
    exact = rows[0]
    others = rows[1:]
    ok = [r for r in others if r[3] <= 10 * max(exact[3], 1e-16) and r[6] == 0]
    if ok:
        target = min(ok, key=lambda r: r[2])
        how = "fastest solve_ivp reaching the exact accuracy"
    else:
        target = min(others, key=lambda r: (r[6], r[3]))
        how = "no solve_ivp setting reaches it; most accurate setting"
    return target[2] / exact[2], target, how


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--periods", type=int, default=50)
    ap.add_argument("--chaotic-compare", type=int, default=10,
                    help="periods compared for the chaotic scene (default 10)")
    ap.add_argument("--repeat", type=int, default=5, help="timings of the exact simulator")
    args = ap.parse_args(argv)
    if args.periods < 1 or not 1 <= args.chaotic_compare <= args.periods:
        ap.error("need --periods >= 1 and 1 <= --chaotic-compare <= --periods")

    study = OscillatorParams()
    scenes = [
        (f"Delta d = -1e-3 (1/1 attractor), {args.periods} periods compared",
         study.with_(delta_d=-1e-3), args.periods),
        (f"Delta d = -5e-6 uncontrolled (chaotic), first {args.chaotic_compare} of "
         f"{args.periods} periods compared", study.with_(delta_d=-5e-6), args.chaotic_compare),
    ]
    print(f"solve_ivp atol = 1e-3 rtol; CPU time (process_time); start X**; "
          f"{args.periods} periods per run\n")
    for title, p, n in scenes:
        rows, ref_seconds = bench_scene(p, args.periods, n, args.repeat)
        print(f"### {title}\n")
        print(f"(mpmath reference, 50 digits: {ref_seconds:.1f} s for {args.periods} periods)\n")
        print("| method | rtol | s / period | Pi2 error | impacts (found / reference) "
              "| missed | skips |")
        print("|---|---|---|---|---|---|---|")
        for name, rtol, spp, err, found, expected, missed, skips in rows:
            rt = "-" if rtol is None else f"{rtol:.0e}"
            print(f"| {name} | {rt} | {spp:.2e} | {err:.1e} | {found} / {expected} "
                  f"| {missed} | {skips} |")
        ratio, target, how = speed_ratio(rows)
        print(f"\nspeed ratio exact vs {target[0]} rtol={target[1]:.0e} ({how}): "
              f"{ratio:.0f}x\n")


if __name__ == "__main__":
    main()

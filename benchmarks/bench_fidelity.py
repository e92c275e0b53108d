"""Work-precision of the simulator's model fidelities, side by side in one process.

For each fidelity (exact flow, second- and leading-order normal-form maps, solve_ivp
DOP853 at several tolerances) on the same scenes: CPU seconds per forcing period
against the Pi2-point error, measured against the independent 50-digit mpmath model of
tests/reference.py. Also runs the automatic choice for a few tolerances and reports what
it picked and the error that choice actually had.

Scenes (study parameters, controller c2 = -1 and the degenerate c1, on from the start,
starting 1 % off the controlled 1/1 orbit so that the transient is simulated):
Delta d = -1e-4, -1e-6 and -1e-8.

Usage:  .venv/bin/python benchmarks/bench_fidelity.py [--periods 40] [--out benchmarks/out]
Prints a markdown table and writes work_precision.png / .svg to --out.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.dynamics.simulation.fidelity import period_step  # noqa: E402
from grazing_control.dynamics.orbits import one_one  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate  # noqa: E402
from reference import RefModel  # noqa: E402

SCENES = (-1e-4, -1e-6, -1e-8)
METHODS = [("exact", {}), ("zdm2", {}), ("zdm1", {}),
           ("ode", {"rtol": 1e-6}), ("ode", {"rtol": 1e-9}), ("ode", {"rtol": 1e-12})]


def run(p, gains, z0, periods, fidelity, kw):
    """(seconds per period, Pi2 deviations (periods+1, 2)) for one method."""
    dx, dv = z0
    out = [(dx, dv)]
    t0 = time.process_time()
    for _ in range(periods):
        seg = period_step(p, dx, dv, gains.c1 * dx + gains.c2 * dv, fidelity, **kw)
        dx, dv = seg.dx, seg.dv
        out.append((dx, dv))
    return (time.process_time() - t0) / periods, np.array(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=40)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "out"))
    args = ap.parse_args(argv)
    base = OscillatorParams()
    gains = Gains(degenerate_c1(base, -1.0), -1.0)
    rows = []
    for dd in SCENES:
        p = base.with_(delta_d=dd)
        orb = one_one.orbit(p, gains).state
        z0 = (1.01 * orb[0], orb[1])
        ref = RefModel.from_params(p).simulate(
            args.periods + 1, x0=p.x_ref + z0[0], v0=p.v_ref + z0[1],
            gains=(gains.c1, gains.c2), control_after=0)
        ref_pi2 = np.array([[float(x), float(v)] for x, v in ref.pi2]) - [p.x_ref, p.v_ref]
        for fid, kw in METHODS:
            cost, got = run(p, gains, z0, args.periods, fid, kw)
            err = float(np.max(np.abs(got - ref_pi2[: len(got)])))
            label = fid + (f" rtol={kw['rtol']:g}" if kw else "")
            rows.append((dd, label, cost, err))
        for tol in (1e-5, 1e-8, 1e-12):
            res = simulate(p, args.periods + 1, deviation=z0, gains=gains, control_after=0,
                           fidelity="auto", tol=tol)
            err = float(np.max(np.abs(res.pi2_deviation - ref_pi2)))
            rows.append((dd, f"auto tol={tol:g} -> {res.fidelity}", None, err))
    print(f"work-precision of the fidelities, {args.periods} controlled periods per scene, "
          "error = max Pi2 deviation error vs the 50-digit reference\n")
    print("| Delta d | method | s / period | Pi2 error |")
    print("|---|---|---|---|")
    for dd, label, cost, err in rows:
        c = f"{cost:.2e}" if cost is not None else "-"
        print(f"| {dd:g} | {label} | {c} | {err:.1e} |")
    exact = {dd: c for dd, lab, c, _e in rows if lab == "exact"}
    print("\nspeed ratio (exact / method), per scene:")
    for dd, label, cost, err in rows:
        if cost is not None and label != "exact":
            print(f"  Delta d {dd:g}: {label}: {exact[dd] / cost:.2f}x as fast as exact, error {err:.1e}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    markers = {"exact": "o", "zdm2": "s", "zdm1": "^", "ode": "x"}
    for dd, color in zip(SCENES, ("tab:blue", "tab:orange", "tab:green")):
        for _d, label, cost, err in [r for r in rows if r[0] == dd and r[2] is not None]:
            ax.loglog(cost, max(err, 1e-17), markers[label.split()[0]], color=color, ms=8)
            ax.annotate(label, (cost, max(err, 1e-17)), fontsize=7, xytext=(4, 2),
                        textcoords="offset points")
        ax.plot([], [], "o", color=color, label=f"Δd = {dd:g}")
    ax.set(xlabel="CPU seconds per forcing period", ylabel="Π2 error vs 50-digit reference",
           title="Simulator fidelities: work against precision (controlled, c2 = −1)")
    ax.legend(fontsize=8)
    for ext in ("png", "svg"):
        fig.savefig(out / f"work_precision.{ext}", dpi=110)
    print(f"\nchart: {out / 'work_precision.png'} (.svg)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

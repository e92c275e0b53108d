"""The rigid design on the compliant plant: the largest multiplier of the controlled 1/1
orbit against the stop's stiffness ratio, its damping and dry friction, where it fails,
and what a design on the compliant model buys there (docs/theory_contact.md sections 13
and 15).

    PYTHONPATH=. python benchmarks/chart_contact.py          # about 3 min here
    PYTHONPATH=. python benchmarks/chart_contact.py --hertz  # the Hertz stop only
    PYTHONPATH=. python benchmarks/chart_contact.py --delta-d -0.02 --c2 -1.2 \
        --restitution 0.8 --friction 0 0.005 --no-failing    # sets of your own (--help)

For each Delta d, c2, stop restitution r and friction level, the gains are the rigid
design at that r (c1 from Eq. 38 for that c2, dynamics/design/gains.py: the designer knows the
stop's restitution and ignores its compliance and the friction); the controlled 1/1
orbit of the compliant model (CompliantOneDOF, a PeriodMap) is continued in log10 k_c
from 8 down to 1 at fixed contact damping ratio (fixed r, Eq. C3) by
dynamics/orbits/stop_boundary.stop_boundary (continue_orbit, whose bifurcation detection
reports and locates, Brent in the parameter, any multiplier crossing the unit circle; the
same function as ``grazing stop --boundary``). Then the failing set
of section 15: the crossing located by the continuation, checked by bisection on
max |lambda| = 1, and the gains of dynamics/spectral_design at three stiffnesses.
The Hertz stop (section 19; ``--hertz``): the same continuation in log10 k_c (Hertz
stiffness, at fixed Hunt-Crossley alpha) with alpha = (1 - r) / v- (Eq. C5: restitution r
at the rigid controlled orbit's own impact velocity v-, the designer's r where the orbit
hits), frictionless (friction is the Kelvin-Voigt stop's only).
Writes benchmarks/out/contact/rho.png (git-ignored) and prints the tables.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from grazing_control.dynamics.orbits.continuation import continue_orbit
from grazing_control.dynamics.orbits.stop_boundary import rigid_design_plant, stop_boundary
from grazing_control.dynamics.design.spectral_design import least_spectral_radius, spectral_radius
from grazing_control.oscillator.params import OscillatorParams

OUT = Path(__file__).parent / "out" / "contact"
#: today's sets (the defaults of the options)
DELTAS = (-5e-6, -1e-3, -1e-2, -5e-2)
C2S = (-1.0, -1.5)
RESTITUTIONS = (0.68, 0.95, 0.5)
FRICTIONS = (0.0, 0.003, 0.01)
#: the failing set of docs/theory_contact.md section 15 (Delta d, c2, r, F_f)
FAILING = (-5e-2, -1.5, 0.68, 0.01)


def rho(monodromy) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(monodromy))))


def plant(delta_d, c2, r, friction, k=1e8):
    """(rigid-designed Kelvin-Voigt model at stiffness k, the rigid controlled orbit):
    dynamics/orbits/stop_boundary.rigid_design_plant."""
    return rigid_design_plant(OscillatorParams(delta_d=delta_d, r=r), c2, friction=friction,
                              stiffness=k)


def boundary(delta_d, c2, r, friction=0.0, law="kelvin_voigt"):
    """(the rigid controlled orbit's multiplier, the StopBoundary over 1e8 .. 1e1)."""
    p = OscillatorParams(delta_d=delta_d, r=r)
    _, rigid = rigid_design_plant(p, c2, law, friction=friction)
    return rho(rigid.monodromy), stop_boundary(p, c2, law, friction=friction)


def hertz_rows(args):
    """The rigid design on the Hertz stop: largest |multiplier| against log10 k_c."""
    rows = []
    for dd in args.delta_d:
        for c2 in args.c2:
            for r in args.restitution:
                r0, sb = boundary(dd, c2, r, law="hertz")
                rows.append((dd, c2, r, f"H a={sb.law['alpha']:.4g}", r0, sb))
                print_row(rows[-1])
    return rows


def crossing_by_bisection(model, lo, hi, states):
    """log10 k_c where max |lambda| = 1 between lo and hi, by brentq on rho - 1 with the
    orbit shot from the nearest continuation point (an independent check of the
    continuation's Brent on its test functions)."""
    def f(lk):
        near = min(states, key=lambda v: abs(v - lk))
        return spectral_radius(model.with_parameter("log10_stiffness", lk), states[near])[0] - 1.0
    return brentq(f, lo, hi, xtol=1e-10)


def main(args):
    rows = []
    for dd in args.delta_d:
        for c2 in args.c2:
            for r in args.restitution:
                for fr in args.friction:
                    if fr and r != args.restitution[0]:
                        continue  # friction at the first r only
                    rows.append((dd, c2, r, fr, *boundary(dd, c2, r, fr)))
                    print_row(rows[-1])
    if not args.no_failing:
        failing(args.failing)
    figure(rows)


def print_row(row):
    dd, c2, r, fr, r0, sb = row
    br = sb.branch
    vals = {round(pt.value, 6): float(np.max(np.abs(pt.multipliers))) for pt in br.points}
    line = " ".join(f"{vals.get(float(d), math.nan):.3f}" for d in range(8, 0, -1))
    cross = ", ".join(f"{c.type} at 10^{c.log10_stiffness:.4f}" for c in sb.crossings) or "none"
    contacts = f"{br.points[0].impacts}..{br.points[-1].impacts}"
    fr = f"{fr:6.3f}" if isinstance(fr, float) else fr
    print(f"{dd:8.0e} {c2:5.1f} {r:5.2f} {fr} {r0:6.3f} | {line} | {cross} "
          f"(to 10^{br.points[-1].value:.2f}; contacts a period {contacts})", flush=True)


def failing(at):
    dd, c2, r, fr = at
    r0, sb = boundary(dd, c2, r, fr)
    model = plant(dd, c2, r, fr)[0]
    states = {pt.value: pt.state for pt in sb.branch.points}
    print(f"\nfailing set Delta d = {dd}, c2 = {c2}, r = {r}, F_f = {fr}: rigid design c1 = "
          f"{sb.gains[0]:.6f}, rigid-model multiplier {r0:.4f}")
    for c in sb.crossings:
        lo = max(v for v in states if v < c.log10_stiffness)
        hi = min(v for v in states if v > c.log10_stiffness)
        check = crossing_by_bisection(model, lo, hi, states)
        print(f"  continuation: {c.sentence()}; bisection on max|lambda| = 1: {check:.6f}")
    for lk in (8.0, 4.0):
        low, rigid_low = plant(dd, c2, r, 0.001, k=10 ** lk)
        fb = continue_orbit(low, "friction", np.linspace(0.001, fr, 10),
                            rigid_low.state)
        for b in fb.bifurcations:
            print(f"  k_c = 1e{lk:.0f}, continuation in F_f from 0.001: {b.type} at "
                  f"F_f = {b.value:.6f}")
    print("  design on the compliant model (dynamics/spectral_design.least_spectral_radius):")
    for lk in (8.0, 4.0, 2.0):
        near = min(states, key=lambda v: abs(v - lk))
        d = least_spectral_radius(model.with_parameter("log10_stiffness", lk), states[near])
        print(f"  k_c = 1e{lk:.0f}: rigid gains rho = {d.rho_start:.4f} -> c1 = {d.c1:.6f}, "
              f"c2 = {d.c2:.6f}, rho = {d.rho:.3g} ({d.evaluations} orbits)")


def figure(rows):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    OUT.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 5))
    for dd, c2, r, fr, r0, sb in rows:
        br = sb.branch
        ax.plot([10 ** pt.value for pt in br.points],
                [np.max(np.abs(pt.multipliers)) for pt in br.points],
                label=f"Δd={dd:.0e} c2={c2} r={r} F={fr}", lw=0.8)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("k_c / k")
    ax.set_ylabel("largest |multiplier|, controlled 1/1")
    ax.legend(fontsize=5, ncol=2)
    fig.tight_layout()
    fig.savefig(OUT / "rho.png", dpi=120)
    print(f"wrote {OUT / 'rho.png'}")


def parser() -> argparse.ArgumentParser:
    from grazing_control.cli.commands import _NEGATIVE_NUMBER

    a = argparse.ArgumentParser(
        description="The rigid design on the compliant plant: for each Delta d, c2, r and "
                    "friction, the largest multiplier of the controlled 1/1 orbit continued "
                    "in log10 k_c from 8 to 1 and its crossings (dynamics/orbits/"
                    "stop_boundary.py; docs/theory_contact.md sections 15 and 19). Friction "
                    "is run at the first --restitution only; F_s = 1.2 F_f.")
    a._negative_number_matcher = _NEGATIVE_NUMBER   # -5e-6 is a value (grazing's parser)
    a.add_argument("--delta-d", type=float, nargs="+", default=list(DELTAS),
                   help=f"Delta d values (default {' '.join(map(str, DELTAS))})")
    a.add_argument("--c2", type=float, nargs="+", default=list(C2S),
                   help=f"c2 values, each with c1 of Eq. 38 (default {' '.join(map(str, C2S))})")
    a.add_argument("--restitution", type=float, nargs="+", default=None,
                   help="stop restitutions r (default "
                        f"{' '.join(map(str, RESTITUTIONS))}; --hertz: 0.68)")
    a.add_argument("--friction", type=float, nargs="+", default=list(FRICTIONS),
                   help=f"kinetic friction levels F_f (default {' '.join(map(str, FRICTIONS))})")
    a.add_argument("--failing", type=float, nargs=4, default=list(FAILING),
                   metavar=("DELTA_D", "C2", "R", "F_F"),
                   help="the failing set: its crossing checked by bisection, the continuation "
                        "in F_f and the design on the compliant model (default "
                        f"{' '.join(map(str, FAILING))}, section 15)")
    a.add_argument("--no-failing", action="store_true", help="skip the failing set")
    a.add_argument("--hertz", action="store_true",
                   help="the Hertz stop only (alpha = (1 - r) / v- of the rigid orbit, "
                        "frictionless; section 19)")
    return a


if __name__ == "__main__":
    args = parser().parse_args()
    if args.restitution is None:
        args.restitution = [0.68] if args.hertz else list(RESTITUTIONS)
    print(f"{'Delta d':>8} {'c2':>5} {'r':>5} {'F_f':>6} {'rigid':>6} | largest |multiplier| "
          "at log10 k_c = 8 7 6 5 4 3 2 1 | crossings (contacts a period at 1e8..1e1)")
    if args.hertz:
        hertz_rows(args)
    else:
        main(args)

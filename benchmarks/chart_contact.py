"""The rigid design on the compliant plant: the largest multiplier of the controlled 1/1
orbit against the stop's stiffness ratio, its damping and dry friction, where it fails,
and what a design on the compliant model buys there (docs/theory_contact.md sections 13
and 15).

    PYTHONPATH=. python benchmarks/chart_contact.py          # about 3 min here
    PYTHONPATH=. python benchmarks/chart_contact.py --hertz  # the Hertz stop only

For each Delta d, c2, stop restitution r and friction level, the gains are the rigid
design at that r (c1 from Eq. 38 for that c2, dynamics/design/gains.py: the designer knows the
stop's restitution and ignores its compliance and the friction); the controlled 1/1
orbit of the compliant model (CompliantOneDOF, a PeriodMap) is continued in log10 k_c
from 8 down to 1 at fixed contact damping ratio (fixed r, Eq. C3) by
dynamics/continuation.continue_orbit, whose bifurcation detection reports and locates
(Brent in the parameter) any multiplier crossing the unit circle. Then the failing set
of section 15: the crossing located by the continuation, checked by bisection on
max |lambda| = 1, and the gains of dynamics/spectral_design at three stiffnesses.
The Hertz stop (section 19; ``--hertz``): the same continuation in log10 k_c (Hertz
stiffness, at fixed Hunt-Crossley alpha) with alpha = (1 - r) / v- (Eq. C5: restitution r
at the rigid controlled orbit's own impact velocity v-, the designer's r where the orbit
hits), frictionless (friction is the Kelvin-Voigt stop's only).
Writes benchmarks/out/contact/rho.png (git-ignored) and prints the tables.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.orbits.continuation import continue_orbit
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.orbits.shooting import find_periodic
from grazing_control.dynamics.design.spectral_design import least_spectral_radius, spectral_radius
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
from grazing_control.oscillator.hertz import HuntCrossley
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

OUT = Path(__file__).parent / "out" / "contact"
DELTAS = (-5e-6, -1e-3, -1e-2, -5e-2)
C2S = (-1.0, -1.5)
RESTITUTIONS = (0.68, 0.95, 0.5)
FRICTIONS = (0.0, 0.003, 0.01)
DECADES = np.linspace(8.0, 1.0, 15)
#: the failing set of docs/theory_contact.md section 15
FAILING = dict(delta_d=-5e-2, c2=-1.5, r=0.68, friction=0.01)
STATIC_RATIO = 1.2


def rho(monodromy) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(monodromy))))


def plant(delta_d, c2, r, friction, k=1e8):
    """(rigid-designed compliant model at stiffness k, the rigid controlled orbit)."""
    p = OscillatorParams(delta_d=delta_d, r=r)
    gains = Gains(degenerate_c1(p, c2), c2)
    rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
    model = CompliantOneDOF(p, gains, law=KelvinVoigt.from_restitution(k, r),
                            friction=Coulomb(friction, STATIC_RATIO * friction) if friction
                            else None)
    return model, rigid


def hertz_plant(delta_d, c2, r, k=1e8):
    """(rigid-designed model with a Hertz stop at stiffness k, alpha = (1 - r) / v- of the
    rigid controlled orbit's impact; the rigid controlled orbit)."""
    p = OscillatorParams(delta_d=delta_d, r=r)
    gains = Gains(degenerate_c1(p, c2), c2)
    rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
    v_minus = rigid.impacts[0].v_minus
    return CompliantOneDOF(p, gains, law=HuntCrossley.from_restitution(k, r, v_minus)), rigid


def hertz_rows():
    """The rigid design on the Hertz stop: largest |multiplier| against log10 k_c."""
    rows = []
    for dd in DELTAS:
        for c2 in C2S:
            model, rigid = hertz_plant(dd, c2, 0.68)
            branch = continue_orbit(model, "log10_stiffness", DECADES, rigid.state)
            rows.append((dd, c2, 0.68, f"H a={model.law.alpha:.4g}", rho(rigid.monodromy),
                         branch))
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


def main():
    rows = []
    for dd in DELTAS:
        for c2 in C2S:
            for r in RESTITUTIONS:
                for fr in FRICTIONS:
                    if fr and r != 0.68:
                        continue  # friction at the study's r only
                    model, rigid = plant(dd, c2, r, fr)
                    branch = continue_orbit(model, "log10_stiffness", DECADES, rigid.state)
                    rows.append((dd, c2, r, fr, rho(rigid.monodromy), branch))
                    print_row(rows[-1])
    failing(rows)
    figure(rows)


def print_row(row):
    dd, c2, r, fr, r0, br = row
    vals = {round(pt.value, 6): float(np.max(np.abs(pt.multipliers))) for pt in br.points}
    line = " ".join(f"{vals.get(float(d), math.nan):.3f}" for d in range(8, 0, -1))
    cross = ", ".join(f"{b.type} at 10^{b.value:.4f}" for b in br.bifurcations) or "none"
    contacts = f"{br.points[0].impacts}..{br.points[-1].impacts}"
    fr = f"{fr:6.3f}" if isinstance(fr, float) else fr
    print(f"{dd:8.0e} {c2:5.1f} {r:5.2f} {fr} {r0:6.3f} | {line} | {cross} "
          f"(to 10^{br.points[-1].value:.2f}; contacts a period {contacts})", flush=True)


def failing(rows):
    s = FAILING
    model, rigid = plant(s["delta_d"], s["c2"], s["r"], s["friction"])
    branch = continue_orbit(model, "log10_stiffness", DECADES, rigid.state)
    states = {pt.value: pt.state for pt in branch.points}
    print(f"\nfailing set {s}: rigid design c1 = {model.gains.c1:.6f}, rigid-model "
          f"multiplier {rho(rigid.monodromy):.4f}")
    for b in branch.bifurcations:
        lo = max(v for v in states if v < b.value)
        hi = min(v for v in states if v > b.value)
        check = crossing_by_bisection(model, lo, hi, states)
        print(f"  continuation: {b.type} at log10 k_c = {b.value:.6f} (k_c = "
              f"{10 ** b.value:.4g}); bisection on max|lambda| = 1: {check:.6f}")
    for lk in (8.0, 4.0):
        low, rigid_low = plant(s["delta_d"], s["c2"], s["r"], 0.001, k=10 ** lk)
        fb = continue_orbit(low, "friction", np.linspace(0.001, s["friction"], 10),
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
    for dd, c2, r, fr, r0, br in rows:
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


if __name__ == "__main__":
    print(f"{'Delta d':>8} {'c2':>5} {'r':>5} {'F_f':>6} {'rigid':>6} | largest |multiplier| "
          "at log10 k_c = 8 7 6 5 4 3 2 1 | crossings (contacts a period at 1e8..1e1)")
    import sys

    if "--hertz" in sys.argv[1:]:
        hertz_rows()
    else:
        main()

"""The rigid design on the Kelvin-Voigt plant: the largest multiplier of the controlled
1/1 orbit against the stop's stiffness ratio (docs/theory_contact.md section 13).

    PYTHONPATH=. python benchmarks/chart_contact.py

For each Delta d and c2, the gains are the rigid design (c1 from Eq. 38 for that c2,
dynamics/design.py); the controlled 1/1 orbit of the compliant model (CompliantOneDOF, a
PeriodMap) is continued in log10 k_c from 8 down to 1 at the study's r = 0.68 (fixed
contact damping ratio, Eq. C3) by dynamics/continuation.continue_orbit, whose
bifurcation detection reports any multiplier crossing the unit circle; the uncontrolled
orbit's largest multiplier is shown beside it. Writes benchmarks/out/contact/rho.png
(git-ignored) and prints the table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grazing_control.dynamics.compliant_model import CompliantOneDOF
from grazing_control.dynamics.continuation import continue_orbit
from grazing_control.dynamics.design import degenerate_c1
from grazing_control.dynamics.model import OneDOF
from grazing_control.dynamics.shooting import ShootingFailed, find_periodic
from grazing_control.oscillator.contact import KelvinVoigt
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

OUT = Path(__file__).parent / "out" / "contact"
DELTAS = (-5e-6, -1e-4, -1e-3)
C2S = (-1.0, -0.5, -1.5)
DECADES = np.linspace(8.0, 1.0, 29)


def rho(monodromy) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(monodromy))))


def main():
    rows = []
    for dd in DELTAS:
        p = OscillatorParams(delta_d=dd)
        for c2 in C2S:
            gains = Gains(degenerate_c1(p, c2), c2)
            rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
            model = CompliantOneDOF(p, gains, law=KelvinVoigt.from_restitution(1e8, p.r))
            branch = continue_orbit(model, "log10_stiffness", DECADES, rigid.state)
            rows.append((dd, c2, rho(rigid.monodromy), branch))
    print(f"{'Delta d':>8} {'c2':>5} {'rigid':>6} | largest |multiplier| at log10 k_c = "
          "8 7 6 5 4 3 2 1 | crossings")
    for dd, c2, r0, br in rows:
        vals = {round(pt.value, 6): float(np.max(np.abs(pt.multipliers))) for pt in br.points}
        line = " ".join(f"{vals.get(float(d), float('nan')):.3f}" for d in range(8, 0, -1))
        print(f"{dd:8.0e} {c2:5.1f} {r0:6.3f} | {line} | {len(br.bifurcations)} ({br.stopped})")
    print("\nuncontrolled 1/1 orbit, largest |multiplier|:")
    for dd in DELTAS:
        p = OscillatorParams(delta_d=dd)
        out = []
        guess = np.zeros(2)
        for lk in range(1, 9):
            try:
                law = KelvinVoigt.from_restitution(10.0 ** lk, p.r)
                o = find_periodic(CompliantOneDOF(p, law=law), guess)
                out.append(f"1e{lk}:{rho(o.monodromy):.3f}")
            except ShootingFailed:
                out.append(f"1e{lk}:--")
        print(f"{dd:8.0e} " + " ".join(out))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    OUT.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 4))
    for dd, c2, r0, br in rows:
        ax.plot([10 ** pt.value for pt in br.points],
                [np.max(np.abs(pt.multipliers)) for pt in br.points],
                label=f"Δd={dd:.0e}, c2={c2}")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("k_c / k")
    ax.set_ylabel("largest |multiplier|, controlled 1/1")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "rho.png", dpi=120)
    print(f"wrote {OUT / 'rho.png'}")


if __name__ == "__main__":
    main()

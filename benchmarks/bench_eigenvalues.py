"""Work-precision of the 1/1 eigenvalues: perturbation formulas against exact shooting.

Side by side in one process, for the uncontrolled branch and the controlled one
(c2 = -1, c1 from the degenerate condition, Eq. 38), over Delta d in [-1e-4, -1e-9]:

* ``exact shooting``      orbits.orbit_11(...).multipliers (impact-phase shooting with
                          the exact-flow check of one period, the project's reference);
* ``exact, no check``     the same without the flow check (check=False);
* ``normal form, D exact`` Newton on N_g o D_exact (zdm.py): exact too, other algorithm;
* ``normal form, D2``     Newton on N_g o D2 (second-order ZDM);
* ``perturbation (P8)``   perturbation_multipliers(truncation='limit'): Eq. 26 (non-
                          degenerate) / lambda0 of Eq. 23 (degenerate), from scratch;
* ``perturbation (+chi1)`` truncation='practical' (Eq. 25), from scratch;
* ``perturbation, cached`` the practical truncation with the series coefficients
                          computed once (the cost inside a sweep over Delta d).

Cost: seconds per evaluation (best of ``--repeat`` timings of a loop). Error: relative
error of the largest-modulus multiplier against a reference computed by the same
impact-phase equations in mpmath at 40 digits (``--no-mpmath``: against orbit_11).
Prints a table and saves a work-precision chart (PNG) to benchmarks/out/eigenvalues.png.

Run: ``PYTHONPATH=. python benchmarks/bench_eigenvalues.py [--points 11] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.dynamics.orbits.orbits import find_branch_phase, multipliers, orbit_11  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.dynamics.maps.perturbation import (characteristic_roots, delta2_from_delta_d,
                                                   normal_form_fixed_point,
                                                   perturbation_multipliers,
                                                   series_coefficients)

FLOOR = 1e-17  # errors of exactly 0 are drawn here


def mp_multipliers(p: OscillatorParams, gains, psi_guess: float, dps: int = 40):
    """1/1 multipliers at p.delta_d from the impact-phase equations (docs/theory.md 5)
    in mpmath: the branch point solved for Delta d by findroot, J = M S."""
    import mpmath as mp

    with mp.workdps(dps):
        zeta, r, w = mp.mpf(p.zeta), mp.mpf(p.r), mp.mpf(p.omega)
        off, dd = mp.mpf(p.pi2_offset), mp.mpf(p.delta_d)
        two_pi = 2 * mp.pi
        a = 1 / mp.sqrt((1 - w * w) ** 2 + (2 * zeta * w) ** 2)
        tau_s = mp.atan2(2 * zeta * w, 1 - w * w) % two_pi
        tau2 = (tau_s + off) % two_pi
        period = two_pi / w
        wd = mp.sqrt(1 - zeta * zeta)
        d = a + dd

        def phi(h):
            e, c, s = mp.exp(-zeta * h), mp.cos(wd * h), mp.sin(wd * h) / wd
            return [[e * (c + zeta * s), e * s], [-e * s, e * (c - zeta * s)]]

        def mul(x, y):
            return [[sum(x[i][k] * y[k][j] for k in range(2)) for j in range(2)] for i in range(2)]

        def m_of(theta):
            if gains is None:
                return phi(period)
            s = ((tau2 - theta) % two_pi) / w
            g = [[1, 0], [mp.mpf(gains.c1), 1 + mp.mpf(gains.c2)]]
            return mul(phi(period - s), mul(g, phi(s)))

        def branch(psi):
            m = m_of(tau_s + psi)
            u1, u2 = 2 * a * mp.sin(psi / 2) ** 2, a * w * mp.sin(psi)
            b11, b12, b21, b22 = m[0][0] - 1, m[0][1], m[1][0], m[1][1] - 1
            w1, w2 = r * m[0][1], 1 + r * m[1][1]
            rhs1, rhs2 = -(b11 * u1 + b12 * u2), -(b21 * u1 + b22 * u2)
            det = -b11 * w2 + w1 * b21
            return (-rhs1 * w2 + w1 * rhs2) / det, (b11 * rhs2 - b21 * rhs1) / det, m

        psi = mp.findroot(lambda s: branch(s)[0] - dd, mp.mpf(psi_guess))
        _dd, v, m = branch(psi)
        sal = [[-r, 0], [(1 + r) * (mp.cos(tau_s + psi) - d) / v, -r]]
        jac = mul(m, sal)
        tr = jac[0][0] + jac[1][1]
        det = jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0]
        root = mp.sqrt(tr * tr - 4 * det)
        lam = [(tr + root) / 2, (tr - root) / 2]
        lam.sort(key=lambda x: -abs(x))
        return np.array([complex(x) for x in lam])


def cost(fn, repeat: int, budget: float = 0.05) -> float:
    """Seconds per call: loop sized to ~budget seconds, best of ``repeat`` loops."""
    t0 = time.perf_counter()
    fn()
    one = max(time.perf_counter() - t0, 1e-7)
    n = max(1, int(budget / one))
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def methods(gains):
    """name -> function(p) returning the multipliers (largest modulus first)."""
    coeffs = series_coefficients(OscillatorParams(), gains)

    def cached(p):
        return characteristic_roots(coeffs, delta2_from_delta_d(coeffs, p.delta_d), "practical")

    def nf(order):
        def run(p):
            return multipliers(normal_form_fixed_point(p, gains, order=order)[1])
        return run

    return {
        "exact shooting": lambda p: orbit_11(p, gains).multipliers,
        "exact, no check": lambda p: orbit_11(p, gains, check=False).multipliers,
        "normal form, D exact": nf("exact"),
        "normal form, D2": nf(2),
        "perturbation (P8)": lambda p: perturbation_multipliers(p, gains, "limit"),
        "perturbation (+chi1)": lambda p: perturbation_multipliers(p, gains, "practical"),
        "perturbation, cached": cached,
    }


def run(points: int, repeat: int, use_mp: bool):
    base = OscillatorParams()
    branches = {"uncontrolled": None,
                "controlled c2=-1": Gains(degenerate_c1(base, -1.0), -1.0)}
    grid = -np.logspace(-4, -9, points)
    results = {}
    for bname, gains in branches.items():
        refs = []
        for dd in grid:
            p = base.with_(delta_d=float(dd))
            if use_mp:
                refs.append(mp_multipliers(p, gains, find_branch_phase(p, p.delta_d, gains)))
            else:
                refs.append(orbit_11(p, gains).multipliers)
        for mname, fn in methods(gains).items():
            costs, errs = [], []
            for dd, ref in zip(grid, refs):
                p = base.with_(delta_d=float(dd))
                lam = fn(p)
                errs.append(float(abs(lam[0] - ref[0]) / abs(ref[0])))
                costs.append(cost(lambda p=p: fn(p), repeat))
            results[(bname, mname)] = (np.array(costs), np.array(errs))
    return grid, results


def table(grid, results) -> str:
    picks = [int(np.argmin(np.abs(np.log10(-grid) - e))) for e in (-4, -6, -9)]
    head = ("| branch | method | cost per evaluation (median) "
            "| rel. error Δd=%s | Δd=%s | Δd=%s |" % tuple(f"{grid[k]:.0e}" for k in picks))
    lines = [head, "|" + "---|" * 6]
    for (bname, mname), (costs, errs) in results.items():
        lines.append(f"| {bname} | {mname} | {np.median(costs):.2e} s | "
                     + " | ".join(f"{errs[k]:.1e}" for k in picks) + " |")
    return "\n".join(lines)


def chart(grid, results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    branches = list(dict.fromkeys(b for b, _ in results))
    fig, axes = plt.subplots(1, len(branches), figsize=(12, 5), sharey=True)
    markers = "osD^v<>"
    for ax, bname in zip(np.atleast_1d(axes), branches):
        for k, ((b, mname), (costs, errs)) in enumerate(
                (key, val) for key, val in results.items() if key[0] == bname):
            ax.loglog(np.maximum(errs, FLOOR), costs, marker=markers[k % len(markers)],
                      linestyle="-", linewidth=0.8, markersize=4, label=mname)
        ax.set_title(f"{bname}: Δd from {grid[0]:.0e} to {grid[-1]:.0e}")
        ax.set_xlabel("relative error of the largest multiplier (vs 40-digit reference)")
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("cost per evaluation [s]")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.suptitle("1/1 eigenvalues near grazing: work-precision (errors < 1e-17 drawn at 1e-17)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=11, help="Delta d values (log grid), >= 3")
    ap.add_argument("--repeat", type=int, default=3, help="timing repeats (best is kept)")
    ap.add_argument("--no-mpmath", action="store_true", help="reference = orbit_11")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "out" / "eigenvalues.png"))
    args = ap.parse_args(argv)
    if args.points < 3:
        ap.error(f"--points={args.points} is invalid: valid range is >= 3")
    use_mp = not args.no_mpmath
    if use_mp:
        try:
            import mpmath  # noqa: F401
        except ImportError:
            print("mpmath not available: reference = orbit_11", file=sys.stderr)
            use_mp = False
    t0 = time.perf_counter()
    grid, results = run(args.points, args.repeat, use_mp)
    print(table(grid, results))
    print(f"\nreference: {'mpmath 40 digits' if use_mp else 'orbit_11 (double)'}; "
          f"{args.points} values of Δd; wall time {time.perf_counter() - t0:.1f} s")
    chart(grid, results, Path(args.out))
    print(f"chart: {os.path.relpath(args.out, os.getcwd())}")
    cmd = " ".join([os.path.relpath(sys.executable) if sys.executable.startswith(os.getcwd())
                    else sys.executable, *sys.argv])
    print(f"command: cd {os.getcwd()} && PYTHONPATH=. {cmd}")


if __name__ == "__main__":
    main()

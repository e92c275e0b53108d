"""The numbers of docs/theory_ndof.md §11-§12 for a model file (default: the two-mass chain).

Prints the design data (d*, zeros, admissible mu, the design at ``--mu`` and at the
smallest limit radius), then the exact multipliers of the 1/1 orbit born at grazing
(Newton shooting on ModalMap from the explicit branch's Pi2 state) at Delta d = -1e-4 ..
-1e-10 for the design, the two cancel-first-Markov gains and the uncontrolled model, with
the fitted orders / exponents.

Run: ``python benchmarks/bench_ndof_design.py [--model FILE] [--mu 0.2] [--offset 0.5]``
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from grazing_control.dynamics.orbits import modal_branch as nb
from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.shooting import find_periodic, floquet_multipliers
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.ndof.flow import NdofFlow

CHAIN = Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_chain.yaml"
DELTAS = np.array([1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10])


def match(a, b) -> float:
    cost = np.abs(np.subtract.outer(np.asarray(a), np.asarray(b)))
    i, j = linear_sum_assignment(cost)
    return float(cost[i, j].max())


def exact(model, gains, dd):
    m = dataclasses.replace(model, delta_d=-dd)
    bp = nb.orbit_at(m, gains, -dd)
    orbit = find_periodic(ModalMap(m, None if not np.any(gains) else gains), bp.pi2_state)
    return orbit, floquet_multipliers(orbit.monodromy), bp


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(CHAIN))
    ap.add_argument("--mu", type=float, default=0.2)
    ap.add_argument("--offset", type=float, default=0.5)
    a = ap.parse_args(argv)
    m = load_model(a.model)
    flow = NdofFlow.of(m)
    print(f"d* {flow.d_star:.6f}  tau* {flow.tau_star:.6f}  alpha* {m.omega ** 2 * flow.d_star:.6f}")
    print("zeros", np.round(nd.transmission_zeros(m), 6))
    for cond in nd.CONDITIONS:
        print(f"admissible mu ({cond}):", nd.admissible_mu(m, cond))
    zero = np.zeros(2 * m.n)
    print("uncontrolled (d1, gamma1, v1):", nb.branch_coefficients(m, zero))
    sets = nd.admissible_mu(m)
    if sets:
        lo, hi = max(sets, key=lambda iv: iv[1] - iv[0])
        mus = np.linspace(lo, hi, 2001)[1:-1]
        best = min(mus, key=lambda x: nd.evaluate_design(m, x).limit_radius)
        d = nd.evaluate_design(m, best)
        print(f"smallest limit radius {d.limit_radius:.4f} at mu {best:.4f}, k {np.round(d.gains, 4)}")
    d = nd.evaluate_design(m, a.mu)
    print(f"mu {a.mu}: k {d.gains}, limit {np.round(d.limit_multipliers, 4)}, gamma1 {d.gamma1:.4f}, "
          f"admissible {d.admissible}")
    errs = []
    for dd in DELTAS:
        orbit, lam, bp = exact(m, d.gains, dd)
        errs.append(match(lam, d.limit_multipliers))
        print(f"  Delta d {-dd:.0e}: v- {orbit.impacts[0].v_minus:.4e}  max|lam| {np.abs(lam).max():.6f}"
              f"  error {errs[-1]:.3e}  error/sqrt|dd| {errs[-1] / dd ** 0.5:.3f}"
              f"  shooting vs branch {match(lam, np.linalg.eigvals(bp.monodromy)):.1e}")
    print(f"  fitted order {np.polyfit(np.log(DELTAS), np.log(errs), 1)[0]:.4f}")
    gains = {"uncontrolled": zero,
             "cancel first Markov, G(1) = 0": nd.cancel_first_markov(m, a.mu, a.offset),
             "cancel first Markov only": nd.cancel_first_markov(m, a.mu, a.offset,
                                                                smooth_branch=False)}
    for name, k in gains.items():
        try:
            big = [np.abs(exact(m, k, dd)[1]).max() for dd in DELTAS]
        except ValueError as exc:
            print(f"{name}: {exc}")
            continue
        print(f"{name}: max|lam| {big[0]:.4g} .. {big[-1]:.4g}, exponent "
              f"{np.polyfit(np.log(DELTAS), np.log(big), 1)[0]:.4f}")


if __name__ == "__main__":
    main()

"""The n-DOF Pi2 map: the exact core (ModalMap) against an ODE solver, speed and accuracy.

Both run the same periods from the same states of the two-mass chain near grazing
(config/models/two_mass_chain.yaml, the uncontrolled motion at Delta d = -5e-6 after a
transient, 0 or 1 impact per period): the exact core (modal closed form, certified impact
search, docs/theory_ndof_flow.md) and scipy's solve_ivp (DOP853, the wall as a terminal
event, restarted after the impact law) at several tolerances, as a user of a generic
tool would. Error: the largest deviation of the next Pi2 state from a 50-digit mpmath
reference (tests/reference_ndof.py) over the sampled periods. Prints the time per
period and the speed ratio against the exact core, side by side in this process.

Run: ``.venv/bin/python benchmarks/bench_ndof_map.py [--periods 40]``
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from grazing_control.dynamics.maps.modal_map import ModalMap  # noqa: E402
from grazing_control.oscillator.ndof import load_model  # noqa: E402
from reference_ndof import load_reference  # noqa: E402

CHAIN = ROOT / "config" / "models" / "two_mass_chain.yaml"


def ode_step(m: ModalMap, z, rtol):
    """One Pi2 period by solve_ivp on the physical state, impacts by event location."""
    model, flow = m.model, m.flow
    n, iw = model.n, model.i_w
    minv = np.linalg.inv(model.M)
    d = flow.d_star + model.delta_d
    t0 = (flow.tau2 - model.phase) / model.omega
    x = flow.to_physical(flow.tau2, np.asarray(z, float))

    def rhs(t, y):
        force = model.f * math.cos(model.omega * t + model.phase)
        acc = minv @ (force - model.C @ y[n:] - model.K @ y[:n])
        return np.concatenate([y[n:], acc])

    def wall(t, y):
        return y[iw] - d
    wall.terminal, wall.direction = True, 1.0
    t, t1 = t0, t0 + m.period
    for _ in range(1000):
        sol = solve_ivp(rhs, (t, t1), x, method="DOP853", rtol=rtol, atol=rtol * 1e-3,
                        events=wall)
        x = sol.y[:, -1].copy()
        if sol.status != 1:
            break
        t = sol.t_events[0][0]
        x = sol.y_events[0][0].copy()
        x[iw] = d
        x[n + iw] = -model.r * x[n + iw]
        t = math.nextafter(t, math.inf)
    return flow.to_deviation(flow.tau2, x)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=40)
    args = ap.parse_args(argv)
    model = dataclasses.replace(load_model(CHAIN), delta_d=-5e-6)
    m = ModalMap(model)
    z = np.zeros(2 * model.n)
    for _ in range(300):                      # onto the attractor
        z = m.step(z).state
    starts = []
    for _ in range(args.periods):
        starts.append(z)
        z = m.step(z).state
    ref = load_reference(CHAIN, delta_d=-5e-6)
    exact = [np.array([float(v) for v in ref.pi2_map(list(s))[0]]) for s in starts]

    def run(step):
        t = time.perf_counter()
        out = [step(s) for s in starts]
        per = (time.perf_counter() - t) / len(starts)
        err = max(float(np.max(np.abs(o - e))) for o, e in zip(out, exact))
        return per, err

    core = run(lambda s: m.step(s).state)
    print(f"n-DOF Pi2 map, two-mass chain, Delta d = -5e-6, {len(starts)} periods "
          f"({sum(len(m.step(s).impacts) for s in starts)} impacts)")
    print(f"{'method':<24}{'time/period':>14}{'ratio':>10}{'max error':>12}")
    print(f"{'exact core (ModalMap)':<24}{core[0] * 1e3:>11.3f} ms{1.0:>10.1f}{core[1]:>12.2e}")
    for rtol in (1e-6, 1e-9, 1e-12):
        per, err = run(lambda s, r=rtol: ode_step(m, s, r))
        print(f"{'solve_ivp DOP853 ' + format(rtol, '.0e'):<24}{per * 1e3:>11.3f} ms"
              f"{per / core[0]:>10.1f}{err:>12.2e}")


if __name__ == "__main__":
    main()

"""The contact references' integrator: Hairer's Fortran DOP853 with solve_ivp's events
(tests/dop853_events.py) against solve_ivp's DOP853 with dense output, which the
references used before, side by side in one process on the seeded cases of
tests/test_contact.py (Kelvin-Voigt, seed 1000) and tests/test_hertz.py (Hertz, seed
3000): the CPU of each reference per case, their ratio, and the largest differences
between the two (end state over 1 + |x| + |v|, contact entry and exit times).

    .venv/bin/python benchmarks/bench_contact_reference.py --cases 60
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import time
from pathlib import Path

from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import reference_contact  # noqa: E402
import reference_hertz  # noqa: E402
import test_contact  # noqa: E402
import test_hertz  # noqa: E402

FORTRAN = reference_contact._solve


def on_solve_ivp(rhs, t0, y0, t1, events):
    """The references' integrator before: solve_ivp's DOP853 with dense output."""
    return solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol=reference_contact.RTOL,
                     atol=reference_contact.ATOL, events=events, dense_output=True,
                     max_step=reference_contact.MAX_STEP[0], first_step=1e-9)


def _use(solve):
    reference_contact._solve = solve
    reference_hertz._solve = solve


def compare(name, cases, reference):
    cpu = {"solve_ivp": 0.0, "Fortran": 0.0}
    worst_state = worst_time = 0.0
    contacts = 0
    for _, p, law, tau0, x, v in cases:
        out = {}
        for label, solve in (("solve_ivp", on_solve_ivp), ("Fortran", FORTRAN)):
            _use(solve)
            t0 = time.process_time()
            out[label] = reference(p, law, tau0, x, v, p.period)
            cpu[label] += time.process_time() - t0
        (xa, va, ca), (xb, vb, cb) = out["solve_ivp"], out["Fortran"]
        worst_state = max(worst_state, max(abs(xa - xb), abs(va - vb)) / (1 + abs(xa) + abs(va)))
        if len(ca) != len(cb):
            print(f"  {name}: contact count differs: {ca} against {cb}")
            continue
        contacts += len(ca)
        for (ia, oa), (ib, ob) in zip(ca, cb):
            exits = 0.0 if math.isinf(oa) and math.isinf(ob) else abs(oa - ob)
            worst_time = max(worst_time, abs(ia - ib), exits)
    n = len(cases)
    print(f"{name}: {n} cases, {contacts} contacts; CPU per case solve_ivp "
          f"{1e3 * cpu['solve_ivp'] / n:.1f} ms, Fortran {1e3 * cpu['Fortran'] / n:.1f} ms, "
          f"ratio {cpu['solve_ivp'] / cpu['Fortran']:.2f}; largest difference: end state "
          f"{worst_state:.2g}, contact times {worst_time:.2g}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=60)
    a = ap.parse_args(argv)
    rng = random.Random(1000)
    compare("Kelvin-Voigt", [test_contact._case(rng) for _ in range(a.cases)],
            reference_contact.reference_advance)
    rng = random.Random(3000)
    compare("Hertz", [test_hertz._case(rng) for _ in range(a.cases)],
            reference_hertz.reference_advance_hertz)
    _use(FORTRAN)


if __name__ == "__main__":
    main()

"""Cost of one period with a Kelvin-Voigt stop (and friction) against the rigid wall, and
the rigid limit k_c -> inf (docs/benchmarks.md "Compliant stop", docs/theory_contact.md).

    PYTHONPATH=. python benchmarks/bench_contact.py [--periods 200] [--repeat 3]

Scene: the study's parameters (Hertz / Hunt-Crossley: alpha from r at v0 = 0.15, Eq. C5) at Delta d = -1e-3 from X** on Pi2 (the stable 1/1 orbit's
neighbourhood, one contact a period), the stop given by its stiffness ratio and the
study's r = 0.68 (Eq. C3). CPU time per period (time.process_time, best of --repeat).
The rigid limit: one period from (dx, dv) = (0.01, 0) at Delta d = -0.05, the distance
of the compliant end state to the rigid one, and the fitted order in k_c.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from grazing_control.dynamics.simulation.simulate import core_period_step
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, compliant_period_step
from grazing_control.oscillator.hertz import HuntCrossley, hertz_period_step
from grazing_control.oscillator.params import OscillatorParams


def _per_period(step, periods, repeat):
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        dx, dv, contacts = 0.0, 0.0, 0
        for _ in range(periods):
            dx, dv, n = step(dx, dv)
            contacts += n
        best = min(best, (time.process_time() - t0) / periods)
    return best, contacts / periods


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    p = OscillatorParams(delta_d=-1e-3)

    def rigid(dx, dv):
        s = core_period_step(p, dx, dv)
        return s.dx, s.dv, len(s.impacts)

    cost, n = _per_period(rigid, args.periods, args.repeat)
    print(f"{'model':<28} {'us/period':>10} {'contacts/period':>16}")
    print(f"{'rigid wall (core)':<28} {cost * 1e6:10.1f} {n:16.2f}")
    for k in (1e2, 1e4, 1e6, 1e8):
        law = KelvinVoigt.from_restitution(k, p.r)
        for fr in (None, Coulomb(0.01, 0.015)):
            def compliant(dx, dv, law=law, fr=fr):
                s = compliant_period_step(p, law, dx, dv, friction=fr)
                return s.x, s.v, len(s.contacts)
            cost, n = _per_period(compliant, args.periods, args.repeat)
            name = f"KV k_c={k:.0e}" + (" + friction" if fr else "")
            print(f"{name:<28} {cost * 1e6:10.1f} {n:16.2f}")
    for k in (1e2, 1e4, 1e6):
        law = HuntCrossley.from_restitution(k, p.r, 0.15)  # v- of the 1/1 orbit ~ 0.15

        def hertz(dx, dv, law=law):
            s = hertz_period_step(p, law, dx, dv)
            return s.x, s.v, len(s.contacts)
        cost, n = _per_period(hertz, args.periods // 4, args.repeat)
        print(f"{'Hertz-HC k_c=' + format(k, '.0e'):<28} {cost * 1e6:10.1f} {n:16.2f}")
    print()
    q = OscillatorParams(delta_d=-0.05, r=0.68)
    rig = core_period_step(q, 0.01, 0.0)
    ks = 10.0 ** np.arange(2, 9)
    errs = []
    print(f"{'k_c':>8} {'|state - rigid|':>16} {'contact time':>13}")
    for k in ks:
        s = compliant_period_step(q, KelvinVoigt.from_restitution(k, 0.68), 0.01, 0.0)
        errs.append(math.hypot(s.x - rig.dx, s.v - rig.dv))
        print(f"{k:8.0e} {errs[-1]:16.3e} {s.contacts[0].duration:13.3e}")
    slope = np.polyfit(np.log(ks[2:]), np.log(errs[2:]), 1)[0]
    print(f"fitted order over k_c = 1e4..1e8: {slope:.4f}")


if __name__ == "__main__":
    main()

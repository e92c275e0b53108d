"""The compliant grazing discontinuity maps against the exact flow: fitted order and
coefficient (docs/theory_contact.md sections 14 and 20, Eqs. C9, C10 and C12; the tests
assert the same cases).

    PYTHONPATH=.:tests python benchmarks/zdm_contact.py

One contact through the apex at tau*, Delta d = -1e-3: the velocity jump pulled back to
the apex (tests/reference_contact.apex_jump) at a range of virtual penetrations H, its
log-log slope, the coefficient at the smallest H, and the derived ones.
"""

from __future__ import annotations

import numpy as np

from grazing_control.oscillator import hertz
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, advance_compliant, grazing_jump
from grazing_control.oscillator.hertz import HuntCrossley, advance_hertz
from grazing_control.oscillator.params import OscillatorParams

from reference_contact import apex_jump

FRICTION = Coulomb(0.2, 0.25)
HERTZ = [(HuntCrossley(1e2), 10.0 ** np.arange(-7, -4.9, 0.5)),
         (HuntCrossley(1e3, 0.5), 10.0 ** np.arange(-7, -4.9, 0.5)),
         (HuntCrossley(1e4, 2.0), 10.0 ** np.arange(-7, -4.9, 0.5))]
KELVIN_VOIGT = [(KelvinVoigt(10.0, 0.0), 10.0 ** np.arange(-8, -3.9, 0.5)),
                (KelvinVoigt(100.0, 2.0), 10.0 ** np.arange(-11, -5.9, 0.5)),
                (KelvinVoigt(1e4, 50.0), 10.0 ** np.arange(-11, -5.9, 0.5))]


def fit(p, flow, heights, kinetic=0.0):
    jumps = [apex_jump(p, flow, p.tau_star, h, kinetic) for h in heights]
    dvs = np.array([-j for j, _ in jumps])
    return np.polyfit(np.log(heights), np.log(dvs), 1)[0], dvs[0], jumps[0][1]


def main():
    p = OscillatorParams(delta_d=-1e-3)
    print(f"{'stop':<46} {'slope':>8} {'order':>5} {'coef':>10} {'derived':>10} {'no friction':>11}")
    for law, hs in HERTZ:
        slope, dv, alpha = fit(p, lambda q, *a: advance_hertz(q, law, *a), hs)
        order, coef, _ = hertz.grazing_jump(law, alpha, hs[0])
        print(f"{str(law):<46} {slope:8.5f} {order:5.2f} {dv / hs[0] ** order:10.6g} {coef:10.6g}")
    for law, hs in HERTZ:
        slope, dv, alpha = fit(p, lambda q, *a: advance_hertz(q, law, *a, friction=FRICTION),
                               hs, FRICTION.kinetic)
        order, coef, _ = hertz.grazing_jump(law, alpha, hs[0], friction=FRICTION)
        bare = hertz.grazing_jump(law, alpha, hs[0])[1]
        print(f"{str(law) + ' F 0.2/0.25':<46} {slope:8.5f} {order:5.2f} "
              f"{dv / hs[0] ** order:10.6g} {coef:10.6g} {bare:11.6g}")
    for law, hs in KELVIN_VOIGT:
        slope, dv, alpha = fit(p, lambda q, *a: advance_compliant(q, law, *a, friction=FRICTION),
                               hs, FRICTION.kinetic)
        order, coef, _ = grazing_jump(law, alpha, hs[0], friction=FRICTION)
        bare = grazing_jump(law, alpha, hs[0])[1]
        print(f"{str(law) + ' F 0.2/0.25':<46} {slope:8.5f} {order:5.2f} "
              f"{dv / hs[0] ** order:10.6g} {coef:10.6g} {bare:11.6g}")


if __name__ == "__main__":
    main()

"""The condition number of the largest multiplier near grazing, on the 50-digit reference
(tests/reference_ndof.py), and each route's error there: why the n = 1 model file and the
1-DOF commands cannot agree to 1e-12 on every multiplier (issue 32, tests/test_n1_model_file.py).

    python benchmarks/n1_conditioning.py        # about 1.5 min

For each case (the study's 1-DOF model as the n = 1 file, c2 = -1 or no control, one
parameter of the plant off by a relative error as ``robustness model`` does, Delta d):
lambda on the reference (Newton at 50 digits from the n-DOF orbit), the relative error
of the 1-DOF route (``orbits.orbit_11``) and of the n-DOF route
(``modal_branch.branch_multipliers``) against it, and kappa = sum over the data p
(omega, r, C = 2 zeta, Delta d, pi2_offset, the gains) of |d lambda / d ln p| / |lambda|
by a relative step of 1e-24 on the reference. kappa u (u = 2^-53) is the error that
rounding the data alone gives; measured on the commit that added this file:

    case                         kappa u   1-DOF    n-DOF
    free  -6.6e-6                4.8e-13   4.9e-14  1.0e-12
    c2=-1 -1e-7                  6.6e-12   2.4e-12  1.1e-11
    c2=-1 -1e-10                 2.1e-10   2.4e-11  3.1e-10
    c2=-1 omega+1e-4 -3.2e-6     4.4e-10   2.9e-10  2.4e-10
    c2=-1 C+1e-2 -1.8e-8         3.5e-10   2.7e-10  3.3e-10
    c2=-1 r+0.1 -1e-10           1.5e-10   1.1e-10  1.4e-10
    c2=-1 r+0.1 -1e-14           1.5e-8    1.5e-9   1.9e-8

kappa grows like 1/v- (the designed cancellation of the singular term s q^T p of
J = B + s p q^T leaves lambda sensitive to every datum through s ~ 1/v-); omega carries
most of it (the degenerate frequency). Both routes stay within about 2 kappa u of the
reference, so they can differ by that much: the test bounds the multipliers by
max(1e-12, 4 kappa_omega u).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from mpmath import mpf  # noqa: E402
from reference_ndof import NdofRef  # noqa: E402

from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.dynamics.design.mismatch import mismatched, mismatched_model  # noqa: E402
from grazing_control.dynamics.orbits import modal_branch  # noqa: E402
from grazing_control.dynamics.orbits.orbits import orbit_11  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.oscillator.ndof import load_model  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402

ONE = Path(__file__).resolve().parents[1] / "config" / "models" / "study_1dof.yaml"
#: (controlled, 1-DOF parameter, model parameter, error, Delta d)
CASES = [(False, None, None, 0.0, -6.579332246575683e-06),
         (True, None, None, 0.0, -1e-07),
         (True, None, None, 0.0, -1e-10),
         (True, "omega", "omega", 1e-4, -3.162277660168379e-06),
         (True, "zeta", "C", 1e-2, -1.7782794100389228e-08),
         (True, "r", "r", 0.1, -1e-10),
         (True, "r", "r", 0.1, -1e-14)]
STEP = mpf("1e-24")


def case(controlled, name, model_name, error, delta_d):
    model = load_model(ONE)
    p = OscillatorParams(zeta=0.01, r=model.r, omega=model.omega, pi2_offset=model.pi2_offset)
    gains = Gains(degenerate_c1(p, -1.0), -1.0) if controlled else None
    k = [gains.c1, gains.c2] if controlled else [0.0, 0.0]
    if name is not None:
        p, model = mismatched(p, name, error), mismatched_model(model, model_name, error)
    model = dataclasses.replace(model, delta_d=delta_d)
    point = modal_branch.orbit_at(model, np.array(k), delta_d)
    ndof = modal_branch.branch_multipliers(model, np.array(k), point)[0]
    one = orbit_11(p.with_(delta_d=delta_d), gains).multipliers[0]
    data = dict(M=model.M.tolist(), C=model.C.tolist(), K=model.K.tolist(),
                f=model.f.tolist(), omega=model.omega, i_w=0, delta_d=delta_d, r=model.r,
                i_a=0, phase=model.phase, pi2_offset=model.pi2_offset)

    def lam(changes=(), kk=k):
        ref = NdofRef(**{**data, **dict(changes)})
        _z, jac, _imp = ref.fixed_point([mpf(float(x)) for x in point.pi2_state],
                                        gains=[mpf(x) for x in kk] if controlled else None,
                                        tol=mpf("1e-28"), max_iter=40)
        return ref.multipliers(jac)[0]

    l0 = lam()
    kappa = 0.0
    for key in ("omega", "r", "delta_d", "pi2_offset"):
        kappa += float(abs(lam({key: mpf(data[key]) * (1 + STEP)}) - l0) / abs(l0) / STEP)
    kappa += float(abs(lam({"C": [[mpf(data["C"][0][0]) * (1 + STEP)]]}) - l0) / abs(l0) / STEP)
    if controlled:
        for i in (0, 1):
            kk = [mpf(x) for x in k]
            kk[i] *= 1 + STEP
            kappa += float(abs(lam(kk=kk) - l0) / abs(l0) / STEP)
    err = [float(abs(complex(x) - complex(l0)) / abs(l0)) for x in (one, ndof)]
    return kappa * 2.0 ** -53, err[0], err[1]


def main():
    print(f"{'case':<30} {'kappa u':>9} {'1-DOF':>9} {'n-DOF':>9}")
    for c in CASES:
        label = (f"{'c2=-1' if c[0] else 'free'} {'' if c[1] is None else f'{c[2]}{c[3]:+g}'} "
                 f"{c[4]:.2g}")
        print(f"{label:<30} " + " ".join(f"{x:9.2g}" for x in case(*c)), flush=True)


if __name__ == "__main__":
    main()

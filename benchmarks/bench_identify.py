"""The identification's fits (dynamics/identification/fit.py and modal_fit.py), this
tree against a baseline's, side by side in one process on the same seeded recordings.

The baseline is a checkout (``git worktree add --detach /tmp/base-id <rev>``): its
fit.py, initial.py and modal_fit.py are loaded beside this tree's (the other modules of
the package are this tree's: the benchmark is for changes inside those three files).
Each recording is identified by both, in turn first; printed: the CPU of each (this
process's), the ratio baseline / this, whether every fitted vector, covariance and
Jacobian at the solution is the same, float for float, and where not, how far apart
(the fitted globals in standard errors, the Jacobians relative to each column).

    .venv/bin/python benchmarks/bench_identify.py --baseline /tmp/base-id [--seeds 6]

The 1-DOF recordings are tests/identification_scenes.py's rig recordings (four
scenes: x and v, position only in a rig's units, no impact topic, controlled), both ways
of finding the impacts; the modal ones are tests/test_modal_identification.py's random
chains (two masses, kicked, T/200).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import baseline_module  # noqa: E402

PACKAGE = "grazing_control.dynamics.identification"


def baseline(root: Path):
    """(fit, modal_fit) of the baseline, wired to its own initial guess and fit."""
    initial = baseline_module.load(root, f"{PACKAGE}.initial")
    fit = baseline_module.load(root, f"{PACKAGE}.fit")
    fit.initial_guess = initial.initial_guess
    fit.find_impacts = initial.find_impacts
    modal_fit = baseline_module.load(root, f"{PACKAGE}.modal_fit")
    for name in ("coloured_jacobian", "interior", "check_size"):
        if hasattr(modal_fit, name):
            setattr(modal_fit, name, getattr(fit, name))
    return fit, modal_fit


def one_dof_cases(seeds: int):
    from grazing_control.oscillator.control import Gains
    from identification_scenes import rig_recording

    scenes = [{}, dict(velocity=False, sin=False, Omega=1.3, A=0.7, theta=0.2),
              dict(impacts=False, Omega=0.8, A=2.0, theta=-1.0),
              dict(gains=Gains(-0.9, -0.5), control_after=8)]
    for seed in range(seeds):
        for scene in scenes:
            rec = rig_recording(periods=8, noise=1e-4, seed=seed, **scene)
            for impacts in ("recorded", "motion") if scene.get("velocity", True) \
                    else ("recorded",):
                yield rec, dict(impacts=impacts)


def modal_cases(seeds: int):
    from test_modal_identification import random_chain, simulate

    for seed in range(seeds):    # tests/test_modal_identification.py's seeded chains
        rng = np.random.default_rng(seed)
        model = random_chain(rng)
        kicks = 0.02 * rng.standard_normal(8)
        rec, dv = simulate(model, 8, 200, 1e-4, seed, kicks=kicks, delay=1.0, on=2)
        yield rec, dict(n=2, correction_dv=dv)


def _compare(a, b):
    """(the same float for float, the largest |difference| of the fitted globals in
    units of the baseline's standard errors, the largest |difference| of the Jacobians
    at the solution relative to the column's largest entry)."""
    ja, jb = a.problem.jacobian(a.solution), b.problem.jacobian(b.solution)
    same = (np.array_equal(a.solution, b.solution) and np.array_equal(ja, jb)
            and np.array_equal(np.asarray(a.covariance), np.asarray(b.covariance)))
    ng = np.asarray(a.covariance).shape[0]
    se = np.sqrt(np.diag(np.asarray(a.covariance)))
    held = se == 0.0
    z = np.abs(a.solution[:ng] - b.solution[:ng]) / np.where(held, 1.0, se)
    scale = np.maximum(np.max(np.abs(ja), axis=0), 1e-300)
    return same, float(np.max(z[~held], initial=0.0)), float(np.max(np.abs(ja - jb) / scale))


def run(label, cases, fit_base, fit_this):
    cpu = {"baseline": 0.0, "this": 0.0}
    same = count = 0
    z = jac = 0.0
    for i, (rec, kw) in enumerate(cases):
        order = (("baseline", fit_base), ("this", fit_this))
        out = {}
        for name, fit in order if i % 2 == 0 else order[::-1]:
            t0 = time.process_time()
            out[name] = fit(rec, **kw)
            cpu[name] += time.process_time() - t0
        one, dz, dj = _compare(out["baseline"], out["this"])
        same += one
        z, jac = max(z, dz), max(jac, dj)
        count += 1
    print(f"{label}: {count} fits, CPU baseline {cpu['baseline']:.2f} s, this "
          f"{cpu['this']:.2f} s, ratio {cpu['baseline'] / cpu['this']:.2f}; "
          f"the same float for float: {same} of {count}; largest difference of a fitted "
          f"global {z:.1e} standard errors, of a Jacobian entry {jac:.1e} of its column")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--seeds", type=int, default=6)
    args = ap.parse_args(argv)
    from grazing_control.dynamics.identification import fit, modal_fit
    from grazing_control.oscillator import kernel

    kernel.warm_up()
    base_fit, base_modal = baseline(args.baseline)
    run("1-DOF identify", one_dof_cases(args.seeds), base_fit.identify, fit.identify)
    run("modal identify_modal", modal_cases(args.seeds), base_modal.identify_modal,
        modal_fit.identify_modal)
    return 0


if __name__ == "__main__":
    sys.exit(main())

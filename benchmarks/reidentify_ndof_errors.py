"""The n-DOF re-identification of a controller model the model filter rejects (issue 32;
docs/theory_reidentification.md §6, the table under "Impacts found in the samples").

The core loop of tests/test_reidentification_ndof.py (the two-mass scene at Delta d =
-1e-3, x_0 at T/200 with sigma 1e-4, mu = -0.22, delay 1.0): 40 periods on a controller
model with one matrix or r scaled, the refit of the last 20 as the node requests it
(StreamRecord.snapshot(find_impacts=True): where the filter restarted too recently, the
impacts found in the samples), the worst distance of a fitted parameter from the TRUE
model's in its standard errors, |k - k_true| before and after, and the mean distance
of the last 20 Pi2 states from the true design's orbit over 40 more periods with and
without the switch.

    .venv/bin/python benchmarks/reidentify_ndof_errors.py C 1.05 K 1.02 r 1.03

``--seconds``: the refit's wall-clock budget (REFIT_SECONDS: 60; on a loaded machine a
longer one separates a slow fit from a failed one).
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import test_reidentification_ndof as scene  # noqa: E402
from grazing_control.dynamics.design.family import evaluate_design, family_mu  # noqa: E402
from grazing_control.dynamics.estimation.reidentification import (  # noqa: E402
    REFIT_SECONDS, ReidentificationError, StreamRecord, VectorGains, refit, redesign,
    switch_estimator)
from grazing_control.dynamics.identification.modal import modal_of  # noqa: E402
from grazing_control.dynamics.maps.modal_map import ModalMap  # noqa: E402
from grazing_control.dynamics.orbits.shooting import find_periodic  # noqa: E402
from grazing_control.oscillator.ndof.flow import NdofFlow  # noqa: E402

TRUE, MU, DELAY, SIGMA = scene.TRUE, scene.MU, scene.DELAY, scene.SIGMA


def run(which: str, factor: float, seconds: float) -> None:
    value = {"C": TRUE.C, "K": TRUE.K, "r": TRUE.r}[which]
    wrong = dataclasses.replace(TRUE, **{which: factor * value})
    gains = VectorGains.of(wrong, evaluate_design(wrong, MU, DELAY).gains, DELAY)
    loop = scene.Loop(wrong, gains.k, record=StreamRecord(TRUE.period, scene.PERIODS))
    loop.run(40)
    window = loop.record.snapshot(find_impacts=True)
    head = (f"{which} x {factor:g}: filter restarts {loop.est.resets} of 40, impacts "
            f"{sum(loop.impacts[-scene.PERIODS:])} in the window, sampled {window.sampled}")
    c0, w0 = time.process_time(), time.monotonic()
    try:
        fit = refit(window.recording(wrong, gains.delay), wrong, kicks=window.kick_sizes(),
                    actuation=gains.actuation, sigma=SIGMA, seconds=seconds)
        new = redesign(fit.model, gains)
    except ReidentificationError as exc:
        print(f"{head}\n  refused {exc.reason}: {exc} ({time.process_time() - c0:.1f} s CPU, "
              f"{time.monotonic() - w0:.1f} s)")
        return
    m, se, truth = fit.modal, fit.modal_stderr, modal_of(TRUE)
    errs = {f"{a}_{j}": (getattr(m, a)[j] - getattr(truth, a)[j]) / se[f"{a}_{j}"]
            for a in ("natural_frequency", "damping_ratio") for j in range(TRUE.n)}
    errs.update({a: (getattr(m, a) - getattr(TRUE, a)) / se[a] for a in ("r", "delta_d")})
    worst = max(errs, key=lambda k: abs(errs[k]))
    k_true = evaluate_design(TRUE, MU, DELAY).gains
    admissible = evaluate_design(TRUE, family_mu(TRUE, new.k, DELAY), DELAY).admissible
    target = find_periodic(ModalMap(TRUE, k_true, DELAY), np.zeros(2 * TRUE.n)).state
    ref = NdofFlow.of(TRUE)
    ref = ref.particular(ref.tau2)
    distance = {}
    for switched in (False, True):
        copy = scene.Loop(wrong, gains.k)
        copy.run(40)
        start = copy.k

        def switch(k, copy=copy, switched=switched, start=start):
            if switched and k == start:
                switch_estimator(copy.est, fit.model)
                copy.gains = np.asarray(new.k)
        copy.run(40, switch)
        pi2 = np.array(copy.pi2[-20:]) - ref
        distance[switched] = (float(np.mean(np.linalg.norm(pi2 - target, axis=1))),
                              copy.impacts[-20:])
    print(f"{head}\n  worst {worst} {errs[worst]:+.2f} standard errors "
          f"({time.process_time() - c0:.1f} s CPU, {time.monotonic() - w0:.1f} s); "
          f"|k - k_true| {np.linalg.norm(gains.k - k_true):.2e} -> "
          f"{np.linalg.norm(new.k - k_true):.2e}, admissible on the truth {admissible}\n"
          f"  distance from the true orbit: kept {distance[False][0]:.2e}, switched "
          f"{distance[True][0]:.2e} (impacts {distance[True][1]})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("errors", nargs="+", help="pairs: C|K|r factor")
    ap.add_argument("--seconds", type=float, default=REFIT_SECONDS)
    a = ap.parse_args()
    if len(a.errors) % 2:
        ap.error("errors come in pairs: C|K|r factor")
    for which, factor in zip(a.errors[::2], a.errors[1::2]):
        if which not in ("C", "K", "r"):
            ap.error(f"{which!r}: valid are C, K, r")
        run(which, float(factor), a.seconds)


if __name__ == "__main__":
    main()

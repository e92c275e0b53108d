"""Issue 32 in the core: the capture rule on the two-mass chain against the law at once.

config/models/two_mass_chain.yaml at Delta d = -1e-3, the pulse design (mu -0.22, delay
1, width 1), exact state on the n-DOF map (``pulse_step`` with a force limit), started on
z** and left uncontrolled N = 50, 150, ..., 1950 periods, then the law k^T z at once or
the capture rule (radius 5 sqrt(|Delta d|)) for ``--periods`` periods. Captured: one impact
per period and within the radius to the end. Prints, per force limit and switch: how many
of the 20 starts were captured, the rule's wait (median, max periods), the last entry into
the radius, the largest |Delta v| asked. docs/theory_capture.md, "Measured, n DOF".

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ndof_capture.py
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np

from grazing_control.dynamics.design.capture import CAPTURE_RADIUS
from grazing_control.dynamics.design.family import Actuation, evaluate_design
from grazing_control.dynamics.maps.modal_map import ModalMap, pulse_step
from grazing_control.dynamics.orbits.one_one import orbit
from grazing_control.oscillator.ndof.model import load_model
from grazing_control.ros import launcher


def run(cm, free, k, target, radius, N, rule, periods, limit):
    """(on_at, captured_from or None, largest |Delta v| asked, final distance)."""
    z = target.copy()
    for _ in range(N):
        z = free.step(z).state
    on, last_bad, peak = None, None, 0.0
    for j in range(periods):
        if on is None and (not rule or np.linalg.norm(z - target) <= radius):
            on = j
        dv = float(k @ z) if on is not None else 0.0
        peak = max(peak, abs(dv))
        out = pulse_step(cm.flow, z, dv, start=cm.pulse_start, width=cm.width,
                         force_limit=limit)
        z = np.asarray(out.state)
        if len(out.impacts) != 1 or not np.linalg.norm(z - target) <= radius:
            last_bad = j
    cap = None if last_bad == periods - 1 else (0 if last_bad is None else last_bad + 1)
    return on, cap, peak, float(np.linalg.norm(z - target))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=2000)
    ap.add_argument("--limits", type=float, nargs="+", default=[math.inf, 0.6, 0.3])
    a = ap.parse_args(argv)
    model = dataclasses.replace(load_model(launcher.CONFIG_DIR / "models" /
                                           "two_mass_chain.yaml"), delta_d=-1e-3)
    k = evaluate_design(model, -0.22, Actuation(1.0, 1.0)).gains
    target = orbit(model, k, delay=1.0, width=1.0).state
    radius = CAPTURE_RADIUS * math.sqrt(1e-3)
    cm, free = ModalMap(model, k, 1.0, 1.0), ModalMap(model)
    print(f"k {k}, z** {target} (|z**| {np.linalg.norm(target):.3f}, its correction "
          f"{k @ target:.3f}), radius {radius:.3f}")
    starts = range(50, 2050, 100)
    for limit in a.limits:
        for rule in (False, True):
            rows = [run(cm, free, k, target, radius, N, rule, a.periods, limit)
                    for N in starts]
            caps = [r[1] for r in rows if r[1] is not None]
            ons = [r[0] for r in rows]
            finals = [r[3] for r in rows if r[1] is None]
            print(f"limit {limit} {'rule' if rule else 'at once'}: captured "
                  f"{len(caps)}/{len(rows)}, on at median {np.median(ons):g} max {max(ons)}, "
                  f"captured from max {max(caps) if caps else None}, largest |dv| "
                  f"{max(r[2] for r in rows):.3f}, not captured end "
                  f"{min(finals, default=math.nan):.3f}-{max(finals, default=math.nan):.3f}"
                  " from z**", flush=True)


if __name__ == "__main__":
    main()

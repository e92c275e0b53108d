"""The model filter's fit per section, this tree against a baseline's, side by side
(issue 32: the two-mass rig at physical speed; issue 30: the T/200 stream).

Each section's fit (``section_state.model_update``: Gauss-Newton on the exact motion,
docs/theory_estimation.md (E4), (E11), "Where the fit stops") is run twice on the same
prior and the same samples: by the baseline's ``section_state`` (``--baseline DIR``, a
checkout such as ``git worktree add --detach /tmp/base-fit <rev>``: its
grazing_control/dynamics/estimation/section_state.py, loaded beside this tree's) and by
this tree's, in turn first. The stream is the one of benchmarks/bench_stream_estimator.py
(``--scene masses``: the two-mass rig's n-DOF filter on mass 1 at 500 samples a period;
``t200``: the 1-DOF T/200 stream with sigma 1e-4), replayed into a StreamEstimator whose
fits are the baseline's (so both see the baseline's filter states) while this tree's fit
runs on each call's inputs too. Printed: evaluations of the motion per fit, the fit's CPU
time (this thread's) p50 / p99 / max for each, and how far this tree's state at the
section is from the baseline's in units of the baseline's reported standard deviation.

    .venv/bin/python benchmarks/bench_model_fit.py --baseline /tmp/base-fit \\
        [--scene masses|t200] [--periods 300]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_stream_estimator as bench  # noqa: E402
from grazing_control.dynamics.estimation import section_state, stream  # noqa: E402
from grazing_control.oscillator import kernel  # noqa: E402


def _baseline(root: Path):
    """The baseline's section_state module, loaded under another name beside ours."""
    path = root / "grazing_control" / "dynamics" / "estimation" / "section_state.py"
    spec = importlib.util.spec_from_file_location("baseline_section_state", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _counted(module, counts, key):
    motion = module.trajectory

    def trajectory(*a, **k):
        counts[key] += 1
        return motion(*a, **k)

    module.trajectory = trajectory


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--scene", choices=("masses", "t200"), default="masses")
    ap.add_argument("--periods", type=int, default=300)
    args = ap.parse_args(argv)
    base = _baseline(args.baseline)
    kernel.warm_up()
    stream.warm_up()
    counts = {"baseline": 0, "this": 0}
    _counted(base, counts, "baseline")
    _counted(section_state, counts, "this")
    rows = []

    def timed(fit, *a, **k):
        t0 = time.thread_time()
        out = fit(*a, **k)
        return out, time.thread_time() - t0

    def both(p, prior, *a, **k):
        # in turn first: the second of a pair runs on caches the first warmed (measured
        # 1.3x between two copies of the same code in a fixed order)
        first_base = len(rows) % 2 == 0
        old_prior = base.FilterState(prior.z, prior.cov, prior.periods)
        if first_base:
            old, t_old = timed(base.model_update, p, old_prior, *a, **k)
        new, t_new = timed(section_state.model_update, p, prior, *a, **k)
        if not first_base:
            old, t_old = timed(base.model_update, p, old_prior, *a, **k)
        sd = np.sqrt(np.diag(old[0].cov))
        rows.append((float(np.max(np.abs(np.array(old[0].z) - new[0].z) / sd)),
                     t_old, t_new))
        return (section_state.FilterState(old[0].z, old[0].cov, old[0].periods),) + old[1:]

    stream.model_update = both
    if args.scene == "masses":
        rig, ndof, pulse, rate, v, kw = bench.masses_scene()
        samples = bench.record_masses(rig, ndof, v, kw, args.periods, 1)
        counts.update(baseline=0, this=0)
        rows.clear()
        bench.replay_masses(ndof, pulse, v, kw, samples, 1, True)
    else:
        p, gains, rate, kw = bench.t200_scene()
        samples = bench.record(p, gains, rate, kw, args.periods, 100)
        counts.update(baseline=0, this=0)
        rows.clear()
        bench.replay(p, gains, kw, samples, 100, True)
    r = np.array(rows)
    print(f"{args.scene}: {len(r)} fits, baseline {args.baseline}")
    for key, col in (("baseline", 1), ("this", 2)):
        ms = r[:, col] * 1e3
        print(f"  {key:8s} motion evaluations per fit {counts[key] / len(r):5.2f}  CPU ms "
              f"p50 {np.percentile(ms, 50):.3f} p99 {np.percentile(ms, 99):.3f} "
              f"max {ms.max():.2f}")
    print(f"  ratio baseline/this: CPU p50 {np.median(r[:, 1]) / np.median(r[:, 2]):.2f}, "
          f"p99 {np.percentile(r[:, 1], 99) / np.percentile(r[:, 2], 99):.2f}, "
          f"total {r[:, 1].sum() / r[:, 2].sum():.2f}")
    print(f"  this - baseline at the section, in baseline std: max {r[:, 0].max():.2e} "
          f"p99 {np.percentile(r[:, 0], 99):.2e} p50 {np.percentile(r[:, 0], 50):.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

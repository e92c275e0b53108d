"""The Kelvin-Voigt stop's exact flow before and after its hot path was made cheaper
(issue 30, the suite's CPU; docs/benchmarks.md "The compliant stop's hot path").

    PYTHONPATH=. python benchmarks/bench_compliant_flow.py [--base c0ece06] [--repeat 3]

In one process: ``grazing_control/oscillator/contact.py`` as it was at ``--base`` (read
from git, loaded as a sibling module of the current one) and as it is now, on the same
calls: the 600 seeded cases of tests/test_compliant_flow_bits.py (advance_compliant:
contacts, sticks, friction, forces, monodromy, dense output), its 200 period-map cases,
and the period map over the 60 Pi2 samples of tests/test_stop_selection.py's compliant
scene (what one evaluation of the stop's fit computes). CPU time (time.process_time,
best of --repeat, old and new alternated, then the new one with the compiled bracketing
of contact.load_compiled), the ratios to the old, and whether every output of the three
is the same float (the first case that differs is named).
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from grazing_control.oscillator import contact  # noqa: E402
from grazing_control.oscillator.contact import KelvinVoigt  # noqa: E402
from grazing_control.plant.engine import Engine  # noqa: E402
from grazing_control.plant.settings import settings_from_values  # noqa: E402
from test_compliant_flow_bits import (_canonical, flow_cases, period_cases,  # noqa: E402
                                      run_flow)


def load_base(rev: str):
    """contact.py at git revision ``rev`` as the module grazing_control.oscillator._contact_base
    (its relative imports resolve to the current package's flow, impact and params)."""
    source = subprocess.run(["git", "-C", str(REPO), "show",
                             f"{rev}:grazing_control/oscillator/contact.py"],
                            check=True, capture_output=True, text=True).stdout
    name = "grazing_control.oscillator._contact_base"
    spec = importlib.util.spec_from_loader(name, loader=None)
    module = importlib.util.module_from_spec(spec)
    module.__package__ = "grazing_control.oscillator"
    sys.modules[name] = module
    exec(compile(source, f"{rev}:contact.py", "exec"), module.__dict__)
    return module


def scene_cases() -> list:
    """compliant_period_step's calls in one evaluation of the stop's fit: the 60 Pi2
    samples of test_stop_selection's compliant scene (k_c = 1e3, r = 0.68, seed 1)."""
    law = KelvinVoigt.from_restitution(1e3, 0.68)
    s = settings_from_values({"delta_d": -0.05, "noise": 1e-4, "seed": 1,
                              "state_period": 0.0, "contact": "kelvin_voigt",
                              "contact_stiffness": law.stiffness,
                              "contact_damping": law.damping, "friction": 0.0})
    eng = Engine(s)
    eng.dx, eng.dv = 0.3, -0.2
    cases = []
    for _ in range(60):
        cases.append(((s.params, law, eng.dx, eng.dv, 0.0), {}))
        eng.begin_period(0.0)
        eng.end_period()
    return cases


def _time(fn, cases, repeat_out):
    t0 = time.process_time()
    out = run_flow(fn, cases)
    repeat_out.append(time.process_time() - t0)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="c0ece06", help="the git revision of the old code")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    base = load_base(args.base)
    workloads = [("advance_compliant, 600 cases", "advance_compliant", flow_cases()),
                 ("compliant_period_step, 200", "compliant_period_step", period_cases()),
                 ("stop fit: 60 Pi2 samples x 10", "compliant_period_step",
                  scene_cases() * 10)]
    print(f"base {args.base}; CPU s, best of {args.repeat}; new: Python bracketing, "
          f"+compiled: after contact.load_compiled()")
    print(f"{'workload':<32} {'old s':>8} {'new s':>8} {'new/old':>8} {'+compiled':>10} "
          f"{'/old':>6}  same bits")
    rows = []
    for label, fn, cases in workloads:
        old_t, new_t = [], []
        for _ in range(args.repeat):
            old = _time(getattr(base, fn), cases, old_t)
            new = _time(getattr(contact, fn), cases, new_t)
        rows.append((label, fn, cases, old, old_t, new, new_t))
    contact.load_compiled()            # compiles or loads outside the timings
    for label, fn, cases, old, old_t, new, new_t in rows:
        comp_t = []
        for _ in range(args.repeat):
            comp = _time(getattr(contact, fn), cases, comp_t)
        diff = next((i for i, (a, b, c) in enumerate(zip(old, new, comp))
                     if not _canonical(a) == _canonical(b) == _canonical(c)), None)
        same = "yes" if diff is None else f"NO (case {diff})"
        print(f"{label:<32} {min(old_t):8.3f} {min(new_t):8.3f} "
              f"{min(new_t) / min(old_t):8.3f} {min(comp_t):10.3f} "
              f"{min(comp_t) / min(old_t):6.3f}  {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

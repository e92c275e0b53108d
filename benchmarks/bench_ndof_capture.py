"""Issue 32 in the core: the capture rule on an n-DOF model against the law at once.

Default: config/models/two_mass_chain.yaml at Delta d = -1e-3, the pulse design (mu
-0.22, delay 1, width 1), exact state on the n-DOF map (``pulse_step`` with a force
limit), started on z** and left uncontrolled N = 50, 150, ..., 1950 periods, then the law
k^T z at once or the capture rule (radius 5 sqrt(|Delta d|)) for ``--periods`` periods.
Captured: one impact per period and within the radius to the end. Prints, per force limit
and switch: how many of the 20 starts were captured, the rule's wait (median, max
periods), the last entry into the radius, the largest |Delta v| asked.
docs/theory_capture.md, "Measured, n DOF".

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ndof_capture.py

``--rig FILE`` (a rig of n masses, docs/rig.md): the same on the rig's dimensionless model,
its design (the controller's: ``rig_boundary.masses_controller_values``, the default mu
or ``--mu``),
delay, pulse and force limit, the scene's start X** (docs/theory_capture.md, "The two-mass
beam after a late switch-on"): (1) the free motion's distance to z** from X** and its
closest approach once it has left; (2) the clipped law's basin, 20 seeded directions per
radius; (3) from the free motion (the 20 starts N = 100, ..., 119 periods after X**) the
law at once, the gain ramp and the capture rule at 5 sqrt(|Delta d|) and at a radius the
free motion reaches; (4) switched on E periods after X**.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ndof_capture.py --rig config/rigs/two_mass_beam.yaml
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from types import SimpleNamespace

import numpy as np

from grazing_control.dynamics.design.capture import CAPTURE_RADIUS, CaptureRule, GainRamp
from grazing_control.dynamics.design.family import Actuation, evaluate_design
from grazing_control.dynamics.maps.modal_map import ModalMap, pulse_step
from grazing_control.dynamics.orbits.one_one import orbit
from grazing_control.oscillator.impact import InitialStateError
from grazing_control.oscillator.ndof.model import load_model
from grazing_control.ros import launcher

STARTS = range(50, 2050, 100)
#: A rig's late switch-on: 20 consecutive periods from the scene's 100 (every state of a
#: free motion of period up to 20).
LATE = range(100, 120)


def run(cm, k, target, radius, z, switch, periods, limit):
    """(on_at, captured_from or None, largest |Delta v| asked, final distance) from the
    deviation z; ``switch(j, z)`` the factor of section j's correction (None: at once);
    (None, None, 0, nan) for a start beyond the wall."""
    on, last_bad, peak = None, None, 0.0
    try:
        for j in range(periods):
            factor = 1.0 if switch is None else switch(j, z)
            if on is None and factor > 0.0:
                on = j
            dv = factor * float(k @ z)
            peak = max(peak, abs(dv))
            out = pulse_step(cm.flow, z, dv, start=cm.pulse_start, width=cm.width,
                             force_limit=limit)
            z = np.asarray(out.state)
            if len(out.impacts) != 1 or not np.linalg.norm(z - target) <= radius:
                last_bad = j
    except InitialStateError:
        return None, None, 0.0, math.nan
    cap = None if last_bad == periods - 1 else (0 if last_bad is None else last_bad + 1)
    return on, cap, peak, float(np.linalg.norm(z - target))


def rule_switch(target, radius):
    """The capture rule (dynamics/design/capture.py) on the exact state (a finite
    covariance): switch(j, z)."""
    rule = CaptureRule(target, radius)
    return lambda j, z: rule(j, SimpleNamespace(z=z, cov=np.eye(z.size)))


def ramp_switch(sections):
    """The gain ramp over ``sections`` sections: switch(j, z)."""
    ramp = GainRamp(sections)
    return lambda j, z: ramp(j)


def report(name, rows) -> None:
    """One line: captured count, the switch-on (median, max), captured from (max), the
    largest |Delta v| asked, the final distance of those not captured."""
    rows = [r for r in rows if not math.isnan(r[3])]
    caps = [r[1] for r in rows if r[1] is not None]
    ons = [r[0] for r in rows if r[0] is not None]
    finals = [r[3] for r in rows if r[1] is None]
    print(f"{name}: captured {len(caps)}/{len(rows)}, on {len(ons)}/{len(rows)} (median "
          f"{np.median(ons) if ons else None} max {max(ons) if ons else None}), captured "
          f"from max {max(caps) if caps else None}, largest |dv| "
          f"{max(r[2] for r in rows):.3f}, not captured end "
          f"{min(finals, default=math.nan):.3f}-{max(finals, default=math.nan):.3f} from z**",
          flush=True)


def free_run(free, z, periods):
    """The free motion's states after each of ``periods`` periods from z."""
    out = []
    for _ in range(periods):
        z = np.asarray(free.step(z).state)
        out.append(z)
    return out


def chain(a) -> None:
    """The two-mass chain (module docstring)."""
    model = dataclasses.replace(load_model(launcher.CONFIG_DIR / "models" /
                                           "two_mass_chain.yaml"), delta_d=-1e-3)
    k = evaluate_design(model, -0.22, Actuation(1.0, 1.0)).gains
    target = orbit(model, k, delay=1.0, width=1.0).state
    radius = CAPTURE_RADIUS * math.sqrt(1e-3)
    cm, free = ModalMap(model, k, 1.0, 1.0), ModalMap(model)
    print(f"k {k}, z** {target} (|z**| {np.linalg.norm(target):.3f}, its correction "
          f"{k @ target:.3f}), radius {radius:.3f}")
    trail = free_run(free, target.copy(), max(STARTS))
    for limit in a.limits:
        for rule in (False, True):
            rows = [run(cm, k, target, radius, trail[N - 1],
                        rule_switch(target, radius) if rule else None, a.periods, limit)
                    for N in STARTS]
            report(f"limit {limit} {'rule' if rule else 'at once'}", rows)


def rig_study(a) -> None:
    """A rig of n masses (module docstring)."""
    from grazing_control.plant.rig import load_rig
    from grazing_control.ros.rig_boundary import masses_controller_values

    rig = load_rig(a.rig)
    model, v = rig.model(), masses_controller_values(rig, a.mu)
    k, delay, width = np.array(v["gains"]), v["actuation_delay"], v["pulse_width"]
    limit = v["force_limit"] or math.inf
    target = orbit(model, k, delay=delay, width=width).state
    radius = CAPTURE_RADIUS * math.sqrt(abs(model.delta_d))
    cm, free = ModalMap(model, k, delay, width), ModalMap(model)
    ma = 1.0 / np.linalg.inv(model.M)[model.i_a, model.i_a]
    print(f"{a.rig}: mu {v['mu']:.4g}, k {k} (|k| {np.linalg.norm(k):.3f}), z** {target} "
          f"(|z**| {np.linalg.norm(target):.4f}, its correction {k @ target:.4f}), radius "
          f"5 sqrt|dd| {radius:.4f}, force limit {limit:.4g} = |dv| <= "
          f"{limit * width / ma:.4f} per pulse, |k^T z**| + |k| radius "
          f"{abs(k @ target) + np.linalg.norm(k) * radius:.4f}")
    trail = free_run(free, np.zeros(model.n * 2), 1000)
    dist = np.array([np.linalg.norm(z - target) for z in [np.zeros(2 * model.n)] + trail])
    left = int(np.argmax(dist > radius))
    print(f"free from X**: distance to z** at periods 0-5 {np.round(dist[:6], 4)}, leaves "
          f"the radius at period {left}; closest over periods 10-1000 {dist[10:1001].min():.4f}"
          f" ({dist[10:1001].min() / radius:.1f} radii), quantiles 10/50/90 % "
          f"{np.round(np.quantile(dist[10:1001], [0.1, 0.5, 0.9]), 3)}", flush=True)
    rng = np.random.default_rng(a.seed)
    dirs = rng.normal(size=(20, 2 * model.n))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dirs[:, model.i_w] = -np.abs(dirs[:, model.i_w])    # the wall mass away from the stop
    near = [min(np.linalg.norm(z - target) for z in free_run(free, target + r * u, 600)[100:])
            for u, r in zip(dirs, np.geomspace(0.01, 0.3, 20))]
    print(f"free from 20 seeded starts 0.01-0.3 about z**: closest over periods 100-600 "
          f"{min(near):.4f}-{max(near):.4f}", flush=True)
    for lim in (limit, math.inf):
        for r in a.radii:
            report(f"basin, limit {lim:.4g}, r {r:g}", [run(cm, k, target, radius, target + r * u,
                                                           None, a.periods, lim) for u in dirs])
    wide = float(np.ceil(dist[10:1001].min() * 10.0 + 1.0) / 10.0)
    for lim in (limit, math.inf):
        for name, make in (("at once", lambda: None), ("ramp 20", lambda: ramp_switch(20)),
                           ("ramp 100", lambda: ramp_switch(100)),
                           (f"rule {radius:.3g}", lambda: rule_switch(target, radius)),
                           (f"rule {wide:g}", lambda: rule_switch(target, wide))):
            report(f"free motion, limit {lim:.4g}, {name}",
                   [run(cm, k, target, radius, trail[N - 1], make(), a.periods, lim)
                    for N in LATE])
    for E in (1, 2, 3, 5, 10, 100):
        z0 = trail[E - 1]
        once, rule = (run(cm, k, target, radius, z0, s, a.periods, limit)
                      for s in (None, rule_switch(target, radius)))
        print(f"switched on after {E} periods ({np.linalg.norm(z0 - target):.3f} from z**), "
              f"limit {limit:.4g}: at once captured from {once[1]}, rule {radius:.3g} on at "
              f"{rule[0]} captured from {rule[1]}", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=None,
                    help="periods after the switch-on (2000; with --rig 300)")
    ap.add_argument("--limits", type=float, nargs="+", default=[math.inf, 0.6, 0.3])
    ap.add_argument("--rig", default=None, help="a rig file of n masses (module docstring)")
    ap.add_argument("--radii", type=float, nargs="+", default=[0.02, 0.05, 0.1, 0.2, 0.5, 0.85])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--mu", type=float, default=math.nan,
                    help="with --rig: the design's mu (default: the controller's)")
    a = ap.parse_args(argv)
    if a.periods is None:
        a.periods = 2000 if a.rig is None else 300
    if a.rig is None:
        chain(a)
    else:
        rig_study(a)


if __name__ == "__main__":
    main()

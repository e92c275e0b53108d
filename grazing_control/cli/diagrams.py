"""`grazing sweep` and `grazing figures` on a model file (``--model``, :mod:`.model_file`):
the brute-force diagram of one parameter and the figure set near grazing of any n
(docs/ndof_commands.md). Without ``--model`` the commands are the 1-DOF study's, in the
studies they run (studies/sweeps/cli.py, studies/figures/command.py); :func:`.model_file.
dispatch` picks the one.
"""

from __future__ import annotations

import time

import numpy as np

from grazing_control.oscillator.params import ParameterError

from .common import nulls
from .model_file import control_of, coordinates, delay_of, load

__all__ = ["cmd_sweep", "cmd_figures"]


def cmd_sweep(args):
    """sweep --model FILE --grid NAME=A:B:N --periods P [gains [--delay D]]
    (docs/ndof_commands.md): the kick ``--delay`` after each sample, as simulate."""
    import os
    import sys

    from grazing_control.studies.sweeps.model_file import diagram
    from grazing_control.studies.sweeps.plot import coordinate_index, diagram_png

    model = load(args.model)
    if len(args.grid) != 1:
        raise ParameterError(f"--grid is given {len(args.grid)} times: with --model a sweep has "
                             "one axis (delta_d, omega, r, phase or pi2_offset)")
    name, values = args.grid[0]
    k, mu, how = control_of(args, model)
    delay = delay_of(args, model)
    coordinate = args.coordinate or f"x{model.i_w}"
    coordinate_index(coordinates(model), coordinate)     # valid before the run
    transient = args.periods // 2 if args.transient is None else args.transient
    out = os.path.abspath(args.out)
    if os.path.isdir(out) or args.out.endswith(os.sep):
        out = os.path.join(out, "sweep.npz")
    if not out.endswith(".npz"):
        out += ".npz"
    os.makedirs(os.path.dirname(out), exist_ok=True)
    t0 = time.perf_counter()
    res = diagram(model, values, name=name, periods=args.periods, transient=transient,
                  start=args.z0, gains=k, control_after=args.control_after,
                  workers=args.workers, scheduler=args.scheduler, period_tol=args.period_tol,
                  max_period=args.max_period, progress=not args.json and sys.stderr.isatty(),
                  delay=delay)
    seconds = time.perf_counter() - t0
    res.to_npz(out)
    png = None if args.no_png else diagram_png(res, out[:-4] + ".png", coordinate=coordinate)
    periods, n_of = np.unique(res.period, return_counts=True)
    summary = {"model": args.model, "npz": out, "png": png, "points": int(res.values.size),
               "grid": [name], "periods": res.periods, "transient": res.transient,
               "gains": None if k is None else k.tolist(), "mu": mu,
               "control_after": res.control_after, "coordinate": coordinate,
               "seconds": seconds,
               "detected_periods": {str(int(p)): int(c) for p, c in zip(periods, n_of)},
               "failed": int(np.sum(res.period == -1))}
    if delay:
        summary["actuation_delay"] = delay
    if args.json:
        return summary
    hist = ", ".join(f"{'failed' if p == '-1' else 'none' if p == '0' else 'period ' + p}: {c}"
                     for p, c in summary["detected_periods"].items())
    lines = [
        f"sweep of {res.values.size} points of {name} for {args.model}, {res.periods} periods "
        f"each, last {res.periods - res.transient} kept"
        + ("" if k is None else f", control on from sample {res.control_after} ({how}"
           + (f", actuation delay {delay:.6g})" if delay else ")")),
        f"  time              : {seconds:.3g} s",
        f"  detected on Pi2   : {hist}",
        f"  written           : {out}" + (f"\n                      {png}" if png else ""),
    ]
    if summary["failed"]:
        first = next(e for e in res.errors if e)
        lines.append(f"  failed points     : {summary['failed']} (first: {first})")
    return "\n".join(lines)



def cmd_figures(args):
    """figures --model FILE [--out DIR] [--mu MU] [--delay D] [--quick]
    (docs/ndof_commands.md)."""
    import sys
    from dataclasses import replace

    from grazing_control.studies.figures.near_grazing import DEFAULT, QUICK, make_ndof_figures

    model = load(args.model)
    delay = delay_of(args, model)
    settings = replace(QUICK if args.quick else DEFAULT, mu=args.mu)
    out = args.out if args.out != "out/figures" else "out/figures_ndof"
    log = None if args.json else (lambda line: print(line, file=sys.stderr))
    numbers = make_ndof_figures(model, out, settings, model_file=args.model,
                                workers=args.workers, log=log, delay=delay)
    if args.json:
        return nulls(numbers)
    m = numbers["multipliers"]
    lines = [f"n-DOF figures of {args.model} in {out}: ndof_diagram.png, ndof_multipliers.png, "
             "ndof_scene.png, ndof_figures.json",
             f"  mu = {numbers['mu']:.6g} ({numbers['mu_chosen']})"
             + (f", actuation delay {delay:.6g}" if delay else "")]
    lines += [f"  {label:16s}: {_scaling_text(entry)}" for label, entry in m.items()
              if isinstance(entry, dict)]
    sc = numbers["scene"]
    dist = sc["final_distance"]
    lines.append(f"  scene at Delta d = {sc['delta_d']:g}: final distance to the controlled "
                 "orbit " + ("n/a (" + sc["orbit_error"][:120] + ")" if dist is None
                             else f"{dist:.3e}" + (" (captured)" if dist < 1e-8 else
                                                   " (not captured: the controller acts "
                                                   "locally, near the grazing orbit)")))
    return "\n".join(lines)


def _scaling_text(entry) -> str:
    """One curve of the multiplier figure: its fitted exponent, or why it is not drawn."""
    if "error" in entry:
        return f"not drawn ({entry['error']})"
    slope = entry["fitted_exponent"]
    return (f"fitted exponent {'n/a' if slope is None else f'{slope:.4f}'} over "
            f"{entry['fit_points']} points; smallest |Delta d| reached "
            f"{entry['smallest_delta_d_found']}")

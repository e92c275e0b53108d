"""``grazing sweep``: a parameter grid simulated on all local cores or on a Dask cluster.

    grazing sweep --grid delta_d=-2e-5:0:200 --periods 2000 --transient 1000
    grazing sweep --grid delta_d=-1e-3:-1e-7:100:log --grid c2=-1.5:-0.5:3 --control-after 0
    grazing sweep --grid delta_d=-2e-5:0:200 --scheduler tcp://127.0.0.1:8786

Writes the npz of :meth:`SweepResult.to_npz` and a PNG of the diagram next to it; a
progress bar on a terminal, nothing but one JSON object with --json.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from grazing_control.oscillator.params import ParameterError
from grazing_control.support.arguments import non_empty_path

__all__ = ["add_sweep_command", "parse_grid", "cmd_sweep"]


def parse_grid(text):
    """``NAME=START:STOP:N[:log]`` (N values, linear or geometric) or ``NAME=V1,V2,...``."""
    name, sep, spec = text.partition("=")
    name = name.strip().replace("-", "_")
    if not sep or not name or not spec:
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid: expected NAME=START:STOP:N[:log] or NAME=V1,V2,...")
    try:
        if ":" in spec:
            parts = spec.split(":")
            if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] != "log"):
                raise ValueError
            lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n < 1 or not (math.isfinite(lo) and math.isfinite(hi)):
                raise ValueError
            if len(parts) == 4:
                if lo == 0 or hi == 0 or (lo < 0) != (hi < 0):
                    raise argparse.ArgumentTypeError(
                        f"{text!r} is invalid: a :log range needs START and STOP of one sign, "
                        "nonzero")
                values = np.geomspace(lo, hi, n)
            else:
                values = np.linspace(lo, hi, n)
        else:
            values = np.array([float(v) for v in spec.split(",")])
            if not np.all(np.isfinite(values)):
                raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid: expected NAME=START:STOP:N[:log] (N >= 1) or NAME=V1,V2,... "
            "with finite numbers") from None
    return name, values


def _start(text):
    try:
        dx, dv = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid: expected DX,DV (deviation from X** on Pi2)") from None
    if not (math.isfinite(dx) and math.isfinite(dv)):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected finite DX,DV")
    return dx, dv


def _scheduler(text):
    from .run import check_scheduler
    try:
        return check_scheduler(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("scheduler=", "", 1)) from None


def add_sweep_command(sub, common, finite, count):
    """Register ``grazing sweep`` on the ``grazing`` subparsers (see grazing_control.cli)."""
    s = sub.add_parser("sweep", help="bifurcation diagram: simulate a parameter grid on Pi2")
    common(s)
    s.add_argument("--grid", type=parse_grid, action="append", required=True,
                   metavar="NAME=START:STOP:N[:log]",
                   help="a grid axis (repeatable; first = x axis of the PNG): delta_d, zeta, r, "
                        "omega, tau0, pi2_offset, c1 or c2; or NAME=V1,V2,...")
    s.add_argument("--periods", type=count, default=2000, help="periods per point (default 2000)")
    s.add_argument("--transient", type=count, help="periods dropped first (default periods / 2)")
    s.add_argument("--start", type=_start, action="append", metavar="DX,DV",
                   help="start on Pi2 as (x - x**, v - v**) (repeatable; default 0,0); "
                        "write --start=-1e-4,0 for a negative DX")
    s.add_argument("--c1", type=finite, help="gain c1 (default with --c2: Eq. 38)")
    s.add_argument("--c2", type=finite, help="gain c2 (turns the controller on)")
    s.add_argument("--control-after", type=count,
                   help="controller on from this sample (default 0 when there are gains)")
    s.add_argument("--workers", type=count, help="local processes (default: all cores)")
    s.add_argument("--scheduler", metavar="tcp://HOST:PORT", type=_scheduler,
                   help="run on this Dask scheduler instead of local processes")
    s.add_argument("--engine", choices=("auto", "kernel", "python"), default="auto",
                   help="compiled kernel (auto: if numba imports) or the pure-Python core")
    s.add_argument("--period-tol", type=finite, default=1e-10,
                   help="tolerance of the period detection on Pi2 (default 1e-10)")
    s.add_argument("--max-period", type=count, help="longest period detected (default 64)")
    s.add_argument("--out", default="out/sweep/sweep.npz", type=non_empty_path,
                   help="npz file (default out/sweep/sweep.npz), or an existing folder "
                        "(then FOLDER/sweep.npz); the PNG goes next to it. Its arrays, one "
                        "row per point (grid values x start, np.ndindex order): axis_NAME "
                        "(each grid axis), point_NAME (each point's value of NAME), c1, c2 "
                        "(the gains, nan uncontrolled), starts (the start deviation), pi2 "
                        "(the kept Pi2 samples x, v), pi2_deviation (pi2 - X**), reference "
                        "(X** of the point), impacts_per_period (per kept period), period "
                        "(detected on Pi2: 0 none, -1 failed), errors ('' where the point "
                        "ran), lyapunov (with --lyapunov), meta (JSON: names, shape, "
                        "periods, transient, control_after, base, engine, delay) "
                        "(docs/sweeps.md)")
    s.add_argument("--component", choices=("x", "v"), default="x",
                   help="Pi2 coordinate drawn in the PNG (default x)")
    s.add_argument("--no-png", action="store_true", help="write only the npz")
    s.add_argument("--lyapunov", action="store_true",
                   help="also the Lyapunov exponents of each point's kept orbit, per forcing "
                        "period (not per unit time), largest first: npz array 'lyapunov' of "
                        "shape (points, 2), nan for a failed point, -inf where the map is "
                        "singular (a sticking impact; c2 = -1 makes the second one -inf) "
                        "(docs/theory_lyapunov.md); a "
                        "lambda_max panel; with two grid axes an atlas PNG of lambda_max and "
                        "the detected period")
    s.set_defaults(func=cmd_sweep)
    return s


def cmd_sweep(args):
    """Run the sweep and write its files; returns the summary (dict with --json)."""
    from grazing_control.oscillator.control import Gains
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.oscillator.params import OscillatorParams
    from .plot import atlas, diagram
    from .run import sweep

    grid = {}
    for name, values in args.grid:
        if name in grid:
            raise ParameterError(f"--grid {name} is given twice: give each name once")
        grid[name] = values
    p = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, pi2_offset=args.pi2_offset)
    gains = None
    delay = float(getattr(args, "delay", 0.0) or 0.0)
    if args.c2 is not None:
        c1 = degenerate_c1(p, args.c2, delay) if args.c1 is None else args.c1
        gains = Gains(c1, args.c2, delay)
    elif args.c1 is not None and "c2" not in grid:
        raise ParameterError("c1 given without c2: give both, or c2 alone (c1 from Eq. 38)")
    if delay and gains is None:
        raise ParameterError("--delay needs the gains: give --c2 (and optionally --c1)")
    if args.control_after is not None and gains is None and not ({"c1", "c2"} & set(grid)):
        raise ParameterError("--control-after needs the gains: give --c2 (or a c2 grid)")
    if gains is None and args.c1 is not None:  # c2 gridded, c1 fixed
        grid.setdefault("c1", np.array([args.c1]))
    transient = args.periods // 2 if args.transient is None else args.transient
    out = os.path.abspath(args.out)
    if os.path.isdir(out) or args.out.endswith(os.sep):   # a folder: the file goes inside
        out = os.path.join(out, "sweep.npz")
    if not out.endswith(".npz"):
        out += ".npz"
    os.makedirs(os.path.dirname(out), exist_ok=True)
    t0 = time.perf_counter()
    res = sweep(p, grid, periods=args.periods, transient=transient,
                deviation=np.array(args.start) if args.start else (0.0, 0.0), gains=gains,
                control_after=args.control_after, workers=args.workers,
                scheduler=args.scheduler, engine=args.engine, period_tol=args.period_tol,
                max_period=args.max_period, progress=not args.json and sys.stderr.isatty(),
                lyapunov=args.lyapunov)
    seconds = time.perf_counter() - t0
    res.to_npz(out)
    png = atlas_png = None
    if not args.no_png:
        png = diagram(res, out[:-4] + ".png", component=args.component)
        if len(res.names) == 2:
            atlas_png = atlas(res, out[:-4] + "_atlas.png")
    periods, n_of = np.unique(res.period, return_counts=True)
    summary = {
        "npz": out, "png": png, "points": res.n_points, "grid": list(res.names),
        "shape": list(res.shape), "periods": res.periods, "transient": res.transient,
        "engine": res.engine, "seconds": seconds,
        "periods_per_second": res.n_points * res.periods / seconds if seconds > 0 else None,
        "detected_periods": {str(int(k)): int(v) for k, v in zip(periods, n_of)},
        "failed": int(np.sum(res.period == -1)),
    }
    if atlas_png:
        summary["atlas_png"] = atlas_png
    if res.lyapunov is not None:
        lmax = res.lyapunov[:, 0]
        ok = np.isfinite(lmax)
        summary["lyapunov_max"] = {
            "positive": int(np.sum(lmax[ok] > 0)), "min": float(lmax[ok].min()) if ok.any() else None,
            "max": float(lmax[ok].max()) if ok.any() else None,
            "minus_infinity": int(np.sum(lmax == -np.inf))}
    if args.json:
        return summary
    hist = ", ".join(f"{'failed' if k == '-1' else 'none' if k == '0' else 'period ' + k}: {v}"
                     for k, v in summary["detected_periods"].items())
    where = args.scheduler or f"{args.workers or 'all'} local worker(s)"
    lines = [
        f"sweep of {res.n_points} points ({' x '.join(res.names)}"
        f"{' x starts' if res.shape[-1] > 1 else ''}), {res.periods} periods each, "
        f"last {res.periods - res.transient} kept",
        f"  engine            : {res.engine} on {where}",
        f"  time              : {seconds:.3g} s ({summary['periods_per_second']:.3g} periods/s)",
        f"  detected on Pi2   : {hist}",
        f"  written           : {out}" + (f"\n                      {png}" if png else ""),
    ]
    if res.lyapunov is not None:
        ly = summary["lyapunov_max"]
        lines.insert(4, f"  lambda_max        : > 0 at {ly['positive']} of {res.n_points} points"
                        + (f", range {ly['min']:.4g} .. {ly['max']:.4g} per period"
                           if ly["min"] is not None else ""))
    if atlas_png:
        lines.append(f"                      {atlas_png}")
    if summary["failed"]:
        first = next(e for e in res.errors if e)
        lines.append(f"  failed points     : {summary['failed']} (first: {first})")
    return "\n".join(lines)

"""``grazing basins``: which attractor each start on Pi2 reaches, locally or on Dask.

    grazing basins --delta-d -5e-6                       # uncontrolled, default box
    grazing basins --delta-d -5e-6 --c2 -1               # controlled (c1 from Eq. 38)
    grazing basins --delta-d -1.25e-5 --dx=-1e-2:1e-2 --dv=-1e-2:1e-2 --nx 201 --nv 201
    grazing basins --delta-d -5e-6 --scheduler tcp://127.0.0.1:8786

Writes FILE.npz (every grid and the attractors, :meth:`BasinResult.to_npz`), FILE.json
(the summary: fraction of the starts per attractor, the cycles, the colours) and the
picture FILE.png + FILE.svg; prints a report, or the summary as one JSON object with
--json. Bad input: one line ``grazing: error: ...`` and status 2, nothing written.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

from grazing_control.support.arguments import integer_at_least, non_empty_path

__all__ = ["add_basins_parser", "cmd_basins", "parse_range"]


def parse_range(text):
    """``LO:HI``, two finite numbers with LO < HI."""
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid: expected LO:HI (write --dx=-1e-3:1e-3 for a negative LO)") \
            from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected finite LO < HI")
    return lo, hi


def _scheduler(text):
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.studies.sweeps.run import check_scheduler

    try:
        return check_scheduler(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("scheduler=", "", 1)) from None


def add_basins_parser(sub):
    """Register ``grazing basins`` on the ``grazing`` subparsers."""
    from .common import add_common, add_gains, count, finite

    s = sub.add_parser("basins", help="basins of attraction: the attractor of each start "
                                      "of a grid on Pi2")
    add_common(s)
    s.add_argument("--delta-d", type=finite,
                   help="Delta d = d - d* (required, unless --params gives it)")
    s.add_argument("--dx", type=parse_range, metavar="LO:HI",
                   help="starts' x - x** on Pi2 (default: a square around X** of half-width "
                        "4 x the 1/1 orbit's distance from it at -|Delta d|); write "
                        "--dx=-1e-3:1e-3")
    s.add_argument("--dv", type=parse_range, metavar="LO:HI",
                   help="starts' v - v** on Pi2 (default as --dx)")
    s.add_argument("--nx", type=integer_at_least(1), default=101,
                   help="grid points along x (default 101)")
    s.add_argument("--nv", type=integer_at_least(1), default=101,
                   help="grid points along v (default 101)")
    s.add_argument("--transient", type=count, default=2000,
                   help="periods run before the record (default 2000)")
    s.add_argument("--max-period", type=integer_at_least(1), default=64,
                   help="longest period detected; the record is twice it (default 64)")
    s.add_argument("--period-tol", type=finite, default=1e-10,
                   help="tolerance of the period detection on Pi2 (default 1e-10)")
    s.add_argument("--match-tol", type=finite,
                   help="largest distance of two cycles of one attractor (default 1e-3 x the "
                        "1/1 orbit's distance from X** at -|Delta d|)")
    add_gains(s)
    s.add_argument("--control-after", type=count,
                   help="controller on from this sample (default 0 with --c2)")
    s.add_argument("--workers", type=integer_at_least(1),
                   help="local processes (default: all cores)")
    s.add_argument("--scheduler", metavar="tcp://HOST:PORT", type=_scheduler,
                   help="run on this Dask scheduler instead of local processes")
    s.add_argument("--engine", choices=("auto", "kernel", "python"), default="auto",
                   help="compiled kernel (auto: if numba imports) or the pure-Python core")
    s.add_argument("--out", default="out/basins/basins", type=non_empty_path,
                   help="file stem (default out/basins/basins: .npz, .json, .png, .svg), or "
                        "an existing folder (then FOLDER/basins.*). The npz arrays: xs, vs "
                        "(the starts' deviations from X** on Pi2), the (nv, nx) grids "
                        "attractor (index into the attractors' table), period (detected: 0 "
                        "none, -1 failed), mean_impacts (impacts per period over the record), "
                        "final (last sample, deviation), errors; the attractors' table "
                        "attractor_label, attractor_kind, attractor_period, "
                        "attractor_impacts, attractor_starts, attractor_slow, "
                        "attractor_points_J (attractor J's cycle, or the record of its "
                        "representative start); meta (the JSON summary) (docs/basins.md)")
    s.add_argument("--no-png", action="store_true", help="write only the npz and the JSON")
    s.set_defaults(func=cmd_basins)
    return s


def _stem(out):
    stem = os.path.abspath(out)
    if os.path.isdir(stem) or out.endswith(os.sep):
        stem = os.path.join(stem, "basins")
    for ext in (".npz", ".json", ".png", ".svg"):
        if stem.endswith(ext):
            stem = stem[:-len(ext)]
    return stem


def cmd_basins(args):
    """Run the grid and write its files; returns the report (the summary with --json)."""
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.studies.basins import basins, picture
    from .common import gains_of, params_of

    if args.delta_d is None:
        raise ParameterError("--delta-d is required (or a --params FILE with delta_d)")
    p = params_of(args, args.delta_d)
    gains = gains_of(args, p)
    if args.control_after is not None and gains is None:
        raise ParameterError("--control-after needs the gains: give --c2 (and optionally --c1)")
    stem = _stem(args.out)
    t0 = time.perf_counter()
    res = basins(p, dx_range=args.dx, dv_range=args.dv, nx=args.nx, nv=args.nv, gains=gains,
                 control_after=args.control_after, transient=args.transient,
                 max_period=args.max_period, period_tol=args.period_tol,
                 match_tol=args.match_tol, workers=args.workers, scheduler=args.scheduler,
                 engine=args.engine, progress=not args.json and sys.stderr.isatty())
    seconds = time.perf_counter() - t0
    os.makedirs(os.path.dirname(stem), exist_ok=True)
    res.to_npz(stem + ".npz")
    summary = res.summary()
    summary.update(npz=stem + ".npz", json=stem + ".json", png=None, svg=None,
                   seconds=seconds)
    if not args.no_png:
        folder, name = os.path.split(stem)
        png, svg = picture(res, folder, name)
        summary.update(png=os.path.join(folder, png), svg=os.path.join(folder, svg))
    with open(stem + ".json", "w") as f:
        json.dump(summary, f, indent=1, sort_keys=True)
        f.write("\n")
    if args.json:
        return summary
    where = args.scheduler or f"{args.workers or 'all'} local worker(s)"
    grid = summary["grid"]
    lines = [
        f"basins at Delta d = {p.delta_d:g}, "
        + ("uncontrolled" if gains is None else
           f"c1 = {gains.c1:.8g}, c2 = {gains.c2:.8g}"
           + (f", delay {gains.delay:g}" if gains.delay else "")
           + f", on from sample {res.control_after}"),
        f"  starts            : {grid['nx']} x {grid['nv']} in x - x** in "
        f"[{grid['dx_range'][0]:.4g}, {grid['dx_range'][1]:.4g}], v - v** in "
        f"[{grid['dv_range'][0]:.4g}, {grid['dv_range'][1]:.4g}]",
        f"  run               : {res.transient} periods, then {2 * res.max_period} recorded; "
        f"{res.engine} on {where}, {seconds:.3g} s",
        "  attractors        : (label: fraction of starts, cycle's first point on Pi2)",
    ]
    for a in summary["attractors"]:
        at = f", at ({a['cycle_pi2'][0][0]:.8g}, {a['cycle_pi2'][0][1]:.8g})" \
            if a["kind"] == "periodic" else ""
        error = f" (first: {a['first_error']})" if a["kind"] == "failed" else ""
        slow = f", {a['slow_starts']} still converging" if a["slow_starts"] else ""
        lines.append(f"    {a['label']:10s}: {100 * a['fraction']:6.2f} % "
                     f"({a['starts']} starts{slow}){at}{error}")
    lines.append(f"  written           : {stem}.npz, {stem}.json"
                 + ("" if args.no_png else f", {stem}.png, {stem}.svg"))
    return "\n".join(lines)

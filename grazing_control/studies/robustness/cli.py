"""``grazing robustness delay|faults|noise|model``: the robustness studies and their charts.

Registered from :func:`grazing_control.cli.build_parser`. Both write their charts (PNG)
and numbers (JSON) to ``--out`` (default out/robustness) and print a summary (or, with
--json, one JSON object). docs/theory_delay.md section 6 and docs/robustness.md give the
exact commands that made the committed charts.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

from grazing_control.support.arguments import integer_at_least, negative, positive

__all__ = ["add_robustness_parser"]


def _pair(text):
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected DELAY:C2, e.g. 2.0:0.5") from None
    if not (math.isfinite(a) and math.isfinite(b) and a >= 0.0):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected DELAY:C2 with a finite delay >= 0")
    return a, b


def _out_dir(path):
    if not path:
        raise ValueError("out='' is invalid: give a folder name")
    os.makedirs(path, exist_ok=True)
    return path


def cmd_delay(args):
    from grazing_control.dynamics.design.gains import admissible_c2, max_design_delay
    from grazing_control.oscillator.params import OscillatorParams
    from grazing_control.dynamics.maps.perturbation import perturbation_multipliers
    from grazing_control.oscillator.control import Gains
    from .charts import plot_delay_curves, plot_stability_maps
    from .delay import design_gains, multiplier_curve, stability_interval, stability_map

    lo, hi = args.c2_range
    if not lo < hi:
        from grazing_control.oscillator.params import ParameterError
        raise ParameterError(f"c2_range=({lo!r}, {hi!r}) is invalid: expected LOW < HIGH")
    base = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, pi2_offset=args.pi2_offset)
    out = _out_dir(args.out)
    t0 = time.perf_counter()
    top = math.nextafter(max_design_delay(base), 0.0)
    delays = np.linspace(0.0, top, args.points)
    designs = args.design or [(0.0, -1.0), (2.0, 0.5)]
    curves, summary = [], []
    for da, c2 in designs:
        g = design_gains(base, c2, da)
        c = {"design_delay": da, "c2": c2, "c1": g.c1, "delays": delays.tolist(),
             "by_delta_d": {}, "perturbation": {}, "intervals": {}}
        for dd in args.delta_d:
            q = base.with_(delta_d=dd)
            vals = multiplier_curve(q, g, delays)
            c["by_delta_d"][dd] = vals.tolist()
            c["perturbation"][dd] = [float(np.max(np.abs(perturbation_multipliers(q, Gains(g.c1, g.c2, d)))))
                                     for d in delays]
            iv = stability_interval(q, g, da, hi=top, n=args.points)
            c["intervals"][dd] = iv
            summary.append({"design_delay": da, "c2": c2, "c1": g.c1, "delta_d": dd,
                            "stable_delays": None if iv is None else [iv[0], iv[1]],
                            "ends": None if iv is None else list(iv[2])})
        curves.append(c)
    plot_delay_curves(curves, os.path.join(out, "delay_curves.png"))
    maps = {}
    c2s = np.linspace(args.c2_range[0], args.c2_range[1], args.map_points)
    mdelays = np.linspace(0.0, top, args.map_points)
    for design in ("delayed", "undelayed"):
        for dd in args.delta_d:
            maps[(design, dd)] = stability_map(base.with_(delta_d=dd), design, c2s, mdelays,
                                               workers=args.workers)
    bounds = {float(d): admissible_c2(base, args.c2_range[0], args.c2_range[1], 201, delay=float(d))
              for d in mdelays[::2]}
    plot_stability_maps(maps, os.path.join(out, "delay_stability_map.png"), bounds)
    cost = time.perf_counter() - t0
    record = {"model": {"zeta": base.zeta, "r": base.r, "omega": base.omega,
                        "pi2_offset": base.pi2_offset, "max_design_delay": max_design_delay(base)},
              "stability_intervals": summary, "seconds": cost,
              "maps": {f"{d}:{dd}": {"c2": m.c2s.tolist(), "delays": m.delays.tolist(),
                                     "max_abs_multiplier": [[None if not math.isfinite(v) else v for v in row]
                                                            for row in m.values.tolist()]}
                       for (d, dd), m in maps.items()},
              "files": [os.path.join(out, "delay_curves.png"), os.path.join(out, "delay_stability_map.png")]}
    with open(os.path.join(out, "delay.json"), "w") as fh:
        json.dump(record, fh)
    if args.json:
        return {k: v for k, v in record.items() if k != "maps"}
    lines = [f"actuation-delay robustness (design range 0 <= delta < T - s = {max_design_delay(base):.6g})",
             f"{'delta_a':>8} {'c2':>6} {'Delta d':>9}  stable actual delays"]
    for s in summary:
        iv = "none" if s["stable_delays"] is None else \
            f"[{s['stable_delays'][0]:.6g}, {s['stable_delays'][1]:.6g}] ({s['ends'][0]}, {s['ends'][1]})"
        lines.append(f"{s['design_delay']:8.4g} {s['c2']:6.3g} {s['delta_d']:9.1e}  {iv}")
    lines.append(f"charts and numbers in {out} ({cost:.1f} s)")
    return "\n".join(lines)


def cmd_faults(args):
    from concurrent.futures import ProcessPoolExecutor

    from grazing_control.oscillator.params import OscillatorParams
    from .charts import plot_fault_sweep
    from .delay import design_gains
    from .faults import LEVELS, fault_sweep
    from grazing_control.oscillator.control import Gains

    base = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, pi2_offset=args.pi2_offset)
    out = _out_dir(args.out)
    t0 = time.perf_counter()
    configs = args.design or [(0.0, -1.0), (2.0, 0.5)]
    results = []
    ex = ProcessPoolExecutor(max_workers=args.workers) if args.workers > 1 else None
    try:
        for da, c2 in configs:
            g = design_gains(base, c2, da)
            g = Gains(g.c1, g.c2, da)
            for dd in args.delta_d:
                for kind in args.kinds:
                    results.append(fault_sweep(base, g, dd, kind, LEVELS[kind], args.seeds,
                                               horizon=args.horizon, tail=args.tail,
                                               threshold=args.threshold, hold=args.hold, executor=ex))
    finally:
        if ex is not None:
            ex.shutdown()
    cost = time.perf_counter() - t0
    plot_fault_sweep(results, os.path.join(out, "faults.png"))
    record = {"results": results, "seconds": cost, "files": [os.path.join(out, "faults.png")]}
    with open(os.path.join(out, "faults.json"), "w") as fh:
        json.dump(record, fh)
    if args.json:
        return record
    lines = [f"capture of the controlled 1/1 orbit within {args.horizon} samples "
             f"(|z - z*| <= {args.threshold:g} for {args.hold} samples), {args.seeds} seeds"]
    for r in results:
        cells = " ".join(f"{row['level']:g}:{row['capture_probability']:.2f}" for row in r["rows"])
        lines.append(f"  Δd={r['delta_d']:.0e} c2={r['c2']:g} δ={r['actuation_delay']:g} {r['kind']:6s} {cells}")
    lines.append(f"charts and numbers in {out} ({cost:.1f} s)")
    return "\n".join(lines)


def cmd_noise(args):
    from grazing_control.oscillator.params import OscillatorParams
    from .charts import plot_noise_gain
    from .noise import noise_gain_curves

    base = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, pi2_offset=args.pi2_offset)
    out = _out_dir(args.out)
    t0 = time.perf_counter()
    record = noise_gain_curves(base, args.delta_d, args.delay, args.points)
    png = os.path.join(out, "noise_gain.png" if not args.delay else f"noise_gain_delay{args.delay:g}.png")
    plot_noise_gain(record, png)
    record.update(seconds=time.perf_counter() - t0, files=[png])
    with open(os.path.splitext(png)[0] + ".json", "w") as fh:
        json.dump(record, fh)
    if args.json:
        return record
    lines = [f"noise gain (std of the Pi2 position per unit measurement noise) over the admissible c2"
             f"{f', delay {args.delay:g}' if args.delay else ''}",
             f"{'Delta d':>9} {'least gain':>11} {'at c2':>10} {'c1':>10} {'study c2=-1':>12}"]
    for c in record["curves"]:
        b = c["best"]
        study = "-" if c["study"] is None else f"{c['study']:.4g}"
        lines.append(f"{c['delta_d']:9.1e} {b['gain']:11.4g} {b['c2']:10.5f} {b['c1']:10.5f} {study:>12}")
    lines.append(f"chart and numbers in {out} ({record['seconds']:.1f} s)")
    return "\n".join(lines)


def cmd_model(args):
    from grazing_control.dynamics.design.tuning import optimize_noise
    from grazing_control.oscillator.params import OscillatorParams
    from .charts import plot_model_bands
    from .model import model_error_bands

    if getattr(args, "model", None) is not None:
        return _cmd_model_ndof(args)
    if args.mu or args.parameter:
        from grazing_control.oscillator.params import ParameterError
        raise ParameterError("--mu and --parameter go with --model FILE (an n-DOF design); "
                             "the 1-DOF study takes --c2")
    base = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, pi2_offset=args.pi2_offset)
    out = _out_dir(args.out)
    t0 = time.perf_counter()
    if args.c2:
        designs = [(f"c2 = {c:g}", c) for c in args.c2]
    else:
        best = optimize_noise(base.with_(delta_d=-5e-6))
        designs = [("study", -1.0), ("least noise at -5e-6", best.c2)]
    record = model_error_bands(base, designs)
    png = os.path.join(out, "model_error_bands.png")
    plot_model_bands(record, png)
    record.update(seconds=time.perf_counter() - t0, files=[png])
    with open(os.path.join(out, "model_error_bands.json"), "w") as fh:
        json.dump(record, fh)
    if args.json:
        return record
    lines = ["band of Delta d next to grazing where the controlled orbit fails (gains designed on "
             "the nominal model, plant off by a relative error e)",
             f"{'design':>22} {'param':>6} {'error':>9} {'band end':>11} {'series':>11} {'end/e^2':>10}"]
    for d in record["designs"]:
        for r in d["bands"]:
            end = "none" if r["end"] == 0.0 else f"{r['end']:.4g}"
            lines.append(f"{d['label']:>22} {r['parameter']:>6} {r['error']:+9.2g} {end:>11} "
                         f"{r['predicted']:11.4g} {r['k']:10.4g}")
    lines.append(f"chart and numbers in {out} ({record['seconds']:.1f} s)")
    return "\n".join(lines)


def _cmd_model_ndof(args):
    """``robustness model --model FILE --mu MU [--delay D] [--parameter NAME ...]``: the
    bands of an n-DOF design (docs/robustness.md section 4, "n > 1")."""
    from grazing_control.oscillator.ndof import load_model
    from grazing_control.oscillator.params import ParameterError
    from .charts import plot_model_bands
    from .model import NDOF_ERRORS, model_error_bands

    if args.c2:
        raise ParameterError("--c2 is a 1-DOF design: with --model give --mu MU (the family "
                             "member w^T N = mu w^T, docs/theory_ndof.md)")
    if not args.mu:
        raise ParameterError("--model needs --mu MU (repeatable): the design family's member "
                             "(see grazing design --model FILE for the admissible mu)")
    model = load_model(args.model)
    errors = None
    if args.parameter:
        from grazing_control.dynamics.design.mismatch import mismatched_model

        errors = {}
        for name in args.parameter:
            mismatched_model(model, name, 0.0)      # refuses a bad name, naming it
            errors[name] = NDOF_ERRORS.get(name[:1] if name[1:2] == "[" else name, NDOF_ERRORS["M"])
    out = _out_dir(args.out)
    t0 = time.perf_counter()
    record = model_error_bands(model, [(f"mu = {mu:g}", mu) for mu in args.mu], errors,
                               delay=args.delay)
    png = os.path.join(out, "model_error_bands.png")
    plot_model_bands(record, png)
    record.update(model=str(args.model), delta_d=model.delta_d, delay=args.delay,
                  seconds=time.perf_counter() - t0, files=[png])
    with open(os.path.join(out, "model_error_bands.json"), "w") as fh:
        json.dump(record, fh)
    if args.json:
        return record
    lines = [f"band of Delta d next to grazing where the controlled orbit fails ({args.model}, "
             f"gains k(mu) designed on the nominal model, plant off by a relative error e; "
             f"tolerated: the error the design tolerates at delta_d = {model.delta_d:g})",
             f"{'design':>12} {'param':>8} {'error':>9} {'band end':>11} {'end/e^2':>10} {'tolerated':>10}"]
    for d in record["designs"]:
        for r in d["bands"]:
            end = "none" if r["end"] == 0.0 else f"{r['end']:.4g}"
            tol = "-" if r["tolerated"] is None else f"{r['tolerated']:.3g}"
            lines.append(f"{d['label']:>12} {r['parameter']:>8} {r['error']:+9.2g} {end:>11} "
                         f"{r['k']:10.4g} {tol:>10}")
    lines.append(f"chart and numbers in {out} ({record['seconds']:.1f} s)")
    return "\n".join(lines)


_count = integer_at_least(1)


def add_robustness_parser(sub, common, finite):
    """Register ``grazing robustness delay|faults|noise|model`` on the subparsers ``sub``."""
    s = sub.add_parser("robustness", help="robustness to the actuation delay and to loss/noise/jitter")
    rsub = s.add_subparsers(dest="study", required=True)

    d = rsub.add_parser("delay", help="max multiplier vs the actual delay; stability maps over (c2, delay)")
    common(d)
    d.add_argument("--design", type=_pair, action="append",
                   help="DELAY:C2 of a design (repeatable; default 0:-1 and 2:0.5)")
    d.add_argument("--delta-d", type=negative, nargs="+", default=[-1e-4, -1e-5, -1e-6],
                   help="wall offsets Delta d < 0 (default -1e-4 -1e-5 -1e-6)")
    d.add_argument("--points", type=_count, default=141, help="actual delays on the curves (141)")
    d.add_argument("--map-points", type=_count, default=61, help="grid points per axis of the maps (61)")
    d.add_argument("--c2-range", type=finite, nargs=2, default=[-3.0, 2.0], help="c2 axis of the maps")
    d.add_argument("--workers", type=_count, default=2, help="processes (default 2)")
    d.add_argument("--out", default="out/robustness", help="folder for charts and JSON")
    d.set_defaults(func=cmd_delay)

    f = rsub.add_parser("faults", help="capture probability and spread vs loss, noise, jitter (core)")
    common(f)
    f.add_argument("--design", type=_pair, action="append",
                   help="DELAY:C2 of a design (repeatable; default 0:-1 and 2:0.5)")
    f.add_argument("--delta-d", type=negative, nargs="+", default=[-5e-6, -9e-6],
                   help="wall offsets (default the study's scenes -5e-6 -9e-6)")
    f.add_argument("--kinds", nargs="+", choices=("loss", "noise", "jitter"),
                   default=["loss", "noise", "jitter"])
    f.add_argument("--seeds", type=_count, default=48, help="runs per level (default 48)")
    f.add_argument("--horizon", type=_count, default=400, help="N: capture within N samples (400)")
    f.add_argument("--tail", type=_count, default=200, help="samples of the stationary spread (200)")
    f.add_argument("--threshold", type=positive, default=1e-4, help="capture distance (1e-4)")
    f.add_argument("--hold", type=_count, default=20, help="M consecutive samples (20)")
    f.add_argument("--workers", type=_count, default=2, help="processes (default 2)")
    f.add_argument("--out", default="out/robustness", help="folder for charts and JSON")
    f.set_defaults(func=cmd_faults)

    n = rsub.add_parser("noise", help="noise gain over the admissible c2 at several Delta d (chart)")
    common(n)
    n.add_argument("--delta-d", type=finite, nargs="+", default=[-1e-4, -1e-5, -5e-6, -1e-6, -1e-7],
                   help="wall offsets Delta d < 0 (default -1e-4 -1e-5 -5e-6 -1e-6 -1e-7)")
    n.add_argument("--delay", type=finite, default=0.0, help="actuation delay of the design (0)")
    n.add_argument("--points", type=_count, default=201, help="c2 per admissible interval (201)")
    n.add_argument("--out", default="out/robustness", help="folder for the chart and JSON")
    n.set_defaults(func=cmd_noise)

    m = rsub.add_parser("model", help="band of Delta d where control fails vs model error (chart)")
    common(m)
    m.add_argument("--c2", type=finite, action="append",
                   help="c2 of a design on the nominal model (repeatable; default the study's -1 "
                        "and the least-noise c2 at Delta d = -5e-6)")
    m.add_argument("--model", metavar="FILE",
                   help="an n-DOF model file (docs/ndof_model.md): the bands of its design "
                        "k(mu) (give --mu) over the exact n-DOF map, errors in M, C, K, the "
                        "masses M[i,i], r and omega")
    m.add_argument("--mu", type=finite, action="append",
                   help="with --model: the design family's member w^T N = mu w^T (repeatable)")
    m.add_argument("--delay", type=finite, default=0.0,
                   help="with --model: the kick's delay after Pi2 of the design (0)")
    m.add_argument("--parameter", action="append", metavar="NAME",
                   help="with --model: the parameters to put an error on (repeatable; M, C, K, "
                        "r, omega, or an entry M[i,j], C[i,j], K[i,j]; default M, C, K, r, omega "
                        "and every mass M[i,i])")
    m.add_argument("--out", default="out/robustness", help="folder for the chart and JSON")
    m.set_defaults(func=cmd_model)

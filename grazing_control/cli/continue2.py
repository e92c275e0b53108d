"""`grazing continue2`: the 1/1 orbit's PD and fold curves in two parameters (issue 18 s1).

The plane is (mu, Delta d), mu = --parameter (omega, zeta, r, or the gain c2 with c1
held); the algorithms are :mod:`grazing_control.dynamics.orbits.two_parameter`, the panels and
data files :mod:`grazing_control.studies.figures.two_parameter`
(docs/theory_two_parameter.md).
"""

from __future__ import annotations

from grazing_control.support.arguments import finite, integer_at_least, non_empty_path

__all__ = ["add_parser", "run"]

#: Default range of each parameter: omega covers the degenerate points m = 1..4.
DEFAULT_RANGE = {"omega": (0.45, 2.1), "zeta": (0.001, 0.9), "r": (0.05, 0.95),
                 "c2": (-3.0, 1.0)}

#: Most points per direction of a curve (a run of 400 takes ~0.2 s per curve).
MAX_POINTS = 100_000

#: ``grazing continue2 --help``: the files and the words of the summary
#: (docs/theory_two_parameter.md, sections 3 and 5).
DESCRIPTION = (
    "PD and fold curves of the 1/1 orbit in the plane (mu, Delta d), mu = --parameter; the "
    "degenerate grazing points (N_g,12 = 0, Eq. 33) where they meet the grazing curve "
    "Delta d = 0 (docs/theory_two_parameter.md). "
    "continue2_curves.csv has one row per curve point, with the columns: curve (the "
    "curve's index in continue2.json), kind (period-doubling or fold), then a column named "
    "after --parameter (omega, zeta, r or c2: the value of mu), psi (impact phase - tau*, "
    "rad), delta_d (d - d*), d (the absolute clearance), v_minus (the impact velocity), "
    "abs_lambda1, abs_lambda2 (the moduli of the two multipliers, largest first), physical "
    "(1: a 1/1 motion, one impact per period by the exact flow; 0: drawn dotted). "
    "Each curve has two ends, one per direction: grazing (psi crossed 0: the curve meets "
    "the grazing curve at a degenerate point), unphysical side (v- < 0, a seed on the "
    "grazing curve continues into v- > 0 only), range (the end of --from/--to), points "
    "(--max-points reached), controller phase (the impact reaches the phase of the "
    "controller's kick, pi2_offset after tau*, where the branch jumps: the curve stops "
    "there), phase (|psi| = pi), step size (the corrector failed down to a step of 1e-12 "
    "elsewhere).")


def add_parser(sub, common, gain_args):
    """Register ``continue2`` (``common``, ``gain_args``: the shared option groups)."""
    s = sub.add_parser("continue2", help="PD and fold curves of the 1/1 orbit in two "
                                         "parameters, degenerate grazing points, diagram",
                       description=DESCRIPTION)
    common(s)
    s.add_argument("--parameter", choices=("omega", "zeta", "r", "c2"), default="omega",
                   help="the second parameter next to Delta d (default omega; c2 needs --c2, "
                        "c1 held)")
    s.add_argument("--from", dest="start", type=finite,
                   help="start of the parameter's range (default: omega 0.45, zeta 0.001, "
                        "r 0.05, c2 -3)")
    s.add_argument("--to", dest="stop", type=finite,
                   help="end of the range (default: omega 2.1, zeta 0.9, r 0.95, c2 1)")
    s.add_argument("--design", action="store_true",
                   help="with --parameter c2: c1 follows c2 by the degenerate condition (Eq. 38), "
                        "the study's family of designs; the curves meet grazing where lambda0 "
                        "= -1 (PD) or +1 (fold), the ends of the admissible c2 set")
    s.add_argument("--curves", choices=("both", "period-doubling", "fold"), default="both",
                   help="which curves (default both)")
    s.add_argument("--max-points", type=integer_at_least(2), default=400,
                   help="points per direction of each curve (default 400), >= 2")
    s.add_argument("--out", type=non_empty_path, default="out/continue2",
                   help="folder for the panels (PNG, SVG), continue2.json and "
                        "continue2_curves.csv (columns above; default out/continue2)")
    gain_args(s)
    s.set_defaults(func=run)
    return s


def run(args):
    import argparse
    from pathlib import Path

    from grazing_control.dynamics.orbits.two_parameter import KINDS, Family, two_parameter_diagram
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.studies.figures.two_parameter import write_diagram
    from .common import gains_of, params_of

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out={args.out!r} is invalid: it exists and is not a folder")
    p = params_of(args)
    gains = gains_of(args, p)
    lo, hi = DEFAULT_RANGE[args.parameter]
    lo = lo if args.start is None else args.start
    hi = hi if args.stop is None else args.stop
    if not lo < hi:
        raise ParameterError(f"--from={lo!r}, --to={hi!r} are invalid: valid range is from < to")
    if args.parameter != "c2":
        for end in (lo, hi):   # each end a computable model, as the shared options are
            params_of(argparse.Namespace(**{**vars(args), args.parameter: end}))
    if args.max_points > MAX_POINTS:
        raise ParameterError(f"--max-points={args.max_points!r} is invalid: valid range is "
                             f"2 <= max-points <= {MAX_POINTS}")
    fam = Family(p, gains, args.parameter, design=args.design)
    kinds = KINDS if args.curves == "both" else (args.curves,)
    diagram = two_parameter_diagram(fam, lo, hi, kinds, max_points=args.max_points)
    doc = write_diagram(diagram, out, p, gains)
    if args.json:
        return doc
    name = args.parameter
    lines = [f"two-parameter diagram in ({name}, Delta d), {name} in [{lo:g}, {hi:g}]"
             + ("" if gains is None else ", c1 from Eq. 38 at every c2 (the design family)"
                if args.design else f", c1={gains.c1:.6g}, c2={gains.c2:.6g}"),
             "grazing curve: Delta d = 0, i.e. d = d*(" + name + ")"]
    for c in doc["codim2"]:
        ref = ""
        if "m" in c:
            ref = (f"  (2 omega_d/{c['m']} = {c['omega_star']:.16g}, "
                   f"difference {c['difference']:.1e})")
        what = ("lambda0 = -1 or +1 at grazing (an end of the admissible c2 set)"
                if args.design else "degenerate grazing")
        lines.append(f"{what} at {name} = {c['value']:.16g}{ref}")
        for kind, k in c["curves"].items():
            side = ">" if k["side"] > 0 else "<"
            p_fit = k["fitted_exponent"]
            lines.append(f"  {kind:16s} Delta d ~ {k['kappa']:.6g} |{name} - {name}*|^{k['exponent']} on "
                         f"{name} {side} {name}*; measured exponent "
                         f"{'n/a' if p_fit is None else format(p_fit, '.5f')}, kappa "
                         f"{'n/a' if k['measured_kappa'] is None else format(k['measured_kappa'], '.6g')}")
    for c in doc["curves"]:
        pts = c["points"]
        phys = sum(q["physical"] for q in pts)
        meets = ", ".join(f"{m:.10g}" for m in c["meets_grazing_at"]) or "none"
        lines.append(f"{c['kind']:16s} curve: {len(pts)} points ({phys} physical 1/1 orbits), "
                     f"{name} {min(q['value'] for q in pts):.6g} .. "
                     f"{max(q['value'] for q in pts):.6g}, meets grazing at {meets}; "
                     f"ends: {', '.join(c['ends'])}")
    lines.append(f"files: {out}/ {' '.join(doc['files'])}")
    return "\n".join(lines)

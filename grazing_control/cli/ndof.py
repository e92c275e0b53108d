"""`grazing design|orbit|continue|simulate --model FILE`: the commands on an n-DOF model.

The same commands as the 1-DOF ones (cli/commands.py), on a model file
(docs/ndof_model.md) instead of --zeta/--r/--omega; what each prints is in
docs/ndof_commands.md. The gains are a vector k of 2n numbers (the kick
v[i_a] += k^T (X - X**) at Pi2, coordinates x0..x{n-1}, v0..v{n-1}), given as

* ``--gains k0,k1,...``: the vector itself;
* ``--mu MU``: the member of the design family whose free eigenvalue is mu
  (w^T N = mu w^T, docs/theory_ndof.md, "Kick design");
* ``--free-gain NAME=VALUE``: the member of the family whose gain on coordinate NAME
  is VALUE (for n = 1, ``--free-gain v0=C2`` is the 1-DOF ``--c2 C2``).

Errors are one line and status 2, as for every command (cli/commands.py).
"""

from __future__ import annotations

import math
import time

import numpy as np

from grazing_control.oscillator.params import ParameterError

from .common import nulls

__all__ = ["add_model_option", "add_gain_options", "add_design_options", "add_start_option",
           "add_sweep_options", "check_options", "load", "gains_of", "dispatch",
           "add_figures_options", "cmd_design", "cmd_orbit", "cmd_continue", "cmd_simulate",
           "cmd_sweep", "cmd_figures"]

#: Options of the 1-DOF commands that a model file replaces (refused with --model).
ONE_DOF_OPTIONS = ("--zeta", "--r", "--omega", "--pi2-offset", "--params", "--rig", "--c1", "--c2",
                   "--delay", "--method", "--optimize", "--sensor-rate", "--estimator",
                   "--x0", "--v0", "--dx0", "--dv0", "--lyapunov", "--fidelity", "--tol",
                   "--engine", "--component", "--start", "--bags", "--docs")
#: Options that need --model.
MODEL_OPTIONS = ("--mu", "--gains", "--free-gain", "--z0", "--coordinate",
                 "--cancel-first-markov", "--markov-only")


def add_model_option(parser) -> None:
    """``--model FILE`` on a subcommand's parser."""
    parser.add_argument("--model", metavar="FILE",
                        help="an n-DOF model file (docs/ndof_model.md, e.g. "
                             "config/models/two_mass_chain.yaml): run this command on it "
                             "(docs/ndof_commands.md); the 1-DOF model options are then refused")


def _vector(text):
    import argparse

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected comma-separated "
                                         "finite numbers, e.g. 0.1,-0.2,0,0.5")
    return values


def _named(text):
    import argparse

    name, sep, value = text.partition("=")
    try:
        v = float(value)
    except ValueError:
        v = math.nan
    if not sep or not name.strip() or not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected NAME=VALUE, e.g. v1=-1")
    return name.strip(), v


def add_gain_options(parser, *, markov: bool = False) -> None:
    """--gains / --mu / --free-gain (module docstring), and --cancel-first-markov."""
    g = parser.add_argument_group("n-DOF gains (with --model; at most one)")
    g.add_argument("--gains", type=_vector, metavar="K0,K1,...",
                   help="the 2n gains k (x0..x{n-1}, v0..v{n-1}) of v[i_a] += k^T (X - X**)")
    g.add_argument("--mu", type=_finite, help="the design family's member with w^T N = mu w^T")
    g.add_argument("--free-gain", type=_named, metavar="NAME=VALUE",
                   help="the design family's member whose gain on NAME (x0.., v0..) is VALUE")
    if markov:
        g.add_argument("--cancel-first-markov", type=_finite, metavar="OFFSET",
                       help="with --mu: the gain k(mu) + OFFSET d that cancels w^T N u "
                            "and G(1), d a unit vector off the family (the singular eigenvalue "
                            "then grows like |Delta d|^(-1/4) instead of staying bounded; "
                            "docs/ndof_commands.md)")
        parser.add_argument("--markov-only", action="store_true",
                            help="with --cancel-first-markov: cancel w^T N u only, G(1) left "
                                 "free (the branch is linear in the impact phase and the "
                                 "singular eigenvalue grows like |Delta d|^(-1/2))")


def add_design_options(parser) -> None:
    """--mu / --free-gain of ``design --model`` (the chosen member of the family)."""
    g = parser.add_argument_group("n-DOF design (with --model)")
    g.add_argument("--mu", type=_finite,
                   help="the chosen member of the family, w^T N = mu w^T (default: the middle "
                        "of the widest admissible interval)")
    g.add_argument("--free-gain", type=_named, metavar="NAME=VALUE",
                   help="the member whose gain on NAME (x0.., v0..) is VALUE (n = 1: "
                        "--free-gain v0=C2 is the 1-DOF --c2 C2)")


def add_start_option(parser) -> None:
    """--z0 of ``simulate --model``: the start on Pi2 as a deviation from X**."""
    parser.add_argument("--z0", type=_vector, metavar="Z0,Z1,...",
                        help="with --model: the start on Pi2, 2n deviations from the grazing "
                             "orbit (x0.., v0..); default 0 (write --z0=-1e-4,0,0,0 for a "
                             "negative first value)")


def _finite(text):
    from grazing_control.support.arguments import finite

    return finite(text)


def _given(argv, flag):
    return any(a == flag or a.startswith(flag + "=") for a in argv)


#: The commands of this module (``run --model`` is the launcher's: ros/launcher.py).
COMMANDS = ("design", "orbit", "continue", "simulate", "sweep", "figures")


def check_options(args, argv) -> None:
    """Refuse 1-DOF model options with --model, and n-DOF options without it (the
    commands of :data:`COMMANDS`)."""
    if getattr(args, "command", None) not in COMMANDS:
        return
    model = getattr(args, "model", None)
    if model is not None:
        bad = [f for f in ONE_DOF_OPTIONS if _given(argv, f)
               and not (f == "--delay" and args.command == "design")]   # the delayed design
        if bad:
            raise ParameterError(f"{', '.join(bad)} {'is a 1-DOF option' if len(bad) == 1 else 'are 1-DOF options'}"
                                 f": with --model the model file gives the model "
                                 "(docs/ndof_model.md); give the gains as --gains, --mu or "
                                 "--free-gain")
    else:
        bad = [f for f in MODEL_OPTIONS if _given(argv, f)]
        if bad:
            raise ParameterError(f"{', '.join(bad)} {'needs' if len(bad) == 1 else 'need'} "
                                 "--model FILE (an n-DOF model file, docs/ndof_model.md)")


def load(path):
    """The model of ``--model FILE``; one-line ParameterError for an unreadable file."""
    from grazing_control.oscillator.ndof import load_model
    from grazing_control.support.files import YamlFileError

    try:
        return load_model(path)
    except YamlFileError as exc:
        raise ParameterError(f"--model {exc}") from None
    except ParameterError as exc:
        raise ParameterError(f"--model {path}: {exc}") from None


def coordinates(model) -> tuple:
    """x0..x{n-1}, v0..v{n-1}: the names of the state's (and the gains') components."""
    return tuple(f"x{i}" for i in range(model.n)) + tuple(f"v{i}" for i in range(model.n))


def family_member(model, name: str, value: float, delay: float = 0.0) -> float:
    """mu of the family member whose gain on ``name`` is ``value`` (the family is affine
    in mu, docs/theory_ndof.md, "Kick design"; for a kick ``delay`` after Pi2, §14)."""
    from grazing_control.dynamics.design.ndof_design import gain_family

    names = coordinates(model)
    if name not in names:
        raise ParameterError(f"--free-gain {name}={value!r} is invalid: valid names are "
                             f"{', '.join(names)}")
    j = names.index(name)
    k0 = np.asarray(gain_family(model, 0.0, delay), dtype=float)
    k1 = np.asarray(gain_family(model, 1.0, delay), dtype=float) - k0
    if not abs(k1[j]) > 1e-12 * max(1.0, float(np.max(np.abs(k1)))):
        raise ParameterError(f"--free-gain {name}={value!r} is invalid: the gain on {name} is "
                             f"the same ({k0[j]:.12g}) for every member of the family; choose "
                             "another coordinate, or --mu")
    mu = float((value - k0[j]) / k1[j])
    from grazing_control.dynamics.design.ndof_design import MU_LIMIT

    if not abs(mu) <= MU_LIMIT:
        raise ParameterError(f"--free-gain {name}={value!r} is invalid: it is the member "
                             f"mu = {mu:g} of the family; valid are the gains of |mu| <= "
                             f"{MU_LIMIT:g}, i.e. {name} between "
                             f"{k0[j] - MU_LIMIT * abs(k1[j]):.6g} and "
                             f"{k0[j] + MU_LIMIT * abs(k1[j]):.6g}")
    return mu


def gains_of(args, model):
    """(gains or None, mu or None, how): the gains of --gains / --mu / --free-gain (at most
    one), or of --cancel-first-markov OFFSET with --mu; None: uncontrolled."""
    offset = getattr(args, "cancel_first_markov", None)
    given = [f for f, v in (("--gains", getattr(args, "gains", None)),
                            ("--mu", getattr(args, "mu", None)),
                            ("--free-gain", getattr(args, "free_gain", None))) if v is not None]
    if offset is not None:
        if given != ["--mu"]:
            raise ParameterError("--cancel-first-markov OFFSET needs --mu MU (the family member "
                                 "it moves off by OFFSET), and neither --gains nor --free-gain")
        from grazing_control.dynamics.design.ndof_design import cancel_first_markov

        only = bool(getattr(args, "markov_only", False))
        k = np.asarray(cancel_first_markov(model, args.mu, offset, smooth_branch=not only),
                       dtype=float)
        what = "only w^T N u" if only else "w^T N u and G(1)"
        return k, None, f"cancels {what}: k(mu = {args.mu:g}) + {offset:g} d"
    if getattr(args, "markov_only", False):
        raise ParameterError("--markov-only goes with --cancel-first-markov OFFSET --mu MU")
    if len(given) > 1:
        raise ParameterError(f"{' and '.join(given)} are given: give one of --gains, --mu, "
                             "--free-gain")
    if not given:
        return None, None, "uncontrolled"
    if given[0] == "--gains":
        k = np.asarray(args.gains, dtype=float)
        if k.size != 2 * model.n:
            raise ParameterError(f"--gains has {k.size} values: the model has n = {model.n}, "
                                 f"give 2n = {2 * model.n} ({', '.join(coordinates(model))})")
        return k, None, "given"
    from grazing_control.dynamics.design.ndof_design import gain_family

    mu = args.mu if given[0] == "--mu" else family_member(model, *args.free_gain)
    return np.asarray(gain_family(model, mu), dtype=float), mu, "design family"


def _complex_list(values):
    return [[float(np.real(z)), float(np.imag(z))] for z in np.atleast_1d(values)]


def _fmt_vec(v, digits=10):
    return "[" + ", ".join(f"{x:.{digits}g}" for x in np.asarray(v, dtype=float)) + "]"


def _fmt_intervals(intervals):
    def end(x):
        return "inf" if x is None or not math.isfinite(x) else f"{x:.10g}"
    return " U ".join(f"({end(lo)}, {end(hi)})" for lo, hi in intervals) or "empty"


def _intervals(raw):
    return [(float(lo), float(hi)) for lo, hi in raw]


def _intersection(a, b):
    """The intervals common to two unions of disjoint open intervals."""
    out = []
    for lo1, hi1 in a:
        for lo2, hi2 in b:
            lo, hi = max(lo1, lo2), min(hi1, hi2)
            if lo < hi:
                out.append((lo, hi))
    return sorted(out)


def _json_interval(iv):
    return [x if math.isfinite(x) else None for x in iv]


def _header(model, path):
    from grazing_control.oscillator.ndof.flow import NdofFlow

    flow = NdofFlow.of(model)
    return {"model": str(path), "n": model.n, "i_w": model.i_w, "i_a": model.i_a,
            "d_star": float(flow.d_star), "tau_star": float(flow.tau_star),
            "coordinates": list(coordinates(model))}


# ---------------------------------------------------------------------------- design
def cmd_design(args):
    """design --model FILE [--mu MU | --free-gain NAME=V] [--delay D] [--pulse-width W
    [--actuator-bandwidth B] [--actuator-latency L]] [--out FILE] (docs/ndof_commands.md;
    the delayed design is docs/theory_ndof.md §14, the pulse's §15)."""
    from grazing_control.dynamics.design import ndof_design as nd

    model = load(args.model)
    delay = nd.design_actuation(float(getattr(args, "delay", 0.0) or 0.0),
                                *(float(getattr(args, a, 0.0) or 0.0) for a in
                                  ("pulse_width", "actuator_bandwidth", "actuator_latency")))
    pulse = nd.actuation_parameters(delay) if isinstance(delay, nd.Actuation) else None
    t0 = time.perf_counter()
    k0 = np.asarray(nd.gain_family(model, 0.0, delay), dtype=float)
    k1 = np.asarray(nd.gain_family(model, 1.0, delay), dtype=float) - k0
    zeros = np.asarray(nd.transmission_zeros(model, delay), dtype=complex)
    sets = {c: _intervals(nd.admissible_mu(model, c, delay))
            for c in ("impacting", "non-impacting")}
    intervals = _intersection(sets["impacting"], sets["non-impacting"])   # "combined"
    given = [f for f, v in (("--mu", args.mu), ("--free-gain", args.free_gain)) if v is not None]
    if len(given) > 1:
        raise ParameterError("--mu and --free-gain are given: give one of them")
    if args.mu is not None:
        mu, chosen = float(args.mu), "given (--mu)"
    elif args.free_gain is not None:
        mu, chosen = family_member(model, *args.free_gain, delay), \
            f"from --free-gain {args.free_gain[0]}"
    elif intervals:
        # the middle of the widest interval; an unbounded one: 1 inside its finite end
        lo, hi = max(intervals, key=lambda iv: iv[1] - iv[0])
        mu = 0.5 * (lo + hi) if math.isfinite(lo) and math.isfinite(hi) else \
            (hi - 1.0 if math.isfinite(hi) else lo + 1.0)
        chosen = "the middle of the widest admissible interval (no --mu given)"
    else:
        mu, chosen = 0.0, "mu = 0 (no admissible mu; no --mu given)"
    mu += 0.0   # no "-0" in the report
    design = nd.evaluate_design(model, mu, delay)
    k = np.asarray(design.gains, dtype=float)
    lam0 = np.asarray(design.limit_multipliers, dtype=complex)
    gamma = float(design.gamma1)
    rho_free = float(np.max(np.abs(nd.free_multipliers(model, mu, delay))))
    conditions = {"limit_stable": bool(design.stable), "exists_impacting": bool(design.exists),
                  "free_stable": bool(design.free_stable)}
    admissible = bool(design.admissible)
    # no design anywhere on the family: say where the section could go (a scan, §4)
    sections = None if intervals else nd.sections_with_stable_zeros(model, delay=delay)
    seconds = time.perf_counter() - t0
    out = _header(model, args.model)
    out.update({
        "family": {"k_at_mu_0": k0.tolist(), "dk_dmu": k1.tolist()},
        "transmission_zeros": _complex_list(zeros),
        "transmission_zeros_max_modulus": float(np.max(np.abs(zeros))) if zeros.size else 0.0,
        "admissible_mu": [_json_interval(iv) for iv in intervals],
        "admissible_mu_sets": {"combined": [_json_interval(iv) for iv in intervals],
                               **{c: [_json_interval(iv) for iv in ivs]
                                  for c, ivs in sets.items()}},
        "delay": delay.delay if pulse else delay, **({"pulse": pulse} if pulse else {}),
        "mu": mu, "mu_chosen": chosen, "gains": k.tolist(),
        "multipliers_limit": _complex_list(lam0), "gamma1": gamma,
        "spectral_radius_free": rho_free, "conditions": conditions, "admissible": admissible,
        "pi2_offsets_with_stable_zeros": None if sections is None else
        [list(iv) for iv in sections],
        "seconds": seconds,
    })
    if args.out:
        if not admissible:
            raise ParameterError(f"mu={mu!r} is not admissible: valid range is "
                                 f"{_fmt_intervals(intervals)}; nothing written to {args.out}")
        nd.write_gain_yaml(args.out, model, design, args.model)
        out["written"] = args.out
    if args.json:
        return out
    ok = {True: "yes", False: "NO"}
    names = coordinates(model)
    lines = [
        f"n-DOF degenerate grazing design (w^T N = mu w^T) for {args.model} (n = {model.n}, "
        f"wall on x{model.i_w}, kick on v{model.i_a})",
        f"  d*, tau*           = {out['d_star']:.15g}, {out['tau_star']:.15g}",
        *([f"  actuation delay    = {delay:.15g}  (the kick acts this long after the Pi2 "
           f"sample; the family, zeros and limits are those of the delayed kick)"]
          if delay and not pulse else []),
        *([f"  pulse              = {', '.join(f'{a} {b:.10g}' for a, b in pulse.items())}  "
           f"(the correction as a force pulse; family, zeros and limits are the pulse's, "
           f"docs/theory_ndof.md §15)"] if pulse else []),
        f"  family k(mu)       = k0 + mu dk, over ({', '.join(names)})",
        f"    k0               = {_fmt_vec(k0, 12)}",
        f"    dk               = {_fmt_vec(k1, 12)}",
        f"  transmission zeros = {', '.join(f'{z:.6g}' for z in zeros)}",
        f"    max |zero|       = {out['transmission_zeros_max_modulus']:.6g}  (< 1 needed: "
        f"{ok[out['transmission_zeros_max_modulus'] < 1.0]})",
        f"  admissible mu      = {_fmt_intervals(intervals)}  (all three conditions)",
        f"    impacting side   = {_fmt_intervals(sets['impacting'])}  (|lambda0| < 1, gamma1 > 0)",
        f"    non-impacting    = {_fmt_intervals(sets['non-impacting'])}  (rho(N) < 1)",
        f"  mu                 = {mu:.15g}  ({chosen})",
        f"  gains k            = {_fmt_vec(k, 15)}",
        f"  |lambda0|          = {', '.join(f'{abs(z):.6g}' for z in lam0)}  (limit Delta d -> "
        f"0-: {ok[conditions['limit_stable']]} < 1)",
        f"  gamma1             = {gamma:.6g}  (> 0: 1/1 motion exists for d < d*: "
        f"{ok[conditions['exists_impacting']]})",
        f"  rho(N)             = {rho_free:.6g}  (non-impacting motion, d > d*: "
        f"{ok[conditions['free_stable']]} < 1)",
        f"  this mu            : {'admissible' if admissible else 'NOT admissible'}",
    ]
    if sections is not None:
        where = " U ".join(f"({a:.4f}, {b:.4f})" for a, b in sections) or "none"
        lines.append(f"  no admissible mu: pi2_offset values whose zeros all lie inside the "
                     f"unit circle (scan): {where} (this file: {model.pi2_offset:.4g})")
    if args.out:
        lines.append(f"  gains written to {args.out}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------- orbit
def _orbit_json(o):
    return {"delta_d": o.delta_d, "impact_phase": o.impact_phase, "impact_dt": o.impact_dt,
            "v_minus": o.v_minus, "section_pi2": o.physical.tolist(),
            "section_pi2_deviation": o.state.tolist(),
            "multipliers": _complex_list(o.multipliers), "stable": o.stable,
            "guess": o.guess, "branch": "grazing" if o.near_grazing else "other",
            "prediction_offset": o.prediction_offset if math.isfinite(o.prediction_offset)
            else None}


def cmd_orbit(args):
    """orbit --model FILE --delta-d DD [gains] (docs/ndof_commands.md)."""
    from grazing_control.studies.ndof.branch import EXPLICIT, grazing_side, orbit_11, with_delta_d

    model = with_delta_d(load(args.model), args.delta_d)
    k, mu, how = gains_of(args, model)
    t0 = time.perf_counter()
    side = grazing_side(model, k)
    try:
        o = orbit_11(model, k)
    except RuntimeError as exc:
        if side * args.delta_d < 0.0:
            raise RuntimeError(f"{exc}; note: the local map puts the 1/1 orbit born at "
                               f"grazing on the side Delta d {'>' if side > 0 else '<'} 0 for "
                               "this model and gains") from None
        raise
    seconds = time.perf_counter() - t0
    out = _header(model, args.model)
    out.update(_orbit_json(o))
    out["grazing_side"] = side
    out.update(gains=None if k is None else k.tolist(), mu=mu, control=how, seconds=seconds)
    if args.json:
        return out
    ctl = " (uncontrolled)" if k is None else f" with k = {_fmt_vec(k, 8)} ({how}" + \
        (f", mu = {mu:.8g})" if mu is not None else ")")
    explicit = o.guess == EXPLICIT
    route = "the factored monodromy" if explicit else "shooting"
    born = "born at grazing (" + ("on the branch from psi = 0" if explicit else
                                  "the local map's prediction")
    born += (f", {o.prediction_offset:.2g} relative from the local map's prediction)"
             if math.isfinite(o.prediction_offset) else ")")
    return "\n".join([
        f"1/1 orbit at Delta d = {model.delta_d:.6g}{ctl}",
        f"  impact phase  = {o.impact_phase:.15g}",
        f"  v-            = {o.v_minus:.10g}",
        f"  Pi2 point     = {_fmt_vec(o.physical, 15)}",
        f"  multipliers   = {', '.join(f'{z:.6g}' for z in o.multipliers)}  "
        f"(|max| {np.max(np.abs(o.multipliers)):.6g}; {route}, {seconds:.3g} s)",
        f"  stable        = {o.stable}",
        f"  found from    : {o.guess}",
        f"  branch        = " + (born if o.near_grazing
                                 else "another 1/1 orbit, not the one born at grazing "
                                      "(docs/ndof_commands.md)"),
    ])


# ---------------------------------------------------------------------------- continue
#: Impact velocity, in units of d* omega, below which a point found by shooting is
#: flagged: v-^2 / (2 |a|) then nears the gap's rounding (~1e-16 d*), and v- was found
#: 1e-2 off at v- = 1.5e-7 (issue 32).
UNRESOLVED_V = 1e-5


def continuation_values(start: float, stop: float, points: int) -> np.ndarray:
    """Delta d from ``start`` to ``stop``: log-spaced in |Delta d| when both have one sign
    (points crowd towards grazing; ``stop`` = 0: down to 1e-12 |start|), else linear."""
    if points < 2:
        raise ParameterError(f"points={points!r} is invalid: valid range is points >= 2")
    if start == stop:
        raise ParameterError("--from and --to must differ")
    if start != 0.0 and stop == 0.0:
        stop = start * 1e-12
    if start * stop > 0.0:
        return math.copysign(1.0, start) * np.geomspace(abs(start), abs(stop), points)
    return np.linspace(start, stop, points)


def cmd_continue(args):
    """continue --model FILE --from A --to B [gains] (docs/ndof_commands.md)."""
    from grazing_control.dynamics.orbits.continuation import continue_orbit
    from grazing_control.dynamics.orbits.ndof_branch import continue_branch
    from grazing_control.dynamics.maps.ndof_map import NdofMap
    from grazing_control.studies.ndof.branch import EXPLICIT, fold_beyond, orbit_11, with_delta_d

    values = continuation_values(args.start, args.stop, args.points)
    model = with_delta_d(load(args.model), float(values[0]))
    k, mu, how = gains_of(args, model)
    t0 = time.perf_counter()
    first = orbit_11(model, k)
    # the branch born at grazing: explicit in the impact phase, every point exact to
    # rounding (issue 32: shooting returned points 1e-2 off near |Delta d| = 3e-8)
    explicit = first.guess == EXPLICIT
    branch = continue_branch(model, k, values) if explicit else \
        continue_orbit(NdofMap(model, k), "delta_d", values, first.state)
    fold = fold_beyond(model, k, branch, float(values[-1]))
    seconds = time.perf_counter() - t0
    # by shooting, an impact with v-^2 near the gap's rounding is resolved to a few
    # digits only (docs/ndof_commands.md, "Near grazing"): say which points that is
    floor = UNRESOLVED_V * model.omega * _header(model, args.model)["d_star"]
    weak = [] if explicit else [p.value for p in branch.points if p.v_min < floor]
    warning = None if not weak else (
        f"{len(weak)} of {len(branch.points)} points have v- below {floor:.3g}, where "
        f"shooting resolves the impact to a few digits only (Delta d {weak[0]:.6g} .. "
        f"{weak[-1]:.6g})")
    limit = None
    if mu is not None:
        from grazing_control.dynamics.design.ndof_design import limit_multipliers

        limit = np.asarray(limit_multipliers(model, mu), dtype=complex)
    out = _header(model, args.model)
    out.update({
        "gains": None if k is None else k.tolist(), "mu": mu, "control": how,
        "branch": [{"delta_d": p.value, "v_minus": p.v_min, "impacts": p.impacts,
                    "multipliers": _complex_list(p.multipliers), "stable": p.stable,
                    "section_pi2_deviation": np.asarray(p.state).tolist()}
                   for p in branch.points],
        "bifurcations": [{"type": b.type, "delta_d": b.value,
                          "multipliers": _complex_list(b.multipliers)}
                         for b in branch.bifurcations],
        "stopped": branch.stopped, "fold": fold,
        "route": "impact phase" if explicit else "shooting", "warning": warning,
        "start_branch": "grazing" if first.near_grazing else "other",
        "multipliers_limit": None if limit is None else _complex_list(limit),
        "seconds": seconds,
    })
    if args.json:
        return nulls(out)
    route = "in the impact phase (exact to rounding)" if explicit else "by shooting"
    lines = [f"1/1 branch {route}, {len(branch.points)} points from Delta d = "
             f"{args.start:g} towards {args.stop:g}"
             + ("" if k is None else f" ({how}{'' if mu is None else f', mu = {mu:.8g}'})"),
             f"{'Delta d':>14} {'v-':>14} {'max|lambda|':>14} stable"]
    step = max(1, len(branch.points) // 20)
    for p in branch.points[::step]:
        lines.append(f"{p.value:14.6e} {p.v_min:14.6e} {np.max(np.abs(p.multipliers)):14.6e} "
                     f"{p.stable}")
    lines.append("bifurcations:" if branch.bifurcations else "bifurcations: none in range")
    for b in branch.bifurcations:
        lines.append(f"  {b.type:16s} at Delta d = {b.value:.15g}")
    lines.append(f"  stopped: {branch.stopped}")
    if warning:
        lines.append(f"  warning: {warning}")
    if fold is not None:
        lines.append(f"  fold at Delta d = {fold['delta_d']:.15g} (psi = {fold['psi']:.6g}, "
                     f"v- = {fold['v_minus']:.6g}): the branch turns back, a multiplier "
                     f"{complex(*fold['multiplier_near_1']):.10g}; the exact map keeps its "
                     f"orbit to {fold['residual']:.1e}")
    if not first.near_grazing:
        lines.append("  note: the orbit at the start is another 1/1 orbit, not the one born at "
                     "grazing (docs/ndof_commands.md)")
    if limit is not None:
        lines.append(f"  predicted limit |lambda0| = "
                     f"{', '.join(f'{abs(z):.6g}' for z in limit)} (Delta d -> 0-)")
    return "\n".join(lines)


# ---------------------------------------------------------------------------- simulate
def cmd_simulate(args):
    """simulate --model FILE --delta-d DD --periods N [--control-after K] [gains] [--z0]."""
    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.studies.ndof.branch import OrbitNotFound, orbit_11, with_delta_d
    from grazing_control.studies.ndof.scene import simulate_pi2

    model = with_delta_d(load(args.model), args.delta_d)
    k, mu, how = gains_of(args, model)
    if args.control_after is not None and k is None:
        raise ParameterError("--control-after needs the gains: give --gains, --mu or --free-gain")
    if args.z0 is not None and len(args.z0) != 2 * model.n:
        raise ParameterError(f"--z0 has {len(args.z0)} values: give 2n = {2 * model.n} "
                             f"({', '.join(coordinates(model))}, deviation from X** on Pi2)")
    after = None if k is None else (0 if args.control_after is None else args.control_after)
    samples, counts = simulate_pi2(model, args.periods, args.z0, k, after)
    flow = NdofFlow.of(model)
    ref = flow.to_physical(flow.tau2, np.zeros(2 * model.n))
    out = {"pi2": (samples[:-1] + ref).tolist(), "pi2_deviation": samples[:-1].tolist(),
           "impacts_per_period": counts.tolist(), "final_deviation": samples[-1].tolist(),
           "gains": None if k is None else k.tolist(), "mu": mu, "control_after": after}
    orbit_note = ""
    if k is not None:
        try:
            o = orbit_11(model, k)
            dist = float(np.linalg.norm(samples[-1] - o.state))
            out.update(distance_to_orbit=dist, orbit_deviation=o.state.tolist(),
                       orbit_multipliers=_complex_list(o.multipliers))
            orbit_note = (f"{dist:.3e} (|lambda|max of that orbit "
                          f"{np.max(np.abs(o.multipliers)):.4g})")
        except OrbitNotFound as exc:
            out.update(distance_to_orbit=None, orbit_error=str(exc))
            orbit_note = f"none ({' '.join(str(exc).split())[:160]})"
    if args.json:
        return out
    n = args.periods
    tail = counts[-min(n, 20):].tolist()
    lines = [
        f"simulated {n} periods of {args.model} at Delta d = {model.delta_d:.6g}"
        + (f", control on from sample {after} ({how})" if k is not None else ", uncontrolled"),
        f"  impacts in all     = {int(counts.sum())}",
        f"  impacts per period, last {len(tail)}: {tail}",
        f"  last state (dev.)  = {_fmt_vec(samples[-1], 10)}",
    ]
    if k is not None:
        lines.append(f"  distance to the controlled 1/1 orbit = {orbit_note}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------- sweep
def dispatch(one_dof, n_dof):
    """A subcommand's function: ``n_dof`` with --model, else the 1-DOF ``one_dof``."""
    def run(args):
        return n_dof(args) if getattr(args, "model", None) is not None else one_dof(args)

    run.__name__ = getattr(one_dof, "__name__", "run")
    return run


def add_sweep_options(parser) -> None:
    """--model, the gains, --z0 and --coordinate of ``sweep --model``."""
    add_model_option(parser)
    add_gain_options(parser)
    add_start_option(parser)
    parser.add_argument("--coordinate", metavar="NAME",
                        help="with --model: the Pi2 coordinate drawn in the PNG, x0.. or v0.. "
                             "(default: the wall coordinate x{i_w})")


def cmd_sweep(args):
    """sweep --model FILE --grid NAME=A:B:N --periods P (docs/ndof_commands.md)."""
    import os
    import sys

    from grazing_control.studies.ndof.diagram import diagram
    from grazing_control.studies.ndof.plot import coordinate_index, diagram_png

    model = load(args.model)
    if len(args.grid) != 1:
        raise ParameterError(f"--grid is given {len(args.grid)} times: with --model a sweep has "
                             "one axis (delta_d, omega, r, phase or pi2_offset)")
    name, values = args.grid[0]
    k, mu, how = gains_of(args, model)
    if args.control_after is not None and k is None:
        raise ParameterError("--control-after needs the gains: give --gains, --mu or --free-gain")
    if args.z0 is not None and len(args.z0) != 2 * model.n:
        raise ParameterError(f"--z0 has {len(args.z0)} values: give 2n = {2 * model.n} "
                             f"({', '.join(coordinates(model))})")
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
                  max_period=args.max_period, progress=not args.json and sys.stderr.isatty())
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
    if args.json:
        return summary
    hist = ", ".join(f"{'failed' if p == '-1' else 'none' if p == '0' else 'period ' + p}: {c}"
                     for p, c in summary["detected_periods"].items())
    lines = [
        f"sweep of {res.values.size} points of {name} for {args.model}, {res.periods} periods "
        f"each, last {res.periods - res.transient} kept"
        + ("" if k is None else f", control on from sample {res.control_after} ({how})"),
        f"  time              : {seconds:.3g} s",
        f"  detected on Pi2   : {hist}",
        f"  written           : {out}" + (f"\n                      {png}" if png else ""),
    ]
    if summary["failed"]:
        first = next(e for e in res.errors if e)
        lines.append(f"  failed points     : {summary['failed']} (first: {first})")
    return "\n".join(lines)


# ---------------------------------------------------------------------------- figures
def add_figures_options(parser) -> None:
    """--model and --mu of ``figures --model``."""
    add_model_option(parser)
    parser.add_argument("--mu", type=_finite,
                        help="with --model: the design family's member drawn (default: the "
                             "middle of the widest admissible interval)")


def cmd_figures(args):
    """figures --model FILE [--out DIR] [--mu MU] [--quick] (docs/ndof_commands.md)."""
    import sys
    from dataclasses import replace

    from grazing_control.studies.figures.ndof import DEFAULT, QUICK, make_ndof_figures

    model = load(args.model)
    settings = replace(QUICK if args.quick else DEFAULT, mu=args.mu)
    out = args.out if args.out != "out/figures" else "out/figures_ndof"
    log = None if args.json else (lambda line: print(line, file=sys.stderr))
    numbers = make_ndof_figures(model, out, settings, model_file=args.model,
                                workers=args.workers, log=log)
    if args.json:
        return nulls(numbers)
    m = numbers["multipliers"]
    lines = [f"n-DOF figures of {args.model} in {out}: ndof_diagram.png, ndof_multipliers.png, "
             "ndof_scene.png, ndof_figures.json",
             f"  mu = {numbers['mu']:.6g} ({numbers['mu_chosen']})"]
    for label, entry in m.items():
        if not isinstance(entry, dict):
            continue
        if "error" in entry:
            lines.append(f"  {label:16s}: not drawn ({entry['error']})")
            continue
        slope = entry["fitted_exponent"]
        lines.append(f"  {label:16s}: fitted exponent "
                     f"{'n/a' if slope is None else f'{slope:.4f}'} over {entry['fit_points']} "
                     f"points; smallest |Delta d| reached {entry['smallest_delta_d_found']}")
    sc = numbers["scene"]
    dist = sc["final_distance"]
    lines.append(f"  scene at Delta d = {sc['delta_d']:g}: final distance to the controlled "
                 "orbit " + ("n/a (" + sc["orbit_error"][:120] + ")" if dist is None
                             else f"{dist:.3e}" + (" (captured)" if dist < 1e-8 else
                                                   " (not captured: the controller acts "
                                                   "locally, near the grazing orbit)")))
    return "\n".join(lines)

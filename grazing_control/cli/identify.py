"""``grazing identify BAG... [--json] [--out FILE]``: the model's parameters from recordings.

Fits the model (zeta, r, omega, delta_d, and the rig's natural frequency, forcing
amplitude and phase) to each bag's state stream and impacts
(:mod:`grazing_control.recordings.identify`; the method: docs/theory_identification.md),
prints each parameter with its standard error, the residuals and a re-simulation check,
and with ``--out`` writes the parameter file (:mod:`.parameter_file`) that ``grazing
design --params``, ``grazing run --params`` / ``--sim-params`` and the nodes
(``--params-file``) take. Where a bag carries its rig (``grazing/rig``) or ``--rig FILE``
gives it, the model in SI as well (natural frequency, damping ratio, restitution, gap,
standard errors propagated), and ``--out-rig FILE`` writes it as a rig file
(docs/rig.md, "Recordings"). A bag of an n-DOF scene (recorded with a ``model_file`` of
n > 1, or ``--model FILE``) gets the n-DOF fit: the wall coordinate's modal parameters
(docs/theory_identification.md section 11), and ``--out-model FILE`` writes them as a
model file (docs/ndof_model.md) that ``grazing design --model`` reads.

A bag whose corrections were force pulses through the first-order actuator
(``pulse_width``, ``actuator_bandwidth``, ``actuator_latency``, ``force_limit`` in its
parameter record) is fitted with the commands' force as a known input: the pulse, its
latency and the lag's tail (docs/theory_identification.md section 12); a poor fit of a
bag with corrections names, among its suspects, corrections that acted otherwise than
modelled (an actuator the record does not give).

``--stop``: which stop the bags' Pi2 samples support (rigid, Kelvin-Voigt, with
friction; :mod:`grazing_control.recordings.stop`, docs/theory_contact.md section 17),
each candidate with its parameters, standard errors and BIC, the oscillator's
parameters fitted with it (``--known-oscillator``: held at the bag's record); status 0.

Exit status: 0 good fit; 1 poor fit (the motion is not this model's: the report says
why; nothing is written); 2 bad input (unreadable bag, no state stream, too few samples,
no impact), with one line ``grazing: error: ...``.
"""

from __future__ import annotations

import json
import math
import sys

from grazing_control.support.arguments import integer_at_least, non_empty_path

#: --max-arcs by default: the first 100 arcs, fewer where the Jacobian's bound needs it.
DEFAULT_ARCS = 100

__all__ = ["add_identify_parser", "cmd_identify"]


def _plain(obj):
    """Standard JSON: nan/inf -> null (a parameter not identified), numpy -> Python."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "item"):          # numpy scalars
        return _plain(obj.item())
    return obj


def cmd_identify(args) -> int:
    """Run ``grazing identify``; the exit status (module docstring)."""
    from grazing_control.recordings.identify import identify_bags, si_report

    if args.stop:
        return _cmd_stop(args)
    rig = None
    if args.rig is not None:
        from .rig import load

        rig = load(args.rig)
    result = identify_bags(args.bags, position_only=args.position_only,
                           impacts=not args.no_impacts,
                           max_arcs=DEFAULT_ARCS if args.max_arcs is None else args.max_arcs,
                           shrink=args.max_arcs is None, model=args.model)
    if result.get("n", 1) > 1:
        return _ndof_result(args, result)
    if args.out_model:
        from grazing_control.oscillator.params import ParameterError

        raise ParameterError(f"--out-model {args.out_model}: the bag is a 1-DOF scene (no "
                             "model_file of n > 1): its model is written by --out")
    si_report(result, args.bags, rig)
    fitted_rig = result.pop("_rig", None)
    if args.out_rig and fitted_rig is None:
        from grazing_control.oscillator.params import ParameterError

        raise ParameterError(f"--out-rig {args.out_rig}: no rig to write the model into: the "
                             "bags carry none on grazing/rig; give --rig FILE")
    good = result["fit"] == "good"
    if args.out_rig:
        result["out_rig"] = args.out_rig if good else None
        if good:
            _write_rig(args.out_rig, fitted_rig, result)
    if args.out:
        if good:
            from .parameter_file import write_parameter_file

            par = result["parameters"]
            write_parameter_file(
                args.out, {k: par[k]["value"] for k in ("zeta", "r", "omega", "delta_d")},
                [f"model parameters identified by `grazing identify` from "
                 f"{', '.join(result['bags'])}"]
                + [f"{k} = {par[k]['value']!r} +- {par[k]['stderr']:.3g}"
                   for k in ("zeta", "r", "omega", "delta_d")])
            result["out"] = args.out
        else:
            result["out"] = None
    tail = []
    if args.out:
        tail.append(f"  parameter file written to {args.out}" if good else
                    f"  poor fit: nothing written to {args.out}")
    if args.out_rig:
        tail.append(f"  rig file written to {args.out_rig}" if good else
                    f"  poor fit: nothing written to {args.out_rig}")
    _emit(args, result, tail)
    return 0 if good else 1


def _emit(args, result, tail) -> None:
    """Print the result: one JSON object (--json), else the text report and ``tail``."""
    from grazing_control.recordings.identify import format_report

    if args.json:
        json.dump(_plain(result), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print("\n".join([format_report(result)] + tail))
    sys.stdout.flush()


def _ndof_result(args, result) -> int:
    """An n-DOF bag's report; ``--out-model``: the identified model as a model file
    (docs/ndof_model.md) after a good fit whose realisation misses no modal parameter by
    more than REALISATION_LIMIT standard errors; the exit status (module docstring)."""
    from grazing_control.dynamics.identification.modal import realise
    from grazing_control.oscillator.params import ParameterError

    ident, nominal = result.pop("_ident"), result.pop("_model")
    for flag, value in (("--out", args.out), ("--out-rig", args.out_rig), ("--rig", args.rig)):
        if value:
            raise ParameterError(f"{flag} {value}: the bag is an n-DOF scene (n = "
                                 f"{result['n']}): its model is written by --out-model")
    good = result["fit"] == "good"
    if args.out_model:
        model = None
        if good:
            se = [ident.stderr[k] for k in ident.names]
            model, misfit = realise(ident.model, nominal, se, ident.phase.tau0)
            result["realisation_misfit"] = misfit
            if not misfit <= REALISATION_LIMIT:
                good = False
                result["fit"] = "poor"
                result["reasons"].append(
                    f"no symmetric M, C, K near the bag's model file shows the fitted modes: "
                    f"the nearest misses them by {misfit:.3g} standard errors (limit "
                    f"{REALISATION_LIMIT:g})")
        if good:
            _write_model(args.out_model, model, result)
        result["out_model"] = args.out_model if good else None
    tail = []
    if args.out_model:
        tail.append(f"  model file written to {args.out_model} (realisation misses the fitted "
                    f"modal parameters by {result['realisation_misfit']:.2g} standard errors "
                    "at most)" if good else f"  poor fit: nothing written to {args.out_model}")
    _emit(args, result, tail)
    return 0 if good else 1


#: Largest misfit (in standard errors) of a written model's modal parameters.
REALISATION_LIMIT = 3.0


def _write_model(path, model, result) -> None:
    """The identified n-DOF model as a model file (docs/ndof_model.md), atomically."""
    from grazing_control.support.files import write_yaml_atomic

    doc = {"M": model.M.tolist(), "C": model.C.tolist(), "K": model.K.tolist(),
           "f": model.f.tolist(), "omega": float(model.omega), "i_w": int(model.i_w),
           "delta_d": float(model.delta_d), "r": float(model.r), "i_a": int(model.i_a),
           "phase": float(model.phase), "pi2_offset": float(model.pi2_offset)}
    par = result["parameters"]
    write_yaml_atomic(path, doc, [
        f"n-DOF model identified by `grazing identify` from {result['bag']} (the wall "
        f"coordinate's modal parameters, realised as symmetric M, C, K nearest the bag's "
        f"model file {result['model_file']}: docs/theory_identification.md section 11)"]
        + [f"{k} = {v['value']!r} +- {v['stderr']:.3g}" for k, v in par.items()])


def _cmd_stop(args) -> int:
    """``--stop``: which stop each bag supports (recordings.stop); status 0."""
    from grazing_control.recordings.stop import format_stop_report, select_bag_stop

    reports = [select_bag_stop(bag, max_samples=args.max_samples,
                               oscillator="known" if args.known_oscillator else "fit")
               for bag in args.bags]
    if args.json:
        json.dump(_plain(reports if len(reports) > 1 else reports[0]), sys.stdout,
                  allow_nan=False)
        sys.stdout.write("\n")
    else:
        print("\n".join(format_stop_report(r) for r in reports))
    sys.stdout.flush()
    return 0


def _write_rig(path, rig, result) -> None:
    """The identified model as a rig file (docs/rig.md), written atomically."""
    from grazing_control.plant.rig import rig_to_dict
    from grazing_control.support.files import write_yaml_atomic

    si = result["si"]
    write_yaml_atomic(path, rig_to_dict(rig),
                      [f"rig identified by `grazing identify` from {', '.join(result['bags'])} "
                       f"(with the rig of {result['rig_from']}: its forcing, mass, sensor, "
                       "actuator and budget)"]
                      + [f"{k} = {v['value']!r} +- {v['stderr']:.3g}" for k, v in si.items()])


def add_identify_parser(sub) -> None:
    """Register ``grazing identify`` on the subcommands of the ``grazing`` parser."""
    s = sub.add_parser("identify", help="the model's parameters (zeta, r, omega, delta_d, "
                                        "...) with standard errors from recorded bags")
    s.add_argument("bags", nargs="+", metavar="BAG", help="bag directories or .mcap files "
                   "(several: each fitted, their estimates combined)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.add_argument("--stop", action="store_true",
                   help="instead of the free-flight fit: which stop the bag's Pi2 samples "
                        "support (rigid, kelvin_voigt, kelvin_voigt_friction: fits with "
                        "standard errors, the least BIC chosen; the oscillator's zeta, "
                        "omega, forcing amplitude and phase and delta_d fitted with each "
                        "stop, from the bag's parameter record as the start; "
                        "docs/theory_contact.md section 17)")
    s.add_argument("--known-oscillator", action="store_true",
                   help="--stop: hold the oscillator at the bag's parameter record and fit "
                        "the stop alone (faster, about 5x)")
    s.add_argument("--max-samples", type=integer_at_least(8), default=200, metavar="N",
                   help="--stop: fit the first N Pi2 samples of each bag (>= 8; default "
                        "200)")
    s.add_argument("--out", type=non_empty_path, metavar="FILE",
                   help="write the identified model as a ROS 2 parameter file (only after a "
                        "good fit)")
    s.add_argument("--model", metavar="FILE",
                   help="an n-DOF bag's model file (docs/ndof_model.md: its n, i_w, i_a; "
                        "default: the bag's parameter record's model_file). n > 1: the wall "
                        "coordinate's modal parameters are fitted (natural frequencies, "
                        "damping ratios, its kick and forcing responses, d, r, delta_d; "
                        "the stream's position i_w read, any i_w; "
                        "docs/theory_identification.md section 11)")
    s.add_argument("--out-model", type=non_empty_path, metavar="FILE",
                   help="an n-DOF bag: write the identified model as a model file "
                        "(docs/ndof_model.md) that grazing design --model reads (only after "
                        "a good fit)")
    s.add_argument("--rig", metavar="FILE",
                   help="the rig file the bags were recorded on, for the model in SI "
                        "(natural frequency, damping ratio, restitution, gap) when the bags "
                        "carry none on grazing/rig (docs/rig.md)")
    s.add_argument("--out-rig", type=non_empty_path, metavar="FILE",
                   help="write the identified model as a rig file (the bag's or --rig's rig "
                        "with the fitted natural frequency, damping, restitution and gap; only "
                        "after a good fit)")
    s.add_argument("--no-impacts", action="store_true",
                   help="ignore the recorded impacts (oscillator/impact): find them in the "
                        "motion")
    s.add_argument("--position-only", action="store_true",
                   help="ignore the recorded velocity: fit the positions only")
    s.add_argument("--max-arcs", type=integer_at_least(2), default=None,
                   help="fit each bag up to its N-th impact or correction (the fit's time "
                        "grows as N^3, 4 s for 100 on an idle machine; a fit whose dense "
                        "Jacobian would exceed 32 MiB, about 300 arcs of the study's "
                        "stream, is refused; default 100, or fewer where a dense stream "
                        "needs it: the report says how many were used)")
    s.set_defaults(func=cmd_identify)

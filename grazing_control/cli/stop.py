"""``grazing stop``: the cheapest adequate model of a scene's stop (issue 31 part 4).

The scene's stop given in full (a Kelvin-Voigt stop: ``--stiffness`` and ``--damping``
or ``--restitution``; optional Coulomb ``--friction``), the scene's start, horizon and
controller (the rigid design for ``--c2``): which of rigid (the wall with the stop's
restitution, Eq. C3), compliant (without the friction) or compliant with friction keeps
the Pi2 error within ``--tol`` over the horizon, the cheapest chosen and the reason
printed (:func:`grazing_control.dynamics.simulation.stop_fidelity.choose_stop_fidelity`; the
criterion: docs/theory_contact.md section 18). Exit status 0; 2 for a bad value, in
one line naming it.

``grazing stop --boundary``: where the rigid design stops working for the user's
oscillator and stop: the rigid design for ``--c2`` at the stop's restitution, the
controlled 1/1 orbit of the compliant model continued in log10 k_c over
``--stiffness-range`` (default 1e8 down to 1e1), one line per crossing of the unit circle,
or the 'none' line with the largest multiplier
(:func:`grazing_control.dynamics.orbits.stop_boundary.stop_boundary`;
docs/theory_contact.md section 22). ``--rig FILE``: the oscillator, the design's r and the
stop (its type, restitution or alpha, friction) from a rig file's ``stop:`` section.
"""

from __future__ import annotations

import json
import math
import sys

from grazing_control.oscillator.params import ParameterError
from grazing_control.support.arguments import finite, integer_at_least, positive

#: the stop models (dynamics.simulation.stop_fidelity.STOP_FIDELITIES, not imported at
#: the parser's start-up)
_FIDELITIES = ("rigid", "compliant", "compliant_friction")

__all__ = ["add_stop_parser", "add_stop_options", "add_run_stop_options", "apply_run_stop",
           "cmd_stop"]


def add_run_stop_options(s) -> None:
    """``grazing run --stop``: the scene's Kelvin-Voigt stop run on its cheapest adequate
    model, or the one named, checked (:func:`apply_run_stop`)."""
    _add_choice(s, "a scene with a kelvin_voigt stop (--sim-param contact:=kelvin_voigt): run "
                   "it on auto, the cheapest adequate model (rigid: the wall with the "
                   "stop's restitution; compliant: without the friction; compliant_friction) "
                   "by the estimated Pi2 error over --periods against --stop-tol, or on the "
                   "model named, checked (a warning where its bound exceeds the tolerance); "
                   "the choice and its bound in the summary and the bag's stop_model.json "
                   "(docs/theory_contact.md section 18; default: the stop as given)")


def _add_choice(s, stop_help: str) -> None:
    """--stop (the model, or auto) and --stop-tol (its tolerance)."""
    s.add_argument("--stop", choices=("auto",) + _FIDELITIES, default=None, help=stop_help)
    s.add_argument("--stop-tol", type=positive, default=None,
                   help="tolerance on the Pi2 error after the horizon for --stop (default "
                        "1e-3)")


def apply_run_stop(args) -> dict | None:
    """``grazing run --stop``: the choice for the scene's stop, applied to the simulator's
    overrides (rigid: ``contact:=rigid`` with ``r`` the stop's restitution, Eq. C3;
    compliant: friction 0), and its report {stop, reason, estimates, warning}; None
    without --stop. The scene as sim_node will take it (its file, --sim-param,
    --delta-d, --periods) and the controller's gains where they act from the first
    sample (--enable-after 0; else the probe runs uncontrolled)."""
    if args.stop is None:
        if args.stop_tol is not None:
            raise ParameterError("--stop-tol needs --stop (auto or a model)")
        return None
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.simulation.stop_fidelity import simulate_stop_choice
    from grazing_control.oscillator.contact import KelvinVoigt
    from grazing_control.oscillator.control import Gains
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros.launcher import CONFIG_DIR
    from grazing_control.ros.scene_nodes import parameter_values

    if args.model is not None or args.rig is not None:
        raise ParameterError("--stop is invalid with --model or --rig: it chooses the model "
                             "of the 1-DOF scene's kelvin_voigt stop")
    values = {**parameter_values(args.sim_params or CONFIG_DIR / "study.yaml"),
              **dict(args.sim_overrides or {})}
    if args.delta_d is not None:
        values["delta_d"] = args.delta_d
    if args.periods is not None:
        values["max_periods"] = args.periods
    s = settings_from_values(values)
    if s.contact is None or not isinstance(s.contact.law, KelvinVoigt):
        kind = values.get("contact", "rigid")
        raise ParameterError(f"--stop needs a kelvin_voigt stop (contact={kind!r}: "
                             "give --sim-param contact:=kelvin_voigt and its stiffness and "
                             "damping)")
    if s.max_periods == 0:
        raise ParameterError("--stop needs the scene's horizon: give --periods (max_periods "
                             "is 0, unbounded)")
    p = s.params
    x = p.x_ref if math.isnan(s.x0) else s.x0
    v = p.v_ref if math.isnan(s.v0) else s.v0
    ctl = {**parameter_values(args.controller_params or CONFIG_DIR / "controller.yaml"),
           **dict(args.controller_overrides or {})}
    enable = args.enable_after if args.enable_after is not None else \
        int(ctl.get("enable_after", 1000))
    gains = None
    if enable == 0 and ctl.get("c2") is not None:
        c2 = float(ctl["c2"])
        c1 = float(ctl["c1"]) if ctl.get("c1") is not None else degenerate_c1(p, c2)
        gains = Gains(c1, c2) if math.isfinite(c1) else Gains(degenerate_c1(p, c2), c2)
    law, friction = s.contact.law, s.contact.friction
    tol = 1e-3 if args.stop_tol is None else args.stop_tol
    choice, warning = simulate_stop_choice(p, law, friction, s.max_periods,
                                           deviation=(x - p.x_ref, v - p.v_ref),
                                           gains=gains, stop=args.stop, tol=tol)
    over = dict(args.sim_overrides or {})
    if choice.stop != "compliant_friction":
        over.update(friction=0.0, friction_static=0.0)
    if choice.stop == "rigid":
        over.update(contact="rigid", r=float(law.restitution))
    args.sim_overrides = over
    return {"stop": choice.stop, "reason": choice.reason, "warning": warning, "tol": tol,
            "estimates": {k: {"one_period_error": e if math.isfinite(e) else None,
                              "bound": b if math.isfinite(b) else None}
                          for k, (e, b) in choice.estimates.items()},
            "scene_stop": {"stiffness": law.stiffness, "damping": law.damping,
                           "restitution": law.restitution,
                           "friction": 0.0 if friction is None else friction.kinetic}}


def add_stop_options(s) -> None:
    """The scene's stop and its model choice, for ``grazing simulate`` (sim_node's names,
    docs/nodes.md): the cheapest adequate model run, or the one named, checked."""
    s.add_argument("--contact", choices=("rigid", "kelvin_voigt"), default="rigid",
                   help="the stop: rigid (the wall, --r; default) or kelvin_voigt "
                        "(spring-dashpot, docs/theory_contact.md)")
    s.add_argument("--contact-stiffness", type=positive, default=None,
                   help="kelvin_voigt: the stop's stiffness k_c over the oscillator's (> 0)")
    s.add_argument("--contact-damping", type=finite, default=None,
                   help="kelvin_voigt: the stop's damping c_c (>= 0, underdamped; default: "
                        "the c_c whose restitution is --r, Eq. C3)")
    s.add_argument("--friction", type=finite, default=None,
                   help="kelvin_voigt: Coulomb friction on the mass, kinetic level F_f "
                        "(>= 0; default 0)")
    s.add_argument("--friction-static", type=finite, default=None,
                   help="static friction level F_s >= F_f (default F_f)")
    _add_choice(s, "kelvin_voigt: the model the scene runs on: auto (default) the cheapest "
                   "adequate of rigid (the wall with the stop's restitution), compliant "
                   "(without friction), compliant_friction, by the estimated Pi2 error over "
                   "the horizon against --stop-tol (docs/theory_contact.md section 18); a "
                   "model named is run and checked (a warning where its bound exceeds the "
                   "tolerance)")


#: the options of the model choice only, and of the boundary only (None: not given)
_CHOICE_ONLY = (("stiffness", "--stiffness"), ("damping", "--damping"), ("dx", "--dx"),
                ("dv", "--dv"), ("periods", "--periods"), ("tol", "--tol"))
_BOUNDARY_ONLY = (("law", "--law"), ("alpha", "--alpha"), ("stiffness_range", "--stiffness-range"),
                  ("per_decade", "--per-decade"), ("rig", "--rig"))
#: what --rig sets for --boundary (refused if given too)
_RIG_SETS = (("delta_d", "--delta-d"), ("zeta", "--zeta"), ("law", "--law"),
             ("restitution", "--restitution"), ("alpha", "--alpha"), ("friction", "--friction"),
             ("friction_static", "--friction-static"))


def _given(args, pairs) -> list:
    return [flag for attr, flag in pairs if getattr(args, attr, None) is not None]


def _boundary_inputs(args):
    """(OscillatorParams, stop_boundary's keywords, the rig's own k_c or None) from the
    options or ``--rig``; a ParameterError line naming the option otherwise."""
    from grazing_control.oscillator.contact import KelvinVoigt
    from grazing_control.oscillator.params import OscillatorParams

    if args.rig is not None:
        both = _given(args, _RIG_SETS)
        if both:
            raise ParameterError(f"--rig FILE and {', '.join(both)} are both given: the rig's "
                                 "stop section and model set them (docs/rig.md); give one")
        from .rig import load

        rig = load(args.rig)
        st = rig.contact_values()
        if st["contact"] == "rigid":
            raise ParameterError(f"--rig {args.rig}: stop.type is rigid: --boundary needs a "
                                 "compliant stop (stop.type kelvin_voigt or hertz)")
        p = rig.params()
        kw = {"law": st["contact"], "friction": st["friction"],
              "friction_static": st["friction_static"] if st["friction"] > 0.0 else None}
        if st["contact"] == "hertz":
            kw["alpha"] = st["contact_damping"]
        else:
            kw["restitution"] = KelvinVoigt(st["contact_stiffness"],
                                            st["contact_damping"]).restitution
        if not p.delta_d < 0.0:
            raise ParameterError(f"--rig {args.rig}: its Delta d = {p.delta_d!r} >= 0 (the gap "
                                 "at or beyond grazing): --boundary needs the controlled 1/1 "
                                 "orbit, Delta d < 0")
        return p, kw, st["contact_stiffness"]
    law = args.law or "kelvin_voigt"
    r = 0.68 if args.restitution is None else args.restitution
    if law == "kelvin_voigt" and args.alpha is not None:
        raise ParameterError("--alpha is Hertz's (--law hertz): a Kelvin-Voigt stop is given "
                             "by --restitution")
    if law == "kelvin_voigt" and not math.exp(-2.0) < r <= 1.0:
        raise ParameterError(f"--restitution={r!r} is invalid: a Kelvin-Voigt stop reaches "
                             "exp(-2) < r <= 1 (Eq. C3)")
    if not 0.0 < r <= 1.0:
        raise ParameterError(f"--restitution={r!r} is invalid: valid range is 0 < r <= 1")
    if args.alpha is not None and not args.alpha >= 0.0:
        raise ParameterError(f"--alpha={args.alpha!r} is invalid: valid range is alpha >= 0")
    dd = -0.05 if args.delta_d is None else args.delta_d
    if not dd < 0.0:
        raise ParameterError(f"--delta-d={dd!r} is invalid: --boundary needs Delta d < 0 (the "
                             "controlled 1/1 orbit impacts)")
    fr = 0.0 if args.friction is None else args.friction
    if not fr >= 0.0:
        raise ParameterError(f"--friction={fr!r} is invalid: valid range is F_f >= 0")
    if args.friction_static is not None and not (fr > 0.0 and args.friction_static >= fr):
        raise ParameterError(f"--friction-static={args.friction_static!r} is invalid: valid "
                             f"range is F_s >= --friction = {fr!r} > 0")
    try:
        p = OscillatorParams(delta_d=dd, r=r, zeta=0.01 if args.zeta is None else args.zeta)
    except ParameterError as exc:
        name = str(exc).split("=", 1)[0]
        raise ParameterError(f"--{name.replace('_', '-')}={str(exc).split('=', 1)[1]}") \
            from None
    return p, {"law": law, "friction": fr, "friction_static": args.friction_static,
               "alpha": args.alpha}, None


def _cmd_boundary(args) -> int:
    """``grazing stop --boundary`` (module docstring)."""
    from grazing_control.dynamics.orbits.stop_boundary import SOFT, STIFF, stop_boundary

    given = _given(args, _CHOICE_ONLY)
    if given:
        raise ParameterError(f"{', '.join(given)}: the model choice's, invalid with "
                             "--boundary (it continues over --stiffness-range)")
    p, kw, rig_k = _boundary_inputs(args)
    c2 = -1.0 if args.c2 is None else args.c2
    hi, lo = args.stiffness_range or (STIFF, SOFT)
    if not (hi > 0.0 and lo > 0.0 and hi != lo):
        raise ParameterError(f"--stiffness-range={hi!r} {lo!r} is invalid: two different "
                             "k_c > 0, the stiff end first")
    try:
        sb = stop_boundary(p, c2, stiffness_range=(hi, lo), per_decade=args.per_decade or 2,
                           **kw)
    except ParameterError as exc:     # the library's names as the options'
        text = str(exc)
        raise ParameterError(f"--{text}" if text.startswith("c2=") else text) from None
    lines = sb.lines(hi, lo)
    out = {"delta_d": p.delta_d, "zeta": p.zeta, "r": p.r,
           "stiffness_range": [hi, lo], **sb.as_dict(), "lines": lines}
    if rig_k is not None:
        side = _side(sb, rig_k)
        out["rig_stiffness"] = {"stiffness": rig_k, "side": side}
        lines.append(f"the rig's stop: k_c = {rig_k:.6g}, {side}")
    if args.json:
        json.dump(out, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print("\n".join(lines))
    return 0


def _side(sb, k) -> str:
    """Where k_c = k lies on the continued branch (:meth:`StopBoundary.at`), in words."""
    near = sb.at(k)
    if near is None:
        return "outside the range continued"
    rho = float(max(abs(near.multipliers)))
    return (f"the rigid design {'fails' if rho > 1.0 else 'holds'} there (largest multiplier "
            f"{rho:.3f} at the branch's nearest point, k_c = {10.0 ** near.value:.4g})")


def cmd_stop(args) -> int:
    """Run ``grazing stop``; the exit status (module docstring)."""
    if args.boundary:
        return _cmd_boundary(args)
    given = _given(args, _BOUNDARY_ONLY)
    if given:
        raise ParameterError(f"{', '.join(given)}: valid only with --boundary")
    if args.stiffness is None:
        raise ParameterError("--stiffness is missing: the stop's stiffness k_c over the "
                             "oscillator's (> 0); or give --boundary")
    for attr, default in (("dx", 0.0), ("dv", 0.0), ("periods", 100), ("tol", 1e-3),
                          ("friction", 0.0), ("delta_d", -0.05), ("zeta", 0.01)):
        if getattr(args, attr) is None:
            setattr(args, attr, default)
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.simulation.stop_fidelity import choose_stop_fidelity
    from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
    from grazing_control.oscillator.control import Gains
    from grazing_control.oscillator.params import OscillatorParams

    p = OscillatorParams(delta_d=args.delta_d, zeta=args.zeta)
    if (args.damping is None) == (args.restitution is None):
        raise ParameterError("--damping and --restitution: give exactly one (the stop's "
                             "damping c_c, or the restitution r it stands for, Eq. C3)")
    law = (KelvinVoigt(args.stiffness, args.damping) if args.damping is not None
           else KelvinVoigt.from_restitution(args.stiffness, args.restitution))
    friction = Coulomb(args.friction, args.friction_static) if args.friction > 0.0 else None
    gains = Gains(degenerate_c1(p, args.c2), args.c2) if args.c2 is not None else None
    choice = choose_stop_fidelity(p, law, friction, args.periods, args.tol,
                                  deviation=(args.dx, args.dv), gains=gains)
    def plain(x):   # standard JSON: a refused candidate's inf as null
        return x if math.isfinite(x) else None
    out = {"stop": choice.stop, "reason": choice.reason,
           "estimates": {k: {"one_period_error": plain(e), "bound": plain(b)}
                         for k, (e, b) in choice.estimates.items()}}
    if args.json:
        json.dump(out, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(f"stop model = {choice.stop}\n  {choice.reason}")
    return 0


def add_stop_parser(sub) -> None:
    """Register ``grazing stop`` on the subcommands of the ``grazing`` parser."""
    s = sub.add_parser("stop", help="the cheapest adequate model of a scene's stop: rigid, "
                                    "compliant, or compliant with friction")
    s.add_argument("--stiffness", type=positive, default=None,
                   help="the stop's stiffness k_c over the oscillator's (> 0; required "
                        "without --boundary)")
    s.add_argument("--damping", type=finite, help="the stop's damping c_c (>= 0, "
                   "underdamped); or give --restitution")
    s.add_argument("--restitution", type=finite, help="the restitution r the stop stands "
                   "for (Eq. C3, exp(-2) < r <= 1); or give --damping. --boundary: the "
                   "stop's and the design's r (default 0.68)")
    s.add_argument("--friction", type=finite, default=None,
                   help="Coulomb friction on the mass, kinetic level F_f (>= 0; default 0)")
    s.add_argument("--friction-static", type=finite, default=None,
                   help="static level F_s >= F_f (default F_f; --boundary: 1.2 F_f, the "
                        "chart's)")
    s.add_argument("--delta-d", type=finite, default=None, help="the scene's Delta d "
                   "(default -0.05)")
    s.add_argument("--zeta", type=finite, default=None, help="damping ratio (default 0.01)")
    s.add_argument("--c2", type=finite, default=None, help="the scene's controller: the "
                   "rigid design for this c2 (c1 of Eq. 38) from the first sample; default "
                   "none (--boundary: the design's c2, default -1)")
    s.add_argument("--dx", type=finite, default=None, help="the start, x - x** on Pi2 "
                   "(default 0)")
    s.add_argument("--dv", type=finite, default=None, help="the start, v - v** on Pi2 "
                   "(default 0)")
    s.add_argument("--periods", type=integer_at_least(1), default=None,
                   help="the scene's horizon N (default 100)")
    s.add_argument("--tol", type=positive, default=None,
                   help="tolerance on the Pi2 error after N periods (default 1e-3)")
    b = s.add_argument_group(
        "the boundary of the rigid design (--boundary; docs/theory_contact.md section 22)")
    b.add_argument("--boundary", action="store_true",
                   help="where the rigid design for --c2 stops working on this stop: the "
                        "controlled 1/1 orbit continued in log10 k_c over --stiffness-range, "
                        "one line per crossing of the unit circle (or none, with the "
                        "largest multiplier)")
    b.add_argument("--law", choices=("kelvin_voigt", "hertz"), default=None,
                   help="the stop law: kelvin_voigt (default; at fixed --restitution) or "
                        "hertz (Hunt-Crossley, at fixed --alpha)")
    b.add_argument("--alpha", type=finite, default=None,
                   help="hertz: Hunt-Crossley alpha >= 0 (default (1 - r) / v- at the rigid "
                        "orbit's impact, Eq. C5)")
    b.add_argument("--stiffness-range", type=positive, nargs=2, default=None,
                   metavar=("STIFF", "SOFT"),
                   help="k_c from STIFF down to SOFT (default 1e8 1e1)")
    b.add_argument("--per-decade", type=integer_at_least(1), default=None,
                   help="continuation points a decade (default 2; crossings are located "
                        "between them to 1e-13)")
    b.add_argument("--rig", metavar="FILE", default=None,
                   help="the oscillator, the design's r and the stop (its stop: section: "
                        "type, damping as restitution or alpha, friction) from a rig file "
                        "(docs/rig.md); the rig's own k_c placed on the chart")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_stop)

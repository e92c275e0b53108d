"""The `grazing` command line: design, orbit, continue, simulate, run, demo, robustness.

Every subcommand shares --zeta --r --omega --pi2-offset (defaults: the study's set).
Output is human-readable by default; with --json exactly one JSON object goes to
stdout and nothing else. User errors (bad parameters, no orbit) print one line
``grazing: error: ...`` to stderr and exit with status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import sys
import time
import warnings

import numpy as np

from grazing_control.support.arguments import (finite, integer_at_least, non_empty_path,
                                               non_negative)
from . import ndof
from .parameter_file import add_params_option, apply_to_args
from .rig import add_rig_option, apply_rig
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import (STUDY_R, STUDY_ZETA, OscillatorParams,
                                               ParameterError, study_omega)

__all__ = ["main", "build_parser"]

TWO_PI = 2.0 * math.pi


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``grazing <command>: error: ...``, exit status 2.

    A negative number in exponent form (``--delta-d -5e-6 -1e-6``) is a value, not an
    option: argparse's own pattern only knows ``-1`` and ``-1.5``, so the second value of
    a list was taken for an unknown option.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message):
        command = self.prog.split()[-1]
        where = "" if command == "grazing" else f"{command}: "
        self.exit(2, f"grazing: error: {where}{message}\n")


_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|nan)$", re.IGNORECASE)


def _complex_list(values):
    return [[float(np.real(z)), float(np.imag(z))] for z in values]


_finite = finite
_count = integer_at_least(0)
_path = non_empty_path


def _non_finite(obj, where=""):
    """Key paths of the non-finite floats in a result (nested dicts and lists)."""
    if isinstance(obj, float):
        return [] if math.isfinite(obj) else [f"{where}={obj!r}"]
    if isinstance(obj, dict):
        return [w for k, v in obj.items() for w in _non_finite(v, f"{where}.{k}" if where else k)]
    if isinstance(obj, (list, tuple)):
        return [w for i, v in enumerate(obj) for w in _non_finite(v, f"{where}[{i}]")]
    return []


def _require_finite(out, command):
    """A result with nan/inf is an input outside the computable range: say so (status 2)."""
    bad = _non_finite(out)
    if bad:
        raise ParameterError(
            f"{command}: the result is not finite ({', '.join(bad[:3])}"
            f"{', ...' if len(bad) > 3 else ''}): an input is outside the computable range")


def _nulls(obj):
    """nan/inf -> None (JSON null), recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _nulls(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nulls(v) for v in obj]
    return obj


def _common(parser):
    g = parser.add_argument_group("model (defaults: the study's parameter set)")
    g.add_argument("--zeta", type=_finite, default=STUDY_ZETA, help="damping ratio, 0 < zeta < 1")
    g.add_argument("--r", type=_finite, default=STUDY_R, help="restitution, 0 < r < 1")
    g.add_argument("--omega", type=_finite, default=study_omega(), help="forcing frequency > 0")
    g.add_argument("--pi2-offset", type=_finite, default=math.pi / 2,
                   help="phase of Pi2 after Pi1, in (0, 2 pi)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_params_option(g)
    add_rig_option(g)


def _method_arg(parser):
    parser.add_argument("--method", choices=("exact", "perturbation"), default="exact",
                        help="exact (shooting, the accurate route) or perturbation (series in "
                             "delta2, the fast estimate); the cost is reported")


def _gain_args(parser, required=False):
    parser.add_argument("--c1", type=_finite, help="gain c1 (default: degenerate condition Eq. 38)")
    parser.add_argument("--c2", type=_finite, required=required, help="gain c2")
    _delay_arg(parser)


def _delay_arg(parser):
    parser.add_argument("--delay", type=_finite, default=0.0,
                        help="actuation delay: the correction acts this long (simulation time) "
                             "after the Pi2 sample, 0 <= delay < T - pi2_offset/omega "
                             "(docs/theory_delay.md); default 0")


#: Largest zeta T (forcing periods' decay exponent) the commands accept: e^{-2 zeta T}
#: underflows near 700 and the period maps become 0.
_MAX_DECAY = 300.0


def _params(args, delta_d=0.0):
    p = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, delta_d=delta_d,
                         pi2_offset=args.pi2_offset)
    if not 1e-100 < p.amplitude < 1e100:
        raise ParameterError(
            f"omega={p.omega!r} is invalid with zeta={p.zeta!r}: the non-impacting amplitude "
            f"a(omega) = {p.amplitude:.3g} is outside the computable range (1e-100, 1e100)")
    if not p.zeta * p.period <= _MAX_DECAY:
        raise ParameterError(
            f"omega={p.omega!r} is invalid with zeta={p.zeta!r}: valid range is "
            f"omega >= 2 pi zeta / {_MAX_DECAY:g} = {TWO_PI * p.zeta / _MAX_DECAY:.3g} "
            f"(the decay e^(-zeta T) over a forcing period underflows)")
    return p


def _gains(args, p):
    delay = getattr(args, "delay", 0.0)
    if args.c2 is None:
        if args.c1 is not None:
            raise ParameterError("c1 given without c2: give both, or c2 alone (c1 from Eq. 38)")
        if delay != 0.0:
            raise ParameterError("--delay needs the gains: give --c2 (and optionally --c1)")
        return None
    from grazing_control.dynamics.design import degenerate_c1

    c1 = degenerate_c1(p, args.c2, delay) if args.c1 is None else args.c1
    return Gains(c1, args.c2, delay)


# ---------------------------------------------------------------------------- design
def cmd_design(args):
    if args.model is not None:
        return ndof.cmd_design(args)
    from grazing_control.dynamics.design import (C2_LIMIT, admissible_c2, evaluate_design,
                                                 write_controller_yaml)

    p = _params(args)
    t0 = time.perf_counter()
    tuned = None
    if args.optimize is not None:
        if args.c2 is not None:
            raise ParameterError("c2 is given with --optimize: give one of --c2 and --optimize")
        tuned = _optimize(args, p)
        args.c2 = tuned["c2"]
    elif args.c2 is None:
        raise ParameterError("c2 is missing: give --c2 (the chosen gain) or --optimize noise")
    point = evaluate_design(p, args.c2, args.delay)
    sets = {c: admissible_c2(p, delay=args.delay, conditions=c)
            for c in ("combined", "impacting", "non-impacting")}
    cost = time.perf_counter() - t0
    other = None
    if args.method == "perturbation":
        from grazing_control.dynamics.perturbation import (admissible_c2_perturbation,
                                                           existence_coefficient_perturbation,
                                                           limit_multipliers_perturbation)

        t0 = time.perf_counter()
        g = point.gains()
        lam_p = limit_multipliers_perturbation(p, g)
        gamma_p = existence_coefficient_perturbation(p, g)
        sets_p = {c: admissible_c2_perturbation(p, delay=args.delay, conditions=c) for c in sets}
        cost_p = time.perf_counter() - t0
        other = {"exact": {"admissible_c2": [_json_interval(iv) for iv in sets["combined"]],
                           "multipliers_limit": _complex_list(point.multipliers_limit),
                           "gamma1": point.gamma1, "seconds": cost}}
        exact_combined = sets["combined"]
        point = type(point)(point.c1, point.c2, lam_p, gamma_p, point.multipliers_free, point.delay)
        sets, cost = sets_p, cost_p
        ends = [(a - b) for iv, jv in zip(sets["combined"], exact_combined) for a, b in zip(iv, jv)
                if math.isfinite(a) and math.isfinite(b)]
        other["difference_admissible_ends"] = ends
    intervals = sets["combined"]
    chosen = next((iv for iv in intervals if iv[0] <= args.c2 <= iv[1]), None)
    shown = chosen or (max(intervals, key=lambda iv: iv[1] - iv[0]) if intervals else None)
    rho_free = float(np.max(np.abs(point.multipliers_free)))
    out = {
        "c1": point.c1,
        "c2": point.c2,
        "actuation_delay": point.delay,
        "x_ref": p.x_ref,
        "v_ref": p.v_ref,
        "admissible_c2": _json_interval(shown) if shown else None,
        "admissible_c2_sets": {c: [_json_interval(iv) for iv in ivs] for c, ivs in sets.items()},
        "c2_search_limit": C2_LIMIT,
        "multipliers_limit": _complex_list(point.multipliers_limit),
        "gamma1": point.gamma1,
        "multipliers_free": _complex_list(point.multipliers_free),
        "spectral_radius_free": rho_free,
        "conditions": {"limit_stable": point.stable, "exists_impacting": point.gamma1 > 0.0,
                       "free_stable": point.free_stable},
        "admissible": point.admissible,
        "admissible_impacting": point.admissible_impacting,
        "method": args.method,
        "seconds": cost,
    }
    if other is not None:
        out["comparison"] = other
    noise = None
    if args.delta_d is not None or tuned is not None:
        noise = _noise_report(args, p, point)
        out.update(noise)
    if tuned is not None:
        out["optimize"] = tuned
    gains = point.gains()
    if any(getattr(args, k, 0.0) for k in ("actuator_bandwidth", "actuator_latency",
                                           "pulse_width")):
        gains, out["actuator"] = _actuator_report(args, p, point)
        out["c1_ideal"], out["c1"] = out["c1"], gains.c1
    _require_finite(out, "design")
    if args.out:
        if not point.admissible:
            raise ParameterError(
                f"c2={args.c2!r} is not admissible: valid range is {_fmt_intervals(intervals)}; "
                f"nothing written to {args.out}")
        write_controller_yaml(args.out, p, gains)
    if args.json:
        return out
    lam = ", ".join(f"{abs(z):.6g}" for z in point.multipliers_limit)
    ok = {True: "yes", False: "NO"}
    delay = f", actuation delay {point.delay:.12g}" if point.delay else ""
    lines = [
        f"degenerate grazing design (N_g,12 = 0, Eq. 38) for c2 = {point.c2:.12g}{delay}",
        f"  c1                 = {point.c1:.15g}",
        f"  X** on Pi2         = ({p.x_ref:.15g}, {p.v_ref:.15g})",
        f"  |lambda0|          = {lam}  (limit Delta d -> 0-: {ok[point.stable]} < 1)",
        f"  gamma1             = {point.gamma1:.6g}  (> 0: 1/1 motion exists for d < d*: "
        f"{ok[point.gamma1 > 0.0]})",
        f"  rho(N_g)           = {rho_free:.6g}  (non-impacting motion, d > d*: "
        f"{ok[point.free_stable]} < 1)",
        f"  admissible c2      = {_fmt_intervals(intervals)}  (all three conditions)",
        f"    impacting side   = {_fmt_intervals(sets['impacting'])}  (|lambda0| < 1, gamma1 > 0)",
        f"    non-impacting    = {_fmt_intervals(sets['non-impacting'])}  (rho(N_g) < 1)",
        f"  this c2            : {'admissible' if point.admissible else 'NOT admissible'}",
        f"  method             : {args.method} ({cost:.3g} s)",
    ]
    if noise is not None:
        gain = noise["noise_gain"]
        lines.append(f"  noise gain         = {'none (no stable controlled orbit)' if gain is None else f'{gain:.4g}'}"
                     f"  (std of the Pi2 position per unit measurement noise on x and v, "
                     f"Delta d = {noise['noise_gain_delta_d']:.3g})")
        pos = noise["noise_gain_position_only"]
        sensor = noise["position_only_sensor"]
        lines.append(f"  position only      = {'none' if pos is None else f'{pos:.4g}'}"
                     f"  (a position sensor at {sensor['samples_per_period']} samples per "
                     f"period, {sensor['estimator']} estimator, per unit sigma)")
    if tuned is not None:
        study = tuned["study_noise_gain"]
        lines.append(f"  optimised          : least noise gain in {_fmt_intervals([tuned['interval']])}"
                     f" ({tuned['evaluations']} evaluations); the study's c2 = {tuned['study_c2']:g}: "
                     + ("no stable controlled orbit with this delay" if study is None
                        else f"{study:.4g} ({study / tuned['noise_gain']:.3g}x)"))
    if other is not None:
        lines.append(f"  exact route        : admissible c2 = "
                     f"{_fmt_intervals(other['exact']['admissible_c2'])} ({other['exact']['seconds']:.3g} s); "
                     f"end differences {other['difference_admissible_ends']}")
    if "actuator" in out:
        a = out["actuator"]
        lines.append(f"  through the actuator: c1 = {gains.c1:.15g} (exact N_g,12 = 0 for the "
                     f"force profile, (P1); tau_a {a['time_constant']:.6g}, latency "
                     f"{a['latency']:.6g}, pulse {a['pulse_width']:.6g})")
        if a["spectral_radius"] is None:
            lines.append(f"    no 1/1 orbit through the actuator at Delta d = {a['delta_d']:.3g}")
        else:
            both, pos = (("none" if v is None else f"{v[0]:.4g}")
                         for v in (a["spread"], a["spread_position_only"]))
            offset = a["orbit_offset"]
            lines.append(f"    at Delta d = {a['delta_d']:.3g}: spectral radius "
                         f"{a['spectral_radius']:.6g}, orbit x - x** "
                         f"{'?' if offset is None else f'{offset[0]:.3g}'}, spread (std x "
                         f"per sigma) {both} (x, v measured), {pos} (position only)")
    if args.out:
        lines.append(f"  controller parameters written to {args.out}")
    return "\n".join(lines)


def _actuator_report(args, p, point):
    """--actuator-bandwidth/--actuator-latency/--pulse-width: the design through the
    first-order actuator (dynamics.actuator.actuated_design, docs/theory_pulse.md (P1)
    and section 7): its gains, and at --delta-d (default -5e-6) the loop's orbit, spectral
    radius and predicted spread (x and v measured with sigma; a position-only sensor at
    --sensor-rate with the chosen estimator)."""
    from grazing_control.dynamics.actuator import Actuator, actuated_design
    from grazing_control.dynamics.design import degenerate_c1
    from grazing_control.dynamics.estimation import estimate_covariance
    from grazing_control.dynamics.orbits import OrbitNotFound, orbit_11

    bw, lat, w = args.actuator_bandwidth, args.actuator_latency, args.pulse_width
    for name, value in (("actuator_bandwidth", bw), ("actuator_latency", lat),
                        ("pulse_width", w)):
        if not value >= 0.0:
            raise ParameterError(f"{name}={value!r} is invalid: valid range is {name} >= 0")
    if not w > 0.0:
        raise ParameterError(f"pulse_width={w!r} is invalid with an actuator: valid range is "
                             "pulse_width > 0 (the design is for the pulse's force profile)")
    actuator = Actuator(1.0 / bw if bw > 0.0 else 0.0, lat)
    q = p.with_(delta_d=_noise_delta_d(args))
    _gains_, orbit, spread = actuated_design(q, point.c2, point.delay, w, actuator)
    report = {"time_constant": actuator.time_constant, "latency": lat, "pulse_width": w,
              "bandwidth": bw, "bandwidth_over_omega": bw / p.omega, "delta_d": q.delta_d,
              "spectral_radius": None, "spread": None, "spread_position_only": None,
              "orbit_offset": None}
    if orbit is not None:
        report.update(spectral_radius=orbit.spectral_radius,
                      spread=None if spread is None else [float(x) for x in spread])
        try:
            kick = Gains(degenerate_c1(q, point.c2, point.delay), point.c2, point.delay)
            x_star = orbit_11(q, kick).pi2_deviation
            report["orbit_offset"] = [orbit.state[0] - x_star[0], orbit.state[1] - x_star[1]]
            r = estimate_covariance(q, kick, args.sensor_rate, estimator=args.estimator)
            report["spread_position_only"] = [float(x) for x in np.sqrt(np.diag(
                orbit.noise_covariance(_gains_, r)))]
        except (OrbitNotFound, ValueError, ArithmeticError):
            pass
    return _gains_, report


def _noise_delta_d(args):
    """Delta d of the noise gain: --delta-d, or the study's first scene for --optimize."""
    dd = -5e-6 if args.delta_d is None else args.delta_d
    if not dd < 0.0:
        raise ParameterError(f"delta_d={dd!r} is invalid: the noise gain is that of the "
                             f"controlled 1/1 orbit, valid range is delta_d < 0")
    return dd


def _optimize(args, p):
    """--optimize noise: the c2 of least noise gain (dynamics.tuning.optimize_noise)."""
    from grazing_control.dynamics.tuning import STUDY_C2, optimize_noise

    r = optimize_noise(p.with_(delta_d=_noise_delta_d(args)), args.delay)
    study = r.study_noise_gain if math.isfinite(r.study_noise_gain) else None
    return {"objective": args.optimize, "delta_d": r.delta_d, "c2": r.c2, "c1": r.c1,
            "noise_gain": r.noise_gain, "interval": _json_interval(r.interval),
            "study_c2": STUDY_C2, "study_noise_gain": study, "evaluations": r.evaluations}


def _noise_report(args, p, point):
    """noise_gain (null where no stable controlled orbit) at --delta-d, issue 15 section 3."""
    from grazing_control.dynamics.tuning import design_noise_gain

    from grazing_control.dynamics.design import degenerate_c1
    from grazing_control.dynamics.estimation import estimate_covariance
    from grazing_control.dynamics.orbits import OrbitNotFound

    dd = _noise_delta_d(args)
    q = p.with_(delta_d=dd)
    gain = design_noise_gain(q, point.c2, point.delay)
    out = {"noise_gain": gain if math.isfinite(gain) else None, "noise_gain_delta_d": dd}
    # the position-only sensor (issue 15 section 3): the estimate's covariance per unit
    # sigma^2 of the chosen estimator at --sensor-rate samples per period (E7)
    try:
        g = Gains(degenerate_c1(q, point.c2, point.delay), point.c2, point.delay)
        r = estimate_covariance(q, g, args.sensor_rate, estimator=args.estimator,
                                lead=args.sensor_lead)
        pos = design_noise_gain(q, point.c2, point.delay, measurement=r)
    except (OrbitNotFound, ValueError, ArithmeticError):
        pos = math.inf
    out.update(noise_gain_position_only=pos if math.isfinite(pos) else None,
               position_only_sensor={"samples_per_period": args.sensor_rate,
                                     "estimator": args.estimator,
                                     "lead": args.sensor_lead})
    return out


def _fmt_intervals(intervals):
    """'(lo, hi) U ...'; an end open at the search limit reads 'beyond -1e+06' (design.C2_LIMIT)."""
    from grazing_control.dynamics.design import C2_LIMIT

    def end(x, sign):
        if x is None or not math.isfinite(x):
            return f"beyond {sign}{C2_LIMIT:.0e}"
        return f"{x:.10g}"

    return " U ".join(f"({end(lo, '-')}, {end(hi, '+')})" for lo, hi in intervals) or "empty"


def _json_interval(iv):
    """[lo, hi] with an end open at the search limit as null (the key c2_search_limit)."""
    return [x if math.isfinite(x) else None for x in iv]


# ---------------------------------------------------------------------------- orbit
def cmd_orbit(args):
    if args.model is not None:
        return ndof.cmd_orbit(args)
    from grazing_control.dynamics.orbits import orbit_11

    p = _params(args, args.delta_d)
    gains = _gains(args, p)
    t0 = time.perf_counter()
    o = orbit_11(p, gains)
    lam = o.multipliers
    cost = time.perf_counter() - t0
    if args.method == "perturbation":
        from grazing_control.dynamics.perturbation import perturbation_multipliers

        if o.branch != "grazing":
            raise ParameterError(
                f"--method perturbation is a series about grazing on the branch born there; "
                f"the 1/1 orbit at delta_d={p.delta_d!r} is not near grazing (branch: "
                f"{_BRANCH_TEXT.get(o.branch, o.branch)}; v- = {o.v_minus:.3g}): use --method exact")

        t0 = time.perf_counter()
        lam = perturbation_multipliers(p, gains)
        cost = time.perf_counter() - t0
    out = {
        "delta_d": o.params.delta_d,
        "impact_phase": o.impact_phase,
        "v_minus": o.v_minus,
        "section_pi2": list(o.pi2),
        "multipliers": _complex_list(lam),
        "stable": bool(np.max(np.abs(lam)) < 1.0),
        "branch": o.branch,
        "method": args.method,
        "seconds": cost,
    }
    if gains is not None and gains.delay:
        out.update(c1=gains.c1, c2=gains.c2, actuation_delay=gains.delay,
                   section_pi2_deviation=list(o.pi2_deviation))
    _require_finite(out, "orbit")
    if args.json:
        return out
    lam = ", ".join(f"{z:.6g}" for z in lam)
    ctl = f" with c1={gains.c1:.6g}, c2={gains.c2:.6g}" if gains else " (uncontrolled)"
    if gains is not None and gains.delay:
        ctl += f", actuation delay {gains.delay:.6g}"
    return "\n".join([
        f"1/1 orbit at Delta d = {o.params.delta_d:.6g}{ctl}",
        f"  impact phase  = {o.impact_phase:.15g}",
        f"  v-            = {o.v_minus:.10g}",
        f"  Pi2 point     = ({o.pi2[0]:.15g}, {o.pi2[1]:.15g})",
        f"  multipliers   = {lam}  ({args.method}, {cost:.3g} s)",
        f"  stable        = {out['stable']}",
        f"  branch        = {_BRANCH_TEXT.get(o.branch, o.branch)}",
    ])


_BRANCH_TEXT = {
    "grazing": "born at grazing (v- -> 0 as Delta d -> 0)",
    "grazing past a fold": "born at grazing, past a fold (saddle-node): far from grazing",
    "other": "another 1/1 branch, not connected to grazing",
}


# ---------------------------------------------------------------------------- continue
def cmd_continue(args):
    if args.model is not None:
        return ndof.cmd_continue(args)
    from grazing_control.dynamics.continuation import continue_11

    p = _params(args)
    gains = _gains(args, p)
    branch = continue_11(p, args.start, args.stop, gains, points=args.points, check=True)
    out = {
        "branch": [
            {"delta_d": b.delta_d, "v_minus": b.v_minus,
             "multipliers": _complex_list(b.multipliers), "stable": b.stable}
            for b in branch.points
        ],
        "bifurcations": [
            {"type": b.type, "delta_d": b.delta_d, "multipliers": _complex_list(b.multipliers)}
            for b in branch.bifurcations
        ],
    }
    if args.json:
        return _nulls(out)  # inf multipliers at the grazing point itself -> null
    lines = [f"1/1 branch, {len(branch.points)} points from Delta d = {args.start:g} to {args.stop:g}",
             f"{'Delta d':>14} {'v-':>14} {'max|lambda|':>14} stable"]
    step = max(1, len(branch.points) // 20)
    for b in branch.points[::step]:
        lines.append(f"{b.delta_d:14.6e} {b.v_minus:14.6e} {np.max(np.abs(b.multipliers)):14.6e} {b.stable}")
    lines.append("bifurcations:" if branch.bifurcations else "bifurcations: none in range")
    for b in branch.bifurcations:
        lines.append(f"  {b.type:16s} at Delta d = {b.delta_d:.15g}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------- simulate
def cmd_simulate(args):
    if args.model is not None:
        return ndof.cmd_simulate(args)
    from grazing_control.dynamics.simulate import simulate

    p = _params(args, args.delta_d)
    gains = _gains(args, p)
    if args.control_after is not None and gains is None:
        raise ParameterError("--control-after needs the gains: give --c2 (and optionally --c1)")
    control_after = args.control_after if args.control_after is not None else (0 if gains else None)
    physical = args.x0 is not None or args.v0 is not None
    deviation = None
    if args.dx0 is not None or args.dv0 is not None:
        if physical:
            raise ParameterError("--x0/--v0 and --dx0/--dv0 both given: give the initial state "
                                 "in one form (physical, or deviation from X**)")
        deviation = (args.dx0 or 0.0, args.dv0 or 0.0)
    progress = (not args.json and args.periods >= 2000 and sys.stderr.isatty())
    res = simulate(p, args.periods, x0=args.x0, v0=args.v0, deviation=deviation, gains=gains,
                   control_after=control_after, fidelity=args.fidelity, tol=args.tol,
                   progress=progress)
    out = {"pi2": res.pi2.tolist(), "impacts_per_period": res.impacts_per_period.tolist()}
    if args.fidelity != "exact":
        out.update(fidelity=res.fidelity, fidelity_reason=res.fidelity_reason)
    _require_finite(out, "simulate")
    spectrum = None
    if args.lyapunov:
        from grazing_control.dynamics.lyapunov import lyapunov_exact

        if args.fidelity != "exact" or args.periods < 2:
            raise ParameterError("--lyapunov needs --fidelity exact and --periods >= 2 (the "
                                 "exponents average the last half of the periods)")
        start = (res.pi2[0][0] - p.x_ref, res.pi2[0][1] - p.v_ref)
        spectrum = lyapunov_exact(p, start, args.periods, args.periods // 2, gains,
                                  control_after)
        out["lyapunov"] = {"exponents": list(spectrum.exponents),
                           "periods": spectrum.periods,
                           "impacts_per_period": spectrum.impacts_per_period,
                           "stuck_periods": spectrum.stuck_periods,
                           "expected_sum": spectrum.expected_sum,
                           "sum_residual": spectrum.sum_residual}
    if args.json:
        return out
    n = args.periods
    tail = res.impacts_per_period[-min(n, 20):].tolist()
    last = (f"({res.pi2[-1][0]:.15g}, {res.pi2[-1][1]:.15g})" if n else "none (0 periods)")
    return "\n".join([
        f"simulated {n} periods at Delta d = {p.delta_d:.6g}"
        + (f", control on from sample {control_after}" if gains is not None else ", uncontrolled"),
        f"  impacts in all     = {int(res.impacts_per_period.sum())}",
        f"  impacts per period, last {len(tail)}: {tail}",
        f"  last Pi2 sample    = {last}",
        f"  model              = {res.fidelity_reason}",
    ] + ([] if spectrum is None else [
        f"  Lyapunov exponents = {spectrum.exponents[0]:.10g}, {spectrum.exponents[1]:.10g} "
        f"per period (last {spectrum.periods} periods, {spectrum.impacts_per_period:.4g} "
        "impacts per period)",
        f"  sum identity       = {spectrum.expected_sum:.15g} (-2 zeta T + 2 nu ln r"
        f"{' + ln|1 + c2| share' if gains is not None else ''}), residual "
        f"{spectrum.sum_residual:.2e}"
        + (f"; {spectrum.stuck_periods} periods stuck (singular map)"
           if spectrum.stuck_periods else "")]))


# ---------------------------------------------------------------------------- run / demo
@contextlib.contextmanager
def _stdout_to_stderr():
    """Send this process's stdout, and that of the processes it starts, to stderr."""
    sys.stdout.flush()
    try:
        fd = sys.stdout.fileno()
        saved = os.dup(fd)
    except (AttributeError, OSError, ValueError):  # no real file descriptor (captured)
        fd = saved = None
    try:
        if fd is not None:
            os.dup2(sys.stderr.fileno(), fd)
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        if fd is not None:
            sys.stderr.flush()
            os.dup2(saved, fd)
            os.close(saved)


def _live_port(text: str) -> int:
    """``--live PORT``: an integer 0..65535 (0: any free port, which live_node logs)."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: valid range is an integer "
                                         "0..65535 (0: any free port)")
    return port


def _port_in_use(port: int, host: str = "127.0.0.1") -> str | None:
    """Why live_node could not listen on ``host:port``, before any node starts, or None."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            return (f"port {port} is in use on {host} ({exc.strerror}): stop the other "
                    "server or choose another port")
    return None


def _check_run_files(args) -> None:
    """Read the files a scene's nodes will read, here and once, before any node starts:
    a FIFO, an alias bomb or a file beyond the limits of
    :func:`grazing_control.support.files.read_yaml_file` is one ParameterError line
    naming the option (a node would block on a FIFO, or take the bomb's memory)."""
    from grazing_control.support.files import YamlFileError, read_yaml_file

    for option, path in (("--sim-params", args.sim_params), ("--model", args.model),
                         ("--controller-params", args.controller_params)):
        if path is not None:
            try:
                read_yaml_file(path)
            except YamlFileError as exc:
                raise ParameterError(f"{option} {exc}") from None
    if getattr(args, "rig", None) is not None:     # the rig file, validated once here
        from grazing_control.plant.rig import load_rig

        try:
            load_rig(args.rig)
        except (ParameterError, YamlFileError) as exc:
            raise ParameterError(f"--rig {exc}") from None


def cmd_run(args):
    import dataclasses

    from grazing_control.ros.launcher import run

    kwargs = {k: v for k, v in vars(args).items() if k not in ("func", "command", "json")}
    _check_run_files(args)
    if getattr(args, "live", None):
        busy = _port_in_use(args.live)
        if busy:
            print(f"grazing run: error: --live {args.live}: {busy}", file=sys.stderr)
            return 2
    if not args.json:
        result = run(**kwargs)
        print(result)
        return result.exit_code
    with _stdout_to_stderr():  # stdout: the one JSON object only
        result = run(**kwargs)
    summary = _nulls(dataclasses.asdict(result)) if dataclasses.is_dataclass(result) else {}
    summary.update(ok=bool(result.ok), exit_code=result.exit_code, summary=str(result))
    _print_json(summary)
    return result.exit_code


def cmd_demo(args):
    from pathlib import Path

    from grazing_control.studies.demo import main as demo_main

    if not args.json:
        return demo_main(args)
    with _stdout_to_stderr():  # the progress lines go to stderr
        status = demo_main(args)
    report = Path(args.out) / "report.json"
    summary = {"exit_code": status, "report": str(Path(args.out) / "report.md"),
               "numbers": str(report)}
    if report.is_file():
        summary.update(json.loads(report.read_text(encoding="utf-8")))
    _print_json(_nulls(summary))
    return status


def _print_json(obj):
    json.dump(obj, sys.stdout, allow_nan=False)
    sys.stdout.write("\n")
    sys.stdout.flush()


# ---------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    from grazing_control import __version__

    parser = _Parser(
        prog="grazing",
        description="Exact analysis and discrete control of grazing in an impact oscillator.")
    parser.add_argument("--version", action="version", version=f"grazing {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    s = sub.add_parser("design", help="gains (c1, c2) for degenerate grazing, admissible c2")
    _common(s)
    s.add_argument("--c2", type=_finite, help="chosen gain c2 (or --optimize)")
    _delay_arg(s)
    s.add_argument("--delta-d", type=_finite,
                   help="report the noise gain (std of the Pi2 position per unit measurement "
                        "noise) of the controlled orbit at this Delta d < 0")
    s.add_argument("--sensor-rate", type=integer_at_least(2), default=200,
                   help="position-only sensor for the noise gain: samples per period "
                        "(default 200)")
    s.add_argument("--estimator", choices=("model", "arc", "nearest"), default="model",
                   help="its Pi2 estimator (default model, docs/theory_estimation.md)")
    s.add_argument("--sensor-lead", type=non_negative, default=0.0,
                   help="its estimate made this long (model time) before the section's last "
                        "sample, the later samples unused (a rig controller's answer_lead; "
                        "default 0)")
    s.add_argument("--optimize", choices=("noise",),
                   help="choose c2 in the admissible set: noise = least noise gain at --delta-d "
                        "(default -5e-6, the study's first scene)")
    s.add_argument("--out", type=_path, help="write the controller's YAML parameter file here "
                                             "(c1, c2, actuation_delay, X**, the model)")
    s.add_argument("--pulse-width", type=_finite, default=0.0,
                   help="the correction as a force pulse of this width centred at --delay "
                        "(simulation time; sim_node's pulse_width); with it c1 is the exact "
                        "design for the pulse's force profile (P1, docs/theory_pulse.md)")
    s.add_argument("--actuator-bandwidth", type=_finite, default=0.0,
                   help="a first-order actuator's bandwidth 1/tau_a (radians per simulation "
                        "time unit, sim_node's actuator_bandwidth; 0: ideal): c1 for the "
                        "force through it, the loop's margin and predicted spread at "
                        "--delta-d (needs --pulse-width)")
    s.add_argument("--actuator-latency", type=_finite, default=0.0,
                   help="the actuator's latency (simulation time, sim_node's "
                        "actuator_latency; needs --pulse-width)")
    _method_arg(s)
    ndof.add_model_option(s)
    ndof.add_design_options(s)
    s.set_defaults(func=cmd_design)

    s = sub.add_parser("orbit", help="the 1/1 orbit and its Floquet multipliers")
    _common(s)
    s.add_argument("--delta-d", type=_finite, help="Delta d = d - d* (< 0); required unless "
                                                  "--rig or --params gives it")
    _gain_args(s)
    _method_arg(s)
    ndof.add_model_option(s)
    ndof.add_gain_options(s, markov=True)
    s.set_defaults(func=cmd_orbit)

    s = sub.add_parser("continue", help="continue the 1/1 branch in Delta d, find bifurcations")
    _common(s)
    s.add_argument("--from", dest="start", type=_finite, required=True, help="start Delta d <= 0")
    s.add_argument("--to", dest="stop", type=_finite, required=True, help="end Delta d <= 0")
    s.add_argument("--points", type=_count, default=200, help="grid points (default 200)")
    _gain_args(s)
    ndof.add_model_option(s)
    ndof.add_gain_options(s, markov=True)
    s.set_defaults(func=cmd_continue)

    from .continue2 import add_parser as add_continue2_parser
    add_continue2_parser(sub, _common, _gain_args)

    s = sub.add_parser("simulate", help="simulate on Pi2, optionally switching control on")
    _common(s)
    s.add_argument("--delta-d", type=_finite, help="Delta d = d - d*; required unless --rig "
                                                  "or --params gives it")
    s.add_argument("--periods", type=_count, required=True, help="number of forcing periods")
    s.add_argument("--control-after", type=_count, help="switch control on at this sample")
    s.add_argument("--x0", type=_finite, help="initial x on Pi2 (default x**)")
    s.add_argument("--v0", type=_finite, help="initial v on Pi2 (default v**)")
    s.add_argument("--dx0", type=_finite,
                   help="initial x - x** on Pi2 (deviation; full precision near grazing)")
    s.add_argument("--dv0", type=_finite, help="initial v - v** on Pi2 (deviation)")
    s.add_argument("--lyapunov", action="store_true",
                   help="also the Lyapunov exponents per period over the last half of the "
                        "periods, with the sum identity (docs/theory_lyapunov.md)")
    s.add_argument("--fidelity", choices=("exact", "zdm2", "zdm1", "ode", "auto"), default="exact",
                   help="model: exact flow (default), normal-form maps zdm2/zdm1, solve_ivp "
                        "(ode, comparison), or auto: the cheapest meeting --tol over the horizon")
    s.add_argument("--tol", type=_finite, default=1e-9,
                   help="Pi2 error tolerance for --fidelity auto (default 1e-9)")
    _gain_args(s)
    ndof.add_model_option(s)
    ndof.add_gain_options(s)
    ndof.add_start_option(s)
    s.set_defaults(func=cmd_simulate)

    from grazing_control.studies.sweeps.cli import add_sweep_command

    s = add_sweep_command(sub, _common, _finite, _count)
    ndof.add_sweep_options(s)
    s.set_defaults(func=ndof.dispatch(s.get_default("func"), ndof.cmd_sweep))
    from .basins import add_basins_parser

    add_basins_parser(sub)

    try:
        from grazing_control.ros.launcher import add_run_arguments
    except ImportError:  # pragma: no cover - the launcher lands with the ROS issue
        add_run_arguments = None
    if add_run_arguments is not None:
        s = sub.add_parser("run", help="run a scene through the real ROS 2 nodes")
        add_run_arguments(s)
        s.add_argument("--live", type=_live_port, default=None, metavar="PORT",
                       help="also start live_node: a Foxglove WebSocket server on PORT "
                            "(e.g. 8765) streaming the scene to Foxglove/Lichtblick "
                            "(docs/live.md)")
        s.add_argument("--json", action="store_true",
                       help="print one JSON summary object: ok, exit_code, each node's "
                            "exit status, reason (why a failed scene failed: the realtime "
                            "watchdog's trip, a refused feasibility check, a node that "
                            "failed; docs/nodes.md), sim_verdict (the simulator's summary, "
                            "watchdog trip and feasibility verdict); node output goes to "
                            "stderr")
        add_params_option(s)
        s.set_defaults(func=cmd_run)

    from .bag import add_bag_parser
    add_bag_parser(sub)
    from .rig import add_rig_parser
    add_rig_parser(sub)
    from .identify import add_identify_parser
    add_identify_parser(sub)
    from grazing_control.studies.robustness.cli import add_robustness_parser

    add_robustness_parser(sub, _common, _finite)
    from grazing_control.studies.figures.command import add_parser as add_figures_parser

    s = add_figures_parser(sub)
    ndof.add_figures_options(s)
    s.set_defaults(func=ndof.dispatch(s.get_default("func"), ndof.cmd_figures))

    s = sub.add_parser("demo", help="the main job: the study's two control scenes and a report")
    s.add_argument("--out", type=_path, default="out/demo", help="report folder (default out/demo)")
    s.add_argument("--offline", action="store_true", help="through the core only, no ROS nodes")
    s.add_argument("--json", action="store_true",
                   help="print one JSON summary object (progress goes to stderr)")
    s.set_defaults(func=cmd_demo)

    from grazing_control.recordings import add_commands   # analyze, replay (docs/analysis.md)
    add_commands(sub)
    return parser



def _require_delta_d(args) -> None:
    """orbit and simulate need Delta d: from --delta-d, --rig or --params."""
    if args.command in ("orbit", "simulate") and args.delta_d is None:
        raise ParameterError(f"{args.command}: the following arguments are required: "
                             "--delta-d (or --rig FILE, or --params FILE with delta_d)")


def _one_line(exc) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def main(argv=None) -> int:
    """Entry point of the `grazing` console script."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    try:
        # overflow in a computation shows up as nan/inf in the result, which is refused
        # below with one line; numpy's warnings would add lines of their own
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            ndof.check_options(args, argv)   # --model and the 1-DOF options (cli/ndof.py)
            apply_rig(args, argv)         # --rig FILE (cli/rig.py)
            apply_to_args(args, argv)     # --params FILE (cli/parameter_file.py)
            _require_delta_d(args)
            result = args.func(args)
    except (ParameterError, ValueError, RuntimeError, OSError) as exc:
        print(f"grazing: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except ArithmeticError as exc:  # ZeroDivisionError, OverflowError, FloatingPointError
        print(f"grazing: error: numerical failure ({type(exc).__name__}: {_one_line(exc)}): "
              "an input is outside the computable range", file=sys.stderr)
        return 2
    except MemoryError:
        print("grazing: error: out of memory: reduce the size of the request", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("grazing: interrupted", file=sys.stderr)
        return 130
    if isinstance(result, int):
        return result
    bad = _non_finite(result) if isinstance(result, dict) else []
    if bad:
        print(f"grazing: error: {args.command}: the result is not finite ({', '.join(bad[:3])}): "
              "an input is outside the computable range", file=sys.stderr)
        return 2
    try:
        if isinstance(result, dict):
            json.dump(result, sys.stdout, allow_nan=False)
            sys.stdout.write("\n")
        elif result is not None:
            print(result)
        sys.stdout.flush()
    except BrokenPipeError:  # the reader went away (| head): not an error of ours
        sys.stdout = None
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

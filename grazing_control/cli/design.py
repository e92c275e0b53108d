"""`grazing design`: the kick gains of the 1-DOF study, their admissible set and limit
multipliers, the noise-optimal gain and the controller's parameter file (docs/commands.md).

Moved out of cli/commands.py so that ``grazing rig`` (cli/rig.py), which runs this design
for a rig, and the parser (cli/commands.py) both sit above it without an import circle.
"""

from __future__ import annotations

import math
import time

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import ParameterError

from . import ndof
from .common import complex_list, params_of, require_finite

__all__ = ["cmd_design"]


def cmd_design(args):
    if args.model is not None:
        return ndof.cmd_design(args)
    from grazing_control.dynamics.design.gains import (C2_LIMIT, admissible_c2, evaluate_design,
                                                 write_controller_yaml)

    p = params_of(args)
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
        from grazing_control.dynamics.maps.perturbation import (admissible_c2_perturbation,
                                                           existence_coefficient_perturbation,
                                                           limit_multipliers_perturbation)

        t0 = time.perf_counter()
        g = point.gains()
        lam_p = limit_multipliers_perturbation(p, g)
        gamma_p = existence_coefficient_perturbation(p, g)
        sets_p = {c: admissible_c2_perturbation(p, delay=args.delay, conditions=c) for c in sets}
        cost_p = time.perf_counter() - t0
        other = {"exact": {"admissible_c2": [_json_interval(iv) for iv in sets["combined"]],
                           "multipliers_limit": complex_list(point.multipliers_limit),
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
        "multipliers_limit": complex_list(point.multipliers_limit),
        "gamma1": point.gamma1,
        "multipliers_free": complex_list(point.multipliers_free),
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
    require_finite(out, "design")
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
    first-order actuator (dynamics.simulation.actuator.actuated_design, docs/theory_pulse.md (P1)
    and section 7): its gains, and at --delta-d (default -5e-6) the loop's orbit, spectral
    radius and predicted spread (x and v measured with sigma; a position-only sensor at
    --sensor-rate with the chosen estimator)."""
    from grazing_control.dynamics.simulation.actuator import Actuator, actuated_design
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.estimation.section_state import estimate_covariance
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11

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
    """--optimize noise: the c2 of least noise gain (dynamics.design.tuning.optimize_noise)."""
    from grazing_control.dynamics.design.tuning import STUDY_C2, optimize_noise

    r = optimize_noise(p.with_(delta_d=_noise_delta_d(args)), args.delay)
    study = r.study_noise_gain if math.isfinite(r.study_noise_gain) else None
    return {"objective": args.optimize, "delta_d": r.delta_d, "c2": r.c2, "c1": r.c1,
            "noise_gain": r.noise_gain, "interval": _json_interval(r.interval),
            "study_c2": STUDY_C2, "study_noise_gain": study, "evaluations": r.evaluations}


def _noise_report(args, p, point):
    """noise_gain (null where no stable controlled orbit) at --delta-d, issue 15 section 3."""
    from grazing_control.dynamics.design.tuning import design_noise_gain

    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.estimation.section_state import estimate_covariance
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    dd = _noise_delta_d(args)
    q = p.with_(delta_d=dd)
    if not args.sensor_lead < q.period:     # (the stream estimator's answer_lead range)
        raise ParameterError(f"sensor_lead={args.sensor_lead!r} is invalid: valid range is "
                             f"0 <= sensor_lead < T = {q.period!r}")
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
    from grazing_control.dynamics.design.gains import C2_LIMIT

    def end(x, sign):
        if x is None or not math.isfinite(x):
            return f"beyond {sign}{C2_LIMIT:.0e}"
        return f"{x:.10g}"

    return " U ".join(f"({end(lo, '-')}, {end(hi, '+')})" for lo, hi in intervals) or "empty"


def _json_interval(iv):
    """[lo, hi] with an end open at the search limit as null (the key c2_search_limit)."""
    return [x if math.isfinite(x) else None for x in iv]

"""`grazing design`: the degenerate grazing design of either model, its admissible set and
limit multipliers, and the controller's parameter file (docs/commands.md,
docs/ndof_commands.md).

One command, one report: each model's design goes through the one entry
``dynamics/design/model_design.py`` (the 1-DOF closed form in c2, or a model file's
family in mu), and :func:`design_lines` prints both from a :class:`DesignReport`: the
model's own head (the 1-DOF c1 and X**; a model file's d*, delay or pulse, family and
transmission zeros), the member's limit multipliers, gamma1 and the non-impacting
spectral radius, the admissible set of the family's parameter, and the model's own tail
(the 1-DOF method, noise gains, optimum, actuator; a model file's predicted spread, the
sections to move to, a rig's gains in SI). The JSON is each model's (the 1-DOF keys of
docs/commands.md, the model file's of docs/ndof_commands.md).

Moved out of cli/commands.py so that ``grazing rig`` (cli/rig.py), which runs this design
for a rig, and the parser (cli/commands.py) both sit above it without an import circle.
"""

from __future__ import annotations

import os

import math
import time
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import ParameterError

from .common import complex_list, params_of, require_finite
from .model_file import coordinates, family_member, fmt_vec, header, load

__all__ = ["cmd_design", "DesignReport", "design_lines"]


class DesignReport(NamedTuple):
    """What :func:`design_lines` prints for either model: the title, the model's own
    ``head`` lines, the family's parameter (``name``: c2 or mu) and its smooth map
    (``free_map``: N_g or N), whether its admissible set is unbounded (``unbounded``: mu)
    and printed before the member (``admissible_first``), the ``member`` lines (the
    chosen member's gains), its limit multipliers, gamma1, non-impacting spectral radius
    and ``conditions``, the admissible sets (``intervals``: all three conditions,
    ``sets``: each side), whether the member is admissible, and the ``tail`` lines."""

    title: str
    head: list
    name: str
    free_map: str
    unbounded: bool
    admissible_first: bool
    member: list
    multipliers_limit: np.ndarray
    gamma1: float
    rho_free: float
    conditions: dict
    intervals: list
    sets: dict
    admissible: bool
    tail: list


def design_lines(r: DesignReport) -> list:
    """The report of ``grazing design`` for either model (module docstring)."""
    ok = {True: "yes", False: "NO"}
    admissible = _admissible_lines(r.name, r.intervals, r.sets, r.free_map, r.unbounded)
    limits = [
        f"  |lambda0|          = {', '.join(f'{abs(z):.6g}' for z in r.multipliers_limit)}"
        f"  (limit Delta d -> 0-: {ok[r.conditions['limit_stable']]} < 1)",
        f"  gamma1             = {r.gamma1:.6g}  (> 0: 1/1 motion exists for d < d*: "
        f"{ok[r.conditions['exists_impacting']]})",
        f"  {'rho(' + r.free_map + ')':19s}= {r.rho_free:.6g}  (non-impacting motion, d > d*: "
        f"{ok[r.conditions['free_stable']]} < 1)",
    ]
    return [r.title, *r.head, *(admissible if r.admissible_first else []), *r.member,
            *limits, *([] if r.admissible_first else admissible),
            f"  this {r.name:14s}: {'admissible' if r.admissible else 'NOT admissible'}",
            *r.tail]


def cmd_design(args):
    """design [--c2 C2 | --optimize noise] ... or --model FILE [--mu MU | --free-gain ..]:
    the model's design (:func:`_study_design`, :func:`_family_design`), printed by
    :func:`design_lines`, or its JSON."""
    out, report = (_family_design if args.model is not None else _study_design)(args)
    return out if args.json else "\n".join(design_lines(report))


def _study_design(args):
    """The 1-DOF study's design at --c2 (or --optimize noise): its JSON and its report."""
    from grazing_control.dynamics.design.gains import C2_LIMIT, write_controller_yaml
    from grazing_control.dynamics.design.model_design import admissible_set, evaluate_design

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
    sets = {c: admissible_set(p, c, args.delay)
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
    delay = f", actuation delay {point.delay:.12g}" if point.delay else ""
    lines = [f"  method             : {args.method} ({cost:.3g} s)"]
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
        exact = noise.get("noise_gain_position_only_exact_plant")
        if exact is not None:
            lines.append(f"    on an exact plant = {exact:.4g}  (the model right, no process "
                         "noise: the filter's floor not in the plant, E7')")
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
    return out, DesignReport(
        f"degenerate grazing design (N_g,12 = 0, Eq. 38) for c2 = {point.c2:.12g}{delay}",
        [f"  c1                 = {point.c1:.15g}",
         f"  X** on Pi2         = ({p.x_ref:.15g}, {p.v_ref:.15g})"],
        "c2", "N_g", False, False, [], point.multipliers_limit, point.gamma1, rho_free,
        out["conditions"], intervals, sets, point.admissible, lines)


def _actuator_report(args, p, point):
    """--actuator-bandwidth/--actuator-latency/--pulse-width: the design through the
    first-order actuator (dynamics.simulation.actuator.actuated_design, docs/theory_pulse.md (P1)
    and section 7): its gains, and at --delta-d (default -5e-6) the loop's orbit, spectral
    radius and predicted spread (x and v measured with sigma; a position-only sensor at
    --sensor-rate with the chosen estimator)."""
    from grazing_control.dynamics.simulation.actuator import Actuator, actuated_design
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.estimation.section_state import estimate_covariance
    from grazing_control.dynamics.orbits import one_one
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

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
            x_star = one_one.orbit(q, kick).state
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
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11

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
        # the controlled orbit once for the reported and the exact-plant covariance
        target = None if args.estimator == "nearest" else orbit_11(q, g).pi2_deviation
        r = estimate_covariance(q, g, args.sensor_rate, estimator=args.estimator,
                                lead=args.sensor_lead, target=target)
        pos = design_noise_gain(q, point.c2, point.delay, measurement=r)
        exact = math.inf
        if args.estimator == "model":
            r = estimate_covariance(q, g, args.sensor_rate, lead=args.sensor_lead,
                                    target=target, exact_plant=True)
            exact = design_noise_gain(q, point.c2, point.delay, measurement=r)
    except (OrbitNotFound, ValueError, ArithmeticError):
        pos = exact = math.inf
    out.update(noise_gain_position_only=pos if math.isfinite(pos) else None,
               noise_gain_position_only_exact_plant=exact if math.isfinite(exact) else None,
               position_only_sensor={"samples_per_period": args.sensor_rate,
                                     "estimator": args.estimator,
                                     "lead": args.sensor_lead})
    return out


def _fmt_intervals(intervals, unbounded: bool = False):
    """'(lo, hi) U ...'; an end open at the search limit reads 'beyond -1e+06' (design.C2_LIMIT),
    or 'inf' for the n-DOF family's mu (``unbounded``)."""
    from grazing_control.dynamics.design.gains import C2_LIMIT

    def end(x, sign):
        if x is None or not math.isfinite(x):
            return "inf" if unbounded else f"beyond {sign}{C2_LIMIT:.0e}"
        return f"{x:.10g}"

    return " U ".join(f"({end(lo, '-')}, {end(hi, '+')})" for lo, hi in intervals) or "empty"


def _admissible_lines(name, combined, sets, free_map, unbounded=False) -> list:
    """The admissible set of the free design parameter (c2 of the 1-DOF design, mu of the
    n-DOF family): all three conditions, then each side of grazing."""
    return [f"  admissible {name:8s}= {_fmt_intervals(combined, unbounded)}  (all three conditions)",
            f"    impacting side   = {_fmt_intervals(sets['impacting'], unbounded)}  "
            "(|lambda0| < 1, gamma1 > 0)",
            f"    non-impacting    = {_fmt_intervals(sets['non-impacting'], unbounded)}  "
            f"(rho({free_map}) < 1)"]


def _json_interval(iv):
    """[lo, hi] with an end open at the search limit as null (the key c2_search_limit)."""
    return [x if math.isfinite(x) else None for x in iv]


# ---------------------------------------------------------------------------- the n-DOF family
def _intervals(raw):
    """The admissible sets as (lo, hi) float pairs."""
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


def _family_design(args):
    """design --model FILE [--mu MU | --free-gain NAME=V] [--delay D] [--pulse-width W
    [--actuator-bandwidth B] [--actuator-latency L]] [--out FILE] (docs/ndof_commands.md;
    the delayed design is docs/theory_ndof.md §14, the pulse's §15)."""
    from grazing_control.dynamics.design import family as nd
    from grazing_control.dynamics.design.model_design import (admissible_set, evaluate_design,
                                                              free_multipliers)

    rig = getattr(args, "rig_model", None)          # --rig FILE of n masses (cli/rig.py)
    model = load(args.model) if rig is None else rig.model()
    delay = nd.design_actuation(float(getattr(args, "delay", 0.0) or 0.0),
                                *(float(getattr(args, a, 0.0) or 0.0) for a in
                                  ("pulse_width", "actuator_bandwidth", "actuator_latency")))
    pulse = nd.actuation_parameters(delay) if isinstance(delay, nd.Actuation) else None
    t0 = time.perf_counter()
    k0 = np.asarray(nd.gain_family(model, 0.0, delay), dtype=float)
    k1 = np.asarray(nd.gain_family(model, 1.0, delay), dtype=float) - k0
    zeros = np.asarray(nd.transmission_zeros(model, delay), dtype=complex)
    sets = {c: _intervals(admissible_set(model, c, delay))
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
    else:
        mu, chosen = nd.default_mu(intervals)
    mu += 0.0   # no "-0" in the report
    design = evaluate_design(model, mu, delay)
    k = np.asarray(design.gains, dtype=float)
    lam0 = np.asarray(design.limit_multipliers, dtype=complex)
    gamma = float(design.gamma1)
    rho_free = float(np.max(np.abs(free_multipliers(model, mu, delay))))
    conditions = {"limit_stable": bool(design.stable), "exists_impacting": bool(design.exists),
                  "free_stable": bool(design.free_stable)}
    admissible = bool(design.admissible)
    # no design anywhere on the family: say where the section could go (a scan, §4)
    sections = None if intervals else nd.sections_with_stable_zeros(model, delay=delay)
    seconds = time.perf_counter() - t0
    out = header(model, args.model)
    out.update({
        "family": {"k_at_mu_0": k0.tolist(), "dk_dmu": k1.tolist()},
        "transmission_zeros": complex_list(zeros),
        "transmission_zeros_max_modulus": float(np.max(np.abs(zeros))) if zeros.size else 0.0,
        "admissible_mu": [_json_interval(iv) for iv in intervals],
        "admissible_mu_sets": {"combined": [_json_interval(iv) for iv in intervals],
                               **{c: [_json_interval(iv) for iv in ivs]
                                  for c, ivs in sets.items()}},
        "delay": delay.delay if pulse else delay, **({"pulse": pulse} if pulse else {}),
        "mu": mu, "mu_chosen": chosen, "gains": k.tolist(),
        "multipliers_limit": complex_list(lam0), "gamma1": gamma,
        "spectral_radius_free": rho_free, "conditions": conditions, "admissible": admissible,
        "pi2_offsets_with_stable_zeros": None if sections is None else
        [list(iv) for iv in sections],
        "seconds": seconds,
    })
    out["spread"] = _family_spread(args, model, design, delay)
    if rig is not None:
        out["rig"] = args.model
        out["si"] = {"effective_mass_kg": rig.effective_mass,
                     "actuated_mass": rig.structure.actuated, **rig.state_gains_si(k)}
    if args.out:
        if not admissible:
            raise ParameterError(f"mu={mu!r} is not admissible: valid range is "
                                 f"{_fmt_intervals(intervals, True)}; nothing written to {args.out}")
        # the model file as an absolute path: the gain file is read from wherever the
        # scene runs (a relative one resolved against that folder: 'no such file')
        nd.write_gain_yaml(args.out, model, design, os.path.abspath(args.model))
        out["written"] = args.out
    ok = {True: "yes", False: "NO"}
    names = coordinates(model)
    head = [
        f"  d*, tau*           = {out['d_star']:.15g}, {out['tau_star']:.15g}",
        *([f"  actuation delay    = {delay:.15g}  (the kick acts this long after the Pi2 "
           f"sample; the family, zeros and limits are those of the delayed kick)"]
          if delay and not pulse else []),
        *([f"  pulse              = {', '.join(f'{a} {b:.10g}' for a, b in pulse.items())}  "
           f"(the correction as a force pulse; family, zeros and limits are the pulse's, "
           f"docs/theory_ndof.md §15)"] if pulse else []),
        f"  family k(mu)       = k0 + mu dk, over ({', '.join(names)})",
        f"    k0               = {fmt_vec(k0, 12)}",
        f"    dk               = {fmt_vec(k1, 12)}",
        f"  transmission zeros = {', '.join(f'{z:.6g}' for z in zeros)}",
        f"    max |zero|       = {out['transmission_zeros_max_modulus']:.6g}  (< 1 needed: "
        f"{ok[out['transmission_zeros_max_modulus'] < 1.0]})",
    ]
    member = [f"  mu                 = {mu:.15g}  ({chosen})",
              f"  gains k            = {fmt_vec(k, 15)}"]
    lines = []
    lines += _spread_lines(out["spread"], names)
    if sections is not None:
        where = " U ".join(f"({a:.4f}, {b:.4f})" for a, b in sections) or "none"
        lines.append(f"  no admissible mu: pi2_offset values whose zeros all lie inside the "
                     f"unit circle (scan): {where} (this file: {model.pi2_offset:.4g})")
    if rig is not None:
        lines += _si_lines(out["si"], names)
    if args.out:
        lines.append(f"  gains written to {args.out}")
    return out, DesignReport(
        f"n-DOF degenerate grazing design (w^T N = mu w^T) for {args.model} (n = {model.n}, "
        f"wall on x{model.i_w}, kick on v{model.i_a})", head, "mu", "N", True, True, member,
        lam0, gamma, rho_free, conditions, intervals, sets, admissible, lines)


def _si_lines(si: dict, names) -> list:
    """The text of the gains in SI of a rig of n masses (cli/rig.py, masses_design_si)."""
    n = len(names) // 2
    out = [f"  in SI: Delta v_{si['actuated_mass']} = sum (k_x omega_n) x + sum k_v v, "
           f"k_x omega_n = {fmt_vec(si['position_gains_per_s'], 6)} 1/s, k_v = "
           f"{fmt_vec(si['velocity_gains'], 6)}"]
    if "force_gains_position_N_per_m" in si:
        out.append(f"  as the pulse's force (m_a = {si['effective_mass_kg']:.6g} kg): "
                   f"{fmt_vec(si['force_gains_position_N_per_m'], 6)} N/m on "
                   f"({', '.join(names[:n])}), {fmt_vec(si['force_gains_velocity_N_s_per_m'], 6)}"
                   f" N*s/m on ({', '.join(names[n:])})")
    return out


def _family_spread(args, model, design, delay):
    """The design's predicted spread at --delta-d (default: the model file's Delta d where
    it is < 0; none where it is >= 0 and no --delta-d is given): the loop's stationary
    std per unit sigma of each coordinate on Pi2 (and the actuator's force through the
    lag) and of the corrections, every coordinate measured with sigma (R = I), the
    position of the wall coordinate only (the model filter's covariance at --sensor-rate
    over the samples a lockstep controller fits), and the velocity noise at Pi2
    (dynamics/design/noise.py, docs/theory_ndof.md section 17). Null entries
    where the loop has no stable 1/1 orbit there."""
    import dataclasses

    from grazing_control.dynamics.design.family import Actuation
    from grazing_control.dynamics.design.noise import filter_covariance, predicted_spread
    from grazing_control.dynamics.simulation.actuator import Actuator

    given = getattr(args, "delta_d", None)      # (grazing rig's design has none)
    dd = given if given is not None else model.delta_d
    if not dd < 0.0:
        if given is not None:
            raise ParameterError(f"delta_d={dd!r} is invalid: the predicted spread is that of "
                                 f"the controlled 1/1 orbit, valid range is delta_d < 0")
        return None
    q = dataclasses.replace(model, delta_d=float(dd))
    rate = int(getattr(args, "sensor_rate", 200))
    out = {"delta_d": float(dd), "sensor_rate": rate, "sensor_coordinate": int(model.i_w),
           "spectral_radius": None, "orbit": None, "measured": None, "position_only": None,
           "velocity_noise": None}
    d = 2 * model.n
    try:
        first = predicted_spread(q, design.gains, delay)
        orbit = first.orbit
        out.update(spectral_radius=first.spectral_radius, orbit=orbit.tolist())
        lag = isinstance(delay, Actuation) and delay.time_constant > 0.0
        act = None if not isinstance(delay, Actuation) else \
            Actuator(delay.time_constant, delay.latency)
        kick_delay = delay.delay if isinstance(delay, Actuation) else delay
        r = filter_covariance(q, design.gains, orbit[:d], rate, model.i_w, kick_delay,
                                   width=delay.width if act else 0.0, section_sample=False,
                                   actuator=act, force0=float(orbit[d]) if lag else 0.0)
        cases = {"measured": {}, "position_only": {"measurement": r},
                 "velocity_noise": {"measurement": np.zeros((d, d)), "velocity": 1.0}}
        for key, kw in cases.items():
            s = first if key == "measured" else predicted_spread(q, design.gains, delay,
                                                                 orbit=orbit, **kw)
            out[key] = {"std": s.std.tolist(), "correction_std": s.correction_std}
    except (ValueError, ArithmeticError):
        pass
    return out


def _spread_lines(spread, names) -> list:
    """The predicted spread's lines of `design --model` (:func:`_family_spread`)."""
    if spread is None:
        return ["  predicted spread   : give --delta-d < 0 (the model file's Delta d is >= 0)"]
    head = f"  predicted spread at Delta d = {spread['delta_d']:.6g}"
    if spread["measured"] is None:
        return [head + ": none (no stable controlled 1/1 orbit found)"]
    cols = list(names) + (["F"] if len(spread["orbit"]) > len(names) else [])
    lines = [head + f" (std per unit sigma of {', '.join(cols)} on Pi2 | of the corrections; "
             f"spectral radius {spread['spectral_radius']:.6g})"]
    for key, text in (("measured", "every coordinate measured"),
                      ("position_only", f"x{spread['sensor_coordinate']} only, "
                                        f"{spread['sensor_rate']} samples per period"),
                      ("velocity_noise", "velocity noise at Pi2 (sigma_v)")):
        row = spread[key]
        lines.append(f"    {text:34s}= {fmt_vec(row['std'], 4)} | "
                     f"{row['correction_std']:.4g}")
    return lines

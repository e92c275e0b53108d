"""``grazing rig FILE`` and ``--rig FILE``: a rig in SI units at the command line (docs/rig.md).

``grazing rig FILE [--c2 C2 | --optimize noise] [--json]`` reads a rig file
(:func:`grazing_control.plant.rig.load_rig`) and says what the package makes of it: the
rig in SI as understood, the scales, the study's dimensionless model, d* and the gap at
grazing, the design for the budget's actuation delay in SI (c1 in 1/s, c2, the pulse's
force gains), the correction as a force pulse, the predicted Pi2 spread of the controlled
orbit and whether the timing budget is feasible
(:mod:`grazing_control.plant.rig_budget`). An infeasible budget or too slow a sensor is
status 2 with one line naming ``controller.budget`` or ``sensor.rate`` and the numbers.

A rig of n >= 2 masses (plant/rig_structure.py) gets :func:`masses_report` and, on
``grazing design --rig FILE``, the n-DOF pulse design on its model
(:func:`_apply_masses_rig`); ``--model-out PATH`` writes the model file of any rig.

``--rig FILE`` on design, orbit, continue, continue2, simulate, sweep, basins and
robustness sets the model's options from the file (:func:`apply_rig`, the table
:func:`rig_options`); an option the rig sets given as well is refused, naming both.
"""

from __future__ import annotations

import argparse
import math

from grazing_control.oscillator.params import ParameterError
from grazing_control.support.arguments import finite, integer_at_least

from .common import add_rig_option, file_path

__all__ = ["add_rig_option", "add_rig_parser", "apply_rig", "rig_options", "load",
           "cmd_rig", "RIG_COMMANDS", "POSITION_ERROR", "VELOCITY_ERROR"]

#: The commands that take ``--rig`` (their model options come from the file).
RIG_COMMANDS = ("design", "orbit", "continue", "continue2", "simulate", "sweep", "basins",
                "robustness")
#: The errors ``grazing rig`` shows as force pulses: 1 um of position, 1 mm/s of velocity.
POSITION_ERROR = 1e-6
VELOCITY_ERROR = 1e-3


def load(path, option: str = "--rig"):
    """The Rig of ``path``; a ParameterError line naming ``option`` (if any), the file and
    the field otherwise."""
    from grazing_control.plant.rig import load_rig
    from grazing_control.support.files import YamlFileError

    prefix = f"{option} " if option else ""
    try:
        return load_rig(path)
    except (YamlFileError, ParameterError) as exc:
        raise ParameterError(f"{prefix}{exc}") from None


def _given(argv, flag) -> bool:
    return any(a == flag or a.startswith(flag + "=") for a in argv)


def rig_options(rig, args) -> dict:
    """option -> (attribute, value) that ``--rig`` sets on the parsed ``args`` of its
    command (docs/rig.md, "--rig on the commands")."""
    from grazing_control.plant.rig_budget import samples_per_period

    p = rig.params()
    out = {"--zeta": ("zeta", p.zeta), "--r": ("r", p.r), "--omega": ("omega", p.omega),
           "--pi2-offset": ("pi2_offset", p.pi2_offset)}
    delay = rig.dimensionless()["actuation_delay"]
    command, study = args.command, getattr(args, "study", None)
    if command == "design":
        if p.delta_d < 0.0:          # the noise gain is that of the controlled 1/1 orbit
            out["--delta-d"] = ("delta_d", p.delta_d)
        out["--delay"] = ("delay", delay)
        out["--sensor-rate"] = ("sensor_rate", samples_per_period(rig))
        # the rig controller's estimate: answer_lead before the section's last sample
        from grazing_control.ros.rig_boundary import answer_lead

        out["--sensor-lead"] = ("sensor_lead", answer_lead(rig))
    elif command in ("orbit", "simulate", "basins"):
        out["--delta-d"] = ("delta_d", p.delta_d)
    elif command == "robustness" and hasattr(args, "delta_d"):
        if not p.delta_d < 0.0:
            raise ParameterError(f"--rig: the rig's Delta d = {p.delta_d!r} >= 0 (its gap is "
                                 "at or beyond grazing): robustness studies the controlled "
                                 "1/1 orbit, Delta d < 0")
        out["--delta-d"] = ("delta_d", [p.delta_d])
    if command == "robustness" and study == "noise":
        out["--delay"] = ("delay", delay)
    elif command != "design" and hasattr(args, "delay") and getattr(args, "c2", None) is not None:
        out["--delay"] = ("delay", delay)   # control on: it acts at the rig's budget
    return out


def apply_rig(args, argv) -> None:
    """Apply ``args.rig`` (if any) to the parsed options of a :data:`RIG_COMMANDS`
    command; refuse it with ``--params`` or with an option it sets. Removes ``args.rig``."""
    path = getattr(args, "rig", None)
    if getattr(args, "command", None) not in RIG_COMMANDS:
        return
    if hasattr(args, "rig"):
        delattr(args, "rig")
    if path is None:
        return
    if getattr(args, "params", None) is not None:
        raise ParameterError("--rig FILE and --params FILE are both given: each gives the "
                             "model; give one of them")
    rig = load(path)
    if rig.n > 1:
        _apply_masses_rig(rig, path, args, argv)
        return
    from .model_file import MODEL_OPTIONS

    bad = [f for f in MODEL_OPTIONS if _given(argv, f)]
    if bad:
        raise ParameterError(f"{', '.join(bad)} {'needs' if len(bad) == 1 else 'need'} an "
                             f"n-DOF model: --model FILE, or --rig FILE of n >= 2 masses "
                             f"({path} has one mass)")
    table = rig_options(rig, args)
    both = [f for f in table if _given(argv, f)]
    if both:
        raise ParameterError(f"--rig FILE and {', '.join(both)} are both given: the rig file "
                             f"sets {', '.join(table[f][0] for f in both)} (docs/rig.md); "
                             "give one of them")
    for attr, value in table.values():
        setattr(args, attr, value)
    if args.command == "sweep" and not any(name == "delta_d" for name, _ in args.grid):
        import numpy as np

        args.grid.append(("delta_d", np.array([rig.params().delta_d])))


#: The n-DOF design's actuation options a rig of n masses sets (rig.dimensionless()).
MASSES_OPTIONS = {"--delay": ("delay", "actuation_delay"),
                  "--pulse-width": ("pulse_width", "pulse_width"),
                  "--actuator-bandwidth": ("actuator_bandwidth", "actuator_bandwidth"),
                  "--actuator-latency": ("actuator_latency", "actuator_latency")}


def _apply_masses_rig(rig, path, args, argv) -> None:
    """``--rig FILE`` of n >= 2 masses: ``grazing design``'s n-DOF design (cli/design.py,
    docs/theory_ndof.md section 15) on the rig's model (``args.rig_model``), for the
    budget's delay and the pulse of the rig's width, latency and bandwidth in model
    time (the options of :data:`MASSES_OPTIONS`, refused when given as well); the 1-DOF
    options are refused, and every other command (its n-DOF form takes --model FILE)."""
    from .model_file import ONE_DOF_OPTIONS

    if args.command != "design":
        raise ParameterError(f"--rig {path} has {rig.n} masses: grazing {args.command} takes "
                             "an n-DOF model as --model FILE (write it with grazing rig "
                             f"{path} --model-out FILE); --rig of n masses is for grazing rig "
                             "and grazing design")
    if getattr(args, "model", None) is not None:
        raise ParameterError("--rig FILE and --model FILE are both given: each gives the "
                             "model; give one of them")
    both = [f for f in MASSES_OPTIONS if _given(argv, f)]
    if both:
        raise ParameterError(f"--rig FILE and {', '.join(both)} are both given: the rig file "
                             "sets the actuation (controller.budget, actuator.pulse_width, "
                             "latency, bandwidth; docs/rig.md); give one of them")
    bad = [f for f in ONE_DOF_OPTIONS if f != "--rig" and _given(argv, f)]
    if bad:
        raise ParameterError(f"{', '.join(bad)} {'is a 1-DOF option' if len(bad) == 1 else 'are 1-DOF options'}"
                             f": the rig {path} has {rig.n} masses, its design is the n-DOF "
                             "one; give the gains as --mu or --free-gain")
    if getattr(args, "out", None) is not None:
        raise ParameterError(f"--out with --rig of {rig.n} masses: the controller reads an "
                             f"n-DOF model file; write it with grazing rig {path} --model-out "
                             "M and run grazing design --model M with the rig's --delay and "
                             "--pulse-width (grazing rig prints them)")
    d = rig.dimensionless()
    for attr, key in MASSES_OPTIONS.values():
        setattr(args, attr, d[key])
    args.model, args.rig_model = str(path), rig


# ---------------------------------------------------------------------- grazing rig
def _design(rig, args) -> tuple:
    """(``grazing design``'s JSON for this rig, which c2 and why): the design of
    cli/design.py on the rig's options, with --c2 or --optimize noise."""
    from .design import cmd_design

    ns = argparse.Namespace(command="design", model=None, json=True, c2=args.c2,
                            optimize=None, estimator="model", out=None, method="exact",
                            delta_d=None)
    for attr, value in rig_options(rig, ns).values():
        setattr(ns, attr, value)
    if args.c2 is None:
        ns.optimize = "noise"
        how = ("the least noise gain in the admissible set (--optimize noise of grazing "
               "design, at the rig's Delta d" if ns.delta_d is not None else
               "the least noise gain in the admissible set (--optimize noise of grazing "
               "design, at Delta d = -5e-6: the rig's gap is at or beyond grazing")
        how += ", unit noise on x and v)"
    else:
        how = "--c2"
    try:
        return cmd_design(ns), how, ns
    except ParameterError as exc:
        if not str(exc).startswith("delay="):
            raise
        raise ParameterError(f"controller.budget={rig.budget * 1e3:.6g} ms: the design for its "
                             f"actuation delay (budget x omega_n): {exc}") from None


def _pulse(rig, dv_model: float) -> dict:
    """A dimensionless correction as SI (m/s, N s, N over the pulse) and whether the
    force is within the actuator's limit."""
    out = rig.correction_si(dv_model)
    limit = rig.actuator.force_limit
    if "force_N" in out:
        out["within_force_limit"] = bool(limit == 0.0 or abs(out["force_N"]) <= limit)
    return out


def _at_controlled_orbit(rig, model, gains, k, delay: float = 0.0) -> tuple:
    """(the controlled 1/1 orbit's Pi2 deviation or None, its correction as a force pulse
    or None): the orbit of the rig's model at its Delta d under the design's gains, from
    the one entry of every model (:func:`grazing_control.dynamics.orbits.one_one.orbit`:
    the 1-DOF closed form for ``model`` an OscillatorParams with ``gains`` its Gains, a
    model file's for an NdofModel with ``gains`` = k and the actuation ``delay``); the
    correction is k^T z (``k``: the gains over the 2n deviation coordinates) as SI
    (:func:`_pulse`), with the deviation in model units and in m and m/s. None and None
    at or beyond grazing (Delta d >= 0: no impacting orbit to hold); a note where the
    orbit is not found."""
    if not model.delta_d < 0.0:
        return None, None
    from grazing_control.dynamics.orbits.one_one import orbit
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    try:
        z = orbit(model, gains, delay=delay).state
    except (OrbitNotFound, ValueError, ArithmeticError) as exc:
        return None, {"note": f"no controlled orbit: {exc}"}
    n, s = len(z) // 2, rig.scales
    dv = sum(float(ki) * float(zi) for ki, zi in zip(k, z))
    return z, {"pi2_deviation": [float(v) for v in z],
               "pi2_deviation_m_and_m_per_s": [float(v) * s.length for v in z[:n]]
               + [float(v) * s.velocity for v in z[n:]],
               **_pulse(rig, dv)}


def _timing(rig, p, gains, args, target) -> dict:
    from grazing_control.plant.rig_budget import (check_budget, samples_per_period,
                                                  time_estimate, timing_budget)

    n = samples_per_period(rig)
    if args.compute_tail is not None:
        measured = None
        tail, how = args.compute_tail, "given by --compute-tail"
    else:
        measured = time_estimate(p, gains, n, rig.dimensionless()["sensor_noise"],
                                 runs=args.runs,
                                 target=(0.0, 0.0) if target is None else target)
        if args.tail == "cpu":
            tail = measured.cpu_p99
            how = (f"CPU-time p99 of {measured.runs} measured here; wall p99 "
                   f"{measured.p99 * 1e3:.3g} ms at load {measured.load:.2f}")
        else:
            tail = measured.p99
            how = (f"wall-clock p99 of {measured.runs} measured here at load "
                   f"{measured.load:.2f}; CPU p99 {measured.cpu_p99 * 1e3:.3g} ms")
    b = timing_budget(rig, tail)
    check_budget(b, rig.sensor.rate, how)
    out = {"sensor_latency_s": b.sensor_latency, "sample_interval_s": b.sample_interval,
           "estimate_s": b.compute, "estimate_from": how,
           "actuator_latency_s": b.actuator_latency, "needed_s": b.needed,
           "available_s": b.available, "slack_s": b.slack, "feasible": b.feasible}
    if measured is not None:
        out["measured"] = {"estimator": measured.estimator,
                           "samples_per_period": measured.samples_per_period,
                           "runs": measured.runs, "p50_s": measured.p50, "p99_s": measured.p99,
                           "max_s": measured.max, "cpu_p99_s": measured.cpu_p99,
                           "resets": measured.resets, "load_average": measured.load,
                           "on": ("the controlled 1/1 orbit" if target is not None else
                                  "the motion from the grazing orbit's section (no "
                                  "controlled 1/1 orbit)")}
    return out


def rig_report(rig, path, args) -> dict:
    """The JSON of ``grazing rig`` (docs/rig.md, "grazing rig")."""
    from grazing_control.oscillator.control import Gains
    from grazing_control.plant.rig_budget import samples_per_period

    p = rig.params()
    s = rig.scales
    dl = rig.dimensionless()
    design, how, ns = _design(rig, args)
    c1, c2 = design["c1"], design["c2"]
    gains = Gains(c1, c2, design["actuation_delay"])
    n = samples_per_period(rig)
    report = {
        "rig": str(path),
        "si": {"mass_kg": rig.mass, "stiffness_N_per_m": rig.stiffness,
               "damping_N_s_per_m": rig.damping, "natural_frequency_Hz": rig.natural_frequency,
               "omega_n_rad_per_s": rig.omega_n, "damping_ratio": rig.zeta,
               "restitution": rig.restitution, "gap_m": rig.gap, "forcing": rig.forcing,
               "forcing_amplitude": rig.amplitude,
               "forcing_amplitude_unit": "N" if rig.forcing == "force" else "m",
               "force_amplitude_N": rig.force_amplitude,
               "forcing_frequency_Hz": rig.frequency, "forcing_period_s": rig.forcing_period,
               "forcing_phase_rad": rig.phase,
               "sensor": {"rate_Hz": rig.sensor.rate, "noise_m": rig.sensor.noise,
                          "resolution_m": rig.sensor.resolution,
                          "latency_s": rig.sensor.latency,
                          "measures": "position_velocity" if rig.sensor.velocity else "position",
                          "samples_per_period": rig.sensor.rate / rig.frequency},
               "actuator": {"pulse_width_s": rig.actuator.pulse_width,
                            "force_limit_N": rig.actuator.force_limit,
                            "latency_s": rig.actuator.latency},
               "budget_s": rig.budget, "section_time_s": rig.section_time(),
               "stop": _stop_si(rig)},
        "scales": {"time_s": s.time, "length_m": s.length, "velocity_m_per_s": s.velocity,
                   "force_N": s.force},
        "dimensionless": {"zeta": p.zeta, "r": p.r, "omega": p.omega, "delta_d": p.delta_d,
                          "d_star": p.d_star, "d": p.d, "tau2": p.tau2,
                          "pi2_offset": p.pi2_offset, "period": p.period,
                          "samples_per_period": n,
                          **{k: v for k, v in dl.items() if k != "sensor_velocity"},
                          "stop": rig.contact_values()},
        "grazing": {"d_star": p.d_star, "gap_at_grazing_m": p.d_star * s.length,
                    "gap_m": rig.gap, "gap_minus_grazing_m": p.delta_d * s.length},
        "design": {"c2_from": how, "c1": c1, "c2": c2,
                   "actuation_delay": design["actuation_delay"],
                   "admissible_c2": design["admissible_c2"],
                   "admissible": design["admissible"],
                   "multipliers_limit": design["multipliers_limit"],
                   "si": rig.gains_si(c1, c2)},
        "corrections": {
            "position_error_m": POSITION_ERROR,
            "for_position_error": _pulse(rig, c1 * POSITION_ERROR / s.length),
            "velocity_error_m_per_s": VELOCITY_ERROR,
            "for_velocity_error": _pulse(rig, c2 * VELOCITY_ERROR / s.velocity)},
    }
    if "optimize" in design:
        report["design"]["optimize"] = design["optimize"]
    target, at_orbit = _at_controlled_orbit(rig, p, gains, (c1, c2))
    if at_orbit is not None:
        report["corrections"]["at_controlled_orbit"] = at_orbit
    report["predicted_spread"] = _spread(rig, design, ns, n)
    report["timing"] = _timing(rig, p, gains, args, target)
    return report


def _spread(rig, design, ns, n) -> dict:
    """The predicted Pi2 spread: the design's position-only noise gain at the rig's
    samples per period (model estimator as the rig's controller runs it: answering
    answer_lead before the section's last sample) x the sensor noise (docs/rig.md; the
    pulse's O(w^2) effect on the covariance is left out, as in the design's c1)."""
    from grazing_control.ros.rig_boundary import answer_lead

    out = {"samples_per_period": n, "estimator": "model", "sensor_noise_m": rig.sensor.noise,
           "lead_s": answer_lead(rig) / rig.omega_n,
           "sensor_noise": rig.dimensionless()["sensor_noise"],
           "reference": f"grazing design --rig FILE --c2 {design['c2']!r}: "
                        "noise_gain_position_only x sensor.noise"}
    gain = design.get("noise_gain_position_only")
    if ns.delta_d is None or gain is None:
        why = ("the rig's gap is at or beyond grazing (Delta d >= 0): there is no impacting "
               "orbit to hold" if ns.delta_d is None else
               "no stable controlled 1/1 orbit for this design at the rig's Delta d")
        out.update(noise_gain_position_only=None, spread_m=None, note=why)
        return out
    out.update(noise_gain_position_only=gain, delta_d=design["noise_gain_delta_d"],
               spread_m=gain * rig.sensor.noise,
               spread=gain * rig.dimensionless()["sensor_noise"])
    notes = []
    if abs(rig.sensor.rate / rig.frequency - n) > 1e-9 * n:
        notes.append(f"the sensor gives {rig.sensor.rate / rig.frequency:.6g} samples per "
                     f"period; the design takes the nearest integer, {n}")
    if rig.sensor.velocity:
        notes.append("the sensor also measures the velocity: the position-only gain is an "
                     "upper bound")
    if rig.sensor.resolution > 0.0:
        q = rig.sensor.resolution
        notes.append(f"quantisation of {q:.3g} m not included; as uniform noise it would give "
                     f"{gain * math.sqrt(rig.sensor.noise ** 2 + q * q / 12.0):.4g} m")
    if notes:
        out["note"] = "; ".join(notes)
    return out


def _g(v, spec=".6g") -> str:
    return "none" if v is None else format(v, spec)


def _stop_si(rig) -> dict:
    """The rig's stop in SI (docs/rig.md, "The stop")."""
    st = rig.stop
    if st.type == "rigid":
        return {"type": "rigid"}
    if st.type == "hertz":
        return {"type": "hertz", "stiffness_N_per_m1_5": st.stiffness,
                "damping_s_per_m": st.damping, "friction_N": st.friction,
                "friction_static_N": st.friction_static}
    return {"type": "kelvin_voigt", "stiffness_N_per_m": st.stiffness,
            "damping_N_s_per_m": st.damping, "friction_N": st.friction,
            "friction_static_N": st.friction_static}


def _stop_lines(si: dict, dl: dict) -> list:
    """The stop's lines of the text report: SI, then the dimensionless contact."""
    st = si["stop"]
    if st["type"] == "rigid":
        return ["  stop               = rigid wall (restitution r)"]
    if st["type"] == "hertz":
        law = (f"hertz K_H = {st['stiffness_N_per_m1_5']:.6g} N/m^1.5, Hunt-Crossley "
               f"A = {st['damping_s_per_m']:.6g} s/m")
        model = (f"k_c = K_H sqrt(l)/k = {dl['contact_stiffness']:.6g}, alpha = A omega_n l = "
                 f"{dl['contact_damping']:.6g}")
        if st["friction_static_N"] > 0.0:
            law += (f", friction {st['friction_N']:.6g} N (static "
                    f"{st['friction_static_N']:.6g} N)")
            model += (f", friction F/(k l) = {dl['friction']:.6g} (static "
                      f"{dl['friction_static']:.6g})")
    else:
        law = (f"kelvin_voigt K = {st['stiffness_N_per_m']:.6g} N/m, C = "
               f"{st['damping_N_s_per_m']:.6g} N*s/m, friction {st['friction_N']:.6g} N "
               f"(static {st['friction_static_N']:.6g} N)")
        model = (f"k_c = K/k = {dl['contact_stiffness']:.6g}, c_c = C/(m omega_n) = "
                 f"{dl['contact_damping']:.6g}, friction F/(k l) = {dl['friction']:.6g} "
                 f"(static {dl['friction_static']:.6g})")
    return [f"  stop               = {law}",
            f"                       dimensionless: {model}"]


def format_report(r: dict) -> str:
    """The text of ``grazing rig`` (docs/rig.md explains each line)."""
    si, sc, dl, gz = r["si"], r["scales"], r["dimensionless"], r["grazing"]
    de, co, sp, ti = r["design"], r["corrections"], r["predicted_spread"], r["timing"]
    sen, act = si["sensor"], si["actuator"]
    amp = (f"force F0 = {si['forcing_amplitude']:.6g} N" if si["forcing"] == "force" else
           f"base excitation Y = {si['forcing_amplitude']:.6g} m (F0 = m Omega^2 Y = "
           f"{si['force_amplitude_N']:.6g} N), stop on the frame")
    lines = [
        f"rig {r['rig']} (SI, as understood)",
        f"  mass m             = {si['mass_kg']:.6g} kg",
        f"  stiffness k        = {si['stiffness_N_per_m']:.6g} N/m  (f_n = "
        f"{si['natural_frequency_Hz']:.6g} Hz, omega_n = {si['omega_n_rad_per_s']:.6g} rad/s)",
        f"  damping c          = {si['damping_N_s_per_m']:.6g} N*s/m  (zeta = "
        f"{si['damping_ratio']:.6g})",
        f"  restitution r      = {si['restitution']:.6g}",
        f"  gap g              = {si['gap_m']:.9g} m  (stop at rest distance, +x side)",
        f"  forcing            = {amp}, f = {si['forcing_frequency_Hz']:.9g} Hz (period "
        f"{si['forcing_period_s'] * 1e3:.6g} ms), phase {si['forcing_phase_rad']:.6g} rad",
        f"  sensor             = {sen['measures']} at {sen['rate_Hz']:.6g} Hz "
        f"({sen['samples_per_period']:.6g} samples per period), noise {sen['noise_m']:.3g} m, "
        f"resolution {_g(sen['resolution_m'] or None, '.3g')}, latency "
        f"{sen['latency_s'] * 1e3:.4g} ms",
        f"  actuator           = pulse {act['pulse_width_s'] * 1e3:.4g} ms, force limit "
        f"{_g(act['force_limit_N'] or None, '.4g')} N, latency {act['latency_s'] * 1e3:.4g} ms",
        f"  controller budget  = {si['budget_s'] * 1e3:.4g} ms (section to pulse centre); first "
        f"Pi2 section at rig time {si['section_time_s'] * 1e3:.6g} ms",
        *_stop_lines(si, dl["stop"]),
        "scales",
        f"  time 1/omega_n     = {sc['time_s']:.6g} s",
        f"  length l = F0/k    = {sc['length_m']:.6g} m",
        f"  velocity omega_n l = {sc['velocity_m_per_s']:.6g} m/s",
        f"  force k l          = {sc['force_N']:.6g} N",
        "dimensionless model (the study's Eq. 1)",
        f"  zeta = {dl['zeta']!r}, r = {dl['r']!r}, omega = {dl['omega']!r}",
        f"  Delta d = {dl['delta_d']:.12g}, d* = {dl['d_star']:.15g}, d = {dl['d']:.15g}",
        f"  tau2 = {dl['tau2']:.12g} (pi2_offset {dl['pi2_offset']:.6g}), period T = "
        f"{dl['period']:.12g}",
        f"  state_period = {dl['state_period']:.6g} ({dl['samples_per_period']} samples per "
        f"period), sensor_noise = {dl['sensor_noise']:.6g}, pulse_width = "
        f"{dl['pulse_width']:.6g}",
        f"  actuation_delay = {dl['actuation_delay']:.6g} (budget x omega_n), time_scale = "
        f"{dl['time_scale']:.6g} (omega_n: model time per second)",
        "grazing",
        f"  d* l               = {gz['gap_at_grazing_m']:.9g} m (the gap at grazing); the rig's "
        f"gap is {gz['gap_minus_grazing_m']:.4g} m from it (Delta d l)",
        f"design for the actuation delay {de['actuation_delay']:.6g} (c2 from {de['c2_from']})",
        f"  c1 = {de['c1']:.12g}, c2 = {de['c2']:.12g}  ("
        f"{'admissible' if de['admissible'] else 'NOT admissible'}; admissible c2 = "
        f"({_g(de['admissible_c2'][0] if de['admissible_c2'] else None)}, "
        f"{_g(de['admissible_c2'][1] if de['admissible_c2'] else None)}))",
        f"  in SI: Delta v = c1 omega_n Delta x + c2 Delta v with c1 omega_n = "
        f"{de['si']['c1_per_s']:.6g} 1/s, c2 = {de['si']['c2']:.6g}",
    ]
    if "force_gain_position_N_per_m" in de["si"]:
        lines.append(f"  as the pulse's force F = kx Delta x + kv Delta v: kx = "
                     f"{de['si']['force_gain_position_N_per_m']:.6g} N/m, kv = "
                     f"{de['si']['force_gain_velocity_N_s_per_m']:.6g} N*s/m")
    lines.append(f"correction as a force pulse over {act['pulse_width_s'] * 1e3:.4g} ms")
    for label, key in ((f"{co['position_error_m'] * 1e6:g} um position error", "for_position_error"),
                       (f"{co['velocity_error_m_per_s'] * 1e3:g} mm/s velocity error",
                        "for_velocity_error"), ("at the controlled orbit", "at_controlled_orbit")):
        c = co.get(key)
        if c is None:
            continue
        if "note" in c and "velocity_m_per_s" not in c:
            lines.append(f"  {label:24s}: {c['note']}")
            continue
        force = (f", force {c['force_N']:.6g} N"
                 + ("" if c["within_force_limit"] else " (beyond the force limit)")
                 if "force_N" in c else "")
        lines.append(f"  {label:24s}: Delta v = {c['velocity_m_per_s']:.6g} m/s, impulse "
                     f"{c['impulse_N_s']:.6g} N s{force}")
    lines.append("predicted Pi2 spread of the controlled orbit")
    if sp["spread_m"] is None:
        lines.append(f"  none: {sp['note']}")
    else:
        lines.append(f"  noise gain {sp['noise_gain_position_only']:.6g} (position only, "
                     f"{sp['samples_per_period']} samples per period, model estimator "
                     f"answering {sp['lead_s'] * 1e3:.4g} ms before the section's last "
                     f"sample) x "
                     f"sensor noise {sp['sensor_noise_m']:.4g} m = {sp['spread_m']:.6g} m "
                     f"(std of the Pi2 position)")
        if "note" in sp:
            lines.append(f"  note: {sp['note']}")
    m = ti.get("measured")
    lines += ["timing budget",
              f"  sensor latency {ti['sensor_latency_s'] * 1e3:.4g} ms + sample interval "
              f"{ti['sample_interval_s'] * 1e3:.4g} ms + estimate {ti['estimate_s'] * 1e3:.4g} ms "
              f"+ actuator latency {ti['actuator_latency_s'] * 1e3:.4g} ms = "
              f"{ti['needed_s'] * 1e3:.4g} ms <= budget - pulse_width / 2 = "
              f"{ti['available_s'] * 1e3:.4g} ms: feasible (slack {ti['slack_s'] * 1e3:.4g} ms)",
              f"  estimate: {ti['estimate_from'] if m is None else 'p99 of %d measured here' % m['runs']}"
              + ("" if m is None else
                 f" ({m['estimator']} estimator, {m['samples_per_period']} samples per period: "
                 f"p50 {m['p50_s'] * 1e3:.3g} ms, p99 {m['p99_s'] * 1e3:.3g} ms, max "
                 f"{m['max_s'] * 1e3:.3g} ms, CPU p99 {m['cpu_p99_s'] * 1e3:.3g} ms, load "
                 f"{m['load_average']:.2f}; on {m['on']})")]
    return "\n".join(lines)


def model_to_dict(model) -> dict:
    """The model file's mapping of an NdofModel (docs/ndof_model.md; repr floats: the
    file read back is the same model)."""
    return {"M": model.M.tolist(), "C": model.C.tolist(), "K": model.K.tolist(),
            "f": model.f.tolist(), "omega": model.omega, "i_w": model.i_w,
            "delta_d": model.delta_d, "r": model.r, "i_a": model.i_a, "phase": model.phase,
            "pi2_offset": model.pi2_offset}


def masses_report(rig, path, args) -> dict:
    """The JSON of ``grazing rig`` for a rig of n >= 2 masses (docs/rig.md, "A rig with n
    masses"): the rig in SI (M, K, the modal damping C, the modes), the scales, the
    n-DOF model, the gap at grazing, the n-DOF design for the budget's pulse with its
    gains in SI (grazing design --rig FILE), a 1 um error of the impacting mass and the
    correction at the controlled 1/1 orbit (:func:`_at_controlled_orbit`, the 1-DOF
    rig's) as the pulse's force, and the timing budget with --compute-tail (the n-DOF
    estimate is not timed here)."""
    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.plant.rig_budget import check_budget, timing_budget
    from grazing_control.plant.rig_structure import modes

    from .design import cmd_design

    if args.c2 is not None or args.optimize is not None:
        raise ParameterError(f"{'--c2' if args.c2 is not None else '--optimize'} is a 1-DOF "
                             f"option: the rig {path} has {rig.n} masses (its design is the "
                             "n-DOF one: grazing design --rig FILE --mu MU)")
    st, s, model = rig.structure, rig.scales, rig.model()
    flow = NdofFlow.of(model)
    omega, _phi = modes(st.M, st.K)
    ns = argparse.Namespace(command="design", json=True, mu=None, free_gain=None, out=None,
                            model=str(path), rig_model=rig)
    d = rig.dimensionless()
    for attr, key in MASSES_OPTIONS.values():
        setattr(ns, attr, d[key])
    design = cmd_design(ns)
    k = design["gains"]
    pos = k[st.impacting] * POSITION_ERROR / s.length
    report = {
        "rig": str(path), "n": rig.n,
        "si": {"masses_kg": list(st.masses), "stiffness_N_per_m": st.K.tolist(),
               "damping_N_s_per_m": st.C.tolist(), "damping_ratios": list(st.damping_ratios),
               "mode_frequencies_Hz": (omega / (2 * math.pi)).tolist(),
               "impacting": st.impacting, "actuated": st.actuated, "measured": list(st.measured),
               "forced": st.forced if rig.forcing == "force" else None,
               "effective_mass_kg": rig.effective_mass, "restitution": rig.restitution,
               "gap_m": rig.gap, "forcing": rig.forcing, "forcing_amplitude": rig.amplitude,
               "force_amplitude_N": rig.force_amplitude, "forcing_frequency_Hz": rig.frequency,
               "sensor_rate_Hz": rig.sensor.rate, "sensor_noise_m": rig.sensor.noise,
               "pulse_width_s": rig.actuator.pulse_width, "budget_s": rig.budget,
               "section_time_s": rig.section_time()},
        "scales": {"reference": f"mass {st.impacting} on its own springs (m_ref = M_ww, "
                                "k_ref = K_ww)",
                   "mass_kg": s.mass, "stiffness_N_per_m": rig.stiffness,
                   "omega_n_rad_per_s": rig.omega_n, "time_s": s.time, "length_m": s.length,
                   "velocity_m_per_s": s.velocity, "force_N": s.force},
        "model": model_to_dict(model),
        "dimensionless": {"d_star": float(flow.d_star), "tau_star": float(flow.tau_star),
                          "tau2": float(flow.tau2), "period": model.period,
                          **{key: v for key, v in d.items() if key != "sensor_velocity"}},
        "grazing": {"d_star": float(flow.d_star), "gap_at_grazing_m": flow.d_star * s.length,
                    "gap_minus_grazing_m": model.delta_d * s.length},
        "design": {key: design[key] for key in ("mu", "mu_chosen", "gains", "admissible",
                                                "admissible_mu", "transmission_zeros_max_modulus",
                                                "multipliers_limit", "delay", "pulse")},
        "corrections": {"position_error_m": POSITION_ERROR,
                        "for_position_error_of_the_impacting_mass": _pulse(rig, pos)},
    }
    report["design"]["si"] = design["si"]
    _z, at_orbit = _at_controlled_orbit(rig, model, k, k, design["delay"])
    if at_orbit is not None:
        report["corrections"]["at_controlled_orbit"] = at_orbit
    if args.compute_tail is not None:
        b = timing_budget(rig, args.compute_tail)
        check_budget(b, rig.sensor.rate, "given by --compute-tail")
        report["timing"] = {"needed_s": b.needed, "available_s": b.available,
                            "slack_s": b.slack, "feasible": b.feasible}
    else:
        report["timing"] = {"note": "the n-DOF estimate is not timed here: give "
                                    "--compute-tail SECONDS to check the budget"}
    if args.model_out:
        from grazing_control.support.files import write_yaml_atomic

        write_yaml_atomic(args.model_out, model_to_dict(model),
                          [f"The n-DOF model of the rig {path} (grazing rig --model-out; "
                           "docs/rig.md, docs/ndof_model.md)"])
        report["model_written"] = args.model_out
    return report


def _pulse_text(c: dict) -> str:
    """A correction of :func:`_pulse` as text: Delta v, impulse and force."""
    return (f"Delta v = {c['velocity_m_per_s']:.6g} m/s, impulse {c['impulse_N_s']:.6g} N s"
            + (f", force {c['force_N']:.6g} N" if "force_N" in c else ""))


def _orbit_correction_lines(c) -> list:
    """The n-DOF report's line of the correction at the controlled 1/1 orbit (none at or
    beyond grazing)."""
    if c is None:
        return []
    if "note" in c:
        return [f"  at the controlled orbit: {c['note']}"]
    return ["  at the controlled orbit: " + _pulse_text(c)]


def format_masses_report(r: dict) -> str:
    """The text of ``grazing rig`` for a rig of n masses."""
    si, sc, m, dl, de = r["si"], r["scales"], r["model"], r["dimensionless"], r["design"]
    c = r["corrections"]["for_position_error_of_the_impacting_mass"]
    names = [f"x{i}" for i in range(r["n"])] + [f"v{i}" for i in range(r["n"])]
    from .model_file import fmt_vec

    from .design import _si_lines

    lines = [
        f"rig {r['rig']} (SI, as understood): {r['n']} masses",
        f"  masses             = {fmt_vec(si['masses_kg'], 6)} kg; mass {si['impacting']} "
        f"meets the stop, the actuator pushes mass {si['actuated']} (m_a = "
        f"{si['effective_mass_kg']:.6g} kg), the sensor measures {si['measured']}",
        f"  stiffness K        = {si['stiffness_N_per_m']} N/m",
        f"  modes              = {fmt_vec(si['mode_frequencies_Hz'], 6)} Hz, damping ratios "
        f"{fmt_vec(si['damping_ratios'], 6)}",
        f"  gap g              = {si['gap_m']:.9g} m; forcing {si['forcing']} "
        f"F0 = {si['force_amplitude_N']:.6g} N at {si['forcing_frequency_Hz']:.9g} Hz",
        f"scales (reference: {sc['reference']})",
        f"  omega_n = {sc['omega_n_rad_per_s']:.6g} rad/s, l = F0/k_ref = {sc['length_m']:.6g} m, "
        f"omega_n l = {sc['velocity_m_per_s']:.6g} m/s, k_ref l = {sc['force_N']:.6g} N",
        "dimensionless n-DOF model (docs/ndof_model.md)",
        f"  M = {m['M']}, C = {m['C']}, K = {m['K']}, f = {m['f']}",
        f"  omega = {m['omega']!r}, i_w = {m['i_w']}, i_a = {m['i_a']}, r = {m['r']!r}, "
        f"pi2_offset = {m['pi2_offset']:.6g}",
        f"  Delta d = {m['delta_d']:.12g}, d* = {dl['d_star']:.15g}; delay "
        f"{dl['actuation_delay']:.6g}, pulse_width {dl['pulse_width']:.6g}, sensor_noise "
        f"{dl['sensor_noise']:.6g}",
        f"grazing: d* l = {r['grazing']['gap_at_grazing_m']:.9g} m; the gap is "
        f"{r['grazing']['gap_minus_grazing_m']:.4g} m from it",
        f"design (grazing design --rig FILE): mu = {de['mu']:.12g} ({de['mu_chosen']}), "
        f"{'admissible' if de['admissible'] else 'NOT admissible'}",
        f"  gains k            = {fmt_vec(de['gains'], 12)} over ({', '.join(names)})",
        *_si_lines(de["si"], names),
        f"  {r['corrections']['position_error_m'] * 1e6:g} um error of mass {si['impacting']}: "
        + _pulse_text(c),
        *_orbit_correction_lines(r["corrections"].get("at_controlled_orbit")),
        "timing: " + (r["timing"]["note"] if "note" in r["timing"] else
                      f"needed {r['timing']['needed_s'] * 1e3:.4g} ms <= available "
                      f"{r['timing']['available_s'] * 1e3:.4g} ms: feasible"),
    ]
    if "model_written" in r:
        lines.append(f"model written to {r['model_written']}")
    return "\n".join(lines)


def cmd_rig(args):
    """``grazing rig``: the report (dict with --json, text otherwise)."""
    if args.c2 is not None and args.optimize is not None:
        raise ParameterError("--c2 and --optimize are both given: give one of them")
    rig = load(args.file, option="")
    if rig.n > 1:
        report = masses_report(rig, args.file, args)
        return report if args.json else format_masses_report(report)
    if args.model_out:
        from grazing_control.support.files import write_yaml_atomic

        write_yaml_atomic(args.model_out, model_to_dict(rig.model()),
                          [f"The n-DOF model (n = 1) of the rig {args.file} (grazing rig "
                           "--model-out; docs/rig.md, docs/ndof_model.md)"])
    report = rig_report(rig, args.file, args)
    if args.model_out:
        report["model_written"] = args.model_out
    return report if args.json else format_report(report) + (
        f"\nmodel written to {args.model_out}" if args.model_out else "")


def _seconds(text):
    value = finite(text)
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: valid range is >= 0 (seconds)")
    return value


DESCRIPTION = (
    "Read a rig file in SI units (docs/rig.md) and print the rig as understood, the scales "
    "(1/omega_n, l = F0/k, omega_n l, k l), the study's dimensionless model (zeta, r, omega, "
    "Delta d, d*, tau2, the sensor, pulse and budget in model units), d* l (the gap at "
    "grazing), the design for the budget's actuation delay in SI (c1 omega_n in 1/s, c2, the "
    "pulse's force gains in N/m and N*s/m), corrections as force pulses, the predicted Pi2 "
    "spread (the design's position-only noise gain x the sensor noise) and the timing budget: "
    "sensor latency + one sample interval + the Pi2 estimate's measured p99 + actuator latency "
    "<= budget - pulse_width / 2. An infeasible budget or too slow a sensor: status 2, one "
    "line naming controller.budget or sensor.rate with the numbers. A rig of n masses "
    "(masses: [...], docs/rig.md 'A rig with n masses'): its n-DOF model, the n-DOF pulse "
    "design at the budget with the gains in SI, the correction at the controlled orbit, "
    "the budget with --compute-tail; "
    "--model-out PATH writes the model file (any n).")


def add_rig_parser(sub) -> None:
    """Register ``grazing rig`` on the subcommands of the ``grazing`` parser."""
    s = sub.add_parser("rig", help="a rig file in SI: its dimensionless model, the design in "
                                   "SI, the predicted spread, the timing budget",
                       description=DESCRIPTION)
    s.add_argument("file", metavar="FILE", help="the rig file (YAML, docs/rig.md)")
    s.add_argument("--c2", type=finite, help="the gain c2 (default: --optimize noise)")
    s.add_argument("--optimize", choices=("noise",),
                   help="c2 of least noise gain at the rig's Delta d (the default)")
    s.add_argument("--compute-tail", type=_seconds, metavar="SECONDS",
                   help="the Pi2 estimate's compute time to budget (e.g. a p99 measured on "
                        "the controller's computer) instead of timing it here")
    s.add_argument("--tail", choices=("cpu", "wall"), default="cpu",
                   help="which measured p99 is budgeted: cpu (default: the estimate's own "
                        "CPU time, what it costs on a core of its own, as on the rig's "
                        "controller computer; the same on an idle and a loaded machine) or "
                        "wall (wall-clock time on this machine now: what other processes "
                        "cost it too); both are reported")
    s.add_argument("--runs", type=integer_at_least(10), default=300,
                   help="estimates timed for the compute tail (default 300; its p99 is used)")
    s.add_argument("--model-out", type=file_path, metavar="PATH",
                   help="write the rig's dimensionless n-DOF model file here (docs/ndof_model.md; "
                        "for --model FILE of design, orbit, continue, simulate, sweep)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_rig)

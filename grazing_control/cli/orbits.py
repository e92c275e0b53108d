"""`grazing orbit`, `continue`, `simulate`: the 1/1 orbit, its branch in Delta d and the
Pi2 samples of a scene, on the 1-DOF study's model or a model file's (``--model``,
:mod:`.model_file`; docs/commands.md, docs/ndof_commands.md).

Each command reads its model (the 1-DOF parameters of :mod:`.common` or the file), asks
the one entry of its concept for the numbers (the 1/1 orbit and its branch:
``dynamics.orbits.one_one.orbit`` and ``branch``, which run the 1-DOF closed form or the
model file's branch in the impact phase, or shooting; the simulation:
``simulation.simulate`` or ``studies.near_grazing.scene``), and prints them through one
report: :func:`orbit_lines`, :func:`branch_lines`, :func:`impact_lines`.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from grazing_control.oscillator.params import ParameterError


from .common import complex_list, gains_of, nulls, params_of, require_finite
from .model_file import actuation_of, control_of, delay_of, fmt_vec, header, load, pulse_width_of
from .model_file import gains_of as vector_gains_of

__all__ = ["cmd_orbit", "cmd_continue", "cmd_simulate", "orbit_lines", "branch_lines",
           "impact_lines"]


def orbit_lines(delta_d, control, impact_phase, v_minus, pi2, multipliers, stable, branch,
                found=None) -> str:
    """The report of ``grazing orbit`` (both models): ``pi2``, ``multipliers`` and
    ``branch`` as text; ``found``: the route that found the orbit, when the model has more
    than one."""
    return "\n".join([
        f"1/1 orbit at Delta d = {delta_d:.6g}{control}",
        f"  impact phase  = {impact_phase:.15g}",
        f"  v-            = {v_minus:.10g}",
        f"  Pi2 point     = {pi2}",
        f"  multipliers   = {multipliers}",
        f"  stable        = {stable}",
        *([] if found is None else [f"  found from    : {found}"]),
        f"  branch        = {branch}",
    ])


def branch_lines(title, points, bifurcations) -> list:
    """The table of ``grazing continue`` (both models): at most 20 of the ``points``
    (Delta d, v-, multipliers, stable) and the ``bifurcations`` (type, Delta d)."""
    lines = [title, f"{'Delta d':>14} {'v-':>14} {'max|lambda|':>14} stable"]
    step = max(1, len(points) // 20)
    for value, v_minus, multipliers, stable in points[::step]:
        lines.append(f"{value:14.6e} {v_minus:14.6e} {np.max(np.abs(multipliers)):14.6e} "
                     f"{stable}")
    lines.append("bifurcations:" if bifurcations else "bifurcations: none in range")
    for kind, value in bifurcations:
        lines.append(f"  {kind:16s} at Delta d = {value:.15g}")
    return lines


def impact_lines(counts, periods: int, word: str = "impacts") -> list:
    """The impacts (or contacts) of ``grazing simulate``: in all, and per period over the
    last 20 periods."""
    tail = counts[-min(periods, 20):].tolist()
    return [f"  {word + ' in all':19s}= {int(counts.sum())}",
            f"  {word} per period, last {len(tail)}: {tail}"]


# ---------------------------------------------------------------------------- orbit
def cmd_orbit(args):
    """orbit --delta-d DD [--c2 ..] or --model FILE [gains]: the 1/1 orbit and its
    multipliers by the one entry (``one_one.orbit``), the model and the report's words
    read per model (:func:`_study_orbit`, :func:`_file_orbit`)."""
    out, report = (_file_orbit if args.model is not None else _study_orbit)(args)
    return out if args.json else orbit_lines(**report)


def _study_orbit(args):
    """The 1-DOF study's orbit (the one entry, its closed form; or the perturbation
    series' multipliers): its JSON and its report's fields."""
    from grazing_control.dynamics.orbits import one_one   # scipy: not at --version

    p = params_of(args, args.delta_d)
    gains = gains_of(args, p)
    t0 = time.perf_counter()
    o = one_one.orbit(p, gains)
    lam = o.multipliers
    cost = time.perf_counter() - t0
    if args.method == "perturbation":
        from grazing_control.dynamics.maps.perturbation import perturbation_multipliers

        if o.branch != "grazing":
            raise ParameterError(
                f"--method perturbation is a series about grazing on the branch born there; "
                f"the 1/1 orbit at delta_d={p.delta_d!r} is not near grazing (branch: "
                f"{_BRANCH_TEXT.get(o.branch, o.branch)}; v- = {o.v_minus:.3g}): use --method exact")

        t0 = time.perf_counter()
        lam = perturbation_multipliers(p, gains)
        cost = time.perf_counter() - t0
    out = {
        "delta_d": o.delta_d,
        "impact_phase": o.impact_phase,
        "v_minus": o.v_minus,
        "section_pi2": o.physical.tolist(),
        "multipliers": complex_list(lam),
        "stable": bool(np.max(np.abs(lam)) < 1.0),
        "branch": o.branch,
        "method": args.method,
        "seconds": cost,
    }
    if gains is not None and gains.delay:
        out.update(c1=gains.c1, c2=gains.c2, actuation_delay=gains.delay,
                   section_pi2_deviation=o.state.tolist())
    require_finite(out, "orbit")
    ctl = f" with c1={gains.c1:.6g}, c2={gains.c2:.6g}" if gains else " (uncontrolled)"
    if gains is not None and gains.delay:
        ctl += f", actuation delay {gains.delay:.6g}"
    return out, dict(delta_d=o.delta_d, control=ctl, impact_phase=o.impact_phase,
                     v_minus=o.v_minus, pi2=f"({o.physical[0]:.15g}, {o.physical[1]:.15g})",
                     multipliers=f"{', '.join(f'{z:.6g}' for z in lam)}  "
                                 f"({args.method}, {cost:.3g} s)",
                     stable=out["stable"], branch=_BRANCH_TEXT.get(o.branch, o.branch))


_BRANCH_TEXT = {
    "grazing": "born at grazing (v- -> 0 as Delta d -> 0)",
    "grazing past a fold": "born at grazing, past a fold (saddle-node): far from grazing",
    "other": "another 1/1 branch, not connected to grazing",
}


def _orbit_json(o):
    """The orbit of a model file as JSON (docs/ndof_commands.md, orbit)."""
    return {"delta_d": o.delta_d, "impact_phase": o.impact_phase, "impact_dt": o.impact_dt,
            "v_minus": o.v_minus, "section_pi2": o.physical.tolist(),
            "section_pi2_deviation": o.state.tolist(),
            "multipliers": complex_list(o.multipliers), "stable": o.stable,
            "guess": o.route, "branch": o.branch,
            "prediction_offset": o.prediction_offset if math.isfinite(o.prediction_offset)
            else None}


def _file_orbit(args):
    """A model file's orbit (docs/ndof_commands.md; the one entry: on the branch in the
    impact phase, or by shooting from the local map's prediction): its JSON and its
    report's fields."""
    from grazing_control.dynamics.orbits import one_one   # scipy: not at --version

    from grazing_control.dynamics.orbits.near_grazing import grazing_side, with_delta_d

    model = with_delta_d(load(args.model), args.delta_d)
    k, mu, how = vector_gains_of(args, model)
    delay, width = delay_of(args, model), pulse_width_of(args, model)
    t0 = time.perf_counter()
    side = grazing_side(model, k, delay=actuation_of(args, model))
    try:
        o = one_one.orbit(model, k, delay=delay, width=width)
    except RuntimeError as exc:
        if side * args.delta_d < 0.0:
            raise RuntimeError(f"{exc}; note: the local map puts the 1/1 orbit born at "
                               f"grazing on the side Delta d {'>' if side > 0 else '<'} 0 for "
                               "this model and gains") from None
        raise
    seconds = time.perf_counter() - t0
    out = header(model, args.model)
    out.update(_orbit_json(o))
    out["grazing_side"] = side
    out.update(gains=None if k is None else k.tolist(), mu=mu, control=how, seconds=seconds)
    out.update(_actuation_json(delay, width))
    ctl = " (uncontrolled)" if k is None else f" with k = {fmt_vec(k, 8)} ({how}" + \
        (f", mu = {mu:.8g})" if mu is not None else ")") + _delay_text(delay, width)
    explicit = o.route == one_one.EXPLICIT
    route = "the factored monodromy" if explicit else "shooting"
    born = "born at grazing (" + ("on the branch from psi = 0" if explicit else
                                  "the local map's prediction")
    born += (f", {o.prediction_offset:.2g} relative from the local map's prediction)"
             if math.isfinite(o.prediction_offset) else ")")
    return out, dict(delta_d=model.delta_d, control=ctl, impact_phase=o.impact_phase,
                     v_minus=o.v_minus, pi2=fmt_vec(o.physical, 15),
                     multipliers=f"{', '.join(f'{z:.6g}' for z in o.multipliers)}  "
                                 f"(|max| {np.max(np.abs(o.multipliers)):.6g}; {route}, "
                                 f"{seconds:.3g} s)",
                     stable=o.stable,
                     branch=born if o.near_grazing else "another 1/1 orbit, not the one born "
                     "at grazing (docs/ndof_commands.md)", found=o.route)


def _delay_text(delay: float, width: float = 0.0) -> str:
    """The report's words for an actuation delay or a pulse (none for the kick at the
    sample)."""
    if width:
        return f", a pulse of width {width:.6g} centred {delay:.6g} after the sample"
    return f", actuation delay {delay:.6g}" if delay else ""


def _actuation_json(delay: float, width: float) -> dict:
    """A model file's report's actuation entries: actuation_delay (when not 0) and
    pulse_width (a pulse's), the names of the gain file."""
    return {**({"actuation_delay": delay} if delay else {}),
            **({"pulse_width": width} if width else {})}


# ---------------------------------------------------------------------------- continue
def cmd_continue(args):
    """continue --from A --to B [--c2 ..] or --model FILE [gains]: the 1/1 branch by the
    one entry (``one_one.branch``), the model and the report's words read per model
    (:func:`_study_branch`, :func:`_file_branch`)."""
    out, title, points, bifurcations, notes = \
        (_file_branch if args.model is not None else _study_branch)(args)
    if args.json:
        return nulls(out)  # inf multipliers at the grazing point itself -> null
    return "\n".join(branch_lines(title, points, bifurcations) + notes)


def _study_branch(args):
    """The 1-DOF study's branch (the one entry, its closed form in the impact phase) at the
    points of ``one_one.continuation_values``, as a model file's (issue 32): its JSON, the
    report's title, points (Delta d, v-, multipliers, stable), bifurcations (type,
    Delta d) and notes."""
    from grazing_control.dynamics.orbits import one_one   # scipy: not at --version

    p = params_of(args)
    gains = gains_of(args, p)
    branch = one_one.branch(p, gains, args.start, args.stop, args.points)
    out = {
        "branch": [
            {"delta_d": b.value, "v_minus": b.v_min,
             "multipliers": complex_list(b.multipliers), "stable": b.stable}
            for b in branch.points
        ],
        "bifurcations": [
            {"type": b.type, "delta_d": b.value, "multipliers": complex_list(b.multipliers)}
            for b in branch.bifurcations
        ],
    }
    return (out,
            f"1/1 branch, {len(branch.points)} points from Delta d = {args.start:g} to "
            f"{args.stop:g}",
            [(b.value, b.v_min, b.multipliers, b.stable) for b in branch.points],
            [(b.type, b.value) for b in branch.bifurcations], [])


#: Impact velocity, in units of d* omega, below which a point found by shooting is
#: flagged: v-^2 / (2 |a|) then nears the gap's rounding (~1e-16 d*), and v- was found
#: 1e-2 off at v- = 1.5e-7 (issue 32).
UNRESOLVED_V = 1e-5


def _file_branch(args):
    """A model file's branch (docs/ndof_commands.md; the one entry: in the impact phase
    when the start is on the branch born at grazing, else by shooting); as
    :func:`_study_branch`."""
    from grazing_control.dynamics.orbits import one_one   # scipy: not at --version

    from grazing_control.dynamics.orbits.near_grazing import with_delta_d

    values = one_one.continuation_values(args.start, args.stop, args.points)
    model = with_delta_d(load(args.model), float(values[0]))
    k, mu, how = vector_gains_of(args, model)
    delay, width = delay_of(args, model), pulse_width_of(args, model)
    t0 = time.perf_counter()
    branch = one_one.branch(model, k, args.start, args.stop, args.points, delay=delay,
                            width=width)
    first, fold = branch.first, branch.fold
    explicit = branch.route == "impact phase"
    seconds = time.perf_counter() - t0
    # by shooting, an impact with v-^2 near the gap's rounding is resolved to a few
    # digits only (docs/ndof_commands.md, "Near grazing"): say which points that is
    out = header(model, args.model)
    floor = UNRESOLVED_V * model.omega * out["d_star"]
    weak = [] if explicit else [p.value for p in branch.points if p.v_min < floor]
    warning = None if not weak else (
        f"{len(weak)} of {len(branch.points)} points have v- below {floor:.3g}, where "
        f"shooting resolves the impact to a few digits only (Delta d {weak[0]:.6g} .. "
        f"{weak[-1]:.6g})")
    limit = None
    if mu is not None:
        from grazing_control.dynamics.design.family import limit_multipliers

        limit = np.asarray(limit_multipliers(model, mu, actuation_of(args, model)),
                           dtype=complex)
    out.update({
        "gains": None if k is None else k.tolist(), "mu": mu, "control": how,
        "branch": [{"delta_d": p.value, "v_minus": p.v_min, "impacts": p.impacts,
                    "multipliers": complex_list(p.multipliers), "stable": p.stable,
                    "section_pi2_deviation": np.asarray(p.state).tolist()}
                   for p in branch.points],
        "bifurcations": [{"type": b.type, "delta_d": b.value,
                          "multipliers": complex_list(b.multipliers)}
                         for b in branch.bifurcations],
        "stopped": branch.stopped, "fold": fold,
        "route": "impact phase" if explicit else "shooting", "warning": warning,
        "start_branch": "grazing" if first.near_grazing else "other",
        "multipliers_limit": None if limit is None else complex_list(limit),
        "seconds": seconds,
    })
    out.update(_actuation_json(delay, width))
    route = "in the impact phase (exact to rounding)" if explicit else "by shooting"
    title = (f"1/1 branch {route}, {len(branch.points)} points from Delta d = "
             f"{args.start:g} towards {args.stop:g}"
             + ("" if k is None else f" ({how}{'' if mu is None else f', mu = {mu:.8g}'}"
                f"{_delay_text(delay, width)})"))
    lines = [f"  stopped: {branch.stopped}"]
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
    return (out, title, [(p.value, p.v_min, p.multipliers, p.stable) for p in branch.points],
            [(b.type, b.value) for b in branch.bifurcations], lines)


# ---------------------------------------------------------------------------- simulate
def cmd_simulate(args):
    """simulate --delta-d DD --periods N [--c2 ..] or --model FILE [gains]: the Pi2 samples,
    by the model's route (:func:`_study_simulation`, :func:`_file_simulation`)."""
    out, lines = (_file_simulation if args.model is not None else _study_simulation)(args)
    return out if args.json else "\n".join(lines)


def _study_simulation(args):
    """The 1-DOF study's simulation (the exact flow or a fidelity, or a compliant stop,
    :func:`_simulate_stop`): its JSON and its report's lines."""
    from grazing_control.dynamics.simulation.simulate import simulate

    p = params_of(args, args.delta_d)
    gains = gains_of(args, p)
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
    if args.contact != "rigid" or _stop_options(args):
        return _simulate_stop(args, p, gains, control_after, physical, deviation)
    progress = (not args.json and args.periods >= 2000 and sys.stderr.isatty())
    res = simulate(p, args.periods, x0=args.x0, v0=args.v0, deviation=deviation, gains=gains,
                   control_after=control_after, fidelity=args.fidelity, tol=args.tol,
                   progress=progress)
    out = {"pi2": res.pi2.tolist(), "impacts_per_period": res.impacts_per_period.tolist()}
    if args.fidelity != "exact":
        out.update(fidelity=res.fidelity, fidelity_reason=res.fidelity_reason)
    require_finite(out, "simulate")
    spectrum = None
    if args.lyapunov:
        from grazing_control.dynamics.simulation.lyapunov import lyapunov_exact

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
    return out, (_pi2_lines(
        f"simulated {args.periods} periods at Delta d = {p.delta_d:.6g}"
        + (f", control on from sample {control_after}" if gains is not None else ", uncontrolled"),
        res, args.periods) + ([] if spectrum is None else [
        f"  Lyapunov exponents = {spectrum.exponents[0]:.10g}, {spectrum.exponents[1]:.10g} "
        f"per period (last {spectrum.periods} periods, {spectrum.impacts_per_period:.4g} "
        "impacts per period)",
        f"  sum identity       = {spectrum.expected_sum:.15g} (-2 zeta T + 2 nu ln r"
        f"{' + ln|1 + c2| share' if gains is not None else ''}), residual "
        f"{spectrum.sum_residual:.2e}"
        + (f"; {spectrum.stuck_periods} periods stuck (singular map)"
           if spectrum.stuck_periods else "")]))


_STOP_OPTIONS = (("contact_stiffness", "--contact-stiffness"),
                 ("contact_damping", "--contact-damping"), ("friction", "--friction"),
                 ("friction_static", "--friction-static"), ("stop", "--stop"),
                 ("stop_tol", "--stop-tol"))


def _stop_options(args) -> list:
    """The compliant stop's options given (``grazing simulate``)."""
    return [flag for name, flag in _STOP_OPTIONS if getattr(args, name) is not None]


def _simulate_stop(args, p, gains, control_after, physical, deviation):
    """``grazing simulate --contact kelvin_voigt``: the scene on the cheapest adequate stop
    model, or the one ``--stop`` names, checked (:func:`grazing_control.dynamics.
    simulation.stop_fidelity.simulate_stop`; docs/theory_contact.md section 18)."""
    from grazing_control.dynamics.simulation.stop_fidelity import simulate_stop
    from grazing_control.oscillator.contact import Coulomb, KelvinVoigt

    if args.contact == "rigid":
        raise ParameterError(f"{', '.join(_stop_options(args))}: valid only with --contact "
                             "kelvin_voigt (the compliant stop they describe)")
    for flag, bad in (("--fidelity", args.fidelity != "exact"), ("--lyapunov", args.lyapunov)):
        if bad:
            raise ParameterError(f"{flag} is invalid with --contact kelvin_voigt: the stop "
                                 "model is chosen by --stop (the exact flow of each)")
    if args.contact_stiffness is None:
        raise ParameterError("--contact kelvin_voigt needs --contact-stiffness (k_c over the "
                             "oscillator's, > 0)")
    law = (KelvinVoigt.from_restitution(args.contact_stiffness, p.r)
           if args.contact_damping is None
           else KelvinVoigt(args.contact_stiffness, args.contact_damping))
    friction = None
    if args.friction:
        friction = Coulomb(args.friction, args.friction_static)
    elif args.friction_static:
        raise ParameterError("--friction-static needs --friction > 0 (the kinetic level)")
    if physical:
        deviation = ((p.x_ref if args.x0 is None else args.x0) - p.x_ref,
                     (p.v_ref if args.v0 is None else args.v0) - p.v_ref)
    tol = 1e-3 if args.stop_tol is None else args.stop_tol
    res, choice, warning = simulate_stop(
        p, law, friction, args.periods, deviation=deviation or (0.0, 0.0), gains=gains,
        control_after=control_after, stop=args.stop or "auto", tol=tol)
    if warning:
        print(f"grazing: warning: {warning}", file=sys.stderr)
    out = {"pi2": res.pi2.tolist(), "impacts_per_period": res.impacts_per_period.tolist(),
           "stop": choice.stop, "stop_reason": choice.reason,
           "stop_estimates": {k: {"one_period_error": e, "bound": b}
                              for k, (e, b) in choice.estimates.items()},
           "contact": {"stiffness": law.stiffness, "damping": law.damping,
                       "restitution": law.restitution,
                       "friction": 0.0 if friction is None else friction.kinetic,
                       "friction_static": 0.0 if friction is None else friction.static}}
    if warning:
        out["stop_warning"] = warning
    out = nulls(out)          # a refused candidate's bound: inf -> null
    require_finite({k: out[k] for k in ("pi2", "impacts_per_period")}, "simulate")
    return out, _pi2_lines(
        f"simulated {args.periods} periods at Delta d = {p.delta_d:.6g} with a Kelvin-Voigt stop "
        f"(k_c = {law.stiffness:.6g}, c_c = {law.damping:.6g}, r = {law.restitution:.6g}"
        + (f", friction {friction.kinetic:.6g}" if friction else "") + ")"
        + (f", control on from sample {control_after}" if gains is not None else
           ", uncontrolled"),
        res, args.periods, "contacts", [f"  stop model         = {choice.stop}"])


def _pi2_lines(title, res, periods: int, word: str = "impacts", first=()) -> list:
    """The report of a 1-DOF ``grazing simulate`` (rigid or compliant stop): the title,
    ``first``, the impacts (:func:`impact_lines`), the last Pi2 sample, the model."""
    last = (f"({res.pi2[-1][0]:.15g}, {res.pi2[-1][1]:.15g})" if periods
            else "none (0 periods)")
    return [title, *first, *impact_lines(res.impacts_per_period, periods, word),
            f"  last Pi2 sample    = {last}", f"  model              = {res.fidelity_reason}"]


def _file_simulation(args):
    """A model file's simulation on Pi2 (docs/ndof_commands.md; its stop is rigid): its
    JSON and its report's lines."""
    from grazing_control.dynamics.orbits import one_one   # scipy: not at --version

    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.dynamics.orbits.near_grazing import with_delta_d
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound
    from grazing_control.studies.near_grazing.scene import simulate_pi2

    if args.contact != "rigid" or _stop_options(args):
        raise ParameterError("--contact and its options are 1-DOF options: an n-DOF "
                             "model file's stop is rigid (docs/ndof_model.md)")
    model = with_delta_d(load(args.model), args.delta_d)
    k, mu, how = control_of(args, model)
    delay, width = delay_of(args, model), pulse_width_of(args, model)
    after = None if k is None else (0 if args.control_after is None else args.control_after)
    samples, counts = simulate_pi2(model, args.periods, args.z0, k, after, delay, width)
    flow = NdofFlow.of(model)
    ref = flow.to_physical(flow.tau2, np.zeros(2 * model.n))
    out = {"pi2": (samples[:-1] + ref).tolist(), "pi2_deviation": samples[:-1].tolist(),
           "impacts_per_period": counts.tolist(), "final_deviation": samples[-1].tolist(),
           "gains": None if k is None else k.tolist(), "mu": mu, "control_after": after}
    out.update(_actuation_json(delay, width))
    orbit_note = ""
    if k is not None:
        try:
            o = one_one.orbit(model, k, delay=delay, width=width)
            dist = float(np.linalg.norm(samples[-1] - o.state))
            out.update(distance_to_orbit=dist, orbit_deviation=o.state.tolist(),
                       orbit_multipliers=complex_list(o.multipliers))
            orbit_note = (f"{dist:.3e} (|lambda|max of that orbit "
                          f"{np.max(np.abs(o.multipliers)):.4g})")
        except OrbitNotFound as exc:
            out.update(distance_to_orbit=None, orbit_error=str(exc))
            orbit_note = f"none ({' '.join(str(exc).split())[:160]})"
    n = args.periods
    lines = [
        f"simulated {n} periods of {args.model} at Delta d = {model.delta_d:.6g}"
        + (f", control on from sample {after} ({how}{_delay_text(delay, width)})"
           if k is not None
           else ", uncontrolled"),
        *impact_lines(counts, n),
        f"  last state (dev.)  = {fmt_vec(samples[-1], 10)}",
    ]
    if k is not None:
        lines.append(f"  distance to the controlled 1/1 orbit = {orbit_note}")
    return out, lines


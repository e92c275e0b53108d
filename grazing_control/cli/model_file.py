"""``--model FILE``: a command's model from a model file (docs/ndof_model.md) instead of the
1-DOF parameters, and the gains over it (docs/ndof_commands.md).

Every model command (design, orbit, continue, simulate, sweep, figures) is one command:
its model is the 1-DOF study's (the options of :mod:`.common`) or, with ``--model``, the
file's model of any n (``oscillator.ndof.NdofModel``; the n = 1 file gives the 1-DOF
numbers, tests/test_cli_model.py). This module reads the model side: the option, the file,
the refusal of the other side's options, and the gains as a vector k of 2n numbers (the
kick v[i_a] += k^T (X - X**) at Pi2, coordinates x0..x{n-1}, v0..v{n-1}), given as

* ``--gains k0,k1,...``: the vector itself;
* ``--mu MU``: the member of the design family whose free eigenvalue is mu
  (w^T N = mu w^T, docs/theory_ndof.md, "Kick design");
* ``--free-gain NAME=VALUE``: the member of the family whose gain on coordinate NAME
  is VALUE (for n = 1, ``--free-gain v0=C2`` is the 1-DOF ``--c2 C2``).

With ``--delay D`` (every command here: design, orbit, continue, simulate, sweep,
figures) the kick k^T z of the sample acts D later, 0 <= D < T - pi2_offset/omega (:func:`delay_of`): the family members of ``--mu``
and ``--free-gain`` are the delayed kick's (docs/theory_ndof.md §14), as ``design --delay``
gives them. With ``--pulse-width W`` as well (orbit, continue, simulate; design has its
own) the correction is the force pulse of width W centred D after the sample
(:func:`pulse_width_of`, :func:`actuation_of`): the family members are the pulse's
(docs/theory_ndof.md §15), as ``design --delay D --pulse-width W`` gives them, and a gain
file of that design carries both.

A leaf of the command line like :mod:`.common`. Errors are one line and status 2, as for
every command (cli/commands.py).
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.oscillator.params import ParameterError

__all__ = ["add_model_option", "add_gain_options", "add_design_options", "add_start_option",
           "add_sweep_options", "add_figures_options", "check_options", "load", "coordinates",
           "family_member", "gains_of", "delay_of", "pulse_width_of", "actuation_of",
           "add_pulse_option", "control_of", "dispatch", "fmt_vec", "header"]

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


class GainFile(str):
    """``--gains FILE``: the path of a gain file of ``design --model M --out FILE``
    (read against the model by :func:`gain_file`)."""


def _gains_value(text):
    """``--gains``: comma-separated numbers, or the path of a YAML gain file (a name
    ending in .yaml or .yml, or any existing file: ``design --out`` writes YAML under
    the name it is given)."""
    import argparse
    import os

    if text.lower().endswith((".yaml", ".yml")):
        return GainFile(text)
    try:
        return _vector(text)
    except argparse.ArgumentTypeError:
        if os.path.isfile(text):
            return GainFile(text)
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected comma-separated "
                                         "finite numbers, e.g. 0.1,-0.2,0,0.5, or a gain file "
                                         "of design --out (FILE.yaml)") from None


#: Entries of a gain file that must equal the model's (``family.controller_parameters``).
GAIN_FILE_MODEL = ("n", "i_a", "omega", "pi2_offset")


#: A gain file's actuator entries: orbit, continue and simulate run the kick or the ideal
#: pulse, not the pulse through a first-order actuator (its force is a state of its own).
GAIN_FILE_ACTUATOR = ("actuator_bandwidth", "actuator_latency")


def gain_file(path, model):
    """(k, actuation_delay, pulse_width) of a gain file of ``design --model M --out FILE``
    (``family.write_gain_yaml``), checked against ``model``: its n, i_a, omega and
    pi2_offset must be the model's (a file designed for another model is refused, one
    line naming the entry); a file of a pulse through an actuator (actuator_bandwidth or
    actuator_latency not 0) is refused (these commands run the kick or the ideal
    pulse)."""
    from grazing_control.support.files import YamlFileError, read_yaml_file, ros_parameters

    try:
        values = ros_parameters(read_yaml_file(path))
    except YamlFileError as exc:
        raise ParameterError(f"--gains {exc}") from None
    if "gains" not in values:
        raise ParameterError(f"--gains {path}: not a gain file of design --model --out "
                             "(expected /**: ros__parameters: {gains: [...], n, i_a, omega, "
                             "pi2_offset})")
    for name in GAIN_FILE_MODEL:
        want = getattr(model, name)
        got = values.get(name)
        if isinstance(got, bool) or not isinstance(got, (int, float)) or \
                not abs(float(got) - want) <= 1e-12 * max(1.0, abs(want)):
            raise ParameterError(f"--gains {path}: {name}={got!r} is invalid for this model: "
                                 f"the model file gives {name} = {want!r} (a gain file of "
                                 "another model)")
    for name in GAIN_FILE_ACTUATOR:
        if values.get(name):
            raise ParameterError(f"--gains {path}: {name}={values[name]!r} is invalid here: "
                                 "orbit, continue and simulate run the kick or the ideal "
                                 f"pulse (valid: {name} absent or 0)")
    try:
        k = np.array([float(x) for x in values["gains"]], dtype=float)
        delay = float(values.get("actuation_delay", 0.0))
        width = float(values.get("pulse_width", 0.0))
    except (TypeError, ValueError):
        k, delay, width = np.array([math.nan]), math.nan, math.nan
    if k.size != 2 * model.n or not np.all(np.isfinite(k)) or not math.isfinite(delay) \
            or not math.isfinite(width):
        raise ParameterError(f"--gains {path}: gains, actuation_delay and pulse_width are "
                             f"invalid: expected 2n = {2 * model.n} finite gains, a finite "
                             "delay and a finite width")
    return k, delay, width


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
    g.add_argument("--gains", type=_gains_value, metavar="K0,K1,...|FILE.yaml",
                   help="the 2n gains k (x0..x{n-1}, v0..v{n-1}) of v[i_a] += k^T (X - X**), "
                        "or a gain file of design --model M [--delay D] [--pulse-width W] "
                        "--out FILE.yaml: its gains, its actuation_delay and its pulse_width "
                        "(its n, i_a, omega, pi2_offset must be the model's; a --delay or "
                        "--pulse-width given must equal the file's; sweep takes a kick's file)")
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


def add_pulse_option(parser) -> None:
    """``--pulse-width W`` of orbit, continue and simulate (:func:`pulse_width_of`)."""
    parser.add_argument("--pulse-width", type=_finite, default=None, metavar="W",
                        help="with --model: the correction k^T z acts as a force pulse of "
                             "this width centred --delay after the Pi2 sample (the ideal "
                             "pulse of design --model M --delay D --pulse-width W; "
                             "docs/theory_ndof.md sections 15, 18), ending before the grazing "
                             "phase; default 0, the kick. A gain file of that design gives it")


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
#: The commands whose ``--pulse-width`` needs ``--model`` (design has a 1-DOF pulse design).
PULSE_COMMANDS = ("orbit", "continue", "simulate")


def check_options(args, argv) -> None:
    """Refuse 1-DOF model options with --model, and n-DOF options without it (the
    commands of :data:`COMMANDS`)."""
    if getattr(args, "command", None) not in COMMANDS:
        return
    model = getattr(args, "model", None)
    if model is None and args.command in PULSE_COMMANDS and _given(argv, "--pulse-width"):
        raise ParameterError("--pulse-width needs --model FILE: the 1-DOF orbit, continue "
                             "and simulate run the kick (the pulse's 1/1 orbit of the same "
                             "oscillator: --model config/models/study_1dof.yaml)")
    if model is not None:
        bad = [f for f in ONE_DOF_OPTIONS if _given(argv, f)
               and f != "--delay"          # every model command takes the delayed kick
               and not (f == "--sensor-rate" and args.command == "design")]
        # (the delayed kick; the predicted spread's position-only sensor)
        if bad:
            raise ParameterError(f"{', '.join(bad)} {'is a 1-DOF option' if len(bad) == 1 else 'are 1-DOF options'}"
                                 f": with --model the model file gives the model "
                                 "(docs/ndof_model.md); give the gains as --gains, --mu or "
                                 "--free-gain")
    elif getattr(args, "rig", None) is None:   # a rig of n masses takes them (cli/rig.py)
        bad = [f for f in MODEL_OPTIONS if _given(argv, f)]
        if args.command == "figures" and _given(argv, "--delay"):
            bad.append("--delay")        # the study's figures run no controller to delay
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
    from grazing_control.dynamics.design.family import gain_family

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
    from grazing_control.dynamics.design.family import MU_LIMIT

    if not abs(mu) <= MU_LIMIT:
        raise ParameterError(f"--free-gain {name}={value!r} is invalid: it is the member "
                             f"mu = {mu:g} of the family; valid are the gains of |mu| <= "
                             f"{MU_LIMIT:g}, i.e. {name} between "
                             f"{k0[j] - MU_LIMIT * abs(k1[j]):.6g} and "
                             f"{k0[j] + MU_LIMIT * abs(k1[j]):.6g}")
    return mu


def delay_of(args, model) -> float:
    """The actuation delay of ``--delay`` (default 0), checked against the model: the kick
    must act before the grazing phase, 0 <= delay < T - s, s = pi2_offset / omega
    (docs/theory_ndof.md §14; the bound of ``design --delay``). One-line ParameterError
    naming --delay and the range."""
    delay = float(getattr(args, "delay", 0.0) or 0.0)
    reach = model.period - model.pi2_offset / model.omega
    if not (math.isfinite(delay) and 0.0 <= delay < reach):
        raise ParameterError(f"--delay {delay!r} is invalid: valid range is 0 <= delay < "
                             f"T - pi2_offset/omega = {reach:.10g} for this model (the kick "
                             "must act before the grazing phase, docs/theory_ndof.md §14)")
    return delay


def pulse_width_of(args, model) -> float:
    """The pulse width of ``--pulse-width`` (default 0: the kick), checked against the
    model and ``--delay`` D: the pulse centred D after the sample (it starts at
    max(D - W/2, 0)) must end before the grazing phase, end = max(D + W/2, W) < R =
    T - pi2_offset/omega, i.e. 0 <= W < min(R, 2 (R - D)) (docs/theory_ndof.md §15; the
    bound of ``design --pulse-width``). One-line ParameterError naming --pulse-width and
    the range."""
    width = getattr(args, "pulse_width", None)
    width = 0.0 if width is None else float(width)
    delay = delay_of(args, model)
    reach = model.period - model.pi2_offset / model.omega
    most = min(reach, 2.0 * (reach - delay))
    if not (math.isfinite(width) and 0.0 <= width < most):
        raise ParameterError(f"--pulse-width {width!r} is invalid: valid range is 0 <= "
                             f"pulse_width < {most:.10g} with --delay {delay:g} for this model "
                             "(the pulse centred at the delay must end before the grazing "
                             f"phase T - pi2_offset/omega = {reach:.10g}, docs/theory_ndof.md "
                             "§15)")
    return width


def actuation_of(args, model):
    """The correction's actuation of ``--delay`` and ``--pulse-width``: the kick's delay
    (a float), or ``family.Actuation(delay, width)`` for the pulse (the ``delay``
    argument of the family and the orbits, ``family.design_actuation``)."""
    from grazing_control.dynamics.design.family import design_actuation

    return design_actuation(delay_of(args, model), pulse_width_of(args, model))


def gains_of(args, model):
    """(gains or None, mu or None, how): the gains of --gains / --mu / --free-gain (at most
    one), or of --cancel-first-markov OFFSET with --mu; None: uncontrolled. With
    ``--delay`` (:func:`delay_of`) and ``--pulse-width`` (:func:`pulse_width_of`) the
    family is the delayed kick's or the pulse's; a delay or a pulse without gains is
    refused. ``--gains FILE`` (:func:`gain_file`) sets ``args.delay`` and
    ``args.pulse_width`` to the file's actuation_delay and pulse_width (a different
    --delay or --pulse-width is refused, and a pulse's file in a command without
    --pulse-width: sweep)."""
    if isinstance(getattr(args, "gains", None), GainFile):
        k, file_delay, file_width = gain_file(args.gains, model)
        given = float(getattr(args, "delay", 0.0) or 0.0)
        if given and given != file_delay:
            raise ParameterError(f"--delay {given!r} is invalid with --gains {args.gains}: "
                                 f"the file's actuation_delay is {file_delay!r} (give the "
                                 "same, or none)")
        args.delay = file_delay
        delay_of(args, model)
        _file_pulse(args, file_width)
        pulse_width_of(args, model)
        if getattr(args, "cancel_first_markov", None) is not None or \
                getattr(args, "mu", None) is not None or getattr(args, "free_gain", None):
            raise ParameterError("--gains FILE and --mu/--free-gain/--cancel-first-markov are "
                                 "given: give one of --gains, --mu, --free-gain")
        return k, None, f"gain file {args.gains}"
    delay = actuation_of(args, model)
    offset = getattr(args, "cancel_first_markov", None)
    given = [f for f, v in (("--gains", getattr(args, "gains", None)),
                            ("--mu", getattr(args, "mu", None)),
                            ("--free-gain", getattr(args, "free_gain", None))) if v is not None]
    if offset is not None:
        if given != ["--mu"]:
            raise ParameterError("--cancel-first-markov OFFSET needs --mu MU (the family member "
                                 "it moves off by OFFSET), and neither --gains nor --free-gain")
        from grazing_control.dynamics.design.family import cancel_first_markov

        only = bool(getattr(args, "markov_only", False))
        k = np.asarray(cancel_first_markov(model, args.mu, offset, smooth_branch=not only,
                                           delay=delay), dtype=float)
        what = "only w^T N u" if only else "w^T N u and G(1)"
        return k, None, f"cancels {what}: k(mu = {args.mu:g}) + {offset:g} d"
    if getattr(args, "markov_only", False):
        raise ParameterError("--markov-only goes with --cancel-first-markov OFFSET --mu MU")
    if len(given) > 1:
        raise ParameterError(f"{' and '.join(given)} are given: give one of --gains, --mu, "
                             "--free-gain")
    if not given:
        if getattr(args, "pulse_width", None):
            raise ParameterError("--pulse-width needs the gains: give --gains, --mu or "
                                 "--free-gain")
        if delay:
            raise ParameterError("--delay needs the gains: give --gains, --mu or --free-gain")
        return None, None, "uncontrolled"
    if given[0] == "--gains":
        k = np.asarray(args.gains, dtype=float)
        if k.size != 2 * model.n:
            raise ParameterError(f"--gains has {k.size} values: the model has n = {model.n}, "
                                 f"give 2n = {2 * model.n} ({', '.join(coordinates(model))})")
        return k, None, "given"
    from grazing_control.dynamics.design.family import gain_family

    mu = args.mu if given[0] == "--mu" else family_member(model, *args.free_gain, delay)
    return np.asarray(gain_family(model, mu, delay), dtype=float), mu, "design family"




def _file_pulse(args, width: float) -> None:
    """Set ``args.pulse_width`` to a gain file's pulse_width: a different ``--pulse-width``
    given is refused, and a pulse's file in a command that runs the kick only (no
    ``--pulse-width`` option: sweep), each in one line naming the option or the entry."""
    if not hasattr(args, "pulse_width"):
        if width:
            raise ParameterError(f"--gains {args.gains}: pulse_width={width!r} is invalid "
                                 f"here: {args.command} runs the kick (valid: a kick's gain "
                                 "file, pulse_width absent or 0; orbit, continue and "
                                 "simulate run the pulse)")
        return
    given = args.pulse_width
    if given is not None and float(given) != width:
        raise ParameterError(f"--pulse-width {float(given)!r} is invalid with --gains "
                             f"{args.gains}: the file's pulse_width is {width!r} (give the "
                             "same, or none)")
    args.pulse_width = width


def control_of(args, model):
    """(gains or None, mu or None, how) of a command that runs the model from a start
    (simulate, sweep): the gains of :func:`gains_of`, with ``--control-after`` refused
    without them and ``--z0`` checked to have 2n values."""
    k, mu, how = gains_of(args, model)
    if args.control_after is not None and k is None:
        raise ParameterError("--control-after needs the gains: give --gains, --mu or --free-gain")
    if args.z0 is not None and len(args.z0) != 2 * model.n:
        raise ParameterError(f"--z0 has {len(args.z0)} values: give 2n = {2 * model.n} "
                             f"({', '.join(coordinates(model))}, deviation from X** on Pi2)")
    return k, mu, how


def fmt_vec(v, digits=10):
    """``[a, b, ...]`` of a vector, each to ``digits`` significant digits."""
    return "[" + ", ".join(f"{x:.{digits}g}" for x in np.asarray(v, dtype=float)) + "]"


def header(model, path) -> dict:
    """The model file's header of every report: the file, n, i_w, i_a, d*, tau*, the
    coordinates."""
    from grazing_control.oscillator.ndof.flow import NdofFlow

    flow = NdofFlow.of(model)
    return {"model": str(path), "n": model.n, "i_w": model.i_w, "i_a": model.i_a,
            "d_star": float(flow.d_star), "tau_star": float(flow.tau_star),
            "coordinates": list(coordinates(model))}


def dispatch(one_dof, model_file):
    """A subcommand's function: ``model_file`` with --model, else the 1-DOF ``one_dof``
    (sweep and figures, whose 1-DOF commands live in the studies they run)."""
    def run(args):
        return model_file(args) if getattr(args, "model", None) is not None else one_dof(args)

    run.__name__ = getattr(one_dof, "__name__", "run")
    return run


def add_sweep_options(parser) -> None:
    """--model, the gains, --delay, --z0 and --coordinate of ``sweep --model`` (--delay:
    also the 1-DOF sweep's, the actuation delay of its gains)."""
    from .common import add_delay

    add_model_option(parser)
    add_gain_options(parser)
    add_delay(parser)
    add_start_option(parser)
    parser.add_argument("--coordinate", metavar="NAME",
                        help="with --model: the Pi2 coordinate drawn in the PNG, x0.. or v0.. "
                             "(default: the wall coordinate x{i_w})")




def add_figures_options(parser) -> None:
    """--model, --mu and --delay of ``figures --model``."""
    add_model_option(parser)
    parser.add_argument("--mu", type=_finite,
                        help="with --model: the design family's member drawn (default: the "
                             "middle of the widest admissible interval)")
    parser.add_argument("--delay", type=_finite, default=0.0,
                        help="with --model: the kick k^T z acts this long after the Pi2 "
                             "sample, 0 <= delay < T - pi2_offset/omega: the delayed "
                             "family's member, its multipliers near grazing, diagram and "
                             "scene (docs/theory_ndof.md section 14); default 0")



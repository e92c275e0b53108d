"""What the `grazing` subcommands share: the 1-DOF model and gain options, their reading
into :class:`OscillatorParams` and :class:`Gains`, and the JSON helpers of every report.

A leaf of the command line: cli/commands.py (the parser and the orbit, continue,
simulate commands), cli/design.py, cli/basins.py and cli/continue2.py import it; it
imports none of them (docs/architecture.md, the `cli` row; .importlinter, cli-no-circle).
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import (STUDY_R, STUDY_ZETA, OscillatorParams,
                                               ParameterError, study_omega)
from grazing_control.support.arguments import finite, integer_at_least, non_empty_path

from .parameter_file import add_params_option

__all__ = ["TWO_PI", "MAX_DECAY", "complex_list", "non_finite", "require_finite", "nulls",
           "finite", "count", "file_path", "add_common", "add_method", "add_gains", "add_delay",
           "params_of", "gains_of", "add_rig_option"]

TWO_PI = 2.0 * math.pi


def complex_list(values):
    return [[float(np.real(z)), float(np.imag(z))] for z in values]


count = integer_at_least(0)
file_path = non_empty_path


def non_finite(obj, where=""):
    """Key paths of the non-finite floats in a result (nested dicts and lists)."""
    if isinstance(obj, float):
        return [] if math.isfinite(obj) else [f"{where}={obj!r}"]
    if isinstance(obj, dict):
        return [w for k, v in obj.items() for w in non_finite(v, f"{where}.{k}" if where else k)]
    if isinstance(obj, (list, tuple)):
        return [w for i, v in enumerate(obj) for w in non_finite(v, f"{where}[{i}]")]
    return []


def require_finite(out, command):
    """A result with nan/inf is an input outside the computable range: say so (status 2)."""
    bad = non_finite(out)
    if bad:
        raise ParameterError(
            f"{command}: the result is not finite ({', '.join(bad[:3])}"
            f"{', ...' if len(bad) > 3 else ''}): an input is outside the computable range")


def nulls(obj):
    """nan/inf -> None (JSON null), recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: nulls(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [nulls(v) for v in obj]
    return obj


def add_common(parser):
    g = parser.add_argument_group("model (defaults: the study's parameter set)")
    g.add_argument("--zeta", type=finite, default=STUDY_ZETA, help="damping ratio, 0 < zeta < 1")
    g.add_argument("--r", type=finite, default=STUDY_R, help="restitution, 0 < r < 1")
    g.add_argument("--omega", type=finite, default=study_omega(), help="forcing frequency > 0")
    g.add_argument("--pi2-offset", type=finite, default=math.pi / 2,
                   help="phase of Pi2 after Pi1, in (0, 2 pi)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_params_option(g)
    add_rig_option(g)


def add_method(parser):
    parser.add_argument("--method", choices=("exact", "perturbation"), default="exact",
                        help="exact (shooting, the accurate route) or perturbation (series in "
                             "delta2, the fast estimate); the cost is reported")


def add_gains(parser, required=False):
    parser.add_argument("--c1", type=finite, help="gain c1 (default: degenerate condition Eq. 38)")
    parser.add_argument("--c2", type=finite, required=required, help="gain c2")
    add_delay(parser)


def add_delay(parser):
    parser.add_argument("--delay", type=finite, default=0.0,
                        help="actuation delay: the correction acts this long (simulation time) "
                             "after the Pi2 sample, 0 <= delay < T - pi2_offset/omega "
                             "(docs/theory_delay.md); default 0. With --model (design, orbit, "
                             "continue, simulate, sweep) the kick k^T z acts this long after the "
                             "sample and --mu/--free-gain are the delayed family's "
                             "(docs/ndof_commands.md)")


#: Largest zeta T (forcing periods' decay exponent) the commands accept: e^{-2 zeta T}
#: underflows near 700 and the period maps become 0.
MAX_DECAY = 300.0


def params_of(args, delta_d=0.0):
    p = OscillatorParams(zeta=args.zeta, r=args.r, omega=args.omega, delta_d=delta_d,
                         pi2_offset=args.pi2_offset)
    if not 1e-100 < p.amplitude < 1e100:
        raise ParameterError(
            f"omega={p.omega!r} is invalid with zeta={p.zeta!r}: the non-impacting amplitude "
            f"a(omega) = {p.amplitude:.3g} is outside the computable range (1e-100, 1e100)")
    if not p.zeta * p.period <= MAX_DECAY:
        raise ParameterError(
            f"omega={p.omega!r} is invalid with zeta={p.zeta!r}: valid range is "
            f"omega >= 2 pi zeta / {MAX_DECAY:g} = {TWO_PI * p.zeta / MAX_DECAY:.3g} "
            f"(the decay e^(-zeta T) over a forcing period underflows)")
    return p


def gains_of(args, p):
    delay = getattr(args, "delay", 0.0)
    if args.c2 is None:
        if args.c1 is not None:
            raise ParameterError("c1 given without c2: give both, or c2 alone (c1 from Eq. 38)")
        if delay != 0.0:
            raise ParameterError("--delay needs the gains: give --c2 (and optionally --c1)")
        return None
    from grazing_control.dynamics.design.gains import degenerate_c1

    c1 = degenerate_c1(p, args.c2, delay) if args.c1 is None else args.c1
    return Gains(c1, args.c2, delay)


def add_rig_option(parser) -> None:
    """``--rig FILE`` on a subcommand's parser or group (read by cli/rig.py, apply_rig)."""
    parser.add_argument("--rig", metavar="FILE", default=None,
                        help="take the model from this rig file in SI units (docs/rig.md, "
                             "e.g. config/rigs/lab_20hz.yaml): zeta, r, omega, pi2_offset and "
                             "Delta d, and where the command has them the actuation delay "
                             "(the budget) and the sensor's samples per period; those options "
                             "are then refused")

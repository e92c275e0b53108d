"""The model's parameter file: what ``grazing identify --out`` writes and ``--params`` reads.

A ROS 2 parameter file keyed ``/**`` (so that it applies to any node, under any
namespace), the format sim_node loads with ``--params-file`` and ``grazing run
--sim-params`` takes::

    # model parameters identified by `grazing identify` ...
    /**:
      ros__parameters:
        zeta: 0.01
        r: 0.68
        omega: 0.6671333325
        delta_d: -5.0e-06

``--params FILE`` (the commands that take the model: design, orbit, continue, simulate,
sweep, basins, robustness, run) reads the model's keys from such a file, or from any ROS 2
parameter file with them (``grazing design --out``'s controller file too); an option given
on the command line wins over the file.
"""

from __future__ import annotations

import math

from grazing_control.oscillator.params import ParameterError

__all__ = ["MODEL_KEYS", "write_parameter_file", "read_parameter_file",
           "add_params_option", "apply_to_args"]

#: The model's keys a parameter file may carry (sim_node's parameter names).
MODEL_KEYS = ("zeta", "r", "omega", "delta_d", "pi2_offset")


def write_parameter_file(path, values: dict, comments=()) -> None:
    """Write ``values`` (model keys -> floats) as a ``/**`` ROS 2 parameter file, with
    ``comments`` as ``#`` lines on top; written to a temporary file and renamed."""
    from grazing_control.support.files import write_yaml_atomic

    body = {k: float(values[k]) for k in MODEL_KEYS if k in values}
    write_yaml_atomic(path, {"/**": {"ros__parameters": body}}, comments)


def read_parameter_file(path) -> dict:
    """The model's keys of a ROS 2 parameter file (``/**`` first, then the other node
    keys in file order). ParameterError naming the file and key for a non-number, and
    for a file beyond the limits of :func:`grazing_control.support.files.read_yaml_file`."""
    from grazing_control.support.files import YamlFileError, read_yaml_file

    try:
        doc = read_yaml_file(path)
    except YamlFileError as exc:
        raise ParameterError(f"--params {exc}") from None
    if not isinstance(doc, dict):
        raise ParameterError(f"--params {path}: not a ROS 2 parameter file (expected "
                             "'/**: ros__parameters: {...}')")
    keys = sorted(doc, key=lambda k: k != "/**")
    out = {}
    for node in keys:
        params = doc[node].get("ros__parameters") if isinstance(doc[node], dict) else None
        if not isinstance(params, dict):
            continue
        for k in MODEL_KEYS:
            if k in params and k not in out:
                v = params[k]
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ParameterError(f"--params {path}: {k}={v!r} is invalid: expected a "
                                         "finite real number")
                out[k] = float(v)
    if not out:
        raise ParameterError(f"--params {path}: no model parameter in it (expected some of "
                             f"{', '.join(MODEL_KEYS)} under '/**: ros__parameters:')")
    return out


def add_params_option(parser) -> None:
    """Add ``--params FILE`` (module docstring) to a subcommand's parser or group."""
    parser.add_argument("--params", metavar="FILE", default=None,
                        help="read the model (zeta, r, omega, pi2_offset, delta_d) from this "
                             "parameter file (`grazing identify --out`); options given here win")


def _given(argv, name) -> bool:
    """Whether ``--name`` was given on the command line (then it wins over the file)."""
    flag = "--" + name.replace("_", "-")
    return any(a == flag or a.startswith(flag + "=") for a in argv)


def apply_to_args(args, argv) -> None:
    """Apply ``args.params`` (if any) to the parsed options not given on the command line;
    for ``run``, as sim_node overrides. Removes ``args.params``."""
    path = getattr(args, "params", None)
    if hasattr(args, "params"):
        delattr(args, "params")
    if path is None:
        return
    values = read_parameter_file(path)
    if getattr(args, "command", None) == "run":
        over = dict(args.sim_overrides or {})
        for k, v in values.items():
            if k == "delta_d" and args.delta_d is not None:
                continue
            over.setdefault(k, v)
        args.sim_overrides = over
        return
    for k, v in values.items():
        if hasattr(args, k) and not _given(argv, k):
            setattr(args, k, v)

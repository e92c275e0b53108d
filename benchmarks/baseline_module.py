"""A baseline checkout's module loaded beside this tree's, for the benchmarks that run
the two side by side in one process (``git worktree add --detach /tmp/base <rev>``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path


def load(root: Path, module: str, name: str | None = None):
    """The baseline's ``module`` (dotted, e.g. grazing_control.dynamics.orbits.orbits) from
    the checkout at ``root``, registered as ``name`` (default: the module's package with
    ``_baseline_`` before its last part, so that its relative imports are this tree's
    siblings)."""
    package, _, last = module.rpartition(".")
    name = name or f"{package}._baseline_{last}"
    spec = importlib.util.spec_from_file_location(
        name, Path(root).joinpath(*module.split(".")).with_suffix(".py"))
    loaded = importlib.util.module_from_spec(spec)
    sys.modules[name] = loaded
    spec.loader.exec_module(loaded)
    return loaded


def report(label: str, count: int, unit: str, cpu: dict, same: int, what: str) -> None:
    """One line: the CPU of the baseline and of this tree, their ratio, and how many of
    the ``count`` outputs are the same, float for float."""
    print(f"{label}: {count} {unit}, CPU baseline {cpu['baseline']:.2f} s, this "
          f"{cpu['this']:.2f} s, ratio {cpu['baseline'] / cpu['this']:.2f}; the same {what} "
          f"float for float: {same} of {count}")


def random_oscillator(rng, with_delta_d: bool = False):
    """A seeded random oscillator of the design and orbit benchmarks (zeta 0.005-0.2,
    r 0.3-0.95, omega 0.3-2.5; with ``with_delta_d`` Delta d of 0, -1e-5, 1e-4 or -0),
    or None where the parameters are refused."""
    from grazing_control.oscillator.params import OscillatorParams, ParameterError

    values = dict(zeta=rng.uniform(0.005, 0.2), r=rng.uniform(0.3, 0.95),
                  omega=rng.uniform(0.3, 2.5))
    if with_delta_d:
        values["delta_d"] = rng.choice([0.0, -1e-5, 1e-4, -0.0])
    try:
        return OscillatorParams(**values)
    except ParameterError:
        return None

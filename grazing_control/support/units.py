"""Physical quantities as a rig file writes them: a number and a unit, "0.5 kg", "2 um".

:func:`quantity` reads one value of a given dimension and returns it in SI base units,
or raises :class:`UnitError` with one line naming the field, what was given and the
units it takes. A bare number is refused where a unit is required (a rig file that says
``gap: 0.002`` could mean metres or millimetres: the package does not guess).

The units are the few a rig of this field is written in; the prefixes are the SI ones
(n, u or µ, m, k) on the base units listed. No unit algebra: each dimension lists its
spellings (``N/m``, ``N*s/m``, ``N s/m``).
"""

from __future__ import annotations

import math
import re

__all__ = ["UnitError", "quantity", "DIMENSIONS", "format_quantity"]


class UnitError(ValueError):
    """A value without a unit, with a unit of the wrong dimension, or not a finite number."""


_PREFIX = {"n": 1e-9, "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "m": 1e-3, "": 1.0, "k": 1e3}


def _prefixed(base, prefixes="numk"):
    out = {base: 1.0}
    for p in prefixes:
        out[p + base] = _PREFIX[p]
    if "u" in prefixes:
        out["µ" + base] = out["μ" + base] = 1e-6
    return out


#: dimension -> {unit spelling: factor to SI}
DIMENSIONS = {
    "mass": {"kg": 1.0, "g": 1e-3},
    "length": _prefixed("m", "num"),
    "time": _prefixed("s", "num"),
    "frequency": {**_prefixed("Hz", "mk"), "rad/s": 1.0 / (2.0 * math.pi)},
    "force": _prefixed("N", "umk"),
    "stiffness": {"N/m": 1.0, "kN/m": 1e3, "N/mm": 1e3},
    "damping": {"N*s/m": 1.0, "N s/m": 1.0, "Ns/m": 1.0, "kg/s": 1.0},
    "force_constant": {"N/A": 1.0},
    "hertz_stiffness": {"N/m^1.5": 1.0, "N/m^(3/2)": 1.0, "N/m**1.5": 1.0},
    "hertz_damping": {"s/m": 1.0},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0},
}

#: The SI unit each dimension is returned in (frequency: Hz).
SI_UNIT = {"mass": "kg", "length": "m", "time": "s", "frequency": "Hz", "force": "N",
           "stiffness": "N/m", "damping": "N*s/m", "force_constant": "N/A", "angle": "rad",
           "hertz_stiffness": "N/m^1.5", "hertz_damping": "s/m"}

_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def quantity(field: str, value, dimension: str) -> float:
    """``value`` ("20 Hz", "2 um", "0.5 kg") in the SI unit of ``dimension``.

    Raises UnitError naming ``field`` for a bare number, an unknown or foreign unit, or a
    value that is not a finite number.
    """
    units = DIMENSIONS[dimension]
    accepted = ", ".join(units)
    if isinstance(value, bool):
        raise UnitError(f"{field}={value!r} is invalid: expected a number with a unit "
                        f"({accepted})")
    if isinstance(value, (int, float)):
        raise UnitError(f"{field}={value!r} has no unit: write it with one of {accepted} "
                        f"(e.g. '{value} {next(iter(units))}')")
    if not isinstance(value, str):
        raise UnitError(f"{field}={value!r} is invalid: expected a number with a unit "
                        f"({accepted})")
    m = _NUMBER.match(value)
    if m is None:
        raise UnitError(f"{field}={value!r} is invalid: expected a number with a unit "
                        f"({accepted})")
    number, unit = float(m.group(1)), m.group(2)
    if not unit:
        raise UnitError(f"{field}={value!r} has no unit: write it with one of {accepted}")
    if unit not in units:
        raise UnitError(f"{field}={value!r}: unit {unit!r} is not a {dimension.replace('_', ' ')}"
                        f" unit: valid units are {accepted}")
    si = number * units[unit]
    if not math.isfinite(si):
        raise UnitError(f"{field}={value!r} is invalid: not a finite {dimension}")
    return si


def format_quantity(value: float, dimension: str, digits: int = 17) -> str:
    """``value`` (SI) written back as a rig file takes it: "0.5 kg", "2e-06 m"."""
    return f"{value:.{digits}g} {SI_UNIT[dimension]}"

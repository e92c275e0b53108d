"""The rig file's field readers (plant/rig.py, plant/rig_structure.py): each value read
with its unit and range, each refusal one :class:`RigError` line naming the field."""

from __future__ import annotations

import math

from grazing_control.oscillator.params import ParameterError
from grazing_control.support.units import SI_UNIT, UnitError, quantity

__all__ = ["RigError", "MAGNITUDE"]

#: Every dimensional value other than an angle is 0 (where the field allows it) or of
#: magnitude in [1e-12, 1e12] in SI units: beyond, the model's scales under- or overflow.
MAGNITUDE = (1e-12, 1e12)


class RigError(ParameterError):
    """A rig file that cannot be used; one line naming the field and its valid range."""


def _section(doc, name, keys, required=True):
    value = doc.get(name)
    if value is None:
        if required:
            raise RigError(f"{name} is missing: a mapping of {', '.join(sorted(keys))}")
        return {}
    if not isinstance(value, dict):
        raise RigError(f"{name}={value!r} is invalid: expected a mapping of "
                       f"{', '.join(sorted(keys))}")
    unknown = sorted(set(map(str, value)) - keys)
    if unknown:
        raise RigError(f"{name}.{unknown[0]} is not a rig field: valid fields of {name} are "
                       f"{', '.join(sorted(keys))}")
    return value


def _q(doc, prefix, key, dimension, *, ok=None, valid="", default=None):
    field = f"{prefix}{key}"
    if key not in doc or doc[key] is None:
        if default is not None:
            return default
        raise RigError(f"{field} is missing: give it with a unit ({dimension.replace('_', ' ')})")
    try:
        value = quantity(field, doc[key], dimension)
    except UnitError as exc:
        raise RigError(str(exc)) from None
    if ok is not None and not ok(value):
        raise RigError(f"{field}={doc[key]!r} is invalid: valid range is {valid}")
    lo, hi = MAGNITUDE
    if dimension != "angle" and value != 0.0 and not lo <= abs(value) <= hi:
        raise RigError(f"{field}={doc[key]!r} is invalid: valid range is {lo:g} to {hi:g} "
                       f"{SI_UNIT[dimension]} in magnitude (the model's scales under- or "
                       "overflow beyond)")
    return value


def _number(doc, key, ok, valid, default=None):
    if key not in doc or doc[key] is None:
        if default is not None:
            return default
        raise RigError(f"{key} is missing: a number, {valid}")
    value = doc[key]
    if isinstance(value, str):
        raise RigError(f"{key}={value!r} is invalid: a dimensionless number, {valid} "
                       "(no unit)")
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or not ok(value):
        raise RigError(f"{key}={value!r} is invalid: valid range is {valid}")
    return float(value)


def _one_of(doc, prefix, a, b):
    have = [k for k in (a, b) if doc.get(k) is not None]
    if len(have) != 1:
        raise RigError(f"{prefix}{a} / {prefix}{b}: give exactly one of them "
                       f"({'both' if have else 'neither'} given)")
    return have[0]


def _list(doc, key, n=None) -> list:
    """The list ``doc[key]``: non-empty, of ``n`` entries (one per mass) if n is given."""
    value = doc.get(key)
    size = "a non-empty list" if n is None else f"a list of {n} entries (one per mass)"
    if not isinstance(value, list) or not value or (n is not None and len(value) != n):
        raise RigError(f"{key}={value!r} is invalid: expected {size}")
    return value


def _index(doc, prefix, key, n, default):
    """A mass index 0 <= i < n (``default`` if absent and not None)."""
    value = doc.get(key)
    if value is None and default is not None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
        raise RigError(f"{prefix}{key}={value!r} is invalid: valid range is a mass index, "
                       f"an integer 0 <= {prefix}{key} < {n} (0-based, the order of masses)")
    return value

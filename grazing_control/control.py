"""The discrete controller on section Pi2 (spec section 4, study Eq. 28).

Each time the orbit crosses Pi2 the velocity is changed instantaneously::

    v <- v + c1 (x - x**) + c2 (v - v**)

with X** = (x**, v**) the grazing orbit's point on Pi2. Since the grazing orbit is
the non-impacting motion x_p at d = d*, X** = y_p(tau2) and in deviation
coordinates (:mod:`grazing_control.flow`) the correction is linear:
dv <- dv + c1 dx + c2 dv, i.e. z <- G z with G = [[1, 0], [c1, 1 + c2]] (Eq. 29).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .params import ParameterError

__all__ = ["Gains", "correction", "gain_matrix"]


@dataclass(frozen=True)
class Gains:
    """Controller gains (c1, c2) of Eq. 28; both finite reals."""

    c1: float
    c2: float

    def __post_init__(self):
        for name in ("c1", "c2"):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ParameterError(f"{name}={value!r} is invalid: expected a finite real number") from None
            if not math.isfinite(value):
                raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite real number")
            object.__setattr__(self, name, value)


def correction(gains: Gains, x: float, v: float, x_ref: float, v_ref: float) -> float:
    """Velocity correction dv = c1 (x - x**) + c2 (v - v**) (Eq. 28)."""
    return gains.c1 * (x - x_ref) + gains.c2 * (v - v_ref)


def gain_matrix(gains: Gains | None):
    """G = [[1, 0], [c1, 1 + c2]] (Eq. 29) as (G11, G12, G21, G22); identity if None."""
    if gains is None:
        return (1.0, 0.0, 0.0, 1.0)
    return (1.0, 0.0, gains.c1, 1.0 + gains.c2)

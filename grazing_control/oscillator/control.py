"""The discrete controller on section Pi2 (spec section 4, study Eq. 28).

Each time the orbit crosses Pi2 the velocity is changed instantaneously::

    v <- v + c1 (x - x**) + c2 (v - v**)

with X** = (x**, v**) the grazing orbit's point on Pi2. Since the grazing orbit is
the non-impacting motion x_p at d = d*, X** = y_p(tau2) and in deviation
coordinates (:mod:`grazing_control.oscillator.flow`) the correction is linear:
dv <- dv + c1 dx + c2 dv, i.e. z <- G z with G = [[1, 0], [c1, 1 + c2]] (Eq. 29).

**Actuation delay** (docs/theory_delay.md, section 1). A correction k^T z computed
from the sample z and applied ``delay`` = delta after it (with no impact in between)
equals a kick on Pi2 along b_delta = Phi(-delta) e2::

    G_delta = I + b_delta k^T,   k = (c1, c2),   det G_delta = 1 + k^T b_delta,

so every linear map of the controlled motion (N_g, the monodromy of the 1/1 orbit)
keeps its form with G replaced by G_delta. delta = 0 gives b = e2 and Eq. 29 exactly.

**A model of n degrees of freedom** (docs/theory_ndof.md) takes the same kick with the
gains as one vector k over its 2n deviation coordinates (x0..x{n-1}, v0..v{n-1}):
:func:`gain_vector` is its one check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .flow import transition_matrix
from .params import ParameterError

__all__ = ["Gains", "correction", "gain_matrix", "gain_determinant", "kick_direction",
           "gain_vector"]


@dataclass(frozen=True)
class Gains:
    """Controller gains (c1, c2) of Eq. 28, both finite reals, and the actuation delay.

    Parameters
    ----------
    c1, c2 : float
        Gains of Eq. 28.
    delay : float
        Time (simulation units) from the Pi2 sample to the correction's action,
        finite and >= 0; 0 is the study's controller (docs/theory_delay.md). The
        upper limit (below the next sample, before the next impact) depends on the
        model and is checked where the gains are used.
    """

    c1: float
    c2: float
    delay: float = 0.0

    def __post_init__(self):
        for name in ("c1", "c2", "delay"):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ParameterError(f"{name}={value!r} is invalid: expected a finite real number") from None
            if not math.isfinite(value):
                raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite real number")
            object.__setattr__(self, name, value)
        if self.delay < 0.0:
            raise ParameterError(f"delay={self.delay!r} is invalid: valid range is a finite delay >= 0")


def correction(gains: Gains, x: float, v: float, x_ref: float, v_ref: float) -> float:
    """Velocity correction dv = c1 (x - x**) + c2 (v - v**) (Eq. 28)."""
    return gains.c1 * (x - x_ref) + gains.c2 * (v - v_ref)


def kick_direction(zeta: float, delay: float):
    """b_delta = Phi(-delta) (0, 1)^T: the kick on Pi2 equivalent to a delayed one.

    (0.0, 1.0) exactly for delay 0 (docs/theory_delay.md, Eq. (D1)).
    """
    if delay == 0.0:
        return (0.0, 1.0)
    _f11, f12, _f21, f22 = transition_matrix(zeta, -delay)
    return (f12, f22)


def _zeta_for(gains: Gains, zeta):
    if zeta is None:
        raise ValueError(f"delay={gains.delay!r} > 0 needs the damping ratio zeta to build G_delta")
    return zeta


def gain_matrix(gains: Gains | None, zeta: float | None = None):
    """G_delta = I + b_delta k^T as (G11, G12, G21, G22); identity if None.

    With no delay this is G = [[1, 0], [c1, 1 + c2]] (Eq. 29), built exactly as
    before; with a delay, ``zeta`` is needed for b_delta (docs/theory_delay.md, (D2)).
    """
    if gains is None:
        return (1.0, 0.0, 0.0, 1.0)
    if gains.delay == 0.0:
        return (1.0, 0.0, gains.c1, 1.0 + gains.c2)
    b1, b2 = kick_direction(_zeta_for(gains, zeta), gains.delay)
    return (1.0 + b1 * gains.c1, b1 * gains.c2, b2 * gains.c1, 1.0 + b2 * gains.c2)


def gain_determinant(gains: Gains | None, zeta: float | None = None) -> float:
    """det G_delta = 1 + k^T b_delta (1 + c2 without delay; 1 uncontrolled)."""
    if gains is None:
        return 1.0
    if gains.delay == 0.0:
        return 1.0 + gains.c2
    b1, b2 = kick_direction(_zeta_for(gains, zeta), gains.delay)
    return 1.0 + gains.c1 * b1 + gains.c2 * b2


def gain_vector(gains, n: int) -> np.ndarray:
    """The gains k of the kick v[i_a] += k^T z over the 2n deviation coordinates of a model
    of n degrees of freedom, as a new float array of 2n finite values (for n = 1,
    (c1, c2) of Eq. 28).

    Anything else is a :class:`ParameterError` naming ``gains`` and its valid range: the
    one check of a model file's gains (the design family, the explicit branch, the
    shooting near grazing, the modal map and the sweep over a model file).
    """
    try:
        k = np.array(gains, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        k = None
    if k is None or k.shape != (2 * n,) or not np.all(np.isfinite(k)):
        names = "x0, v0" if n == 1 else f"x0..x{n - 1}, v0..v{n - 1}"
        raise ParameterError(f"gains={_shown(gains)} is invalid: valid range is 2n = {2 * n} "
                             f"finite real numbers (the kick's gain on each of {names})")
    return k


def _shown(value) -> str:
    """``value`` as the refusal shows it (an array as its list)."""
    try:
        return repr(np.asarray(value).tolist())
    except (TypeError, ValueError):
        return repr(value)

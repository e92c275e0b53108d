"""Model parameters of the forced impact oscillator and the quantities derived from them.

The model (spec section 1, study Eq. 1), nondimensional with natural frequency 1::

    x'' + 2 zeta x' + x = cos(omega t + tau0)      while x < d
    v+ = -r v-                                      at x = d, v- > 0

One immutable object, :class:`OscillatorParams`, holds the free parameters with the
study's reference set as defaults; everything else (damped frequency, forcing period,
amplitude and phase lag of the non-impacting motion, grazing clearance d*, grazing phase
tau*, the section Pi2 and the grazing point X** on it) is derived, never stored.

Validation happens once, in the constructor: a bad value raises :class:`ParameterError`
that names the parameter and its valid range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from functools import cached_property

__all__ = [
    "ParameterError",
    "OscillatorParams",
    "STUDY_ZETA",
    "STUDY_R",
    "study_omega",
]

TWO_PI = 2.0 * math.pi

#: Damping ratio of the study's reference set.
STUDY_ZETA = 0.01
#: Coefficient of restitution of the study's reference set.
STUDY_R = 0.68


def study_omega(zeta: float = STUDY_ZETA) -> float:
    """Forcing frequency of the study, omega = 2 omega_d / 3 + 5e-4 (spec section 1)."""
    return 2.0 * math.sqrt(1.0 - zeta * zeta) / 3.0 + 5e-4


class ParameterError(ValueError):
    """A parameter is outside its valid range; the message names it and the range."""


def _require(name: str, value: float, ok: bool, valid: str) -> None:
    if not ok:
        raise ParameterError(f"{name}={value!r} is invalid: valid range is {valid}")


def _check_real(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            import numpy as np  # numpy scalars are fine

            if isinstance(value, np.generic) and np.isrealobj(value):
                value = float(value)
            else:
                raise TypeError
        except TypeError:
            raise ParameterError(
                f"{name}={value!r} is invalid: expected a real number"
            ) from None
    value = float(value)
    _require(name, value, math.isfinite(value), "a finite real number")
    return value


@dataclass(frozen=True)
class OscillatorParams:
    """Parameters of the single-degree-of-freedom impact oscillator (study Eq. 1).

    Parameters
    ----------
    zeta : float
        Damping ratio, 0 < zeta < 1.
    r : float
        Coefficient of restitution, 0 < r < 1.
    omega : float
        Forcing frequency, finite and > 0, not equal to the resonance 1 (where the
        non-impacting amplitude is not defined for zeta -> 0; it is allowed for zeta > 0).
    delta_d : float
        Wall clearance relative to grazing, Delta d = d - d* (the bifurcation
        parameter), any finite value; Delta d < 0 is the impacting side.
    tau0 : float
        Forcing phase at t = 0, finite; reduced modulo 2 pi.
    pi2_offset : float
        Phase of section Pi2 after Pi1, in (0, 2 pi); the study uses pi / 2 (Eq. 27).

    Notes
    -----
    Derived quantities are properties: :attr:`omega_d`, :attr:`period`,
    :attr:`amplitude` a(omega), :attr:`lag` phi, :attr:`d_star` = a(omega),
    :attr:`d`, :attr:`tau_star` = phi, :attr:`tau2`, :attr:`a_star` (Eq. 3) and
    :attr:`x_ref`, :attr:`v_ref` (X** on Pi2, spec section 3).

    Examples
    --------
    >>> p = OscillatorParams(delta_d=-5e-6)
    >>> round(p.d_star, 6), p.non_sticking
    (1.801498, True)
    """

    zeta: float = STUDY_ZETA
    r: float = STUDY_R
    omega: float = study_omega()
    delta_d: float = 0.0
    tau0: float = 0.0
    pi2_offset: float = math.pi / 2

    def __post_init__(self) -> None:
        values = {f.name: _check_real(f.name, getattr(self, f.name)) for f in fields(self)}
        _require("zeta", values["zeta"], 0.0 < values["zeta"] < 1.0, "0 < zeta < 1")
        _require("r", values["r"], 0.0 < values["r"] < 1.0, "0 < r < 1")
        _require("omega", values["omega"], values["omega"] > 0.0, "finite omega > 0")
        _require(
            "pi2_offset",
            values["pi2_offset"],
            0.0 < values["pi2_offset"] < TWO_PI,
            "0 < pi2_offset < 2*pi",
        )
        tau0 = math.fmod(values["tau0"], TWO_PI) % TWO_PI
        values["tau0"] = 0.0 if tau0 >= TWO_PI else tau0  # % may round 2 pi - tiny up to 2 pi
        for name, value in values.items():
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ derived
    @cached_property
    def omega_d(self) -> float:
        """Damped natural frequency omega_d = sqrt(1 - zeta^2)."""
        return math.sqrt(1.0 - self.zeta * self.zeta)

    @cached_property
    def period(self) -> float:
        """Forcing period T = 2 pi / omega."""
        return TWO_PI / self.omega

    @cached_property
    def amplitude(self) -> float:
        """a(omega) = 1 / sqrt((1 - omega^2)^2 + (2 zeta omega)^2) (spec section 1)."""
        w = self.omega
        return 1.0 / math.hypot(1.0 - w * w, 2.0 * self.zeta * w)

    @cached_property
    def lag(self) -> float:
        """Phase lag phi = atan2(2 zeta omega, 1 - omega^2) of x_p (spec section 1)."""
        w = self.omega
        return math.atan2(2.0 * self.zeta * w, 1.0 - w * w)

    @cached_property
    def d_star(self) -> float:
        """Critical clearance of grazing d* = a(omega) (Eq. 2)."""
        return self.amplitude

    @cached_property
    def d(self) -> float:
        """Wall position d = d* + Delta d."""
        return self.d_star + self.delta_d

    @cached_property
    def tau_star(self) -> float:
        """Grazing phase tau* = phi mod 2 pi (Eq. 2): the phase of section Pi1."""
        return self.lag % TWO_PI

    @cached_property
    def tau2(self) -> float:
        """Phase of section Pi2, tau* + pi2_offset mod 2 pi (Eq. 27)."""
        return (self.tau_star + self.pi2_offset) % TWO_PI

    @cached_property
    def a_star(self) -> float:
        """Acceleration at the grazing point, a* = cos tau* - d* (Eq. 3)."""
        return math.cos(self.tau_star) - self.d_star

    @cached_property
    def non_sticking(self) -> bool:
        """Regular grazing condition a* < 0 (Eq. 3)."""
        return self.a_star < 0.0

    @cached_property
    def x_ref(self) -> float:
        """x** = d* cos(tau2 - phi), the grazing orbit's position on Pi2 (spec section 3)."""
        return self.d_star * math.cos(self.pi2_offset)

    @cached_property
    def v_ref(self) -> float:
        """v** = -d* omega sin(tau2 - phi), the grazing orbit's velocity on Pi2."""
        return -self.d_star * self.omega * math.sin(self.pi2_offset)

    def with_(self, **changes) -> "OscillatorParams":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    @classmethod
    def from_d(cls, d: float, **kwargs) -> "OscillatorParams":
        """Build from the absolute wall position d instead of Delta d."""
        d = _check_real("d", d)
        base = cls(**kwargs)
        return base.with_(delta_d=d - base.d_star)

"""The compliant stop's laws and the forces on the mass: what :mod:`.contact`'s flow integrates.

* :class:`KelvinVoigt`, the linear spring-dashpot stop (stiffness ratio k_c, damping c_c),
  with its free-mass restitution (:func:`kelvin_voigt_restitution`, docs/theory_contact.md
  Eq. C3) and the inverse (:func:`kelvin_voigt_damping`);
* :class:`Coulomb`, dry friction on the mass (kinetic and static levels);
* :class:`LagForce`, an external force F_inf + C e^{-rate t} (the first-order actuator's);
* the valid ranges of the stop's stiffness and the friction (:data:`MAX_STIFFNESS`,
  :data:`MAX_FRICTION`), as sim_node's parameters and the commands' options check them.

Split from :mod:`grazing_control.oscillator.contact` (876 lines; the rule: no module over
800), which re-exports every public name here, so callers import them from either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from .params import ParameterError, _check_real

__all__ = [
    "KelvinVoigt",
    "Coulomb",
    "LagForce",
    "MAX_STIFFNESS",
    "MAX_FRICTION",
    "kelvin_voigt_restitution",
    "kelvin_voigt_damping",
]


def kelvin_voigt_restitution(contact_zeta: float) -> float:
    """Restitution of a free mass on a Kelvin-Voigt stop with damping ratio zeta_c < 1.

    delta'' + c delta' + k delta = 0, delta(0) = 0, delta'(0) = v > 0; the contact ends
    when k delta + c delta' = 0, at omega_c t_c = theta = atan2(2 zeta_c sqrt(1 - zeta_c^2),
    2 zeta_c^2 - 1), with delta'(t_c) = -v exp(-beta t_c) exactly, so (docs/theory_contact.md,
    Eq. C3; Schwager and Poeschel, Phys. Rev. E 75 (2007))

        r = exp(-zeta_c theta / sqrt(1 - zeta_c^2)),   zeta_c = c / (2 sqrt(k)).

    r decreases from 1 (zeta_c = 0) to exp(-2) (zeta_c -> 1) and depends on zeta_c only.
    """
    z = float(contact_zeta)
    if not 0.0 <= z < 1.0:
        raise ParameterError(f"contact_zeta={z!r} is invalid: valid range is 0 <= zeta_c < 1")
    s = math.sqrt(1.0 - z * z)
    theta = math.atan2(2.0 * z * s, 2.0 * z * z - 1.0)
    return math.exp(-z * theta / s)


def kelvin_voigt_damping(r: float) -> float:
    """The contact damping ratio zeta_c whose restitution is r (inverse of Eq. C3).

    Bisection to the last ulp on the monotone r(zeta_c); valid for exp(-2) < r <= 1.
    """
    r = float(r)
    if not math.exp(-2.0) < r <= 1.0:
        raise ParameterError(f"r={r!r} is invalid: a Kelvin-Voigt stop reaches exp(-2) < r <= 1")
    lo, hi = 0.0, 1.0
    while True:
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            return lo
        if kelvin_voigt_restitution(mid) > r:
            lo = mid
        else:
            hi = mid


#: The largest stiffness ratio k_c of a compliant stop: the contact lasts about pi /
#: sqrt(k_c), 3e-9 of a time unit here, far below any tolerance the rigid map misses by;
#: beyond it the closed form's arithmetic overflows (1e308 gave an OverflowError).
MAX_STIFFNESS = 1e18
#: The largest friction level F_f, F_s (over k l): a thousand times beyond any that lets
#: the forced mass slip; 1e308 poisoned the certified search with non-finite values and
#: it never returned (grazing simulate ... --friction 1e308, found by hand).
MAX_FRICTION = 1e6


@dataclass(frozen=True)
class KelvinVoigt:
    """A linear spring-dashpot stop: stiffness ratio k_c = K_c / k and damping c_c.

    Parameters
    ----------
    stiffness : float
        k_c > 0, the stop's stiffness over the oscillator's (finite).
    damping : float
        c_c >= 0, the stop's damping over m omega_n (finite), with the contact
        underdamped: (2 zeta + c_c)^2 < 4 (1 + k_c) (checked with the oscillator).
    """

    stiffness: float
    damping: float = 0.0

    def __post_init__(self) -> None:
        k = _check_real("stiffness", self.stiffness)
        c = _check_real("damping", self.damping)
        if not 0.0 < k <= MAX_STIFFNESS:
            raise ParameterError(f"stiffness={k!r} is invalid: valid range is "
                                 f"0 < k_c <= {MAX_STIFFNESS:g}")
        if not c >= 0.0:
            raise ParameterError(f"damping={c!r} is invalid: valid range is c_c >= 0")
        if not c < 2.0 * math.sqrt(k):
            raise ParameterError(f"damping={c!r} is invalid: valid range is "
                                 f"0 <= c_c < 2 sqrt(k_c) = {2.0 * math.sqrt(k)!r} (underdamped)")
        object.__setattr__(self, "stiffness", k)
        object.__setattr__(self, "damping", c)

    @classmethod
    def from_restitution(cls, stiffness: float, r: float) -> "KelvinVoigt":
        """The stop of stiffness k_c whose free-mass restitution (Eq. C3) is r."""
        k = _check_real("stiffness", stiffness)
        if not 0.0 < k <= MAX_STIFFNESS:
            raise ParameterError(f"stiffness={k!r} is invalid: valid range is "
                                 f"0 < k_c <= {MAX_STIFFNESS:g}")
        return cls(k, 2.0 * kelvin_voigt_damping(r) * math.sqrt(k))

    @property
    def contact_zeta(self) -> float:
        """zeta_c = c_c / (2 sqrt(k_c))."""
        return self.damping / (2.0 * math.sqrt(self.stiffness))

    @property
    def restitution(self) -> float:
        """r(k_c, c_c) of Eq. C3: the rigid law this stop tends to as k_c -> inf."""
        return kelvin_voigt_restitution(self.contact_zeta)

    def force(self, delta: float, velocity: float) -> float:
        """k_c delta + c_c delta' (the stop pushes where this and delta are > 0)."""
        return self.stiffness * delta + self.damping * velocity



@dataclass(frozen=True)
class Coulomb:
    """Coulomb dry friction on the mass: -F_f sign(x') in slip, a stick at x' = 0 while
    the force without friction |G| <= F_s (F_s >= F_f; default F_s = F_f)."""

    kinetic: float
    static: float | None = None

    def __post_init__(self) -> None:
        # named as sim_node's parameters and the commands' options name them
        f = _check_real("friction", self.kinetic)
        if not 0.0 <= f <= MAX_FRICTION:
            raise ParameterError(f"friction={f!r} is invalid: valid range is "
                                 f"0 <= F_f <= {MAX_FRICTION:g}")
        s = f if self.static is None else _check_real("friction_static", self.static)
        if not f <= s <= MAX_FRICTION:
            raise ParameterError(f"friction_static={s!r} is invalid: valid range is "
                                 f"F_f = {f!r} <= F_s <= {MAX_FRICTION:g}")
        object.__setattr__(self, "kinetic", f)
        object.__setattr__(self, "static", s)


class LagForce(NamedTuple):
    """An external force on the mass, F(t) = F_inf + C e^{-rate t} (t from the segment's
    start): the first-order actuator's force on a piece where its command is constant
    (grazing_control.dynamics.simulation.actuator, docs/theory_pulse.md section 5;
    rate = 1 / tau_a, C = 0 for a constant force)."""

    f_inf: float
    c: float = 0.0
    rate: float = 0.0

    def at(self, t: float) -> float:
        """F(t)."""
        return self.f_inf + (self.c * math.exp(-self.rate * t) if self.c else 0.0)

    def transient(self, t: float) -> float:
        """C e^{-rate t}: the decaying part at time t."""
        return self.c * math.exp(-self.rate * t) if self.c else 0.0


def _force_at(force: "LagForce | None", t: float) -> float:
    return 0.0 if force is None else force.at(t)

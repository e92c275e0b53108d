"""The 1-DOF oscillator with a compliant stop on Pi2: a :class:`~.model.PeriodMap`.

The period map of :func:`grazing_control.oscillator.contact.compliant_period_step`
(Kelvin-Voigt, with or without Coulomb friction) or
:func:`grazing_control.oscillator.hertz.hertz_period_step` (Hertz / Hunt-Crossley) with
the controller of Eq. 28 on Pi2 (no actuation delay), and the contacts as the period's
events. The Jacobian: exact for the frictionless Kelvin-Voigt stop (the regions'
transition matrices, the entry's saltation, docs/theory_contact.md Eq. C8, times the
gain matrix G); by central differences of the map otherwise (step 1e-6: the Hertz map is
accurate to about 1e-11, so the Jacobian to about 1e-5; the friction's sticks make the
map only piecewise smooth, docs/theory_contact.md section 15). Shooting, Floquet
multipliers and continuation (:mod:`.shooting`, :func:`.continuation.continue_orbit`)
run over it unchanged. Parameters: those of :class:`OscillatorParams`, ``c1`` and ``c2``
with gains, and the stop's ``stiffness`` (k_c; for Kelvin-Voigt changed at fixed contact
damping ratio zeta_c, so at fixed restitution r(zeta_c) of Eq. C3; for Hertz at fixed
alpha), ``log10_stiffness`` (the same, in decades: the chart's axis), ``contact_zeta``
(Kelvin-Voigt), ``hunt_crossley`` (Hertz's alpha) and ``friction`` (the kinetic level
F_f, the static one kept in the same ratio; 0 removes the friction).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, compliant_period_step
from grazing_control.oscillator.hertz import HuntCrossley, hertz_period_step
from grazing_control.oscillator.control import gain_matrix
from grazing_control.oscillator.flow import matmul2
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.model import OneDOF, Step

__all__ = ["CompliantOneDOF"]

_PARAM_NAMES = tuple(f.name for f in dataclasses.fields(OscillatorParams))
_LAW_NAMES = ("stiffness", "log10_stiffness", "contact_zeta", "hunt_crossley", "friction")
#: central-difference step of the Jacobian where it is not exact (module docstring)
FD_STEP = 1e-6


@dataclass(frozen=True)
class CompliantOneDOF(OneDOF):
    """The study's oscillator with a compliant stop, on Pi2 before the correction.

    :class:`~.model.OneDOF`'s section, coordinates and grazing point, with the stop
    ``law`` (keyword, required: :class:`KelvinVoigt` or :class:`HuntCrossley`) in place of
    the rigid wall, and Coulomb ``friction`` on the mass (with either stop).
    """

    law: KelvinVoigt | HuntCrossley | None = None
    friction: Coulomb | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.law, (KelvinVoigt, HuntCrossley)):
            raise ValueError(f"law={self.law!r} is invalid: a KelvinVoigt or HuntCrossley "
                             f"stop is required")
        if self.gains is not None and self.gains.delay != 0.0:
            raise ValueError(f"delay={self.gains.delay!r} is invalid: the compliant map takes "
                             f"the correction on Pi2 only (delay 0)")

    @property
    def exact_jacobian(self) -> bool:
        """True for the frictionless Kelvin-Voigt stop (Eq. C8), else central differences."""
        return isinstance(self.law, KelvinVoigt) and self.friction is None

    def _segment(self, dx: float, dv: float, monodromy: bool = False):
        dvc = self.gains.c1 * dx + self.gains.c2 * dv if self.gains is not None else 0.0
        if isinstance(self.law, HuntCrossley):
            return hertz_period_step(self.params, self.law, dx, dv, dvc,
                                     friction=self.friction)
        return compliant_period_step(self.params, self.law, dx, dv, dvc,
                                     friction=self.friction, monodromy=monodromy)

    def step(self, state, jacobian: bool = False) -> Step:
        dx, dv = float(state[0]), float(state[1])
        seg = self._segment(dx, dv, monodromy=jacobian and self.exact_jacobian)
        jac = None
        if jacobian and self.exact_jacobian:
            jac = np.array(matmul2(seg.monodromy, gain_matrix(self.gains))).reshape(2, 2)
        elif jacobian:
            cols = []
            for e in ((FD_STEP, 0.0), (0.0, FD_STEP)):
                hi = self._segment(dx + e[0], dv + e[1])
                lo = self._segment(dx - e[0], dv - e[1])
                cols.append(((hi.x - lo.x) / (2 * FD_STEP), (hi.v - lo.v) / (2 * FD_STEP)))
            jac = np.array(cols).T
        return Step(np.array([seg.x, seg.v]), jac, tuple(seg.contacts))

    def parameter(self, name: str) -> float:
        if name == "stiffness":
            return self.law.stiffness
        if name == "log10_stiffness":
            return math.log10(self.law.stiffness)
        if name == "contact_zeta" and isinstance(self.law, KelvinVoigt):
            return self.law.contact_zeta
        if name == "hunt_crossley" and isinstance(self.law, HuntCrossley):
            return self.law.alpha
        if name == "friction":
            return 0.0 if self.friction is None else self.friction.kinetic
        if name == "delay":
            raise ValueError("parameter 'delay' is invalid: the compliant map has no delay")
        try:
            return super().parameter(name)
        except ValueError:
            law = (("contact_zeta",) if isinstance(self.law, KelvinVoigt)
                   else ("hunt_crossley",))
            raise ValueError(f"parameter {name!r} is invalid: valid names are "
                             f"{', '.join(_PARAM_NAMES + ('c1', 'c2', 'stiffness'))}, "
                             f"log10_stiffness, {law[0]}, friction") from None

    def with_parameter(self, name: str, value: float) -> "CompliantOneDOF":
        self.parameter(name)
        if name == "friction":
            if value == 0.0:
                return dataclasses.replace(self, friction=None)
            ratio = 1.0 if self.friction is None or self.friction.kinetic == 0.0 else (
                self.friction.static / self.friction.kinetic)
            return dataclasses.replace(self, friction=Coulomb(value, ratio * value))
        if name in _LAW_NAMES:
            k = self.law.stiffness
            if name == "stiffness":
                k = value
            elif name == "log10_stiffness":
                k = 10.0 ** value
            if isinstance(self.law, HuntCrossley):
                alpha = value if name == "hunt_crossley" else self.law.alpha
                return dataclasses.replace(self, law=HuntCrossley(k, alpha))
            z = value if name == "contact_zeta" else self.law.contact_zeta
            return dataclasses.replace(self, law=KelvinVoigt(k, 2.0 * z * math.sqrt(k)))
        return super().with_parameter(name, value)

    def jacobian_det(self, periods: int, impacts: int) -> float | None:
        """None: the contact's time in the stop's damping makes no product formula."""
        return None

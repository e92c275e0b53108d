"""The 1-DOF oscillator with a Kelvin-Voigt stop on Pi2: a :class:`~.model.PeriodMap`.

The period map of :func:`grazing_control.oscillator.contact.compliant_period_step` with
the controller of Eq. 28 on Pi2 (no actuation delay), its exact Jacobian (the regions'
transition matrices, the entry's saltation, docs/theory_contact.md Eq. C8) times the
gain matrix G, and the contacts as the period's events. Shooting, Floquet multipliers and
continuation (:mod:`.shooting`, :func:`.continuation.continue_orbit`) run over it
unchanged. Parameters: those of :class:`OscillatorParams`, ``c1`` and ``c2`` with gains,
and the stop's ``stiffness`` (k_c, changed at fixed contact damping ratio zeta_c, so at
fixed restitution r(zeta_c) of Eq. C3), ``log10_stiffness`` (the same, in decades: the
chart's axis) and ``contact_zeta``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.contact import KelvinVoigt, compliant_period_step
from grazing_control.oscillator.control import gain_matrix
from grazing_control.oscillator.flow import matmul2
from grazing_control.oscillator.params import OscillatorParams
from .model import OneDOF, Step

__all__ = ["CompliantOneDOF"]

_PARAM_NAMES = tuple(f.name for f in dataclasses.fields(OscillatorParams))
_LAW_NAMES = ("stiffness", "log10_stiffness", "contact_zeta")


@dataclass(frozen=True)
class CompliantOneDOF(OneDOF):
    """The study's oscillator with a Kelvin-Voigt stop, on Pi2 before the correction.

    :class:`~.model.OneDOF`'s section, coordinates and grazing point, with the stop
    ``law`` (keyword, required) in place of the rigid wall.
    """

    law: KelvinVoigt | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.law, KelvinVoigt):
            raise ValueError(f"law={self.law!r} is invalid: a KelvinVoigt stop is required")
        if self.gains is not None and self.gains.delay != 0.0:
            raise ValueError(f"delay={self.gains.delay!r} is invalid: the compliant map takes "
                             f"the correction on Pi2 only (delay 0)")

    def step(self, state, jacobian: bool = False) -> Step:
        dx, dv = float(state[0]), float(state[1])
        dvc = self.gains.c1 * dx + self.gains.c2 * dv if self.gains is not None else 0.0
        seg = compliant_period_step(self.params, self.law, dx, dv, dvc, monodromy=jacobian)
        jac = None
        if jacobian:
            jac = np.array(matmul2(seg.monodromy, gain_matrix(self.gains))).reshape(2, 2)
        return Step(np.array([seg.x, seg.v]), jac, tuple(seg.contacts))

    def parameter(self, name: str) -> float:
        if name == "stiffness":
            return self.law.stiffness
        if name == "log10_stiffness":
            return math.log10(self.law.stiffness)
        if name == "contact_zeta":
            return self.law.contact_zeta
        if name == "delay":
            raise ValueError("parameter 'delay' is invalid: the compliant map has no delay")
        try:
            return super().parameter(name)
        except ValueError:
            raise ValueError(f"parameter {name!r} is invalid: valid names are "
                             f"{', '.join(_PARAM_NAMES + ('c1', 'c2') + _LAW_NAMES)}") from None

    def with_parameter(self, name: str, value: float) -> "CompliantOneDOF":
        self.parameter(name)
        if name in _LAW_NAMES:
            k, z = self.law.stiffness, self.law.contact_zeta
            if name == "stiffness":
                k = value
            elif name == "log10_stiffness":
                k = 10.0 ** value
            else:
                z = value
            return dataclasses.replace(self, law=KelvinVoigt(k, 2.0 * z * math.sqrt(k)))
        return super().with_parameter(name, value)

    def jacobian_det(self, periods: int, impacts: int) -> float | None:
        """None: the contact's time in the stop's damping makes no product formula."""
        return None

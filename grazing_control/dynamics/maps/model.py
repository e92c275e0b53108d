"""The model protocol: a periodically forced impact system seen on its Poincare section.

Shooting, Floquet multipliers and continuation with bifurcation detection
(:mod:`.shooting`, :func:`.continuation.continue_orbit`) need only this of a model
(docs/architecture.md, "The model protocol"):

* the **period map** P from a section state z (a vector of ``dimension`` deviations
  from the grazing point) to the next sample one forcing period later, with its
  Jacobian DP(z) when asked (the product of the flow's transition matrices, the
  saltation matrices of the impacts and the controller's gain matrix in time order,
  spec section 5) and the **impact events** on the way (time, phase, v-, v+);
* the **section geometry**: the forcing phase of the section and the names of the
  state's coordinates;
* the **grazing point**: the section state of the orbit that touches the wall with
  zero velocity (z = 0 in the deviation coordinates used here);
* a **parameter family**: the same model with one named parameter changed.

:class:`OneDOF` is the first implementation: the study's oscillator with its exact
closed-form flow (:func:`grazing_control.dynamics.maps.maps.pi2_map`, Pi2 sampled before
the correction of Eq. 28). The 1/1 branch of the 1-DOF model also has an explicit
route (impact-phase shooting, :mod:`.orbits`, :func:`.continuation.continue_11`),
which the generic algorithms are checked against; the compiled kernel still drives
the hot paths (sweeps, long simulations).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from grazing_control.oscillator.control import Gains, gain_determinant
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams

from grazing_control.dynamics.maps.maps import pi2_map

__all__ = ["Step", "PeriodMap", "SectionMap", "OneDOF", "is_model_file"]


def is_model_file(model) -> bool:
    """Which implementation an entry of one concept for every model runs (issue 32): True
    for a model file of any n (:class:`NdofModel`, n = 1 included: its modal flow), False
    for the 1-DOF oscillator's parameters (:class:`OscillatorParams`: the closed form, the
    certified fast path); anything else is refused with a TypeError naming it."""
    if isinstance(model, NdofModel):
        return True
    if isinstance(model, OscillatorParams):
        return False
    raise TypeError(f"model={model!r} is invalid: expected OscillatorParams (the 1-DOF "
                    "oscillator) or NdofModel (a model file)")


class Step(NamedTuple):
    """One application of a period map.

    ``state``: the next section state (1-d array); ``jacobian``: DP at the start
    (``dimension`` x ``dimension`` array) or None when not asked; ``impacts``: the
    impact events of the period in time order, each with ``dt`` (time since the
    sample), ``phase``, ``v_minus``, ``v_plus`` and ``sticking``
    (:class:`grazing_control.oscillator.impact.Impact`).
    """

    state: np.ndarray
    jacobian: np.ndarray | None
    impacts: tuple


@runtime_checkable
class PeriodMap(Protocol):
    """What the generic algorithms need of a model (module docstring)."""

    #: Dimension of the section state.
    dimension: int

    @property
    def period(self) -> float:
        """Forcing period T: the time one application of the map covers."""

    @property
    def section_phase(self) -> float:
        """Forcing phase of the section."""

    @property
    def coordinates(self) -> tuple:
        """Names of the state's coordinates (deviations from the grazing point)."""

    def step(self, state, jacobian: bool = False) -> Step:
        """P(state), with DP(state) if ``jacobian``, and the period's impacts."""

    def grazing_state(self) -> np.ndarray:
        """Section state of the grazing orbit."""

    def parameter(self, name: str) -> float:
        """Value of a named parameter."""

    def with_parameter(self, name: str, value: float) -> "PeriodMap":
        """The same model with one parameter changed (validated: a bad value raises)."""

    def jacobian_det(self, periods: int, impacts: int) -> float | None:
        """det of the Jacobian of P^periods with ``impacts`` impacts on the way, when the
        model knows it exactly (else None: computed from the matrix)."""


class SectionMap:
    """The members of :class:`PeriodMap` that follow from the model alone, written once for
    every implementation: the period T and the section's phase come from its ``section``
    (an object with ``period`` and ``tau2``: the 1-DOF parameters, the n-DOF flow), and the
    grazing orbit is the origin z = 0 of the deviation coordinates."""

    @property
    def period(self) -> float:
        return self.section.period

    @property
    def section_phase(self) -> float:
        return self.section.tau2

    def grazing_state(self) -> np.ndarray:
        return np.zeros(self.dimension)


_GAIN_NAMES = ("c1", "c2", "delay")
_PARAM_NAMES = tuple(f.name for f in dataclasses.fields(OscillatorParams))


@dataclass(frozen=True)
class OneDOF(SectionMap):
    """The study's 1-DOF impact oscillator on Pi2, optionally with the controller.

    State: (x - x**, v - v**) sampled on Pi2 before the correction; the grazing point
    X** is the origin. Parameters: those of :class:`OscillatorParams` (``delta_d``,
    ``zeta``, ``r``, ``omega``, ...) and, with gains, ``c1``, ``c2``, ``delay``.
    """

    params: OscillatorParams
    gains: Gains | None = None
    dimension: int = 2

    @property
    def section(self) -> OscillatorParams:
        """The parameters: T and tau2 (:class:`SectionMap`)."""
        return self.params

    @property
    def coordinates(self) -> tuple:
        return ("x - x**", "v - v**")

    def step(self, state, jacobian: bool = False) -> Step:
        """The Pi2 map (:func:`grazing_control.dynamics.maps.maps.pi2_map`, spec section 5)."""
        seg = pi2_map(self.params, float(state[0]), float(state[1]), self.gains,
                      monodromy=jacobian)
        jac = np.array(seg.monodromy).reshape(2, 2) if jacobian else None
        return Step(np.array([seg.dx, seg.dv]), jac, tuple(seg.impacts))

    def parameter(self, name: str) -> float:
        if name in _GAIN_NAMES:
            if self.gains is None:
                raise ValueError(f"parameter {name!r} is invalid without gains: valid names "
                                 f"are {', '.join(_PARAM_NAMES)}")
            return float(getattr(self.gains, name))
        if name in _PARAM_NAMES:
            return float(getattr(self.params, name))
        raise ValueError(f"parameter {name!r} is invalid: valid names are "
                         f"{', '.join(_PARAM_NAMES + _GAIN_NAMES)}")

    def with_parameter(self, name: str, value: float) -> "OneDOF":
        self.parameter(name)   # the name is valid
        if name in _GAIN_NAMES:
            return dataclasses.replace(self, gains=dataclasses.replace(self.gains,
                                                                       **{name: value}))
        return dataclasses.replace(self, params=self.params.with_(**{name: value}))

    def jacobian_det(self, periods: int, impacts: int) -> float | None:
        """e^{-2 zeta n T} r^(2 m) (det G)^n: products of det Phi, det S and det G (spec
        section 5); None with an actuation delay, where an impact inside the delay makes
        the product formula wrong (docs/theory_delay.md, (D3))."""
        if self.gains is not None and self.gains.delay != 0.0:
            return None
        p = self.params
        g = gain_determinant(self.gains, p.zeta)
        return math.exp(-2.0 * p.zeta * periods * p.period) * p.r ** (2 * impacts) * g ** periods

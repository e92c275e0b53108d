"""The design of grazing control, one entry for every model (issue 32).

A degenerate grazing design is one member of a one-parameter gain family, and what a
caller asks of it is the same for every model: the multipliers of the controlled 1/1
orbit as Delta d -> 0- (the limit spectrum, study Eq. 23), the existence coefficient
gamma1 (Eq. 36), the multipliers of the non-impacting motion, and the admissible set of
the family's parameter. The model supplies the rest:

* the 1-DOF oscillator (:class:`OscillatorParams`): the closed form of :mod:`.gains`,
  parametrised by c2 (c1 from the degenerate condition, docs/theory_delay.md (D4)),
  unchanged bit for bit (tests/test_model_design.py);
* a model file of any n (:class:`NdofModel`): the family w^T N(k) = mu w^T of
  :mod:`.family`, parametrised by mu (docs/theory_ndof.md §3-§8, §14, §15).

For n = 1 the two are one family: mu = 0 is c2 = -1, and the file's limit multipliers
at the mu of a c2 are the closed form's to 1e-12 (tests/test_n1_model_file.py,
tests/test_model_design.py). ``delay`` is the actuation delay (both models) or, for a
model file, an :class:`~grazing_control.dynamics.design.family.Actuation` (pulse, lag).
"""

from __future__ import annotations

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

from grazing_control.dynamics.design import family, gains
from grazing_control.dynamics.maps.model import is_model_file

__all__ = ["PARAMETERS", "parameter_name", "evaluate_design", "limit_multipliers",
           "existence_coefficient", "free_multipliers", "admissible_set"]

#: The family's parameter by model: c2 for the 1-DOF closed form, mu for a model file.
PARAMETERS = {"1-DOF": "c2", "model file": "mu"}


def parameter_name(model) -> str:
    """'c2' (the 1-DOF closed form) or 'mu' (a model file's family)."""
    return PARAMETERS["model file" if is_model_file(model) else "1-DOF"]


def _closed_form_gains(p: OscillatorParams, c2: float, delay) -> Gains:
    """The 1-DOF member at c2: c1 from the degenerate condition (:func:`.gains.degenerate_c1`)."""
    return Gains(gains.degenerate_c1(p, c2, delay), c2, delay)


def evaluate_design(model, value: float, delay=0.0):
    """The design quantities at the family's parameter ``value`` (c2 or mu): a
    :class:`.gains.DesignPoint` for the 1-DOF oscillator, a :class:`.family.FamilyDesign`
    for a model file; both say ``stable``, ``free_stable``, ``admissible_impacting`` and
    ``admissible`` and carry ``gamma1``."""
    if is_model_file(model):
        return family.evaluate_design(model, value, delay)
    return gains.evaluate_design(model, value, delay)


def limit_multipliers(model, value: float, delay=0.0) -> np.ndarray:
    """The multipliers of the controlled 1/1 orbit as Delta d -> 0- (Eq. 23; §6)."""
    if is_model_file(model):
        return family.limit_multipliers(model, value, delay)
    return gains.limit_multipliers(model, _closed_form_gains(model, value, delay))


def existence_coefficient(model, value: float, delay=0.0) -> float:
    """gamma1 of Delta d = -gamma1 psi^2 + O(psi^3) on the 1/1 branch (Eq. 36; §7)."""
    if is_model_file(model):
        return family.existence_coefficient(model, value, delay)
    return gains.existence_coefficient(model, _closed_form_gains(model, value, delay))


def free_multipliers(model, value: float, delay=0.0) -> np.ndarray:
    """The eigenvalues of the smooth map N through grazing: the non-impacting motion's
    multipliers (d > d*; for a model file mu and the transmission zeros, §4)."""
    if is_model_file(model):
        return family.free_multipliers(model, value, delay)
    return gains.free_multipliers(model, _closed_form_gains(model, value, delay))


def admissible_set(model, conditions: str = "combined", delay=0.0) -> list:
    """The intervals of the family's parameter where the design's ``conditions`` hold
    ('combined', 'impacting', 'non-impacting'): :func:`.gains.admissible_c2` (c2) or
    :func:`.family.admissible_mu` (mu), an unbounded end reported as infinite."""
    if is_model_file(model):
        return family.admissible_mu(model, conditions, delay)
    return gains.admissible_c2(model, delay=delay, conditions=conditions)

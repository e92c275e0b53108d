"""Identification of the oscillator's parameters from a recorded motion (issue 16 §1).

Pure numerics (docs/theory_identification.md): :mod:`.model` (the rig's model in its own
units: free flight in closed form, the impact law, the map to the study's nondimensional
parameters), :mod:`.phase` (the forcing's phase reference), :mod:`.data` (a recording as
arrays, cut into free-flight arcs), :mod:`.initial` (the robust initial guess: the exact
ARX(2) recursion of the sampled flow, per-arc linear fits, impacts found from the
motion), :mod:`.fit` (multiple-shooting nonlinear least squares with complex-step
Jacobians, standard errors) and :mod:`.checks` (residual whiteness, re-simulation, the
verdict); :mod:`.stop` (which stop the Pi2 data support: rigid, Kelvin-Voigt, with
friction, by BIC; docs/theory_contact.md section 17); :mod:`.modal` and :mod:`.modal_fit`
(n > 1: the modal parameters the wall coordinate shows, their multiple-shooting fit and
a model file's realisation; docs/theory_identification.md section 11).

May import: :mod:`grazing_control.dynamics` and below. Never rclpy.
"""

from grazing_control.dynamics.identification.data import Recording
from grazing_control.dynamics.identification.fit import IdentificationError, Identification, identify
from grazing_control.dynamics.identification.model import RigModel

__all__ = ["Recording", "RigModel", "Identification", "IdentificationError", "identify"]

"""The linear n-DOF impact oscillator (issue 17): the model file and its loader
(``model``, docs/ndof_model.md), the exact flow and periodic response (``flow``), and
certified impacts, saltation, chattering (``impact``) and sticking (``sticking``)
(docs/theory_ndof_flow.md; sticking: docs/theory_ndof.md section 16), and the flow under
a force pulse or a first-order actuator on the actuated coordinate (``forced``,
docs/theory_ndof.md section 15). Imports only ``oscillator.params``,
``oscillator.impact`` and ``support``."""

from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import ChatteringError, NdofImpact, NdofSegment
from grazing_control.oscillator.ndof.model import NdofModel, load_model, model_from_mapping

__all__ = ["NdofModel", "load_model", "model_from_mapping", "NdofFlow", "NdofImpact",
           "NdofSegment", "ChatteringError"]

"""The linear n-DOF impact oscillator (issue 17): model and loader (docs/ndof_model.md)."""

from grazing_control.oscillator.ndof.model import NdofModel, load_model, model_from_mapping

__all__ = ["NdofModel", "load_model", "model_from_mapping"]

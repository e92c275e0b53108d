"""The controller's law for an n-DOF scene: a gain vector on the whole Pi2 state (issue 17).

controller_node with ``model_file`` set answers each Pi2 sample X = (x_0 .. x_{n-1},
v_0 .. v_{n-1}) of the n-DOF oscillator (docs/ndof_model.md) with the kick on the
actuated coordinate's velocity

    Delta v = k^T (X - X**),      k = ``gains`` (2n values),

X** the grazing orbit's state on Pi2: the periodic response at the section phase,
``NdofFlow.particular(tau2)`` (docs/theory_ndof.md, "Kick design"; the kick of
:class:`grazing_control.dynamics.maps.ndof_map.NdofMap`). The switch-on (``enable_after``,
``~/enable``), the saturation and the stale-sample rules are the 1-DOF controller's
(:class:`grazing_control.ros.controller_values.ControlLaw`); the 1-DOF law's parameters
(c1, c2, x_ref, v_ref, zeta, r) must be left at their defaults (else refused with the
reason). With ``pi2_source`` stream the Pi2 state is estimated from the sensor stream by
the model filter over the exact n-DOF map (:func:`ndof_stream_from_values`; issue 32:
the position, and velocity where carried, of coordinate ``sensor_coordinate``). The section data the design's
parameter file carries with the gains (``n``, ``i_a``, ``omega``, ``pi2_offset``:
:func:`grazing_control.dynamics.design.ndof_design.write_gain_yaml`) must be the model file's:
gains designed for another model are refused, naming both values. No rclpy.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.oscillator.params import OscillatorParams, ParameterError, study_omega
from grazing_control.plant.settings import load_model_file

__all__ = ["NdofLaw", "NdofController", "ndof_controller_from_values",
           "ndof_stream_from_values", "GAIN_LIMIT", "ONE_DOF_DEFAULTS"]

#: Largest |k_i| accepted (as the 1-DOF controller's |c1|, |c2|).
GAIN_LIMIT = 1e6

#: The 1-DOF law's parameters and their defaults: an n-DOF controller refuses any other
#: value (the model file and ``gains`` give the n-DOF law). The 1-DOF model's defaults
#: are filled in by :func:`ndof_controller_from_values`.
ONE_DOF_DEFAULTS = {"c1": 0.0, "c2": 0.0, "x_ref": math.nan, "v_ref": math.nan,
                    "zeta": OscillatorParams().zeta, "r": OscillatorParams().r}
#: The section data of the design's parameter file and the value meaning "not given":
#: given, each must be the model's.
SECTION_DATA = {"n": -1, "i_a": -1, "omega": study_omega(),
                "pi2_offset": OscillatorParams().pi2_offset}


class NdofLaw:
    """Delta v = k^T (X - X**) for a sample (x, v) of n positions and n velocities.

    The mixin of :class:`grazing_control.ros.controller_values.ControlLaw`'s ``_law``:
    ``gains`` is k (2n,), ``x_ref``, ``v_ref`` are X**'s halves.
    """

    def _law(self, x, v) -> float:
        """k^T (X - X**) (docs/theory_ndof.md, "Kick design")."""
        n = self.x_ref.size
        k = self.gains
        return float(k[:n] @ (np.asarray(x, float) - self.x_ref)
                     + k[n:] @ (np.asarray(v, float) - self.v_ref))


@dataclasses.dataclass(frozen=True)
class NdofController:
    """What an n-DOF controller needs besides the law's switches: the model (with the
    plant's delta_d), its flow, X** on Pi2, the gains, and whether it predicts."""

    model: object
    flow: object
    gains: np.ndarray
    x_ref: np.ndarray
    v_ref: np.ndarray
    predicts: bool

    def predict(self, x, v, dv: float, delay: float):
        """The Pi2 sample after (x, v) with ``dv`` acting ``delay`` after it: one exact
        period of the model (the engine's calls, plant.ndof_engine). Returns (x', v')."""
        m, f = self.model, self.flow
        n = m.n
        z = f.to_deviation(f.tau2, np.concatenate([np.asarray(x, float), np.asarray(v, float)]))
        tau = f.tau2
        if delay > 0.0:
            z = advance(f, tau, z, delay).z
            tau = (tau + m.omega * delay) % (2.0 * math.pi)
        z = np.array(z, dtype=float)
        z[n + m.i_a] += dv
        z = advance(f, tau, z, m.period - delay).z
        X = f.to_physical(f.tau2, z)
        return X[:n], X[n:]


def ndof_controller_from_values(values: dict, model_file: str, gains) -> NdofController:
    """Validate an n-DOF controller's values (ParameterError naming the parameter).

    ``gains``: the ``gains`` parameter (None when not given); ``values``: the 1-DOF
    controller's parameters, of which c1, c2, x_ref, v_ref must stay at their defaults
    and ``pi2_source`` at ``sample``; ``delta_d`` (finite) replaces the file's Delta d and
    switches the prediction of the next correction on (NaN: the file's, no prediction).
    """
    model = load_model_file(model_file)
    for name, default in ONE_DOF_DEFAULTS.items():
        value = float(values.get(name, default))
        if not (value == default or (math.isnan(value) and math.isnan(default))):
            raise ParameterError(f"{name}={value!r} is invalid with model_file={model_file!r}:"
                                 f" valid is its default {default!r} (the n-DOF law is "
                                 "Delta v = k^T (X - X**) with k = gains and X** from the "
                                 "model)")
    for name, unset in SECTION_DATA.items():
        value = values.get(name, unset)
        want = getattr(model, name)
        if value != unset and value != want:
            raise ParameterError(f"{name}={value!r} is invalid with model_file={model_file!r}: "
                                 f"valid is the model's {want!r} (the gains were designed "
                                 "for another model)")
    want = 2 * model.n
    if gains is None:
        raise ParameterError(f"gains is not given: with model_file it is required, {want} "
                             f"values k (on x_0..x_{model.n - 1}, v_0..v_{model.n - 1})")
    k = np.array(gains, dtype=float).reshape(-1)
    if k.size != want:
        raise ParameterError(f"gains has {k.size} values: valid is 2n = {want} for the "
                             f"{model.n}-DOF model of {model_file!r} (k on x_0..x_"
                             f"{model.n - 1}, v_0..v_{model.n - 1})")
    if not np.all(np.abs(k) <= GAIN_LIMIT):
        raise ParameterError(f"gains={k.tolist()!r} is invalid: valid range is |k_i| <= "
                             f"{GAIN_LIMIT:g}, finite")
    delta_d = float(values.get("delta_d", math.nan))
    if math.isinf(delta_d):
        raise ParameterError(f"delta_d={delta_d!r} is invalid: valid range is a finite real "
                             "number (the plant's Delta d), or NaN for the file's")
    if not math.isnan(delta_d):
        model = dataclasses.replace(model, delta_d=delta_d)
    flow = NdofFlow.of(model)
    X = np.asarray(flow.particular(flow.tau2), dtype=float)
    n = model.n
    k.setflags(write=False)
    return NdofController(model, flow, k, X[:n].copy(), X[n:].copy(),
                          predicts=not math.isnan(delta_d))


def ndof_stream_from_values(values: dict, ndof: NdofController):
    """The n-DOF scene's stream estimator for ``pi2_source`` stream, None for ``sample``
    (ParameterError naming the parameter): the model filter over the exact n-DOF map
    (:class:`grazing_control.dynamics.estimation.stream.StreamEstimator` with the
    controller's model, docs/theory_estimation.md (E11)) reading coordinate
    ``sensor_coordinate``; it needs the plant's ``delta_d`` (``ndof.predicts``), the
    estimator ``model``, ``sensor_noise`` > 0 and impacts detected in the stream."""
    from grazing_control.dynamics.estimation.stream import StreamEstimator

    source = values.get("pi2_source", "sample")
    if source == "sample":
        return None
    if source != "stream":
        raise ParameterError(f"pi2_source={source!r} is invalid: valid values are sample, "
                             "stream")
    if not ndof.predicts:
        raise ParameterError("delta_d=nan is invalid with pi2_source=stream: valid range is "
                             "the plant's finite Delta d (the estimator's model needs the wall)")
    if values.get("impact_source", "stream") != "stream":
        raise ParameterError(f"impact_source={values['impact_source']!r} is invalid with "
                             "model_file: valid is stream (the n-DOF model filter finds the "
                             "impacts in its exact motion)")
    for name in ("estimate_bias", "track_delta_d", "capture", "reidentify"):
        if values.get(name):
            raise ParameterError(f"{name}=True is invalid with model_file: valid is false "
                                 "(not built for n-DOF)")
    if int(values.get("consistency_window", 0) or 0) > 0:
        raise ParameterError(f"consistency_window={values['consistency_window']!r} is invalid "
                             "with model_file: valid is 0 (not built for n-DOF)")
    floor = float(values.get("model_noise", 1e-2))
    if not (math.isfinite(floor) and floor >= 0.0):
        raise ParameterError(f"model_noise={floor!r} is invalid: valid range is a finite "
                             "model_noise >= 0 (process noise per period, in sensor_noise)")
    return StreamEstimator(ndof.model, values.get("estimator", "model"),
                           float(values.get("sensor_noise", 0.0)), "stream",
                           float(values.get("state_period", 0.0)), floor,
                           bool(values.get("answer_after_section", False)),
                           float(values.get("answer_lead", 0.0)),
                           kernel=False,     # the n-DOF motion is the core's (E11)
                           coordinate=int(values.get("sensor_coordinate", 0)))

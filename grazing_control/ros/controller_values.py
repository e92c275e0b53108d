"""The controller's law and its scene, read from the node's parameter values (no ROS): the
law Delta v = k^T (X - X**) on the Pi2 state with its switch, saturation and sample
bookkeeping (:class:`ControlLaw`: for the study's 1-DOF oscillator k = (c1, c2), Eq. 28;
for an n-DOF model file k = ``gains``, 2n values, :func:`model_controller_from_values`),
the model the controller predicts with, the stream estimator, the pulse the plant acts,
the capture rule and the actuation delay; each ``*_from_values`` validates its values with
one line naming the parameter (ParameterError).

An n-DOF scene (``model_file``, docs/ndof_model.md; issues 17, 32) answers each Pi2
sample X = (x_0 .. x_{n-1}, v_0 .. v_{n-1}) with the kick on the actuated coordinate's
velocity, X** the grazing orbit's state on Pi2, ``NdofFlow.particular(tau2)``
(docs/theory_ndof.md, "Kick design"; the kick of
:class:`grazing_control.dynamics.maps.modal_map.ModalMap`). The switch-on, the saturation
and the stale-sample rules are the same :class:`ControlLaw`'s; the 1-DOF law's
parameters (c1, c2, x_ref, v_ref, zeta, r) must be left at their defaults (else refused
with the reason). With ``pi2_source`` stream the Pi2 state is estimated from the sensor
stream by the model filter over the exact n-DOF map (:func:`model_stream_from_values`:
the position, and velocity where carried, of coordinate ``sensor_coordinate``). The
section data the design's parameter file carries with the gains (``n``, ``i_a``,
``omega``, ``pi2_offset``: :func:`grazing_control.dynamics.design.family.write_gain_yaml`)
must be the model file's: gains designed for another model are refused, naming both
values."""

from __future__ import annotations

import dataclasses
import math
import threading
from collections import deque

import numpy as np

from grazing_control.dynamics.design.capture import CAPTURE_RADIUS, CaptureRule
from grazing_control.dynamics.design.degenerate import degenerate_c1
from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.estimation.section_state import ESTIMATORS
from grazing_control.dynamics.estimation.motion import actuator_legs
from grazing_control.dynamics.estimation.stream import (IMPACT_SOURCES, StreamEstimator,
                                                        predict_section, pulse_shape)
from grazing_control.dynamics.estimation.stream import warm_up as warm_stream
from grazing_control.dynamics.simulation.actuator import Actuator
from grazing_control.oscillator import kernel as _kernel
from grazing_control.oscillator.control import Gains, correction
from grazing_control.oscillator.ndof.section import NdofSection
from grazing_control.oscillator.params import OscillatorParams, ParameterError, study_omega
from grazing_control.plant.settings import MAX_BANDWIDTH, below, load_model_file

from .model_watch import WATCH_DEFAULTS, watch_from_values

__all__ = ["ControlLaw", "GAIN_LIMIT", "PI2_SOURCES", "law_from_values",
           "model_from_values", "stream_from_values", "pulse_from_values",
           "capture_from_values", "model_capture_from_values",
           "actuation_delay_from_values", "below_period", "model_omega",
           "ModelController", "model_controller_from_values", "model_stream_from_values",
           "gain_vector_correction", "predicted_correction", "warm_up_kernel", "ONE_DOF_DEFAULTS",
           "unseen_rebound", "degeneracy_warning", "DEGENERATE_TOL"]

#: Where the Pi2 state comes from: the simulator's exact samples, or the sensor stream.
PI2_SOURCES = ("sample", "stream")


def gain_vector_correction(k, x, v, x_ref, v_ref) -> float:
    """Delta v = k^T (X - X**) for a sample (x, v) of n positions and n velocities
    (docs/theory_ndof.md, "Kick design"); k (2n,), X**'s halves ``x_ref``, ``v_ref``."""
    n = x_ref.size
    return float(k[:n] @ (np.asarray(x, float) - x_ref) + k[n:] @ (np.asarray(v, float) - v_ref))


class ControlLaw:
    """Delta v = k^T (X - X**) with a switch, a saturation and the sample bookkeeping (no
    ROS), for any n: the 1-DOF gains (c1, c2) are the n = 1 member, evaluated by the closed
    form's expression (Eq. 28, :func:`grazing_control.oscillator.control.correction`).

    Parameters
    ----------
    gains : Gains, or the gain vector k (2n,) of an n-DOF model
    x_ref, v_ref : float, or (n,) arrays
        X** on Pi2.
    enable_after : int
        First sample index (from 0) that is controlled; -1: only by :meth:`enable`.
    saturation : float
        Limit on |Delta v|, > 0 (inf: none).
    """

    #: Answered stamps remembered to recognise duplicates.
    RECENT = 64

    def __init__(self, gains: Gains, x_ref: float, v_ref: float, enable_after: int,
                 saturation: float):
        self.configure(gains, x_ref, v_ref, enable_after, saturation)
        self.count = 0          # samples answered since the start or the last reset
        self.newest = None      # stamp key of the newest sample answered
        self.recent = deque(maxlen=self.RECENT)   # stamp keys of the last answers
        self.out_of_order = 0   # samples answered though older than the newest
        self._before_reset = None   # (count, newest, recent) before a t = 0 sample
        self.forced = None      # None: follow enable_after; True/False: set by ~/enable

    def configure(self, gains, x_ref, v_ref, enable_after, saturation) -> None:
        self.gains, self.x_ref, self.v_ref = gains, x_ref, v_ref
        self.enable_after, self.saturation = enable_after, saturation
        # the law's expression: Eq. 28's for (c1, c2), k^T (X - X**) for a gain vector
        self._correction = correction if isinstance(gains, Gains) else gain_vector_correction

    @property
    def enabled(self) -> bool:
        """Whether the next sample is controlled."""
        if self.forced is not None:
            return self.forced
        return 0 <= self.enable_after <= self.count

    def answer(self, key: tuple, x: float, v: float):
        """Delta v for the sample with stamp ``key``; None when it must not be answered.

        None for a duplicate (a stamp among the last :attr:`RECENT` answered). The
        result may be non-finite (overflow): the caller must not publish it.
        """
        if self._before_reset is not None:
            count, newest, recent = self._before_reset
            self._before_reset = None
            if key > newest:        # the stream went on: that t = 0 sample was a stray
                self.count, self.newest = count + self.count, newest
                self.recent = recent
                self.recent.append((0, 0))
        if key == (0, 0) and self.newest is not None:
            # back to t = 0: the simulator was reset (confirmed by the next sample)
            self._before_reset = (self.count, self.newest, self.recent)
            self.count = 0
            self.newest = None
            self.recent = deque(maxlen=self.RECENT)
        if key in self.recent:
            return None
        if self.newest is not None and key < self.newest:
            self.out_of_order += 1
        dv = 0.0
        if self.enabled:
            dv = self._law(x, v)
            if abs(dv) > self.saturation:
                dv = math.copysign(self.saturation, dv)
        self.newest = key if self.newest is None else max(self.newest, key)
        self.recent.append(key)
        self.count += 1
        return dv

    def off_for_two(self) -> bool:
        """Whether the next sample's answer and the prediction for the one after it are 0
        whatever the state: the control is off for both (forced off, or on only through
        ~/enable, or ``enable_after`` more than one sample away)."""
        if self.forced is not None:
            return not self.forced
        return self.enable_after < 0 or self.enable_after > self.count + 1

    def preview(self, x: float, v: float) -> float:
        """The correction the next sample would get if it were (x, v): Eq. 28 with the
        saturation when the next sample is controlled, else 0 (issue 16 section 3)."""
        if not self.enabled:
            return 0.0
        dv = self._law(x, v)
        if abs(dv) > self.saturation:
            dv = math.copysign(self.saturation, dv)
        return dv

    def _law(self, x, v) -> float:
        """k^T (X - X**) before the saturation (Eq. 28 for n = 1)."""
        return self._correction(self.gains, x, v, self.x_ref, self.v_ref)


def predicted_correction(law: ControlLaw, model, ndof, stream, pulse: tuple, delay: float,
                         x, v, dv: float) -> float:
    """The correction of the next sample predicted by one exact period of the model
    (``model``, or the n-DOF ``ndof``) from the answered state (x, v) with ``dv`` applied
    ``delay`` after the section as ``pulse`` acts (issue 16 section 3): ``law``'s preview
    of the predicted state; NaN without a model or where the prediction fails. With a
    ``stream`` estimator, from the force its known corrections left at this section."""
    if (model is None and ndof is None) or (ndof is not None and not ndof.predicts):
        return math.nan
    try:
        # the force the earlier corrections left at this section (stream mode: the
        # estimator knows them; else 0, a share e^{-T / tau_a} of one pulse's force)
        force0 = (stream.section_force(stream.next_k - 1)
                  if stream is not None and stream.next_k else 0.0)
        if ndof is not None:
            xn, vn = ndof.predict(x, v, dv, delay, pulse, force0)
        else:
            p = model
            zx, zv = predict_section(p, (x - p.x_ref, v - p.v_ref), dv, delay,
                                     width=pulse[0], force_limit=pulse[1], actuator=pulse[2],
                                     force0=force0, kernel=(stream.kernel if stream is not None
                                                            else _kernel.loaded()))
            xn, vn = p.x_ref + zx, p.v_ref + zv
    except (ValueError, ArithmeticError, RuntimeError):
        return math.nan
    return law.preview(xn, vn)


def warm_up_kernel(model, stream) -> threading.Thread | None:
    """Load the compiled kernel where it is in use (``GRAZING_KERNEL``): in stream mode
    now, the model filter's and the prediction's, so that section 0 does not wait for it
    (:func:`grazing_control.dynamics.estimation.stream.warm_up`); with a model and exact
    samples in a thread, returned (issue 30: the prediction on the Python flow, ~70 us a
    section on the lockstep answer's path, until :func:`predicted_correction` finds it
    loaded; the same numbers bit for bit, never a wait). None: nothing to load, or done."""
    if stream is not None:
        if stream.kernel:
            warm_stream(model)
        return None
    if model is None or not _kernel.use_kernel() or _kernel.loaded() or any(
            t.name == "kernel_warm_up" and t.is_alive() for t in threading.enumerate()):
        return None             # (composed: the simulator's thread loads it already)
    loading = threading.Thread(target=_kernel.warm_up, name="kernel_warm_up", daemon=True)
    loading.start()
    return loading


#: Largest |c1|, |c2| (and |k_i| of an n-DOF gain vector) accepted (the design's search
#: limit, dynamics.design.gains.C2_LIMIT).
GAIN_LIMIT = 1e6


def law_from_values(values: dict) -> ControlLaw:
    """Validate the controller's parameters into a :class:`ControlLaw` (ParameterError).

    |c1|, |c2| <= GAIN_LIMIT: a gain of 1e308 passed the finiteness check and the next
    correction (inf) stopped the simulator (issue 21); the design's admissible sets end
    within 1e6 (dynamics.design.gains.C2_LIMIT).
    """
    for name in ("c1", "c2"):
        if not abs(float(values[name])) <= GAIN_LIMIT:
            raise ParameterError(f"{name}={values[name]!r} is invalid: valid range is "
                                 f"|{name}| <= {GAIN_LIMIT:g}")
    gains = Gains(values["c1"], values["c2"])
    x_ref, v_ref = float(values["x_ref"]), float(values["v_ref"])
    if math.isnan(x_ref) or math.isnan(v_ref):
        p = OscillatorParams(zeta=values["zeta"], r=values["r"], omega=values["omega"],
                             pi2_offset=values["pi2_offset"])
        x_ref = p.x_ref if math.isnan(x_ref) else x_ref
        v_ref = p.v_ref if math.isnan(v_ref) else v_ref
    for name, value in (("x_ref", x_ref), ("v_ref", v_ref)):
        if not math.isfinite(value):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite real "
                                 "number, or NaN to compute X** from the model parameters")
    enable_after = int(values["enable_after"])
    if enable_after < -1:
        raise ParameterError(f"enable_after={enable_after} is invalid: valid range is >= 0, "
                             "or -1 for only through ~/enable")
    saturation = float(values["saturation"])
    if not saturation > 0.0:
        raise ParameterError(f"saturation={saturation!r} is invalid: valid range is "
                             "saturation > 0 (inf: no limit)")
    stale_after = float(values["stale_after"])
    if not stale_after > 0.0:
        raise ParameterError(f"stale_after={stale_after!r} is invalid: valid range is "
                             "stale_after > 0 (inf: no age limit)")
    return ControlLaw(gains, x_ref, v_ref, enable_after, saturation)


def model_from_values(values: dict):
    """The plant model (with Delta d) for the estimator and the prediction, or None when
    ``delta_d`` is NaN (no model: no prediction, and no stream mode)."""
    delta_d = float(values["delta_d"])
    if math.isnan(delta_d):
        return None
    if not math.isfinite(delta_d):
        raise ParameterError(f"delta_d={delta_d!r} is invalid: valid range is a finite real "
                             "number (the plant's Delta d), or NaN for no model")
    return OscillatorParams(zeta=values["zeta"], r=values["r"], omega=values["omega"],
                            delta_d=delta_d, pi2_offset=values["pi2_offset"])


def stream_from_values(values: dict, model, pulse: tuple = (0.0, math.inf)):
    """The :class:`StreamEstimator` of ``pi2_source`` stream, None for ``sample``
    (ParameterError naming the parameter and its valid values); the augmented filter
    (:class:`AugmentedStreamEstimator`) when the model watch is on
    (:mod:`grazing_control.ros.model_watch`). ``pulse``: (width, force limit) of the
    plant's corrections in model units (a rig file's actuator; (0, inf): a kick)."""
    source = values["pi2_source"]
    if source not in PI2_SOURCES:
        raise ParameterError(f"pi2_source={source!r} is invalid: valid values are "
                             f"{', '.join(PI2_SOURCES)}")
    if values["estimator"] not in ESTIMATORS:
        raise ParameterError(f"estimator={values['estimator']!r} is invalid: valid values "
                             f"are {', '.join(ESTIMATORS)}")
    if values["impact_source"] not in IMPACT_SOURCES:
        raise ParameterError(f"impact_source={values['impact_source']!r} is invalid: valid "
                             f"values are {', '.join(IMPACT_SOURCES)}")
    floor = float(values["model_noise"])
    if not (math.isfinite(floor) and floor >= 0.0):
        raise ParameterError(f"model_noise={floor!r} is invalid: valid range is a finite "
                             "model_noise >= 0 (process noise per period, in sensor_noise)")
    for name in ("sensor_noise", "state_period"):
        value = float(values[name])
        if not (math.isfinite(value) and value >= 0.0):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite "
                                 f"{name} >= 0")
    watch = watch_from_values({**WATCH_DEFAULTS, **values})    # refused in sample mode
    if source == "sample":
        return None
    if model is None:
        raise ParameterError("delta_d=nan is invalid with pi2_source=stream: valid range is "
                             "the plant's finite Delta d (the estimator's model needs the wall)")
    act = pulse[2] if len(pulse) > 2 else None
    if watch is not None:       # the augmented filter (ros/model_watch.py, issue 29)
        return AugmentedStreamEstimator(
            model, values["sensor_noise"], values["impact_source"], values["state_period"],
            floor, bool(values["answer_after_section"]), values.get("answer_lead", 0.0),
            **watch[0], pulse_width=pulse[0], force_limit=pulse[1], actuator=act)
    return StreamEstimator(model, values["estimator"], values["sensor_noise"],
                           values["impact_source"], values["state_period"], floor,
                           bool(values["answer_after_section"]),
                           values.get("answer_lead", 0.0), pulse_width=pulse[0],
                           force_limit=pulse[1], actuator=act)


def unseen_rebound(lead: float) -> str:
    """The warning of a stream controller whose answer ``lead`` reached past an impact
    (StreamEstimator.unseen_impacts, docs/theory_estimation.md (E2''))."""
    return (f"answer_lead={lead!r} reaches past an impact: no sample of its section saw "
            "the rebound, which comes from the model's impact law alone (an identified r; "
            "docs/theory_estimation.md (E2''))")

def pulse_from_values(values: dict, omega: float, delay: float) -> tuple:
    """(width, force limit, actuator or None) of the plant's corrections from the
    :data:`PULSE_KEYS` (model units, as sim_node's): the pulse (``pulse_width`` 0: a
    kick) and the first-order actuator between its command and the force
    (``actuator_bandwidth`` 1 / tau_a, 0: ideal; ``actuator_latency``), which the stream
    estimator and the prediction integrate (dynamics.estimation.motion.trajectory).
    ParameterError, one line naming the parameter and its valid range."""
    period = 2.0 * math.pi / omega
    width, limit = pulse_shape(OscillatorParams(omega=omega), values["pulse_width"],
                               values["force_limit"])
    bw, lat = float(values["actuator_bandwidth"]), float(values["actuator_latency"])
    if not (bw == 0.0 or 1.0 / MAX_BANDWIDTH <= bw <= MAX_BANDWIDTH):
        raise ParameterError(f"actuator_bandwidth={bw!r} is invalid: valid range is 0 (ideal) "
                             f"or 1e-12 <= actuator_bandwidth <= {MAX_BANDWIDTH:g}")
    if not (math.isfinite(lat) and lat >= 0.0):
        raise ParameterError(f"actuator_latency={lat!r} is invalid: valid range is a finite "
                             "actuator_latency >= 0")
    act = Actuator(1.0 / bw if bw else 0.0, lat)
    if act.ideal:
        return width, limit, None
    if width == 0.0:
        raise ParameterError("pulse_width=0.0 is invalid with actuator_bandwidth or "
                             f"actuator_latency: valid range is 0 < pulse_width < T = {period!r}")
    actuator_legs(None, 0.0, delay, period, width, limit, act)     # the latency: named
    return width, limit, act


def capture_from_values(values: dict, model, delay: float):
    """The :class:`CaptureRule` of ``capture`` (None when off): no correction until the
    estimate is within ``capture_radius`` of the controlled orbit's Pi2 state z**
    (0: the documented CAPTURE_RADIUS sqrt(|Delta d|), docs/theory_capture.md), then
    Eq. 28 (latched). Stream mode only (the estimate's covariance says it is one);
    ParameterError naming the parameter, or the missing controlled orbit."""
    radius = _capture_radius(values)
    if not values["capture"]:
        return None
    if values["pi2_source"] != "stream" or model is None:
        raise ParameterError(f"capture=True is invalid with pi2_source={values['pi2_source']}: "
                             "valid only with pi2_source=stream and a model (delta_d)")
    from grazing_control.dynamics.orbits.orbits import orbit_11

    gains = Gains(values["c1"], values["c2"], delay)
    try:
        target = orbit_11(model, gains).pi2_deviation
    except (ValueError, ArithmeticError, RuntimeError) as exc:
        raise ParameterError(f"capture=True is invalid here: no controlled 1/1 orbit of the "
                             f"gains at delta_d={model.delta_d!r} ({exc})") from None
    return _capture_rule(target, model.delta_d, radius)


def _capture_radius(values: dict) -> float:
    """``capture_radius`` checked: finite and >= 0 (0: the default, 5 sqrt(|Delta d|))."""
    radius = float(values.get("capture_radius", 0.0))
    if not (math.isfinite(radius) and radius >= 0.0):
        raise ParameterError(f"capture_radius={radius!r} is invalid: valid range is a finite "
                             "capture_radius >= 0 (0: 5 sqrt(|delta_d|))")
    return radius


def _capture_rule(target, delta_d: float, radius: float) -> CaptureRule:
    """The rule about ``target`` with ``radius`` (0: CAPTURE_RADIUS sqrt(|Delta d|))."""
    if radius == 0.0:
        return CaptureRule.for_wall(target, delta_d, CAPTURE_RADIUS)
    return CaptureRule(target, radius)


def model_capture_from_values(values: dict, ndof: ModelController, delay: float,
                              pulse: tuple = (0.0, math.inf)):
    """The n-DOF :class:`CaptureRule` of ``capture`` (None when off): no correction until
    the estimate z^ = X^ - X** is within ``capture_radius`` (Euclidean in the 2n
    coordinates; 0: CAPTURE_RADIUS sqrt(|Delta d|), docs/theory_capture.md) of the
    controlled 1/1 orbit's Pi2 deviation z** of the design (gains k, actuation ``delay``,
    ``pulse`` (width, force limit[, actuator]) as :func:`pulse_from_values`; through an
    actuator the lag's orbit, :func:`grazing_control.dynamics.design.noise.controlled_orbit`),
    then k^T z^ (latched). Stream mode only; ParameterError naming the parameter. The
    rule's ``forecast``: a warning where the model's free motion from X** leaves the radius
    and does not come back (:func:`_free_forecast`), else None."""
    radius = _capture_radius(values)
    if not values.get("capture"):
        return None
    if values.get("pi2_source", "sample") != "stream" or not ndof.predicts:
        raise ParameterError(f"capture=True is invalid with pi2_source="
                             f"{values.get('pi2_source', 'sample')}: valid only with "
                             "pi2_source=stream and the plant's finite delta_d")
    width = float(pulse[0])
    act = pulse[2] if len(pulse) > 2 else None
    try:
        if act is None:
            from grazing_control.dynamics.orbits.one_one import orbit

            target = orbit(ndof.model, ndof.gains, delay=delay, width=width).state
        else:
            from grazing_control.dynamics.design.family import Actuation
            from grazing_control.dynamics.design.noise import controlled_orbit

            target = controlled_orbit(ndof.model, ndof.gains, Actuation(
                delay, width, act.time_constant, act.latency))[:2 * ndof.model.n]
    except (ValueError, ArithmeticError, RuntimeError) as exc:
        raise ParameterError(f"capture=True is invalid here: no controlled 1/1 orbit of the "
                             f"gains at delta_d={ndof.model.delta_d!r} ({exc})") from None
    rule = _capture_rule(target, ndof.model.delta_d, radius)
    rule.forecast = _free_forecast(ndof.model, rule)
    return rule


def _free_forecast(model, rule) -> str | None:
    """The warning of :func:`~grazing_control.dynamics.design.capture.free_approach` for
    the model's free motion from X** (None where it comes back, or cannot be flowed)."""
    from grazing_control.dynamics.design.capture import free_approach
    from grazing_control.dynamics.maps.modal_map import ModalMap

    free = ModalMap(model)
    try:
        return free_approach(lambda z: free.step(z).state, rule.target, rule.radius).warning()
    except (ValueError, ArithmeticError, RuntimeError):
        return None


def actuation_delay_from_values(values: dict) -> float:
    """The design's actuation delay, 0 <= delay < T = 2 pi / omega (ParameterError)."""
    delay = float(values.get("actuation_delay", 0.0))
    period = 2.0 * math.pi / float(values["omega"])
    if not (math.isfinite(delay) and 0.0 <= delay < period):
        raise ParameterError(f"actuation_delay={delay!r} is invalid: valid range is "
                             f"0 <= actuation_delay < T = {period!r} (simulation time)")
    return delay


#: How far c1 may lie from Eq. 38's degenerate gain of the running c2 and delay, relative
#: to that gain, before the controller warns: a design's c1 is that gain to rounding, one
#: typed from a table to its digits.
DEGENERATE_TOL = 1e-3


def degeneracy_warning(values: dict, pulse: tuple) -> str | None:
    """The start-up warning of a 1-DOF controller whose c1 is not the degenerate gain of
    its c2 at its ``actuation_delay`` (Eq. 38; docs/theory_delay.md (D5)): gains designed
    for another delay than the one given (the design's ``actuation_delay`` overridden) do
    not make the grazing bifurcation degenerate, and the watchdog would end the scene
    only once the orbit is lost. None where c1 is that gain (within DEGENERATE_TOL),
    where both gains are 0 (said apart), where the correction is a pulse (``pulse``
    (width, ...) of :func:`pulse_from_values`; its design is ``grazing design
    --pulse-width``'s), or where Eq. 38 has no c1."""
    c1, c2 = float(values["c1"]), float(values["c2"])
    if (c1 == 0.0 and c2 == 0.0) or pulse[0] > 0.0:
        return None
    delay = float(values.get("actuation_delay", 0.0))
    try:
        p = OscillatorParams(zeta=values["zeta"], r=values["r"], omega=values["omega"],
                             pi2_offset=values["pi2_offset"])
        want = degenerate_c1(p, c2, delay)
    except (ParameterError, ArithmeticError, ValueError):
        return None
    if abs(c1 - want) <= DEGENERATE_TOL * abs(want):
        return None
    return (f"c1={c1!r} is not the degenerate gain of c2={c2!r} at actuation_delay="
            f"{delay!r} (Eq. 38: c1={want!r}): the grazing bifurcation is not made "
            "degenerate here, and the controlled orbit loses its stability near grazing "
            f"(gains designed for another delay? grazing design --c2 {c2!r} --delay {delay!r})")


def below_period(omega: float) -> float:
    """The largest actuation delay below T = 2 pi / omega, the same expression as
    :func:`actuation_delay_from_values` (the described range's end; inf where omega is
    not > 0: refused by name at start)."""
    return below(2.0 * math.pi / float(omega)) if omega > 0.0 else math.inf


def model_omega(model_file: str, omega: float) -> float:
    """The forcing frequency of the scene: the n-DOF model file's, else ``omega``
    (also where the file cannot be read: refused by name when the law is built)."""
    if not model_file:
        return omega
    try:
        return load_model_file(model_file).omega
    except ParameterError:
        return omega

#: The 1-DOF law's parameters and their defaults: an n-DOF controller refuses any other
#: value (the model file and ``gains`` give the n-DOF law). The 1-DOF model's defaults
#: are filled in by :func:`model_controller_from_values`.
ONE_DOF_DEFAULTS = {"c1": 0.0, "c2": 0.0, "x_ref": math.nan, "v_ref": math.nan,
                    "zeta": OscillatorParams().zeta, "r": OscillatorParams().r}
#: The section data of the design's parameter file and the value meaning "not given":
#: given, each must be the model's.
SECTION_DATA = {"n": -1, "i_a": -1, "omega": study_omega(),
                "pi2_offset": OscillatorParams().pi2_offset}


@dataclasses.dataclass(frozen=True)
class ModelController:
    """What an n-DOF controller needs besides the law's switches: the model (with the
    plant's delta_d), its pieces (:class:`NdofSection`: the flow, the kick), X** on Pi2,
    the gains, and whether it predicts."""

    model: object
    section: NdofSection
    gains: np.ndarray
    x_ref: np.ndarray
    v_ref: np.ndarray
    predicts: bool

    @property
    def flow(self):
        """The model's exact flow (``NdofFlow``)."""
        return self.section.flow

    def predict(self, x, v, dv: float, delay: float, pulse: tuple = (0.0, math.inf),
                force0: float = 0.0):
        """The Pi2 sample after (x, v) with ``dv`` acting ``delay`` after it: one exact
        period of the model (the plant engine's calls, plant.engine); ``pulse`` (width,
        force limit[, actuator]): the correction as the force pulse of that width centred
        ``delay`` after the sample (:func:`grazing_control.dynamics.maps.modal_map.pulse_step`,
        docs/theory_ndof.md section 15), through the first-order actuator from the force
        ``force0`` at the section where one is given (``actuated_step``). Returns (x', v')."""
        from grazing_control.dynamics.maps.modal_map import actuated_step, pulse_step
        from grazing_control.dynamics.simulation.actuation import pulse_start

        sec, f = self.section, self.section.flow
        n = sec.n
        z = f.to_deviation(f.tau2, np.concatenate([np.asarray(x, float), np.asarray(v, float)]))
        tau = f.tau2
        width, limit = pulse[0], pulse[1]
        act = pulse[2] if len(pulse) > 2 else None
        if act is not None:
            z = actuated_step(f, z, force0, dv, start=pulse_start(sec.period, delay, width),
                              width=width, time_constant=act.time_constant,
                              latency=act.latency, force_limit=limit)[0]
            X = f.to_physical(f.tau2, z)
            return X[:n], X[n:]
        if width > 0.0:
            z = pulse_step(f, z, dv, start=pulse_start(sec.period, delay, width), width=width,
                           force_limit=limit).state
            X = f.to_physical(f.tau2, z)
            return X[:n], X[n:]
        if delay > 0.0:
            z = sec.advance(tau, z, delay).z
            tau = (tau + sec.omega * delay) % (2.0 * math.pi)
        z = sec.advance(tau, sec.kicked(z, dv), sec.period - delay).z
        X = f.to_physical(f.tau2, z)
        return X[:n], X[n:]


def model_controller_from_values(values: dict, model_file: str, gains,
                                 model=None) -> ModelController:
    """Validate an n-DOF controller's values (ParameterError naming the parameter).

    ``gains``: the ``gains`` parameter (None when not given); ``values``: the 1-DOF
    controller's parameters, of which c1, c2, x_ref, v_ref must stay at their defaults
    and ``pi2_source`` at ``sample``; ``delta_d`` (finite) replaces the file's Delta d and
    switches the prediction of the next correction on (NaN: the file's, no prediction).
    ``model``: the model when already built (a rig of n masses: Rig.model(), ``model_file``
    then the rig file's path, for the messages).
    """
    model = load_model_file(model_file) if model is None else model
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
    section = NdofSection(model)
    X = np.asarray(section.flow.particular(section.tau2), dtype=float)
    n = model.n
    k.setflags(write=False)
    return ModelController(model, section, k, X[:n].copy(), X[n:].copy(),
                           predicts=not math.isnan(delta_d))


def model_stream_from_values(values: dict, ndof: ModelController,
                             pulse: tuple = (0.0, math.inf)):
    """The n-DOF scene's stream estimator for ``pi2_source`` stream, None for ``sample``
    (ParameterError naming the parameter): the model filter over the exact n-DOF map
    (:class:`grazing_control.dynamics.estimation.stream.StreamEstimator` with the
    controller's model, docs/theory_estimation.md (E11)) reading coordinate
    ``sensor_coordinate``; it needs the plant's ``delta_d`` (``ndof.predicts``), the
    estimator ``model``, ``sensor_noise`` > 0 and impacts detected in the stream.
    ``pulse``: (width, force limit[, actuator]) of the plant's force pulse
    (:func:`pulse_from_values`; its trajectory, through the first-order actuator where one
    is given, is the filter's, docs/theory_ndof.md section 15), (0, inf): the kick.
    The model watch (``estimate_bias``, ``track_delta_d``, ``consistency_window``,
    :mod:`grazing_control.ros.model_watch`) selects the augmented filter over the model
    file (:class:`AugmentedStreamEstimator`, docs/theory_estimation.md (E12)), its values
    checked as for 1-DOF; ``reidentify``: :mod:`grazing_control.ros.reidentify`."""
    from grazing_control.dynamics.estimation.stream import StreamEstimator

    source = values.get("pi2_source", "sample")
    if source not in PI2_SOURCES:
        raise ParameterError(f"pi2_source={source!r} is invalid: valid values are sample, "
                             "stream")
    watch = watch_from_values({**WATCH_DEFAULTS, "pi2_source": source, "estimator": "model",
                               **values})           # refused in sample mode
    if source == "sample":
        return None
    if not ndof.predicts:
        raise ParameterError("delta_d=nan is invalid with pi2_source=stream: valid range is "
                             "the plant's finite Delta d (the estimator's model needs the wall)")
    if values.get("impact_source", "stream") != "stream":
        raise ParameterError(f"impact_source={values['impact_source']!r} is invalid with "
                             "model_file: valid is stream (the n-DOF model filter finds the "
                             "impacts in its exact motion)")
    floor = float(values.get("model_noise", 1e-2))
    if not (math.isfinite(floor) and floor >= 0.0):
        raise ParameterError(f"model_noise={floor!r} is invalid: valid range is a finite "
                             "model_noise >= 0 (process noise per period, in sensor_noise)")
    if watch is not None:   # the augmented filter over the model file (E12, issue 32)
        return AugmentedStreamEstimator(
            ndof.model, float(values.get("sensor_noise", 0.0)), "stream",
            float(values.get("state_period", 0.0)), floor,
            bool(values.get("answer_after_section", False)),
            float(values.get("answer_lead", 0.0)), **watch[0],
            coordinate=int(values.get("sensor_coordinate", 0)), pulse_width=pulse[0],
            force_limit=pulse[1], actuator=pulse[2] if len(pulse) > 2 else None)
    return StreamEstimator(ndof.model, values.get("estimator", "model"),
                           float(values.get("sensor_noise", 0.0)), "stream",
                           float(values.get("state_period", 0.0)), floor,
                           bool(values.get("answer_after_section", False)),
                           float(values.get("answer_lead", 0.0)),
                           kernel=None,      # compiled where numba is: bit for bit (E11)
                           coordinate=int(values.get("sensor_coordinate", 0)),
                           pulse_width=pulse[0], force_limit=pulse[1],
                           actuator=pulse[2] if len(pulse) > 2 else None)

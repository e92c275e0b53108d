"""The controller's law and its validation (grazing_control.ros.controller_values), without
middleware, for any n: X** is the grazing orbit's Pi2 state, the answer is k^T (X - X**)
(the 1-DOF (c1, c2) its n = 1 member, bit for bit), the prediction is one exact period
of the engine, and wrong gains are refused with a reason."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.family import evaluate_design, gain_family, write_gain_yaml
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.oscillator.ndof.flow import periodic_response
from grazing_control.oscillator.ndof.model import load_model
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros.controller_values import (ControlLaw, gain_vector_correction,
                                                   model_controller_from_values)

SCENE = str(Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_scene.yaml")
MODEL = load_model(SCENE)
K = gain_family(MODEL, 0.0)


def test_x_ref_is_the_grazing_orbit_on_pi2():
    c = model_controller_from_values({}, SCENE, K.tolist())
    m = MODEL
    # independent: the periodic response at the time of Pi2, pi2_offset / omega after the
    # grazing maximum of the wall coordinate (a grid maximum, then the root of its
    # velocity there by bisection)
    from scipy.optimize import brentq

    ts = np.linspace(0.0, m.period, 20001)
    xw = periodic_response(m, ts)[0][:, m.i_w]
    j = int(np.argmax(xw))
    t_star = brentq(lambda t: float(periodic_response(m, t)[1][m.i_w]), ts[j - 1], ts[j + 1],
                    xtol=1e-14)
    x, v = periodic_response(m, t_star + m.pi2_offset / m.omega)
    np.testing.assert_allclose(c.x_ref, x, atol=1e-8)
    np.testing.assert_allclose(c.v_ref, v, atol=1e-8)
    assert abs(c.v_ref[m.i_w] + m.omega * abs(xw.max())) < 1e-8   # a quarter period on
    assert not c.predicts and c.model.delta_d == m.delta_d


def Law(c):
    """The controller's law of a model file's controller, always on, no saturation."""
    return ControlLaw(c.gains, c.x_ref, c.v_ref, 0, math.inf)


def test_the_one_dof_gains_are_the_n_equals_1_member_of_the_gain_vector_law():
    """(c1, c2) on (x, v) and k = (c1, c2) on X = (x, v): the same correction to the bit
    (a one-term dot product is one product), on many random samples; and the law picks
    Eq. 28's expression for Gains, the vector's for an array."""
    p = OscillatorParams()
    rng = np.random.default_rng(11)
    for _ in range(200):
        c1, c2 = rng.normal(scale=3.0, size=2)
        x, v = p.x_ref + rng.normal(scale=1e-3), p.v_ref + rng.normal(scale=1e-3)
        one = ControlLaw(Gains(c1, c2), p.x_ref, p.v_ref, 0, math.inf)
        vec = ControlLaw(np.array([c1, c2]), np.array([p.x_ref]), np.array([p.v_ref]), 0,
                         math.inf)
        assert one._law(x, v) == vec._law(np.array([x]), np.array([v]))
    assert vec._correction is gain_vector_correction and one._correction is not vec._correction


def test_the_answer_is_k_dot_the_deviation_and_the_prediction_the_next_sample():
    c = model_controller_from_values({"delta_d": -2e-5}, SCENE, K.tolist())
    assert c.predicts and c.model.delta_d == -2e-5
    rng = np.random.default_rng(3)
    z = rng.normal(scale=1e-3, size=4)
    X = np.concatenate([c.x_ref, c.v_ref]) + z
    law = Law(c)
    assert law._law(X[:2], X[2:]) == pytest.approx(float(K @ z), rel=1e-12)
    # the predicted next sample is the engine's next sample from that state and kick
    s = settings_from_values({"delta_d": -2e-5}, SCENE)
    eng = Engine(s)
    eng.z = eng.section.flow.to_deviation(eng.section.flow.tau2, X)
    dv = law._law(X[:2], X[2:])
    eng.begin_period(dv)
    ev, _ = eng.end_period()
    xn, vn = c.predict(X[:2], X[2:], dv, 0.0)
    np.testing.assert_allclose(np.concatenate([xn, vn]), ev.x + ev.v, rtol=0, atol=1e-14)
    # and ModalMap with the gains (its kick is k^T z of the same state)
    step = ModalMap(c.model, K).step(z)
    np.testing.assert_allclose(eng.z, step.state, rtol=0, atol=1e-14)
    # with the kick 1.0 after the sample (what a realtime simulator substitutes at a
    # missed deadline of a delayed scene, issue 32): ModalMap's delayed step
    xn, vn = c.predict(X[:2], X[2:], dv, 1.0)
    delayed = ModalMap(c.model, K, 1.0).step(z).state
    np.testing.assert_allclose(np.concatenate([xn, vn]) - np.concatenate([c.x_ref, c.v_ref]),
                               delayed, rtol=0, atol=1e-14)
    # with the force pulse of width 1 centred 1.0 after it (issue 32, section 15):
    # ModalMap(width=)'s step, which the pulsed engine repeats bit for bit; it is not the kick
    xn, vn = c.predict(X[:2], X[2:], dv, 1.0, (1.0, math.inf))
    pulsed = ModalMap(c.model, K, 1.0, 1.0).step(z).state
    got = np.concatenate([xn, vn]) - np.concatenate([c.x_ref, c.v_ref])
    np.testing.assert_allclose(got, pulsed, rtol=0, atol=1e-14)
    assert np.max(np.abs(got - delayed)) > 1e-6


def test_the_n_dof_stream_filter_models_the_plants_pulse():
    """Issue 32: with the plant's pulse (pulse_from_values of the controller's
    pulse_width) the n-DOF model filter's trajectory is the pulsed one (on main
    model_stream_from_values dropped it: the filter modelled a kick)."""
    from grazing_control.ros.controller_values import (model_stream_from_values,
                                                       pulse_from_values)

    c = model_controller_from_values({"delta_d": -2e-5}, SCENE, K.tolist())
    pulse = pulse_from_values({"pulse_width": 1.0, "force_limit": 0.0,
                               "actuator_bandwidth": 0.0, "actuator_latency": 0.0},
                              c.model.omega, 1.0)
    values = {"pi2_source": "stream", "sensor_noise": 1e-4, "state_period": 0.1}
    est = model_stream_from_values(values, c, pulse)
    assert est.pulse[0] == 1.0 and model_stream_from_values(values, c).pulse[0] == 0.0


def test_gains_of_the_wrong_length_or_size_are_refused_with_the_reason():
    with pytest.raises(ParameterError, match=r"gains has 3 values: valid is 2n = 4"):
        model_controller_from_values({}, SCENE, [1.0, 2.0, 3.0])
    with pytest.raises(ParameterError, match=r"gains is not given: with model_file it is "
                                             r"required, 4 values"):
        model_controller_from_values({}, SCENE, None)
    with pytest.raises(ParameterError, match=r"gains=.* is invalid: valid range is \|k_i\|"):
        model_controller_from_values({}, SCENE, [1e300, 0.0, 0.0, 0.0])
    with pytest.raises(ParameterError, match=r"gains=.* is invalid"):
        model_controller_from_values({}, SCENE, [math.nan, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("values, text", [
    ({"c1": -1.0}, "c1=-1.0 is invalid with model_file"),
    ({"x_ref": 0.5}, "x_ref=0.5 is invalid with model_file"),
    ({"zeta": 0.05}, "zeta=0.05 is invalid with model_file"),
    ({"n": 3}, "n=3 is invalid with model_file=.*valid is the model's 2"),
    ({"i_a": 0}, "i_a=0 is invalid .* valid is the model's 1"),
    ({"omega": 0.8}, "omega=0.8 is invalid .* valid is the model's 0.275"),
    ({"delta_d": math.inf}, "delta_d=inf is invalid")])
def test_one_dof_parameters_and_another_models_design_are_refused(values, text):
    with pytest.raises(ParameterError, match=text):
        model_controller_from_values(values, SCENE, K.tolist())


@pytest.mark.parametrize("values, text", [
    ({"delta_d": math.nan}, "delta_d=nan is invalid with pi2_source=stream"),
    ({"estimator": "arc"}, "estimator='arc' is invalid with an n-DOF model: valid is model"),
    ({"impact_source": "topic"}, "impact_source='topic' is invalid with model_file"),
    ({"sensor_coordinate": 2}, "sensor_coordinate=2 is invalid: valid range is 0 <= "
                               "sensor_coordinate < n = 2"),
    ({"sensor_noise": 0.0}, "sensor_noise=0.0 is invalid")])
def test_the_n_dof_stream_estimator_refuses_what_it_does_not_do(values, text):
    """pi2_source stream with model_file (issue 32): the model filter over the n-DOF map
    of one coordinate; what it needs or does not do is refused with the reason."""
    from grazing_control.ros.controller_values import model_stream_from_values

    base = {"pi2_source": "stream", "estimator": "model", "sensor_noise": 1e-4,
            "delta_d": -1e-3, "state_period": 0.1}
    c = model_controller_from_values({"delta_d": values.get("delta_d", -1e-3)}, SCENE,
                                    K.tolist())
    with pytest.raises(ParameterError, match=text):
        model_stream_from_values({**base, **values}, c)
    c = model_controller_from_values({"delta_d": -1e-3}, SCENE, K.tolist())
    est = model_stream_from_values({**base, "sensor_coordinate": 1}, c)
    assert est.coordinate == 1 and est.p is c.model
    assert model_stream_from_values({"pi2_source": "sample"}, c) is None


@pytest.mark.parametrize("values, text", [
    ({"consistency_window": -1}, "consistency_window=-1 is invalid: valid range is an "
                                 "integer >= 0 periods"),
    ({"consistency_window": 5, "false_alarm": 0.7}, "false_alarm=0.7 is invalid: valid range "
                                                     "is 0 < false_alarm < 0.5"),
    ({"track_delta_d": True, "wall_noise": -1.0}, "wall_noise=-1.0 is invalid: valid range "
                                                   "is a finite wall_noise >= 0"),
    ({"estimate_bias": True, "bias_std": 0.0}, "bias_std=0.0 is invalid: valid range is a "
                                               "finite bias_std > 0"),
    ({"estimate_bias": True, "pi2_source": "sample"},
     "estimate_bias=True is invalid with pi2_source=sample estimator=model: valid only "
     "with pi2_source=stream")])
def test_the_n_dof_model_watch_is_built_and_its_bad_values_name_the_range(values, text):
    """estimate_bias, track_delta_d and consistency_window with model_file (issue 32; were
    refused as 'not built for n-DOF'): the augmented filter over the model file, reading
    sensor_coordinate, with the watch's values; a bad value is refused naming the
    parameter and its valid range, in sample mode as in 1-DOF."""
    from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
    from grazing_control.ros.controller_values import model_stream_from_values

    base = {"pi2_source": "stream", "estimator": "model", "sensor_noise": 1e-4,
            "delta_d": -1e-3, "state_period": 0.1}
    c = model_controller_from_values({"delta_d": -1e-3}, SCENE, K.tolist())
    with pytest.raises(ParameterError, match=text):
        model_stream_from_values({**base, **values}, c)
    est = model_stream_from_values({**base, "estimate_bias": True, "wall_noise": 2e-8,
                                    "sensor_coordinate": 1}, c)
    assert isinstance(est, AugmentedStreamEstimator) and est.coordinate == 1
    assert est.use_bias and not est.use_wall and est.wall_noise == 2e-8
    est = model_stream_from_values({**base, "consistency_window": 10}, c)
    assert isinstance(est, AugmentedStreamEstimator) and not (est.use_bias or est.use_wall)
    assert type(model_stream_from_values(base, c)) is not AugmentedStreamEstimator


def test_the_designs_parameter_file_is_accepted(tmp_path):
    import yaml

    path = tmp_path / "gains.yaml"
    write_gain_yaml(path, MODEL, evaluate_design(MODEL, 0.2), SCENE)
    values = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    c = model_controller_from_values(values, values["model_file"], values["gains"])
    np.testing.assert_array_equal(c.gains, gain_family(MODEL, 0.2))


#: A fresh interpreter: the controller's kernel loaded in a thread for the prediction.
_WARM = r"""
import json, math, sys
from grazing_control.oscillator import kernel
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros.controller_values import (ControlLaw, predicted_correction,
                                                   warm_up_kernel)
from grazing_control.oscillator.control import Gains
p = OscillatorParams(delta_d=-5e-6)
law = ControlLaw(Gains(-1.0, -1.0), p.x_ref, p.v_ref, 0, math.inf)
states = [(p.x_ref + 1e-4 * i, p.v_ref - 3e-4 * i, 2e-5 * i) for i in range(-5, 6)]
args = (law, p, None, None, (0.0, math.inf, None), 0.0)
before = kernel.loaded()
python = [predicted_correction(*args, *s) for s in states]
thread = warm_up_kernel(p, None)
again = warm_up_kernel(p, None)       # loading already: no second thread
thread.join()
compiled = [predicted_correction(*args, *s) for s in states]
print(json.dumps({"before": before, "thread": thread.name, "again": again is None,
                  "loaded": kernel.loaded(), "same": python == compiled,
                  "python": python, "no_model": warm_up_kernel(None, None) is None}))
"""


@pytest.mark.parametrize("choice", ["auto", "python"])
def test_the_prediction_kernel_loads_in_a_thread_and_changes_no_number(choice):
    """With a model and exact samples the controller loads the compiled kernel in a thread
    (the prediction ran ~70 us a section on the Python flow, on the lockstep answer's
    path); until it is loaded the prediction runs on the Python flow, after it on the
    kernel, with the same numbers bit for bit. GRAZING_KERNEL=python loads nothing."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, GRAZING_KERNEL=choice)
    out = subprocess.run([sys.executable, "-c", _WARM.replace(
        "thread.join()", "thread.join()" if choice == "auto" else "pass").replace(
        "thread.name", "thread.name" if choice == "auto" else "thread")],
        env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["before"] is False and res["same"] and res["no_model"]
    assert all(math.isfinite(x) and x != 0.0 for x in res["python"][:5])
    if choice == "auto":
        assert res["thread"] == "kernel_warm_up" and res["again"] and res["loaded"]
    else:
        assert res["thread"] is None and not res["loaded"]


# ------------------------------------------------------------- the design's delay
def test_gains_of_another_delay_are_warned_and_designed_ones_are_not():
    """degeneracy_warning against Eq. 38 itself over seeded random designs: c1 =
    degenerate_c1(c2, delay) is never warned (at its own delay), the same gains at another
    delay are when Eq. 38 moves c1 there by more than DEGENERATE_TOL, and a c1 off by 1 %
    always; both gains 0 and a pulse are not checked here."""
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.oscillator.params import OscillatorParams
    from grazing_control.ros.controller_values import DEGENERATE_TOL, degeneracy_warning

    rng = np.random.default_rng(20261129)
    p = OscillatorParams()
    base = {"zeta": p.zeta, "r": p.r, "omega": p.omega, "pi2_offset": p.pi2_offset}
    kick, checked = (0.0, math.inf), 0
    for _ in range(300):
        c2, delay, other = rng.uniform(-2.0, 1.0), rng.uniform(0.0, 6.0), rng.uniform(0.0, 6.0)
        try:
            c1, c1_other = degenerate_c1(p, c2, delay), degenerate_c1(p, c2, other)
        except ParameterError:
            continue
        checked += 1
        values = dict(base, c1=c1, c2=c2, actuation_delay=delay)
        assert degeneracy_warning(values, kick) is None
        text = degeneracy_warning(dict(values, actuation_delay=other), kick)
        assert (text is not None) == (abs(c1 - c1_other) > DEGENERATE_TOL * abs(c1_other))
        if text is not None:
            assert f"at actuation_delay={other!r}" in text and f"c1={c1_other!r}" in text
        assert degeneracy_warning(dict(values, c1=c1 * 1.01), kick) is not None
        assert degeneracy_warning(dict(values, c1=c1 * 1.01), (0.1, math.inf)) is None
    assert checked > 250
    assert degeneracy_warning(dict(base, c1=0.0, c2=0.0, actuation_delay=3.0), kick) is None

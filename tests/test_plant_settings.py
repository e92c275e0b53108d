"""The simulator's parameter table and its validation (grazing_control.plant.settings).

sim_node declares its simulation parameters from PARAMETERS and validates them with
settings_from_values: the table must be complete (every field of SimSettings, every key
the validation reads), its defaults valid, and every bad value refused with the
parameter's name and its valid range. An n-DOF scene's settings (a model file, issue
32) are the same object: the model file, delta_d, the table's other values validated as
before, and every option not built for n-DOF refused by name, never half-applied.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import pytest

from grazing_control.oscillator.ndof.model import load_model
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.settings import (ACTUATIONS, MODEL_KEYS, MODES, NOT_WITH_MODEL_FILE,
                                            ON_MISS, PARAMETERS, check_live_change,
                                            SETTING_KEYS, SimSettings, default_values, described_range,
                                            initial_deviation, settings_from_values)


def test_the_table_names_every_setting_once_with_a_type_and_a_doc():
    names = [p.name for p in PARAMETERS]
    assert len(set(names)) == len(names) and tuple(names) == SETTING_KEYS
    # the model file is sim_node's own (read-only) parameter, the argument of the validation
    fields = {f.name for f in dataclasses.fields(SimSettings)} - {
        "params", "sensor", "watchdog", "actuator", "model", "model_file"}
    sensor = {n for n in names if n.startswith(("sensor_", "watchdog_", "actuator_", "contact_",
                                                "friction"))}
    assert fields | set(MODEL_KEYS) | sensor == set(names)
    kinds = {"double": float, "integer": int, "string": str, "bool": bool,
             "double_array": tuple}
    for p in PARAMETERS:
        assert isinstance(p.default, kinds[p.kind]), p
        assert p.doc and (p.kind == "string") == bool(p.choices), p


def test_the_defaults_are_valid_and_are_the_study_scene():
    s = settings_from_values({})
    assert s.params == OscillatorParams(delta_d=0.0)
    assert (s.mode, s.fidelity, s.actuation) == ("lockstep", "exact", "auto")
    assert settings_from_values(default_values()) == s
    assert not s.scheduled and not s.faults.active


@pytest.mark.parametrize("p", [p for p in PARAMETERS if p.kind == "double" and p.lo is not None],
                         ids=lambda p: p.name)
def test_the_described_range_ends_are_accepted_and_the_next_doubles_refused_by_name(p):
    """The closed range a descriptor states (issue 27: [0, 1] for 0 < zeta < 1, [0, inf]
    for finite values) is exactly what the validation accepts, with the other
    parameters at their defaults (described_range narrows actuation_delay to < T)."""
    lo, hi = described_range(p, default_values())
    for end in (lo, hi):
        settings_from_values({p.name: end})
    for bad in (math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf), math.nan):
        with pytest.raises(ParameterError, match=rf"^{p.name}=.*invalid.*valid"):
            settings_from_values({p.name: bad})


@pytest.mark.parametrize("name, choices", [("mode", MODES), ("actuation", ACTUATIONS),
                                           ("on_miss", ON_MISS),
                                           ("feasibility", ("refuse", "warn", "off"))])
def test_strings_outside_their_choices_are_refused_with_the_choices(name, choices):
    with pytest.raises(ParameterError, match=re.escape(", ".join(choices))):
        settings_from_values({name: "nonsense"})
    for c in choices:
        extra = {"actuation_delay": 1.0} if c == "scheduled" else {}
        assert getattr(settings_from_values({name: c, **extra}), name) == c


def test_describe_is_one_line_with_the_faults_only_when_injected():
    assert "faults" not in settings_from_values({}).describe()
    text = settings_from_values({"loss": 0.1, "seed": 4}).describe()
    assert "\n" not in text and "loss=0.1" in text and "seed=4" in text


def test_initial_deviation_nan_is_the_grazing_point():
    p = OscillatorParams(delta_d=-5e-6)
    assert initial_deviation(p, math.nan, math.nan) == (0.0, 0.0)
    assert initial_deviation(p, -0.5, math.nan) == (-0.5 - p.x_ref, 0.0)


@pytest.mark.parametrize("kw, text", [
    ({"sensor_noise": -1e-4}, "sensor_noise=-0.0001 is invalid: valid range"),
    ({"sensor_noise": math.nan}, "sensor_noise=nan is invalid"),
    ({"sensor_quantum": -1.0}, "sensor_quantum=-1.0 is invalid: valid range"),
    ({"sensor_bias": math.inf}, "sensor_bias=inf is invalid: valid range"),
    ({"sensor_seed": -2}, "sensor_seed=-2 is invalid: valid range is an integer >= 0"),
    ({"sensor_velocity": "yes"}, "sensor_velocity='yes' is invalid: valid values"),
    ({"pulse_width": -0.1}, "pulse_width=-0.1 is invalid: valid range"),
    ({"pulse_width": 0.1}, "pulse_width=0.1 is invalid with actuation_delay=0.0: valid range"),
    ({"pulse_width": 1.0, "actuation_delay": 0.4}, "pulse_width <= 2 actuation_delay"),
    ({"pulse_width": 1.0, "actuation_delay": 9.0}, "actuation_delay + pulse_width / 2 < T"),
    ({"force_limit": -1.0}, "force_limit=-1.0 is invalid: valid range"),
    ({"pulse_width": 0.2, "actuation_delay": 1.0, "fidelity": "zdm2"}, "fidelity='zdm2'"),
    ({"pulse_width": 0.2, "actuation_delay": 1.0, "mode": "realtime",
      "actuation": "on_arrival"}, "pulse_width=0.2 is invalid with actuation=on_arrival"),
])
def test_sensor_and_pulse_values_are_refused_by_name_and_range(kw, text):
    with pytest.raises(ParameterError, match=re.escape(text)):
        settings_from_values(kw)


def test_the_sensor_is_plant_sensors_model_and_the_pulse_is_carried():
    s = settings_from_values({"sensor_noise": 1e-4, "sensor_velocity": False,
                              "sensor_quantum": 1e-5, "sensor_bias": 2e-4, "sensor_seed": 9,
                              "pulse_width": 0.1, "actuation_delay": 5.0, "force_limit": 3.0})
    assert (s.sensor.noise, s.sensor.velocity, s.sensor.quantum, s.sensor.bias,
            s.sensor.seed) == (1e-4, False, 1e-5, 2e-4, 9)
    assert (s.pulse_width, s.force_limit) == (0.1, 3.0)
    assert "sensor noise=0.0001 velocity=false" in s.describe()
    assert settings_from_values({}).sensor.exact


# ------------------------------------------------------------------- an n-DOF scene
SCENE = str(Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_scene.yaml")
CHAIN = str(Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_chain.yaml")



def test_the_model_comes_from_the_file_and_delta_d_replaces_its_wall():
    s = settings_from_values({}, SCENE)
    file_model = load_model(SCENE)
    assert isinstance(s, SimSettings) and s.model.delta_d == file_model.delta_d == -1e-5
    assert s.params.period == file_model.period        # the bounds on times read T
    s2 = settings_from_values({"delta_d": -3e-6, "max_periods": 7}, SCENE)
    assert s2.model.delta_d == -3e-6 and s2.max_periods == 7
    assert (s2.model.K == file_model.K).all() and s2.model.omega == file_model.omega
    # the node passes every value of the table: defaults are accepted
    s3 = settings_from_values({**default_values(), "delta_d": -1e-5}, SCENE)
    assert s3.model.delta_d == -1e-5 and s3.mode == "lockstep"
    assert "n=2" in s3.describe() and "delta_d=-1e-05" in s3.describe()


@pytest.mark.parametrize("model_file", ["", CHAIN], ids=["1-DOF", "chain"])
def test_an_absurd_drift_is_refused_at_the_start_naming_its_range(model_file):
    """delta_d_drift (issue 32): 1e308 ran until Delta d overflowed mid-scene. Valid is
    |delta_d_drift| <= d*, the amplitude of the wall coordinate's non-impacting motion
    (1.8015 for the study's oscillator, 3.1885 for two_mass_chain: per period the wall
    moves by at most the motion it bounds); d* itself and the drifts of the scenes are
    accepted, the next double, 1e308, inf and nan refused in one line naming the
    parameter and the range; with a model file the model's d*, not the 1-DOF one."""
    from grazing_control.oscillator.ndof.flow import grazing_clearance

    d_star = grazing_clearance(load_model(CHAIN)) if model_file else OscillatorParams().d_star
    assert d_star == pytest.approx(3.188547848893602 if model_file else 1.801498314953796)
    for ok in (0.0, 5e-10, -1e-4, 1e-6, d_star, -d_star):
        assert settings_from_values({"delta_d_drift": ok}, model_file).delta_d_drift == ok
    for bad in (math.nextafter(d_star, math.inf), -math.nextafter(d_star, math.inf), 1e308,
                -1e308, math.inf, -math.inf, math.nan):
        with pytest.raises(ParameterError) as exc:
            settings_from_values({"delta_d_drift": bad}, model_file)
        text = str(exc.value)
        assert text.startswith(f"delta_d_drift={bad!r} is invalid: valid range is "
                               f"|delta_d_drift| <= d* = {d_star!r} per forcing period")
        assert "\n" not in text


def test_times_are_bounded_by_the_n_dof_period():
    T = load_model(SCENE).period                        # 22.8, the study's is 9.4
    assert settings_from_values({"actuation_delay": 20.0}, SCENE).actuation_delay == 20.0
    with pytest.raises(ParameterError, match=rf"actuation_delay=23.0 is invalid.*T = {T!r}"):
        settings_from_values({"actuation_delay": 23.0}, SCENE)


def test_the_first_order_actuator_is_taken_with_a_model_file_and_a_pulse():
    """Issue 32: the actuator reaches the n-DOF engine (refused on main, ignored before
    the fold; tests/test_plant_engine.py runs it); it needs a pulse width, as in 1-DOF."""
    s = settings_from_values({"actuator_bandwidth": 20.0, "actuator_latency": 0.05,
                              "pulse_width": 0.4, "actuation_delay": 0.3}, SCENE)
    assert (s.actuator.time_constant, s.actuator.latency) == (0.05, 0.05)
    with pytest.raises(ParameterError, match=r"pulse_width"):
        settings_from_values({"actuator_bandwidth": 20.0, "actuation_delay": 0.3}, SCENE)


def test_a_force_pulse_is_taken_with_a_model_file_with_its_bounds_on_the_models_T(tmp_path):
    """Issue 32: pulse_width (and force_limit) reach the n-DOF engine (on main it was
    refused naming the kick); its bounds read the model's T, and a model without a
    static deflection (K singular: a rigid-body mode, docs/theory_ndof.md section 15)
    is refused in one line naming pulse_width and K."""
    s = settings_from_values({"pulse_width": 1.0, "actuation_delay": 1.0,
                              "force_limit": 2.0}, SCENE)
    assert (s.pulse_width, s.force_limit, s.actuation_delay) == (1.0, 2.0, 1.0)
    T = load_model(SCENE).period
    with pytest.raises(ParameterError, match=r"pulse_width <= 2 actuation_delay"):
        settings_from_values({"pulse_width": 1.0, "actuation_delay": 0.4}, SCENE)
    with pytest.raises(ParameterError, match=rf"actuation_delay \+ pulse_width / 2 < T.*{T:.6g}"):
        settings_from_values({"pulse_width": 2.0, "actuation_delay": T - 0.5}, SCENE)
    free = tmp_path / "free.yaml"
    free.write_text("M: [[1.0, 0.0], [0.0, 1.0]]\nC: [[0.04, -0.02], [-0.02, 0.04]]\n"
                    "K: [[1.0, -1.0], [-1.0, 1.0]]\nf: [0.0, 1.0]\nomega: 0.5\n"
                    "i_w: 0\ni_a: 1\nr: 0.7\n")
    assert settings_from_values({}, str(free)).model.n == 2       # the kick is fine
    with pytest.raises(ParameterError, match=r"^pulse_width=1.0 is invalid with model_file="
                                             r".*free.yaml'.*K is invalid.*singular"):
        settings_from_values({"pulse_width": 1.0, "actuation_delay": 1.0}, str(free))


@pytest.mark.parametrize("name", sorted(NOT_WITH_MODEL_FILE))
def test_options_not_built_for_n_dof_are_refused_by_name(name):
    default = default_values()[name]
    bad = {float: 0.5, bool: (not default) if isinstance(default, bool) else None,
           str: "zdm2"}[type(default)]
    if name in ("r", "zeta"):
        bad = 0.3
    with pytest.raises(ParameterError, match=rf"^{name}=.* is invalid with model_file=.*"
                                             r"valid is its default"):
        settings_from_values({name: bad}, SCENE)


@pytest.mark.parametrize("value,text", [
    ([0.0, 0.0, 0.0], r"state0=\[0.0, 0.0, 0.0\] is invalid: valid is 2n = 4 finite values "
                      r"\[x_0, x_1, v_0, v_1\] \(the physical state on Pi2\), or empty"),
    ([0.0, 0.0, math.inf, 0.0], r"state0=.* is invalid: v_0=inf is not finite; valid is 2n"),
    ([0.0, math.nan, 0.0, 0.0], r"state0=.* is invalid: x_1=nan is not finite"),
    ([50.0, 0.0, 0.0, 0.0], r"state0=\[50.0, 0.0, 0.0, 0.0\] is invalid: x_0=50.0 lies "
                            r"beyond the wall; valid range is x_0 <= d = d\* \+ delta_d = "),
    ("abcd", r"state0='abcd' is invalid: valid is 2n = 4"),
    ([3.0, 1e308, 0.0, 0.0], r"state0=\[3.0, 1e\+308, 0.0, 0.0\] is invalid: its deviation "
                             r"from X\*\* is absurdly large .*; valid range is cond\(V\) "
                             r"max\|z\| <= 1e\+150"),     # was refused by the core at t = 0
])
def test_a_bad_n_dof_start_state_is_one_line_naming_state0(value, text):
    """Issue 32: the start of an n-DOF scene (state0, 2n values) refused in one line with
    its valid range: wrong length, not finite, beyond the wall (x_{i_w} <= d)."""
    with pytest.raises(ParameterError, match="^" + text) as err:
        settings_from_values({"state0": value, "delta_d": -1e-3}, CHAIN)
    assert "\n" not in str(err.value)


def test_the_start_state_is_the_wall_coordinates_and_one_dof_refuses_it():
    """The wall's bound is the gap at Pi2 (NdofFlow.gap): a start on the wall is valid,
    a start beyond it by 1e-9 refused; a 1-DOF scene starts at x0, v0 (state0 empty)."""
    from grazing_control.oscillator.ndof.flow import NdofFlow

    model = settings_from_values({"delta_d": -1e-3}, CHAIN).model
    f = NdofFlow.of(model)
    on = f.particular(f.tau2)
    on[model.i_w] += f.on_wall(f.tau2)[0]       # z_w at the wall: gap 0
    assert f.gap(f.tau2, f.to_deviation(f.tau2, on)) <= 0.0
    assert settings_from_values({"state0": on.tolist(), "delta_d": -1e-3}, CHAIN).state0
    on[model.i_w] += 1e-9
    with pytest.raises(ParameterError, match=r"^state0=.* lies beyond the wall"):
        settings_from_values({"state0": on.tolist(), "delta_d": -1e-3}, CHAIN)
    assert settings_from_values({"state0": []}, CHAIN).state0 == ()
    with pytest.raises(ParameterError, match=r"^state0=\[1.0, 2.0\] is invalid without "
                                             r"model_file: valid is empty"):
        settings_from_values({"state0": [1.0, 2.0]})


def test_bad_values_keep_the_one_dof_messages():
    for values, text in [({"mode": "fast"}, "mode='fast' is invalid"),
                         ({"time_scale": 0.0}, "time_scale"),
                         ({"max_periods": -1}, "max_periods=-1"),
                         ({"delta_d": math.inf}, "delta_d=inf is invalid"),
                         ({"loss": 2.0}, "loss=2.0")]:
        with pytest.raises(ParameterError, match=re.escape(text)):
            settings_from_values(values, SCENE)


def test_a_bad_model_file_is_one_line_naming_model_file(tmp_path):
    missing = tmp_path / "none.yaml"
    with pytest.raises(ParameterError, match=r"^model_file='.*none.yaml' is invalid: cannot "
                                             r"read it .*no such file"):
        settings_from_values({}, str(missing))
    broken = tmp_path / "broken.yaml"
    broken.write_text("M: [[1.0, 0.0], [0.0\n")
    with pytest.raises(ParameterError, match=r"^model_file=.*broken.yaml' is invalid: cannot "
                                             r"read it as a model YAML file"):
        settings_from_values({}, str(broken))
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(Path(SCENE).read_text().replace("r: 0.68", "r: 1.5"))
    with pytest.raises(ParameterError, match=r"^model_file=.*wrong.yaml' is invalid: r=1.5 "
                                             r"is invalid: valid range is 0 < r <= 1"):
        settings_from_values({}, str(wrong))
    for err in (missing, broken, wrong):
        try:
            settings_from_values({}, str(err))
        except ParameterError as exc:
            assert "\n" not in str(exc)


def test_live_changes_of_an_n_dof_scene_are_checked_on_its_model():
    """While an n-DOF scene runs (sim_node/parameters.py calls check_live_change): the
    stream's period, the sensor's noise and max_periods change as in 1-DOF, bounded by
    the model's scales (the wall coordinate's amplitude d*, the model's period T); a
    change of delta_d (the model) is refused in one line naming it and why."""
    from grazing_control.oscillator.ndof.flow import grazing_clearance

    old = settings_from_values({"max_periods": 100}, SCENE)
    d_star, T = grazing_clearance(old.model), old.model.period
    ok = settings_from_values({"max_periods": 200, "state_period": T / 100,
                               "sensor_noise": 0.5 * d_star}, SCENE)
    check_live_change(old, ok, 50)
    with pytest.raises(ParameterError) as exc:
        check_live_change(old, settings_from_values({"max_periods": 100, "delta_d": -2e-5},
                                                    SCENE), 50)
    text = str(exc.value)
    assert text.startswith("delta_d=-2e-05 is invalid while an n-DOF scene runs") and \
        "not built" in text and "\n" not in text
    with pytest.raises(ParameterError, match=r"^sensor_noise=.* valid range is \[0, "
                                             + re.escape(f"{d_star:.6g}")):
        check_live_change(old, settings_from_values({"max_periods": 100,
                                                     "sensor_noise": 2.0 * d_star}, SCENE), 50)
    with pytest.raises(ParameterError, match=re.escape(f"T/1e4 = {T * 1e-4:.6g}")):
        check_live_change(old, settings_from_values({"max_periods": 100,
                                                     "state_period": T * 1e-5}, SCENE), 50)

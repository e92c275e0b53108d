"""An n-DOF scene's simulator settings (grazing_control.plant.ndof_settings): the model
file, delta_d, the 1-DOF table's other values validated as before, and every option not
built for n-DOF refused by name, never half-applied."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from grazing_control.oscillator.ndof.model import load_model
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.ndof_settings import (UNSUPPORTED, NdofSettings,
                                                 ndof_settings_from_values)
from grazing_control.plant.settings import default_values

SCENE = str(Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_scene.yaml")


def test_the_model_comes_from_the_file_and_delta_d_replaces_its_wall():
    s = ndof_settings_from_values({}, SCENE)
    file_model = load_model(SCENE)
    assert isinstance(s, NdofSettings) and s.model.delta_d == file_model.delta_d == -1e-5
    assert s.params.period == file_model.period        # the bounds on times read T
    s2 = ndof_settings_from_values({"delta_d": -3e-6, "max_periods": 7}, SCENE)
    assert s2.model.delta_d == -3e-6 and s2.max_periods == 7
    assert (s2.model.K == file_model.K).all() and s2.model.omega == file_model.omega
    # the node passes every value of the table: defaults are accepted
    s3 = ndof_settings_from_values({**default_values(), "delta_d": -1e-5}, SCENE)
    assert s3.model.delta_d == -1e-5 and s3.mode == "lockstep"
    assert "n=2" in s3.describe() and "delta_d=-1e-05" in s3.describe()


def test_times_are_bounded_by_the_n_dof_period():
    T = load_model(SCENE).period                        # 22.8, the study's is 9.4
    assert ndof_settings_from_values({"actuation_delay": 20.0}, SCENE).actuation_delay == 20.0
    with pytest.raises(ParameterError, match=rf"actuation_delay=23.0 is invalid.*T = {T!r}"):
        ndof_settings_from_values({"actuation_delay": 23.0}, SCENE)


@pytest.mark.parametrize("name", sorted(UNSUPPORTED))
def test_options_not_built_for_n_dof_are_refused_by_name(name):
    default = default_values()[name]
    bad = {float: 0.5, bool: (not default) if isinstance(default, bool) else None,
           str: "zdm2"}[type(default)]
    if name in ("r", "zeta"):
        bad = 0.3
    with pytest.raises(ParameterError, match=rf"^{name}=.* is invalid with model_file=.*"
                                             r"valid is its default"):
        ndof_settings_from_values({name: bad}, SCENE)


def test_bad_values_keep_the_one_dof_messages():
    for values, text in [({"mode": "fast"}, "mode='fast' is invalid"),
                         ({"time_scale": 0.0}, "time_scale"),
                         ({"max_periods": -1}, "max_periods=-1"),
                         ({"delta_d": math.inf}, "delta_d=inf is invalid"),
                         ({"loss": 2.0}, "loss=2.0")]:
        with pytest.raises(ParameterError, match=re.escape(text)):
            ndof_settings_from_values(values, SCENE)


def test_a_bad_model_file_is_one_line_naming_model_file(tmp_path):
    missing = tmp_path / "none.yaml"
    with pytest.raises(ParameterError, match=r"^model_file='.*none.yaml' is invalid: cannot "
                                             r"read it .*no such file"):
        ndof_settings_from_values({}, str(missing))
    broken = tmp_path / "broken.yaml"
    broken.write_text("M: [[1.0, 0.0], [0.0\n")
    with pytest.raises(ParameterError, match=r"^model_file=.*broken.yaml' is invalid: cannot "
                                             r"read it as a model YAML file"):
        ndof_settings_from_values({}, str(broken))
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(Path(SCENE).read_text().replace("r: 0.68", "r: 1.5"))
    with pytest.raises(ParameterError, match=r"^model_file=.*wrong.yaml' is invalid: r=1.5 "
                                             r"is invalid: valid range is 0 < r <= 1"):
        ndof_settings_from_values({}, str(wrong))
    for err in (missing, broken, wrong):
        try:
            ndof_settings_from_values({}, str(err))
        except ParameterError as exc:
            assert "\n" not in str(exc)

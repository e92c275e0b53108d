"""Which stop the data support (dynamics/identification/stop.py): on the Pi2 samples of
scenes run by the simulator's engine (the same numbers sim_node publishes), a compliant
stop's stiffness and damping (and friction) are recovered within 3 standard errors and
that model is preferred by BIC; on a rigid scene the rigid wall is (issue 31 part 4,
docs/theory_contact.md section 17)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.dynamics.identification.stop import STOPS, fit_stop, select_stop
from grazing_control.oscillator.contact import KelvinVoigt
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

PERIODS = 60


def _scene(contact, seed, stiffness=1e3, friction=0.0, noise=1e-4):
    """PERIODS uncontrolled periods from (0.3, -0.2) off X** at Delta d = -0.05 (contacts
    of every size), velocity noise ``noise`` at each sample: (p, samples, corrections,
    the stop)."""
    values = {"delta_d": -0.05, "noise": noise, "seed": seed, "state_period": 0.0}
    if contact != "rigid":
        law = KelvinVoigt.from_restitution(stiffness, 0.68)
        values.update(contact=contact, contact_stiffness=law.stiffness,
                      contact_damping=law.damping, friction=friction)
    s = settings_from_values(values)
    eng = Engine(s)
    eng.dx, eng.dv = 0.3, -0.2
    z = []
    for _ in range(PERIODS):
        z.append((eng.dx, eng.dv))
        eng.begin_period(0.0)
        eng.end_period()
    return s.params, np.array(z), np.zeros(PERIODS), s.contact


def _within(fit, name, true, n_se=3.0):
    value, se = fit.values[name], fit.stderr[name]
    assert math.isfinite(se) and se > 0.0 and abs(value - true) <= n_se * se, (
        name, value, se, true)


@pytest.mark.timeout(300)  # a hang guard
def test_a_compliant_scene_is_recovered_and_preferred():
    p, z, dv, contact = _scene("kelvin_voigt", 1)
    best, fit, fits = select_stop(p, z, dv, stops=("rigid", "kelvin_voigt"))
    assert best == "kelvin_voigt", fits
    _within(fit, "stiffness", contact.law.stiffness)
    _within(fit, "damping", contact.law.damping)
    assert fit.stderr["stiffness"] < 0.01 * contact.law.stiffness


@pytest.mark.timeout(300)
def test_friction_is_recovered_and_preferred():
    p, z, dv, contact = _scene("kelvin_voigt", 3, friction=0.01)
    best, fit, fits = select_stop(p, z, dv)
    assert best == "kelvin_voigt_friction", fits
    _within(fit, "stiffness", contact.law.stiffness)
    _within(fit, "damping", contact.law.damping)
    _within(fit, "friction", 0.01)
    # the frictionless stop fitted to the same data is biased well beyond its errors
    kv = next(f for f in fits if f.stop == "kelvin_voigt")
    assert abs(kv.values["stiffness"] - 1e3) > 3 * kv.stderr["stiffness"]


@pytest.mark.timeout(300)
def test_a_rigid_scene_prefers_the_rigid_wall():
    p, z, dv, _ = _scene("rigid", 4)
    best, fit, fits = select_stop(p, z, dv, stops=("rigid", "kelvin_voigt"))
    assert best == "rigid", fits
    _within(fit, "r", p.r)
    bics = {f.stop: f.bic for f in fits}
    assert bics["kelvin_voigt"] - bics["rigid"] > 10.0, bics


def test_bad_input_is_named():
    p, z, dv, _ = _scene("rigid", 0)
    with pytest.raises(ParameterError, match="stop="):
        fit_stop(p, "rubber", z, dv)
    with pytest.raises(ParameterError, match="samples"):
        fit_stop(p, "rigid", z[:3], dv[:3])
    assert STOPS[0] == "rigid"


# ======================================================================= bags
@pytest.mark.timeout(600)  # a hang guard: a node scene, then three fits
def test_grazing_identify_stop_on_a_compliant_bag_and_on_a_rigid_bag(tmp_path, capsys):
    """``grazing identify --stop``: a scene recorded through the nodes with a Kelvin-Voigt
    stop (k_c = 1e3, r = 0.68 by C3; 60 uncontrolled periods from (0.3, -0.2) off X**,
    velocity noise 1e-4) gives back k_c and c_c within 3 standard errors and prefers
    kelvin_voigt; the repository's rigid bag (bags/scene_5e-6, its first 40 samples)
    prefers rigid; a bag without a parameter record is bad input (status 2)."""
    import json

    pytest.importorskip("grazing_control.ros.recorder_node")
    from grazing_control.cli.commands import main
    from grazing_control.ros import launcher
    from test_closed_loop import CONTROLLER, STUDY, new_domain

    p = OscillatorParams(delta_d=-0.05)
    law = KelvinVoigt.from_restitution(1e3, p.r)
    x0, v0 = p.x_ref + 0.3, p.v_ref - 0.2
    bag = tmp_path / "bag"
    res = launcher.run(STUDY, CONTROLLER, bag, PERIODS, domain_id=new_domain(), timeout=120,
                       sim_overrides={"delta_d": p.delta_d, "x0": x0, "v0": v0,
                                      "noise": 1e-4, "seed": 5, "state_period": 0.0,
                                      "contact": "kelvin_voigt",
                                      "contact_stiffness": law.stiffness,
                                      "contact_damping": law.damping},
                       controller_overrides={"enable_after": 10 * PERIODS},
                       log_dir=tmp_path / "logs")
    assert res.ok, res
    assert main(["identify", "--stop", "--json", str(bag)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["chosen"] == "kelvin_voigt" and report["samples"] == PERIODS, report
    fit = next(c for c in report["candidates"] if c["stop"] == "kelvin_voigt")["parameters"]
    for name, true in (("stiffness", law.stiffness), ("damping", law.damping)):
        assert abs(fit[name]["value"] - true) <= 3 * fit[name]["stderr"], (name, fit, true)
    assert report["recorded"]["contact"] == "kelvin_voigt"

    assert main(["identify", "--stop", "--json", "--max-samples", "40",
                 "bags/scene_5e-6"]) == 0
    rigid = json.loads(capsys.readouterr().out)
    assert rigid["chosen"] == "rigid" and rigid["samples"] == 40, rigid

    empty = tmp_path / "empty.mcap"
    from mcap_ros2.writer import Writer
    with open(empty, "wb") as f:
        Writer(f).finish()
    assert main(["identify", "--stop", str(empty)]) == 2
    assert "parameter record" in capsys.readouterr().err

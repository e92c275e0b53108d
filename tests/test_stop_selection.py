"""Which stop the data support (dynamics/identification/stop.py): on the Pi2 samples of
scenes run by the simulator's engine (the same numbers sim_node publishes), a compliant
stop's stiffness and damping (and friction) are recovered within 3 standard errors and
that model is preferred by BIC; on a rigid scene the rigid wall is (issue 31 part 4,
docs/theory_contact.md section 17) - with the oscillator's parameters (zeta, omega, the
forcing's amplitude and phase, Delta d) fitted jointly, from a start well off them."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from grazing_control.dynamics.identification.stop import (OSCILLATOR_NAMES, STOPS, fit_stop,
                                                          select_stop)
from grazing_control.oscillator.contact import KelvinVoigt
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

PERIODS = 60
#: seeded synthetic records for the differential check at the end (0: skipped; set, the
#: friction test fits the oscillator too); a case costs about 20 s on the 2-core machine,
#: 100-250 s when it is loaded, so the suite runs the scenes below
STOP_CASES = int(os.environ.get("GRAZING_STOP_CASES", "0"))
#: the seeded starts' distance from the truth, in units of :func:`_off`'s
START_SCALE = float(os.environ.get("GRAZING_STOP_START", "0.2"))


def _scene(contact, seed, stiffness=1e3, friction=0.0, noise=1e-4, periods=PERIODS,
           restitution=0.68, **model):
    """``periods`` uncontrolled periods from (0.3, -0.2) off X** at Delta d = -0.05
    (contacts of every size; ``model``: other model values), velocity noise ``noise`` at
    each sample: (p, samples, corrections, the stop)."""
    values = {"delta_d": -0.05, "noise": noise, "seed": seed, "state_period": 0.0, **model}
    if contact != "rigid":
        law = KelvinVoigt.from_restitution(stiffness, restitution)
        values.update(contact=contact, contact_stiffness=law.stiffness,
                      contact_damping=law.damping, friction=friction)
    s = settings_from_values(values)
    eng = Engine(s)
    eng.dx, eng.dv = 0.3, -0.2
    z = []
    for _ in range(periods):
        z.append((eng.dx, eng.dv))
        eng.begin_period(0.0)
        eng.end_period()
    return s.params, np.array(z), np.zeros(periods), s.contact


def _within(fit, name, true, n_se=3.0):
    value, se = fit.values[name], fit.stderr[name]
    assert math.isfinite(se) and se > 0.0 and abs(value - true) <= n_se * se, (
        name, value, se, true)


def _off(p, rng=None, scale=1.0):
    """A start for the oscillator's fit well off ``p`` (OSCILLATOR_NAMES order): zeta
    x1.5, omega +1 %, the forcing's amplitude +3 % and phase +0.02 rad, Delta d x1.2;
    with ``rng`` a random start within ``scale`` times those bounds."""
    u = np.ones(5) if rng is None else scale * rng.uniform(-1.0, 1.0, 5)
    return [p.zeta * (1.0 + 0.5 * u[0]), p.omega * (1.0 + 0.01 * u[1]), 1.0 + 0.03 * u[2],
            0.02 * u[3], p.delta_d * (1.0 + 0.2 * u[4])]


def _oscillator_within(fit, p, n_se=3.0):
    """The jointly fitted oscillator within n_se standard errors of the truth."""
    for name, true in zip(OSCILLATOR_NAMES, (p.zeta, p.omega, 1.0, 0.0, p.delta_d)):
        _within(fit, name, true, n_se)


@pytest.mark.timeout(300)  # a hang guard
def test_a_compliant_scene_is_recovered_and_preferred():
    """Jointly with the oscillator from a start off it (module docstring); the stop alone
    at the known oscillator agrees, with smaller errors (the oscillator's uncertainty is
    not in them)."""
    p, z, dv, contact = _scene("kelvin_voigt", 1)
    best, fit, fits = select_stop(p, z, dv, stops=("rigid", "kelvin_voigt"),
                                  start_oscillator=_off(p))
    assert best == "kelvin_voigt", fits
    _within(fit, "stiffness", contact.law.stiffness)
    _within(fit, "damping", contact.law.damping)
    _oscillator_within(fit, p)
    assert fit.stderr["stiffness"] < 0.01 * contact.law.stiffness
    known = fit_stop(p, "kelvin_voigt", z, dv, oscillator="known")
    assert set(known.values) == {"stiffness", "damping"}
    _within(known, "stiffness", contact.law.stiffness)
    assert known.stderr["stiffness"] < fit.stderr["stiffness"]


@pytest.mark.timeout(300)
def test_friction_is_recovered_and_preferred():
    """With the oscillator known in the suite; fitted jointly (from :func:`_off`) where
    GRAZING_STOP_CASES is set: the joint friction fit took 245 s on the loaded 2-core
    machine (docs/theory_contact.md section 17)."""
    p, z, dv, contact = _scene("kelvin_voigt", 3, friction=0.01)
    joint = STOP_CASES > 0
    best, fit, fits = select_stop(p, z, dv, oscillator="fit" if joint else "known",
                                  start_oscillator=_off(p) if joint else None)
    assert best == "kelvin_voigt_friction", fits
    _within(fit, "stiffness", contact.law.stiffness)
    _within(fit, "damping", contact.law.damping)
    _within(fit, "friction", 0.01)
    if joint:
        _oscillator_within(fit, p)
    # the frictionless stop fitted to the same data is biased well beyond its errors
    kv = next(f for f in fits if f.stop == "kelvin_voigt")
    assert abs(kv.values["stiffness"] - 1e3) > 3 * kv.stderr["stiffness"]


@pytest.mark.timeout(300)
def test_a_rigid_scene_prefers_the_rigid_wall():
    p, z, dv, _ = _scene("rigid", 4)
    best, fit, fits = select_stop(p, z, dv, stops=("rigid", "kelvin_voigt"),
                                  start_oscillator=_off(p))
    assert best == "rigid", fits
    _within(fit, "r", p.r)
    _oscillator_within(fit, p)
    bics = {f.stop: f.bic for f in fits}
    # measured 7.2 with the oscillator fitted with each stop (270.5 with it known: at
    # the bound k_c = 1e8 the compliant period is ~1e-4 off the rigid one, which the
    # fitted oscillator absorbs): the stiffest compliant stop does not pay for its
    # extra parameter (log N = 4.8)
    assert bics["kelvin_voigt"] - bics["rigid"] > 5.0, bics


def test_bad_input_is_named():
    p, z, dv, _ = _scene("rigid", 0)
    with pytest.raises(ParameterError, match="stop="):
        fit_stop(p, "rubber", z, dv)
    with pytest.raises(ParameterError, match="samples"):
        fit_stop(p, "rigid", z[:3], dv[:3])
    with pytest.raises(ParameterError, match="oscillator="):
        fit_stop(p, "rigid", z, dv, oscillator="guessed")
    assert STOPS[0] == "rigid"


# ======================================================================= bags
@pytest.mark.timeout(900)  # a hang guard: a node scene, then five joint fits
def test_grazing_identify_stop_on_a_compliant_bag_and_on_a_rigid_bag(tmp_path, capsys):
    """``grazing run --stop auto`` then ``grazing identify --stop``: a scene run through
    the nodes with a Kelvin-Voigt stop (k_c = 1e3, r = 0.68 by C3; 60 uncontrolled
    periods from (0.3, -0.2) off X**, velocity noise 1e-4) runs on the compliant model
    (the rigid one's bound is far over the tolerance), says so in its summary and its
    bag, and the bag gives back k_c and c_c within 3 standard errors with the
    oscillator fitted jointly (its zeta, omega, Delta d within 3 standard errors too),
    preferring kelvin_voigt; the repository's rigid bag (bags/scene_5e-6, its first 24
    samples) prefers rigid; a bag without a parameter record is bad input (status 2)."""
    import json

    pytest.importorskip("grazing_control.ros.recorder_node")
    from grazing_control.cli.commands import main
    from test_closed_loop import CONTROLLER, STUDY, new_domain

    p = OscillatorParams(delta_d=-0.05)
    law = KelvinVoigt.from_restitution(1e3, p.r)
    x0, v0 = p.x_ref + 0.3, p.v_ref - 0.2
    bag = tmp_path / "bag"
    sim = {"x0": x0, "v0": v0, "noise": 1e-4, "seed": 5, "state_period": 0.0,
           "contact": "kelvin_voigt", "contact_stiffness": law.stiffness,
           "contact_damping": law.damping}
    argv = ["run", "--sim-params", str(STUDY), "--controller-params", str(CONTROLLER),
            "--bag", str(bag), "--periods", str(PERIODS), "--delta-d", repr(p.delta_d),
            "--domain-id", str(new_domain()), "--timeout", "120",
            "--enable-after", str(10 * PERIODS), "--log-dir", str(tmp_path / "logs"),
            "--stop", "auto", "--json"]
    for key, value in sim.items():
        argv += ["--sim-param", f"{key}:={value!r}" if isinstance(value, float)
                 else f"{key}:={value}"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["ok"] and summary["stop_model"]["stop"] == "compliant", summary
    assert summary["stop_model"]["estimates"]["rigid"]["bound"] > 1e-3
    assert json.loads((bag / "stop_model.json").read_text()) == summary["stop_model"]
    assert main(["identify", "--stop", "--json", str(bag)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["chosen"] == "kelvin_voigt" and report["samples"] == PERIODS, report
    assert report["oscillator"] == "fit"
    fit = next(c for c in report["candidates"] if c["stop"] == "kelvin_voigt")["parameters"]
    for name, true in (("stiffness", law.stiffness), ("damping", law.damping),
                       ("zeta", p.zeta), ("omega", p.omega), ("delta_d", p.delta_d)):
        assert abs(fit[name]["value"] - true) <= 3 * fit[name]["stderr"], (name, fit, true)
    assert report["recorded"]["contact"] == "kelvin_voigt"

    assert main(["identify", "--stop", "--json", "--max-samples", "24",
                 "bags/scene_5e-6"]) == 0
    rigid = json.loads(capsys.readouterr().out)
    assert rigid["chosen"] == "rigid" and rigid["samples"] == 24, rigid

    empty = tmp_path / "empty.mcap"
    from mcap_ros2.writer import Writer
    with open(empty, "wb") as f:
        Writer(f).finish()
    assert main(["identify", "--stop", str(empty)]) == 2
    assert "parameter record" in capsys.readouterr().err


# ======================================================================= differential


def _case(seed):
    """A seeded record of the core (the engine's exact flow: the truth is known exactly):
    even seeds a Kelvin-Voigt stop (k_c log-uniform in 1e2 .. 1e4, r in 0.5 .. 0.85), odd
    seeds the rigid wall; zeta in 0.005 .. 0.03, Delta d in -0.08 .. -0.03; the fit's
    start for the oscillator drawn within the bounds of :func:`_off`."""
    rng = np.random.default_rng(seed)
    model = {"zeta": rng.uniform(0.005, 0.03), "delta_d": rng.uniform(-0.08, -0.03)}
    k, r = 10.0 ** rng.uniform(2.0, 4.0), rng.uniform(0.5, 0.85)
    contact = "kelvin_voigt" if seed % 2 == 0 else "rigid"
    if contact == "rigid":
        model["r"] = r
    p, z, dv, stop = _scene(contact, seed, stiffness=k, restitution=r, **model)
    return p, z, dv, stop, _off(p, rng, START_SCALE)


@pytest.mark.skipif(STOP_CASES == 0, reason="GRAZING_STOP_CASES=N runs N seeded cases")
@pytest.mark.timeout(0)
def test_the_joint_fit_over_seeded_records():
    """The cases prefer their own stop, and the compliant ones give k_c and c_c within 3
    standard errors, each in at least 95 % of the cases: a 3-standard-error interval
    holds 99.7 % where the errors are right (two of them: about 0.5 % misses), and BIC
    takes a rigid record for the stiffest compliant stop (k_c at its bound, the
    oscillator absorbing the rest: nearly nested, one parameter more) where chi2_1
    exceeds log N = 4.8, about 3 % of the rigid cases (docs/theory_contact.md
    section 17)."""
    wrong, missed, compliant = [], [], 0
    for seed in range(STOP_CASES):
        p, z, dv, stop, start = _case(seed)
        best, fit, fits = select_stop(p, z, dv, stops=("rigid", "kelvin_voigt"),
                                      start_oscillator=start)
        truth = "rigid" if stop is None else "kelvin_voigt"
        if best != truth:
            wrong.append((seed, best, [(f.stop, f.bic) for f in fits]))
            continue
        if stop is not None:
            compliant += 1
            for name, true in (("stiffness", stop.law.stiffness), ("damping", stop.law.damping)):
                if not abs(fit.values[name] - true) <= 3.0 * fit.stderr[name]:
                    missed.append((seed, name, fit.values[name], fit.stderr[name], true))
    print(f"{STOP_CASES} cases: {len(wrong)} chose the wrong stop, {len(missed)} of "
          f"{compliant} compliant fits missed by more than 3 standard errors")
    assert len(wrong) <= 0.05 * STOP_CASES, wrong
    assert len(missed) <= 0.05 * max(compliant, 1), missed

"""The simulator's compliant stop (plant/contact_plant.py, sim_node's contact parameters):
the engine runs the core's compliant period map, its stream states are that flow, and a
bad contact parameter is one clear line naming it (issue 31, docs/nodes.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.dynamics.compliant_model import CompliantOneDOF
from grazing_control.dynamics.design import degenerate_c1
from grazing_control.dynamics.shooting import iterate
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, advance_compliant
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.hertz import HuntCrossley
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

#: the failing set of docs/theory_contact.md section 15 at a stiffness above the boundary
SCENE = dict(delta_d=-0.05, contact="kelvin_voigt", friction=0.01, friction_static=0.012)


def _settings(k, **kw):
    p = OscillatorParams(delta_d=-0.05)
    law = KelvinVoigt.from_restitution(k, p.r)
    return settings_from_values({**SCENE, "contact_stiffness": law.stiffness,
                                 "contact_damping": law.damping, "state_period": 0.5, **kw})


def test_engine_runs_the_compliant_period_map_with_its_corrections():
    """Ten periods of the engine under the rigid design's corrections (c2 = -1.5) equal
    CompliantOneDOF's map (the model the chart's multipliers are of) period by period, to
    rounding, and the contacts are published as impacts."""
    s = _settings(1e4)
    p = s.params
    gains = Gains(degenerate_c1(p, -1.5), -1.5)
    model = CompliantOneDOF(p, gains, law=s.contact.law, friction=s.contact.friction)
    eng = Engine(s)
    z = np.array([eng.dx, eng.dv])
    impacts = 0
    for _ in range(10):
        dvc = gains.c1 * eng.dx + gains.c2 * eng.dv
        events = eng.begin_period(dvc)
        impacts += sum(e.kind == "impact" for e in events)
        eng.end_period()
        z, _, _ = iterate(model, z)
        assert (eng.dx, eng.dv) == pytest.approx(tuple(z), abs=1e-12)
    assert impacts >= 5


def test_stream_states_are_the_compliant_flow():
    """The oscillator/state samples of a period are advance_compliant from its start."""
    s = _settings(1e2, state_period=0.25)
    eng = Engine(s)
    p = s.params
    x0, v0 = p.x_ref + eng.dx, p.v_ref + eng.dv
    events = eng.begin_period(0.0)
    for e in [e for e in events if e.kind == "state"][:8]:
        ref = advance_compliant(p, s.contact.law, p.tau2, x0, v0, e.t,
                                friction=s.contact.friction)
        assert (e.x, e.v) == pytest.approx((ref.x, ref.v), abs=1e-11)


def test_hertz_and_rigid_values():
    s = settings_from_values({"delta_d": -0.01, "contact": "hertz", "contact_stiffness": 1e4,
                              "contact_damping": 0.5})
    assert s.contact.law == HuntCrossley(1e4, 0.5) and s.contact.friction is None
    assert settings_from_values({"delta_d": -0.01}).contact is None
    kv = _settings(1e3, friction_static=0.0)
    assert kv.contact.friction == Coulomb(0.01, 0.01)


@pytest.mark.parametrize("bad, name", [
    (dict(contact="rubber"), "contact="),
    (dict(contact_stiffness=0.0), "contact_stiffness="),
    (dict(contact_stiffness=math.inf), "contact_stiffness="),
    (dict(contact_damping=-1.0), "contact_damping="),
    (dict(contact_damping=1e3), "contact_damping="),
    (dict(friction=-0.1), "friction="),
    (dict(friction_static=0.005), "friction_static="),
    (dict(contact="rigid"), "friction="),
    (dict(contact="hertz"), "friction="),
    (dict(mode="realtime"), "mode="),
    (dict(actuation_delay=0.5), "actuation_delay="),
    (dict(fidelity="zdm2"), "fidelity="),
    (dict(delta_d_drift=1e-6), "delta_d_drift="),
])
def test_bad_contact_parameters_name_the_parameter(bad, name):
    with pytest.raises(ParameterError, match=name):
        _settings(1e3, **bad)

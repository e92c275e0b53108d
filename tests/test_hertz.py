"""The Hertz / Hunt-Crossley stop (oscillator/hertz.py) against a 20-digit mpmath reference.

docs/theory_contact.md, "Hertz accuracy": DOP853 at rtol 1e-12 agrees with the reference
to the documented tolerance of 1e-10 in the contact time and the exit state.
"""

from __future__ import annotations

import math
import random

import pytest

from grazing_control.dynamics.simulate import core_period_step
from grazing_control.oscillator.hertz import HuntCrossley, advance_hertz, hertz_period_step
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from reference_hertz import reference_contact

#: documented tolerance of the contact map at RTOL = 1e-12 (measured up to 2.1e-12 over 16)
TOL = 1e-10


@pytest.mark.parametrize("seed", range(4))
def test_one_contact_matches_the_mpmath_reference(seed):
    """Contact time, exit gap and exit velocity of one contact from the stop, seeded:
    k_c in 1e1..1e3, v0 in 1e-2..1, alpha v0 in 0.01..1.2 (up to exits with delta > 0,
    where 1 + 1.5 alpha delta' = 0 ends the contact first)."""
    rng = random.Random(seed)
    p = OscillatorParams(delta_d=-10 ** rng.uniform(-3, -0.5))
    v0 = 10 ** rng.uniform(-2, 0)
    law = HuntCrossley(10 ** rng.uniform(1, 3), rng.choice([0.01, 0.3, 1.2]) / v0)
    tau_e = rng.uniform(0, 2 * math.pi)
    seg = advance_hertz(p, law, tau_e, p.d, v0, 3.0)
    contact = seg.contacts[0]
    te, gap, vel = reference_contact(p, law, tau_e, v0)
    assert contact.duration == pytest.approx(float(te), abs=TOL)
    assert contact.v_plus == pytest.approx(float(vel), abs=TOL)
    assert contact.exit_gap == pytest.approx(float(gap), abs=TOL)


def test_a_contact_that_ends_above_the_stop_continues_in_closed_form():
    """alpha v0 = 1.2: the force's factor reaches 0 with delta > 0; the flight above the
    stop is the closed form and the mass returns below it (or to a new contact)."""
    p = OscillatorParams(delta_d=-0.1)
    law = HuntCrossley(300.0, 12.0)
    seg = advance_hertz(p, law, 1.0, p.d, 0.1, p.period)
    first = seg.contacts[0]
    assert first.exit_gap > 0.0
    assert first.v_plus == pytest.approx(-2.0 / (3.0 * law.alpha), rel=1e-12)


def test_no_contact_is_the_free_flow():
    p = OscillatorParams(delta_d=0.3)
    law = HuntCrossley(1e4, 0.5)
    for dx, dv in ((0.01, -0.02), (-0.05, 0.03)):
        seg = hertz_period_step(p, law, dx, dv)
        rigid = core_period_step(p, dx, dv)
        assert not seg.contacts and not rigid.impacts
        assert seg.x == pytest.approx(rigid.dx, abs=1e-13)
        assert seg.v == pytest.approx(rigid.dv, abs=1e-13)


def test_restitution_parameter_and_bad_values():
    law = HuntCrossley.from_restitution(1e4, 0.8, 0.5)
    assert law.alpha == pytest.approx(0.4)
    with pytest.raises(ParameterError, match="alpha"):
        HuntCrossley(1.0, -1.0)
    with pytest.raises(ParameterError, match="stiffness"):
        HuntCrossley(0.0)
    with pytest.raises(ParameterError, match="v_ref"):
        HuntCrossley.from_restitution(1.0, 0.5, 0.0)


def test_held_in_the_stop_is_bounded():
    p = OscillatorParams(delta_d=-1.2)
    seg = advance_hertz(p, HuntCrossley(1e4, 0.2), 0.0, p.d - 0.01, 0.3, 3 * p.period)
    assert 1 <= len(seg.contacts) < 200

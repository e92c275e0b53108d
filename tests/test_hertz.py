"""The Hertz / Hunt-Crossley stop (oscillator/hertz.py) against a 20-digit mpmath reference.

docs/theory_contact.md, "Hertz accuracy": DOP853 at rtol 1e-12 agrees with the reference
to the documented tolerance of 1e-10 in the contact time and the exit state.
"""

from __future__ import annotations

import math
import os
import random

import numpy as np
import pytest

from grazing_control.dynamics.simulation.simulate import core_period_step
from grazing_control.oscillator.contact import Coulomb
from grazing_control.oscillator.hertz import (HuntCrossley, advance_hertz, grazing_jump,
                                              hertz_period_step)
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from reference_contact import apex_jump, assert_matches, seeded_start
from reference_hertz import reference_advance_hertz, reference_contact

#: documented tolerance of the contact map at RTOL = 1e-12 (measured up to 2.1e-12 over 16)
TOL = 1e-10
#: documented tolerance of a full period's state (docs/theory_contact.md §7)
TOL_FLOW = 1e-10
#: seeded cases per run; HERTZ_CASES=4000 for the long run of docs/theory_contact.md
CASES = int(os.environ.get("HERTZ_CASES", "200"))
#: seeded cases with Coulomb friction; HERTZ_FRICTION_CASES=4000 for the long run (§20)
FRICTION_CASES = int(os.environ.get("HERTZ_FRICTION_CASES", "200"))
TWO_PI = 2.0 * math.pi


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


@pytest.mark.timeout(120)  # a hang guard, not a speed measurement
def test_held_in_the_stop_is_bounded():
    p = OscillatorParams(delta_d=-1.2)
    seg = advance_hertz(p, HuntCrossley(1e4, 0.2), 0.0, p.d - 0.01, 0.3, 3 * p.period)
    assert 1 <= len(seg.contacts) < 200


def _case(rng):
    """A seeded Hertz case: random states, grazing flights (free maximum 1e-9..1e-3
    either side of the stop) and deep clearances where the forcing holds the mass in the
    stop (reference_contact.seeded_start); k_c in 1e1..1e4, alpha 0 or 1e-2..10 (up to
    contacts that end above the stop)."""
    p = OscillatorParams(delta_d=-10 ** rng.uniform(-6, -0.5), zeta=rng.uniform(0.005, 0.2))
    law = HuntCrossley(10 ** rng.uniform(1, 4), rng.choice([0.0, 10 ** rng.uniform(-2, 1)]))
    kind, p, tau0, x, v = seeded_start(rng, p, held="held")
    return kind, p, law, tau0, x, v


@pytest.mark.timeout(1800)  # a hang guard (HERTZ_CASES=4000 runs about 4 min here)
@pytest.mark.parametrize("seed", range(4))
def test_hertz_matches_the_reference_over_seeded_cases(seed):
    """Full periods against the DOP853 reference at its floor (tests/reference_hertz.py,
    physical coordinates, no closed form): states to TOL_FLOW (times 1 + |x| + |v|; a
    case beyond it is compared again with the reference at a step of 0.005), contacts
    counted exactly, entry and exit times to 1e-8, over HERTZ_CASES / 4 cases per seed
    (grazing contacts, held contacts and exits above the stop included)."""
    rng = random.Random(3000 + seed)
    counted = {"random": 0, "graze": 0, "held": 0}
    long_contacts = above = 0
    for _ in range(CASES // 4):
        kind, p, law, tau0, x, v = _case(rng)
        seg = advance_hertz(p, law, tau0, x, v, p.period)
        long_contacts += assert_matches(seg, reference_advance_hertz,
                                        (p, law, tau0, x, v, p.period), TOL_FLOW, 1e-8, kind)
        above += sum(math.isfinite(c.duration) and c.exit_gap > 0.0 for c in seg.contacts)
        counted[kind] += len(seg.contacts)
    assert min(counted.values()) > 0 and long_contacts > 0 and above > 0, (counted, above)


@pytest.mark.parametrize("law", [HuntCrossley(1e2), HuntCrossley(1e3, 0.5),
                                 HuntCrossley(1e4, 2.0)])
def test_grazing_map_order_and_coefficient_match_the_exact_flow(law):
    """Eq. C9 against the flow of advance_hertz: one contact through the apex at tau*,
    Delta d = -1e-3, virtual penetration H = 1e-7..1e-5 (k_c H^{1/2} / alpha <= 1.3):
    the fitted log-log slope of |dv| within 0.02 of 2 (the rigid map's is 1/2, the
    Kelvin-Voigt stop's 1 or 3/2), the coefficient (3 pi / 8) k_c sqrt(2 / alpha) within
    1 % at the smallest H, whatever the Hunt-Crossley damping."""
    p = OscillatorParams(delta_d=-1e-3)
    heights = 10.0 ** np.arange(-7, -4.9, 0.5)

    def flow(p, tau0, x, v, duration):
        return advance_hertz(p, law, tau0, x, v, duration)
    jumps = [apex_jump(p, flow, p.tau_star, h) for h in heights]
    dvs = [-j for j, _ in jumps]
    order, coef, _ = grazing_jump(law, jumps[0][1], heights[0])
    slope = np.polyfit(np.log(heights), np.log(dvs), 1)[0]
    assert abs(slope - order) < 0.02, slope
    assert dvs[0] / heights[0] ** order == pytest.approx(coef, rel=1e-2)


# ============================================================ with Coulomb friction (§20)
def _friction_case(rng):
    """A seeded Hertz case with friction: the draws of :func:`_case` (random states,
    grazing flights, held contacts), then F_f in 1e-2..0.5 and F_s / F_f in 1..1.5."""
    kind, p, law, tau0, x, v = _case(rng)
    f_kin = 10 ** rng.uniform(-2, -0.3)
    return kind, p, law, Coulomb(f_kin, f_kin * rng.uniform(1.0, 1.5)), tau0, x, v


@pytest.mark.timeout(1800)  # a hang guard (HERTZ_FRICTION_CASES=4000: docs/theory_contact.md §20)
@pytest.mark.parametrize("seed", range(2))
def test_hertz_with_friction_matches_the_reference_over_seeded_cases(seed):
    """Hertz with Coulomb friction against the DOP853 reference with the friction written
    in (tests/reference_hertz.py: the slip's sign in the right-hand side, sticks ended on
    a grid refined by brentq, not the closed form): states to TOL_FLOW (times 1 + |x| +
    |v|; a case beyond it compared again at a step of 0.005), contacts and sticks counted
    exactly, entry, exit and stick times to 1e-8, over HERTZ_FRICTION_CASES / 2 cases a
    seed; sticks in contact and in free flight both occur."""
    from reference_contact import refined

    rng = random.Random(4000 + seed)
    counted = {"random": 0, "graze": 0, "held": 0}
    sticks = in_contact = 0
    for _ in range(FRICTION_CASES // 2):
        kind, p, law, friction, tau0, x, v = _friction_case(rng)
        seg = advance_hertz(p, law, tau0, x, v, p.period, friction=friction)
        args = (p, law, tau0, x, v, p.period)
        xr, vr, ref, ref_sticks = reference_advance_hertz(*args, friction=friction)
        tol = TOL_FLOW * (1.0 + abs(xr) + abs(vr))
        if not (abs(seg.x - xr) <= tol and abs(seg.v - vr) <= tol):
            xr, vr, ref, ref_sticks = refined(reference_advance_hertz, *args, friction=friction)
        assert abs(seg.x - xr) <= tol and abs(seg.v - vr) <= tol, (kind, seg, xr, vr)
        assert len(seg.contacts) == len(ref), (kind, seg.contacts, ref)
        for c, (t_in, t_out) in zip(seg.contacts, ref):
            assert abs(c.dt - t_in) <= 1e-8, (kind, c, t_in)
            assert (math.isinf(c.duration) if math.isinf(t_out)
                    else abs(c.dt + c.duration - t_out) <= 1e-8), (kind, c, t_out)
        assert len(seg.sticks) == len(ref_sticks), (kind, seg.sticks, ref_sticks)
        for (a, b), (ar, br) in zip(seg.sticks, ref_sticks):
            assert a == pytest.approx(ar, abs=1e-8)
            assert b == pytest.approx(br, abs=1e-8) if math.isfinite(br) else math.isinf(b)
            in_contact += any(c.dt <= a <= c.dt + c.duration for c in seg.contacts)
        sticks += len(seg.sticks)
        counted[kind] += len(seg.contacts)
    assert min(counted.values()) > 0 and sticks > 10 and 0 < in_contact < sticks, (
        counted, sticks, in_contact)


@pytest.mark.timeout(120)  # a hang guard, not a speed measurement
@pytest.mark.parametrize("static", [0.95, 1.05])
def test_hertz_stick_slip_at_the_edge_of_sticking_never_hangs(static):
    """Static friction about the forcing's reach, the mass on a soft Hertz stop for 20
    periods (as test_contact's Kelvin-Voigt case): sticks and contacts every period,
    never a cascade, and the cap a clear error where it is set below them."""
    from grazing_control.oscillator.impact import ImpactCapError

    p = OscillatorParams(delta_d=-0.05)
    law, friction = HuntCrossley(1e3, 1.0), Coulomb(0.5, static)
    seg = advance_hertz(p, law, 0.3, p.d - 0.01, 0.2, 20 * p.period, friction=friction)
    assert 15 <= len(seg.sticks) <= 80 and 15 <= len(seg.contacts) <= 80, (
        len(seg.sticks), len(seg.contacts))
    with pytest.raises(ImpactCapError, match="max_contacts=2"):
        advance_hertz(p, law, 0.3, p.d - 0.01, 0.2, 20 * p.period, friction=friction,
                      max_contacts=2)


@pytest.mark.parametrize("law", [HuntCrossley(1e2), HuntCrossley(1e3, 0.5),
                                 HuntCrossley(1e4, 2.0)])
def test_grazing_map_with_friction_matches_the_exact_flow(law):
    """Eq. C12 against the flow of advance_hertz with Coulomb friction (F_f = 0.2,
    F_s = 0.25 below alpha = 0.80), as the frictionless case above: slope within 0.02 of
    2, the coefficient as derived within 1 % at the smallest H (the frictionless one is
    18 % away, so the check can fail)."""
    p = OscillatorParams(delta_d=-1e-3)
    heights = 10.0 ** np.arange(-7, -4.9, 0.5)
    friction = Coulomb(0.2, 0.25)

    def flow(p, tau0, x, v, duration):
        return advance_hertz(p, law, tau0, x, v, duration, friction=friction)
    jumps = [apex_jump(p, flow, p.tau_star, h, friction.kinetic) for h in heights]
    dvs = [-j for j, _ in jumps]
    order, coef, _ = grazing_jump(law, jumps[0][1], heights[0], friction=friction)
    slope = np.polyfit(np.log(heights), np.log(dvs), 1)[0]
    assert abs(slope - order) < 0.02, slope
    assert dvs[0] / heights[0] ** order == pytest.approx(coef, rel=1e-2)
    assert dvs[0] / heights[0] ** order != pytest.approx(
        grazing_jump(law, jumps[0][1], heights[0])[1], rel=0.1)
    with pytest.raises(ParameterError, match="static"):
        grazing_jump(law, 0.2, heights[0], friction=friction)

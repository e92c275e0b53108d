"""The Kelvin-Voigt stop (oscillator/contact.py) against an independent reference.

docs/theory_contact.md derives what is checked here: the restitution r(k_c, c_c) (Eq. C3),
the exact piecewise flow with its switching times, and the rigid limit k_c -> inf.
"""

from __future__ import annotations

import math
import os
import random

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from grazing_control.oscillator.contact import (MAX_FRICTION, MAX_STIFFNESS, Coulomb,
                                                KelvinVoigt, advance_compliant,
                                                compliant_period_step,
                                                kelvin_voigt_damping,
                                                grazing_jump, kelvin_voigt_restitution)
from grazing_control.oscillator.impact import ImpactCapError, advance
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.simulate import core_period_step

from reference_contact import (apex_jump, assert_matches, reference_advance, refined,
                               seeded_start)

#: seeded cases per test run; CONTACT_CASES=6000 for the long run of docs/theory_contact.md
CASES = int(os.environ.get("CONTACT_CASES", "600"))
FRICTION_CASES = int(os.environ.get("CONTACT_FRICTION_CASES", "300"))
TWO_PI = 2.0 * math.pi


@pytest.mark.parametrize("zeta_c", [0.0, 0.05, 0.2, 0.5, 0.7071, 0.9, 0.99])
def test_restitution_matches_the_integrated_free_contact(zeta_c):
    """Eq. C3 against DOP853 (rtol 1e-13) of delta'' + c delta' + k delta = 0 until the
    force k delta + c delta' returns to 0."""
    k = 37.0
    c = 2.0 * zeta_c * math.sqrt(k)

    def force(t, y):
        return k * y[0] + c * y[1]
    force.terminal, force.direction = True, -1.0
    sol = solve_ivp(lambda t, y: [y[1], -c * y[1] - k * y[0]], (0.0, 10.0), [0.0, 1.0],
                    method="DOP853", rtol=1e-13, atol=1e-15, events=force, first_step=1e-9)
    r_numeric = -sol.y_events[0][0][1]
    assert kelvin_voigt_restitution(zeta_c) == pytest.approx(r_numeric, abs=1e-11)


def test_restitution_inverse_round_trips_and_is_monotone():
    zs = np.linspace(0.0, 0.999, 200)
    rs = [kelvin_voigt_restitution(z) for z in zs]
    assert all(a > b for a, b in zip(rs, rs[1:]))
    assert rs[-1] > math.exp(-2.0)
    for r in (0.2, 0.5, 0.68, 0.9, 0.999):
        assert kelvin_voigt_restitution(kelvin_voigt_damping(r)) == pytest.approx(r, rel=1e-14)
    law = KelvinVoigt.from_restitution(1e4, 0.68)
    assert law.restitution == pytest.approx(0.68, rel=1e-14)


@pytest.mark.parametrize("bad", [dict(stiffness=0.0), dict(stiffness=-1.0),
                                 dict(stiffness=math.nan), dict(stiffness=10.0, damping=-1.0),
                                 dict(stiffness=100.0, damping=20.0)])
def test_bad_stop_names_the_parameter(bad):
    with pytest.raises(ParameterError, match=next(iter(bad)) if "damping" not in bad
                       else "damping"):
        KelvinVoigt(**bad)
    with pytest.raises(ParameterError, match="r="):
        kelvin_voigt_damping(0.1)


def _case(rng):
    """A seeded case: random states, grazing flights (penetration 1e-9..1e-3 either side
    of the stop) and deep clearances where the forcing pushes the mass into the stop."""
    p = OscillatorParams(delta_d=-10 ** rng.uniform(-6, -0.5), zeta=rng.uniform(0.005, 0.2))
    law = KelvinVoigt.from_restitution(10 ** rng.uniform(0.5, 4), rng.uniform(0.2, 1.0))
    kind, p, tau0, x, v = seeded_start(rng, p)
    return kind, p, law, tau0, x, v


@pytest.mark.timeout(1800)  # a hang guard (CONTACT_CASES=4000 runs about 5 min here)
@pytest.mark.parametrize("seed", range(4))
def test_kelvin_voigt_matches_the_reference_over_seeded_cases(seed):
    """States to 1e-12 (times 1 + |x| + |v|; a case beyond it is compared again with the
    reference at DOP853's step 0.005, docs/theory_contact.md §9), contacts counted
    exactly, entry and exit times to 1e-9, over CASES / 4 cases per seed (grazing and
    held contacts included)."""
    rng = random.Random(1000 + seed)
    counted = {"random": 0, "graze": 0, "stick": 0}
    long_contacts = 0
    for _ in range(CASES // 4):
        kind, p, law, tau0, x, v = _case(rng)
        seg = advance_compliant(p, law, tau0, x, v, p.period)
        long_contacts += assert_matches(seg, reference_advance, (p, law, tau0, x, v, p.period),
                                        1e-12, 1e-9, kind)
        counted[kind] += len(seg.contacts)
    # the cases exercise what they are meant to: contacts of every kind, and contacts
    # that last to the period's end (the mass held in the stop by the forcing)
    assert min(counted.values()) > 0 and long_contacts > 0, (counted, long_contacts)


def test_damped_contact_ends_before_the_mass_returns_to_the_stop():
    p = OscillatorParams(delta_d=-0.05)
    tau0, x, v = p.tau_star, p.d - 0.01, 0.5
    damped = advance_compliant(p, KelvinVoigt.from_restitution(1e3, 0.6), tau0, x, v, 2.0)
    elastic = advance_compliant(p, KelvinVoigt(1e3, 0.0), tau0, x, v, 2.0)
    assert damped.contacts[0].exit_gap > 1e-6
    assert damped.contacts[0].v_plus < 0.0
    assert abs(elastic.contacts[0].exit_gap) < 1e-15


def test_no_contact_is_the_free_flow():
    """Far from the stop the compliant period is the wall's exact period to rounding."""
    p = OscillatorParams(delta_d=0.3)
    law = KelvinVoigt(1e4, 1.0)
    rng = random.Random(3)
    for _ in range(50):
        dx, dv = rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)
        seg = compliant_period_step(p, law, dx, dv)
        rigid = core_period_step(p, dx, dv)
        assert not seg.contacts and not rigid.impacts
        assert seg.x == pytest.approx(rigid.dx, abs=1e-13)
        assert seg.v == pytest.approx(rigid.dv, abs=1e-13)


def test_rigid_limit_is_of_order_one_half_in_the_stiffness():
    """k_c -> inf at the restitution of Eq. C3: one period with one impact converges to
    the rigid period with that r, the error ~ k_c^(-1/2) (the contact time
    theta / Omega, docs/theory_contact.md "The rigid limit"); fitted slope -0.5 +- 0.02."""
    p = OscillatorParams(delta_d=-0.05, r=0.68)
    dx, dv = 0.01, 0.0
    rigid = advance(p, p.tau2, dx, dv, p.period)
    assert len(rigid.impacts) == 1
    ks = 10.0 ** np.arange(4, 9)
    errs = []
    for k in ks:
        seg = compliant_period_step(p, KelvinVoigt.from_restitution(k, 0.68), dx, dv)
        assert len(seg.contacts) == 1
        errs.append(math.hypot(seg.x - rigid.dx, seg.v - rigid.dv))
    slope = np.polyfit(np.log(ks), np.log(errs), 1)[0]
    assert abs(slope + 0.5) < 0.02, slope
    assert errs[-1] < 1e-3


@pytest.mark.timeout(120)  # a hang guard, not a speed measurement
def test_a_mass_held_in_the_stop_never_hangs_and_the_cap_is_a_clear_error():
    """Forcing pushes the mass into a soft stop: a finite number of contacts, the last
    lasting to the period's end (no Zeno sequence: each contact lasts about pi / Omega)."""
    p = OscillatorParams(delta_d=-1.2)
    law = KelvinVoigt.from_restitution(1e4, 0.9)
    seg = advance_compliant(p, law, 0.0, p.d - 0.01, 0.3, 5 * p.period)
    assert 1 < len(seg.contacts) < 200
    with pytest.raises(ImpactCapError, match="max_contacts=2"):
        advance_compliant(p, law, 0.0, p.d - 0.01, 0.3, 5 * p.period, max_contacts=2)


@pytest.mark.timeout(1800)  # a hang guard
@pytest.mark.parametrize("seed", range(2))
def test_friction_matches_the_reference_over_seeded_cases(seed):
    """Coulomb friction with the Kelvin-Voigt stop: states to 1e-12 (times 1 + |x| + |v|;
    a case beyond it is compared again with the reference at a step of 0.005),
    contacts and sticks counted exactly, stick ends to 1e-9."""
    rng = random.Random(2000 + seed)
    sticks = contacts = 0
    for _ in range(FRICTION_CASES // 2):
        p = OscillatorParams(delta_d=-10 ** rng.uniform(-3, 0.2), zeta=rng.uniform(0.005, 0.2))
        law = KelvinVoigt.from_restitution(10 ** rng.uniform(0.5, 4), rng.uniform(0.2, 1.0))
        f_kin = 10 ** rng.uniform(-2, -0.3)
        friction = Coulomb(f_kin, f_kin * rng.uniform(1.0, 1.5))
        tau0, x, v = rng.uniform(0, TWO_PI), p.d - rng.uniform(0, 1), rng.uniform(-1, 1)
        seg = advance_compliant(p, law, tau0, x, v, p.period, friction=friction)
        xr, vr, ref, ref_sticks = reference_advance(p, law, tau0, x, v, p.period, friction)
        tol = 1e-12 * (1.0 + abs(xr) + abs(vr))
        if not (abs(seg.x - xr) <= tol and abs(seg.v - vr) <= tol):  # the reference again,
            xr, vr, ref, ref_sticks = refined(reference_advance, p, law, tau0, x, v,  # finer
                                              p.period, friction)
        assert abs(seg.x - xr) <= tol and abs(seg.v - vr) <= tol, (seg, xr, vr)
        assert len(seg.contacts) == len(ref)
        assert len(seg.sticks) == len(ref_sticks), (seg.sticks, ref_sticks)
        for (a, b), (ar, br) in zip(seg.sticks, ref_sticks):
            assert a == pytest.approx(ar, abs=1e-9)
            assert b == pytest.approx(br, abs=1e-9) if math.isfinite(br) else math.isinf(b)
        sticks += len(seg.sticks)
        contacts += len(seg.contacts)
    assert sticks > 10 and contacts > 50, (sticks, contacts)


@pytest.mark.timeout(120)  # a hang guard, not a speed measurement
@pytest.mark.parametrize("static", [0.95, 1.05])
def test_stick_slip_at_the_edge_of_sticking_never_hangs(static):
    """Static friction near the forcing's reach (F_s about the amplitude of G), the mass
    on a soft stop over 20 periods: a stick and a contact every period (20-22 of each),
    never more than 4 a period (every stick ends at a closed-form release, every slip at
    a zero of x' of a closed-form flow, docs/theory_contact.md §6), and the cap a clear
    error where it is set below them."""
    p = OscillatorParams(delta_d=-0.05)
    law = KelvinVoigt(1e3, 1.0)
    friction = Coulomb(0.5, static)
    seg = advance_compliant(p, law, 0.3, p.d - 0.01, 0.2, 20 * p.period, friction=friction)
    assert 10 <= len(seg.sticks) <= 4 * 20 and len(seg.contacts) <= 4 * 20, (
        len(seg.sticks), len(seg.contacts))
    with pytest.raises(ImpactCapError, match="max_contacts=0"):
        advance_compliant(p, law, 0.3, p.d - 0.01, 0.2, 20 * p.period, friction=friction,
                          max_contacts=0)


def test_zero_friction_is_the_frictionless_flow():
    """Coulomb(0.0) is a valid law and means no friction: the period equals the
    frictionless one (it stuck the mass at its first x' = 0, where |G| <= F_s = 0 was
    read as a stick, and held it there until cos tau came back to G = 0)."""
    p = OscillatorParams(delta_d=-1e-2)
    law = KelvinVoigt.from_restitution(1e4, p.r)
    bare = compliant_period_step(p, law, 0.01, 0.01)
    zero = compliant_period_step(p, law, 0.01, 0.01, friction=Coulomb(0.0))
    assert len(zero.contacts) == len(bare.contacts) == 1 and zero.sticks == ()
    assert zero.x == pytest.approx(bare.x, abs=1e-15) and zero.v == pytest.approx(bare.v, abs=1e-15)


def test_bad_friction_names_the_parameter():
    with pytest.raises(ParameterError, match="^friction="):
        Coulomb(-0.1)
    with pytest.raises(ParameterError, match="^friction_static="):
        Coulomb(0.2, 0.1)


@pytest.mark.timeout(60)
def test_a_stop_or_a_friction_beyond_its_range_is_refused_and_the_range_ends_run():
    """Friction 1e308 poisoned the certified search with non-finite values and
    `grazing simulate --friction 1e308` never returned (found by hand); stiffness 1e308
    overflowed. Both are one ParameterError naming the value and its range; the range
    ends themselves run a period (friction: sticks, stiffness: one contact)."""
    from grazing_control.oscillator.hertz import HuntCrossley

    for make, text in ((lambda: KelvinVoigt(1e308), "stiffness"),
                       (lambda: KelvinVoigt.from_restitution(MAX_STIFFNESS * 10, 0.68),
                        "stiffness"),
                       (lambda: HuntCrossley(1e308), "stiffness"),
                       (lambda: Coulomb(1e308), "friction"),
                       (lambda: Coulomb(0.1, 1e308), "friction_static")):
        with pytest.raises(ParameterError, match=text + r".*valid range is.*1e\+(18|06)"):
            make()
    p = OscillatorParams(delta_d=-0.05)
    seg = advance_compliant(p, KelvinVoigt(1e3, 1.0), 0.0, 0.0, 0.1, p.period,
                            friction=Coulomb(MAX_FRICTION))
    assert len(seg.sticks) == 1 and seg.v == 0.0
    stiff = compliant_period_step(p, KelvinVoigt.from_restitution(MAX_STIFFNESS, p.r),
                                  0.01, 0.01)
    assert math.isfinite(stiff.x) and math.isfinite(stiff.v)


def test_friction_above_the_forcing_sticks_for_ever():
    """F_s larger than every force at rest: the mass stops once and stays (one stick to
    the end), found without a search."""
    p = OscillatorParams(delta_d=-0.05)
    seg = advance_compliant(p, KelvinVoigt(1e3, 1.0), 0.0, 0.0, 0.1, 3 * p.period,
                            friction=Coulomb(5.0))
    assert len(seg.sticks) == 1 and math.isinf(seg.sticks[0][1]) and seg.v == 0.0


@pytest.mark.parametrize("law, heights", [
    (KelvinVoigt(10.0, 0.0), 10.0 ** np.arange(-8, -3.9, 0.5)),
    (KelvinVoigt(100.0, 2.0), 10.0 ** np.arange(-11, -5.9, 0.5)),
    (KelvinVoigt(1e4, 50.0), 10.0 ** np.arange(-11, -5.9, 0.5)),
])
def test_grazing_map_order_and_coefficient_match_the_exact_flow(law, heights):
    """Eq. C7 against the exact flow: the fitted log-log slope of |dv| against the virtual
    penetration H within 0.02 of the derived order (1 with damping, 3/2 without), the
    coefficient within 1 % at the smallest H."""
    p = OscillatorParams(delta_d=-1e-3)
    jumps = [apex_jump(p, _kelvin_voigt(law), p.tau_star, h) for h in heights]
    dvs = [-j for j, _ in jumps]
    order, coef, _ = grazing_jump(law, jumps[0][1], heights[0])
    slope = np.polyfit(np.log(heights), np.log(dvs), 1)[0]
    assert abs(slope - order) < 0.02, slope
    assert dvs[0] / heights[0] ** order == pytest.approx(coef, rel=1e-2)


def _kelvin_voigt(law, friction=None):
    return lambda p, tau0, x, v, duration: advance_compliant(p, law, tau0, x, v, duration,
                                                             friction=friction)


@pytest.mark.parametrize("law, heights", [
    (KelvinVoigt(10.0, 0.0), 10.0 ** np.arange(-8, -3.9, 0.5)),
    (KelvinVoigt(100.0, 2.0), 10.0 ** np.arange(-11, -5.9, 0.5)),
    (KelvinVoigt(1e4, 50.0), 10.0 ** np.arange(-11, -5.9, 0.5)),
])
def test_grazing_map_with_friction_matches_the_exact_flow(law, heights):
    """Eq. C10 against the exact flow with Coulomb friction (F_f = 0.2, F_s = 0.25 below
    alpha = 0.8: the mass slips through the apex): the order of Eq. C7 unchanged (fitted
    slope within 0.02), the coefficient scaled as derived (within 1 % at the smallest H;
    the frictionless coefficient is 10-40 % away, so the check can fail)."""
    p = OscillatorParams(delta_d=-1e-3)
    friction = Coulomb(0.2, 0.25)
    jumps = [apex_jump(p, _kelvin_voigt(law, friction), p.tau_star, h, friction.kinetic)
             for h in heights]
    dvs = [-j for j, _ in jumps]
    order, coef, _ = grazing_jump(law, jumps[0][1], heights[0], friction=friction)
    slope = np.polyfit(np.log(heights), np.log(dvs), 1)[0]
    assert abs(slope - order) < 0.02, slope
    assert dvs[0] / heights[0] ** order == pytest.approx(coef, rel=1e-2)
    assert abs(coef / grazing_jump(law, jumps[0][1], heights[0])[1] - 1.0) > 0.05
    with pytest.raises(ParameterError, match="static"):
        grazing_jump(law, 0.2, heights[0], friction=friction)

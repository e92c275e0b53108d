"""dynamics/orbits/one_one.py: the 1/1 orbit and its branch, one entry for every model
(issue 32). The 1-DOF closed form behind it gives the same floats as before the entry
(orbits.orbit_11, continuation.continue_11: compared with ==), a model file the same as
its explicit branch (modal_branch), and the n = 1 model file the 1-DOF numbers to 1e-12."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.family import gain_family
from grazing_control.dynamics.orbits import modal_branch, one_one
from grazing_control.dynamics.orbits.continuation import continue_11
from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.params import OscillatorParams

ROOT = Path(__file__).resolve().parents[1]
ONE = load_model(ROOT / "config" / "models" / "study_1dof.yaml")
CHAIN = load_model(ROOT / "config" / "models" / "two_mass_chain.yaml")
P = OscillatorParams()


def _k_for_c2(c2):
    """The n = 1 family member whose k_v0 is c2 (the family is affine in mu)."""
    k0, k1 = gain_family(ONE, 0.0), gain_family(ONE, 1.0)
    return gain_family(ONE, (c2 - k0[1]) / (k1[1] - k0[1]))


def _same(a, b) -> bool:
    return np.array_equal(np.asarray(a), np.asarray(b))


#: tests/test_orbits.py's orbits on the other branches (issue 7): past a fold, and another
#: branch, not connected to grazing
FOLD = OscillatorParams(zeta=0.2, r=0.3, omega=1.5)
OTHER = (OscillatorParams(zeta=0.006638694214357835, r=0.6869943793584391,
                          omega=1.069458758465759, pi2_offset=6.178984565892156),
         -0.0009979230443342096, Gains(-9.152301501092964, -0.4013223587735988))


@pytest.mark.parametrize("base, dd, gains", [
    (P, -1e-3, None), (P, -1e-9, None), (P, -1e-3, Gains(-0.5, -0.5)),
    (P, -1e-6, Gains(-0.4, -0.5, 0.5)), (FOLD, -1e-3, None), OTHER])
def test_1dof_orbit_is_the_closed_form_bit_for_bit(base, dd, gains):
    """Every number the entry returns for the 1-DOF oscillator is orbits.orbit_11's float
    (the certified closed form behind it), whatever the branch (past a fold, other)."""
    p = base.with_(delta_d=dd)
    ref = orbit_11(p, gains)
    got = one_one.orbit(p, gains)
    assert got.delta_d == ref.params.delta_d
    assert _same(got.state, ref.pi2_deviation) and _same(got.physical, ref.pi2)
    assert _same(got.multipliers, ref.multipliers) and _same(got.monodromy, ref.monodromy)
    assert (got.v_minus, got.impact_phase, got.impact_dt) == \
        (ref.v_minus, ref.impact_phase, ref.impacts[0].dt)
    assert got.branch == ref.branch and got.route == one_one.CLOSED_FORM
    assert got.stable == ref.stable
    assert got.near_grazing == (ref.branch != "other")
    # delta_d given to the entry, and the delay given apart from the gains
    assert _same(one_one.orbit(base, gains, dd).state, ref.pi2_deviation)
    assert ref.branch == {FOLD: "grazing past a fold", OTHER[0]: "other"}.get(base, "grazing")
    if gains is not None and gains.delay:
        apart = one_one.orbit(p, Gains(gains.c1, gains.c2), delay=gains.delay)
        assert _same(apart.multipliers, ref.multipliers)


def test_1dof_branch_is_the_closed_form_bit_for_bit():
    """The branch over the command's grid: continue_11's points and bifurcations, the
    same floats; the Pi2 deviation of each point is the closed form's orbit there."""
    gains = Gains(-0.5, -0.5)
    for start, stop, n in ((-1e-2, 0.0, 12), (-1e-2, -1e-8, 9)):
        values = one_one.continuation_values(start, stop, n)
        ref = continue_11(P, start, stop, gains, points=n, check=True, values=values)
        got = one_one.branch(P, gains, start, stop, n)
        assert got.route == "impact phase" and got.stopped == "end" and got.fold is None
        assert len(got.points) == len(ref.points) == n
        for a, b in zip(got.points, ref.points):
            assert (a.value, a.v_min, a.impacts) == (b.delta_d, b.v_minus, 1)
            assert _same(a.multipliers, b.multipliers) and a.stable == b.stable
            orbit = orbit_11(P.with_(delta_d=b.delta_d), gains)
            assert np.allclose(a.state, orbit.pi2_deviation, rtol=1e-9, atol=0.0)
        assert [(x.type, x.value) for x in got.bifurcations] == \
            [(x.type, x.delta_d) for x in ref.bifurcations]
        assert all(_same(x.multipliers, y.multipliers)
                   for x, y in zip(got.bifurcations, ref.bifurcations))
        # c1 = c2 = -0.5: a period doubling near Delta d = -2.8e-5 on both grids
        assert "period-doubling" in [x.type for x in got.bifurcations]
    assert [b.type for b in one_one.branch(P, gains, -1e-2, 0.0, 5).bifurcations][-1] == "grazing"


def test_model_file_orbit_and_branch_are_the_explicit_branch():
    """A model file (the 2-mass chain): the orbit of the entry is modal_branch's orbit at
    Delta d (the same Pi2 state and multipliers), found on the branch explicit in psi;
    its branch is continue_branch's at the command's grid."""
    k = np.asarray(gain_family(CHAIN, 0.2), dtype=float)
    for dd in (-1e-3, -1e-8):
        m = dataclasses.replace(CHAIN, delta_d=dd)
        got = one_one.orbit(m, k)
        bp = modal_branch.orbit_at(m, k, dd)
        assert got.route == one_one.EXPLICIT and got.branch == "grazing" and got.near_grazing
        assert _same(got.state, bp.pi2_state) and got.v_minus == bp.v_minus
        assert _same(got.multipliers, modal_branch.branch_multipliers(m, k, bp))
        assert got.delta_d == dd and got.physical.shape == (4,)
    values = one_one.continuation_values(-1e-3, -1e-9, 8)
    ref = modal_branch.continue_branch(dataclasses.replace(CHAIN, delta_d=-1e-3), k, values)
    got = one_one.branch(CHAIN, k, -1e-3, -1e-9, 8)
    assert got.route == "impact phase" and got.first.route == one_one.EXPLICIT
    assert [p.value for p in got.points] == [p.value for p in ref.points]
    assert all(_same(a.multipliers, b.multipliers) for a, b in zip(got.points, ref.points))
    assert got.stopped == ref.stopped


@pytest.mark.parametrize("dd, c2, delay", [(-1e-3, None, 0.0), (-1e-3, -0.5, 0.0),
                                           (-1e-4, -0.5, 0.5), (-1e-2, -1.0, 0.0)])
def test_n1_model_file_gives_the_1dof_orbit_to_1e12(dd, c2, delay):
    """The same entry on the two models of the study's oscillator: the n = 1 file (modal
    flow, explicit branch in psi) against the 1-DOF closed form, to 1e-12 (relative; the
    multipliers against max(1, |lambda|max)). Measured over the four cases: the state
    1.8e-13, v- 1.8e-13, the multipliers 7.9e-14."""
    k = None if c2 is None else _k_for_c2(c2)
    g = None if c2 is None else Gains(float(k[0]), float(k[1]), delay)
    a = one_one.orbit(P.with_(delta_d=dd), g)
    b = one_one.orbit(ONE, k, dd, delay=delay)
    assert b.route == one_one.EXPLICIT and a.branch == b.branch == "grazing"
    assert np.max(np.abs(a.state - b.state)) <= 1e-12 * np.max(np.abs(a.state))
    assert np.max(np.abs(a.physical - b.physical)) <= 1e-12 * np.max(np.abs(a.physical))
    assert b.v_minus == pytest.approx(a.v_minus, rel=1e-12)
    assert b.impact_phase == pytest.approx(a.impact_phase, rel=1e-12, abs=1e-14)
    assert np.max(np.abs(a.multipliers - b.multipliers)) <= 1e-12 * max(
        1.0, float(np.max(np.abs(a.multipliers))))


def test_n1_model_file_gives_the_1dof_branch_to_1e12():
    """The branch over the same grid on both models to 1e-12. Measured: Delta d 2.0e-13,
    v- 5.8e-13, the Pi2 state 5.9e-13, the multipliers 2.6e-13."""
    k = _k_for_c2(-0.5)
    a = one_one.branch(P, Gains(float(k[0]), float(k[1])), -1e-2, -1e-6, 7)
    b = one_one.branch(ONE, k, -1e-2, -1e-6, 7)
    assert len(a.points) == len(b.points) == 7
    for x, y in zip(a.points, b.points):
        assert y.value == pytest.approx(x.value, rel=1e-12)
        assert y.v_min == pytest.approx(x.v_min, rel=1e-12)
        assert np.max(np.abs(x.state - y.state)) <= 1e-12 * np.max(np.abs(x.state))
        assert np.max(np.abs(x.multipliers - y.multipliers)) <= 1e-12


def test_an_unknown_model_is_refused_and_no_orbit_raises():
    with pytest.raises(TypeError, match="model=.* is invalid: expected OscillatorParams"):
        one_one.orbit({"zeta": 0.1})
    with pytest.raises(OrbitNotFound):
        one_one.orbit(P.with_(delta_d=1e-3))


# ------------------------------------------------------------------ the pulse (§18)
def test_model_file_pulse_orbit_and_branch_are_the_pulsed_explicit_branch():
    """``width`` > 0 (docs/theory_ndof.md §18): the entry's orbit is modal_branch's with the
    pulse's Actuation (the same floats), down to Delta d = -1e-10; its branch is
    continue_branch's, and each point is the entry's orbit at that Delta d (state 1e-12
    relative, multipliers 1e-12: two Brent solves of the same curve)."""
    from grazing_control.dynamics.design.family import Actuation

    act = Actuation(1.0, 1.0)
    k = np.asarray(gain_family(CHAIN, -0.17, act), dtype=float)
    for dd in (-1e-3, -1e-10):
        m = dataclasses.replace(CHAIN, delta_d=dd)
        got = one_one.orbit(m, k, delay=1.0, width=1.0)
        bp = modal_branch.orbit_at(m, k, dd, delay=act)
        assert got.route == one_one.EXPLICIT and got.branch == "grazing"
        assert _same(got.state, bp.pi2_state) and got.v_minus == bp.v_minus
        assert _same(got.multipliers, modal_branch.branch_multipliers(m, k, bp, act))
    got = one_one.branch(CHAIN, k, -1e-3, -1e-9, 8, delay=1.0, width=1.0)
    assert got.route == "impact phase" and got.stopped == "end" and len(got.points) == 8
    for p in got.points:
        o = one_one.orbit(CHAIN, k, p.value, delay=1.0, width=1.0)
        assert np.max(np.abs(o.state - p.state)) <= 1e-12 * np.max(np.abs(o.state))
        assert np.max(np.abs(o.multipliers - p.multipliers)) <= 1e-12


@pytest.mark.parametrize("delay, width, c2", [(0.5, 1.0, -1.0), (2.0, 1.0, 0.5)])
def test_n1_model_file_pulse_orbit_is_the_1dof_pulse_orbit(delay, width, c2):
    """The 1-DOF oscillator has the pulse's orbit only as Newton on its exact pulse map
    with a central-difference Jacobian (``simulation.actuation.pulse_orbit``, no
    command): the n = 1 file's pulsed branch equals it, the state and v- to 1e-12
    (measured 3.7e-15, 4.4e-13), the multipliers to 1e-6 (the 1-DOF differences'
    accuracy: measured 3.3e-7), for the family member with k_v0 = c2 (its k_x0 the 1-DOF
    pulse design's c1, (P1))."""
    from grazing_control.dynamics.design.family import Actuation
    from grazing_control.dynamics.simulation.actuation import pulse_orbit

    act = Actuation(delay, width)
    k0, k1 = gain_family(ONE, 0.0, act), gain_family(ONE, 1.0, act)
    k = gain_family(ONE, (c2 - k0[1]) / (k1[1] - k0[1]), act)
    for dd in (-1e-3, -1e-5):
        ref = pulse_orbit(P.with_(delta_d=dd), Gains(float(k[0]), float(k[1]), delay), width)
        got = one_one.orbit(ONE, k, dd, delay=delay, width=width)
        assert got.route == one_one.EXPLICIT
        assert np.max(np.abs(got.state - ref.pi2_deviation)) <= 1e-12 * np.max(np.abs(got.state))
        assert got.v_minus == pytest.approx(ref.v_minus, rel=1e-12)
        assert np.max(np.abs(np.sort_complex(got.multipliers) - np.sort_complex(ref.multipliers))) <= 1e-6


def test_the_1dof_closed_form_refuses_a_pulse_in_one_line():
    """The 1-DOF closed form runs the kick: a pulse width is refused naming it (the n = 1
    model file is the same oscillator with the pulse)."""
    from grazing_control.oscillator.params import ParameterError

    for call in (lambda: one_one.orbit(P.with_(delta_d=-1e-4), Gains(-0.5, -0.5), width=1.0),
                 lambda: one_one.branch(P, Gains(-0.5, -0.5), -1e-3, -1e-6, 3, width=1.0)):
        with pytest.raises(ParameterError, match="width=1.0 is invalid for the 1-DOF "
                                                 "oscillator's 1/1 orbit: .*valid: 0"):
            call()
    with pytest.raises(ParameterError, match="pulse_width=-1.0 is invalid"):
        one_one.orbit(CHAIN, gain_family(CHAIN, 0.0), -1e-4, width=-1.0)

"""Model fidelities: the normal-form maps converge at their orders, the automatic
choice meets its tolerance on the scene it chose for, and the simulator node runs them."""

import math
import random

import numpy as np
import pytest

from grazing_control.dynamics.simulation import simulate as simulate_module
from grazing_control.recordings.analysis import scene_from_bag
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.simulation.fidelity import (FIDELITIES, ZDM_WINDOW, ModelValidityError,
                                               choose_fidelity, period_step)
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate

P = OscillatorParams()
G = Gains(degenerate_c1(P, -1.0), -1.0)


def _near_orbit(delta_d):
    """A Pi2 state 1 % off the controlled 1/1 orbit, and its correction."""
    p = P.with_(delta_d=delta_d)
    z = orbit_11(p, G).pi2_deviation
    z = (1.01 * z[0], z[1])
    return p, z, G.c1 * z[0] + G.c2 * z[1]


def test_exact_fidelity_is_the_simulators_period_step():
    p, z, dvc = _near_orbit(-5e-6)
    a = period_step(p, *z, dvc, "exact")
    b = simulate_module.period_step(p, *z, dvc)
    assert (a.dx, a.dv) == (b.dx, b.dv)


@pytest.mark.parametrize("fidelity,order", [("zdm2", 1.5), ("zdm1", 1.0)])
def test_map_error_per_period_falls_at_its_order(fidelity, order):
    """Degenerate case: penetration H ~ v-^2 ~ |Delta d|, so the one-period error of the
    second-order map is O(|Delta d|^1.5) and of the leading-order map O(|Delta d|)."""
    dds = np.array([1e-4, 1e-5, 1e-6, 1e-7])
    errs = []
    for dd in dds:
        p, z, dvc = _near_orbit(-dd)
        ref = period_step(p, *z, dvc, "exact")
        got = period_step(p, *z, dvc, fidelity)
        assert len(got.impacts) == len(ref.impacts) == 1
        errs.append(max(abs(got.dx - ref.dx), abs(got.dv - ref.dv)))
    slope = np.polyfit(np.log(dds), np.log(errs), 1)[0]
    assert abs(slope - order) < 0.1, (slope, errs)


def test_ode_fidelity_agrees_with_exact_away_from_grazing():
    p = P.with_(delta_d=-0.05)
    z = orbit_11(p).pi2_deviation
    a = period_step(p, *z, 0.0, "exact")
    b = period_step(p, *z, 0.0, "ode", rtol=1e-11)
    assert len(a.impacts) == len(b.impacts) == 1
    assert max(abs(a.dx - b.dx), abs(a.dv - b.dv)) < 1e-7


@pytest.mark.parametrize("tol,expected", [(1e-6, "zdm1"), (1e-9, "zdm2"), (1e-13, "exact")])
def test_auto_picks_the_cheapest_model_that_meets_the_tolerance(tol, expected):
    p = P.with_(delta_d=-1e-7)
    z0 = (2e-5, 0.0)
    n = 300
    res = simulate(p, n, deviation=z0, gains=G, control_after=0, fidelity="auto", tol=tol)
    assert res.fidelity == expected, res.fidelity_reason
    assert expected in res.fidelity_reason and "tol" in res.fidelity_reason
    exact = simulate(p, n, deviation=z0, gains=G, control_after=0)
    # the estimate is honest on the scene it was made for
    assert np.max(np.abs(res.pi2_deviation - exact.pi2_deviation)) <= tol


def test_auto_keeps_the_exact_flow_for_a_chaotic_scene():
    p = P.with_(delta_d=-5e-6)
    choice = choose_fidelity(p, 1000, 1e-6)
    assert choice.fidelity == "exact" and choice.growth > 1.0
    assert "no model meets" in choice.reason or "exact:" in choice.reason


def test_auto_falls_back_to_exact_where_the_maps_do_not_apply_issue_7():
    """Issue 7: `grazing simulate --delta-d -1 --periods 30 --fidelity auto` failed with
    'the ZDM does not apply' (alpha < 0) where exact works; auto now chooses exact and
    says why, and gives exact's samples."""
    p = P.with_(delta_d=-1.0)
    res = simulate(p, 30, fidelity="auto")
    assert res.fidelity == "exact" and "do not apply" in res.fidelity_reason
    np.testing.assert_array_equal(res.pi2, simulate(p, 30).pi2)
    for fid in ("zdm1", "zdm2"):
        with pytest.raises(ModelValidityError, match=f"{fid} does not apply"):
            simulate(p, 30, fidelity=fid)


def test_auto_uses_exact_for_the_periods_a_chosen_map_does_not_cover():
    """A scene whose transient starts far from grazing: auto chooses a map on the probe
    near the orbit... or exact; periods outside the map's validity are computed exactly
    and counted in the reason."""
    p = P.with_(delta_d=-1e-7)
    res = simulate(p, 60, fidelity="auto", tol=1e-6, deviation=(0.0, 0.0))
    assert res.fidelity in ("zdm1", "zdm2", "exact")
    far = simulate(p, 3, fidelity="zdm1", deviation=(1e-6, 0.0))  # applies: small deviation
    assert far.fidelity == "zdm1"
    with pytest.raises(ModelValidityError, match="within .* rad of tau"):
        simulate(p, 3, fidelity="zdm1", deviation=(-0.5, 0.3))


def test_maps_refuse_states_outside_their_validity_fuzz():
    """Fuzz (seeded, 1500 cases): random parameters, Delta d from -1 to 0.1 and Pi2
    deviations from 1e-9 to 1: every zdm1/zdm2 period either refuses with
    ModelValidityError or returns a Pi2 sample on the physical side (x <= d) with at
    most one impact, at a phase within ZDM_WINDOW of tau*. (Before, hundreds of such
    sets returned samples beyond the wall with no error.)"""
    from grazing_control.oscillator.flow import gap

    rng = np.random.default_rng(5)
    refused = accepted = 0
    for _ in range(1500):
        p = OscillatorParams(zeta=10 ** rng.uniform(-3, -0.5), r=rng.uniform(0.1, 0.9),
                             omega=rng.uniform(0.3, 2.5), pi2_offset=rng.uniform(0.1, 6.2),
                             delta_d=rng.choice([-1, 1]) * 10 ** rng.uniform(-9, 0) * 0.5)
        size = 10 ** rng.uniform(-9, 0)
        dx, dv = size * rng.normal(), size * rng.normal()
        for fid in ("zdm1", "zdm2"):
            try:
                seg = period_step(p, dx, dv, 0.0, fid)
            except ModelValidityError:
                refused += 1
                continue
            accepted += 1
            assert gap(p, p.tau2, seg.dx) <= 1e-12
            assert len(seg.impacts) <= 1
            for i in seg.impacts:
                psi = (i.phase - p.tau_star + math.pi) % (2 * math.pi) - math.pi
                assert abs(psi) <= ZDM_WINDOW
    assert refused > 300 and accepted > 300


def test_bad_fidelity_arguments_are_refused():
    with pytest.raises(ValueError, match="fidelity='rk4'"):
        period_step(P, 0.0, 0.0, 0.0, "rk4")
    with pytest.raises(ValueError, match="tol="):
        choose_fidelity(P.with_(delta_d=-1e-6), 10, 0.0)
    with pytest.raises(ValueError, match="fidelity='fast'"):
        simulate(P, 3, fidelity="fast")
    assert set(FIDELITIES) == {"exact", "zdm2", "zdm1", "ode"}


def test_sim_node_runs_a_map_fidelity_in_lockstep(tmp_path):
    """sim_node with fidelity:=zdm2 reproduces simulate(fidelity='zdm2') sample for sample."""
    from grazing_control.ros.launcher import run_scene

    p = P.with_(delta_d=-1e-6)
    yaml = tmp_path / "controller.yaml"
    from grazing_control.dynamics.design.gains import write_controller_yaml

    write_controller_yaml(yaml, p, G)
    bag = tmp_path / "bag"
    run_scene(p, yaml, bag, periods=60, enable_after=30, timeout=120,   # a claimed domain
              sim_overrides={"fidelity": "zdm2"})
    scene = scene_from_bag(bag)
    core = simulate(p, 60, gains=G, control_after=30, fidelity="zdm2")
    assert np.array_equal(scene.pi2[:30], core.pi2[:30])
    assert np.max(np.abs(scene.pi2 - core.pi2)) < 1e-12
    assert math.isfinite(scene.pi2[-1, 0])

"""The compliant model on Pi2 (dynamics/maps/compliant_model.py) as a PeriodMap: its Jacobian,
the generic shooting and continuation over it, and the rigid limit of its multipliers."""

from __future__ import annotations

import random

import numpy as np
import pytest
from scipy.optimize import brentq

from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.orbits.continuation import continue_orbit
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.model import OneDOF, PeriodMap
from grazing_control.dynamics.orbits.shooting import find_periodic
from grazing_control.dynamics.design.spectral_design import least_spectral_radius, spectral_radius
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
from grazing_control.oscillator.hertz import HuntCrossley
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams


def _model(dd=-1e-3, k=1e6, c2=-1.0):
    p = OscillatorParams(delta_d=dd)
    return CompliantOneDOF(p, Gains(degenerate_c1(p, c2), c2),
                           law=KelvinVoigt.from_restitution(k, p.r))


def test_is_a_period_map_and_names_bad_parameters():
    m = _model()
    assert isinstance(m, PeriodMap)
    assert m.with_parameter("log10_stiffness", 4.0).parameter("stiffness") == pytest.approx(1e4)
    assert m.with_parameter("stiffness", 1e4).law.restitution == pytest.approx(0.68, rel=1e-12)
    with pytest.raises(ValueError, match="bogus"):
        m.parameter("bogus")
    with pytest.raises(ValueError, match="delay"):
        CompliantOneDOF(m.params, Gains(-1.0, -1.0, delay=0.1), law=m.law)
    with pytest.raises(ValueError, match="law"):
        CompliantOneDOF(m.params)


def test_jacobian_matches_central_differences():
    """Eq. C8 (flow matrices, the entry's saltation, the gain matrix) against central
    differences of the map, over seeded states with a contact."""
    rng = random.Random(7)
    for _ in range(20):
        m = _model(dd=-10 ** rng.uniform(-3, -1), k=10 ** rng.uniform(1, 7),
                   c2=rng.uniform(-1.5, -0.5))
        z = np.array([rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03)])
        step = m.step(z, jacobian=True)
        h = 1e-7
        fd = np.column_stack([(m.step(z + e).state - m.step(z - e).state) / (2 * h)
                              for e in (np.array([h, 0.0]), np.array([0.0, h]))])
        assert np.abs(step.jacobian - fd).max() <= 1e-6 * max(1.0, np.abs(fd).max())


def test_stiff_stop_tends_to_the_rigid_multipliers():
    """At Delta d = -1e-3 (|Delta d| >> alpha / k_c) the controlled 1/1 orbit's largest
    multiplier is within 0.005 of the rigid model's at k_c = 1e8 and further at 1e6:
    the order-1/2 approach of docs/theory_contact.md section 8."""
    p = OscillatorParams(delta_d=-1e-3)
    gains = Gains(degenerate_c1(p, -1.0), -1.0)
    rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
    rho_rigid = np.abs(np.linalg.eigvals(rigid.monodromy)).max()
    err = []
    for k in (1e6, 1e8):
        orbit = find_periodic(_model(k=k), rigid.state)
        err.append(abs(np.abs(np.linalg.eigvals(orbit.monodromy)).max() - rho_rigid))
    assert err[1] < 0.005 and err[1] < err[0]


def test_continuation_in_the_stiffness_finds_no_crossing_for_the_rigid_design():
    """The rigid design (c2 = -1, c1 of Eq. 38) continued from k_c = 1e8 down to 1e1 at
    Delta d = -5e-6: no multiplier crosses the unit circle (continue_orbit's detection),
    and the largest rises toward 0.917 for soft stops (docs/theory_contact.md section 13)."""
    p = OscillatorParams(delta_d=-5e-6)
    gains = Gains(degenerate_c1(p, -1.0), -1.0)
    rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
    branch = continue_orbit(_model(dd=-5e-6, k=1e8), "log10_stiffness",
                            np.linspace(8.0, 1.0, 15), rigid.state)
    assert branch.bifurcations == [] or len(branch.bifurcations) == 0
    rhos = [np.abs(pt.multipliers).max() for pt in branch.points]
    assert branch.points[-1].value == pytest.approx(1.0)
    assert max(rhos) < 0.92 and rhos[-1] > 0.9


def _failing(k=1e8):
    """The failing set of docs/theory_contact.md section 15: Delta d = -0.05, the rigid
    design at c2 = -1.5 (its rigid multiplier 0.824), a Kelvin-Voigt stop of r = 0.68 and
    Coulomb friction F_f = 0.01, F_s = 0.012 that the design ignores."""
    p = OscillatorParams(delta_d=-0.05)
    gains = Gains(degenerate_c1(p, -1.5), -1.5)
    rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
    model = CompliantOneDOF(p, gains, law=KelvinVoigt.from_restitution(k, p.r),
                            friction=Coulomb(0.01, 0.012))
    return model, rigid


def test_hertz_and_friction_models_are_period_maps_with_difference_jacobians():
    """Hertz and friction take the central-difference Jacobian (FD_STEP); on a frictionless
    Kelvin-Voigt stop it agrees with the exact one (Eq. C8) to 1e-6, and the parameters
    hunt_crossley and friction change the law (0 removes the friction)."""
    exact = _model(dd=-1e-2, k=1e4)
    z = np.array([0.01, -0.02])
    diff = CompliantOneDOF(exact.params, exact.gains, law=exact.law,
                           friction=Coulomb(0.0))
    assert not diff.exact_jacobian and exact.exact_jacobian
    j_exact = exact.step(z, jacobian=True).jacobian
    j_diff = diff.step(z, jacobian=True).jacobian
    assert np.abs(j_exact - j_diff).max() <= 1e-6 * np.abs(j_exact).max()
    hertz = CompliantOneDOF(exact.params, exact.gains, law=HuntCrossley(1e4, 0.3))
    assert isinstance(hertz, PeriodMap)
    assert hertz.with_parameter("hunt_crossley", 0.5).law.alpha == 0.5
    assert hertz.step(z, jacobian=True).jacobian.shape == (2, 2)
    model, _ = _failing()
    assert model.parameter("friction") == 0.01
    assert model.with_parameter("friction", 0.02).friction.static == pytest.approx(0.024)
    assert model.with_parameter("friction", 0.0).friction is None
    # Hertz with friction (issue 31 part 3): the map is hertz_period_step with it
    from grazing_control.oscillator.hertz import hertz_period_step

    rough = CompliantOneDOF(hertz.params, hertz.gains, law=hertz.law, friction=Coulomb(0.01))
    g = hertz.gains
    seg = hertz_period_step(hertz.params, hertz.law, *z, g.c1 * z[0] + g.c2 * z[1],
                            friction=Coulomb(0.01))
    assert tuple(rough.step(z).state) == (seg.x, seg.v)
    assert tuple(rough.step(z).state) != tuple(hertz.step(z).state)
    with pytest.raises(ValueError, match="hunt_crossley"):
        hertz.parameter("bogus")


def test_the_rigid_design_fails_with_friction_and_continuation_locates_the_stiffness():
    """The failing set: continue_orbit in log10 k_c from 8 to 1 finds a period doubling
    (the rigid design fails for stiffer stops, holds for softer ones), and brentq on
    max |lambda| = 1 with orbits shot directly puts it at the same stiffness to 1e-6
    (docs/theory_contact.md section 15: log10 k_c = 1.2924, k_c = 19.6)."""
    model, rigid = _failing()
    branch = continue_orbit(model, "log10_stiffness", np.linspace(8.0, 1.0, 8), rigid.state)
    rhos = {pt.value: np.abs(pt.multipliers).max() for pt in branch.points}
    assert rhos[8.0] > 1.5 and rhos[1.0] < 1.0
    assert [b.type for b in branch.bifurcations] == ["period-doubling"]
    found = branch.bifurcations[0].value
    lo = max(v for v in rhos if v < found)
    hi = min(v for v in rhos if v > found)
    states = {pt.value: pt.state for pt in branch.points}

    def excess(lk):
        return spectral_radius(model.with_parameter("log10_stiffness", lk), states[hi])[0] - 1.0
    assert brentq(excess, lo, hi, xtol=1e-10) == pytest.approx(found, abs=1e-6)


def test_design_on_the_compliant_model_restores_the_margin():
    """Where the rigid gains fail (k_c = 1e4 with friction: rho 1.71), the gains minimising
    the compliant orbit's spectral radius bring it below 0.1."""
    model, rigid = _failing()
    branch = continue_orbit(model, "log10_stiffness", [8.0, 6.0, 4.0], rigid.state)
    soft = model.with_parameter("log10_stiffness", 4.0)
    design = least_spectral_radius(soft, branch.points[-1].state, max_evaluations=60)
    assert design.rho_start > 1.5 and design.rho < 0.1, design
    again, _ = spectral_radius(soft.with_parameter("c1", design.c1).with_parameter(
        "c2", design.c2), design.state)
    assert again == pytest.approx(design.rho, abs=1e-6)  # difference Jacobian: ~1e-8

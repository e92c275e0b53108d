"""recordings.numbers: the contraction measured from recorded Pi2 samples equals the
largest Floquet multiplier of the exact controlled orbit, also when the multipliers are
complex (the fitted linear map; the slope of the log distance is biased there)."""

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.recordings.numbers import measured_contraction


@pytest.mark.parametrize("dd", [-5e-6, -9e-6, -1e-4])
@pytest.mark.parametrize("c2", [-1.0, -0.75, -0.5, -0.25, 0.0])
def test_measured_contraction_is_the_largest_multiplier(dd, c2):
    p = OscillatorParams(delta_d=dd)
    g = Gains(degenerate_c1(p, c2), c2)
    exact = orbit_11(p, g).multipliers
    res = simulate(p, 1300, gains=g, control_after=1000)
    m = measured_contraction(res.pi2, 1000)
    assert m["method"] == "eigenvalues of the fitted 2x2 map"
    assert m["rho"] == pytest.approx(float(np.max(np.abs(exact))), rel=2e-3)
    fitted = np.array([complex(*z) for z in m["fitted_multipliers"]])
    assert (np.abs(fitted.imag) > 1e-3).all() == (np.abs(exact.imag) > 1e-3).all()


def test_with_complex_multipliers_the_slope_alone_would_be_biased():
    p = OscillatorParams(delta_d=-1e-4)
    g = Gains(degenerate_c1(p, -0.75), -0.75)
    rho = float(np.max(np.abs(orbit_11(p, g).multipliers)))
    m = measured_contraction(simulate(p, 1300, gains=g, control_after=1000).pi2, 1000)
    assert abs(m["rho_distance_slope"] / rho - 1) > 0.02
    assert abs(m["rho"] / rho - 1) < 2e-3


def test_a_drifting_wall_is_named_beside_the_model_check():
    """A scene whose wall drifted (the simulator's delta_d_drift) departs from the model
    check by what the wall moved: the setup's notes say so; none without a drift."""
    from grazing_control.recordings.numbers import drift_notes

    assert drift_notes({}) == [] and drift_notes({"delta_d_drift": 0.0}) == []
    assert drift_notes({"delta_d_drift": "not a number"}) == []
    (note,) = drift_notes({"delta_d_drift": 1e-6})
    assert "delta_d_drift=1e-06 per period" in note and "not a model error" in note

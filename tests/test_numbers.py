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
    """A scene whose wall drifted (the simulator's delta_d_drift): the setup's notes name
    the drift and say that the model check re-integrates each period at the plant's
    Delta d of that period (issue 32: it no longer departs by what the wall moved); none
    without a drift, or with a drift that is not a finite number."""
    from grazing_control.recordings.numbers import drift_notes, recorded_drift

    assert drift_notes({}) == [] and drift_notes({"delta_d_drift": 0.0}) == []
    assert drift_notes({"delta_d_drift": "not a number"}) == []
    assert drift_notes({"delta_d_drift": float("nan")}) == []
    assert recorded_drift({"delta_d_drift": float("inf")}) == 0.0
    (note,) = drift_notes({"delta_d_drift": 1e-6})
    assert "delta_d_drift=1e-06 per period" in note
    assert "the plant's Delta d of that period" in note and "not a model error" not in note


def test_the_sample_index_and_the_drifted_model_are_the_simulators():
    """Sample k is stamped t_k = k T (ns-rounded); the model of its period is the
    simulator's expression Delta d + drift k (plant.engine.Engine._drift_wall), and
    the model itself without a drift."""
    from grazing_control.recordings.numbers import params_at, sample_index

    p = OscillatorParams(delta_d=-1e-3)
    for k in (0, 1, 7, 12345):
        t = round(k * p.period * 1e9) / 1e9
        assert sample_index(t, p.period) == k
        assert params_at(p, 3e-7, t) == p.with_(delta_d=p.delta_d + 3e-7 * k)
    assert params_at(p, 0.0, 5.0 * p.period) is p

"""The stream estimator over an n-DOF model (issue 32, dynamics/estimation/stream.py):
the controller's bookkeeping of sections around the model filter over the exact n-DOF
map, fed by the n-DOF engine's sensor (plant/engine.py over the model file)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design.family import evaluate_design
from grazing_control.dynamics.estimation.stream import StreamEstimator
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

CHAIN = Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_chain.yaml"
SIGMA, RATE, DELAY = 1e-4, 200, 1.0


def test_a_kick_known_wrong_gives_the_carried_state_then_the_filter_again():
    """Controlled chain (delay-aware design), x1's position only: the estimator is told
    that section 19's kick was 0.05 larger than the one that acted (what a lost
    oscillator/substituted would do). No fit of period 20's samples passes the residual
    test, neither from the filter's state nor from the wide prior about it: one reset,
    section 20's estimate is the state carried through the model (``predicted``, an
    answer near the orbit's instead of 0), and from section 21 on the filter fits again,
    within 20 reported std of the truth."""
    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    k = evaluate_design(model, -0.22, DELAY).gains
    T = model.period
    eng = Engine(settings_from_values(
        {"delta_d": -1e-3, "actuation_delay": DELAY, "state_period": T / RATE,
         "sensor_noise": SIGMA, "sensor_velocity": False, "sensor_seed": 1}, str(CHAIN)))
    est = StreamEstimator(model, "model", SIGMA, "stream", T / RATE, coordinate=1)
    due = [d for ev in eng.initial_states() for d in est.add_sample(ev.t, ev.x[1], ev.v[1])]
    sources = []
    for j in range(30):
        due += est.flush(j)
        (e,) = [d[2] for d in due if d[0] == j]
        sources.append(e.source)
        err = np.abs(np.array(e.z) - eng.z) / np.sqrt(np.diag(e.cov))
        if j >= 3 and j != 20:      # section 20: after the wrong kick
            assert np.all(err < 20.0), (j, err)
        dv = float(k @ np.array(e.z))
        est.set_correction(j, dv + (0.05 if j == 19 else 0.0), DELAY)
        events = eng.begin_period(dv, DELAY)
        due = [d for ev in events if ev.kind == "state"
               for d in est.add_sample(ev.t, ev.x[1], ev.v[1])]
        eng.end_period()
    assert est.resets == 1 and sources[0] == "prior" and sources[20] == "predicted", sources
    assert set(sources[1:20] + sources[21:]) == {"model"}, sources


def test_an_n_dof_stream_estimator_takes_only_the_model_filter_of_a_coordinate():
    model = load_model(CHAIN)
    with pytest.raises(ParameterError, match="estimator='arc' is invalid with an n-DOF"):
        StreamEstimator(model, "arc", SIGMA, "stream", 0.1)
    with pytest.raises(ParameterError, match="sensor_coordinate=-1 is invalid: valid range "
                                             "is 0 <= sensor_coordinate < n = 2"):
        StreamEstimator(model, "model", SIGMA, "stream", 0.1, coordinate=-1)


def test_the_analysis_of_a_delayed_scene_finds_the_delayed_controlled_orbit():
    """grazing analyze's controlled orbit of an n-DOF bag whose controller acted
    ``actuation_delay`` after each sample is ModalMap's with that delay (it took the
    undelayed map: |final - exact| 6.6e-2 and a 'predicted' contraction 1.40 for the
    captured delay-1.0 stream scene of docs/ndof_scene.md)."""
    from grazing_control.dynamics.maps.modal_map import ModalMap
    from grazing_control.dynamics.orbits.shooting import find_periodic
    from grazing_control.recordings.analysis import NdofSetup, ndof_controlled_orbit

    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    k = evaluate_design(model, -0.22, DELAY).gains
    P = ModalMap(model, k, DELAY)
    xref = P.flow.particular(P.flow.tau2)
    z = find_periodic(P, np.array([-0.04, 0.03, -0.05, 0.03])).state
    setup = NdofSetup(str(CHAIN), model, 2, k, 10, np.inf, DELAY, "lockstep")
    got = ndof_controlled_orbit(setup, xref + z + 1e-6)
    assert np.max(np.abs(np.array(got["orbit_pi2"]) - (xref + z))) < 1e-12
    assert got["rho"] < 1.0 and got["orbit_impacts"] == 1

"""The loop's noise gain over the n-DOF map (issue 32, dynamics/design/noise.py,
docs/ndof_scene.md): the n = 1 model file gives the 1-DOF linearised loop, and the
predicted spread of a 2-DOF chain under a delay-aware design and a position-only sensor
is the seeded closed loop's (studies.near_grazing.scene.stream_loop: the engine, its sensor,
the stream estimator)."""

import dataclasses
from pathlib import Path

import numpy as np

from grazing_control.dynamics.design import noise
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.design.family import evaluate_design
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.orbits.shooting import find_periodic
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.studies.near_grazing.scene import stream_loop

from test_family import _study

CHAIN = Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_chain.yaml"


def test_the_n1_model_gives_the_1dof_noise_covariance():
    """n = 1 (the study's model file) with R = I: the n-DOF loop's Sigma is
    noise.noise_covariance of the 1-DOF closed form, with and without delay, 1e-9
    relative (two routes: ModalMap's monodromies, the 1-DOF advance)."""
    m, p = _study()
    m, p = dataclasses.replace(m, delta_d=-1e-3), p.with_(delta_d=-1e-3)
    for delay in (0.0, 0.3):
        g = Gains(degenerate_c1(p, -0.3, delay), -0.3, delay)
        target = orbit_11(p, g).pi2_deviation
        want = noise.noise_covariance(p, g, np.eye(2), target)
        got = noise.noise_covariance(m, [g.c1, g.c2], np.eye(2), target, delay)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=0)


def test_the_predicted_spread_is_the_seeded_closed_loops():
    """Chain at Delta d = -1e-3, k(mu = -0.22, delay 1.0), x0's position only at T/200,
    sigma 1e-4: the seeded closed loop on the stream (300 periods, the spread over the
    last 230) has one impact per period and a spread per coordinate within 15 % of the
    prediction over the samples the lockstep controller fits (before t_k:
    section_sample=False), and the filter's errors within 10 % of its predicted
    covariance, both within 5 % on average over the coordinates. Reproduction (issue 32's rig scene): the prediction over j = 1 .. rate
    (the sample at t_k, which the controller answers before, counted) was 1.10-1.13 low
    in the filter's std, so the spread came out 1.076 .. 1.121 times the prediction and
    the filter's errors up to 12 % above it (docs/ndof_scene.md)."""
    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    design = evaluate_design(model, -0.22, 1.0)
    run = stream_loop(CHAIN, design.gains, delta_d=-1e-3, delay=1.0, sigma=1e-4, rate=200,
                      coordinate=0, periods=300, control_after=10, seed=0)
    assert run.resets == 0 and np.all(run.impacts_per_period[70:] == 1)
    orbit = find_periodic(ModalMap(model, design.gains, 1.0), run.truth[-1]).state
    R = noise.filter_covariance(model, design.gains, orbit, 200, 0, 1.0,
                                     section_sample=False)
    S = noise.noise_covariance(model, design.gains, R, orbit, 1.0)
    predicted = 1e-4 * np.sqrt(np.diag(S))
    measured = (run.truth[70:] - orbit).std(axis=0)
    ratio = measured / predicted
    err = (run.estimate[70:] - run.truth[70:]).std(axis=0)
    filt = err / (1e-4 * np.sqrt(np.diag(R)))
    print(f"spread / predicted per coordinate: {np.round(ratio, 3).tolist()}; filter "
          f"error / predicted: {np.round(filt, 3).tolist()}")
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio
    assert np.all(np.abs(filt - 1.0) < 0.1), filt
    # on average over the coordinates within 5 % (measured 0.969 and 0.978; counting the
    # sample at t_k: 1.089 and 1.095)
    assert abs(np.mean(ratio) - 1.0) < 0.05 and abs(np.mean(filt) - 1.0) < 0.05
    # with the sample at t_k counted the filter's predicted std is 10-13 % smaller
    full = noise.filter_covariance(model, design.gains, orbit, 200, 0, 1.0)
    assert np.all(np.sqrt(np.diag(R) / np.diag(full)) > 1.08)

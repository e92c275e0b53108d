"""The rig's motion sensor (grazing_control.plant.sensor): sampled measurements that are a
pure function of (seed, sample index), with the noise, bias and quantisation asked for."""

import math

import numpy as np
import pytest

from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.sensor import BLOCK, EXACT_SENSOR, SensorModel


def test_the_exact_sensor_returns_the_state():
    x, v = np.linspace(-1, 1, 7), np.linspace(2, 3, 7)
    xm, vm = EXACT_SENSOR.measure(123, x, v)
    assert np.array_equal(xm, x) and np.array_equal(vm, v)


def test_measurements_are_a_pure_function_of_seed_and_index_however_the_stream_is_cut():
    s = SensorModel(noise=1e-3, seed=5)
    x = np.zeros(1000)
    whole = s.measure(BLOCK - 17, x, x)
    rng = np.random.default_rng(0)
    cuts = np.sort(rng.choice(np.arange(1, 1000), 30, replace=False))
    parts = [s.measure(BLOCK - 17 + a, x[a:b], x[a:b])
             for a, b in zip(np.r_[0, cuts], np.r_[cuts, 1000])]
    assert np.array_equal(whole[0], np.concatenate([p[0] for p in parts]))
    assert np.array_equal(whole[1], np.concatenate([p[1] for p in parts]))
    other = SensorModel(noise=1e-3, seed=6).measure(BLOCK - 17, x, x)
    assert not np.array_equal(whole[0], other[0])


def test_the_draws_are_their_blocks_generators_whatever_was_drawn_before():
    """Sample j's draws are row j % BLOCK of the generator seeded (seed, j // BLOCK),
    however the blocks kept from earlier calls (for the next segments) were drawn: 300
    seeded calls over a few seeds, against a fresh generator per block; and a kept
    block cannot be written through what a call returns."""
    rng = np.random.default_rng(31)
    blocks = {}

    def block(seed, b):
        if (seed, b) not in blocks:
            blocks[seed, b] = np.random.default_rng([seed, b]).standard_normal((BLOCK, 2))
        return blocks[seed, b]

    for _ in range(300):
        seed, j0, n = int(rng.integers(0, 4)), int(rng.integers(0, 5 * BLOCK)), \
            int(rng.integers(1, 3 * BLOCK))
        got = SensorModel(noise=1.0, seed=seed).draws(j0, n)
        want = np.array([block(seed, j // BLOCK)[j % BLOCK] for j in range(j0, j0 + n)])
        assert np.array_equal(got, want)
        got[:] = 0.0                                    # the caller's copy
    assert np.array_equal(SensorModel(noise=1.0, seed=1).draws(0, 2),
                          np.random.default_rng([1, 0]).standard_normal((BLOCK, 2))[:2])


def test_noise_is_unbiased_with_the_given_std_and_independent_on_x_and_v():
    s = SensorModel(noise=2e-4, seed=1)
    n = 200_000
    xm, vm = s.measure(0, np.zeros(n), np.zeros(n))
    for e in (xm, vm):
        assert abs(e.mean()) < 5 * 2e-4 / math.sqrt(n)
        assert abs(e.std() / 2e-4 - 1) < 5 / math.sqrt(2 * n)
    assert abs(np.corrcoef(xm, vm)[0, 1]) < 5 / math.sqrt(n)
    assert abs(np.corrcoef(xm[:-1], xm[1:])[0, 1]) < 5 / math.sqrt(n)


def test_bias_and_quantisation():
    s = SensorModel(bias=0.01, quantum=1e-3)
    xm, _ = s.measure(0, np.array([0.12344, -0.5, 0.0004]), np.zeros(3))
    assert np.allclose(xm, [0.133, -0.49, 0.010])
    assert np.allclose(xm / 1e-3, np.round(xm / 1e-3))


def test_a_position_only_sensor_gives_no_velocity():
    xm, vm = SensorModel(velocity=False).measure(0, np.ones(4), np.ones(4))
    assert np.all(xm == 1.0) and np.all(np.isnan(vm))


@pytest.mark.parametrize("kw, name", [({"noise": -1.0}, "sensor_noise"),
                                      ({"noise": math.inf}, "sensor_noise"),
                                      ({"quantum": -1e-3}, "sensor_quantum"),
                                      ({"bias": math.nan}, "sensor_bias"),
                                      ({"velocity": "yes"}, "sensor_velocity"),
                                      ({"seed": -1}, "seed")])
def test_bad_settings_are_refused_naming_the_parameter(kw, name):
    with pytest.raises(ParameterError, match=f"{name}=.* is invalid"):
        SensorModel(**kw)

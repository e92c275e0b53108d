"""Specification tests of grazing_control.plant.faults.FaultModel (issue 8 section 3).

The faults of sample k are a pure function of (seed, k): the core and the nodes draw the
same ones. Checked here: validation (one named parameter and its range per error),
determinism and independence of the call order, and the statistics of the draws against
their laws (binomial for loss, normal for noise and jitter) over 8,000 samples, with
tolerances of about 4 standard errors.
"""

import math

import numpy as np
import pytest

from grazing_control.plant.faults import NO_FAULTS, FaultModel, SampleFaults
from grazing_control.oscillator.params import ParameterError

N = 8000
T = 9.42


def _draws(model, n=N, start=0):
    return [model.draw(k) for k in range(start, start + n)]


# ------------------------------------------------------------------ validation
@pytest.mark.parametrize("name, value", [
    ("loss", -1e-9), ("loss", 1.0 + 1e-9), ("loss", math.nan), ("loss", math.inf), ("loss", "a"),
    ("loss", None), ("noise", -1e-12), ("noise", math.inf), ("noise", math.nan), ("noise", "x"),
    ("jitter", -1.0), ("jitter", math.inf), ("jitter", math.nan), ("jitter", [1.0]),
])
def test_invalid_levels_name_the_parameter_and_its_range(name, value):
    with pytest.raises(ParameterError) as err:
        FaultModel(**{name: value})
    msg = str(err.value)
    assert msg.startswith(f"{name}=") and "valid range" in msg and "\n" not in msg


@pytest.mark.parametrize("seed", [-1, 1.5, True, "3", None, math.nan])
def test_invalid_seeds(seed):
    with pytest.raises(ParameterError, match=r"^seed=.*valid range is an integer >= 0"):
        FaultModel(seed=seed)


def test_valid_edges_and_numpy_inputs_are_accepted_and_normalised():
    m = FaultModel(loss=np.float64(1.0), noise=0, jitter=np.float32(0.5), seed=np.int64(7))
    assert (m.loss, m.noise, m.jitter, m.seed) == (1.0, 0.0, 0.5, 7)
    assert all(type(v) is float for v in (m.loss, m.noise, m.jitter)) and type(m.seed) is int
    assert FaultModel(loss=0.0).active is False and NO_FAULTS.active is False
    assert FaultModel(jitter=1e-300).active


# ------------------------------------------------------------------ determinism
def test_draws_are_a_pure_function_of_seed_and_sample():
    a, b = FaultModel(0.3, 0.1, 0.2, seed=5), FaultModel(0.3, 0.1, 0.2, seed=5)
    forward = [a.draw(k) for k in range(200)]
    backward = [b.draw(k) for k in reversed(range(200))][::-1]
    assert forward == backward
    assert all(isinstance(f, SampleFaults) for f in forward)
    other = [FaultModel(0.3, 0.1, 0.2, seed=6).draw(k) for k in range(200)]
    assert sum(f != g for f, g in zip(forward, other)) > 190
    # samples far apart are just as reproducible (no stream state)
    assert a.draw(10 ** 9) == b.draw(10 ** 9)


def test_the_levels_share_the_same_random_numbers():
    """Common random numbers: the level scales the draw, so sweeps over a level compare
    like with like, and a fault kind does not change another's pattern."""
    lo, hi = FaultModel(noise=1e-6, jitter=1e-3, seed=2), FaultModel(noise=2e-6, jitter=3e-3, seed=2)
    for k in range(100):
        f, g = lo.draw(k), hi.draw(k)
        assert g.noise_x == pytest.approx(2 * f.noise_x, rel=1e-15)
        assert g.noise_v == pytest.approx(2 * f.noise_v, rel=1e-15)
        assert g.delay_offset == pytest.approx(3 * f.delay_offset, rel=1e-15)
    drops = [FaultModel(loss=0.2, seed=4).draw(k).dropped for k in range(500)]
    assert drops == [FaultModel(loss=0.2, noise=0.5, jitter=0.5, seed=4).draw(k).dropped
                     for k in range(500)]
    # a higher loss drops a superset of the samples
    more = [FaultModel(loss=0.5, seed=4).draw(k).dropped for k in range(500)]
    assert all(m or not d for d, m in zip(drops, more)) and sum(more) > sum(drops)


def test_no_faults_draws_nothing():
    for m in (NO_FAULTS, FaultModel(seed=9)):
        assert set(_draws(m, 100)) == {SampleFaults(0.0, 0.0, False, 0.0)}
        assert m.actuation_delay(1.25, 3, T) == 1.25


# ------------------------------------------------------------------ statistics
@pytest.mark.parametrize("loss", [0.0, 0.01, 0.2, 0.5, 0.97, 1.0])
def test_loss_is_binomial(loss):
    drops = np.array([f.dropped for f in _draws(FaultModel(loss=loss, seed=11))])
    if loss in (0.0, 1.0):
        assert drops.all() if loss == 1.0 else not drops.any()
        return
    se = math.sqrt(loss * (1 - loss) / N)
    assert abs(drops.mean() - loss) < 4.5 * se
    # independent from sample to sample: lag-1 pairs dropped together ~ loss^2
    both = np.mean(drops[1:] & drops[:-1])
    assert abs(both - loss * loss) < 4.5 * math.sqrt(loss * loss * (1 - loss * loss) / N) + 1e-4


@pytest.mark.parametrize("sigma", [1e-8, 0.3])
def test_noise_is_normal_with_the_given_std_on_x_and_v_independently(sigma):
    d = _draws(FaultModel(noise=sigma, seed=21))
    x = np.array([f.noise_x for f in d]) / sigma
    v = np.array([f.noise_v for f in d]) / sigma
    for e in (x, v):
        assert abs(e.mean()) < 4.5 / math.sqrt(N)
        assert abs(e.std() - 1.0) < 4.5 * math.sqrt(0.5 / N)
        # tails of N(0, 1): P(|e| > 2) = 0.0455
        assert abs(np.mean(np.abs(e) > 2.0) - 0.0455) < 4.5 * math.sqrt(0.0455 * 0.9545 / N)
    assert abs(np.corrcoef(x, v)[0, 1]) < 4.5 / math.sqrt(N)
    assert not any(f.dropped for f in d) and all(f.delay_offset == 0.0 for f in d)


def test_jitter_offsets_and_the_clipped_actuation_delay():
    jit = 0.2
    m = FaultModel(jitter=jit, seed=31)
    off = np.array([f.delay_offset for f in _draws(m)]) / jit
    assert abs(off.mean()) < 4.5 / math.sqrt(N)
    assert abs(off.std() - 1.0) < 4.5 * math.sqrt(0.5 / N)
    delays = np.array([m.actuation_delay(1.0, k, T) for k in range(N)])
    np.testing.assert_allclose(delays, 1.0 + jit * off, rtol=0, atol=1e-15)
    # clipping to [0, T): a delay near 0 and one near T
    big = FaultModel(jitter=3.0, seed=32)
    low = np.array([big.actuation_delay(0.0, k, T) for k in range(2000)])
    high = np.array([big.actuation_delay(T - 0.5, k, T) for k in range(2000)])
    assert low.min() == 0.0 and np.mean(low == 0.0) == pytest.approx(0.5, abs=0.05)
    assert high.max() == math.nextafter(T, 0.0) and np.all(high < T)
    assert np.all(low >= 0.0) and np.all(high >= 0.0)

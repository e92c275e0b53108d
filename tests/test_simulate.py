"""Tests of grazing_control.dynamics.simulation.simulate: runs on Pi2, the controller switch, batches,
dense output, and the two controlled scenes of the study (spec section 8, Fig. 2 f, g).
"""

import math

import numpy as np
import pytest

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.flow import to_deviation, to_physical
from grazing_control.oscillator import kernel
from grazing_control.oscillator.impact import (ImpactCapError, InitialStateError,
                                               NonFiniteStateError, advance)
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import (MAX_PERIODS, SimulationResult,
                                                          core_states_between, period_step,
                                                          simulate, simulate_batch,
                                                          states_between)

STUDY = OscillatorParams()
SCENE = STUDY.with_(delta_d=-1e-3)
GAINS = Gains(0.2, -0.4)


def _design(p):
    return Gains(degenerate_c1(p, -1.0), -1.0)


# ------------------------------------------------------------------ shapes
def test_result_shapes_and_contents():
    res = simulate(SCENE, 25, gains=GAINS, control_after=10)
    assert isinstance(res, SimulationResult)
    assert res.pi2.shape == (25, 2) and res.pi2_deviation.shape == (25, 2)
    assert res.corrections.shape == (25,)
    assert res.impacts_per_period.shape == (25,) and res.impacts_per_period.dtype.kind == "i"
    assert res.impacts.shape == (res.impacts_per_period.sum(), 5)
    assert res.params is SCENE and res.gains is GAINS and res.control_after == 10
    # physical = X** + deviation; the first sample is X** by default
    assert np.allclose(res.pi2, res.pi2_deviation + [SCENE.x_ref, SCENE.v_ref], atol=1e-15)
    assert np.array_equal(res.pi2_deviation[0], [0.0, 0.0])
    # impact rows: [period k, time since start, phase, v-, v+], in time order
    k, t, ph, vm, vp = res.impacts.T
    assert np.array_equal(np.bincount(k.astype(int), minlength=25), res.impacts_per_period)
    assert np.all(np.diff(t) > 0)
    assert np.all((t >= k * SCENE.period) & (t < (k + 1) * SCENE.period))
    assert np.allclose(ph, (SCENE.tau2 + SCENE.omega * (t - k * SCENE.period)) % (2 * math.pi),
                       atol=1e-12)
    assert np.all(vm > 0) and np.allclose(vp, -SCENE.r * vm, rtol=1e-15)


def test_zero_periods_and_argument_validation():
    res = simulate(SCENE, 0)
    assert res.pi2.shape == (0, 2) and res.impacts.shape == (0, 5)
    assert res.final_deviation == (0.0, 0.0)
    for bad in (-1, 1.5):
        with pytest.raises(ValueError, match="periods="):
            simulate(SCENE, bad)
    for bad in (-2, 0.5):
        with pytest.raises(ValueError, match="control_after="):
            simulate(SCENE, 3, gains=GAINS, control_after=bad)


def test_initial_state_forms_agree():
    x0, v0 = SCENE.x_ref - 0.05, SCENE.v_ref + 0.1
    a = simulate(SCENE, 10, x0=x0, v0=v0)
    b = simulate(SCENE, 10, deviation=(x0 - SCENE.x_ref, v0 - SCENE.v_ref))
    assert np.array_equal(a.pi2_deviation, b.pi2_deviation)
    assert np.array_equal(a.impacts, b.impacts)


def test_samples_chain_through_period_step_and_final_deviation():
    res = simulate(SCENE, 12, gains=GAINS, control_after=4)
    dev = res.pi2_deviation
    for k in range(12):
        seg = period_step(SCENE, *dev[k], res.corrections[k])
        nxt = dev[k + 1] if k + 1 < 12 else res.final_deviation
        assert (seg.dx, seg.dv) == tuple(nxt)
        assert len(seg.impacts) == res.impacts_per_period[k]
        # period_step is the exact flow with impacts over one period after the kick
        direct = advance(SCENE, SCENE.tau2, dev[k][0], dev[k][1] + res.corrections[k],
                         SCENE.period)
        assert (direct.dx, direct.dv) == (seg.dx, seg.dv)


# ---------------------------------------------------------- control_after
def test_control_after_semantics():
    res = simulate(SCENE, 20, gains=GAINS, control_after=7)
    dev = res.pi2_deviation
    assert np.all(res.corrections[:7] == 0.0)
    want = GAINS.c1 * dev[7:, 0] + GAINS.c2 * dev[7:, 1]
    assert np.array_equal(res.corrections[7:], want)
    assert np.any(res.corrections[7:] != 0.0)
    # the first 7 samples are those of the uncontrolled run, the 8th already differs
    free = simulate(SCENE, 20)
    assert np.array_equal(free.pi2_deviation[:8], dev[:8])
    assert not np.array_equal(free.pi2_deviation[8:], dev[8:])


@pytest.mark.parametrize("kwargs", [{"gains": GAINS, "control_after": None},
                                    {"gains": None, "control_after": 0},
                                    {"gains": None, "control_after": 5}])
def test_controller_off(kwargs):
    res = simulate(SCENE, 15, **kwargs)
    assert res.control_after is None
    assert np.all(res.corrections == 0.0)
    assert np.array_equal(res.pi2_deviation, simulate(SCENE, 15).pi2_deviation)


def test_control_from_the_start():
    a = simulate(SCENE, 10, gains=GAINS)  # control_after defaults to 0
    b = simulate(SCENE, 10, gains=GAINS, control_after=0)
    assert a.control_after == 0 and np.array_equal(a.pi2, b.pi2)
    assert a.corrections[0] == 0.0  # at X** the correction is zero
    assert np.any(a.corrections[1:] != 0.0)


def test_deterministic():
    p = STUDY.with_(delta_d=-5e-6)  # chaotic: any hidden state would show
    a = simulate(p, 300, gains=_design(p), control_after=150)
    b = simulate(p, 300, gains=_design(p), control_after=150)
    assert np.array_equal(a.pi2, b.pi2) and np.array_equal(a.impacts, b.impacts)
    assert np.array_equal(a.corrections, b.corrections)


# -------------------------------------------------------- the study scenes
@pytest.mark.parametrize("delta_d", [-5e-6, -9e-6])
def test_study_scene_controller_switched_on_after_1000_periods(delta_d):
    """Fig. 2 (f, g): uncontrolled 1000 iterations on Pi2, then c2 = -1 and c1 from the
    degenerate condition: the response settles on the controlled 1/1 orbit (one
    impact per period) and converges to orbit_11(p, gains).pi2.

    Uncontrolled from X**: at -5e-6 the motion stays irregular, with missed impacts;
    at -9e-6 it is irregular for ~540 periods, then settles on a 2/2 orbit (one
    impact per period, period 2 on Pi2). Neither is a 1/1 motion before the switch.
    """
    p = STUDY.with_(delta_d=delta_d)
    gains = _design(p)
    res = simulate(p, 1200, gains=gains, control_after=1000)
    assert np.any(res.impacts_per_period[:500] == 0)  # grazing misses
    before = res.pi2_deviation[900:1000]
    assert np.max(np.abs(np.diff(before, axis=0))) > 1e-4  # not period one on Pi2
    assert np.all(res.impacts_per_period[1100:] == 1)
    target = orbit_11(p, gains)
    err = np.max(np.abs(res.pi2_deviation[1150:] - np.array(target.pi2_deviation)), axis=1)
    assert np.all(err < 1e-10), err.max()
    assert np.max(np.abs(res.pi2[-1] - np.array(target.pi2))) < 1e-10
    assert res.impacts[-1, 3] == pytest.approx(target.v_minus, rel=1e-8)


# --------------------------------------------------------------- batches
def test_simulate_batch_equals_individual_runs():
    dds = [-1e-3, -5e-6, 0.01]
    kwargs = {"gains": GAINS, "control_after": 20, "x0": 0.1, "v0": -1.1}
    pi2, counts = simulate_batch(STUDY, dds, 60, keep=15, **kwargs)
    assert pi2.shape == (3, 15, 2) and counts.shape == (3, 15)
    for i, dd in enumerate(dds):
        one = simulate(STUDY.with_(delta_d=dd), 60, **kwargs)
        assert np.array_equal(pi2[i], one.pi2[-15:])
        assert np.array_equal(counts[i], one.impacts_per_period[-15:])
    full, _ = simulate_batch(STUDY, dds[:1], 10)
    assert full.shape == (1, 10, 2)


def test_simulate_batch_in_worker_processes_is_identical():
    dds = np.linspace(-1e-3, -1e-5, 4)
    a = simulate_batch(STUDY, dds, 40, keep=10, workers=1)
    b = simulate_batch(STUDY, dds, 40, keep=10, workers=2)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


# ------------------------------------------------------------ dense output
@pytest.mark.parametrize("p,z", [(SCENE, (0.0, 0.0)), (STUDY.with_(delta_d=-0.05), (0.1, -0.3)),
                                 (OscillatorParams.from_d(0.5, r=0.5), (0.0, 0.0))])
def test_states_between_agrees_with_advance(p, z):
    duration = 3 * p.period
    seg = advance(p, p.tau2, *z, duration)
    assert seg.impacts  # the dense output has to cross impacts
    times = np.sort(np.random.default_rng(0).uniform(0, duration, 60))
    dense = states_between(p, p.tau2, *z, seg.impacts, times)
    for t, (x, v) in zip(times, dense):
        a = advance(p, p.tau2, *z, t)
        xa, va = to_physical(p, p.tau2 + p.omega * t, a.dx, a.dv)
        assert abs(x - xa) < 1e-12 and abs(v - va) < 1e-12
        assert x <= p.d + 1e-12


def test_states_between_holds_the_mass_on_the_wall_while_it_sticks():
    p = OscillatorParams.from_d(0.5, r=0.5)
    tau = 5.5  # at rest on the wall with cos(tau) - d > 0: sticks until tau = pi/3
    z = to_deviation(p, tau, p.d, 0.0)
    seg = advance(p, tau, *z, 3.5)
    times = np.array([0.5, 1.0, 2.0, 3.4])
    dense = states_between(p, tau, *z, seg.impacts, times)
    for t, (x, v) in zip(times, dense):
        a = advance(p, tau, *z, t)
        xa, va = to_physical(p, tau + p.omega * t, a.dx, a.dv)
        assert abs(x - xa) < 1e-12 and abs(v - va) < 1e-12


def _random_model(rng):
    """A random model in the parameters' valid ranges; half with the wall at d < 1
    (chattering and sticking), a quarter the study's near grazing."""
    kind = rng.integers(4)
    if kind == 0:
        return STUDY.with_(delta_d=-10.0 ** rng.uniform(-10, -2))
    if kind == 1:
        return OscillatorParams(zeta=rng.uniform(0.005, 0.3), r=rng.uniform(0.1, 0.95),
                                omega=rng.uniform(0.3, 3.0), delta_d=rng.uniform(-1.0, 0.2))
    return OscillatorParams.from_d(rng.uniform(-0.5, 1.5), zeta=rng.uniform(0.005, 0.3),
                                   r=rng.uniform(0.05, 0.95), omega=rng.uniform(0.3, 3.0))


def _random_segment(rng):
    """A random model and a real segment of it (the core's advance) from a state near the
    wall: at it moving in, out or at rest, just below it, or near grazing from Pi2."""
    p = _random_model(rng)
    kind = rng.integers(3)
    if kind == 0:   # on the wall at a random phase
        tau = rng.uniform(0, 2 * math.pi)
        v = [0.0, 0.0, 1e-9, -1e-9, 0.1, -0.1, 1.0][rng.integers(7)]
        dx, dv = to_deviation(p, tau, p.d, v)
    elif kind == 1:  # just below it
        tau = rng.uniform(0, 2 * math.pi)
        dx, dv = to_deviation(p, tau, p.d - 10.0 ** rng.uniform(-12, 0),
                              rng.normal() * 10.0 ** rng.uniform(-6, 0))
    else:           # a sample on Pi2 near X**
        tau = p.tau2
        dx, dv = rng.normal(size=2) * 10.0 ** rng.uniform(-9, -1)
    duration = rng.uniform(0.05, 3.0) * p.period
    try:
        seg = advance(p, tau, dx, dv, duration)
    except (ImpactCapError, InitialStateError):
        return None
    return p, float(tau), float(dx), float(dv), seg.impacts, duration


def _random_times(rng, impacts, duration):
    """Sorted sample times over the segment: uniform ones, and some at its events
    exactly (an impact's time, a release), 0 and repeats."""
    m = int(rng.integers(0, 60))
    times = list(rng.uniform(0.0, duration, m))
    events = [i.dt for i in impacts] + [i.release for i in impacts
                                        if i.sticking and math.isfinite(i.release)]
    times += [t for t in events if rng.random() < 0.5]
    if rng.random() < 0.2:
        times += [0.0, duration]
    if times and rng.random() < 0.2:
        times.append(times[int(rng.integers(len(times)))])
    return np.sort(np.array(times, dtype=float))


def test_compiled_states_between_is_the_python_one_bit_for_bit(monkeypatch):
    """Differential test (issue 30): over 4000 seeded random segments (random models,
    starts near the wall, 0, 1 or several impacts, sticking ones) and random sorted
    sample times, the kernel's dense output is the pure-Python one bit for bit, and
    states_between dispatches by GRAZING_KERNEL."""
    pytest.importorskip("numba")
    rng = np.random.default_rng(20261129)
    seen = {"none": 0, "one": 0, "several": 0, "sticking": 0, "samples": 0}
    cases = 0
    while cases < 4000:
        case = _random_segment(rng)
        if case is None:
            continue
        cases += 1
        p, tau, dx, dv, impacts, duration = case
        times = _random_times(rng, impacts, duration)
        ref = core_states_between(p, tau, dx, dv, impacts, times)
        got = kernel.states_between(p, tau, dx, dv, impacts, times)
        assert got.shape == ref.shape == (times.size, 2)
        assert np.array_equal(got, ref), (p, tau, dx, dv, impacts, times)
        assert got.tobytes() == ref.tobytes(), (p, tau, dx, dv, impacts, times)  # -0.0 too
        n = len(impacts)
        seen["none" if n == 0 else "one" if n == 1 else "several"] += 1
        seen["sticking"] += any(i.sticking for i in impacts)
        seen["samples"] += times.size
    assert min(seen["none"], seen["one"], seen["several"]) > 300 and seen["sticking"] > 300, seen
    # the dispatch: the kernel where it is in use, the reference with GRAZING_KERNEL=python
    calls = []
    monkeypatch.setattr(kernel, "states_between", lambda *a: calls.append(a) or ref)
    monkeypatch.setenv(kernel.ENV, "numba")
    assert states_between(p, tau, dx, dv, impacts, list(times)) is ref and len(calls) == 1
    monkeypatch.setenv(kernel.ENV, "python")
    assert np.array_equal(states_between(p, tau, dx, dv, impacts, times), ref)
    assert len(calls) == 1


# ------------------------------------------------------------- overflow (issue 7)
@pytest.mark.parametrize("gains", [Gains(0.0, 1e308), Gains(1e308, 0.0), Gains(-1e308, 0.0),
                                   Gains(0.0, 1e200)])
def test_an_overflowing_controller_stops_with_a_clear_error(gains):
    """Issue 7: `grazing simulate --delta-d -5e-6 --periods 200 --c2 1e308` (and c1 =
    +-1e308) hung the impact search on inf/nan; now it stops at once naming what
    overflowed and the period."""
    import time

    p = OscillatorParams(delta_d=-5e-6)
    start = time.perf_counter()
    with pytest.raises(NonFiniteStateError, match=r"period \d+") as info:
        simulate(p, 200, gains=gains, deviation=(1e-3, 1e-3))
    assert time.perf_counter() - start < 5.0
    assert "overflowed" in str(info.value) or "absurdly large" in str(info.value)


@pytest.mark.parametrize("deviation", [(math.nan, 0.0), (0.0, math.inf), (1e200, 0.0)])
def test_non_finite_initial_state_is_refused(deviation):
    with pytest.raises(NonFiniteStateError, match="initial state"):
        simulate(OscillatorParams(delta_d=-1e-3), 3, deviation=deviation)


def test_period_count_is_bounded():
    """simulate(periods=1e12) raised MemoryError; the limit is stated up front."""
    with pytest.raises(ValueError, match=f"periods=1000000000000 is invalid.*{MAX_PERIODS}"):
        simulate(OscillatorParams(), 10 ** 12)

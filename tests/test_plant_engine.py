"""The plant's engine without ROS (grazing_control.plant.engine): its periods against the
core's period_step, its events on their grid, its end of run.

tests/test_sim_node.py and tests/test_actuation.py hold the engine's earlier
specifications (reproduces simulate; delayed periods bit for bit on both paths; faults
per sample); these add the sample grid of the state stream, the split against
period_step's delay, and the end of a run.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.dynamics.simulate import period_step
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

P = OscillatorParams(delta_d=-5e-6)


def settings(**kw):
    return settings_from_values({"delta_d": P.delta_d, **kw})


def test_state_events_lie_on_one_grid_across_periods_and_splits():
    sp = P.period / 7.31                  # no grid point on a sample within 30 periods
    eng = Engine(settings(state_period=sp))
    times = []
    for k in range(30):
        events = eng.begin_period(0.0)
        if k % 3 == 0:                       # a split re-evaluates the rest of the period
            events = [e for e in events if e.t < eng.t + 2.0] + eng.split(eng.t + 2.0, 0.0)
        times += [e.t for e in events if e.kind == "state"]
        eng.end_period()
    j = np.round(np.array(times) / sp)
    np.testing.assert_allclose(times, j * sp, rtol=0, atol=1e-9)
    assert list(j) == list(range(1, len(j) + 1))          # every grid point once
    assert len(times) == math.ceil(30 * P.period / sp) - 1


def test_split_equals_period_step_with_that_delay():
    rng = np.random.default_rng(3)
    for _ in range(40):
        eng = Engine(settings(delta_d=-10 ** rng.uniform(-6, -2)))
        for _ in range(3):
            tc, dvc = rng.uniform(0.0, eng.p.period), rng.normal(0, 0.05)
            ref = period_step(eng.p, eng.dx, eng.dv, dvc, delay=tc)
            eng.begin_period(0.0)
            events = eng.split(eng.t + tc, dvc)
            assert sum(e.kind == "impact" for e in events) == \
                sum(i.dt > tc for i in ref.impacts)
            assert eng.seg.dx_end == pytest.approx(ref.dx, abs=1e-12)
            assert eng.seg.dv_end == pytest.approx(ref.dv, abs=1e-12)
            eng.end_period()


def test_done_after_max_periods_only():
    eng = Engine(settings(max_periods=3))
    flags = []
    for _ in range(3):
        flags.append(eng.done)
        eng.begin_period(0.0)
        eng.end_period()
    assert flags == [False] * 3 and eng.done
    assert not Engine(settings(max_periods=0)).done


def test_reset_returns_sample_zero_and_forgets_the_run():
    eng = Engine(settings(x0=-0.5, v0=-1.0, noise=1e-4, seed=2))
    first = eng.sample()
    for _ in range(4):
        eng.begin_period(0.0)
        eng.end_period()
    again = eng.reset()
    assert (again.t, again.x, again.v) == (first.t, first.x, first.v)
    assert eng.k == 0 and eng.impacts == 0

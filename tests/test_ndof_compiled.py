"""The compiled n-DOF event search (oscillator/kernel/compiled_modal.py, issue 32) against
the pure path (oscillator/ndof/impact.py with GRAZING_KERNEL=python), run side by side in
one process: the same floats, case by case.

Yardstick: the pure search, itself tested against the dense-grid brute force and the
50-digit reference (tests/test_ndof_impact.py). The cases are that file's seeded
generator (random models n = 1..3 with non-proportional damping; large transients,
starts near X** down to 1e-12, and constructed near-grazing humps of g with a maximum at
d +- 1e-10 .. 1e-1 relative), three horizons each, plus starts on the wall and beyond it.
"""

import math

import numpy as np
import pytest

from grazing_control.oscillator import kernel
from grazing_control.oscillator.ndof import impact as ndof_impact

from test_ndof_impact import _random_cases

pytestmark = pytest.mark.skipif(not kernel.use_kernel(),
                                reason="the kernel is not in use (numba or GRAZING_KERNEL)")


@pytest.fixture(scope="module", autouse=True)
def compiled_search():
    """The compiled search loaded (the suite's conftest has loaded it already, through
    dynamics.estimation.stream.warm_up with a model of two masses)."""
    kernel.warm_up_modal()
    assert kernel.modal_search() is not None


def _both(monkeypatch, call):
    """(pure, compiled) results of ``call()``: a value, or the error's type and message."""
    out = []
    for choice in ("python", "auto"):
        monkeypatch.setenv(kernel.ENV, choice)
        try:
            out.append(call())
        except (ndof_impact.InitialStateError, ndof_impact.ChatteringError,
                ndof_impact.ImpactCapError) as exc:
            out.append((type(exc).__name__, str(exc)))
    return out


@pytest.mark.parametrize("seed", [11, 12])
def test_compiled_search_gives_the_pure_floats(monkeypatch, seed):
    """2 x 1500 random cases x 3 horizons (T, 0.3 T, 3 T) and a finer initial window:
    every first-impact time (or None) equal bit for bit; the cases do hit the wall, near
    grazing too (first impacts with v_w- below 1e-4 d* omega)."""
    cases = _random_cases(seed, 1500)
    differ, hits, grazing = [], 0, 0
    for m, flow, tau0, z in cases:
        for horizon, step in ((m.period, None), (0.3 * m.period, None), (3.0 * m.period, None),
                              (m.period, m.period / 40.0)):
            pure, compiled = _both(monkeypatch, lambda: ndof_impact.next_impact(
                flow, tau0, z, horizon, step))
            if pure != compiled or type(pure) is not type(compiled):
                differ.append((m.n, tau0, z.tolist(), horizon, pure, compiled))
            if pure is not None and horizon == m.period and step is None:
                hits += 1
                zi = flow.transition(pure) @ z
                v = flow.wall_velocity(tau0 + m.omega * pure, zi)
                grazing += v < 1e-4 * flow.d_star * m.omega
    assert differ == []
    assert hits > 500 and grazing > 20


def test_starts_on_and_beyond_the_wall(monkeypatch):
    """A start within the gap's rounding of the wall (leaving, arriving, at rest) and one
    beyond it: the same answer, and the same InitialStateError message, from both."""
    rng = np.random.default_rng(5)
    checked = beyond = 0
    for m, flow, _tau0, _z in _random_cases(7, 200):
        n, w = m.n, m.i_w
        tau = float(rng.uniform(0.0, 2.0 * math.pi))
        wall_x, rest_v = flow.on_wall(tau)
        for dx, dv in ((0.0, 0.0), (0.0, 0.1), (0.0, -0.1), (1e-3, 0.0), (-1e-15, 1e-15)):
            z = 0.1 * flow.d_star * rng.normal(size=2 * n)
            z[w] = wall_x + dx * flow.d_star
            z[n + w] = rest_v + dv * flow.d_star * m.omega
            pure, compiled = _both(monkeypatch, lambda: ndof_impact.next_impact(
                flow, tau, z, m.period))
            assert pure == compiled and type(pure) is type(compiled), (m.n, tau, z, dx, dv)
            beyond += isinstance(pure, tuple)
            checked += 1
    assert checked == 1000 and beyond >= 150


@pytest.mark.parametrize("seed", [21])
def test_advance_through_impacts_gives_the_pure_segment(monkeypatch, seed):
    """advance over two periods from 400 random cases (impacts, chattering summed into
    sticking, releases): the final state, every impact and the monodromy equal bit for
    bit with the compiled search and the pure one."""
    impacts = 0
    for m, flow, tau0, z in _random_cases(seed, 400):
        pure, compiled = _both(monkeypatch, lambda: ndof_impact.advance(
            flow, tau0, z, 2.0 * m.period, monodromy=True, max_impacts=200))
        if isinstance(pure, tuple) and isinstance(pure[0], str):
            assert pure == compiled
            continue
        assert pure.z.tobytes() == compiled.z.tobytes() and pure.tau == compiled.tau
        assert pure.impacts == compiled.impacts
        assert pure.monodromy.tobytes() == compiled.monodromy.tobytes()
        impacts += len(pure.impacts)
    assert impacts > 300


def test_the_environment_chooses_the_pure_path(monkeypatch):
    """GRAZING_KERNEL=python: the n-DOF core searches in Python even with the compiled
    search loaded (the reference path, as for the 1-DOF kernel)."""
    monkeypatch.setenv(kernel.ENV, "python")
    assert kernel.modal_search() is None
    monkeypatch.setenv(kernel.ENV, "auto")
    assert kernel.modal_search() is not None

"""The compiled n-DOF event search, flow with impacts and model filter's events
(oscillator/kernel/compiled_modal.py, issue 32) against the pure path
(oscillator/ndof/impact.py and dynamics/estimation/motion.py with GRAZING_KERNEL=python),
run side by side in one process: the same floats, case by case.

Yardstick: the pure search, itself tested against the dense-grid brute force and the
50-digit reference (tests/test_ndof_impact.py). The cases are that file's seeded
generator (random models n = 1..3 with non-proportional damping; large transients,
starts near X** down to 1e-12, and constructed near-grazing humps of g with a maximum at
d +- 1e-10 .. 1e-1 relative), three horizons each, plus starts on the wall and beyond it.
"""

import dataclasses
import math
from pathlib import Path

import numba
import numpy as np
import pytest

from grazing_control.dynamics.estimation import motion
from grazing_control.oscillator import kernel
from grazing_control.oscillator.ndof import impact as ndof_impact
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from test_ndof_impact import _random_cases, _random_model

ROOT = Path(__file__).resolve().parents[1]

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


def _segment_key(seg):
    """An advance's segment as bytes and floats (equal iff bit for bit)."""
    return seg.z.tobytes(), seg.tau, seg.impacts


@pytest.mark.parametrize("seed", [31])
def test_compiled_advance_gives_the_pure_segment(monkeypatch, seed):
    """advance without the monodromy (what the plant and the model filter run) over one
    and three periods from 1500 random cases (large transients, starts near X**,
    near-grazing humps): the final state, phase and every impact equal bit for bit with
    the compiled flow (kernel.modal_advance) and the pure one. The compiled path itself
    ran (not the fallback) in most cases, through impacts near grazing too; the cases it
    leaves to the pure path (sticks, contacts at rest) are there as well."""
    compiled = kernel.modal_advance()
    differ, ran, fell_back, impacts, grazing = [], 0, 0, 0, 0
    for m, flow, tau0, z in _random_cases(seed, 1500):
        for duration in (m.period, 3.0 * m.period):
            pure, comp = _both(monkeypatch, lambda: ndof_impact.advance(
                flow, tau0, z, duration, max_impacts=500))
            if isinstance(pure, tuple) and isinstance(pure[0], str):
                if pure != comp:
                    differ.append((m.n, tau0, z.tolist(), duration, pure, comp))
                continue
            if _segment_key(pure) != _segment_key(comp):
                differ.append((m.n, tau0, z.tolist(), duration, pure, comp))
            direct = compiled(ndof_impact.search_constants(flow), float(tau0), z, duration,
                              1e-6 * m.period, 500)
            if direct is None:
                fell_back += 1
                continue
            ran += 1
            impacts += len(pure.impacts)
            grazing += sum(i.v_minus < 1e-4 * flow.d_star * m.omega for i in pure.impacts)
    assert differ == []
    assert ran > 2500 and fell_back > 0 and impacts > 2000 and grazing > 20


def _trajectory_cases(seed, count):
    """count random model filter periods (model n = 1..3, r and the actuated coordinate
    random; z0 at Pi2 a large transient, near X**, or on a near-grazing hump of g reached
    inside the period; the correction a kick or a pulse of width 0.01 .. 0.2 T, with or
    without a force limit, at a random delay; 60 samples on (0, T])."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        M, C, K, f, omega, i_w = _random_model(rng)
        n = len(f)
        try:
            m = NdofModel(M=M, C=C, K=K, f=f, omega=omega, i_w=i_w,
                          r=float(rng.uniform(0.3, 0.95)), i_a=int(rng.integers(n)),
                          pi2_offset=float(rng.uniform(0.01, 2 * math.pi - 0.01)))
            flow = NdofFlow.of(m)
        except ParameterError:
            continue
        d_star = flow.d_star
        dd = d_star * [-rng.uniform(0, 2), rng.choice([-1, 1]) * 10 ** rng.uniform(-12, -2),
                       rng.uniform(-0.5, 0.5)][rng.integers(3)]
        m = dataclasses.replace(m, delta_d=float(dd))
        flow = NdofFlow.of(m)
        kind = rng.integers(3)
        if kind == 0:
            z = 10 ** rng.uniform(-1, 0.5) * d_star * rng.normal(size=2 * n)
        elif kind == 1:
            z = 10 ** rng.uniform(-12, -3) * d_star * rng.normal(size=2 * n)
        else:  # a hump of g with its maximum at d +- delta, s after Pi2
            s = rng.uniform(0.02, 0.98) * m.period
            tau_m = (flow.tau2 + omega * s) % (2 * math.pi)
            delta = rng.choice([-1, 1]) * 10 ** rng.uniform(-10, -1) * (d_star + abs(dd))
            zm = 10 ** rng.uniform(-6, 0) * d_star * rng.normal(size=2 * n)
            wall_x, rest_v = flow.on_wall(tau_m)
            zm[i_w], zm[n + i_w] = wall_x + delta, rest_v
            z = flow.transition(-s) @ zm
        if not flow.gap(flow.tau2, z) < 0.0:
            continue
        correction = float(rng.choice([0.0, 1.0, 1e-3]) * rng.normal() * d_star * omega)
        width = float(rng.choice([0.0, rng.uniform(0.01, 0.2) * m.period]))
        force_limit = float(rng.choice([math.inf, abs(rng.normal()) * d_star]))
        delay = float(rng.uniform(0.0, 0.9) * m.period)
        samples = np.sort(rng.uniform(0.0, m.period, 60))
        out.append((m, z, samples, correction, delay, width, force_limit))
    return out


@pytest.mark.parametrize("seed", [41])
def test_compiled_model_filter_period_gives_the_pure_floats(monkeypatch, seed):
    """motion.modal_trajectory, 1500 random periods with kicks and pulses (width > 0,
    clipped or not): the compiled path (kernel=True: kernel.modal_events and the compiled
    samples) and the pure one (kernel=False, GRAZING_KERNEL=python) give every output
    (states and Jacobians at the samples, the end, its monodromy, the impacts) bit for
    bit, or the same error. The compiled events ran in most periods, with impacts, near
    grazing and in pulses."""
    differ, ran, fell_back, impacts, grazing, pulses = [], 0, 0, 0, 0, 0
    for m, z, samples, correction, delay, width, limit in _trajectory_cases(seed, 1500):
        def period(kernel_on):
            return motion.modal_trajectory(m, z, samples, correction, delay, m.period, width,
                                           limit, kernel=kernel_on)
        monkeypatch.setenv(kernel.ENV, "python")
        try:
            pure = period(False)
        except ValueError as exc:
            pure = (type(exc).__name__, str(exc))
        monkeypatch.setenv(kernel.ENV, "auto")
        try:
            comp = period(True)
        except ValueError as exc:
            comp = (type(exc).__name__, str(exc))
        if isinstance(pure[0], str) or isinstance(comp[0], str):
            if pure != comp:
                differ.append((m, z.tolist(), pure, comp))
            continue
        if [np.asarray(a).tobytes() for a in pure[:4]] != [np.asarray(a).tobytes()
                                                           for a in comp[:4]] \
                or pure[4] != comp[4]:
            differ.append((m, z.tolist(), correction, delay, width, limit))
        flow = motion.modal_flow(m)
        ma = motion.actuated_mass(flow) if width > 0.0 else 1.0
        legs = motion.correction_legs(correction, delay, m.period, width, limit / ma)
        if motion._compiled_modal_events(flow, np.array(z), legs, ma) is None:
            fell_back += 1
            continue
        ran += 1
        impacts += len(pure[4])
        grazing += sum(v < 1e-4 * flow.d_star * m.omega for _t, _p, v, _v in pure[4])
        pulses += width > 0.0 and correction != 0.0 and len(pure[4]) > 0
    assert differ == []
    assert ran > 1300 and impacts > 900 and grazing > 15 and pulses > 200


class _Recorder:
    """compiled_modal's entry points, recording the numba types of their arguments."""

    def __init__(self, km):
        self.km, self.types = km, {}
        for name in ("STATUS_OK", "NONE", "STATUS_BEYOND_WALL", "search_stack"):
            setattr(self, name, getattr(km, name))

    def __getattr__(self, name):
        f = getattr(self.km, name)

        def call(*args):
            self.types.setdefault(name, set()).add(tuple(numba.typeof(a) for a in args))
            return f(*args)
        return call


def test_the_warm_up_loads_what_the_model_filter_calls(monkeypatch):
    """kernel.warm_up_modal (the controller's start, the zygote's) calls each compiled
    entry point with the argument types of the calls that the plant and the model filter
    make (a kick and a pulse on the two-mass chain, impacts): a node never compiles at its
    first section."""
    from grazing_control.oscillator.kernel import compiled_modal as km
    from grazing_control.oscillator.ndof.model import load_model

    warm = _Recorder(km)
    kernel._modal_first_calls(warm)
    real = _Recorder(km)
    monkeypatch.setattr(kernel, "_modal", real)
    model = dataclasses.replace(load_model(ROOT / "config" / "models" / "two_mass_chain.yaml"),
                                delta_d=-1e-4)
    flow = NdofFlow.of(model)
    z = 1e-3 * flow.d_star * np.array([1.0, -0.5, 0.3, 0.2])
    samples = np.linspace(0.01, 1.0, 50) * model.period
    impacts = len(ndof_impact.advance(flow, flow.tau2, z, 3.0 * model.period).impacts)
    ndof_impact.next_impact(flow, flow.tau2, z, model.period)
    for width in (0.0, 0.01 * model.period):
        out = motion.modal_trajectory(model, z, samples, 1e-3, 0.3 * model.period,
                                      model.period, width, kernel=True)
        impacts += len(out[4])
    assert impacts > 2
    assert set(real.types) == {"next_impact", "advance", "modal_events"}
    for name, types in real.types.items():
        assert types <= warm.types[name], (name, types - warm.types[name])

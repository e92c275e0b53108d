"""Tests of grazing_control.oscillator.kernel: the compiled exact kernel against the pure-Python core.

The kernel mirrors grazing_control.oscillator.impact and simulate.period_step operation by
operation, so on every scene it must give the same impact counts and Pi2 sequences as
the reference path (here: within 1e-13, and in practice bit for bit), up to where
chaos separates any two correct simulators; the 50-digit mpmath tests of
tests/test_impact.py are run again through the kernel; and a differential fuzz test
compares single periods over thousands of random seeded cases.
"""

import ast
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import test_impact
from grazing_control.oscillator import impact, kernel
from grazing_control.dynamics.simulation import simulate as simulate_module
from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.flow import to_deviation
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.simulation.simulate import simulate

STUDY = OscillatorParams()
WALL = OscillatorParams.from_d(0.5, r=0.5)  # d < 1: chattering and sticking
TOL = 1e-13


def _reference_step(p, dx, dv, dvc=0.0, delay=0.0):
    """simulate.period_step on the pure-Python core (the reference path)."""
    if delay == 0.0:
        return impact.advance(p, p.tau2, dx, dv + dvc, p.period)
    first = impact.advance(p, p.tau2, dx, dv, delay)
    tau = (p.tau2 + p.omega * delay) % (2 * math.pi)
    second = impact.advance(p, tau, first.dx, first.dv + dvc, p.period - delay)
    return impact.Segment(second.dx, second.dv, first.impacts + [
        i._replace(dt=i.dt + delay, release=i.release + delay) for i in second.impacts], None)


def _same_segment(a, b, scale=1.0):
    """Same impact count, end state and impacts within TOL (relative to ``scale``)."""
    assert len(a.impacts) == len(b.impacts)
    tol = TOL * scale
    assert abs(a.dx - b.dx) <= tol and abs(a.dv - b.dv) <= tol, (a.dx - b.dx, a.dv - b.dv)
    for i, j in zip(a.impacts, b.impacts):
        assert i.sticking == j.sticking
        assert abs(i.dt - j.dt) <= tol and abs(i.v_minus - j.v_minus) <= tol
        assert abs(i.v_plus - j.v_plus) <= tol
        assert abs((i.phase - j.phase + math.pi) % (2 * math.pi) - math.pi) <= tol
        assert (math.isnan(i.release) and math.isnan(j.release)) or i.release == j.release \
            or abs(i.release - j.release) <= tol


# ---------------------------------------------------------- the study's scenes
def _design(p):
    return Gains(degenerate_c1(p, -1.0), -1.0)


def _reference_run(p, periods, gains=None, control_after=None, delay=0.0):
    dx = dv = 0.0
    dev, counts = [], []
    for k in range(periods):
        dev.append((dx, dv))
        dvc = gains.c1 * dx + gains.c2 * dv if gains and k >= control_after else 0.0
        seg = _reference_step(p, dx, dv, dvc, delay)
        counts.append(len(seg.impacts))
        dx, dv = seg.dx, seg.dv
    return np.array(dev), np.array(counts)


# compared: every period where the motion converges; the first 15 where it is chaotic
# (test_impact: the reference agrees with mpmath to 1e-12 there, and rounding errors
# grow ~x4 per period afterwards, so two correct simulators part after ~25 periods)
SCENES = [
    # delta_d, periods, controlled from, compared periods
    (-1e-3, 300, None, 300),
    (-9e-6, 300, None, 15),
    (-5e-6, 300, None, 15),
    (-9e-6, 300, 0, 300),
    (-5e-6, 300, 0, 300),
    (-5e-6, 1200, 1000, 15),
]


@pytest.mark.parametrize("delta_d,periods,control_after,compared", SCENES)
def test_study_scenes_match_the_reference_path(delta_d, periods, control_after, compared):
    """The kernel's simulate loop against the Python core period by period: equal impact
    counts and Pi2 deviations within 1e-13 over the compared periods."""
    p = STUDY.with_(delta_d=delta_d)
    gains = _design(p) if control_after is not None else None
    ref_dev, ref_counts = _reference_run(p, periods, gains, control_after)
    dev, corr, counts, imps, end = kernel.simulate_exact(p, periods, 0.0, 0.0, gains, control_after)
    assert np.array_equal(counts[:compared], ref_counts[:compared])
    assert np.max(np.abs(dev[:compared] - ref_dev[:compared])) <= TOL
    assert imps.shape == (counts.sum(), 5) and np.all(imps[:, 3] > 0)
    if control_after is not None:
        on = np.arange(periods) >= control_after
        assert np.array_equal(corr[on], gains.c1 * dev[on, 0] + gains.c2 * dev[on, 1])
        assert np.all(corr[~on] == 0.0)


def test_same_floating_point_operations_bit_for_bit():
    """Stronger than the 1e-13 above: the kernel performs the core's operations in the
    core's order (libm's exp, sin, cos, pow included), so even the chaotic scene, which
    amplifies a one-ulp difference to O(1) within ~30 periods, is bit-identical over
    300 periods. A port that reorders an expression shows up here first."""
    p = STUDY.with_(delta_d=-5e-6)
    ref_dev, ref_counts = _reference_run(p, 300)
    dev, _corr, counts, _imps, _end = kernel.simulate_exact(p, 300, 0.0, 0.0)
    assert np.array_equal(counts, ref_counts) and np.array_equal(dev, ref_dev)


@pytest.mark.parametrize("delay", [0.3, 2.0])
def test_delayed_correction_matches_the_reference_path(delay):
    """The kick applied ``delay`` after the sample (simulate.period_step(delay=...))."""
    p = STUDY.with_(delta_d=-5e-6)
    gains = _design(p)
    ref_dev, ref_counts = _reference_run(p, 40, gains, 0, delay)
    dev, _corr, counts, _imps, _end = kernel.simulate_exact(p, 40, 0.0, 0.0, gains, 0, delay=delay)
    assert np.array_equal(counts[:15], ref_counts[:15])
    assert np.max(np.abs(dev[:15] - ref_dev[:15])) <= TOL


@pytest.mark.parametrize("tau,v,duration", [(0.0, 0.01, 1.5), (0.0, 0.01, 3.0), (5.5, 0.0, 4.0),
                                            (5.9, 0.0, 3.0), (0.0, 0.0, 2.0)])
def test_chattering_and_sticking_match_the_reference_path(tau, v, duration):
    """The chattering sequence, its summation, sticking and release (test_impact's cases)."""
    z = to_deviation(WALL, tau, WALL.d, v)
    _same_segment(kernel.advance(WALL, tau, *z, duration), impact.advance(WALL, tau, *z, duration))


def test_simulate_uses_the_kernel_and_equals_the_reference(monkeypatch):
    """simulate() on the kernel (default) and on the core (GRAZING_KERNEL=python) agree."""
    p = STUDY.with_(delta_d=-9e-6)
    gains = _design(p)
    fast = simulate(p, 200, gains=gains, control_after=100)
    monkeypatch.setenv(kernel.ENV, "python")
    calls = []
    monkeypatch.setattr(kernel, "simulate_exact", lambda *a, **k: calls.append(a))
    slow = simulate(p, 200, gains=gains, control_after=100)
    assert calls == []  # the reference path did not touch the kernel
    assert np.array_equal(fast.impacts_per_period[:15], slow.impacts_per_period[:15])
    assert np.max(np.abs(fast.pi2_deviation[:15] - slow.pi2_deviation[:15])) <= TOL
    # controlled from 100 on, both converge onto the same 1/1 orbit
    assert np.max(np.abs(fast.pi2_deviation[-20:] - slow.pi2_deviation[-20:])) < 1e-12
    assert fast.impacts.shape == slow.impacts.shape and fast.final_deviation[0] == \
        pytest.approx(slow.final_deviation[0], abs=1e-12)


def test_period_step_runs_on_the_kernel(monkeypatch):
    calls = []
    real = kernel.period_step
    monkeypatch.setattr(kernel, "period_step", lambda *a, **k: calls.append(1) or real(*a, **k))
    seg = simulate_module.period_step(STUDY.with_(delta_d=-1e-3), 0.0, 0.0, 0.01, delay=0.5)
    assert calls == [1]
    _same_segment(seg, _reference_step(STUDY.with_(delta_d=-1e-3), 0.0, 0.0, 0.01, 0.5))
    with pytest.raises(ValueError, match="delay=.*valid range is 0 <= delay < T"):
        simulate_module.period_step(STUDY, 0.0, 0.0, 0.0, delay=-1.0)


# ------------------------------------------------- errors, as the core reports them
def test_errors_are_the_cores():
    tau = WALL.lag + 0.3
    dx, dv = to_deviation(WALL, tau, WALL.d, -0.1)
    with pytest.raises(impact.InitialStateError, match=r"beyond the wall: x - d = .*valid: x <= d"):
        kernel.advance(WALL, tau, dx + 1e-6, dv, 1.0)
    with pytest.raises(impact.InitialStateError):
        kernel.next_impact(WALL, tau, dx + 0.3, dv, 1.0)
    with pytest.raises(impact.ImpactCapError, match=r"more than max_impacts=5 impacts"):
        kernel.advance(WALL, WALL.tau2, 0.0, 0.0, 50 * WALL.period, max_impacts=5)
    with pytest.raises(ValueError, match="not finite"):
        kernel.period_step(STUDY, math.nan, 0.0)
    with pytest.raises(ValueError, match="not finite"):
        kernel.simulate_exact(STUDY, 3, 0.0, math.inf)


@pytest.mark.parametrize("gains,deviation", [(Gains(1e300, 0.0), (1.0, 0.0)),
                                             (Gains(0.0, 1e12), (0.0, 1e-3)),
                                             (Gains(-3e5, 2e5), (1e-6, 0.0)),
                                             (Gains(0.0, 1.0), (0.0, 9e149))])
def test_simulate_errors_are_the_same_on_both_paths(gains, deviation, monkeypatch):
    """A controller that blows the state up: simulate stops with the same
    NonFiniteStateError message (the correction's or the state's, and the period) on the
    kernel and on the core."""
    p = STUDY.with_(delta_d=-1e-3)
    messages = []
    for path in ("numba", "python"):
        monkeypatch.setenv(kernel.ENV, path)
        with pytest.raises(impact.NonFiniteStateError) as err:
            simulate(p, 200, deviation=deviation, gains=gains, control_after=0)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "period" in messages[0], messages
    if deviation[1] == 9e149:  # the kicked state, not the kick, is too large
        assert messages[0].startswith("at period 0: the start state is absurdly large")


def test_progress_bar_on_the_kernel_path(capsys):
    res = simulate(STUDY.with_(delta_d=-1e-3), 120_000, progress=True)
    assert res.impacts_per_period.shape == (120_000,) and "period" in capsys.readouterr().err


def test_environment_variable_chooses_the_path(monkeypatch):
    monkeypatch.setenv(kernel.ENV, "python")
    assert kernel.use_kernel() is False
    monkeypatch.setenv(kernel.ENV, "numba")
    assert kernel.use_kernel() is True
    monkeypatch.delenv(kernel.ENV)
    assert kernel.use_kernel() is kernel.available() is True
    monkeypatch.setenv(kernel.ENV, "fortran")
    with pytest.raises(ValueError, match=r"GRAZING_KERNEL='fortran' is invalid: valid values are"):
        kernel.use_kernel()


def test_fallback_without_numba_runs_the_core(tmp_path):
    """With numba hidden from the import system the package falls back to the core."""
    code = (
        "import sys\n"
        "sys.modules['numba'] = None  # import numba now fails, as if not installed\n"
        "from grazing_control.oscillator import kernel\n"
        "from grazing_control.oscillator.params import OscillatorParams\n"
        "from grazing_control.dynamics.simulation.simulate import simulate\n"
        "assert not kernel.available() and not kernel.use_kernel()\n"
        "r = simulate(OscillatorParams(delta_d=-1e-3), 5)\n"
        "print(int(r.impacts_per_period.sum()))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "PYTHONPATH": os.getcwd()})
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["5"]


def test_ctrl_c_while_the_kernel_compiles_is_delivered_once_it_is_loaded(tmp_path):
    """A SIGINT during numba's first compilation (an empty cache: several seconds) is held
    back and delivered as a KeyboardInterrupt once the kernel is loaded: neither lost in
    llvmlite's callbacks nor a crash at exit."""
    import signal

    # The child says when it is compiling (inside the hold, before the first calls); a
    # fixed sleep raced the child's start-up on a loaded machine (the signal came before
    # the hold, or after the compile). It compiles one entry point, next_impact (the
    # event search and the flow: 6 s of CPU on a slow host, 1/5 of all of them): the
    # signal lands inside numba's compiler as it did with every entry point.
    code = ("from grazing_control.oscillator import kernel\n"
            "from grazing_control.oscillator.params import OscillatorParams\n"
            "def compiling():\n"
            "    print('compiling', flush=True)\n"
            "    p = OscillatorParams(delta_d=-1e-3)\n"
            "    kernel.next_impact(p, p.tau2, 0.0, 0.0, p.period)\n"
            "kernel._first_calls = compiling\n"
            "kernel.warm_up()\n"
            "print('not interrupted', flush=True)\n")
    env = {**os.environ, "PYTHONPATH": os.getcwd(), "NUMBA_CACHE_DIR": str(tmp_path)}
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout.readline() == "compiling\n"  # numba imported, compiling
    proc.send_signal(signal.SIGINT)
    try:    # a hang guard: a cold compile took 14 s at load 3, and scales with the load
        out, err = proc.communicate(timeout=600)
    finally:
        proc.kill()     # no compiling child left behind by a failure
    assert proc.returncode in (1, -signal.SIGINT), err
    assert "not interrupted" not in out
    assert err.rstrip().endswith("KeyboardInterrupt") and "Exception ignored" not in err, err
    assert "_sigint_held" in err  # delivered when the load ended, not inside numba
    assert any(tmp_path.rglob("*.nbi"))  # the compilation finished and was cached


# ------------------------------------------------ numba's cache over the kernel's files
def _kernel_dispatchers():
    """Every compiled function defined in a file of oscillator/kernel/."""
    from numba.core.registry import CPUDispatcher

    from grazing_control.oscillator.kernel import (compiled, compiled_contact, compiled_modal,
                                                   interval_search)

    return [f for m in (compiled, compiled_modal, compiled_contact, interval_search)
            for f in vars(m).values()
            if isinstance(f, CPUDispatcher) and f.py_func.__module__ == m.__name__]


def test_every_kernel_function_is_cached_under_the_folders_stamp():
    """The search of interval_search.py runs the models' evaluators of compiled.py and
    compiled_modal.py: each function's cache is stamped by the whole folder
    (kernel/caching.py), not by its own file as numba's locators do."""
    from grazing_control.oscillator.kernel import caching

    functions = _kernel_dispatchers()
    assert {f.py_func.__module__.rsplit(".", 1)[1] for f in functions} == {
        "compiled", "compiled_modal", "compiled_contact", "interval_search"}
    for f in functions:
        assert isinstance(f._cache._impl.locator, caching.LOCATORS), f.__name__
        assert f._cache._impl.locator.get_source_stamp() == caching.folder_stamp()
    # and in every process, whichever module it imports first: a module with a jit of its
    # own would be stamped by its file where caching.py was not imported before it, and
    # two such processes would overwrite each other's cache index in turn
    for path in Path(caching.FOLDER).glob("*.py"):
        if path.name != "caching.py":
            calls = [n.func for n in ast.walk(ast.parse(path.read_text()))
                     if isinstance(n, ast.Call)]
            assert not [f for f in calls if getattr(f, "attr", getattr(f, "id", None))
                        in ("njit", "jit", "generated_jit")], f"{path.name}: use caching.jit"


def test_a_callees_edit_invalidates_its_callers_cache(tmp_path, monkeypatch):
    """numba keys a cached function on its own file: with its own locators, a caller whose
    callee lives in another file keeps loading the callee's old machine code after that
    file changed (here g(1.0) = 2.0 after f became x + 2). A copy of kernel/caching.py in
    a package of two such files, each import a fresh one (as a new process would): the
    cache is written, loaded, and after the callee's edit rejected and written anew."""
    from numba.core import caching as numba_caching

    from grazing_control.oscillator.kernel import caching

    monkeypatch.setattr(numba_caching.CacheImpl, "_locator_classes",
                        list(numba_caching.CacheImpl._locator_classes))
    # no .pyc: the callee's edit keeps its size, and within the same second as its first
    # import Python would load the old bytecode (its check is the source's mtime in
    # seconds and its size): g then recompiled over the old f (a fresh clone's rerun)
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    package = tmp_path / "kernel_copy"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "caching.py").write_text(open(caching.__file__).read())
    callee = "from .caching import jit\n\n\n@jit\ndef f(x):\n    return x + {}\n"
    (package / "callee.py").write_text(callee.format("1.0"))
    (package / "caller.py").write_text("from .caching import jit\nfrom .callee import f\n\n\n"
                                       "@jit\ndef g(x):\n    return f(x)\n")
    monkeypatch.syspath_prepend(str(tmp_path))

    def fresh_g():
        for name in [m for m in sys.modules if m.split(".")[0] == "kernel_copy"]:
            del sys.modules[name]
        from kernel_copy.caller import g

        value = g(1.0)
        return value, sum(g.stats.cache_hits.values()), sum(g.stats.cache_misses.values())

    try:
        assert fresh_g() == (2.0, 0, 1)      # compiled, written
        assert fresh_g() == (2.0, 1, 0)      # loaded from the cache
        (package / "callee.py").write_text(callee.format("2.0"))
        assert fresh_g() == (3.0, 0, 1)      # the index is stale: compiled anew
        assert fresh_g() == (3.0, 1, 0)
    finally:
        for name in [m for m in sys.modules if m.split(".")[0] == "kernel_copy"]:
            del sys.modules[name]


# ------------------------------------------------ the mpmath tests, through the kernel
@pytest.fixture(autouse=True)
def _core_is_the_kernel(monkeypatch):
    """The test_impact tests re-exported below run with advance and next_impact of the
    kernel in place of the core's (their module globals are patched; the tests of this
    module call the core as ``impact.advance``, unaffected)."""
    monkeypatch.setattr(test_impact, "advance", _kernel_advance)
    monkeypatch.setattr(test_impact, "next_impact", kernel.next_impact)


def _kernel_advance(p, tau0, dx, dv, duration, *, monodromy=False, **kwargs):
    assert not monodromy, "the kernel has no monodromy: such tests stay with the core"
    return kernel.advance(p, tau0, dx, dv, duration, **kwargs)


# 50-digit reference: low-velocity impacts (v- down to 1e-10), near misses at 1e-20,
# starts on the wall, chattering against the reference's chain of impacts, sticking and
# release, and issue 20's reproduction. The 600 random chattering sequences against the
# exact continuation, the 100 periods with impacts and the chaotic scene's first 15
# periods run through the kernel in test_impact's tests themselves (one 50-digit run for
# both paths; re-exported here, it was computed twice: 3.6 CPU-s), and so does the
# differential test against the dense grid (tests/brute_impacts.py: one truth, 1.4
# CPU-s, for both; the kernel's next_impact on both seeds, seed 7 only here before).
test_mpmath_low_velocity_impact = \
    test_impact.test_low_velocity_impact_found_with_right_time_and_velocity
test_mpmath_near_miss = test_impact.test_near_miss_is_not_an_impact
test_mpmath_start_on_wall_into_it = \
    test_impact.test_start_on_wall_moving_into_it_is_an_immediate_impact
test_mpmath_start_on_wall_leaving = test_impact.test_start_on_wall_moving_away_leaves
test_mpmath_no_redetection = test_impact.test_no_redetection_after_impacts
test_mpmath_chattering = test_impact.test_chattering_sequence_matches_reference_then_sticks
test_mpmath_release = \
    test_impact.test_chattering_then_release_and_independent_of_the_duration
test_mpmath_sticking = \
    test_impact.test_at_rest_on_the_wall_sticks_and_releases_when_the_force_changes_sign
test_mpmath_concave_hump = test_impact.test_concave_hump_above_the_wall_is_found_issue_7
test_tangency_below_rounding = test_impact.test_tangency_below_rounding_is_not_an_impact_issue_7
test_mpmath_bounce_leaving_the_wall = \
    test_impact.test_bounce_leaving_the_wall_is_not_a_contact_at_rest_issue_20
test_non_finite_state = test_impact.test_non_finite_or_absurd_state_raises_a_clear_error


def test_chattering_sequences_bit_for_bit():
    """test_impact's 600 random chattering sequences (plus issue 20's): the kernel's
    impacts and end state are the core's, bit for bit (a flight leaving the wall within
    the gap's rounding starts on it in both)."""
    p, tau, v = test_impact.ISSUE_20
    cases = test_impact._chatter_cases(20, 600) + [(p, tau, v, 1.0)]
    for p, tau, v, duration in cases:
        z = to_deviation(p, tau, p.d, v)
        ref = impact.advance(p, tau, *z, duration)
        got = kernel.advance(p, tau, *z, duration)
        assert (got.dx, got.dv) == (ref.dx, ref.dv)
        assert [i._replace(release=0.0) for i in got.impacts] == \
            [i._replace(release=0.0) for i in ref.impacts]
        assert [str(i.release) for i in got.impacts] == [str(i.release) for i in ref.impacts]


# simulate.period_step runs on the kernel by default, so test_impact's scene tests
# through period_step (no passage through the wall, sticking carried over Pi2 samples,
# v- > 0 for every impact) test the kernel already; here they run on both paths.
@pytest.mark.parametrize("path", ["numba", "python"])
def test_sticking_carries_over_a_period_boundary_on_both_paths(path, monkeypatch):
    monkeypatch.setenv(kernel.ENV, path)
    test_impact.test_sticking_carries_over_a_period_boundary_issue_7()


# ------------------------------------------------------------- differential fuzz
def _random_case(rng):
    """A random model, start state and correction; a quarter near grazing of the study."""
    kind = rng.integers(4)
    if kind == 0:  # the study's model near grazing
        p = STUDY.with_(delta_d=-10.0 ** rng.uniform(-10, -2))
    elif kind == 1:  # the study's model, either side
        p = STUDY.with_(delta_d=rng.uniform(-0.5, 0.1))
    elif kind == 2:  # another model, wall possibly at d < 1 (sticking)
        p = OscillatorParams.from_d(rng.uniform(-0.5, 2.0), zeta=rng.uniform(0.005, 0.3),
                                    r=rng.uniform(0.1, 0.95), omega=rng.uniform(0.3, 3.0))
    else:
        p = OscillatorParams(zeta=rng.uniform(0.005, 0.3), r=rng.uniform(0.1, 0.95),
                             omega=rng.uniform(0.3, 3.0), delta_d=rng.uniform(-1.0, 0.2))
    scale = 10.0 ** rng.uniform(-9, 0)
    dx, dv = rng.normal(size=2) * scale
    dvc = rng.normal() * scale if rng.random() < 0.3 else 0.0
    delay = rng.uniform(0, p.period) if dvc and rng.random() < 0.5 else 0.0
    return p, float(dx), float(dv), float(dvc), float(delay)


def _random_wall_case(rng):
    """At the wall (x = d) at a random phase, moving in, out, or at rest: advance's start."""
    p = OscillatorParams.from_d(rng.uniform(-0.5, 1.5), zeta=rng.uniform(0.005, 0.3),
                                r=rng.uniform(0.1, 0.95), omega=rng.uniform(0.3, 3.0))
    tau = rng.uniform(0, 2 * math.pi)
    v = [0.0, 1e-9, -1e-9, 0.1, -0.1][rng.integers(5)]
    return p, tau, *to_deviation(p, tau, p.d, v), rng.uniform(0.1, 3.0) * p.period


def _outcome(step, *args):
    try:
        return step(*args)
    except (impact.ImpactCapError, impact.InitialStateError) as exc:
        return type(exc)


def test_differential_fuzz_single_periods():
    """3000 seeded random periods, 1000 segments from the wall, 1500 near-grazing humps,
    transients and starts at grazing: the same exception, or the same impact count and
    end state and impacts within 1e-13 (relative to the state's size)."""
    rng = np.random.default_rng(20261122)
    kinds = {"impacts": 0, "errors": 0, "sticking": 0}
    for _ in range(3000):
        p, dx, dv, dvc, delay = _random_case(rng)
        ref = _outcome(_reference_step, p, dx, dv, dvc, delay)
        got = _outcome(lambda *a: kernel.period_step(*a[:4], delay=a[4]), p, dx, dv, dvc, delay)
        if isinstance(ref, type):
            assert got is ref, (p, dx, dv, dvc, delay)
            kinds["errors"] += 1
            continue
        _same_segment(got, ref, 1.0 + abs(dx) + abs(dv))
        kinds["impacts"] += bool(ref.impacts)
        kinds["sticking"] += any(i.sticking for i in ref.impacts)
    for _ in range(1000):
        p, tau, dx, dv, duration = _random_wall_case(rng)
        ref = _outcome(impact.advance, p, tau, dx, dv, duration)
        got = _outcome(kernel.advance, p, tau, dx, dv, duration)
        if isinstance(ref, type):
            assert got is ref, (p, tau, dx, dv, duration)
            kinds["errors"] += 1
            continue
        _same_segment(got, ref, 1.0 + abs(dx) + abs(dv))
        kinds["sticking"] += any(i.sticking for i in ref.impacts)
    # test_impact's random cases (transients, near X**, constructed humps at d +- 1e-10..)
    # and starts at grazing down to 1e-32 (tangencies below rounding)
    wall = [(p.with_(r=rng.uniform(0.05, 0.95)), tau0, dx, dv)
            for p, tau0, dx, dv in test_impact._random_cases(5, 1000)]
    for _ in range(500):
        size = 10 ** rng.uniform(-32, -6)
        p = STUDY.with_(delta_d=rng.choice([0.0, -size, size * 1e-3]))
        wall.append((p, p.tau2, size * rng.normal(), size * rng.normal()))
    for p, tau0, dx, dv in wall:
        ref = _outcome(impact.advance, p, tau0, dx, dv, 2 * p.period)
        got = _outcome(kernel.advance, p, tau0, dx, dv, 2 * p.period)
        if isinstance(ref, type):
            assert got is ref, (p, tau0, dx, dv)
            kinds["errors"] += 1
            continue
        _same_segment(got, ref, 1.0 + abs(dx) + abs(dv))
        kinds["impacts"] += bool(ref.impacts)
        kinds["sticking"] += any(i.sticking for i in ref.impacts)
    # the cases cover what they should
    assert kinds["impacts"] > 1000 and kinds["errors"] > 50 and kinds["sticking"] > 20, kinds

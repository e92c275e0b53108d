"""Sticking of the wall coordinate for n > 1 (issue 32; docs/theory_ndof.md section 16,
oscillator/ndof/sticking.py): the constrained flow and its release, in ``advance``.

Yardsticks: the 1-DOF core (oscillator/impact.py) for n = 1; for n = 2, 3 the 50-digit
reference tests/reference_ndof.py (``NdofRef.run``: an n x n solve for the contact force
and mpmath's expm of the augmented system, sharing no formula with the package) and
DOP853 with a stiff penalty wall (scipy); finite differences of ``advance`` for the
monodromy through a stick.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from grazing_control.oscillator import impact as impact1
from grazing_control.oscillator.ndof import NdofModel, load_model
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import ChatteringError, advance
from grazing_control.oscillator.ndof.sticking import stuck_flow
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from reference_ndof import NdofRef, load_reference

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
CHAIN = Path(__file__).parent / "models" / "two_mass_chain_w08.yaml"

#: A 3-DOF model with a full (non-diagonal) mass matrix, wall on the middle coordinate:
#: the contact force's Schur term M_wy M_yy^-1 matters (section 16, (S2)).
THREE = dict(M=[[2.0, 0.3, 0.1], [0.3, 1.5, 0.2], [0.1, 0.2, 1.0]],
             C=[[0.05, -0.01, 0.0], [-0.01, 0.04, -0.01], [0.0, -0.01, 0.03]],
             K=[[3.0, -1.0, 0.0], [-1.0, 2.5, -1.0], [0.0, -1.0, 1.5]],
             f=[0.2, 1.0, 0.4], omega=0.7, i_w=1, delta_d=-5.0, r=0.6, i_a=0)   # d* = 10.54


def _pushed_into_wall(flow, margin=0.1):
    """A phase and the deviation of a state at rest on the wall (others at their periodic
    response) whose free acceleration pushes into it by more than ``margin``."""
    m = flow.model
    n, w = m.n, m.i_w
    for tau in np.linspace(0, 2 * math.pi, 64, endpoint=False):
        z = np.zeros(2 * n)
        z[w], z[n + w] = flow.on_wall(tau)
        if flow.wall_acceleration(tau, z) > margin:
            return float(tau), z
    raise AssertionError("no phase pushes into the wall")


# --------------------------------------------------------------------- n = 1
def test_n1_sticking_is_the_1dof_sticking():
    """n = 1 (the study as a model file), 24 seeded (Delta d, r): a start at rest on the
    wall pushed into it, and one moving into it at 1e-9 .. 1e-7 (an impact whose
    chattering is summed at once): the same impacts and sticking flags, and the releases,
    the later impacts, the end state and the monodromy of the 1-DOF core to 1e-12
    (measured <= 1e-14). The summed impact's own time is ill-conditioned (position
    rounding / v-, ~1e-8 between the two cores' searches) and is compared to
    chatter_time; bounces slower than 1e-2 to 1e-9 (a bounce sequence amplifies the cores'
    different roundings, with or without a stick: measured 7e-11 at v- = 1.5e-5)."""
    base = load_model(MODELS / "study_1dof.yaml")
    rng = np.random.default_rng(3201)
    worst, slow, sticks = 0.0, 0.0, 0
    for k in range(24):
        dd, r = float(rng.uniform(-2.0, -1.0)), float(rng.uniform(0.2, 0.9))
        m = dataclasses.replace(base, delta_d=dd, r=r)
        p = OscillatorParams(zeta=0.5 * m.C[0, 0], r=r, omega=m.omega, delta_d=dd)
        flow = NdofFlow.of(m)
        while True:
            tau = float(rng.uniform(0.0, 2 * math.pi))
            if math.cos(tau) - p.d > 0.05:
                break
        z = np.array(flow.on_wall(tau))
        if k % 2:   # on the wall moving into it slowly: one impact, its chattering summed
            z[1] += 10 ** rng.uniform(-9, -7)
        seg = advance(flow, tau, z, 3 * m.period, monodromy=True)
        one = impact1.advance(p, tau, z[0], z[1], 3 * m.period, monodromy=True)
        assert len(seg.impacts) == len(one.impacts)
        err = max(abs(seg.z[0] - one.dx), abs(seg.z[1] - one.dv),
                  float(np.abs(seg.monodromy - np.reshape(one.monodromy, (2, 2))).max()))
        for a, b in zip(seg.impacts, one.impacts):
            assert a.sticking == b.sticking
            sticks += a.sticking
            if a.sticking and b.v_minus > 0.0:
                # a 1e-8 impact's time carries the position's rounding over v- (~1e-8 here,
                # from the cores' own searches): within the summation's chatter_time
                assert abs(a.dt - b.dt) < 1e-6 * m.period and abs(a.v_minus - b.v_minus) < 1e-6
            elif b.v_minus == 0.0 or b.v_minus > 1e-2:
                err = max(err, abs(a.dt - b.dt), abs(a.v_minus - b.v_minus))
            else:   # slow bounces amplify the cores' different roundings (no stick there)
                slow = max(slow, abs(a.dt - b.dt), abs(a.v_minus - b.v_minus))
            if a.sticking:
                assert math.isinf(a.release) == math.isinf(b.release)
                if math.isfinite(b.release):
                    err = max(err, abs(a.release - b.release))
        worst = max(worst, err)
    assert sticks >= 24
    assert worst < 1e-12 and slow < 1e-9


# --------------------------------------------------------------------- n >= 2
def _reference_case(ref: NdofRef, flow: NdofFlow, tau: float, z, duration: float):
    seg = advance(flow, tau, z, duration)
    X, events = ref.run(tau, list(flow.to_physical(tau, z)), duration)
    return seg, np.array([float(x) for x in X]), events


@pytest.mark.parametrize("case", ["chain", "three"])
def test_sticking_against_the_50_digit_reference(case):
    """From rest on the wall pushed into it, one period (a stick, its release, the free
    flight and the next impacts): the same events, release and impact times to 1e-12
    relative to T, impact velocities and the end state to 1e-11 of the state's scale
    (measured: chain 1.1e-16 on the release, 8e-16 on the state; the 3-DOF model with a
    full M 3.1e-15 and 8.9e-15)."""
    if case == "chain":
        m = dataclasses.replace(load_model(CHAIN), delta_d=-1.5)
        ref = load_reference(CHAIN, delta_d=-1.5)
    else:
        m = NdofModel(**THREE)
        ref = NdofRef(**THREE)
    flow = NdofFlow.of(m)
    tau, z = _pushed_into_wall(flow)
    seg, X, events = _reference_case(ref, flow, tau, z, m.period)
    assert [e[0] == "stick" for e in events] == [i.sticking for i in seg.impacts]
    assert seg.impacts[0].sticking and math.isfinite(seg.impacts[0].release)
    for e, imp in zip(events, seg.impacts):
        assert abs(float(e[1]) - imp.dt) < 1e-12 * m.period
        if e[0] == "stick":
            assert abs(float(e[2]) - imp.release) < 1e-12 * m.period
        else:
            assert abs(float(e[2]) - imp.v_minus) < 1e-11 * max(1.0, abs(imp.v_minus))
    scale = 1.0 + float(np.abs(X).max())
    assert np.abs(flow.to_physical(seg.tau, seg.z) - X).max() < 1e-11 * scale


def _penalty_run(m: NdofModel, d: float, tau0: float, X0, t_end: float, k_c: float):
    """DOP853 on M x'' + C x' + K x = f cos tau - lambda e_w with a stiff, critically
    damped penalty wall lambda = max(0, k_c (x_w - d) + c_c v_w) while x_w > d: the
    stuck wall coordinate sits k_c^-1 lambda inside the wall, released when lambda -> 0.
    Returns the physical state at t_end and the release time (last time in contact)."""
    n, w = m.n, m.i_w
    Minv = np.linalg.inv(m.M)
    c_c = 2.0 * math.sqrt(k_c * m.M[w, w])

    def rhs(t, X):
        x, v = X[:n], X[n:]
        F = m.f * math.cos(tau0 + m.omega * t) - m.C @ v - m.K @ x
        pen = x[w] - d
        if pen > 0.0:
            F[w] -= max(0.0, k_c * pen + c_c * v[w])
        return np.concatenate([v, Minv @ F])

    def leave(t, X):
        return X[w] - d
    leave.direction = -1.0

    sol = solve_ivp(rhs, (0.0, t_end), X0, method="DOP853", rtol=1e-12, atol=1e-14,
                    events=leave)
    release = float(sol.t_events[0][-1]) if len(sol.t_events[0]) else math.inf
    return sol.y[:, -1], release


def test_sticking_against_a_stiff_penalty_wall():
    """Chain from rest on the wall, to just after the release plus a free flight (no
    impact): DOP853 with a penalty wall agrees to its model error, which shrinks with k_c
    towards the rigid stick: measured release 4.6e-3, 1.5e-3, 4.6e-4 (~k_c^-1/2) and state
    6.2e-6, 6.3e-7, 6.3e-8 (~k_c^-1) at k_c = 1e5, 1e6, 1e7."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-1.5)
    flow = NdofFlow.of(m)
    tau, z = _pushed_into_wall(flow)
    seg0 = advance(flow, tau, z, m.period)
    release, t_next = seg0.impacts[0].release, seg0.impacts[1].dt
    t_end = 0.5 * (release + t_next)
    seg = advance(flow, tau, z, t_end)
    assert [i.sticking for i in seg.impacts] == [True]
    X = flow.to_physical(seg.tau, seg.z)
    d = flow.d_star + m.delta_d
    errs = []
    for k_c in (1e5, 1e7):
        Xp, rel_p = _penalty_run(m, d, tau, flow.to_physical(tau, z), t_end, k_c)
        errs.append((abs(rel_p - release), float(np.abs(Xp - X).max())))
    assert errs[1][0] < 1e-3 and errs[1][1] < 1e-6
    assert errs[1][1] < errs[0][1] / 50.0 and errs[1][0] < errs[0][0] / 5.0


def test_monodromy_through_a_stick_vs_finite_differences():
    """d z(end) / d z(start) through a stick (the constrained flow on the others, the wall
    coordinate's perturbations die; section 16): the columns of the other coordinates
    equal central differences of advance (step 1e-7) to 1e-6, over a period with the
    stick, its release and a later impact; the wall columns are 0 while stuck."""
    for m in (dataclasses.replace(load_model(CHAIN), delta_d=-1.5), NdofModel(**THREE)):
        flow = NdofFlow.of(m)
        n, w = m.n, m.i_w
        tau, z = _pushed_into_wall(flow)
        seg = advance(flow, tau, z, m.period, monodromy=True)
        assert seg.impacts[0].sticking
        cols = [j for j in range(2 * n) if j not in (w, n + w)]
        for j in cols:
            e = np.zeros(2 * n)
            e[j] = 1e-7
            fd = (advance(flow, tau, z + e, m.period).z - advance(flow, tau, z - e, m.period).z) / 2e-7
            assert np.abs(fd - seg.monodromy[:, j]).max() < 1e-6 * (1.0 + np.abs(fd).max())


def test_stuck_through_the_end_of_a_segment_carries_over():
    """A segment that ends stuck reports release = inf and ends on the wall at rest; the
    next call (chained pieces) stays stuck and releases where one long call does
    (to 1e-12 T): sticking carries over a sample, as in 1-DOF."""
    m = dataclasses.replace(load_model(CHAIN), delta_d=-1.5)
    flow = NdofFlow.of(m)
    tau, z = _pushed_into_wall(flow)
    whole = advance(flow, tau, z, m.period)
    release = whole.impacts[0].release
    first = advance(flow, tau, z, 0.5 * release)
    assert first.impacts[0].sticking and math.isinf(first.impacts[0].release)
    assert abs(flow.gap(first.tau, first.z)) < 1e-14 and abs(flow.wall_velocity(first.tau, first.z)) < 1e-14
    second = advance(flow, first.tau, first.z, m.period - 0.5 * release)
    assert second.impacts[0].sticking
    assert abs(0.5 * release + second.impacts[0].release - release) < 1e-12 * m.period
    assert np.abs(second.z - whole.z).max() < 1e-10 * (1.0 + np.abs(whole.z).max())


def test_the_contact_force_is_the_free_acceleration_over_the_inverse_mass():
    """(S2) against its definition: lambda = a_w,free / (M^-1)_ww at random states on the
    wall (section 16: the sign of lambda is that of the free acceleration), to 1e-12."""
    rng = np.random.default_rng(3202)
    for m in (dataclasses.replace(load_model(CHAIN), delta_d=-1.5), NdofModel(**THREE)):
        flow = NdofFlow.of(m)
        stuck = stuck_flow(flow)
        n, w = m.n, m.i_w
        minv = np.linalg.inv(m.M)[w, w]
        for _ in range(10):
            tau = float(rng.uniform(0, 2 * math.pi))
            z = rng.normal(size=2 * n)
            z[w], z[n + w] = flow.on_wall(tau)
            lam = stuck.force(tau, stuck.reduce(tau, z))
            assert abs(lam - flow.wall_acceleration(tau, z) / minv) < 1e-12 * (1.0 + abs(lam))


def test_a_stuck_motion_that_cannot_be_modelled_is_refused_by_name():
    """K without the wall row/column singular (the others have no equilibrium with x_w
    held): StuckFlow refuses naming K; advance turns it into ChatteringError."""
    m = NdofModel(M=[[1.0, 0.0], [0.0, 1.0]], C=[[0.05, 0.0], [0.0, 0.05]],
                  K=[[1.0, 0.0], [0.0, 0.0]], f=[1.0, 0.5], omega=0.5, i_w=0, delta_d=-1.0)
    flow = NdofFlow.of(m)
    with pytest.raises(ParameterError, match="K is invalid for sticking"):
        stuck_flow(flow)
    tau, z = _pushed_into_wall(flow)
    with pytest.raises(ChatteringError, match=r"x0 sticks at t=0: K is invalid for sticking"):
        advance(flow, tau, z, m.period)

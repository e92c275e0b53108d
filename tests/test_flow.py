"""Tests of grazing_control.oscillator.flow: the exact flow between impacts.

References: scipy.linalg.expm, mpmath's 50-digit matrix exponential and the
closed form written again in mpmath, scipy.integrate.solve_ivp on the ODE, and the
ODE itself (finite-difference residual).
"""

import math

import numpy as np
import pytest
from mpmath import mp, mpf
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from grazing_control.oscillator.flow import (amplitude_bound, gap, particular, propagate,
                                             to_deviation, to_physical, transition_matrix)
from grazing_control.oscillator.params import OscillatorParams

from reference import RefModel

mp.dps = 50
ZETAS = [1e-4, 0.01, 0.3, 0.9]
STEPS = [0.0, 1e-9, 0.37, 2.0, -1.3, 9.418185242872688, 60.0]


def _a(zeta):
    return np.array([[0.0, 1.0], [-1.0, -2.0 * zeta]])


@pytest.mark.parametrize("zeta", ZETAS)
@pytest.mark.parametrize("h", STEPS)
def test_transition_matrix_vs_scipy_expm(zeta, h):
    got = np.array(transition_matrix(zeta, h)).reshape(2, 2)
    want = expm(_a(zeta) * h)
    scale = np.max(np.abs(want))
    # both carry rounding errors growing with |A h| (scaling and squaring in expm)
    assert np.max(np.abs(got - want)) <= 2e-14 * (1 + abs(h)) * scale


@pytest.mark.parametrize("zeta", ZETAS)
@pytest.mark.parametrize("h", STEPS)
def test_transition_matrix_vs_mpmath(zeta, h):
    """50-digit exp(A h): the closed form is accurate to a few ulps of the largest entry."""
    got = transition_matrix(zeta, h)
    A = mp.matrix([[0, 1], [-1, -2 * mpf(zeta)]])
    want = mp.expm(A * mpf(h))
    want = [want[0, 0], want[0, 1], want[1, 0], want[1, 1]]
    scale = max(abs(w) for w in want)
    # h enters sin(omega_d h): its rounding error is ~ulp(omega_d h), hence the |h| term
    tol = (8 + 2 * abs(h)) * 2.0**-52 * scale
    for g, w in zip(got, want):
        assert abs(mpf(g) - w) <= tol, (g, w)


@pytest.mark.parametrize("zeta", ZETAS)
def test_transition_matrix_group_and_determinant(zeta):
    for a, b in [(0.3, 0.9), (5.0, -2.0), (-1.0, 1.0)]:
        pa = np.array(transition_matrix(zeta, a)).reshape(2, 2)
        pb = np.array(transition_matrix(zeta, b)).reshape(2, 2)
        pab = np.array(transition_matrix(zeta, a + b)).reshape(2, 2)
        assert np.allclose(pa @ pb, pab, rtol=0, atol=1e-14 * np.max(np.abs(pab)) + 1e-15)
        # Liouville: det exp(A h) = exp(trace(A) h)
        assert np.linalg.det(pa) == pytest.approx(math.exp(-2 * zeta * a), rel=1e-13)
    assert transition_matrix(zeta, 0.0) == (1.0, 0.0, -0.0, 1.0)


def test_propagate_is_phi_times_z():
    for zeta, h, z in [(0.01, 1.7, (0.3, -0.2)), (0.5, -0.4, (1e-20, 3e-21))]:
        f = transition_matrix(zeta, h)
        got = propagate(zeta, z[0], z[1], h)
        assert got == (f[0] * z[0] + f[1] * z[1], f[2] * z[0] + f[3] * z[1])


# ---------------------------------------------------------------- the ODE
def _physical_path(p, tau0, dx0, dv0, t):
    """Physical (x, v) at time t of the impact-free flow from deviation (dx0, dv0)."""
    dx, dv = propagate(p.zeta, dx0, dv0, t)
    return to_physical(p, tau0 + p.omega * t, dx, dv)


@pytest.mark.parametrize(
    "kwargs,tau0,z0",
    [
        ({}, 0.3, (0.4, -0.7)),
        ({"zeta": 0.2, "omega": 1.7}, 4.0, (-1.0, 2.0)),
        ({"zeta": 0.05, "omega": 0.3, "tau0": 1.0}, 0.0, (0.0, 0.0)),
    ],
)
def test_flow_satisfies_the_ode(kwargs, tau0, z0):
    """x'' + 2 zeta x' + x - cos(tau) by central differences, and v = dx/dt."""
    p = OscillatorParams(**kwargs)
    h = 1e-3
    worst_res, worst_vel = 0.0, 0.0
    for t in np.linspace(0.0, 3 * p.period, 41):
        xm, _ = _physical_path(p, tau0, *z0, t - h)
        x0, v0 = _physical_path(p, tau0, *z0, t)
        xp, _ = _physical_path(p, tau0, *z0, t + h)
        acc = (xp - 2 * x0 + xm) / h**2
        vel = (xp - xm) / (2 * h)
        res = acc + 2 * p.zeta * v0 + x0 - math.cos(p.omega * t + tau0)
        worst_res = max(worst_res, abs(res))
        worst_vel = max(worst_vel, abs(vel - v0))
    # truncation h^2/12 |x''''| ~ 1e-7 and rounding 4 eps |x| / h^2 ~ 1e-9
    assert worst_res < 2e-6
    assert worst_vel < 1e-6


def test_flow_vs_solve_ivp():
    p = OscillatorParams(zeta=0.1, omega=1.3)
    tau0, z0 = 0.7, (0.5, -0.25)
    x0, v0 = to_physical(p, tau0, *z0)

    def rhs(t, y):
        return [y[1], math.cos(p.omega * t + tau0) - 2 * p.zeta * y[1] - y[0]]

    ts = np.linspace(0, 20, 9)
    sol = solve_ivp(rhs, (0, 20), [x0, v0], method="DOP853", rtol=1e-13, atol=1e-15,
                    t_eval=ts)
    for k, t in enumerate(ts):
        x, v = _physical_path(p, tau0, *z0, t)
        assert abs(x - sol.y[0, k]) < 1e-10 and abs(v - sol.y[1, k]) < 1e-10


def test_particular_is_the_periodic_solution():
    """x_p'' + 2 zeta x_p' + x_p = cos(tau), with x_p' = v_p (closed-form derivatives)."""
    for kwargs in [{}, {"zeta": 0.3, "omega": 2.5}, {"zeta": 0.5, "omega": 1.0}]:
        p = OscillatorParams(**kwargs)
        for tau in np.linspace(0, 2 * math.pi, 13):
            xp, vp = particular(p, tau)
            acc = -p.amplitude * p.omega**2 * math.cos(tau - p.lag)
            assert abs(acc + 2 * p.zeta * vp + xp - math.cos(tau)) < 1e-14 * p.amplitude
            # derivative of x_p with respect to time is v_p
            h = 1e-6
            dxp = (particular(p, tau + p.omega * h)[0] - particular(p, tau - p.omega * h)[0])
            assert dxp / (2 * h) == pytest.approx(vp, abs=1e-8)
            # periodic in tau
            assert particular(p, tau + 2 * math.pi) == pytest.approx((xp, vp), abs=1e-14)


def test_particular_matches_mpmath_at_the_grazing_phase():
    p = OscillatorParams()
    ref = RefModel.from_params(p)
    xp, vp = particular(p, p.tau_star)
    rx, rv, _ = ref.particular(p.tau_star)
    assert abs(mpf(xp) - rx) < 4e-16 and abs(mpf(vp) - rv) < 1e-17
    assert abs(mpf(p.d_star) - ref.d_star) < 4e-16


def test_deviation_physical_round_trip():
    p = OscillatorParams(delta_d=-0.01)
    rng = np.random.default_rng(1)
    for _ in range(200):
        tau = rng.uniform(0, 2 * math.pi)
        x, v = rng.normal(size=2)
        dx, dv = to_deviation(p, tau, x, v)
        xb, vb = to_physical(p, tau, dx, dv)
        assert abs(xb - x) <= 4 * math.ulp(max(abs(x), 2.0))
        assert abs(vb - v) <= 4 * math.ulp(max(abs(v), 2.0))
    # X** is the zero deviation on Pi2
    assert to_deviation(p, p.tau2, p.x_ref, p.v_ref) == pytest.approx((0.0, 0.0), abs=1e-15)


# ------------------------------------------------------------------- gap
def _exact_gap(ref: RefModel, tau: float, dx: float):
    """x - d at 50 digits: x = x_p(tau) + dx in physical coordinates, d = d* + delta_d."""
    return ref.gap_deviation(tau, dx)


@pytest.mark.parametrize("psi", [0.0, 1e-10, -3e-10, 2e-11])
@pytest.mark.parametrize("delta_d", [0.0, -1e-16, 3e-15, -2e-13])
@pytest.mark.parametrize("target", [-1e-20, 1e-20, -3e-19])
def test_gap_has_relative_accuracy_near_grazing(psi, delta_d, target):
    """A gap of 1e-20 is resolved to 1e-6 relative; x - d in doubles cannot resolve it.

    dx is chosen (in mpmath, then rounded) so that x - d = target at phase tau* + psi;
    the exact gap of the rounded inputs is then formed at 50 digits in *physical*
    coordinates (x = x_p + dx ~ 1.8) and compared with flow.gap.
    """
    p = OscillatorParams(delta_d=delta_d)
    ref = RefModel.from_params(p)
    tau = p.lag + psi
    xp_mp = ref.particular(tau)[0]
    dx = float(mpf(target) + ref.d - xp_mp)
    exact = _exact_gap(ref, tau, dx)
    assert abs(exact - target) < 1e-3 * abs(target)  # the construction is right
    got = gap(p, tau, dx)
    assert abs(mpf(got) - exact) <= 1e-6 * abs(exact)
    # the naive physical computation has an absolute error ~ ulp(1.8) ~ 2e-16 >> 1e-20
    naive = (particular(p, tau)[0] + dx) - p.d
    assert naive == 0.0 or abs(mpf(naive) - exact) > abs(exact)


def test_gap_far_from_grazing_matches_mpmath():
    p = OscillatorParams(delta_d=-0.3, zeta=0.2, omega=1.4)
    ref = RefModel.from_params(p)
    rng = np.random.default_rng(7)
    for _ in range(50):
        tau = rng.uniform(0, 2 * math.pi)
        dx = rng.normal()
        exact = _exact_gap(ref, tau, dx)
        assert abs(mpf(gap(p, tau, dx)) - exact) <= 1e-15 * (1 + abs(dx) + p.d_star)


@pytest.mark.parametrize("zeta", [0.01, 0.4])
def test_amplitude_bound_bounds_every_derivative(zeta):
    """|z_x^(k)(h)| <= |C| e^{-zeta h}, k = 0..3: the bound the impact search relies on."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        dx, dv = rng.normal(size=2)
        c = amplitude_bound(zeta, dx, dv)
        for h in np.linspace(0, 30, 301):
            z = np.array(propagate(zeta, dx, dv, h))
            zx, zv = z
            zacc = -2 * zeta * zv - zx
            zjerk = -2 * zeta * zacc - zv
            bound = c * math.exp(-zeta * h) * (1 + 1e-12)
            assert max(abs(zx), abs(zv), abs(zacc), abs(zjerk)) <= bound

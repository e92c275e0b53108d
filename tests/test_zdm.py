"""Zero-time discontinuity mapping at Pi1: closed forms, order of accuracy, normal-form maps.

The reference is the exact flow with impacts of the core (grazing_control.dynamics.maps.maps.pi1_map,
through zdm.exact_return for states whose trajectory has already hit the wall at
Pi1) and, for the ZDM alone, the exact ZDM evaluated in mpmath at 40 digits.
Predicted orders (docs/theory_zdm.md, section 3): with H_max = eps and the state
scaled self-similarly (gap ~ eps, gap rate ~ sqrt(eps)), the error of the
leading-order ZDM is O(eps), of the second-order ZDM O(eps^1.5).
"""

import math

import mpmath as mp
import numpy as np
import pytest

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.flow import propagate
from grazing_control.dynamics.maps.maps import pi1_map
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.dynamics.maps.zdm import (crossing, exact_return, h_max, local_grazing,
                                          normal_form_jacobian, normal_form_map, zdm,
                                          zdm_exact, zdm_jacobian, zdm_leading, zdm_second)

P0 = OscillatorParams()
GAINS = {"uncontrolled": None, "controlled": Gains(degenerate_c1(P0, -1.0), -1.0)}
#: Position of the maximum of the gap relative to Pi1, in units of sqrt(eps):
#: 3 -> impact after Pi1 (physical state); 0 -> maximum on Pi1; -2 -> impact before.
SHAPES = (3.0, 0.0, -2.0)
PREDICTED = {1: 1.0, 2: 1.5}


def state_with_hmax(p, eps, c):
    """Deviation on Pi1 whose smooth trajectory has its gap maximum H_max = eps exactly,
    at local time t_m = c sqrt(eps): built at the maximum (gap eps, rate 0) with the
    core's deviation formulas and flowed back to Pi1 exactly."""
    tm = c * math.sqrt(eps)
    zx = eps + p.delta_d + 2.0 * p.amplitude * math.sin(0.5 * p.omega * tm) ** 2
    zv = p.amplitude * p.omega * math.sin(p.omega * tm)
    return propagate(p.zeta, zx, zv, -tm)


def slope(eps, err):
    return float(np.polyfit(np.log10(eps), np.log10(err), 1)[0])


def test_constructed_states_have_the_requested_hmax():
    for eps in (1e-4, 1e-8, 1e-12):
        for c in SHAPES:
            p = P0.with_(delta_d=0.1 * math.sqrt(eps))
            t_max, hm, t1, v = crossing(p, *state_with_hmax(p, eps, c))
            assert hm == pytest.approx(eps, rel=1e-8)
            assert t_max == pytest.approx(c * math.sqrt(eps), rel=1e-6, abs=1e-9 * math.sqrt(eps))
            assert v > 0.0 and (t1 > 0.0) == (c == 3.0)


def test_exact_zdm_closed_form_matches_the_core_flow():
    """N_g o D_exact equals the exact Pi1 map (only the near-grazing impact in the period)."""
    for name, gains in GAINS.items():
        for eps in (1e-4, 1e-7, 1e-10):
            for c in SHAPES:
                p = P0.with_(delta_d=0.1 * math.sqrt(eps))
                z = state_with_hmax(p, eps, c)
                ref = exact_return(p, *z, gains)
                assert len(ref.impacts) == 1
                got = normal_form_map(p, z, gains, "exact")
                scale = math.hypot(ref.dx, ref.dv)
                # the reference's phase is rounded to ulp(tau*) ~ 3.5e-18: absolute floor
                assert max(abs(got[0] - ref.dx), abs(got[1] - ref.dv)) < 1e-12 * scale + 1e-16, name


def test_exact_return_is_pi1_map_for_physical_states():
    p = P0.with_(delta_d=1e-4)
    z = state_with_hmax(p, 1e-8, 3.0)
    a, b = exact_return(p, *z), pi1_map(p, *z)
    assert (a.dx, a.dv, len(a.impacts)) == (b.dx, b.dv, len(b.impacts))


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("name", list(GAINS))
def test_normal_form_map_order_against_pi1_map(order, name):
    """Error of N_g o D_k against the exact map falls like eps^{1, 1.5}.

    The wall sits at Delta d = 0.1 sqrt(eps) > 0 so that the returning trajectory stays
    clear of the wall at the end of the period (one impact per period, asserted), and
    all deviations are O(sqrt(eps)) so that the reference keeps full relative precision.
    eps goes down to 1e-12 for the leading order; for the second order to 1e-11, below
    which its error (~1e-18) is under the reference's rounding floor (~1e-17).
    """
    gains = GAINS[name]
    eps = 10.0 ** -np.arange(4, 13 if order == 1 else 12)
    for c in SHAPES:
        errs = []
        for e in eps:
            p = P0.with_(delta_d=0.1 * math.sqrt(e))
            z = state_with_hmax(p, e, c)
            ref = exact_return(p, *z, gains)
            assert len(ref.impacts) == 1
            got = normal_form_map(p, z, gains, order)
            errs.append(max(abs(got[0] - ref.dx), abs(got[1] - ref.dv)))
        s = slope(eps, errs)
        assert abs(s - PREDICTED[order]) < 0.15, (c, s, errs)
        assert all(b < a for a, b in zip(errs, errs[1:])), errs


def _mp_exact_zdm(p, z):
    """Exact ZDM in 40-digit arithmetic (same formula as zdm_exact, independent code)."""
    with mp.workdps(40):
        zeta, w, a, r = mp.mpf(p.zeta), mp.mpf(p.omega), mp.mpf(p.amplitude), mp.mpf(p.r)
        dd = mp.mpf(p.delta_d)
        wd = mp.sqrt(1 - zeta ** 2)

        def phi(h):
            e, c, s = mp.exp(-zeta * h), mp.cos(wd * h), mp.sin(wd * h) / wd
            return e * (c + zeta * s), e * s, -e * s, e * (c - zeta * s)

        z0 = [mp.mpf(z[0]), mp.mpf(z[1])]

        def gap(t):
            f = phi(t)
            return f[0] * z0[0] + f[1] * z0[1] - dd - 2 * a * mp.sin(w * t / 2) ** 2

        def rate(t):
            f = phi(t)
            return f[2] * z0[0] + f[3] * z0[1] - a * w * mp.sin(w * t)

        alpha = a * w * w
        tm = mp.findroot(rate, z0[1] / alpha)
        hm = gap(tm)
        t1 = mp.findroot(gap, tm - mp.sqrt(2 * hm / alpha))
        v = rate(t1)
        f = phi(-t1)
        return z0[0] - (1 + r) * v * f[1], z0[1] - (1 + r) * v * f[3]


@pytest.mark.parametrize("order", [1, 2])
def test_zdm_order_against_mpmath_over_full_range(order):
    """The ZDM alone against the exact ZDM at 40 digits, eps = 1e-4 ... 1e-12, Delta d = 0."""
    eps = 10.0 ** -np.arange(4, 13)
    for c in SHAPES:
        errs = []
        for e in eps:
            z = state_with_hmax(P0, e, c)
            ref = _mp_exact_zdm(P0, z)
            got = zdm(P0, *z, order)
            errs.append(max(float(abs(got[0] - ref[0])), float(abs(got[1] - ref[1]))))
        s = slope(eps, errs)
        assert abs(s - PREDICTED[order]) < 0.15, (c, s, errs)
    # and the double-precision exact ZDM is at the rounding floor
    for e in (1e-4, 1e-12):
        z = state_with_hmax(P0, e, -2.0)
        ref = _mp_exact_zdm(P0, z)
        got = zdm_exact(P0, *z)
        assert max(float(abs(got[0] - ref[0])), float(abs(got[1] - ref[1]))) < 1e-14 * math.sqrt(e)


def test_no_impact_is_identity():
    p = P0.with_(delta_d=1e-6)
    z = (p.delta_d - 1e-8, 1e-5)  # H = -1e-8 + 1e-10 / (2 alpha) < 0
    assert h_max(p, *z, order=1) < 0.0 and h_max(p, *z, order=2) < 0.0
    for order in (1, 2, "exact"):
        assert zdm(p, *z, order) == z
        assert zdm_jacobian(p, *z, order) == (1.0, 0.0, 0.0, 1.0)


def test_state_leaving_the_wall_gets_minus_one_plus_r_times_its_velocity():
    """On the wall moving out (e1 = 0, e2 = v): exact D = (z_x, z_v - (1 + r) v); the
    second order is exact to O(v^3), the leading order to O(v^2) (position t1 = 0)."""
    p = P0
    for v in (1e-3, 1e-5):
        z = (p.delta_d, v)
        ex = zdm_exact(p, *z)
        assert ex[0] == pytest.approx(z[0], abs=1e-15 * v)
        assert ex[1] == pytest.approx(v - (1.0 + p.r) * v, rel=1e-12)
        assert abs(zdm_second(p, *z)[1] - ex[1]) < 5.0 * v ** 3
        assert abs(zdm_leading(p, *z)[1] - ex[1]) < 5.0 * v ** 2


@pytest.mark.parametrize("order", [1, 2, "exact"])
def test_jacobians_match_finite_differences(order):
    p = P0.with_(delta_d=2e-4)
    z = (2e-4 + 3e-7, 1e-3)
    jac = np.array(zdm_jacobian(p, *z, order)).reshape(2, 2)
    fd = np.zeros((2, 2))
    for j, h in enumerate((1e-12, 1e-10)):
        zp, zm = list(z), list(z)
        zp[j] += h
        zm[j] -= h
        fd[:, j] = (np.array(zdm(p, *zp, order)) - np.array(zdm(p, *zm, order))) / (2 * h)
    assert np.allclose(jac, fd, rtol=1e-6, atol=1e-6 * np.abs(jac).max())
    det = np.linalg.det(jac)
    if order == "exact":  # the ZDM is the impact law conjugated by the flow
        assert det == pytest.approx(p.r ** 2, rel=1e-12)
    if order == 2:  # r^2 + O(delta)
        assert det == pytest.approx(p.r ** 2, rel=1e-3)
    if order == 1:  # 1 - (1 + r) e2 / V: not r^2, the defect behind section 9
        assert abs(det - p.r ** 2) > 0.5
    full = np.array(normal_form_jacobian(p, z, GAINS["controlled"], order)).reshape(2, 2)
    from grazing_control.dynamics.maps.zdm import smooth_map
    assert np.allclose(full, np.array(smooth_map(p, GAINS["controlled"])).reshape(2, 2) @ jac)


def test_local_coefficients():
    g = local_grazing(P0)
    assert g.alpha == pytest.approx(-P0.a_star)
    # alpha = a omega^2 at grazing: x_p satisfies the equation of motion at tau*
    assert g.alpha == pytest.approx(P0.amplitude * P0.omega ** 2, rel=1e-13)
    with pytest.raises(ValueError):
        zdm(P0, 0.0, 0.0, order=3)
    with pytest.raises(ValueError):  # far from grazing: no local event at Pi1
        crossing(P0, 0.0, 5.0)

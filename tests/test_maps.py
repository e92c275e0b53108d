"""Tests of grazing_control.dynamics.maps.maps: the Poincare maps on Pi1 and Pi2 and their Jacobians.

References: central finite differences of the exact maps, scipy.linalg.expm for the
smooth return matrix N_g (Eqs. 29-32), and the controller law of Eq. 28.
"""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from grazing_control.oscillator.control import Gains
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.impact import advance
from grazing_control.dynamics.maps.maps import pi1_map, pi2_map, section_phase, smooth_return_matrix
from grazing_control.oscillator.params import OscillatorParams

STUDY = OscillatorParams()
DESIGN_C2 = -1.0


def _design_gains(p):
    return Gains(degenerate_c1(p, DESIGN_C2), DESIGN_C2)


def _mat(m):
    return np.array(m, dtype=float).reshape(2, 2)


def _fd(mapping, z, h):
    """Fourth-order central differences of z -> mapping(z) (a Segment).

    The map's output carries an absolute rounding error of ~1e-15 (the forcing phase
    is a float), so the difference quotient has a noise floor ~1e-15 / h; the
    fourth-order stencil keeps the truncation error (~h^4 / v-^4) negligible at
    h = 1e-6 where that floor is 1e-9. The impact count must not change across the
    stencil (same branch of the piecewise-smooth map).
    """
    jac = np.zeros((2, 2))
    base = len(mapping(*z).impacts)
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        vals = []
        for k in (2, 1, -1, -2):
            seg = mapping(*(z + k * e))
            assert len(seg.impacts) == base
            vals.append(np.array([seg.dx, seg.dv]))
        jac[:, j] = (-vals[0] + 8 * vals[1] - 8 * vals[2] + vals[3]) / (12 * h)
    return jac


GAIN_CASES = [None, Gains(0.3, -0.5), "design"]


def _gains(p, g):
    return _design_gains(p) if g == "design" else g


# Scenes: a state (deviation) used both on Pi2 and on Pi1 (where the gap is
# dx - Delta d, so dx < Delta d), and the finite-difference step (see _fd). Each has
# an impact within the period uncontrolled and with the design gains.
SCENES = [
    (STUDY.with_(delta_d=-0.05), (-0.3, 0.5), 1e-6),
    (STUDY.with_(delta_d=-0.05), (-0.4979, 1.0506), 1e-6),   # near the 1/1 orbit
    (STUDY.with_(delta_d=-1e-3), (-0.08, 0.1), 1e-6),
    # v- ~ 5e-3, near grazing: the map is smooth on a scale v-^2 ~ 2.5e-5 only
    (STUDY.with_(delta_d=-1e-5), (-3e-3, 3.2e-3), 2.5e-8),
    (OscillatorParams(omega=3.2, delta_d=-0.01), (-0.44, 0.57), 1e-6),
]


@pytest.mark.parametrize("g", GAIN_CASES, ids=["uncontrolled", "gains", "design"])
@pytest.mark.parametrize("p,z,h", SCENES)
def test_pi2_monodromy_vs_finite_differences(p, z, h, g):
    gains = _gains(p, g)
    z = np.array(z)
    seg = pi2_map(p, *z, gains, monodromy=True)
    assert len(seg.impacts) >= 1 or g is GAIN_CASES[1]  # saltation matrix in the product
    jac = _fd(lambda dx, dv: pi2_map(p, dx, dv, gains), z, h)
    mono = _mat(seg.monodromy)
    assert np.max(np.abs(mono - jac)) <= 1e-6 * np.max(np.abs(jac)), (mono, jac)


@pytest.mark.parametrize("g", GAIN_CASES, ids=["uncontrolled", "gains", "design"])
@pytest.mark.parametrize("p,z,h", SCENES)
def test_pi1_monodromy_vs_finite_differences(p, z, h, g):
    gains = _gains(p, g)
    z = np.array(z)
    seg = pi1_map(p, *z, gains, monodromy=True)
    assert len(seg.impacts) >= 1
    jac = _fd(lambda dx, dv: pi1_map(p, dx, dv, gains), z, h)
    assert np.max(np.abs(_mat(seg.monodromy) - jac)) <= 1e-6 * np.max(np.abs(jac))


@pytest.mark.parametrize("g", GAIN_CASES, ids=["uncontrolled", "gains", "design"])
def test_pi2_map_applies_the_controller_before_the_flow(g):
    p = STUDY.with_(delta_d=-0.05)
    gains = _gains(p, g)
    dx, dv = 0.12, -0.31
    seg = pi2_map(p, dx, dv, gains)
    c1, c2 = (0.0, 0.0) if gains is None else (gains.c1, gains.c2)
    # Eq. 28 in deviation coordinates: v - v** = dv, x - x** = dx
    direct = advance(p, p.tau2, dx, dv + c1 * dx + c2 * dv, p.period)
    assert (seg.dx, seg.dv) == (direct.dx, direct.dv)
    assert seg.impacts == direct.impacts


def _phi(p, h):
    a = np.array([[0.0, 1.0], [-1.0, -2.0 * p.zeta]])
    return expm(a * h)


@pytest.mark.parametrize("g", GAIN_CASES, ids=["uncontrolled", "gains", "design"])
@pytest.mark.parametrize("kwargs", [{"delta_d": 0.5}, {"delta_d": 2.0, "pi2_offset": 2.5},
                                    {"zeta": 0.2, "omega": 1.7, "delta_d": 3.0}])
def test_smooth_return_matrix_is_the_monodromy_without_impacts(kwargs, g):
    """Far from the wall (Delta d > 0 large) no impact occurs and the maps are linear:
    Pi1 monodromy = N_g = Phi(T - s) G Phi(s) (Eqs. 29-32), and the Pi2 monodromy
    Phi(T) G is similar to it (conjugate by Phi(s))."""
    p = OscillatorParams(**kwargs)
    gains = _gains(p, g)
    ng = smooth_return_matrix(p, gains)
    s = p.pi2_offset / p.omega
    gm = np.eye(2) if gains is None else np.array([[1.0, 0.0], [gains.c1, 1.0 + gains.c2]])
    want = _phi(p, p.period - s) @ gm @ _phi(p, s)
    scale = np.max(np.abs(want))
    assert np.max(np.abs(ng - want)) < 1e-13 * scale
    z = (0.01, -0.02)
    seg1 = pi1_map(p, *z, gains, monodromy=True)
    seg2 = pi2_map(p, *z, gains, monodromy=True)
    assert seg1.impacts == [] and seg2.impacts == []
    assert np.max(np.abs(_mat(seg1.monodromy) - ng)) < 1e-13 * scale
    # linear map: the image is the monodromy times the state
    assert np.allclose([seg1.dx, seg1.dv], ng @ z, rtol=0, atol=1e-15)
    conj = _phi(p, s) @ ng @ np.linalg.inv(_phi(p, s))
    assert np.max(np.abs(_mat(seg2.monodromy) - conj)) < 1e-12 * scale
    if gains is None:
        assert np.max(np.abs(ng - _phi(p, p.period))) < 1e-13 * scale


def test_degenerate_design_zeroes_ng12():
    """The design gain makes N_g,12 = 0 (Eq. 33); uncontrolled it is not zero."""
    p = STUDY
    assert abs(smooth_return_matrix(p, _design_gains(p))[0, 1]) < 1e-13
    assert abs(smooth_return_matrix(p)[0, 1]) > 1e-3


def test_pi1_and_pi2_maps_are_conjugate():
    """P1 = F2 o P2 o F2^-1 where F2 flows from Pi2 to Pi1 (T - s, with the controller
    before it): iterating both maps from matching states stays matched."""
    p = STUDY.with_(delta_d=-1e-3)
    gains = _design_gains(p)
    s = p.pi2_offset / p.omega
    z1 = np.array([-0.01, 0.02])
    # Pi1 state -> Pi2 state after s
    first = advance(p, p.tau_star, *z1, s)
    z2 = np.array([first.dx, first.dv])
    for _ in range(5):
        a = pi1_map(p, *z1, gains)
        b = pi2_map(p, *z2, gains)
        nxt = advance(p, p.tau_star, a.dx, a.dv, s)
        assert abs(nxt.dx - b.dx) < 1e-12 and abs(nxt.dv - b.dv) < 1e-12
        z1, z2 = np.array([a.dx, a.dv]), np.array([b.dx, b.dv])


def test_section_phase():
    p = STUDY
    assert section_phase(p, "pi1") == p.tau_star
    assert section_phase(p, "pi2") == p.tau2
    assert section_phase(p, "pi2") == pytest.approx((p.tau_star + math.pi / 2) % (2 * math.pi))
    with pytest.raises(ValueError, match="section='pi3' is invalid"):
        section_phase(p, "pi3")

"""Exact flow of the oscillator between impacts, in deviation coordinates.

Between impacts the equation of motion (study Eq. 1) is linear with constant
coefficients, so its solution is closed form (spec section 1)::

    y(t) = y_p(t) + Phi(t - t0) (y(t0) - y_p(t0)),   Phi(h) = exp(A h),
    A = [[0, 1], [-1, -2 zeta]],
    y_p = (x_p, x_p'),  x_p = a cos(tau - phi),  tau = omega t + tau0.

We carry the state as the *deviation* z = y - y_p(tau) from the non-impacting
periodic motion, together with the forcing phase tau. The deviation evolves by the
homogeneous flow alone, z(h) = Phi(h) z(0), and the gap to the wall is

    g = x - d = z_x - Delta d - 2 a sin^2((tau - phi) / 2),

every term of which is small near grazing. Near-grazing quantities (gaps of 1e-20,
impact velocities of 1e-10) are therefore computed with full relative precision,
which the physical coordinates (x ~ d* ~ 1.8) cannot give. See docs/theory.md,
section "Deviation coordinates".

All functions here are scalar and use :mod:`math` only: they are the hot path.
"""

from __future__ import annotations

import math

from .params import OscillatorParams

__all__ = [
    "transition_matrix",
    "propagate",
    "particular",
    "to_deviation",
    "to_physical",
    "gap",
    "amplitude_bound",
    "matmul2",
]


def transition_matrix(zeta: float, h: float):
    """State transition matrix Phi(h) = exp(A h) of x'' + 2 zeta x' + x = 0.

    Closed form with omega_d = sqrt(1 - zeta^2) (spec section 1)::

        Phi = e^{-zeta h} [[c + zeta s / omega_d,  s / omega_d],
                           [-s / omega_d,          c - zeta s / omega_d]]

    where c = cos(omega_d h), s = sin(omega_d h).

    Returns
    -------
    tuple of float
        (Phi11, Phi12, Phi21, Phi22).
    """
    wd = math.sqrt(1.0 - zeta * zeta)
    e = math.exp(-zeta * h)
    c = math.cos(wd * h)
    s = math.sin(wd * h) / wd
    return (e * (c + zeta * s), e * s, -e * s, e * (c - zeta * s))


def propagate(zeta: float, dx: float, dv: float, h: float):
    """Deviation after time h: z(h) = Phi(h) z(0) (homogeneous flow)."""
    f11, f12, f21, f22 = transition_matrix(zeta, h)
    return f11 * dx + f12 * dv, f21 * dx + f22 * dv


def particular(p: OscillatorParams, tau: float):
    """Non-impacting periodic motion y_p at forcing phase tau (spec section 1).

    Returns (x_p, v_p) = (a cos(tau - phi), -a omega sin(tau - phi)).
    """
    psi = tau - p.lag
    a = p.amplitude
    return a * math.cos(psi), -a * p.omega * math.sin(psi)


def to_deviation(p: OscillatorParams, tau: float, x: float, v: float):
    """Physical state (x, v) at phase tau -> deviation z = (x - x_p, v - v_p)."""
    xp, vp = particular(p, tau)
    return x - xp, v - vp


def to_physical(p: OscillatorParams, tau: float, dx: float, dv: float):
    """Deviation z at phase tau -> physical state (x, v)."""
    xp, vp = particular(p, tau)
    return xp + dx, vp + dv


def gap(p: OscillatorParams, tau: float, dx: float) -> float:
    """Gap to the wall g = x - d, computed without cancellation near grazing.

    g = z_x - Delta d - 2 a sin^2((tau - phi)/2)  (x_p - d* = a (cos psi - 1)).
    """
    s = math.sin(0.5 * (tau - p.lag))
    return dx - p.delta_d - 2.0 * p.amplitude * s * s


def amplitude_bound(zeta: float, dx: float, dv: float) -> float:
    """|C| such that every derivative of z_x(h) is bounded by |C| e^{-zeta h}.

    z_x(h) = Re(C e^{lambda h}) with lambda = -zeta + i omega_d and |lambda| = 1, so
    |z_x^{(k)}(h)| <= |C| e^{-zeta h} for all k; |C|^2 = z_x^2 + ((z_v + zeta z_x)/omega_d)^2.
    """
    wd = math.sqrt(1.0 - zeta * zeta)
    return math.hypot(dx, (dv + zeta * dx) / wd)


def matmul2(a, b):
    """Product of two 2x2 matrices given as 4-tuples (row-major): the hot-path form."""
    return (
        a[0] * b[0] + a[1] * b[2],
        a[0] * b[1] + a[1] * b[3],
        a[2] * b[0] + a[3] * b[2],
        a[2] * b[1] + a[3] * b[3],
    )

"""The rig's model in the recording's own units, in closed form (docs/theory_identification.md).

A recording measures position and time in the rig's units, and the forcing's phase on a
reference signal (the shaker's generator). The model is the study's Eq. 1 before it was
made nondimensional::

    x'' + 2 zeta Omega x' + Omega^2 x = A cos(psi),   psi = tau + theta,   while x < d,
    v+ = -r v-                                         at x = d,

with tau = omega t + tau0 the reference's phase (fitted by :mod:`.phase`), Omega the
natural frequency, A the forcing amplitude (per unit mass) and theta the phase of the
force behind the reference. With the time scale 1/Omega and the length scale A/Omega^2
it is the study's model with omega / Omega, d Omega^2 / A and the forcing phase
tau + theta (:meth:`RigModel.nondimensional`).

Every function here is written with analytic operations only (no abs, no comparisons on
the parameters), so that it accepts complex arguments and a complex step gives its
derivatives to rounding (:mod:`.fit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["RigModel", "forced_response", "free_flight", "GLOBAL_NAMES"]

#: The model's parameters in the order of the fit's parameter vector.
GLOBAL_NAMES = ("zeta", "natural_frequency", "forcing_amplitude", "forcing_phase", "d", "r")


def forced_response(zeta, Omega, A, omega, psi):
    """Periodic (non-impacting) response y_p = (x_p, v_p) at forcing phase psi.

    x_p = Re(A e^{i psi} / (Omega^2 - omega^2 + 2 i zeta Omega omega)), i.e. with
    D = Omega^2 - omega^2, E = 2 zeta Omega omega, N = D^2 + E^2::

        x_p = A (D cos psi + E sin psi) / N,   v_p = A omega (E cos psi - D sin psi) / N

    (spec section 1 with Omega = A = 1: a(omega) cos(psi - phi)).
    """
    D = Omega * Omega - omega * omega
    E = 2.0 * zeta * Omega * omega
    N = D * D + E * E
    c, s = np.cos(psi), np.sin(psi)
    return A * (D * c + E * s) / N, A * omega * (E * c - D * s) / N


def free_flight(zeta, Omega, A, omega, psi0, h, X0, V0):
    """State (x, v) a time h after the start state (X0, V0) at forcing phase psi0.

    The exact flow between impacts (spec section 1, with natural frequency Omega)::

        y(h) = y_p(psi0 + omega h) + Phi(h) (y(0) - y_p(psi0)),
        Phi(h) = e^{-zeta Omega h} [[c + zeta Omega s / w,  s / w],
                                    [-Omega^2 s / w,        c - zeta Omega s / w]],

    with w = Omega sqrt(1 - zeta^2), c = cos(w h), s = sin(w h)
    (:func:`grazing_control.oscillator.flow.transition_matrix` for Omega = 1).
    """
    xp0, vp0 = forced_response(zeta, Omega, A, omega, psi0)
    zx, zv = X0 - xp0, V0 - vp0
    w = Omega * np.sqrt(1.0 - zeta * zeta)
    k = zeta * Omega
    e = np.exp(-k * h)
    c = np.cos(w * h)
    s = np.sin(w * h) / w
    xp, vp = forced_response(zeta, Omega, A, omega, psi0 + omega * h)
    x = xp + e * (c * zx + s * (zv + k * zx))
    v = vp + e * (c * zv - s * (Omega * Omega * zx + k * zv))
    return x, v


@dataclass(frozen=True)
class RigModel:
    """The identified model in the recording's units (module docstring).

    Attributes
    ----------
    zeta, natural_frequency (Omega), forcing_amplitude (A), forcing_phase (theta), d, r :
        the fitted parameters (:data:`GLOBAL_NAMES`).
    omega, tau0 : the reference's frequency and phase at t = 0 (:mod:`.phase`).
    """

    zeta: float
    natural_frequency: float
    forcing_amplitude: float
    forcing_phase: float
    d: float
    r: float
    omega: float
    tau0: float

    @classmethod
    def from_vector(cls, g, omega, tau0) -> "RigModel":
        """From the fit's vector g (:data:`GLOBAL_NAMES` order) and the reference."""
        return cls(*(float(np.real(v)) for v in g[:6]), float(omega), float(tau0))

    def vector(self) -> np.ndarray:
        """The fit's vector g (:data:`GLOBAL_NAMES` order)."""
        return np.array([getattr(self, n) for n in GLOBAL_NAMES])

    def nondimensional(self, pi2_offset: float = math.pi / 2) -> OscillatorParams:
        """The study's parameters: zeta, r, omega / Omega, Delta d = d Omega^2 / A - a(omega),
        tau0 + theta (time 1/Omega, length A / Omega^2). ParameterError if outside the
        study's ranges (a fit that left them)."""
        W, A = self.natural_frequency, self.forcing_amplitude
        if not (W > 0.0 and A > 0.0):
            raise ParameterError(f"natural_frequency={W!r}, forcing_amplitude={A!r} are "
                                 "invalid: valid range is > 0 (the fit left the model)")
        p = OscillatorParams(zeta=self.zeta, r=self.r, omega=self.omega / W,
                             tau0=self.tau0 + self.forcing_phase, pi2_offset=pi2_offset)
        return p.with_(delta_d=self.d * W * W / A - p.d_star)


def nondimensional_vector(g, omega):
    """(zeta, r, omega / Omega, d_nd, Delta d) from the fit's vector g, analytic in g (for
    the delta method's complex-step gradient): d_nd = d Omega^2 / A, Delta d = d_nd - a,
    a = 1 / sqrt((1 - w^2)^2 + (2 zeta w)^2), w = omega / Omega (Eq. 2)."""
    zeta, W, A, _theta, d, r = g[:6]
    w = omega / W
    a = 1.0 / np.sqrt((1.0 - w * w) ** 2 + (2.0 * zeta * w) ** 2)
    dnd = d * W * W / A
    return np.array([zeta, r, w, dnd, dnd - a])


NONDIMENSIONAL_NAMES = ("zeta", "r", "omega", "d", "delta_d")

"""The degenerate gain c1 of a c2 (study Eq. 38, with an actuation delay (D5)): the
condition N_g,12 = 0 that makes the grazing bifurcation degenerate.

Derived in docs/theory.md, "Degenerate grazing and the design", and for a delay in
docs/theory_delay.md, section 2 (see :mod:`.gains`, which builds the design's
conditions and admissible set on it). A module of its own, over the oscillator's flow
alone: a controller node checks its gains against it at start (ros/controller_values.py,
``degeneracy_warning``) without importing the design's solvers (scipy.optimize: 0.3 s of
a node's start).
"""

from __future__ import annotations

import math

from grazing_control.oscillator.control import Gains, gain_matrix, kick_direction
from grazing_control.oscillator.flow import matmul2, transition_matrix
from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["degenerate_c1", "max_design_delay"]


def max_design_delay(p: OscillatorParams) -> float:
    """T - s: the delay at which the kick reaches the grazing phase tau* (theory_delay.md, 2).

    A degenerate design needs delay < T - s: a kick after the grazing impact cannot
    cancel the singular multiplier.
    """
    return p.period - p.pi2_offset / p.omega


def degenerate_c1(p: OscillatorParams, c2: float, delay: float = 0.0) -> float:
    """c1 that makes N_g,12 = 0 for a given c2 (Eq. 38), with the kick ``delay`` after Pi2.

    delay = 0 is the study's formula; delay > 0 solves (D5) of docs/theory_delay.md,
    0 <= delay < T - s. Raises ParameterError where no c1 exists
    (Phi12(T - s - delay) = 0) or the delay is out of range.
    """
    return _Degenerate(p, delay).c1(c2)


class _Degenerate:
    """The degenerate design at (p, delay) for any c2: the transition matrices that do not
    depend on c2 (Phi(s), Phi(T - s), and with a delay Phi12(T), Phi12(T - s - delay)),
    formed once. :func:`admissible_c2` evaluates the conditions at hundreds of c2
    (:func:`_values`); each c1 and N_g is formed from these exactly as
    :func:`degenerate_c1` and :func:`~grazing_control.dynamics.maps.maps.period_matrix`
    form them, so the floats are theirs. The constructor raises degenerate_c1's
    ParameterError where no degenerate design exists."""

    __slots__ = ("p", "delay", "phi_s", "phi_rest", "_n12_free", "_h12", "_kick", "decay")

    def __init__(self, p: OscillatorParams, delay: float = 0.0):
        s = p.pi2_offset / p.omega
        self.p, self.delay = p, delay
        self.phi_s = transition_matrix(p.zeta, s)
        if self.phi_s[1] == 0.0:
            raise ParameterError(f"pi2_offset={p.pi2_offset!r} is invalid: Phi12(s) = 0 there, a kick "
                                 f"on Pi2 cannot reach the grazing phase's position (no c1 exists)")
        self.phi_rest = transition_matrix(p.zeta, p.period - s)
        self.decay = math.exp(-2.0 * p.zeta * p.period)     # det Phi(T)
        self._kick = (0.0, 1.0)                              # b_delta, (D1)
        if delay == 0.0:
            if self.phi_rest[1] == 0.0:
                raise ParameterError(f"pi2_offset={p.pi2_offset!r} is invalid: Phi12(T - s) = 0 there, "
                                     f"no gain c1 makes N_g,12 = 0")
            return
        top = max_design_delay(p)
        if not (math.isfinite(delay) and 0.0 < delay < top):
            raise ParameterError(f"delay={delay!r} is invalid: valid range is 0 <= delay < T - s = {top!r} "
                                 f"(the kick must act before the grazing phase)")
        self._n12_free = transition_matrix(p.zeta, p.period)[1]
        self._h12 = transition_matrix(p.zeta, top - delay)[1]
        self._kick = kick_direction(p.zeta, delay)

    def c1(self, c2: float) -> float:
        """:func:`degenerate_c1` at c2."""
        p11, p12, _p21, p22 = self.phi_s
        if self.delay == 0.0:
            q11, q12, _q21, _q22 = self.phi_rest
            return -(q11 * p12 + q12 * (1.0 + c2) * p22) / (q12 * p12)
        h12 = self._h12
        c1 = -(self._n12_free / h12 + c2 * p22) / p12 if h12 != 0.0 else math.inf
        if not math.isfinite(c1):
            raise ParameterError(f"delay={self.delay!r} is invalid: Phi12(T - s - delay) = {h12!r}, no gain c1 "
                                 f"makes N_g,12 = 0 there (delay = T - s - n pi / omega_d)")
        return c1

    def at(self, c2: float):
        """(c1, N_g, det G_delta) at c2: :meth:`c1`, :meth:`period_matrix` and
        ``gain_determinant`` of ``Gains(c1, c2, delay)``, the same floats, without forming
        the gains each time (the design's conditions are evaluated at hundreds of c2:
        :func:`~grazing_control.dynamics.design.gains.admissible_c2`). Gains' ParameterError
        for a c1 or c2 that is not a finite real."""
        c2 = float(c2)
        c1 = self.c1(c2)
        if not (math.isfinite(c1) and math.isfinite(c2)):
            Gains(c1, c2, self.delay)                        # raises, naming the gain
        if self.delay == 0.0:        # gain_matrix's and gain_determinant's two forms
            g, det_g = (1.0, 0.0, c1, 1.0 + c2), 1.0 + c2
        else:
            b1, b2 = self._kick
            g = (1.0 + b1 * c1, b1 * c2, b2 * c1, 1.0 + b2 * c2)
            det_g = 1.0 + c1 * b1 + c2 * b2
        return c1, matmul2(self.phi_rest, matmul2(g, self.phi_s)), det_g

    def period_matrix(self, gains: Gains):
        """N_g = Phi(T - s) G_delta Phi(s) for gains with this delay: period_matrix(p,
        gains), the same product of the same factors."""
        return matmul2(self.phi_rest, matmul2(gain_matrix(gains, self.p.zeta), self.phi_s))

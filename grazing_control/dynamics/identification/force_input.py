"""The actuator's force as the fit's known input (docs/theory_identification.md section 12).

A correction commanded as a force pulse through the plant's first-order actuator
(grazing_control/dynamics/simulation/actuator.py: tau_a F' = u(t - L) - F, u = Delta v / w
on the pulse) does not jump the state at one instant: the force acts from the command's
onset (its start + the latency L) for the pulse's width w and, through the lag, decays as
e^{-h / tau_a} after it, across samples and impacts. The force is known: the command's
size is recorded (Delta v), the actuator's parameters are in the bag's parameter record.
So the fit models it as a known input instead of cutting it out.

The motion is linear in the input, mode by mode: with the wall coordinate's complex modal
state A_k = alpha_k - i beta_k (x_w - x_p = Re sum_k A_k, :mod:`.modal`) and the response
C_k = c_k - i s_k of x_w to a unit kick on the actuated velocity,

    A_k' = lambda_k A_k + C_k g(t),       g = F / m_a (the force as a velocity rate),

and v_w - v_p = Re sum_k lambda_k A_k (sum_k c_k = 0: the force does not move x_w at
once). Over a stretch (S, t] without impacts

    A_k(t) = e^{lambda_k (t - S)} A_k(S) + C_k sum_j Delta v_j D_j(t, S),
    D_j(t, S) = Q_j(t) - e^{lambda (t - S)} Q_j(S),   Q_j(t) = int_{-inf}^t e^{lambda (t - s)} g_j(s) ds,

g_j the response of the actuator to command j per unit Delta v (impulse 1). With
h = t - onset_j, mu = 1 / tau_a and the pulse of width w (:func:`command_response`):

    0 < h <= w:  Q = [(e^{lambda h} - 1) / lambda - (e^{lambda h} - e^{-mu h}) / (lambda + mu)] / w
    h > w:       Q = e^{lambda (h - w)} Q(w) + (1 - e^{-mu w}) / w (e^{lambda (h - w)} - e^{-mu (h - w)}) / (lambda + mu)

(tau_a = 0: the terms in mu drop, the ideal pulse; w = 0: the impulse through the lag,
Q = mu (e^{lambda h} - e^{-mu h}) / (lambda + mu); the kick (both 0) is not an input
here: the fits jump the state for it). This is the plant's own flow (the particular
solution K e^{-h / tau_a} of :func:`~grazing_control.dynamics.simulation.actuator.lag_flow`)
in modal coordinates, exact: the impacts restart the free part only, the input's D
carries on through them.

Every function is written in real arithmetic on (real, imaginary) pairs, analytic in the
modal parameters, so that the fits' complex-step Jacobians stay exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = ["ActuatorInput", "Acting", "equivalent_kick", "command_response", "forced_increment", "kicked"]

#: A command's force is left out of a stretch that starts this many tau_a after the
#: pulse's end (e^{-40} = 4e-18: below the rounding of the state).
LAG_HORIZON = 40.0


@dataclass(frozen=True)
class ActuatorInput:
    """The commands of a recording as the fit's input: ``onsets`` (k,) when each command
    reaches the lag (its pulse's start + the latency, increasing), ``sizes`` (k,) its
    impulse (Delta v as delivered: clipped by a force limit), the pulse ``width`` w >= 0
    and the lag's ``time_constant`` tau_a >= 0 (not both 0), ``latency`` L (already in
    the onsets; kept for the report)."""

    onsets: np.ndarray
    sizes: np.ndarray
    width: float
    time_constant: float
    latency: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "onsets", np.asarray(self.onsets, float).ravel())
        object.__setattr__(self, "sizes", np.asarray(self.sizes, float).ravel())
        if self.onsets.size != self.sizes.size:
            raise ValueError(f"onsets has {self.onsets.size} values for {self.sizes.size} "
                             "command sizes")
        if not (self.width >= 0.0 and self.time_constant >= 0.0
                and self.width + self.time_constant > 0.0):
            raise ValueError(f"width={self.width!r}, time_constant={self.time_constant!r}: "
                             "valid is both >= 0, not both 0 (a kick is not an input)")

    @property
    def reach(self) -> float:
        """How long after its onset a command still acts: w, plus LAG_HORIZON tau_a."""
        return self.width + LAG_HORIZON * self.time_constant

    def relevant(self, t_hi, s_lo) -> "Acting":
        """For each stretch (S, t] with t <= ``t_hi`` and S >= ``s_lo``, the commands that
        act on it (onset < t, onset + reach > S), as pairs (:class:`Acting`)."""
        t_hi = np.asarray(t_hi, float).ravel()
        s_lo = np.asarray(s_lo, float).ravel()
        hi = np.searchsorted(self.onsets, t_hi, side="left")
        lo = np.minimum(np.searchsorted(self.onsets + self.reach, s_lo, side="right"), hi)
        counts = hi - lo
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if counts.size else counts
        rows = np.repeat(np.arange(counts.size), counts)
        commands = lo[rows] + np.arange(rows.size) - starts[rows]
        return Acting(rows, commands, starts, counts > 0)


class Acting(NamedTuple):
    """Pairs (stretch ``rows[i]``, command ``commands[i]``) sorted by stretch; ``starts``:
    each stretch's first pair, ``any``: whether it has one."""

    rows: np.ndarray
    commands: np.ndarray
    starts: np.ndarray
    any: np.ndarray


def _exp(sig, w, h):
    """e^{lambda h} = e^{-sigma h}(cos w h + i sin w h) as a pair."""
    e = np.exp(-sig * h)
    return e * np.cos(w * h), e * np.sin(w * h)


def _div(ar, ai, br, bi):
    """(a / b) of pairs."""
    den = br * br + bi * bi
    return (ar * br + ai * bi) / den, (ai * br - ar * bi) / den


def command_response(sig, w, h, width: float, time_constant: float):
    """Q(h) (module docstring) of a command h after its onset, per unit impulse, as a
    pair (broadcast of sig, w (n,) with h (..., 1)); 0 for h <= 0."""
    real_h = np.real(h)
    started = real_h > 0.0
    hh = np.where(started, h, 0.0)
    lam_r, lam_i = -sig, w
    mu = 1.0 / time_constant if time_constant > 0.0 else None

    def lag_term(x):          # (e^{lambda x} - e^{-mu x}) / (lambda + mu)
        er, ei = _exp(sig, w, x)
        em = np.exp(-mu * x)
        return _div(er - em, ei, lam_r + mu, lam_i)

    if width == 0.0:          # the impulse through the lag
        qr, qi = lag_term(hh)
        return np.where(started, mu * qr, 0.0), np.where(started, mu * qi, 0.0)
    inside = real_h <= width
    hin = np.where(inside, hh, width)            # h on the pulse, else w
    er, ei = _exp(sig, w, hin)
    qr, qi = _div(er - 1.0, ei, lam_r, lam_i)
    if mu is not None:
        lr, li = lag_term(hin)
        qr, qi = qr - lr, qi - li
    qr, qi = qr / width, qi / width
    after = np.where(inside, 0.0, hh - width)
    ar, ai = _exp(sig, w, after)
    out_r, out_i = ar * qr - ai * qi, ar * qi + ai * qr
    if mu is not None:
        lr, li = lag_term(after)
        tail = -math.expm1(-mu * width) / width
        out_r, out_i = out_r + tail * lr, out_i + tail * li
    out_r = np.where(inside, qr, out_r)
    out_i = np.where(inside, qi, out_i)
    return np.where(started, out_r, 0.0), np.where(started, out_i, 0.0)


def forced_increment(sig, w, t, s, inp: ActuatorInput, acting: Acting):
    """sum_j Delta v_j D_j(t, S) (module docstring) per mode, as a pair of (m, n) arrays:
    what the commands ``acting`` (:meth:`ActuatorInput.relevant`) add to the modal state
    over the stretches (S, t] (t, S: (m,), real or complex)."""
    t, s = np.asarray(t), np.asarray(s)
    dtype = np.result_type(t, s, sig, w)
    out_r = np.zeros((t.size, np.size(sig)), dtype)
    out_i = np.zeros_like(out_r)
    if acting.rows.size == 0:
        return out_r, out_i
    tt, ss = t[acting.rows][:, None], s[acting.rows][:, None]
    on = inp.onsets[acting.commands][:, None]
    size = inp.sizes[acting.commands][:, None]
    q1r, q1i = command_response(sig, w, tt - on, inp.width, inp.time_constant)
    q0r, q0i = command_response(sig, w, ss - on, inp.width, inp.time_constant)
    er, ei = _exp(sig, w, tt - ss)
    dr = size * (q1r - (er * q0r - ei * q0i))
    di = size * (q1i - (er * q0i + ei * q0r))
    rows = np.flatnonzero(acting.any)
    out_r[rows] = np.add.reduceat(dr, acting.starts[rows], axis=0)
    out_i[rows] = np.add.reduceat(di, acting.starts[rows], axis=0)
    return out_r, out_i


def kicked(c, s, fr, fi):
    """(alpha, beta) of C F for the kick's response C = c - i s and a pair F = fr + i fi
    (the modal state's alpha - i beta convention, :mod:`.modal`)."""
    return c * fr + s * fi, s * fr - c * fi


def equivalent_kick(sig, w, inp: ActuatorInput, offset: float):
    """The factor (a pair per mode) by which a command multiplies the kick's response
    once its force has died out, for the kick at the command's reference time, ``offset``
    before its onset: Q(h) = e^{lambda (h + offset)} x factor for h >= :attr:`reach`
    (the ideal pulse centred at the reference: sinh(lambda w / 2) / (lambda w / 2)). For
    the initial guesses."""
    reach = inp.reach
    qr, qi = command_response(sig, w, np.asarray([reach]), inp.width, inp.time_constant)
    er, ei = _exp(sig, w, offset - reach)
    return er * qr - ei * qi, er * qi + ei * qr

"""The n-DOF oscillator under a force on the actuated coordinate, exactly (issue 32;
docs/theory_ndof.md section 15).

A rig's actuator pushes the actuated coordinate ``i_a`` with a force F(t):

    M x'' + C x' + K x = f cos(omega t + phase) + e_a F(t),

i.e. z' = A z + B F in deviation coordinates, B = (0 ; M^-1 e_a) per unit force.

Constant force (the pulse)
--------------------------
With F constant the static deflection sigma F, sigma = -A^-1 B = (K^-1 e_a ; 0), is a
particular solution, so z - sigma F obeys the free flow, and the gap to the wall is
x_w - d = (z - sigma F)_w - (Delta d - sigma_w F) - 2 d* sin^2(psi / 2): the free n-DOF
oscillator with the clearance Delta d - sigma_w F (:func:`forced_flow`). Its certified
impact search, impact law, saltation and chatter refusal
(:func:`grazing_control.oscillator.ndof.impact.advance`) apply unchanged
(:func:`advance_with_force`): over a pulse of width w without impact

    z(w) = Phi(w) z + (int_0^w Phi(u) du) B F = Phi(w) (z - sigma F) + sigma F.

It needs K invertible (a model with a rigid-body mode has no static deflection: refused
with a ParameterError naming K). For n = 1 (M = 1) this is the 1-DOF
:func:`grazing_control.dynamics.simulation.actuation.flow_with_force`.

The correction's impulse: the kick changes the actuated velocity by Delta v; the pulse
carrying it has the impulse m_a Delta v, m_a = 1 / (M^-1)_aa (:func:`actuated_mass`, the
mass the actuated coordinate shows to a force on it; M_aa for a diagonal M), so that
F = m_a Delta v / w and the pulse tends to a jump of the actuated velocity by Delta v as
w -> 0 (for a non-diagonal M the other velocities move too, by M^-1 e_a m_a Delta v).

A first-order actuator (the lag)
--------------------------------
The force follows the command u through tau_a F' = u - F. On a piece with u constant,
F(h) = u + c e^{-h / tau_a}, and z_f(h) = sigma u + q e^{-h / tau_a} with
(A + I / tau_a) q = -B c is a particular solution (the augmented linear flow of (z, F),
whose extra eigenvalue is -1 / tau_a), so z - z_f obeys the free flow and the gap holds
one more decaying real mode, q_w e^{-h / tau_a}: the certified search of
oscillator/ndof/impact.py with that term added (its evaluator's ``transient``). At an impact the
impact law restarts the piece with c scaled by e^{-h / tau_a} (:func:`lag_advance`, as
the 1-DOF :func:`grazing_control.dynamics.simulation.actuator.lag_flow`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.impact import _scan_window
from grazing_control.oscillator.params import ParameterError

from .flow import NdofFlow
from .impact import (NdofImpact, NdofSegment, _Eval, advance, check_state,
                     saltation_matrix)

__all__ = ["actuated_mass", "force_input", "static_deflection", "forced_flow",
           "forced_clearance", "advance_with_force", "pulse_input", "actuated_input",
           "lag_particular", "lag_advance", "LagSegment"]

TWO_PI = 2.0 * math.pi
#: Below this impact velocity a lag piece refuses the motion (chattering or sticking under
#: the actuator's force is not resolved, as the 1-DOF lag flow).
MIN_IMPACT_VELOCITY = 1e-9


def actuated_mass(flow: NdofFlow) -> float:
    """m_a = 1 / (M^-1)_aa: the impulse m_a Delta v on coordinate i_a changes its velocity
    by Delta v (module docstring); kept per flow (the model filter asks for it at every
    iteration of its fit)."""
    return _actuated_mass(flow)


@functools.lru_cache(maxsize=64)
def _actuated_mass(flow: NdofFlow) -> float:
    """:func:`actuated_mass`, kept per flow (flows compare by identity)."""
    a = flow.model.i_a
    return float(1.0 / np.linalg.solve(flow.model.M, np.eye(flow.n)[a])[a])


def force_input(flow: NdofFlow) -> np.ndarray:
    """B = (0 ; M^-1 e_a): z' = A z + B F under a unit force on the actuated coordinate."""
    n = flow.n
    out = np.zeros(2 * n)
    out[n:] = np.linalg.solve(flow.model.M, np.eye(n)[flow.model.i_a])
    return out


def static_deflection(flow: NdofFlow) -> np.ndarray:
    """sigma = -A^-1 B = (K^-1 e_a ; 0), the deviation at rest under a unit force; computed
    once per flow (the model filter asks for it at every iteration of its fit, issue 32)
    and read-only.

    Raises ParameterError when K is singular (no static deflection)."""
    return _static_deflection(flow)


@functools.lru_cache(maxsize=64)
def _static_deflection(flow: NdofFlow) -> np.ndarray:
    """:func:`static_deflection`, kept per flow (flows compare by identity)."""
    n, K = flow.n, flow.model.K
    if not np.linalg.cond(K) < 1e12:
        raise ParameterError("K is invalid for a force pulse: it is singular (a rigid-body "
                             "mode has no static deflection); valid: K positive definite")
    out = np.zeros(2 * n)
    out[:n] = np.linalg.solve(K, np.eye(n)[flow.model.i_a])
    out.setflags(write=False)
    return out


def forced_flow(flow: NdofFlow, force: float) -> NdofFlow:
    """The free flow seen by z - sigma F under the constant ``force`` F: the same flow with
    the clearance Delta d - sigma_w F (module docstring). ``flow`` itself for F = 0; the
    same object for the same flow and F (the model filter's fit integrates one pulse at
    each of its iterations: building the model again took 0.45 ms of its 2.8 ms, issue
    32)."""
    if force == 0.0:
        return flow
    return _forced_flow(flow, float(force))


@functools.lru_cache(maxsize=64)
def _forced_flow(flow: NdofFlow, force: float) -> NdofFlow:
    """:func:`forced_flow` for F != 0, kept per (flow, F)."""
    model = dataclasses.replace(flow.model, delta_d=forced_clearance(flow, force))
    return dataclasses.replace(flow, model=model)


def forced_clearance(flow: NdofFlow, force: float) -> float:
    """Delta d - sigma_w F: the clearance of :func:`forced_flow` (without building its
    model, 0.18 ms: the compiled model filter needs only this number, issue 32)."""
    if force == 0.0:
        return flow.model.delta_d
    return flow.model.delta_d - static_deflection(flow)[flow.model.i_w] * force


def advance_with_force(flow: NdofFlow, tau0: float, z0, duration: float, force: float, *,
                       monodromy: bool = False, wall: bool = False):
    """The exact flow with impacts for ``duration`` under the constant ``force`` on the
    actuated coordinate: :func:`~grazing_control.oscillator.ndof.impact.advance` of
    :func:`forced_flow` from z0 - sigma F, shifted back (module docstring). Impact times
    count from the start; the monodromy d z(end) / d z0 is the shifted flow's (the shift is
    constant).

    With ``wall`` it returns (segment, g), g = d z(end) / d Delta d' the sensitivity to the
    clearance (zero before the first impact; an impact adds (I - S) e_w, the flow carries it
    on: docs/theory_estimation.md (E8)), which the pulse map's Jacobian needs
    (:meth:`grazing_control.dynamics.maps.modal_map.ModalMap.step`).
    """
    z0 = check_state(flow, z0, "the start state")
    shifted = forced_flow(flow, force)
    shift = static_deflection(flow) * force if force != 0.0 else np.zeros(2 * flow.n)
    need = monodromy or wall
    seg = advance(shifted, tau0, z0 - shift, duration, monodromy=need)
    out = NdofSegment(seg.z + shift, seg.tau, seg.impacts, seg.monodromy if monodromy else None)
    if not wall:
        return out
    g = _wall_sensitivity(shifted, tau0, z0 - shift, seg.impacts, duration)
    return out, g


def _wall_sensitivity(flow: NdofFlow, tau0: float, z0: np.ndarray, impacts, duration: float):
    """d z(end) / d Delta d along the free flow with impacts from z0 (2n,): Phi between
    impacts, S g + (I - S) e_w at each (docs/theory_estimation.md (E8), any n)."""
    m = flow.model
    n, w = m.n, m.i_w
    g = np.zeros(2 * n)
    z, t = np.array(z0, dtype=float), 0.0
    eye = np.eye(2 * n)
    for imp in impacts:
        phi = flow.transition(imp.dt - t)
        z_minus = phi @ z
        wall_x, rest_v = flow.on_wall(imp.phase)
        z_minus[w], z_minus[n + w] = wall_x, imp.v_minus + rest_v
        S = saltation_matrix(flow, imp.phase, z_minus)
        g = S @ (phi @ g) + (eye - S)[:, w]
        z = z_minus
        z[n + w] = imp.v_plus + rest_v
        t = imp.dt
    return flow.transition(duration - t) @ g


def pulse_input(flow: NdofFlow, start: float, width: float) -> np.ndarray:
    """b_w: the pulse's effective input vector seen on Pi2 (docs/theory_ndof.md (N10)).

    A pulse of ``width`` w > 0 starting ``start`` after the sample, carrying Delta v
    (F = m_a Delta v / w), moves the deviation, when no impact lies in [0, start + w], to

        z(start + w) = Phi(start + w) (z + b_w Delta v),
        b_w = Phi(-(start + w)) (int_0^w Phi(u) du) B m_a / w
            = (Phi(-(start + w)) - Phi(-start)) sigma m_a / w,

    by (int_0^w Phi(u) du) B = (I - Phi(w)) sigma. As w -> 0 it tends to
    Phi(-start) B m_a (the delayed kick's b_delta for a diagonal M); for n = 1 its
    w^T Phi(T - s) b_w is the 1-DOF h of (P1) (docs/theory_pulse.md section 7).
    """
    sigma = static_deflection(flow)
    ma = actuated_mass(flow)
    if width == 0.0:
        return flow.transition(-start) @ force_input(flow) * ma
    return (flow.transition(-(start + width)) - flow.transition(-start)) @ sigma * (ma / width)


def actuated_input(flow: NdofFlow, start: float, width: float, time_constant: float,
                   until: float) -> np.ndarray:
    """b_f: the effective input vector on Pi2 of a pulse commanded on [start, start + w]
    (latency included in ``start``) through the lag tau_a, counting the force up to
    ``until`` (the grazing phase T - s; the force left after it acts after the impact and
    is not in the design, as the 1-DOF (P1): docs/theory_pulse.md section 7):

        b_f = Phi(-until) z(until) m_a,

    z(until) the deviation from rest under the force of a unit-impulse command, by the
    lag's closed form (module docstring: sigma u + q e^{-h / tau_a} + Phi(h)(z0 - sigma u
    - q) on each piece). tau_a = 0 is :func:`pulse_input` at ``start``.
    """
    if time_constant == 0.0:
        return pulse_input(flow, start, width)
    sigma = static_deflection(flow)
    z, force, t = np.zeros(2 * flow.n), 0.0, start
    for end, u in ((start + width, 1.0 / width), (until, 0.0)):
        h = end - t
        if h <= 0.0:
            continue
        q = lag_particular(flow, force - u, time_constant)
        e = math.exp(-h / time_constant)
        z = flow.transition(h) @ (z - sigma * u - q) + sigma * u + q * e
        force = u + (force - u) * e
        t = end
    return flow.transition(-until) @ z * actuated_mass(flow)


# ----------------------------------------------------------------- the first-order lag

def lag_particular(flow: NdofFlow, transient: float, tau_a: float) -> np.ndarray:
    """q with (A + I / tau_a) q = -B c for the force transient c e^{-h / tau_a}
    (module docstring)."""
    a = flow.A + np.eye(2 * flow.n) / tau_a
    return -np.linalg.solve(a, force_input(flow) * transient)


class LagSegment(NamedTuple):
    """Result of :func:`lag_advance`: deviation z (2n,) and force at the end, the end
    phase, the impacts (times from the start)."""

    z: np.ndarray
    force: float
    tau: float
    impacts: tuple


def lag_advance(flow: NdofFlow, tau0: float, z0, duration: float, command: float,
                transient: float, tau_a: float, max_impacts: int = 1000) -> LagSegment:
    """The exact motion for ``duration`` under the force F(h) = command + transient
    e^{-h / tau_a} on the actuated coordinate (module docstring; tau_a > 0): the free flow
    of z - z_f, impacts by the certified search with the transient's mode, restarted by
    the impact law (x_w = d, v_w+ = -r v_w-, the other velocities unchanged).

    Raises ValueError on an impact slower than :data:`MIN_IMPACT_VELOCITY` (chattering or
    sticking under the actuator's force, not resolved here) or more than ``max_impacts``.
    """
    if not tau_a > 0.0:
        raise ParameterError(f"tau_a={tau_a!r} is invalid: valid range is tau_a > 0 "
                             "(a constant force is advance_with_force)")
    m = flow.model
    n, w = m.n, m.i_w
    z = check_state(flow, z0, "the start state")
    shifted = forced_flow(flow, command)
    sigma_u = static_deflection(flow) * command if command != 0.0 else np.zeros(2 * n)
    h_done, tau, c = 0.0, tau0 % TWO_PI, float(transient)
    impacts = []
    rate = 1.0 / tau_a
    while True:
        q = lag_particular(flow, c, tau_a)
        zp = z - sigma_u - q
        rest = duration - h_done
        hit = None
        if rest > 0.0:
            f = _Eval(shifted, tau, zp, rest, transient=(rate, float(q[w])))
            step = min(m.period / 8.0, 0.25 * math.pi / f.rho)
            hit = _scan_window(f, rest, max(1, int(math.ceil(rest / step))),
                               lambda fa: f.gap_rounding(0.0, fa), f"x{w}")
        h = rest if hit is None else hit
        e = math.exp(-h * rate)
        z = flow.transition(h) @ zp + sigma_u + q * e
        tau = (tau + m.omega * h) % TWO_PI
        if hit is None:
            return LagSegment(z, command + c * e, tau, tuple(impacts))
        wall_x, rest_v = flow.on_wall(tau)
        v_minus = z[n + w] - rest_v
        if v_minus < MIN_IMPACT_VELOCITY or len(impacts) >= max_impacts:
            raise ValueError(f"impact velocity {v_minus:.3g} of x{w} under the actuator's "
                             f"force at phase {tau:.6f}: a chattering or sticking motion, not "
                             f"resolved by lag_advance")
        impacts.append(NdofImpact(h_done + h, tau, v_minus, -m.r * v_minus, False))
        z[w] = wall_x
        z[n + w] = rest_v - m.r * v_minus
        c *= e
        h_done += h

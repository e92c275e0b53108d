"""The exact n-DOF motion of the model filter and the prediction (issue 32;
docs/theory_estimation.md (E11), docs/theory_ndof.md section 15): from a Pi2 deviation
before the correction, the states and Jacobians d z / d z0 at the samples, with the
correction a velocity kick, a force pulse or the pulse through the first-order actuator.
:func:`grazing_control.dynamics.estimation.section_state.trajectory` calls these for an
:class:`~grazing_control.oscillator.ndof.model.NdofModel`.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from grazing_control.dynamics.simulation.actuation import pulse_start
from grazing_control.oscillator.ndof import impact as ndof_impact
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.forced import (actuated_mass, forced_flow, lag_advance,
                                                    lag_particular, static_deflection)
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from .section_state import TWO_PI, actuator_legs, correction_legs

__all__ = ["ndof_flow", "ndof_transitions", "ndof_trajectory", "ndof_actuated_trajectory"]


@functools.lru_cache(maxsize=8)
def ndof_flow(model: NdofModel) -> NdofFlow:
    """The model's exact flow, built once per model."""
    return NdofFlow.of(model)


def ndof_transitions(flow: NdofFlow, h) -> np.ndarray:
    """Phi(h_j) = Re(V e^{Lambda h_j} U) for an array of times: (m, 2n, 2n)
    (:meth:`NdofFlow.transition`, vectorised)."""
    e = np.exp(np.multiply.outer(np.asarray(h, dtype=float), flow.eigenvalues))
    return np.einsum("ik,mk,kj->mij", flow.modes, e, flow.inverse).real


def ndof_trajectory(model: NdofModel, z0, s, correction: float, delay: float,
                     duration: float, width: float = 0.0, force_limit: float = math.inf):
    """:func:`.section_state.trajectory` of the n-DOF oscillator (docs/theory_estimation.md, (E11)): from
    the Pi2 deviation z0 (2n) before the correction, the kick v_{i_a} += correction at
    ``delay``; between events z(s) = Phi(s - s_e) z_e, d z(s) / d z0 = Phi(s - s_e) M_e,
    and an impact at t_i (from :func:`grazing_control.oscillator.ndof.impact.advance`)
    puts z- = Phi(t_i - s_e) z_e on the wall with its v-, z+ with v+ (the other
    velocities unchanged) and M <- S Phi(t_i - s_e) M (S the saltation matrix).

    With ``width`` > 0 the correction is the force pulse F = m_a correction / width
    (clipped to +-``force_limit``) on the actuated coordinate, centred at ``delay``
    (:func:`correction_legs`; docs/theory_ndof.md section 15): during it the deviation
    less the static deflection sigma F obeys the free flow against the wall at
    Delta d - sigma_w F (oscillator/ndof/forced.py), so z(s) = Phi(s - s_e)(z_e - sigma F)
    + sigma F and the saltation matrices are the shifted flow's; F does not depend on z0
    (the correction is known), so the Jacobian keeps its form.
    A motion that sticks (a sticking impact of the n-DOF core, issue 32) raises ValueError."""
    flow = ndof_flow(model)
    n, w = model.n, model.i_w
    z = np.array(z0, dtype=float).reshape(-1)
    if z.shape != (2 * n,):
        raise ParameterError(f"z0 has {z.size} entries: valid is 2n = {2 * n}")
    m = np.eye(2 * n)
    events, impacts = [], []
    ma = actuated_mass(flow) if width > 0.0 else 1.0
    legs = correction_legs(correction, delay, duration, width, force_limit / ma)
    for start, end, kick, force in legs:
        force *= ma
        z = z.copy()
        z[n + model.i_a] += kick
        fl = forced_flow(flow, force)
        shift = static_deflection(flow) * force if force else np.zeros(2 * n)
        events.append((start, z - shift, m, shift))
        try:
            seg = ndof_impact.advance(fl, (flow.tau2 + model.omega * start) % TWO_PI,
                                      z - shift, end - start)
        except ndof_impact.ChatteringError as exc:
            raise ValueError(f"the model's motion chatters or sticks: no fit ({exc})") from None
        t_e, z_e = start, z - shift
        for imp in seg.impacts:
            if imp.sticking:   # issue 32: advance sticks instead of raising
                raise ValueError(f"the model's motion sticks at t={start + imp.dt:.9g}: no fit")
            ti = start + imp.dt
            phi = flow.transition(ti - t_e)
            wall_x, rest_v = fl.on_wall(imp.phase)
            z_minus = phi @ z_e
            z_minus[w], z_minus[n + w] = wall_x, imp.v_minus + rest_v
            m = ndof_impact.saltation_matrix(fl, imp.phase, z_minus) @ phi @ m
            z_e = z_minus.copy()
            z_e[n + w] = imp.v_plus + rest_v
            t_e = ti
            events.append((ti, z_e, m, shift))
            impacts.append((ti, imp.phase, imp.v_minus, imp.v_plus))
        m = flow.transition(end - t_e) @ m
        z = np.array(seg.z, dtype=float) + shift
    times = np.array([e[0] for e in events])
    idx = np.clip(np.searchsorted(times, s, side="left") - 1, 0, len(events) - 1)
    phi = ndof_transitions(flow, s - times[idx])
    out = np.einsum("mij,mj->mi", phi, np.array([e[1] for e in events])[idx])
    if width > 0.0:
        out = out + np.array([e[3] for e in events])[idx]
    jac = np.einsum("mij,mjk->mik", phi, np.array([e[2] for e in events])[idx])
    return out, jac, z, m, impacts


def ndof_actuated_trajectory(model: NdofModel, z0, s, correction: float, delay: float,
                              duration: float, width: float, force_limit: float, actuator,
                              force0: float):
    """:func:`.section_state.trajectory` of the n-DOF oscillator through a first-order actuator
    (docs/theory_ndof.md section 15, the plant's
    :func:`grazing_control.dynamics.maps.modal_map.actuated_step`): the command
    u = m_a correction / width (clipped to +-``force_limit``) on :func:`actuator_legs`, the
    force F(h) = u + c e^{-h / tau_a} on each leg from ``force0``, the motion
    :func:`grazing_control.oscillator.ndof.forced.lag_advance`'s. Between events
    z(s) = Phi(s - s_e)(z_e - sigma u - q) + sigma u + q e^{-(s - s_e) / tau_a}, q the
    transient's particular solution (:func:`lag_particular`); F does not depend on z0, so
    d z / d z0 = Phi(s - s_e) M_e, and an impact puts M <- S Phi M with S the saltation
    matrix under the force there (the flow forced by F(t_i)). tau_a = 0 (a latency only):
    the constant pulse starting ``actuator.latency`` later (force0 must be 0)."""
    flow = ndof_flow(model)
    n, w = model.n, model.i_w
    tau_a = actuator.time_constant
    if tau_a == 0.0:
        if force0 != 0.0:
            raise ParameterError(f"force0={force0!r} is invalid: an actuator without lag leaves "
                                 "no force at the section, valid value is 0")
        actuator_legs(model, correction, delay, duration, width, force_limit, actuator)
        start = pulse_start(duration, delay, width) + actuator.latency
        return ndof_trajectory(model, z0, s, correction, start + 0.5 * width, duration,
                                width, force_limit)
    z = np.array(z0, dtype=float).reshape(-1)
    if z.shape != (2 * n,):
        raise ParameterError(f"z0 has {z.size} entries: valid is 2n = {2 * n}")
    ma = actuated_mass(flow)
    sigma = static_deflection(flow)
    m = np.eye(2 * n)
    f = float(force0)
    events, impacts = [], []           # (time, z - sigma u - q, M, sigma u, q)
    rate = 1.0 / tau_a
    for start, end, u in actuator_legs(model, ma * correction, delay, duration, width,
                                       force_limit, actuator):
        if end <= start:
            continue
        tau = (flow.tau2 + model.omega * start) % TWO_PI
        try:
            seg = lag_advance(flow, tau, z, end - start, u, f - u, tau_a)
        except ValueError as exc:
            raise ValueError(f"the model's motion chatters or sticks under the actuator's "
                             f"force: no fit ({exc})") from None
        sig_u = sigma * u if u != 0.0 else np.zeros(2 * n)
        c, t_e = f - u, start
        q = lag_particular(flow, c, tau_a)
        events.append((start, z - sig_u - q, m, sig_u, q))
        for imp in seg.impacts:
            ti = start + imp.dt
            h = ti - t_e
            decay = math.exp(-h * rate)
            phi = flow.transition(h)
            z_minus = phi @ events[-1][1] + sig_u + q * decay
            force = u + c * decay
            fl = forced_flow(flow, force)
            shift = sigma * force
            wall_x, rest_v = fl.on_wall(imp.phase)
            zs = z_minus - shift
            zs[w], zs[n + w] = wall_x, imp.v_minus + rest_v
            m = ndof_impact.saltation_matrix(fl, imp.phase, zs) @ phi @ m
            z_plus = z_minus.copy()
            z_plus[w] = zs[w] + shift[w]
            z_plus[n + w] = imp.v_plus + rest_v + shift[n + w]
            c *= decay
            q = lag_particular(flow, c, tau_a)
            t_e = ti
            events.append((ti, z_plus - sig_u - q, m, sig_u, q))
            impacts.append((ti, imp.phase, imp.v_minus, imp.v_plus))
        m = flow.transition(end - t_e) @ m
        z, f = np.array(seg.z, dtype=float), float(seg.force)
    times = np.array([e[0] for e in events])
    idx = np.clip(np.searchsorted(times, s, side="left") - 1, 0, len(events) - 1)
    h = s - times[idx]
    phi = ndof_transitions(flow, h)
    out = np.einsum("mij,mj->mi", phi, np.array([e[1] for e in events])[idx])
    out += np.array([e[3] for e in events])[idx]
    out += np.array([e[4] for e in events])[idx] * np.exp(-h * rate)[:, None]
    jac = np.einsum("mij,mjk->mik", phi, np.array([e[2] for e in events])[idx])
    return out, jac, z, m, impacts

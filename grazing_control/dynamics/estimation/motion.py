"""The exact motion over one period of the model the estimator fits, for any model.

From a Pi2 deviation before the correction: the states and the Jacobians d z / d z0 at
the sample times, the end of the period and its monodromy, the impacts; the correction a
velocity kick (Eq. 28), a force pulse, or the pulse through the first-order actuator
(docs/theory_estimation.md (E3), (E8), (E11); docs/theory_pulse.md; docs/theory_ndof.md
section 15). One entry, :func:`trajectory` (with :func:`actuated_trajectory`,
:func:`trajectory_end`, :func:`section_force` and the legs of the period), and two
implementations behind it: the 1-DOF closed form (:class:`OscillatorParams`: the
certified core or the compiled kernel, unchanged bit for bit: tests/test_estimation_compiled.py)
and a model file of any n (:class:`NdofModel`: the modal flow, :func:`modal_trajectory`,
:func:`modal_actuated_trajectory`). :mod:`.section_state`'s estimators fit it.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from grazing_control.oscillator import kernel as _kernel
from grazing_control.oscillator.flow import transition_matrix
from grazing_control.oscillator.impact import advance, saltation_matrix
from grazing_control.oscillator.ndof import impact as ndof_impact
from grazing_control.oscillator.ndof.flow import NdofFlow, matmul, matvec
from grazing_control.oscillator.ndof.forced import (actuated_mass, forced_clearance,
                                                    forced_flow, lag_advance, lag_particular,
                                                    static_deflection)
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from grazing_control.dynamics.simulation.actuation import pulse_force, pulse_start

__all__ = ["phi_rows", "correction_legs", "actuator_legs", "trajectory", "actuated_trajectory",
           "trajectory_end", "carry", "section_force", "modal_flow", "modal_transitions",
           "modal_trajectory", "modal_actuated_trajectory"]

TWO_PI = 2.0 * math.pi


def phi_rows(zeta: float, h):
    """Phi(h) = exp(A h) for an array of h: (n, 2, 2) (the closed form of
    :func:`grazing_control.oscillator.flow.transition_matrix`, vectorised)."""
    h = np.asarray(h, dtype=float)
    wd = math.sqrt(1.0 - zeta * zeta)
    e = np.exp(-zeta * h)
    c = np.cos(wd * h)
    s = np.sin(wd * h) / wd
    out = np.empty(h.shape + (2, 2))
    out[..., 0, 0] = e * (c + zeta * s)
    out[..., 0, 1] = e * s
    out[..., 1, 0] = -e * s
    out[..., 1, 1] = e * (c - zeta * s)
    return out


def correction_legs(correction: float, delay: float, duration: float, width: float = 0.0,
                    force_limit: float = math.inf) -> list:
    """The period (0, ``duration``] as legs (start, end, kick, force): the correction as a
    velocity kick at ``delay`` (``width`` 0, Eq. 28), or as the rig's force pulse of
    ``width`` centred at ``delay``, force correction / width clipped to
    +-``force_limit`` (:mod:`grazing_control.dynamics.simulation.actuation`, docs/theory_pulse.md;
    it starts where the simulator's starts it:
    :func:`grazing_control.dynamics.simulation.actuation.pulse_start`)."""
    if width > 0.0 and correction != 0.0:
        if not width < duration:
            raise ParameterError(f"pulse_width={width!r} is invalid: valid range is "
                                 f"0 <= pulse_width < T = {duration!r}")
        start = pulse_start(duration, delay, width)
        force = pulse_force(correction, width, force_limit)
        legs = [(0.0, start, 0.0, 0.0), (start, start + width, 0.0, force),
                (start + width, duration, 0.0, 0.0)]
        return [leg for leg in legs if leg[1] > leg[0]]
    if delay > 0.0:
        return [(0.0, delay, 0.0, 0.0), (delay, duration, correction, 0.0)]
    return [(0.0, duration, correction, 0.0)]


def _through_impact(p: OscillatorParams, q: OscillatorParams, m, g, h: float, imp,
                    wall: bool):
    """The Jacobian ``m`` and the wall's sensitivity ``g`` carried by the free flow over
    ``h`` and through the impact ``imp`` of the oscillator ``q`` (the wall where a force
    shifts it): M <- S Phi(h) M, g <- S Phi(h) g + (I - S) e1 ((E3), (E8))."""
    phi = np.array(transition_matrix(p.zeta, h)).reshape(2, 2)
    sal = np.array(saltation_matrix(q, imp.phase, imp.v_minus)).reshape(2, 2)
    m = sal @ phi @ m
    if wall:
        g = sal @ (phi @ g) + np.array([1.0 - sal[0, 0], -sal[1, 0]])
    return m, g


@functools.lru_cache(maxsize=16)
def _shifted_wall(p: OscillatorParams, force: float) -> OscillatorParams:
    """The oscillator against the wall moved to Delta d - ``force`` (a pulse's, below),
    kept for the calls of one model fit (the same pulse in each of its iterations)."""
    return p.with_(delta_d=p.delta_d - force)


def trajectory(p: OscillatorParams, z0, s, correction: float = 0.0, delay: float = 0.0,
               duration: float | None = None, *, wall: bool = False, width: float = 0.0,
               force_limit: float = math.inf, actuator=None, force0: float = 0.0,
               kernel: bool = False):
    """The exact motion from the section state ``z0`` (before the correction): the
    deviation and its Jacobian d z(s_j) / d z0 at the sorted times ``s`` in
    (0, duration], with the correction (a known velocity kick) at ``delay`` (E3).

    Between events z(s) = Phi(s - s_e) z_e; the Jacobian is Phi(s - s_e) M_e with M_e
    the product of Phi and the saltation matrices S of the impacts before s (spec
    section 5); the known kick shifts the state and leaves the Jacobian unchanged.

    With ``width`` > 0 the correction is the rig's force pulse instead (a constant force
    F = correction / width, clipped to ``force_limit``, centred at ``delay``:
    :func:`correction_legs`): during it the deviation shifted by (F, 0) obeys the free
    flow against the wall moved to Delta d - F (docs/theory_pulse.md, as
    :func:`grazing_control.dynamics.simulation.actuation.pulse_step`), so z(s) = Phi(s - s_e)
    (z_e - F e1) + F e1 and the saltation matrices are those of the shifted wall; the
    Jacobian and the wall's sensitivity keep their form (F does not depend on z0).
    Width 0 is the kick, bit for bit.

    ``kernel``: compiled (numba; issue 30, the controller's estimate at each section):
    the exact flow with impacts of :func:`grazing_control.oscillator.kernel.advance`
    instead of the core's :func:`grazing_control.oscillator.impact.advance` (the same
    segments bit for bit, tests/test_kernel.py), and the evaluation at the samples of
    :mod:`.compiled_flow` (the same floating point operations as the NumPy code here);
    every output the same bit for bit (tests/test_estimation_compiled.py), several times faster
    (benchmarks/bench_stream_estimator.py). The actuator's flow is the core's in both; for
    a model file the events are the core's and the evaluation at the samples is
    :mod:`.compiled_modal_flow`'s (issue 32, bit for bit as well).

    With an ``actuator`` (:class:`grazing_control.dynamics.simulation.actuator.Actuator`, not
    ideal; ``width`` > 0) the pulse is the command, and the force on the mass follows it
    through the first-order lag after the latency, from ``force0`` (the force at the
    section, left by the earlier corrections: :func:`section_force`): the exact flow of
    :func:`_actuated_trajectory`. None or the ideal actuator (with ``force0`` 0): the
    constant pulse above, bit for bit.

    Returns
    -------
    z : (n, 2) deviations, jac : (n, 2, 2), end : (dx, dv) at ``duration`` (default T),
    monodromy : (2, 2) d end / d z0, impacts : list of (time, phase, v-, v+).

    With ``wall`` also the sensitivities to the wall, d z(s_j) / d Delta d (n, 2) and
    d end / d Delta d (2,): zero before the first impact; an impact adds
    (I - S) e1 to the perturbation carried up to it, d z+ = S d z- + (I - S) e1 d(Delta d)
    (docs/theory_estimation.md, (E8)); the flow carries it on by Phi and S. The other
    outputs are the same as without it, bit for bit.

    With a model file for ``p`` (:class:`~grazing_control.oscillator.ndof.model.NdofModel`,
    any n) it is the exact motion over its modal flow (:func:`modal_trajectory`): z (m, 2n),
    jac (m, 2n, 2n), end (2n,), monodromy (2n, 2n), the same impacts; the kick or the force
    pulse of ``width``, through the first-order ``actuator`` from ``force0``
    (:func:`actuated_trajectory`); with ``wall`` the sensitivities (m, 2n) and (2n,), an
    impact adding (I - S) e_w (docs/theory_estimation.md, (E12)).
    """
    duration = p.period if duration is None else float(duration)
    s = np.asarray(s, dtype=float)
    if actuator is not None and not (actuator.ideal and force0 == 0.0):
        return actuated_trajectory(p, z0, s, correction, delay, duration, width, force_limit,
                                   actuator, force0, wall=wall)
    if isinstance(p, NdofModel):
        return modal_trajectory(p, z0, s, correction, delay, duration, width, force_limit,
                                kernel, wall=wall)
    flow = _kernel.advance if kernel else advance
    # events: (time, state after, jacobian after); start, kick, impacts
    events = []
    tau = p.tau2
    z = (float(z0[0]), float(z0[1]))
    m = np.eye(2)
    g = np.zeros(2)                     # d z / d Delta d (``wall``)
    t0 = 0.0
    impacts = []
    legs = correction_legs(correction, delay, duration, width, force_limit)
    for start, end, kick, force in legs:
        z = (z[0], z[1] + kick)
        events.append((start, z, m, g, force))
        q = p if force == 0.0 else _shifted_wall(p, force)
        seg = flow(q, (tau + p.omega * start) % TWO_PI, z[0] - force, z[1], end - start)
        for imp in seg.impacts:
            if imp.sticking:
                raise ValueError("the model's motion sticks to the wall: no fit")
            ti = start + imp.dt
            m, g = _through_impact(p, q, m, g, ti - t0, imp, wall)
            psi = imp.phase - p.lag
            z = (p.d - p.amplitude * math.cos(psi),
                 imp.v_plus + p.amplitude * p.omega * math.sin(psi))
            t0 = ti
            events.append((ti, z, m, g, force))
            impacts.append((ti, imp.phase, imp.v_minus, imp.v_plus))
        f = np.array(transition_matrix(p.zeta, end - t0)).reshape(2, 2)
        m = f @ m
        if wall:
            g = f @ g
        z = (seg.dx + force if force else seg.dx, seg.dv)
        t0 = end
    times = np.array([e[0] for e in events])
    if kernel:
        return _compiled_samples(p, events, times, s, z, m, g, impacts, wall)
    idx = np.searchsorted(times, s, side="left") - 1   # the last event strictly before s
    idx = np.clip(idx, 0, len(events) - 1)
    zs = np.array([e[1] for e in events])[idx]
    ms = np.array([e[2] for e in events])[idx]
    phi = phi_rows(p.zeta, s - times[idx])
    forces = np.array([e[4] for e in events])
    if forces.any():                    # in a pulse: Phi (z_e - F e1) + F e1
        fs = forces[idx]
        zs = zs - np.outer(fs, (1.0, 0.0))
        out = np.einsum("nij,nj->ni", phi, zs) + np.outer(fs, (1.0, 0.0))
    else:
        out = np.einsum("nij,nj->ni", phi, zs)
    jac = np.einsum("nij,njk->nik", phi, ms)
    if wall:
        gs = np.array([e[3] for e in events])[idx]
        return out, jac, z, m, impacts, np.einsum("nij,nj->ni", phi, gs), g
    return out, jac, z, m, impacts


def trajectory_end(p: OscillatorParams, z0, correction: float = 0.0, delay: float = 0.0,
                   duration: float | None = None, *, width: float = 0.0,
                   force_limit: float = math.inf, kernel: bool = False) -> tuple:
    """``end`` of :func:`trajectory` alone, bit for bit (the same legs and the same
    exact flow, the same ValueError where the motion sticks), without the Jacobian and
    the samples: the controller's prediction of the next section on the realtime
    answer's path (issue 30: a third of the compiled :func:`trajectory`'s time went to
    evaluating its zero samples and carrying a Jacobian nobody reads). The kick or the
    constant pulse only (no actuator, a 1-DOF model)."""
    duration = p.period if duration is None else float(duration)
    flow = _kernel.advance if kernel else advance
    tau = p.tau2
    z = (float(z0[0]), float(z0[1]))
    for start, end, kick, force in correction_legs(correction, delay, duration, width,
                                                   force_limit):
        q = p if force == 0.0 else _shifted_wall(p, force)
        seg = flow(q, (tau + p.omega * start) % TWO_PI, z[0] - force, z[1] + kick,
                   end - start)
        if any(imp.sticking for imp in seg.impacts):
            raise ValueError("the model's motion sticks to the wall: no fit")
        z = (seg.dx + force if force else seg.dx, seg.dv)
    return z


def carry(p: OscillatorParams, z, start: float, duration: float, kicks=(), *,
          kernel: bool = False) -> tuple:
    """The exact motion of the deviation ``z`` at time ``start`` after a section (the
    forcing phase tau2 + omega start) over ``duration``, with the known velocity
    ``kicks`` ((time after the section, dv) pairs; those in (start, start + duration]
    act): (end, monodromy d end / d z, impacts), the flow and the saltation matrices of
    :func:`trajectory` (E3) between the kicks. An arc fit's state at its last sample
    carried to the section through an impact that no sample saw
    (:meth:`grazing_control.dynamics.estimation.stream.StreamEstimator`, an answer
    lead longer than the time from the impact to the section; docs/theory_estimation.md,
    (E2''))."""
    flow = _kernel.advance if kernel else advance
    stop = start + duration
    legs = sorted((at, dv) for at, dv in kicks if start < at <= stop and dv != 0.0)
    z = (float(z[0]), float(z[1]))
    m = np.eye(2)
    g = np.zeros(2)
    impacts = []
    t = start
    for at, dv in legs + [(stop, 0.0)]:
        seg = flow(p, (p.tau2 + p.omega * t) % TWO_PI, z[0], z[1], at - t)
        t0 = 0.0
        for imp in seg.impacts:
            if imp.sticking:
                raise ValueError("the model's motion sticks to the wall: no carry")
            m, g = _through_impact(p, p, m, g, imp.dt - t0, imp, False)
            t0 = imp.dt
            impacts.append((t + imp.dt, imp.phase, imp.v_minus, imp.v_plus))
        m = np.array(transition_matrix(p.zeta, at - t - t0)).reshape(2, 2) @ m
        z = (seg.dx, seg.dv + dv)
        t = at
    return z, m, impacts


_NO_ROWS = np.zeros((0, 2))


def _compiled_samples(p, events, times, s, end, m, g, impacts, wall):
    """The end of :func:`trajectory` (the deviation, Jacobian and wall sensitivity at the
    samples from their events) by :mod:`.compiled_flow`, bit for bit."""
    from grazing_control.dynamics.estimation.compiled_flow import (event_offsets,
                                                                   flow_at_samples)

    idx, hh = event_offsets(times, s)
    zeta = p.zeta
    wd = math.sqrt(1.0 - zeta * zeta)           # as phi_rows, whose NumPy functions these are
    forces = np.array([e[4] for e in events])
    out, jac, gs = flow_at_samples(np.exp(-zeta * hh), np.cos(wd * hh), np.sin(wd * hh), zeta,
                                   wd, idx, np.array([e[1] for e in events]),
                                   np.array([e[2] for e in events]), forces,
                                   np.array([e[3] for e in events]) if wall else _NO_ROWS,
                                   bool(forces.any()), wall)
    if wall:
        return out, jac, end, m, impacts, gs, g
    return out, jac, end, m, impacts


def actuator_legs(p: OscillatorParams, correction: float, delay: float, duration: float,
                  width: float, force_limit: float, actuator) -> list:
    """The period (0, ``duration``] through ``actuator`` as legs (start, end, command):
    the command F (:func:`grazing_control.dynamics.simulation.actuation.pulse_force`) on the pulse
    centred at ``delay`` (:func:`grazing_control.dynamics.simulation.actuation.pulse_start`)
    reaches the lag ``actuator.latency`` later, and must end within the period, as in
    the plant's :func:`grazing_control.dynamics.simulation.actuator.actuated_step` (its legs,
    empty ones included). ParameterError naming pulse_width or actuator_latency."""
    if not (math.isfinite(width) and 0.0 < width < duration):
        raise ParameterError(f"pulse_width={width!r} is invalid with an actuator: valid range "
                             f"is 0 < pulse_width < T = {duration!r}")
    on = pulse_start(duration, delay, width) + actuator.latency
    off = on + width
    if not off < duration:
        raise ParameterError(f"actuator_latency={actuator.latency!r} is invalid: valid range "
                             f"is pulse start + actuator_latency + pulse_width < T = "
                             f"{duration!r} (the force within the period)")
    return [(0.0, on, 0.0), (on, off, pulse_force(correction, width, force_limit)),
            (off, duration, 0.0)]


def section_force(p: OscillatorParams, force0: float, correction: float, delay: float,
                  width: float, force_limit: float, actuator,
                  duration: float | None = None) -> float:
    """The actuator's force at the end of the period (the next section's ``force0`` of
    :func:`trajectory`): the lag's closed form over :func:`actuator_legs`,
    f = u + (f - u) e^{-h / tau_a} per leg (u = f at once without lag)."""
    duration = p.period if duration is None else float(duration)
    f = float(force0)
    tau_a = actuator.time_constant
    if isinstance(p, NdofModel):        # the command is the force m_a Delta v / w
        correction = actuated_mass(modal_flow(p)) * correction
    for start, end, u in actuator_legs(p, correction, delay, duration, width, force_limit,
                                       actuator):
        if end > start:
            f = u + (f - u) * math.exp(-(end - start) / tau_a) if tau_a > 0.0 else u
    return f


def actuated_trajectory(p, z0, s, correction: float, delay: float, duration: float,
                        width: float, force_limit: float, actuator, force0: float, *,
                        wall: bool = False):
    """:func:`trajectory` through the first-order ``actuator`` from the force ``force0``,
    for any model: a model file's :func:`modal_actuated_trajectory`, else the 1-DOF closed
    form's (:func:`_actuated_trajectory`), the same outputs as :func:`trajectory`."""
    if isinstance(p, NdofModel):
        return modal_actuated_trajectory(p, z0, s, correction, delay, duration, width,
                                         force_limit, actuator, force0, wall=wall)
    return _actuated_trajectory(p, z0, s, correction, delay, duration, wall, width,
                                force_limit, actuator, force0)


def _actuated_trajectory(p, z0, s, correction, delay, duration, wall, width, force_limit,
                         actuator, force0):
    """:func:`trajectory` through a first-order actuator (docs/theory_pulse.md sections
    5-8, :mod:`grazing_control.dynamics.simulation.actuator`): per leg of constant command u the
    exact flow of
    :func:`grazing_control.dynamics.simulation.actuator.lag_flow` (force u + (f - u) e^{-h/tau_a},
    impacts certified), in its pieces z(h) = Phi(h) z'_e + (x_f, v_f)(h). The force is
    a function of time alone (the command is known), so d z / d z0 is carried by Phi
    between impacts and at each impact by the saltation matrix with the acceleration
    under the force there (the wall shifted by it, as the constant pulse's); the wall's
    sensitivity as (E8)."""
    from grazing_control.dynamics.simulation.actuator import lag_flow

    tau_a = actuator.time_constant
    if tau_a == 0.0 and force0 != 0.0:
        raise ParameterError(f"force0={force0!r} is invalid: an actuator without lag leaves "
                             "no force at the section, valid value is 0")
    z = np.array((float(z0[0]), float(z0[1])))
    m = np.eye(2)
    g = np.zeros(2)
    f = float(force0)
    t0 = 0.0                            # the last event of the Jacobian (start or impact)
    events = []                         # (time, z', k, F_inf, M, g) of each piece
    impacts = []
    for start, end, u in actuator_legs(p, correction, delay, duration, width, force_limit,
                                       actuator):
        length = end - start
        if length <= 0.0:
            continue
        c = f - u if tau_a > 0.0 else 0.0
        flow = lag_flow(p, (p.tau2 + p.omega * start) % TWO_PI, float(z[0]), float(z[1]),
                        length, u, c, tau_a)
        pieces = list(flow.pieces)
        for i, piece in enumerate(pieces):
            if i > 0:                   # the impact that started this piece
                imp = flow.impacts[i - 1]
                ti = start + imp.dt
                force = u + (c * math.exp(-imp.dt / tau_a) if tau_a > 0.0 else 0.0)
                m, g = _through_impact(p, p.with_(delta_d=p.delta_d - force), m, g, ti - t0,
                                       imp, wall)
                t0 = ti
                impacts.append((ti, imp.phase, imp.v_minus, imp.v_plus))
            else:
                phi = np.array(transition_matrix(p.zeta, start - t0)).reshape(2, 2)
                m = phi @ m
                if wall:
                    g = phi @ g
                t0 = start
            events.append((start + piece.h0, piece.zp, piece.k, u, m, g))
        z = np.array((flow.dx, flow.dv))
        f = flow.force if tau_a > 0.0 else u
    phi = np.array(transition_matrix(p.zeta, duration - t0)).reshape(2, 2)
    m_end = phi @ m
    g_end = phi @ g
    times = np.array([e[0] for e in events])
    idx = np.clip(np.searchsorted(times, s, side="left") - 1, 0, len(events) - 1)
    hh = s - times[idx]
    phis = phi_rows(p.zeta, hh)
    zp = np.array([e[1] for e in events])[idx]
    kk = np.array([e[2] for e in events])[idx]
    f_inf = np.array([e[3] for e in events])[idx]
    decay = np.exp(-hh / tau_a) if tau_a > 0.0 else np.zeros_like(hh)
    out = np.einsum("nij,nj->ni", phis, zp)
    out[:, 0] += f_inf + kk * decay
    if tau_a > 0.0:
        out[:, 1] -= kk * decay / tau_a
    jac = np.einsum("nij,njk->nik", phis, np.array([e[4] for e in events])[idx])
    end = (float(z[0]), float(z[1]))
    if wall:
        gs = np.einsum("nij,nj->ni", phis, np.array([e[5] for e in events])[idx])
        return out, jac, end, m_end, impacts, gs, g_end
    return out, jac, end, m_end, impacts


# -- a model file of any n: the modal flow (docs/theory_estimation.md (E11)) ---------------

@functools.lru_cache(maxsize=8)
def modal_flow(model: NdofModel) -> NdofFlow:
    """The model's exact flow, built once per model's dynamics: a model that differs
    from another only in its clearance (:meth:`NdofModel.with_clearance`) gets that
    one's flow, with its own model (the flow does not depend on Delta d)."""
    root = model.dynamics
    if root is model:
        return NdofFlow.of(model)
    return dataclasses.replace(modal_flow(root), model=model)


def modal_transitions(flow: NdofFlow, h) -> np.ndarray:
    """Phi(h_j) = Re(V e^{Lambda h_j} U) for an array of times: (m, 2n, 2n)
    (:meth:`NdofFlow.transition`, vectorised)."""
    e = np.exp(np.multiply.outer(np.asarray(h, dtype=float), flow.eigenvalues))
    return np.einsum("ik,mk,kj->mij", flow.modes, e, flow.inverse).real


def modal_trajectory(model: NdofModel, z0, s, correction: float, delay: float,
                     duration: float, width: float = 0.0, force_limit: float = math.inf,
                     kernel: bool = False, *, wall: bool = False):
    """:func:`trajectory` of a model file (docs/theory_estimation.md, (E11)): from
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
    A motion that sticks (a sticking impact of the n-DOF core, issue 32) raises ValueError.
    ``kernel``: compiled (:func:`grazing_control.oscillator.kernel.modal_events`, the
    events of the period, once kernel.warm_up_modal has loaded it; the evaluation at the
    samples by :mod:`.compiled_modal_flow`), the same numbers bit for bit
    (tests/test_ndof_compiled.py, tests/test_estimation_compiled.py); a period the
    compiled events leave to the pure path (a stick, a contact at rest) runs this
    function's own loop.

    ``wall``: also d z(s_j) / d Delta d (m, 2n) and d end / d Delta d (2n,) (E12): g = 0
    before the first impact, g <- S Phi g + (I - S) e_w at each impact (S the saltation
    matrix there, the shifted wall's in a pulse: the shift does not depend on Delta d),
    carried by Phi between them; computed on the pure path (``kernel`` ignored), the
    other outputs the same as without it."""
    flow = modal_flow(model)
    n = model.n
    z = np.array(z0, dtype=float).reshape(-1)
    if z.shape != (2 * n,):
        raise ParameterError(f"z0 has {z.size} entries: valid is 2n = {2 * n}")
    ma = actuated_mass(flow) if width > 0.0 else 1.0
    legs = correction_legs(correction, delay, duration, width, force_limit / ma)
    kernel = kernel and not wall
    events = _compiled_modal_events(flow, z, legs, ma) if kernel else None
    times, zs, ms, shifts, z, m, impacts, *gs = events or _modal_events(flow, z, legs, ma,
                                                                         wall)
    if kernel:
        return _compiled_modal_samples(flow, times, zs, ms, shifts, s, width > 0.0) + (
            z, m, impacts)
    idx = np.clip(np.searchsorted(times, s, side="left") - 1, 0, len(times) - 1)
    phi = modal_transitions(flow, s - times[idx])
    out = np.einsum("mij,mj->mi", phi, zs[idx])
    if width > 0.0:
        out = out + shifts[idx]
    jac = np.einsum("mij,mjk->mik", phi, ms[idx])
    if wall:
        return out, jac, z, m, impacts, np.einsum("mij,mj->mi", phi, gs[0][idx]), gs[1]
    return out, jac, z, m, impacts


def _modal_events(flow: NdofFlow, z: np.ndarray, legs, ma: float, wall: bool = False):
    """The events of :func:`modal_trajectory`'s period (each leg's start and each impact):
    (times, z_e, M_e, shifts sigma F, z at the end, M at the end, impacts), the products
    in the order of :func:`grazing_control.oscillator.ndof.flow.matvec` (which the
    compiled events repeat); with ``wall`` also (g_e, g at the end) (E12)."""
    model = flow.model
    n, w = model.n, model.i_w
    m = np.eye(2 * n)
    g = np.zeros(2 * n)
    events, impacts, gs = [], [], []
    for start, end, kick, force in legs:
        force *= ma
        z = z.copy()
        z[n + model.i_a] += kick
        fl = forced_flow(flow, force)
        shift = static_deflection(flow) * force if force else np.zeros(2 * n)
        events.append((start, z - shift, m, shift))
        gs.append(g)
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
            z_minus = matvec(phi, z_e)
            z_minus[w], z_minus[n + w] = wall_x, imp.v_minus + rest_v
            sal = ndof_impact.saltation_matrix(fl, imp.phase, z_minus)
            m = matmul(matmul(sal, phi), m)
            if wall:        # (E12): the wall moved by d acts through the impact
                g = sal @ (phi @ g) - sal[:, w]
                g[w] += 1.0
            z_e = z_minus.copy()
            z_e[n + w] = imp.v_plus + rest_v
            t_e = ti
            events.append((ti, z_e, m, shift))
            gs.append(g)
            impacts.append((ti, imp.phase, imp.v_minus, imp.v_plus))
        m = matmul(flow.transition(end - t_e), m)
        g = flow.transition(end - t_e) @ g
        z = np.array(seg.z, dtype=float) + shift
    out = (np.array([e[0] for e in events]), np.array([e[1] for e in events]),
           np.array([e[2] for e in events]), np.array([e[3] for e in events]), z, m, impacts)
    return out + (np.array(gs), g) if wall else out


def _compiled_modal_events(flow: NdofFlow, z: np.ndarray, legs, ma: float):
    """:func:`_modal_events` compiled (oscillator/kernel/compiled_modal.py
    ``modal_events``), or None where it is not loaded or leaves the period to the pure
    path. The legs' forced flows differ from the free one only in Delta d (their wall)."""
    compiled = _kernel.modal_events()
    if compiled is None:
        return None
    model = flow.model
    rows, shifts = [], []
    for start, end, kick, force in legs:
        force *= ma
        rows.append((start, end, kick, forced_clearance(flow, force)))
        shifts.append(static_deflection(flow) * force if force else np.zeros(2 * model.n))
    out = compiled(ndof_impact.search_constants(flow), float(flow.tau2), int(model.i_a), z,
                   np.array(rows, dtype=float), np.array(shifts), 1e-6 * model.period)
    if out is None:
        return None
    return out[:6] + ([tuple(row) for row in out[6].tolist()],)


def _compiled_modal_samples(flow: NdofFlow, times, zs, ms, shifts, s, shifted: bool):
    """(z, jac) at the samples of :func:`modal_trajectory` from its events by
    :mod:`.compiled_modal_flow`, bit for bit."""
    from .compiled_flow import event_offsets
    from .compiled_modal_flow import modal_flow_at_samples

    idx, h = event_offsets(times, s)
    e = np.exp(np.multiply.outer(h, flow.eigenvalues))     # as modal_transitions
    return modal_flow_at_samples(flow.modes, e, flow.inverse, idx, zs, ms, shifts, shifted)


def modal_actuated_trajectory(model: NdofModel, z0, s, correction: float, delay: float,
                              duration: float, width: float, force_limit: float, actuator,
                              force0: float, *, wall: bool = False):
    """:func:`trajectory` of a model file through a first-order actuator
    (docs/theory_ndof.md section 15, the plant's
    :func:`grazing_control.dynamics.maps.modal_map.actuated_step`): the command
    u = m_a correction / width (clipped to +-``force_limit``) on :func:`actuator_legs`, the
    force F(h) = u + c e^{-h / tau_a} on each leg from ``force0``, the motion
    :func:`grazing_control.oscillator.ndof.forced.lag_advance`'s. Between events
    z(s) = Phi(s - s_e)(z_e - sigma u - q) + sigma u + q e^{-(s - s_e) / tau_a}, q the
    transient's particular solution (:func:`lag_particular`); F does not depend on z0, so
    d z / d z0 = Phi(s - s_e) M_e, and an impact puts M <- S Phi M with S the saltation
    matrix under the force there (the flow forced by F(t_i)). tau_a = 0 (a latency only):
    the constant pulse starting ``actuator.latency`` later (force0 must be 0). ``wall``:
    the wall's sensitivities as :func:`modal_trajectory`'s (E12; the force does not depend
    on Delta d)."""
    flow = modal_flow(model)
    n, w = model.n, model.i_w
    tau_a = actuator.time_constant
    if tau_a == 0.0:
        if force0 != 0.0:
            raise ParameterError(f"force0={force0!r} is invalid: an actuator without lag leaves "
                                 "no force at the section, valid value is 0")
        actuator_legs(model, correction, delay, duration, width, force_limit, actuator)
        start = pulse_start(duration, delay, width) + actuator.latency
        return modal_trajectory(model, z0, s, correction, start + 0.5 * width, duration,
                                width, force_limit, wall=wall)
    z = np.array(z0, dtype=float).reshape(-1)
    if z.shape != (2 * n,):
        raise ParameterError(f"z0 has {z.size} entries: valid is 2n = {2 * n}")
    ma = actuated_mass(flow)
    sigma = static_deflection(flow)
    m = np.eye(2 * n)
    g = np.zeros(2 * n)                # d z / d Delta d (``wall``, E12)
    f = float(force0)
    events, impacts = [], []           # (time, z - sigma u - q, M, sigma u, q, g)
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
        events.append((start, z - sig_u - q, m, sig_u, q, g))
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
            sal = ndof_impact.saltation_matrix(fl, imp.phase, zs)
            m = sal @ phi @ m
            g = sal @ (phi @ g) - sal[:, w]
            g[w] += 1.0
            z_plus = z_minus.copy()
            z_plus[w] = zs[w] + shift[w]
            z_plus[n + w] = imp.v_plus + rest_v + shift[n + w]
            c *= decay
            q = lag_particular(flow, c, tau_a)
            t_e = ti
            events.append((ti, z_plus - sig_u - q, m, sig_u, q, g))
            impacts.append((ti, imp.phase, imp.v_minus, imp.v_plus))
        m = flow.transition(end - t_e) @ m
        g = flow.transition(end - t_e) @ g
        z, f = np.array(seg.z, dtype=float), float(seg.force)
    times = np.array([e[0] for e in events])
    idx = np.clip(np.searchsorted(times, s, side="left") - 1, 0, len(events) - 1)
    h = s - times[idx]
    phi = modal_transitions(flow, h)
    out = np.einsum("mij,mj->mi", phi, np.array([e[1] for e in events])[idx])
    out += np.array([e[3] for e in events])[idx]
    out += np.array([e[4] for e in events])[idx] * np.exp(-h * rate)[:, None]
    jac = np.einsum("mij,mjk->mik", phi, np.array([e[2] for e in events])[idx])
    if wall:
        gs = np.einsum("mij,mj->mi", phi, np.array([e[5] for e in events])[idx])
        return out, jac, z, m, impacts, gs, g
    return out, jac, z, m, impacts

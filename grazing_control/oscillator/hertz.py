"""A Hertz stop with Hunt-Crossley damping: the nonlinear contact, integrated with error control.

The stop pushes on the mass with (docs/theory_contact.md, Eq. C6)

    F_c = k_c delta^{3/2} (1 + (3/2) alpha delta')   while delta = x - d > 0 and F_c > 0,

and 0 otherwise. The contact ends where 1 + (3/2) alpha delta' = 0 (the mass leaves with
delta > 0, as for the Kelvin-Voigt stop) or delta returns to 0. Outside the contact the
flow is the closed form of :mod:`grazing_control.oscillator.contact` (entry from below by
the wall's certified search; above the stop after an exit, the certified search for the
return of the force or of the gap). In contact there is no closed form: scipy's DOP853
(order 8, embedded error control) with event location on both ends, restarted at the
entry, where delta^{3/2} is not smooth. Its accuracy against a 30-digit mpmath reference
is in docs/theory_contact.md, "Hertz accuracy".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .contact import (MAX_STIFFNESS, CompliantSegment, Contact, Coulomb, LagForce,
                      _above_switch, _Dense, _first_crossing, _force_at, _Region, _stuck)
from .flow import particular
from .impact import ImpactCapError, NonFiniteStateError, _next_impact, _on_wall_at_rest
from .params import OscillatorParams, ParameterError, _check_real

__all__ = ["HuntCrossley", "advance_hertz", "hertz_period_step", "grazing_jump", "RTOL"]

TWO_PI = 2.0 * math.pi
#: Relative tolerance of DOP853 in contact (docs/theory_contact.md, "Hertz accuracy").
RTOL = 1e-12


@dataclass(frozen=True)
class HuntCrossley:
    """Hertz stiffness k_c > 0 (force per delta^{3/2}) and Hunt-Crossley alpha >= 0."""

    stiffness: float
    alpha: float = 0.0

    def __post_init__(self) -> None:
        k = _check_real("stiffness", self.stiffness)
        a = _check_real("alpha", self.alpha)
        if not 0.0 < k <= MAX_STIFFNESS:
            raise ParameterError(f"stiffness={k!r} is invalid: valid range is "
                                 f"0 < k_c <= {MAX_STIFFNESS:g}")
        if not a >= 0.0:
            raise ParameterError(f"alpha={a!r} is invalid: valid range is alpha >= 0")
        object.__setattr__(self, "stiffness", k)
        object.__setattr__(self, "alpha", a)

    @classmethod
    def from_restitution(cls, stiffness: float, r: float, v_ref: float) -> "HuntCrossley":
        """alpha = (1 - r) / v_ref: restitution r at impact velocity v_ref, to leading
        order in alpha v_ref (Eq. C5; r varies with the impact velocity)."""
        r, v_ref = _check_real("r", r), _check_real("v_ref", v_ref)
        if not 0.0 < r <= 1.0:
            raise ParameterError(f"r={r!r} is invalid: valid range is 0 < r <= 1")
        if not v_ref > 0.0:
            raise ParameterError(f"v_ref={v_ref!r} is invalid: valid range is v_ref > 0")
        return cls(stiffness, (1.0 - r) / v_ref)

    def force(self, delta: float, velocity: float) -> float:
        """F_c of Eq. C6 where delta > 0 (may be <= 0: then no contact)."""
        return self.stiffness * delta ** 1.5 * (1.0 + 1.5 * self.alpha * velocity)


def _contact(p: OscillatorParams, law: HuntCrossley, tau0: float, t: float, y, t_end: float,
             rtol: float, push: float = 0.0, slip: float = 0.0, dense=None,
             force: LagForce | None = None):
    """DOP853 through one contact from time t (``push`` = s F_f, the friction of a slip in
    direction ``slip`` = s, Eq. C4; slip 0: no friction; ``force``: an external force
    F(s) in the right-hand side); returns (t_exit or None, state, what ended it: 'leave'
    (the factor 1 + 1.5 alpha delta' reaches 0), 'back' (delta = 0) or 'stop' (x' = 0 in
    a slip))."""
    # imported here: a node that never meets a Hertz contact imports no solver
    # (tests/test_node_common.py)
    from scipy.integrate import solve_ivp
    k, a, zeta, w, d = law.stiffness, law.alpha, p.zeta, p.omega, p.d

    def rhs(s, u):
        delta = u[0]
        f = k * max(delta, 0.0) ** 1.5 * (1.0 + 1.5 * a * u[1])
        return [u[1], math.cos(w * s + tau0) - 2.0 * zeta * u[1] - (delta + d) - f - push]

    if force is not None:
        plain = rhs

        def rhs(s, u):   # noqa: F811 - the actuator's force on top of the stop's equation
            du, acc = plain(s, u)
            return [du, acc + force.at(s)]

    def leave(s, u):
        return 1.0 + 1.5 * a * u[1]
    leave.terminal, leave.direction = True, -1.0

    def back(s, u):
        return u[0]
    back.terminal, back.direction = True, -1.0

    def stop(s, u):
        return u[1]
    stop.terminal, stop.direction = True, -slip

    events = [leave, back] + ([stop] if slip else [])
    # the first step is short: delta^{3/2} is not smooth at the entry
    sol = solve_ivp(rhs, (t, t_end), list(y), method="DOP853", rtol=rtol, atol=rtol * 1e-3,
                    events=events, first_step=1e-8, max_step=0.1,
                    dense_output=dense is not None)
    hits = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
    if dense is not None:   # the stream's states in the contact: DOP853's interpolant
        dense.piece(t, min(hits)[0] if hits else t_end, lambda u: sol.sol(t + u))
    if not hits:
        return None, (sol.y[0, -1], sol.y[1, -1]), None
    te, i = min(hits)
    state = sol.y_events[i][0]
    if i == 2:
        return te, (state[0], 0.0), "stop"
    return te, (0.0 if i == 1 else state[0], state[1]), ("leave", "back")[i]


def advance_hertz(p: OscillatorParams, law: HuntCrossley, tau0: float, x: float, v: float,
                  duration: float, *, rtol: float = RTOL, friction: Coulomb | None = None,
                  max_contacts: int = 10000, times=None,
                  force: LagForce | None = None) -> CompliantSegment:
    """Flow with a Hertz / Hunt-Crossley stop (and Coulomb friction) for a fixed time
    (physical x, v).

    Regions as for :func:`grazing_control.oscillator.contact.advance_compliant`: below
    (closed form, certified entry), contact (DOP853 at ``rtol``), above after an exit with
    delta > 0 (closed form; a new contact where 1 + 1.5 alpha delta' returns to 0, or
    below again at delta = 0). With ``friction`` (Eq. C4 with the Hertz force at rest,
    G = cos tau - x - k_c max(delta, 0)^{3/2}; docs/theory_contact.md §20) each region
    slips with the force -F_f sign(x') (outside the contact the closed form's offset,
    in contact a term of DOP853's right-hand side), a slip ends at the first zero of x'
    (certified outside the contact, DOP853's event in it), and the mass sticks there
    while |G| <= F_s, released in closed form
    (:func:`~grazing_control.oscillator.contact._release_time`). At most
    2 (3 ``max_contacts`` + 3) region changes, slips' ends and sticks
    (:class:`ImpactCapError` beyond). ``times``: the states there as the segment's
    ``states`` (dense output, :class:`~grazing_control.oscillator.contact._Dense`; in
    contact DOP853's interpolant). ``force``: an external force F_inf + C e^{-rate t}
    (:class:`~grazing_control.oscillator.contact.LagForce`, the first-order actuator's):
    outside the contact the closed form's constant and exponential particular solutions,
    in contact a term of DOP853's right-hand side, in G, and a stick released by the
    certified search (docs/theory_contact.md §21).
    """
    for name, value in (("x", x), ("v", v), ("tau0", tau0), ("duration", duration)):
        if not math.isfinite(value):
            raise NonFiniteStateError(f"{name}={value!r} must be finite")
    if friction is not None and friction.static == 0.0:
        friction = None  # Coulomb(0): no friction (else x' = 0 would read as a stick)
    a, k = law.alpha, law.stiffness
    f_kin = friction.kinetic if friction is not None else 0.0
    f_sta = friction.static if friction is not None else 0.0
    t, tau = 0.0, tau0 % TWO_PI
    delta, vel = x - p.d, v
    contacts: list = []
    sticks: list = []
    if delta > 0.0:
        region = "contact" if 1.0 + 1.5 * a * vel > 0.0 else "above"
    else:
        region = "below"
    entry = (0.0, tau, math.nan) if region == "contact" else None
    switches = 0
    forced = None
    dense = _Dense(times if times is not None else (), p.d)

    def at_rest_force(tau, delta, t):
        return (math.cos(tau) - (delta + p.d) - k * max(delta, 0.0) ** 1.5
                + _force_at(force, t))

    def slip_sign(tau, delta, vel):
        """Direction of the friction's slip; 0 for a stick (x' = 0, |G| <= F_s)."""
        if vel != 0.0 or friction is None:
            return math.copysign(1.0, vel)
        g = at_rest_force(tau, delta, t)
        return 0.0 if abs(g) <= f_sta else math.copysign(1.0, g)

    while t < duration:
        remaining = duration - t
        switches += 1
        if switches > 2 * (3 * max_contacts + 3):
            raise ImpactCapError(
                f"more than max_contacts={max_contacts} contacts in {duration:.6g} time "
                f"units at phase {tau:.6f}: the motion is not resolvable at this cap")
        s = forced if forced is not None else slip_sign(tau, delta, vel)
        forced = None
        if friction is not None and s == 0.0:  # stuck: x fixed until |G| = F_s (C4)
            t_stick = t
            stick, t, forced = _stuck(
                tau, tau0, p.omega, t, duration, p.d + delta + k * max(delta, 0.0) ** 1.5,
                f_sta, lambda u: at_rest_force((tau0 + p.omega * u) % TWO_PI, delta, u),
                force)
            dense.piece(t_stick, t, lambda u: (delta, 0.0))
            sticks.append(stick)
            tau = (tau0 + p.omega * t) % TWO_PI
            vel = 0.0
            if forced is None:
                break
            continue
        push = s * f_kin
        if region == "contact":
            te, (delta, vel), why = _contact(p, law, tau0, t, (delta, vel), duration, rtol,
                                             push, s if friction is not None else 0.0,
                                             dense if times is not None else None, force)
            if te is None:
                t = duration
                break
            t = te
            tau = (tau0 + p.omega * t) % TWO_PI
            if why == "stop":
                continue      # the slip ends in contact: stick, or slip the other way
            contacts.append(Contact(entry[0], entry[1], entry[2], vel, t - entry[0], delta))
            if len(contacts) > max_contacts:
                raise ImpactCapError(
                    f"more than max_contacts={max_contacts} contacts in {duration:.6g} time "
                    f"units at phase {tau:.6f}: the motion is not resolvable at this cap")
            entry = None
            region = "above" if delta > 0.0 else "below"
            continue
        reg = _Region(1.0, p.zeta, p, tau, delta, vel, push, force, t)
        h_stop = None
        if friction is not None:
            h_stop = _first_crossing(lambda h: tuple(-s * u for u in reg(h)[1:]),
                                     lambda h: reg.bound(3, h), remaining, 1.0,
                                     reg.cabs + reg.amp + abs(vel) + 1.0)
        horizon = h_stop if h_stop is not None else remaining
        kind, h = None, None
        if region == "below":
            if friction is None and force is None:
                xp, vp = particular(p, tau)
                dx = _on_wall_at_rest(p, tau)[0] if delta == 0.0 else (delta + p.d) - xp
                h = _next_impact(p, tau, dx, vel - vp, horizon)
            else:
                h = _first_crossing(lambda h: reg(h)[:2], lambda h: reg.bound(2, h), horizon,
                                    1.0, reg.cabs + reg.amp + abs(reg.offset) + abs(reg.kk))
            kind = "entry" if h is not None else None
        else:   # above: delta > 0 and 1 + 1.5 alpha delta' <= 0
            h_force = _first_crossing(
                lambda u: (1.0 + 1.5 * a * reg(u)[1], 1.5 * a * reg(u)[2]),
                lambda u: 1.5 * a * reg.bound(3, u), horizon, 1.0,
                1.0 + 1.5 * a * (reg.cabs + reg.amp * p.omega))
            kind, h = _above_switch(reg, h_force, horizon)
        if kind is None:
            if h_stop is None:
                dense.piece(t, duration, reg)
                delta, vel, _ = reg(remaining)
                t = duration
                break
            dense.piece(t, t + h_stop, reg)
            delta, _, _ = reg(h_stop)
            vel = 0.0  # the slip ends: stick or slip the other way (slip_sign)
            t += h_stop
            tau = (tau0 + p.omega * t) % TWO_PI
            if region == "below":
                delta = min(delta, 0.0)
            continue
        dense.piece(t, t + h, reg)
        delta, vel, _ = reg(h)
        t += h
        tau = (tau0 + p.omega * t) % TWO_PI
        if kind == "below":
            delta, region = 0.0, "below"
            continue
        if region == "below":
            delta = 0.0
            if vel <= 0.0:
                vel = 0.0  # a tangency: no contact (impact.py)
                continue
        entry = (t, tau, vel)
        region = "contact"
    if entry is not None:
        contacts.append(Contact(entry[0], entry[1], entry[2], math.nan, math.inf, math.nan))
    return CompliantSegment(delta + p.d, vel, contacts, tuple(sticks), None,
                            dense.end(delta, vel) if times is not None else None)


def hertz_period_step(p: OscillatorParams, law: HuntCrossley, dx: float, dv: float,
                      dv_correction: float = 0.0, *, rtol: float = RTOL,
                      friction: Coulomb | None = None) -> CompliantSegment:
    """One period from a Pi2 sample with a Hertz stop (and friction): the shape of
    :func:`grazing_control.oscillator.contact.compliant_period_step`."""
    xp, vp = particular(p, p.tau2)
    seg = advance_hertz(p, law, p.tau2, xp + dx, vp + dv + dv_correction, p.period, rtol=rtol,
                        friction=friction)
    xe, ve = particular(p, (p.tau2 + p.omega * p.period) % TWO_PI)
    return CompliantSegment(seg.x - xe, seg.v - ve, seg.contacts, seg.sticks)


def grazing_jump(law: HuntCrossley, alpha: float, penetration: float, *,
                 friction: Coulomb | None = None):
    """Leading order of the Hertz stop's grazing discontinuity map (Eqs. C9, C12).

    A free flight whose virtual maximum is ``penetration`` H > 0 above the stop, with
    deceleration ``alpha`` > 0 there (delta = H - alpha t^2 / 2 about the apex), takes the
    impulse of the contact force along that parabola while k_c H^{1/2} / alpha << 1:

        int k_c delta^{3/2} dt = k_c H^{3/2} sqrt(2 H / alpha) int_{-1}^{1} (1 - s^2)^{3/2} ds
                               = (3 pi / 8) k_c sqrt(2 / alpha) H^2,

    and the Hunt-Crossley term (3/2) alpha_h k_c int delta^{3/2} delta' dt vanishes at this
    order (delta^{5/2} is 0 at both ends), so

        dv = -(3 pi / 8) k_c sqrt(2 / alpha) H^2          (order 2, any damping)

    (docs/theory_contact.md, "The Hertz discontinuity map").

    With Coulomb ``friction`` (F_s < alpha: the mass slips through the apex) the flight
    decelerates at alpha + F_f before the apex and alpha - F_f after it; each half of
    the parabola takes (3 pi / 16) k_c sqrt(2 / a) H^2 (a its deceleration), and the
    half before the apex reaches the section after it scaled by q = (alpha - F_f) /
    (alpha + F_f) (an impulse before the apex moves the friction's switch, as for the
    Kelvin-Voigt stop, Eq. C10); the Hunt-Crossley term is (q - 1) (3/5) alpha_h k_c
    H^{5/2}, of higher order. So (Eq. C12, docs/theory_contact.md §20)

        dv = -(3 pi / 16) sqrt(2) k_c (q / sqrt(alpha + F_f) + 1 / sqrt(alpha - F_f)) H^2,

    order 2 unchanged (F_f = 0 gives C9). Returns (order, coefficient, dv).
    """
    f = 0.0 if friction is None else friction.kinetic
    if friction is not None and not alpha > friction.static:
        raise ParameterError(f"friction static={friction.static!r} is invalid here: the map "
                             f"of Eq. C12 needs the mass to slip through the apex, "
                             f"F_s < alpha = {alpha!r}")
    q = (alpha - f) / (alpha + f)
    coef = (0.1875 * math.pi * math.sqrt(2.0) * law.stiffness
            * (q / math.sqrt(alpha + f) + 1.0 / math.sqrt(alpha - f)))
    return 2.0, coef, -coef * penetration ** 2

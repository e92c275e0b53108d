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

from .contact import CompliantSegment, Contact, _first_crossing, _Region
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
        if not k > 0.0:
            raise ParameterError(f"stiffness={k!r} is invalid: valid range is k_c > 0")
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
             rtol: float):
    """DOP853 through one contact from time t; returns (t_exit or None, state)."""
    # imported here: a node that never meets a Hertz contact imports no solver
    # (tests/test_node_common.py)
    from scipy.integrate import solve_ivp
    k, a, zeta, w, d = law.stiffness, law.alpha, p.zeta, p.omega, p.d

    def rhs(s, u):
        delta = u[0]
        f = k * max(delta, 0.0) ** 1.5 * (1.0 + 1.5 * a * u[1])
        return [u[1], math.cos(w * s + tau0) - 2.0 * zeta * u[1] - (delta + d) - f]

    def leave(s, u):
        return 1.0 + 1.5 * a * u[1]
    leave.terminal, leave.direction = True, -1.0

    def back(s, u):
        return u[0]
    back.terminal, back.direction = True, -1.0

    # the first step is short: delta^{3/2} is not smooth at the entry
    sol = solve_ivp(rhs, (t, t_end), list(y), method="DOP853", rtol=rtol, atol=rtol * 1e-3,
                    events=[leave, back], first_step=1e-8, max_step=0.1)
    hits = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
    if not hits:
        return None, (sol.y[0, -1], sol.y[1, -1])
    te, i = min(hits)
    state = sol.y_events[i][0]
    return te, (0.0 if i == 1 else state[0], state[1])


def advance_hertz(p: OscillatorParams, law: HuntCrossley, tau0: float, x: float, v: float,
                  duration: float, *, rtol: float = RTOL,
                  max_contacts: int = 10000) -> CompliantSegment:
    """Flow with a Hertz / Hunt-Crossley stop for a fixed time (physical x, v).

    Regions as for :func:`grazing_control.oscillator.contact.advance_compliant`: below
    (closed form, certified entry), contact (DOP853 at ``rtol``), above after an exit with
    delta > 0 (closed form; a new contact where 1 + 1.5 alpha delta' returns to 0, or
    below again at delta = 0). At most 3 ``max_contacts`` + 3 region changes
    (:class:`ImpactCapError` beyond).
    """
    for name, value in (("x", x), ("v", v), ("tau0", tau0), ("duration", duration)):
        if not math.isfinite(value):
            raise NonFiniteStateError(f"{name}={value!r} must be finite")
    a = law.alpha
    t, tau = 0.0, tau0 % TWO_PI
    delta, vel = x - p.d, v
    contacts: list = []
    if delta > 0.0:
        region = "contact" if 1.0 + 1.5 * a * vel > 0.0 else "above"
    else:
        region = "below"
    entry = (0.0, tau, math.nan) if region == "contact" else None
    switches = 0
    while t < duration:
        remaining = duration - t
        switches += 1
        if switches > 3 * max_contacts + 3:
            raise ImpactCapError(
                f"more than max_contacts={max_contacts} contacts in {duration:.6g} time "
                f"units at phase {tau:.6f}: the motion is not resolvable at this cap")
        if region == "contact":
            te, (delta, vel) = _contact(p, law, tau0, t, (delta, vel), duration, rtol)
            if te is None:
                t = duration
                break
            t = te
            tau = (tau0 + p.omega * t) % TWO_PI
            contacts.append(Contact(entry[0], entry[1], entry[2], vel, t - entry[0], delta))
            entry = None
            region = "above" if delta > 0.0 else "below"
            continue
        reg = _Region(1.0, p.zeta, p, tau, delta, vel)
        if region == "below":
            xp, vp = particular(p, tau)
            dx = _on_wall_at_rest(p, tau)[0] if delta == 0.0 else (delta + p.d) - xp
            h = _next_impact(p, tau, dx, vel - vp, remaining)
            if h is None:
                delta, vel, _ = reg(remaining)
                t = duration
                break
            _, vel, _ = reg(h)
            delta = 0.0
            t += h
            tau = (tau0 + p.omega * t) % TWO_PI
            if vel <= 0.0:
                vel = 0.0  # a tangency: no contact (impact.py)
                continue
            entry = (t, tau, vel)
            region = "contact"
            continue
        # above: delta > 0 and 1 + 1.5 alpha delta' <= 0
        scale = 1.0 + 1.5 * a * (reg.cabs + reg.amp * p.omega)
        h_force = _first_crossing(lambda s: (1.0 + 1.5 * a * reg(s)[1], 1.5 * a * reg(s)[2]),
                                  lambda s: 1.5 * a * reg.bound(3, s), remaining, 1.0, scale)
        h_gap = _first_crossing(lambda s: reg(s)[:2], lambda s: reg.bound(2, s),
                                h_force if h_force is not None else remaining, -1.0,
                                reg.cabs + reg.amp + abs(reg.offset))
        if h_gap is not None and (h_force is None or h_gap < h_force):
            _, vel, _ = reg(h_gap)
            delta, region = 0.0, "below"
            t += h_gap
        elif h_force is not None:
            delta, vel, _ = reg(h_force)
            t += h_force
            region = "contact"
            entry = (t, (tau0 + p.omega * t) % TWO_PI, vel)
        else:
            delta, vel, _ = reg(remaining)
            t = duration
            break
        tau = (tau0 + p.omega * t) % TWO_PI
    if entry is not None:
        contacts.append(Contact(entry[0], entry[1], entry[2], math.nan, math.inf, math.nan))
    return CompliantSegment(delta + p.d, vel, contacts, ())


def hertz_period_step(p: OscillatorParams, law: HuntCrossley, dx: float, dv: float,
                      dv_correction: float = 0.0, *, rtol: float = RTOL) -> CompliantSegment:
    """One period from a Pi2 sample with a Hertz stop: the shape of
    :func:`grazing_control.oscillator.contact.compliant_period_step`."""
    xp, vp = particular(p, p.tau2)
    seg = advance_hertz(p, law, p.tau2, xp + dx, vp + dv + dv_correction, p.period, rtol=rtol)
    xe, ve = particular(p, (p.tau2 + p.omega * p.period) % TWO_PI)
    return CompliantSegment(seg.x - xe, seg.v - ve, seg.contacts, ())


def grazing_jump(law: HuntCrossley, alpha: float, penetration: float):
    """Leading order of the Hertz stop's grazing discontinuity map (Eq. C9).

    A free flight whose virtual maximum is ``penetration`` H > 0 above the stop, with
    deceleration ``alpha`` > 0 there (delta = H - alpha t^2 / 2 about the apex), takes the
    impulse of the contact force along that parabola while k_c H^{1/2} / alpha << 1:

        int k_c delta^{3/2} dt = k_c H^{3/2} sqrt(2 H / alpha) int_{-1}^{1} (1 - s^2)^{3/2} ds
                               = (3 pi / 8) k_c sqrt(2 / alpha) H^2,

    and the Hunt-Crossley term (3/2) alpha_h k_c int delta^{3/2} delta' dt vanishes at this
    order (delta^{5/2} is 0 at both ends), so

        dv = -(3 pi / 8) k_c sqrt(2 / alpha) H^2          (order 2, any damping)

    (docs/theory_contact.md, "The Hertz discontinuity map"). Returns (order, coefficient, dv).
    """
    coef = 0.375 * math.pi * law.stiffness * math.sqrt(2.0 / alpha)
    return 2.0, coef, -coef * penetration ** 2

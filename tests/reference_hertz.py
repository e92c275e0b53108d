"""20-digit mpmath reference for one Hertz / Hunt-Crossley contact (docs/theory_contact.md,
"Hertz accuracy"), and the full-flow reference of the seeded cases
(:func:`reference_advance_hertz`, DOP853 at its floor).

delta^{3/2} is not analytic at the entry, so mpmath's Taylor-series odefun starts at
h0 = 1e-5 after it, from the free flight's closed form (in mpmath) plus the leading
correction of the contact force: with K = k_c (1 + 1.5 alpha v0),

    delta(h0) = delta_free(h0) - (4/35) K v0^{3/2} h0^{7/2},
    delta'(h0) = delta_free'(h0) - (2/5) K v0^{3/2} h0^{5/2},

whose neglected terms are O(K v0^{1/2} |delta''| h0^{9/2}) (about 1e-20 here). The exit
(the first of 1 + 1.5 alpha delta' = 0 and delta = 0) is bracketed on a grid of the
solution and refined by mpmath's findroot.
"""

from __future__ import annotations

import math

import mpmath as mp
import numpy as np
from scipy.optimize import brentq

# the Kelvin-Voigt reference's solver settings, one place (refined() there shrinks MAX_STEP)
from reference_contact import _solve, gap_events, slip_or_stick

__all__ = ["reference_contact", "reference_advance_hertz"]

H0 = mp.mpf("1e-5")


def reference_contact(p, law, tau_e, v0, dps=20):
    """(exit time after the entry, delta at the exit, delta' at the exit), at ``dps``
    digits (mpmath's working precision is restored on return: the other references of the
    suite set theirs at import)."""
    with mp.workdps(dps):
        return _reference_contact(p, law, tau_e, v0)


def _reference_contact(p, law, tau_e, v0):
    zeta, w, d = mp.mpf(p.zeta), mp.mpf(p.omega), mp.mpf(p.d)
    k, a = mp.mpf(law.stiffness), mp.mpf(law.alpha)
    tau_e, v0 = mp.mpf(tau_e), mp.mpf(v0)
    # free flight from (delta, delta') = (0, v0) at phase tau_e, closed form in mpmath
    amp = 1 / mp.sqrt((1 - w ** 2) ** 2 + (2 * zeta * w) ** 2)
    lag = mp.atan2(2 * zeta * w, 1 - w ** 2)
    wd = mp.sqrt(1 - zeta ** 2)
    c1 = 0 - (amp * mp.cos(tau_e - lag) - d)
    c2 = (v0 + amp * w * mp.sin(tau_e - lag) + zeta * c1) / wd

    def free(h):
        e = mp.exp(-zeta * h)
        x = amp * mp.cos(tau_e + w * h - lag) - d + e * (c1 * mp.cos(wd * h) + c2 * mp.sin(wd * h))
        v = (-amp * w * mp.sin(tau_e + w * h - lag)
             + e * ((wd * c2 - zeta * c1) * mp.cos(wd * h) - (wd * c1 + zeta * c2) * mp.sin(wd * h)))
        return x, v

    big_k = k * (1 + mp.mpf(3) / 2 * a * v0)
    x0, y0 = free(H0)
    x0 -= mp.mpf(4) / 35 * big_k * v0 ** 1.5 * H0 ** 3.5
    y0 -= mp.mpf(2) / 5 * big_k * v0 ** 1.5 * H0 ** 2.5

    def rhs(h, u):
        delta, vel = u
        force = k * (delta if delta > 0 else 0) ** 1.5 * (1 + mp.mpf(3) / 2 * a * vel)
        return [vel, mp.cos(tau_e + w * h) - 2 * zeta * vel - (delta + d) - force]

    sol = mp.odefun(rhs, H0, [x0, y0])

    def ends(h):
        delta, vel = sol(h)
        return delta, 1 + mp.mpf(3) / 2 * a * vel

    step = mp.pi / mp.sqrt(k * mp.sqrt(v0)) / 40  # a fraction of the contact time scale
    lo = H0
    while True:
        hi = lo + step
        gap, factor = ends(hi)
        if gap <= 0 or factor <= 0:
            break
        lo = hi
    which = 0 if gap <= 0 else 1  # the force's first zero: the gap's or the factor's
    te = mp.findroot(lambda h: ends(h)[which], (lo, hi), solver="anderson")
    delta, vel = sol(te)
    return te, delta, vel


# ---------------------------------------------------------------------------------------
# Full flows for the seeded cases: scipy's DOP853 at its floor, physical coordinates.
# ---------------------------------------------------------------------------------------


def reference_advance_hertz(p, law, tau0, x, v, duration, force=0.0, friction=None):
    """(x, v, contacts[, sticks]) after ``duration`` with a Hertz / Hunt-Crossley stop;
    contacts as (t_entry, t_exit or inf); ``force`` a constant force on the mass written
    into the right-hand sides.

    Independent of oscillator/hertz.py: the equation of motion written directly in
    physical coordinates for every region (no closed form outside the contact), DOP853 at
    rtol 2.3e-14 (its floor) with terminal events, restarted at every switch. An entry the
    event location could miss (a penetration inside one step) is caught at the next
    maximum of x and located by brentq on the dense output, as in
    ``reference_contact.reference_advance``. With ``friction`` (kinetic F_f, static F_s),
    as there: the slip's direction in the right-hand side, a slip ends at the event
    x' = 0, a stick (|G| <= F_s, G = cos tau - x - k_c max(x - d, 0)^{3/2}) ends at the
    first sign change of |G| - F_s on a grid of 4000 points per period refined by brentq
    (not the closed form); the sticks are returned as a fourth element.
    """
    k, a, d, zeta, w = law.stiffness, law.alpha, p.d, p.zeta, p.omega
    f_kin = friction.kinetic if friction is not None else 0.0
    f_sta = friction.static if friction is not None else 0.0
    sgn = [0.0]

    def free(t, y):
        return [y[1], math.cos(w * t + tau0) + force - 2.0 * zeta * y[1] - y[0]
                - sgn[0] * f_kin]

    def touch(t, y):
        pen = max(y[0] - d, 0.0)
        return [y[1], math.cos(w * t + tau0) + force - 2.0 * zeta * y[1] - y[0]
                - sgn[0] * f_kin - k * pen ** 1.5 * (1.0 + 1.5 * a * y[1])]

    gap_up, top, gap_down = gap_events(d)

    def factor_down(t, y):
        return 1.0 + 1.5 * a * y[1]
    factor_down.terminal, factor_down.direction = True, -1.0

    def factor_up(t, y):
        return 1.0 + 1.5 * a * y[1]
    factor_up.terminal, factor_up.direction = True, 1.0

    def stop(t, y):
        return y[1]
    stop.terminal = True

    def at_rest(t, xx):
        return math.cos(w * t + tau0) + force - xx - k * max(xx - d, 0.0) ** 1.5

    t, y = 0.0, [x, v]
    contacts, sticks = [], []
    delta = x - d
    region = "below" if delta <= 0.0 else ("contact" if 1.0 + 1.5 * a * v > 0.0 else "above")
    entry = 0.0
    guard = 0
    forced = None
    while t < duration:
        guard += 1
        assert guard < 100000
        if friction is not None:
            stuck = slip_or_stick(p, at_rest, t, y, duration, f_sta, forced, sgn, sticks)
            forced = None
            if stuck is not None:
                t, y, forced = stuck
                if t >= duration:
                    break
                continue
            stop.direction = -sgn[0]
        extra = [stop] if friction is not None else []
        if region == "below":
            sol = _solve(free, t, y, duration, [gap_up, top] + extra)
            hit = [s for s in sol.t_events[0] if s > t]
            halted = [s for s in (sol.t_events[2] if extra else []) if s > t]
            end = hit[0] if hit else (halted[0] if halted else sol.t[-1])
            missed = [s for s in sol.t_events[1] if t < s <= end and sol.sol(s)[0] > d]
            if missed:  # an entry inside one step: the root of x - d before that maximum
                lo = max([t] + [s for s in sol.t_events[1] if s < missed[0]])
                end = brentq(lambda s: sol.sol(s)[0] - d, lo, missed[0], xtol=1e-16)
                hit, halted = [end], []
            if hit and not (halted and halted[0] < end):
                t, y = end, [d, float(sol.sol(end)[1])]
                if y[1] <= 0.0:  # a tangency: no contact
                    continue
                region, entry = "contact", t
                continue
            if halted:
                t, y = halted[0], [min(sol.sol(halted[0])[0], d), 0.0]
                continue
            t, y = duration, list(sol.y[:, -1])
        elif region == "contact":
            sol = _solve(touch, t, y, duration, [factor_down, gap_down] + extra)
            ev = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
            if ev:
                t, i = min(ev)
                y = list(sol.sol(t))
                if i == 2:      # the slip ends in contact
                    y[1] = 0.0
                    continue
                contacts.append((entry, t))
                if i == 1:
                    y[0] = d
                region = "above" if i == 0 and y[0] > d else "below"
                continue
            t, y = duration, list(sol.y[:, -1])
        else:  # above the stop, the factor 1 + 1.5 alpha x' <= 0: free until either returns
            sol = _solve(free, t, y, duration, [factor_up, gap_down] + extra)
            ev = [(e[0], i) for i, e in enumerate(sol.t_events) if len(e) and e[0] > t]
            if ev:
                t, i = min(ev)
                y = list(sol.sol(t))
                if i == 0:
                    region, entry = "contact", t
                elif i == 1:
                    y[0], region = d, "below"
                else:
                    y[1] = 0.0
                continue
            t, y = duration, list(sol.y[:, -1])
    if region == "contact":
        contacts.append((entry, math.inf))
    if friction is not None:
        return y[0], y[1], contacts, sticks
    return y[0], y[1], contacts

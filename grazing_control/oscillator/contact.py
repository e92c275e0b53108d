"""A compliant stop: the Kelvin-Voigt (linear spring-dashpot) contact law, exact.

The rigid wall of :mod:`grazing_control.oscillator.impact` replaced by a massless stop that
pushes on the mass with (nondimensional as study Eq. 1, force per m omega_n^2 l)

    F_c = k_c (x - d) + c_c x'     while x > d and k_c (x - d) + c_c x' > 0,

and 0 otherwise: the stop only pushes, so a contact ends when F_c returns to zero, which
(with c_c > 0) is before x returns to d; the mass then flies free from x > d and the next
contact starts when F_c becomes positive again or x crosses d upwards
(docs/theory_contact.md, "The Kelvin-Voigt stop").

Each region is a linear oscillator with constant coefficients, so the flow is closed form
(the flow of :mod:`grazing_control.oscillator.flow` with other coefficients): with
delta = x - d,

    delta'' + 2 beta delta' + W^2 delta = cos tau - d,
    free:    W^2 = 1,        beta = zeta,
    contact: W^2 = 1 + k_c,  beta = zeta + c_c / 2.

Switching times are certified (docs/theory_contact.md, "Certified switching"): the
contact entry from below the stop is :func:`grazing_control.oscillator.impact._next_impact`
(the wall's certified search, full relative precision near grazing); the contact force's
zero in contact, and the return of the force or of the gap after a contact that ended
with x > d, by a search that excludes an interval only with a rigorous bound on the
second derivative of the event function and brackets a root only where that bound proves
it monotone.

The laws themselves (:class:`KelvinVoigt`, :class:`Coulomb`, :class:`LagForce`, the
restitution of Eq. C3 and the valid ranges) are :mod:`.contact_law`'s, re-exported here.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

from . import kernel
from .flow import matmul2, particular
from .contact_law import (MAX_FRICTION, MAX_STIFFNESS, Coulomb, KelvinVoigt, LagForce,
                          _force_at, kelvin_voigt_damping, kelvin_voigt_restitution)
from .impact import (ImpactCapError, InitialStateError, NonFiniteStateError, _next_impact,
                     _on_wall_at_rest)
from .params import OscillatorParams, ParameterError

__all__ = [
    "KelvinVoigt",
    "Coulomb",
    "LagForce",
    "Contact",
    "CompliantSegment",
    "kelvin_voigt_restitution",
    "kelvin_voigt_damping",
    "MAX_STIFFNESS",
    "MAX_FRICTION",
    "advance_compliant",
    "compliant_period_step",
    "grazing_jump",
    "load_compiled",
]

TWO_PI = 2.0 * math.pi
_EPS = 2.0 ** -52
_MAX_DEPTH = 60


class Contact(NamedTuple):
    """One contact: start time (since the segment's start), phase, velocities, duration.

    ``v_minus``: x' at entry (>= 0); ``v_plus``: x' when the force returns to 0, or nan if
    the contact lasts past the segment's end; ``duration``: the contact time (inf then);
    ``exit_gap``: x - d at the exit (> 0 with damping: the mass leaves before x = d).
    """

    dt: float
    phase: float
    v_minus: float
    v_plus: float
    duration: float
    exit_gap: float




class CompliantSegment(NamedTuple):
    """Result of :func:`advance_compliant`: end state (x, v), the contacts, and the
    sticks of the friction as (start, end) times (end inf: stuck at the segment's end);
    ``states``: the physical (x, v) at the ``times`` asked for (dense output), or None."""

    x: float
    v: float
    contacts: list
    sticks: tuple = ()
    monodromy: tuple | None = None
    states: list | None = None


class _Dense:
    """Dense output as the flow passes: physical (x, v) at the sorted ``times`` (from the
    segment's start), each from the piece of the flow that holds it (a region's closed
    form, a stick, DOP853's interpolant in a Hertz contact). Never alters the
    trajectory: the pieces are the ones the flow takes anyway."""

    def __init__(self, times, d: float):
        self.times, self.d, self.j, self.out = list(times), d, 0, []

    def piece(self, t0: float, t1: float, state) -> None:
        """The times in [.., t1] on the piece that starts at t0: ``state(u)`` is
        (delta, delta') at u = time - t0."""
        while self.j < len(self.times) and self.times[self.j] <= t1:
            delta, vel = state(self.times[self.j] - t0)[:2]
            self.out.append((delta + self.d, vel))
            self.j += 1

    def end(self, delta: float, vel: float) -> list:
        """The times at or past the segment's end: its end state."""
        self.out += [(delta + self.d, vel)] * (len(self.times) - self.j)
        return self.out


class _Region:
    """Closed-form flow of delta'' + 2 beta delta' + w2 delta = cos(tau) - d from one state.

    delta = A cos(tau - phi_c) - d / w2 + Re(C e^{lambda h}), lambda = -beta + i Omega,
    |lambda| = W = sqrt(w2); every derivative of the homogeneous part is bounded by
    |C| W^n e^{-beta h} and of the particular part by A omega^n (docs/theory_contact.md).

    An external ``force`` F_inf + C_0 e^{-rate t} (:class:`LagForce`, t from the segment's
    start; the region starts at ``t0``) adds F_inf / w2 to the offset and the particular
    solution K e^{-rate h}, K = C_0 e^{-rate t0} / (w2 - 2 beta rate + rate^2) (the
    denominator is (rate - beta)^2 + Omega^2 > 0 in an underdamped region), whose n-th
    derivative is bounded by |K| rate^n e^{-rate h} (docs/theory_contact.md §21).

    The hot path (the certified searches evaluate a region some 60 times a switch): the
    products that do not depend on h are formed once (:meth:`_invariants`), each exactly
    as the formula rounds it, so every value is bit for bit the formula's
    (tests/test_compliant_flow_bits.py); :meth:`gap` and :meth:`force_value` give the
    leading values alone, for the bracketing that needs no derivative.
    """

    __slots__ = ("beta", "big_w", "big_om", "omega", "amp", "lag", "offset", "tau0",
                 "c1", "c2", "cabs", "kk", "rate",
                 "_wa", "_wb", "_av", "_aa", "_b2", "_w2", "_r2", "_bn", "_an", "_kn")

    def __init__(self, w2: float, beta: float, p: OscillatorParams, tau0: float,
                 delta0: float, v0: float, push: float = 0.0,
                 force: "LagForce | None" = None, t0: float = 0.0):
        w = p.omega
        self.beta = beta
        self.big_w = math.sqrt(w2)
        self.big_om = math.sqrt(w2 - beta * beta)
        self.omega = w
        self.amp = 1.0 / math.hypot(w2 - w * w, 2.0 * beta * w)
        self.lag = math.atan2(2.0 * beta * w, w2 - w * w)
        self.offset = -(p.d + push) / w2
        self.kk, self.rate = 0.0, 0.0
        if force is not None:
            self.offset = -(p.d + push - force.f_inf) / w2
            self.rate = force.rate
            self.kk = force.transient(t0) / (w2 - 2.0 * beta * self.rate + self.rate ** 2)
        self.tau0 = tau0
        pd, pv = self._particular(0.0)
        self.c1 = delta0 - pd
        self.c2 = (v0 - pv + beta * self.c1) / self.big_om
        self.cabs = math.hypot(self.c1, self.c2)
        self._invariants()

    def _invariants(self) -> None:
        """The h-independent factors of :meth:`__call__` and :meth:`bound`, grouped as
        Python evaluates those formulas (left to right), so the floats are the same."""
        b, om, c1, c2 = self.beta, self.big_om, self.c1, self.c2
        self._wa = om * c2 - b * c1             # (Omega c2 - beta c1): wv's cos factor
        self._wb = om * c1 + b * c2             # (Omega c1 + beta c2): its sin factor
        self._av = -self.amp * self.omega       # the particular part's velocity amplitude
        self._aa = -self.amp * self.omega * self.omega
        self._b2 = 2.0 * b
        self._w2 = self.big_w ** 2
        self._r2 = self.rate * self.rate
        # bound(n, h) = _bn[n] e^{-beta h} + _an[n] (+ _kn[n] e^{-rate h}), n = 1 ... 3
        cabs, bw, amp, w, kk, rate = self.cabs, self.big_w, self.amp, self.omega, abs(self.kk), \
            self.rate
        self._bn = (None, cabs * bw ** 1, cabs * bw ** 2, cabs * bw ** 3)
        self._an = (None, amp * w ** 1, amp * w ** 2, amp * w ** 3)
        self._kn = (None, kk * rate ** 1, kk * rate ** 2, kk * rate ** 3)

    def constants(self) -> tuple:
        """The constants of :meth:`__call__`, :meth:`bound` and :meth:`force_bound`, in the
        order of kernel.compiled_contact's ``R`` (:func:`_region_crossing`)."""
        bn, an, kn = self._bn, self._an, self._kn
        return (self.tau0, self.omega, self.lag, self.amp, self.offset, self.beta,
                self.big_om, self.c1, self.c2, self._av, self._wa, self._wb, self.kk,
                self.rate, self._aa, self._b2, self._w2, self._r2, bn[2], bn[3], an[2], an[3],
                kn[2], kn[3])

    def _particular(self, h: float):
        psi = self.tau0 + self.omega * h - self.lag
        d, v = self.amp * math.cos(psi) + self.offset, -self.amp * self.omega * math.sin(psi)
        if self.kk:
            e = self.kk * math.exp(-self.rate * h)
            d, v = d + e, v - self.rate * e
        return d, v

    def __call__(self, h: float):
        """(delta, delta', delta'') at time h."""
        psi = self.tau0 + self.omega * h - self.lag
        cp = math.cos(psi)
        e = math.exp(-self.beta * h)
        oh = self.big_om * h
        c, s = math.cos(oh), math.sin(oh)
        w = e * (self.c1 * c + self.c2 * s)
        wv = e * (self._wa * c - self._wb * s)
        d = self.amp * cp + self.offset + w
        v = self._av * math.sin(psi) + wv
        # the equation itself gives delta'' (no cancellation beyond that of its terms)
        acc = self._aa * cp - self._b2 * wv - self._w2 * w
        kk = self.kk
        if kk:   # the actuator's transient K e^{-rate h}
            ek = kk * math.exp(-self.rate * h)
            return d + ek, v - self.rate * ek, acc + self._r2 * ek
        return d, v, acc

    def gap(self, h: float) -> float:
        """delta at time h: :meth:`__call__`'s first value, the same float."""
        e = math.exp(-self.beta * h)
        oh = self.big_om * h
        d = (self.amp * math.cos(self.tau0 + self.omega * h - self.lag) + self.offset
             + e * (self.c1 * math.cos(oh) + self.c2 * math.sin(oh)))
        kk = self.kk
        return d + kk * math.exp(-self.rate * h) if kk else d

    def force_value(self, k: float, c: float, h: float) -> float:
        """k delta + c delta' at time h (:func:`_force_event`'s value, the same float)."""
        psi = self.tau0 + self.omega * h - self.lag
        e = math.exp(-self.beta * h)
        oh = self.big_om * h
        cs, sn = math.cos(oh), math.sin(oh)
        d = self.amp * math.cos(psi) + self.offset + e * (self.c1 * cs + self.c2 * sn)
        v = self._av * math.sin(psi) + e * (self._wa * cs - self._wb * sn)
        kk = self.kk
        if kk:
            ek = kk * math.exp(-self.rate * h)
            d, v = d + ek, v - self.rate * ek
        return k * d + c * v

    def transition(self, h: float):
        """Phi(h) of the homogeneous region flow, (Phi11, Phi12, Phi21, Phi22):
        e^{-beta h} [[c + beta s / Omega, s / Omega], [-W^2 s / Omega, c - beta s / Omega]]."""
        e = math.exp(-self.beta * h)
        c = math.cos(self.big_om * h)
        s = math.sin(self.big_om * h) / self.big_om
        return (e * (c + self.beta * s), e * s, -e * self.big_w ** 2 * s, e * (c - self.beta * s))

    def bound(self, n: int, h: float) -> float:
        """max |delta^(n)| on [h, inf), n = 1 ... 3."""
        out = self._bn[n] * math.exp(-self.beta * h) + self._an[n]
        if self.kk:
            out += self._kn[n] * math.exp(-self.rate * h)
        return out

    def force_bound(self, k: float, c: float, h: float) -> float:
        """k bound(2, h) + c bound(3, h) (:func:`_force_bound`), the exponentials once."""
        e = math.exp(-self.beta * h)
        b2 = self._bn[2] * e + self._an[2]
        b3 = self._bn[3] * e + self._an[3]
        if self.kk:
            ek = math.exp(-self.rate * h)
            b2 += self._kn[2] * ek
            b3 += self._kn[3] * ek
        return k * b2 + c * b3


def _first_crossing(event, bound2, horizon, sign, scale, value=None):
    """First h in (0, horizon] at which sign * event(h) >= 0 after being < 0, or None.

    ``event(h)`` returns (f, f'); ``bound2(h)`` bounds |f''| on [h, horizon]. f(0) may be
    0 (the search starts on the previous switching surface, leaving it: sign * f'(0) < 0).
    An interval [a, b] is excluded when the chord bound max(sf(a), sf(b)) + M (b - a)^2 / 8
    is below -margin (``scale`` * 64 eps, the rounding of f), or when M proves f monotone
    (|f'(a)| + |f'(b)| > M (b - a), equal signs) without a sign change; otherwise it is
    bisected (docs/theory_contact.md, "Certified switching"). A root of a monotone
    interval is bracketed to a few ulps; ``value(h)``, where given, is f(h) alone (the
    same float as event(h)[0], cheaper: the bracketing needs no f').
    """
    margin = 64.0 * _EPS * scale
    n = max(1, int(math.ceil(horizon / (0.25 * math.pi))))
    a, fa = 0.0, event(0.0)
    start = True
    for k in range(1, n + 1):
        b = horizon if k == n else k * horizon / n
        fb = event(b)
        root = _crossing_in(event, value, bound2, a, b, fa, fb, sign, margin, 0, start)
        if root is not None:
            return root
        a, fa, start = b, fb, False
    return None


def _crossing_in(event, value, bound2, a, b, fa, fb, sign, margin, depth, start):
    sa, sb = sign * fa[0], sign * fb[0]
    da, db = sign * fa[1], sign * fb[1]
    if start and sa >= -margin and da < 0.0:
        sa = -0.0  # on the surface and leaving it: not a crossing
    m = bound2(a) * (b - a) * (1.0 + 1e-12)
    if sa >= 0.0 and not start:
        return a
    if (da > 0.0 and db > 0.0 or da < 0.0 and db < 0.0) and abs(da) + abs(db) > m:
        # monotone: a crossing iff the ends straddle 0
        if sb >= 0.0 and sa < 0.0:
            return _bracket(value, a, b, sign, fa[0], fb[0], event)
        return None
    upper = max(sa, sb) + 0.125 * (b - a) * m
    if upper < -margin:
        return None
    if depth >= _MAX_DEPTH or b - a <= 4.0 * math.ulp(b):
        return _bracket(value, a, b, sign, fa[0], fb[0], event) if sa < 0.0 <= sb else None
    mid = 0.5 * (a + b)
    fm = event(mid)
    found = _crossing_in(event, value, bound2, a, mid, fa, fm, sign, margin, depth + 1, start)
    if found is not None:
        return found
    return _crossing_in(event, value, bound2, mid, b, fm, fb, sign, margin, depth + 1, False)


def _bracket(value, lo, hi, sign, flo, fhi, event=None):
    """Safeguarded secant/bisection to the first h with sign * f(h) >= 0 (a few ulps);
    ``value(h)`` is f(h) (None: ``event(h)[0]``). A region's gap or force (:class:`_RegionValue`) is bracketed
    by the compiled mirror once :func:`load_compiled` has loaded it (the same floats)."""
    if isinstance(value, _RegionValue):
        if _compiled is not None:
            return value.bracket(lo, hi, sign, flo, fhi)
        value = value._f                 # the bound method itself: a call less an evaluation
    flo, fhi = sign * flo, sign * fhi
    ulp = math.ulp
    while (width := hi - lo) > 4.0 * ulp(hi):
        x = lo + width * (flo / (flo - fhi)) if fhi != flo else 0.5 * (lo + hi)
        if not lo < x < hi or (x - lo) < 0.01 * width or (hi - x) < 0.01 * width:
            x = 0.5 * (lo + hi)
        fx = sign * (value(x) if value is not None else event(x)[0])
        if fx >= 0.0:
            hi, fhi = x, fx
        else:
            lo, flo = x, fx
    return hi


#: kernel.compiled_contact once :func:`load_compiled` has loaded it
_compiled = None
_GAP, _FORCE, _SLIP = 0, 1, 2     # kernel.compiled_contact.GAP, FORCE, SLIP


def load_compiled() -> bool:
    """Search the regions' switching times with the compiled mirror from now on in this
    process (:mod:`grazing_control.oscillator.kernel.compiled_contact`: the certified
    search of a region's gap or force and its bracketing, :func:`_region_crossing`; the
    entry from below the stop by the kernel's wall search, :func:`_wall_entry`; the
    same floats, the stop's fit at 0.30 of the Python path's CPU; docs/benchmarks.md
    "The compliant stop's hot path"), where numba runs (``GRAZING_KERNEL``,
    :func:`kernel.use_kernel`). Compiles or loads from numba's cache on the first call
    (seconds on a fresh clone; it loads the 1-DOF kernel too), so it is asked for by
    the offline callers that evaluate the flow many times (the stop's fit), never on a
    node's first period. Returns whether the compiled path is on."""
    global _compiled
    if _compiled is None and kernel.use_kernel():
        from .kernel import compiled_contact as cc
        kernel.warm_up()            # the wall's search (_wall_entry)
        # compile now: both kinds of the search and the bracketing (one region)
        reg = _Region(2.0, 0.1, OscillatorParams(), 0.0, -0.1, 1.0)
        for kind in (_GAP, _FORCE, _SLIP):
            cc.first_crossing_region(reg.constants(), kind, 1.0, 0.1, 1.0, 1.0, 1.0)
        cc.bracket_region(0.0, 1.0, 1.0, -1.0, 1.0, _GAP, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0,
                          0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
        _compiled = cc
    return _compiled is not None


class _RegionValue:
    """A region's gap (``kind`` _GAP, :meth:`_Region.gap`) or contact force k delta +
    c delta' (_FORCE, :meth:`_Region.force_value`) as a function of h, with its
    bracketing by the compiled mirror (:func:`load_compiled`)."""

    __slots__ = ("reg", "kind", "k", "c", "_f")

    def __init__(self, reg: _Region, kind: int, k: float = 0.0, c: float = 0.0):
        self.reg, self.kind, self.k, self.c = reg, kind, k, c
        self._f = reg.gap if kind == _GAP else partial(reg.force_value, k, c)

    def __call__(self, h: float) -> float:
        return self._f(h)

    def bracket(self, lo, hi, sign, flo, fhi) -> float:
        """:func:`_bracket` of this value, compiled."""
        r = self.reg
        return _compiled.bracket_region(lo, hi, sign, flo, fhi, self.kind, self.k, self.c,
                                        r.tau0, r.omega, r.lag, r.amp, r.offset, r.beta,
                                        r.big_om, r.c1, r.c2, r._av, r._wa, r._wb, r.kk,
                                        r.rate)


def _check_law(p: OscillatorParams, law: KelvinVoigt) -> None:
    beta = p.zeta + 0.5 * law.damping
    if not beta * beta < 1.0 + law.stiffness:
        raise ParameterError(
            f"damping={law.damping!r} is invalid with zeta={p.zeta!r}: the contact must be "
            f"underdamped, (2 zeta + c_c)^2 < 4 (1 + k_c) = {4.0 * (1.0 + law.stiffness)!r}")


def _release_time(tau: float, omega: float, lo: float, hi: float) -> float:
    """Time until cos(tau) leaves [lo, hi] (inf if never): the end of a stick.

    cos leaves through hi where it increases through it, at tau = -acos(hi) mod 2 pi, and
    through lo where it decreases through it, at tau = acos(lo) mod 2 pi
    (docs/theory_contact.md, "Coulomb friction").
    """
    exits = []
    if hi < 1.0:
        exits.append(-math.acos(max(-1.0, hi)))
    if lo > -1.0:
        exits.append(math.acos(min(1.0, lo)))
    if not exits:
        return math.inf
    gaps = []
    for e in exits:
        g = (e - tau) % TWO_PI
        gaps.append(0.0 if g > TWO_PI - 1e-12 else g)
    return min(gaps) / omega


def _stuck(tau: float, tau0: float, omega: float, t: float, duration: float, rest: float,
           f_sta: float, at_rest, force: "LagForce | None" = None):
    """A stick from time t (phase tau) with x fixed: the force at rest is cos tau - rest
    (``rest`` = x + the stop's force at rest, Eq. C4; plus an external ``force``) until it
    leaves [-F_s, F_s] (:func:`_release_time`; with the actuator's decaying transient
    :func:`_forced_release`). Returns the stick (start, end; end inf past ``duration``),
    the time it ends (at most ``duration``) and the direction of the slip after it
    (along G = ``at_rest(time)``; None at ``duration``)."""
    if force is not None:
        rest -= force.f_inf
    if force is None or not force.transient(t):
        release = _release_time(tau, omega, rest - f_sta, rest + f_sta)
    else:
        release = _forced_release(tau, omega, force.transient(t), force.rate, rest, f_sta,
                                  duration - t)
    end = t + min(release, duration - t)
    if end >= duration:
        return (t, math.inf), end, None
    g = at_rest(end)
    return (t, end), end, math.copysign(1.0, g) if g != 0.0 else 1.0  # slips along G


def _forced_release(tau: float, omega: float, c: float, rate: float, rest: float,
                    f_sta: float, horizon: float) -> float:
    """Time until G(h) = cos(tau + omega h) + c e^{-rate h} - rest leaves [-F_s, F_s]
    (inf if not within ``horizon``): the end of a stick under the actuator's decaying
    force, no closed form; the first crossing of G - F_s upwards or of G + F_s downwards,
    each certified by :func:`_first_crossing` with |G''| <= omega^2 + |c| rate^2
    e^{-rate h} (docs/theory_contact.md §21)."""
    def event(level):
        def f(h):
            e = c * math.exp(-rate * h)
            return (math.cos(tau + omega * h) + e - rest - level,
                    -omega * math.sin(tau + omega * h) - rate * e)
        return f

    def bound2(h):
        return omega * omega + abs(c) * rate * rate * math.exp(-rate * h)

    scale = 1.0 + abs(rest) + f_sta + abs(c)
    hits = []
    for level, sign in ((f_sta, 1.0), (-f_sta, -1.0)):
        g0, dg0 = event(level)(0.0)
        if sign * g0 >= 0.0 and sign * dg0 > 0.0:
            return 0.0          # on the edge of the stick and leaving it
        h = _first_crossing(event(level), bound2, horizon, sign, scale)
        if h is not None:
            hits.append(h)
    return min(hits) if hits else math.inf


def advance_compliant(p: OscillatorParams, law: KelvinVoigt, tau0: float, x: float, v: float,
                      duration: float, *, friction: "Coulomb | None" = None,
                      max_contacts: int = 10000, monodromy: bool = False,
                      times=None, force: LagForce | None = None) -> CompliantSegment:
    """Exact flow with a Kelvin-Voigt stop (and Coulomb friction) for a fixed time.

    Physical state (x, v) in and out. The regions (docs/theory_contact.md, "The
    Kelvin-Voigt stop"):

    * below: x <= d, free; contact starts at the first x = d with x' >= 0
      (without friction the wall's certified search, full relative precision);
    * contact: x > d and F_c > 0; ends at the first zero of F_c;
    * above: x > d and F_c <= 0 (after a damped contact), free; ends at the first
      F_c >= 0 (a new contact) or x = d (below again), whichever comes first.

    With ``friction`` each region slips with the force -F_f sign(x') (a constant on the
    right-hand side: the same closed form), ends a slip at the first zero of x', and
    sticks there while |G| <= F_s, G = cos tau - x - k_c max(x - d, 0) the force without
    friction at rest; the stick ends in closed form (:func:`_release_time`).

    Never hangs: at most 3 ``max_contacts`` + 3 region changes and as many sticks, beyond
    which :class:`ImpactCapError` is raised (docs/theory_contact.md, "Bounded switching").
    ``times`` (sorted, in [0, duration]): the states there as the segment's ``states``
    (:class:`_Dense`).

    ``force``: an external force F_inf + C e^{-rate t} on the mass (:class:`LagForce`,
    the first-order actuator's, docs/theory_contact.md §21): in every region a constant
    and an exponential particular solution (:class:`_Region`), the entry from below by the
    certified search on the region's gap (:func:`_first_crossing`, the bound with the
    exponential's), the force in G, and a stick released by the certified search of
    :func:`_forced_release`.
    """
    _check_law(p, law)
    for name, value in (("x", x), ("v", v), ("tau0", tau0), ("duration", duration)):
        if not math.isfinite(value):
            raise NonFiniteStateError(f"{name}={value!r} must be finite")
    if monodromy and force is not None:
        raise ValueError("monodromy=True is invalid with an external force")
    if monodromy and friction is not None and friction.static != 0.0:
        raise ValueError("monodromy=True is invalid with friction: only the frictionless "
                         "stop's Jacobian is built (docs/theory_contact.md, C8)")
    if friction is not None and friction.static == 0.0:
        friction = None  # Coulomb(0): no friction (else x' = 0 would read as a stick)
    mono = (1.0, 0.0, 0.0, 1.0) if monodromy else None
    k, c = law.stiffness, law.damping
    f_kin = friction.kinetic if friction is not None else 0.0
    f_sta = friction.static if friction is not None else 0.0
    t, tau = 0.0, tau0 % TWO_PI
    delta, vel = x - p.d, v
    contacts: list = []
    sticks: list = []
    switches = 0
    free = (1.0, p.zeta)
    touch = (1.0 + k, p.zeta + 0.5 * c)
    scale_x = abs(p.d) + p.amplitude + abs(delta) + abs(vel) + 1.0
    if delta > 0.0:
        region = "contact" if law.force(delta, vel) > 0.0 else "above"
    else:
        region = "below"
    entry = (0.0, tau, math.nan) if region == "contact" else None
    forced = None
    dense = _Dense(times if times is not None else (), p.d)

    def at_rest_force(tau, delta, t):
        return math.cos(tau) - (delta + p.d) - k * max(delta, 0.0) + _force_at(force, t)

    def slip_sign(tau, delta, vel):
        """Direction of the friction's slip; 0 for a stick (x' = 0, |G| <= F_s)."""
        if f_kin == 0.0 and f_sta == 0.0:
            return 0.0 if vel == 0.0 else math.copysign(1.0, vel)
        if vel != 0.0:
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
        if friction is not None and s == 0.0:  # stuck: x fixed until |G| = F_s
            t_stick = t
            stick, t, forced = _stuck(
                tau, tau0, p.omega, t, duration, p.d + delta + k * max(delta, 0.0), f_sta,
                lambda u: at_rest_force((tau0 + p.omega * u) % TWO_PI, delta, u), force)
            dense.piece(t_stick, t, lambda u: (delta, 0.0))
            sticks.append(stick)
            tau = (tau0 + p.omega * t) % TWO_PI
            vel = 0.0
            if forced is None:
                break
            continue
        push = s * f_kin
        geometry = free if region != "contact" else touch
        reg = _Region(*geometry, p, tau, delta, vel, push, force, t)
        h_stop = None
        if friction is not None and s != 0.0:
            h_stop = _slip_end(reg, s, remaining,
                               reg.cabs + reg.amp + abs(reg.kk) + abs(vel) + 1.0)
        horizon = h_stop if h_stop is not None else remaining
        kind, h = None, None
        if region == "below":
            if friction is None and force is None:
                xp, vp = particular(p, tau)
                dx, dv = (delta + p.d) - xp, vel - vp
                if delta == 0.0:  # on the stop: its deviation without cancellation (impact.py)
                    dx = _on_wall_at_rest(p, tau)[0]
                h = _wall_entry(p, tau, dx, dv, horizon)
            else:
                h = _region_crossing(reg, _GAP, 0.0, 0.0, horizon, 1.0,
                                     reg.cabs + reg.amp + abs(reg.offset) + abs(reg.kk))
            kind = "entry" if h is not None else None
        elif region == "contact":
            sc = k * (reg.cabs + reg.amp + abs(reg.offset) + abs(reg.kk)) + c * scale_x
            h = _region_crossing(reg, _FORCE, k, c, horizon, -1.0, sc)
            kind = "exit" if h is not None else None
        else:
            sc = k * (reg.cabs + reg.amp + abs(reg.offset) + abs(reg.kk)) + c * scale_x
            kind, h = _above_switch(reg, _region_crossing(reg, _FORCE, k, c, horizon, 1.0, sc),
                                    horizon)
        if kind is None:
            if h_stop is None:
                dense.piece(t, duration, reg)
                delta, vel, _ = reg(remaining)
                if mono is not None:
                    mono = matmul2(reg.transition(remaining), mono)
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
        if mono is not None:
            mono = matmul2(reg.transition(h), mono)
        t += h
        tau = (tau0 + p.omega * t) % TWO_PI
        if kind == "entry":
            if region == "below":
                delta = 0.0
                if (vel <= 8.0 * _EPS * scale_x
                        and math.cos(tau) - p.d - push + _force_at(force, t) <= 0.0):
                    vel = 0.0  # a tangency below rounding, pulled away: no contact (impact.py)
                    continue
                vel = max(vel, 0.0)
                if mono is not None:  # the dashpot's force c_c v jumps on (C8)
                    mono = matmul2((1.0, 0.0, -c, 1.0), mono)
            entry = (t, tau, vel)
            region = "contact"
        elif kind == "exit":
            contacts.append(Contact(entry[0], entry[1], entry[2], vel, t - entry[0], delta))
            if len(contacts) > max_contacts:
                raise ImpactCapError(
                    f"more than max_contacts={max_contacts} contacts in {duration:.6g} time "
                    f"units at phase {tau:.6f}: the motion is not resolvable at this cap")
            entry = None
            region = "above" if delta > 0.0 else "below"
            if region == "below":
                delta = min(delta, 0.0)
        else:
            delta = 0.0
            region = "below"
    if entry is not None:
        contacts.append(Contact(entry[0], entry[1], entry[2], math.nan, math.inf, math.nan))
    return CompliantSegment(delta + p.d, vel, contacts, tuple(sticks), mono,
                            dense.end(delta, vel) if times is not None else None)


def _above_switch(reg: _Region, h_force: float | None, horizon: float):
    """Above the stop after an exit (free, delta > 0, the force <= 0): the first of the
    force's return to 0 at ``h_force`` (a new contact, 'entry'; None if not within
    ``horizon``, the caller's certified search) and of the gap's (delta = 0: 'below'),
    certified (:func:`_region_crossing`); (None, None) if neither."""
    h_gap = _region_crossing(reg, _GAP, 0.0, 0.0, h_force if h_force is not None else horizon,
                             -1.0, reg.cabs + reg.amp + abs(reg.offset) + abs(reg.kk))
    if h_gap is not None and (h_force is None or h_gap < h_force):
        return "below", h_gap
    if h_force is not None:
        return "entry", h_force
    return None, None


def _region_crossing(reg: _Region, kind: int, k: float, c: float, horizon: float,
                     sign: float, scale: float):
    """:func:`_first_crossing` of a region's gap delta (``kind`` _GAP: the event
    (delta, delta'), the bound :meth:`_Region.bound` (2)) or contact force k delta +
    c delta' (_FORCE: :func:`_force_event`, :func:`_force_bound`), each bracketed on its
    value alone (:class:`_RegionValue`); the whole search by the compiled mirror once
    :func:`load_compiled` has loaded it (kernel.compiled_contact.first_crossing_region:
    the same floats)."""
    if _compiled is not None:
        h = _compiled.first_crossing_region(reg.constants(), kind, k, c, horizon, sign, scale)
        return None if h == _compiled.NONE else h
    if kind == _GAP:
        return _first_crossing(lambda u: reg(u)[:2], lambda u: reg.bound(2, u), horizon, sign,
                               scale, _RegionValue(reg, _GAP))
    return _first_crossing(_force_event(reg, k, c), _force_bound(reg, k, c), horizon, sign,
                           scale, _force_value(reg, k, c))


def _slip_end(reg: _Region, s: float, horizon: float, scale: float):
    """The end of a friction's slip in direction ``s`` (+-1): :func:`_first_crossing` of
    -s delta' (the event -s (delta', delta''), the bound :meth:`_Region.bound` (3)),
    compiled once :func:`load_compiled` has loaded the searches (kind SLIP of
    kernel.compiled_contact.first_crossing_region, the same floats)."""
    if _compiled is not None:
        h = _compiled.first_crossing_region(reg.constants(), _SLIP, s, 0.0, horizon, 1.0,
                                            scale)
        return None if h == _compiled.NONE else h
    return _first_crossing(lambda h: tuple(-s * u for u in reg(h)[1:]),
                           lambda h: reg.bound(3, h), horizon, 1.0, scale)


def _wall_entry(p: OscillatorParams, tau: float, dx: float, dv: float, horizon: float):
    """The entry from below the stop, the rigid wall's certified search
    (:func:`~grazing_control.oscillator.impact._next_impact` from the deviation (dx, dv) at
    phase tau), compiled (:func:`kernel.next_impact_unchecked`, the same floats) once
    :func:`load_compiled` has loaded the compiled searches."""
    if _compiled is not None:
        return kernel.next_impact_unchecked(p, tau, dx, dv, horizon)
    return _next_impact(p, tau, dx, dv, horizon)


def _force_event(reg: _Region, k: float, c: float):
    def event(h):
        d, v, a = reg(h)
        return k * d + c * v, k * v + c * a
    return event


def _force_value(reg: _Region, k: float, c: float):
    """The force's value alone, k delta + c delta' (:meth:`_Region.force_value`)."""
    return _RegionValue(reg, _FORCE, k, c)


def _force_bound(reg: _Region, k: float, c: float):
    """A bound on |F''|: k bound(2) + c bound(3) (:meth:`_Region.force_bound`)."""
    return partial(reg.force_bound, k, c)


def compliant_period_step(p: OscillatorParams, law: KelvinVoigt, dx: float, dv: float,
                          dv_correction: float = 0.0, *, friction: Coulomb | None = None,
                          monodromy: bool = False) -> CompliantSegment:
    """One forcing period from a Pi2 sample with a Kelvin-Voigt stop.

    The shape of :func:`grazing_control.dynamics.simulation.fidelity.period_step`: deviation (dx, dv)
    from x_p at phase tau2 in, the correction dv_correction applied on Pi2 (Eq. 28), one
    period of :func:`advance_compliant`, the deviation at the next Pi2 sample out (as the
    segment's x, v) with the contacts (times from the sample).
    """
    xp, vp = particular(p, p.tau2)
    x0, v0 = xp + dx, vp + dv + dv_correction
    if x0 - p.d > 0.0 and law.force(x0 - p.d, v0) > 0.0 and x0 - p.d > 1e-3:
        raise InitialStateError(f"state deep in the stop: x - d = {x0 - p.d:.3e}")
    seg = advance_compliant(p, law, p.tau2, x0, v0, p.period, friction=friction,
                            monodromy=monodromy)
    tau = (p.tau2 + p.omega * p.period) % TWO_PI
    xe, ve = particular(p, tau)
    return CompliantSegment(seg.x - xe, seg.v - ve, seg.contacts, seg.sticks, seg.monodromy)


def grazing_jump(law: KelvinVoigt, alpha: float, penetration: float, *,
                 friction: Coulomb | None = None):
    """Leading order of the Kelvin-Voigt stop's grazing discontinuity map (Eqs. C7, C10).

    A free flight whose virtual maximum is ``penetration`` H > 0 above the stop, with
    deceleration ``alpha`` = d - cos tau* > 0 there, leaves the contact with its velocity
    changed, relative to the free flow at the apex, by

        dv = -c_c H                                    (c_c > 0: order 1),
        dv = -(4/3) k_c sqrt(2 / alpha) H^{3/2}        (c_c = 0: order 3/2),

    while k_c H / alpha << 1 (the contact is much shorter than the stop's own period);
    the rigid map's -(1 + r) sqrt(2 alpha H) is the limit for k_c H / alpha >> 1
    (docs/theory_contact.md, "The compliant discontinuity map").

    With Coulomb ``friction`` (F_f < alpha - (F_s - F_f): the mass slips through the apex)
    the flight decelerates at alpha + F_f before the apex and alpha - F_f after it, and
    an impulse taken before the apex reaches the section after it scaled by
    q = (alpha - F_f) / (alpha + F_f) (it moves the friction's switch, the apex); the
    order is unchanged and (Eq. C10)

        dv = -q c_c H,
        dv = -(2/3) sqrt(2) k_c (q / sqrt(alpha + F_f) + 1 / sqrt(alpha - F_f)) H^{3/2}.

    Returns (order, coefficient, dv).
    """
    f = 0.0 if friction is None else friction.kinetic
    if friction is not None and not alpha > friction.static:
        raise ParameterError(f"friction static={friction.static!r} is invalid here: the map "
                             f"of Eq. C10 needs the mass to slip through the apex, "
                             f"F_s < alpha = {alpha!r}")
    q = (alpha - f) / (alpha + f)
    if law.damping > 0.0:
        order, coef = 1.0, q * law.damping
    else:
        order, coef = 1.5, ((2.0 / 3.0) * math.sqrt(2.0) * law.stiffness
                            * (q / math.sqrt(alpha + f) + 1.0 / math.sqrt(alpha - f)))
    return order, coef, -coef * penetration ** order

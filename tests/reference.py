"""Independent 50-digit reference of the impact oscillator, in physical coordinates.

This module is the yardstick the tests and benchmarks measure the numerical core
against, so it shares no code with :mod:`grazing_control`: every formula is written
again from the model (spec section 1, study Eq. 1)::

    x'' + 2 zeta x' + x = cos(omega t + tau0)      while x < d
    v+ = -r v-                                      at x = d, v- > 0

Between impacts, with tau = omega t + tau0 and h the time since the start (x0, v0)
of the arc at phase tau_s,

    x(h) = a cos(tau_s + omega h - phi) + e^{-zeta h} (C1 cos(omega_d h) + C2 sin(omega_d h)),
    a = 1 / sqrt((1 - omega^2)^2 + (2 zeta omega)^2),  phi = atan2(2 zeta omega, 1 - omega^2),
    C1 = x0 - x_p(0),  C2 = (v0 - v_p(0) + zeta C1) / omega_d,

which is the particular solution plus the general homogeneous one (check: both satisfy
the ODE, and x(0) = x0, x'(0) = v0). All arithmetic is mpmath at ``DPS`` = 50 digits.

Impacts are the first h > 0 with g(h) = x(h) - d = 0 and v >= 0. They are bracketed on
a uniform grid (``SAMPLES`` per forcing period): each grid cell is first split at the
zeros of the acceleration (so v is monotone on each piece), then an upward sign change
of g brackets a root, and a maximum of g inside a piece (v changing from + to -) is
located and tested, which catches grazing impacts whose g is negative at every grid
point. Roots are refined by a bracketed Newton iteration (bisection fallback) to
``ROOT_TOL`` = 1e-45. Assumption (checked by the tests that use it, not proven): no
grid cell of length T/64 ~ 0.15 contains two zeros of the acceleration.

The controller of Eq. 28 is included, v <- v + c1 (x - x**) + c2 (v - v**) on Pi2,
so that controlled orbits can be checked too. Sticking is *not* modelled: more than
``MAX_IMPACTS_PER_PERIOD`` impacts in a period of :meth:`RefModel.simulate` raise
RuntimeError. Chattering sequences are, bounce by bounce, by :meth:`RefModel.bounces`
(continued from the exact post-impact state until a caller's stopping rule).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mpmath import mp, mpf

__all__ = ["DPS", "RefModel", "RefRun", "mpf"]

DPS = 50
mp.dps = DPS
ROOT_TOL = mpf("1e-45")
SAMPLES = 64
MAX_IMPACTS_PER_PERIOD = 50


def _f(value) -> mpf:
    """A float (or mpf) as an mpf, exactly: floats are dyadic rationals."""
    return value if isinstance(value, mpf) else mpf(float(value))


class RefModel:
    """The model at 50 digits. Parameters are taken exactly from their float values.

    ``d = a(omega) + delta_d`` is formed in mpmath, so that delta_d keeps its meaning
    (distance of the wall from grazing) exactly, as in the core.
    """

    def __init__(self, zeta, r, omega, delta_d, tau0=0.0, pi2_offset=None):
        with mp.workdps(DPS):
            self.zeta = _f(zeta)
            self.r = _f(r)
            self.omega = _f(omega)
            self.delta_d = _f(delta_d)
            self.tau0 = _f(tau0)
            self.pi2_offset = mp.pi / 2 if pi2_offset is None else _f(pi2_offset)
            z, w = self.zeta, self.omega
            self.omega_d = mp.sqrt(1 - z * z)
            self.amplitude = 1 / mp.sqrt((1 - w * w) ** 2 + (2 * z * w) ** 2)
            self.lag = mp.atan2(2 * z * w, 1 - w * w)
            self.d_star = self.amplitude
            self.d = self.d_star + self.delta_d
            self.period = 2 * mp.pi / w
            self.tau_star = self.lag % (2 * mp.pi)
            self.tau2 = (self.tau_star + self.pi2_offset) % (2 * mp.pi)
            self.x_ref = self.amplitude * mp.cos(self.pi2_offset)
            self.v_ref = -self.amplitude * w * mp.sin(self.pi2_offset)

    @classmethod
    def from_params(cls, p) -> "RefModel":
        """From an OscillatorParams (only its six float fields are read)."""
        return cls(p.zeta, p.r, p.omega, p.delta_d, p.tau0, p.pi2_offset)

    # ------------------------------------------------------------- closed form
    def particular(self, tau):
        """(x_p, v_p, a_p) of the non-impacting motion at forcing phase tau."""
        c, s = mp.cos_sin(_f(tau) - self.lag)
        a, w = self.amplitude, self.omega
        return a * c, -a * w * s, -a * w * w * c

    def arc(self, tau, x, v) -> "Arc":
        """The free flow from physical state (x, v) at phase tau."""
        return Arc(self, _f(tau), _f(x), _f(v))

    def flow(self, tau, x, v, h):
        """Physical (x, v) after time h of free flight (no impact check)."""
        g, vel, _a = self.arc(tau, x, v)(_f(h))
        return g + self.d, vel

    def transition_matrix(self, h):
        """Phi(h) = exp(A h) by mpmath's matrix exponential (A = [[0,1],[-1,-2 zeta]])."""
        A = mp.matrix([[0, 1], [-1, -2 * self.zeta]])
        return mp.expm(A * _f(h))

    def gap_deviation(self, tau, dx):
        """x - d for deviation dx at phase tau, formed in physical coordinates."""
        return self.particular(tau)[0] + _f(dx) - self.d

    def to_physical(self, tau, dx, dv):
        xp, vp, _ = self.particular(tau)
        return xp + _f(dx), vp + _f(dv)

    # ---------------------------------------------------------------- impacts
    def next_impact(self, tau, x, v, horizon, samples=SAMPLES):
        """First impact time in (0, horizon] of the arc from (x, v) at phase tau, or None."""
        arc = self.arc(tau, x, v)
        horizon = _f(horizon)
        n = max(4, int(mp.ceil(samples * horizon / self.period)))
        hs = [horizon * k / n for k in range(n + 1)]
        return first_root(arc, hs, ROOT_TOL * 1e-3, _refine)

    def bounces(self, tau, v, duration, stop=None, max_impacts=2000):
        """The exact impacts of the motion that leaves the wall x = d with velocity v.

        From (d, v) at phase tau (v <= 0: the state just after an impact), the free flow
        is continued at 50 digits, each impact located to ``ROOT_TOL`` (:meth:`next_impact`)
        and the impact law v+ = -r v- applied exactly, until ``duration`` has passed or
        ``stop(phase, v_minus)`` is true at an impact (that impact is the last returned).
        Bounces are thus resolved ~35 digits below the rounding of a double, which makes
        this the yardstick of chattering sequences.

        Returns
        -------
        (impacts, stopped)
            impacts: list of (t, phase, v-, v+) with t since the start, phase not reduced;
            stopped: whether ``stop`` ended the sequence.
        """
        x, v, tau, t = self.d, _f(v), _f(tau), mpf(0)
        duration = _f(duration)
        out = []
        while len(out) < max_impacts:
            h = self.next_impact(tau, x, v, duration - t)
            if h is None:
                return out, False
            vm = self.flow(tau, x, v, h)[1]
            t, tau = t + h, tau + self.omega * h
            x, v = self.d, -self.r * vm
            out.append((t, tau, vm, v))
            if stop is not None and stop(tau, vm):
                return out, True
        raise RuntimeError(f"reference: more than {max_impacts} bounces")

    # -------------------------------------------------------------- simulate
    def simulate(self, periods, x0=None, v0=None, gains=None, control_after=0,
                 tau_start=None):
        """Run ``periods`` forcing periods from the Pi2 state (x0, v0) (default X**).

        gains : (c1, c2) or None; the controller acts at samples k >= control_after.
        tau_start : phase of the first sample (default tau2 of this model).

        Returns a :class:`RefRun` with mpf entries.
        """
        x = self.x_ref if x0 is None else _f(x0)
        v = self.v_ref if v0 is None else _f(v0)
        tau = self.tau2 if tau_start is None else _f(tau_start)
        T = self.period
        run = RefRun()
        for k in range(periods):
            run.pi2.append((x, v))
            if gains is not None and control_after is not None and k >= control_after:
                c1, c2 = _f(gains[0]), _f(gains[1])
                v = v + c1 * (x - self.x_ref) + c2 * (v - self.v_ref)
            t_in = mpf(0)
            count = 0
            while True:
                h = self.next_impact(tau, x, v, T - t_in)
                if h is None:
                    x, v = self.flow(tau, x, v, T - t_in)
                    tau = tau + self.omega * (T - t_in)
                    break
                count += 1
                if count > MAX_IMPACTS_PER_PERIOD:
                    raise RuntimeError("reference: chattering is not modelled")
                _xm, vm = self.flow(tau, x, v, h)
                t_in += h
                tau = tau + self.omega * h
                vplus = -self.r * vm
                run.impacts.append((k * T + t_in, tau % (2 * mp.pi), vm, vplus))
                x, v = self.d, vplus
            tau = tau % (2 * mp.pi)
            run.counts.append(count)
        run.final = (x, v)
        return run

    def pi2_map(self, x, v, periods=1, gains=None):
        """P^n on Pi2 (controller before each period if gains), physical coordinates."""
        run = self.simulate(periods, x, v, gains=gains)
        return run.final, run.counts

    def fixed_point(self, x, v, periods=1, gains=None, tol=mpf("1e-35"), max_iter=30):
        """Fixed point of P^n by Newton with a 50-digit central-difference Jacobian.

        Independent of the core's monodromy: the Jacobian is differenced with a step
        of 1e-20, whose truncation error (1e-40) and rounding error (1e-30) are far
        below the 1e-12 the tests ask for.
        """
        z = mp.matrix([_f(x), _f(v)])
        step = mpf("1e-20")
        for _ in range(max_iter):
            (fx, fv), _ = self.pi2_map(z[0], z[1], periods, gains)
            res = mp.matrix([fx - z[0], fv - z[1]])
            J = mp.matrix(2, 2)
            for j in range(2):
                e = mp.matrix([0, 0])
                e[j] = step
                (px, pv), _ = self.pi2_map(z[0] + e[0], z[1] + e[1], periods, gains)
                (mx, mv), _ = self.pi2_map(z[0] - e[0], z[1] - e[1], periods, gains)
                J[0, j] = (px - mx) / (2 * step)
                J[1, j] = (pv - mv) / (2 * step)
            J[0, 0] -= 1
            J[1, 1] -= 1
            dz = mp.lu_solve(J, -res)
            z = z + dz
            if mp.norm(dz) < tol:
                break
        else:
            raise RuntimeError("reference Newton did not converge")
        return z[0], z[1]


@dataclass
class RefRun:
    """Reference run: Pi2 samples (x, v) per period (before control), impacts
    (t, phase mod 2 pi, v-, v+) with t since the first sample, impacts per period."""

    pi2: list = field(default_factory=list)
    impacts: list = field(default_factory=list)
    counts: list = field(default_factory=list)
    final: tuple = (None, None)


class Arc:
    """Gap g = x - d, velocity, acceleration and jerk along one free-flight arc."""

    __slots__ = ("m", "tau", "c1", "c2", "k1", "k2", "aw", "aw2", "aw3", "phase0",
                 "_floats")

    def __init__(self, m: RefModel, tau, x, v):
        self.m = m
        self.tau = tau
        xp, vp, _ = m.particular(tau)
        self.c1 = x - xp
        self.c2 = (v - vp + m.zeta * self.c1) / m.omega_d
        # y' = e^{-zeta h} (k1 cos - k2 sin)
        self.k1 = m.omega_d * self.c2 - m.zeta * self.c1
        self.k2 = m.omega_d * self.c1 + m.zeta * self.c2
        self.aw = m.amplitude * m.omega
        self.aw2 = self.aw * m.omega
        self.aw3 = self.aw2 * m.omega
        self.phase0 = tau - m.lag
        self._floats = None

    def __call__(self, h, jerk=False):
        """(g, v, acc[, jerk]) at time h since the start of the arc."""
        m = self.m
        e = mp.exp(-m.zeta * h)
        c, s = mp.cos_sin(m.omega_d * h)
        cp, sp = mp.cos_sin(self.phase0 + m.omega * h)
        # homogeneous part y = e (c1 c + c2 s) and its derivatives, from y'' = -2 zeta y' - y
        y = e * (self.c1 * c + self.c2 * s)
        y1 = e * (self.k1 * c - self.k2 * s)
        y2 = -2 * m.zeta * y1 - y
        g = m.amplitude * cp + y - m.d
        vel = y1 - self.aw * sp
        acc = y2 - self.aw2 * cp
        if not jerk:
            return g, vel, acc
        y3 = -2 * m.zeta * y2 - y1
        return g, vel, acc, self.aw3 * sp + y3

    def in_floats(self, h, which):
        """Components ``which`` and ``which + 1`` of (g, v, acc, jerk) at h, in double
        precision: only the start of :func:`_refine`'s Newton iteration."""
        if self._floats is None:
            m = self.m
            self._floats = tuple(float(x) for x in (
                m.zeta, m.omega_d, m.omega, m.amplitude, m.d, self.c1, self.c2, self.k1,
                self.k2, self.phase0))
        zeta, omega_d, omega, amplitude, d, c1, c2, k1, k2, phase0 = self._floats
        e = math.exp(-zeta * h)
        c, s = math.cos(omega_d * h), math.sin(omega_d * h)
        cp, sp = math.cos(phase0 + omega * h), math.sin(phase0 + omega * h)
        y = e * (c1 * c + c2 * s)
        y1 = e * (k1 * c - k2 * s)
        y2 = -2 * zeta * y1 - y
        aw = amplitude * omega
        out = (amplitude * cp + y - d, y1 - aw * sp, y2 - aw * omega * cp,
               aw * omega * omega * sp - 2 * zeta * y2 - y1)
        return out[which], out[which + 1]


def first_root(arc, hs, wall_tol, refine):
    """First impact time on the grid ``hs`` of an ``arc`` (h -> (g, v, acc)), or None; the
    search of this module and of tests/reference_ndof.py.

    A start within ``wall_tol`` of the wall is an impact at 0 if v > 0, sticking
    (RuntimeError) if v = 0, else leaving. A cell whose acceleration changes sign is split
    at its zero, so v is monotone on each piece; a piece with g < 0 <= g at its ends
    brackets a root, and one where v goes from + to - holds a maximum of g, tested.
    ``refine(arc, lo, hi, which, increasing)`` finds the root of component ``which``.
    """
    g0, v0, a0 = arc(hs[0])
    if abs(g0) <= wall_tol:  # on the wall (up to 50-digit rounding)
        if v0 > 0:
            return mpf(0)
        if v0 == 0:
            raise RuntimeError("reference: at rest on the wall (sticking) is not modelled")
        g0 = -ROOT_TOL  # leaving the wall: g < 0 just after the start
    lo = (hs[0], (g0, v0, a0))
    for h in hs[1:]:
        hi = (h, arc(h))
        found = _search_cell(arc, lo, hi, refine)
        if found is not None:
            return found
        lo = hi
    return None


def _search_cell(arc, lo, hi, refine):
    # split where the acceleration changes sign, so that v is monotone on pieces
    (a, fa), (b, fb) = lo, hi
    pieces = [(lo, hi)]
    if fa[2] * fb[2] < 0:
        tm = refine(arc, a, b, 2, fa[2] < 0)
        mid = (tm, arc(tm))
        pieces = [(lo, mid), (mid, hi)]
    for (a, fa), (b, fb) in pieces:
        if fa[0] < 0 <= fb[0]:
            return refine(arc, a, b, 0, True)
        if fa[0] < 0 and fb[0] < 0 and fa[1] > 0 and fb[1] <= 0:
            tm = refine(arc, a, b, 1, False)  # maximum of g
            if arc(tm)[0] >= 0:
                return refine(arc, a, tm, 0, True)
    return None


def newton_bracket(arc, x, lo, hi, which, sign):
    """One evaluation of a bracketed Newton iteration (this module's and
    tests/reference_ndof.py's): (f, f', lo, hi) at x, f = ``sign`` times component
    ``which`` of the arc (so that it rises through the bracket), f' the next component
    times ``sign``, and the bracket [lo, hi] narrowed to x on the side of f's sign."""
    vals = arc(x, which == 2)
    fx = sign * vals[which]
    if fx > 0:
        hi = x
    elif fx < 0:
        lo = x
    return fx, sign * vals[which + 1], lo, hi


def _refine(arc, lo, hi, which, increasing):
    """Root of component ``which`` (0 gap, 1 velocity, 2 acceleration) in [lo, hi].

    ``increasing``: the component goes from < 0 at lo to >= 0 at hi (else the reverse).
    Newton with the next component as derivative, kept inside the bracket.
    """
    sign = 1 if increasing else -1
    x = _start_in_floats(arc, lo, hi, which, sign)
    for _ in range(400):
        fx, dfx, lo, hi = newton_bracket(arc, x, lo, hi, which, sign)
        if fx == 0:
            return x
        if hi - lo < ROOT_TOL:
            break
        xn = x - fx / dfx if dfx != 0 else (lo + hi) / 2
        if not lo < xn < hi:
            xn = (lo + hi) / 2
        if abs(xn - x) < ROOT_TOL / 4:
            # Newton has converged: close the bracket around it
            xl, xh = xn - ROOT_TOL / 4, xn + ROOT_TOL / 4
            if sign * arc(xl)[which] < 0 <= sign * arc(xh)[which]:
                return xh
        x = xn
    return hi


def _start_in_floats(arc, lo, hi, which, sign):
    """Where :func:`_refine` starts: the bracket's midpoint, or the limit of the same
    bracketed Newton iteration in double precision (on an arc that offers
    ``in_floats``) when it lies inside the bracket. Only a start: the 50-digit iteration
    goes on from it, inside the 50-digit bracket, so the root is the same; from ~1e-16
    it takes ~3 steps to 1e-45 where it took ~10 from the midpoint."""
    mid = (lo + hi) / 2
    in_floats = getattr(arc, "in_floats", None)
    if in_floats is None:
        return mid
    a, b = float(lo), float(hi)
    x = float(mid)
    for _ in range(60):
        f, df = in_floats(x, which)
        f, df = sign * f, sign * df
        if f == 0:
            break
        if f > 0:
            b = x
        else:
            a = x
        xn = x - f / df if df != 0 else (a + b) / 2
        if not a < xn < b:
            xn = (a + b) / 2
        if abs(xn - x) <= 4 * math.ulp(x) or b - a <= 4 * math.ulp(b):
            x = xn
            break
        x = xn
    start = mpf(x)
    return start if lo < start < hi else mid

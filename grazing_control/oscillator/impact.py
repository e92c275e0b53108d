"""Impact detection, the impact law, saltation, chattering and sticking.

The trajectory between impacts is the exact flow of :mod:`grazing_control.oscillator.flow`. An
impact is the first h > 0 with gap g(h) = x(h) - d = 0 and v >= 0. Finding it must
never miss a low-velocity (near-grazing) impact and never report a spurious one.

Certified search (docs/theory.md, "Impact detection")
-----------------------------------------------------
On an interval [a, b] the acceleration g'' = x'' has a fixed sign whenever

    |g''(a)| + |g''(b)| > J (b - a),   signs equal,   J >= max |g'''|,

because g'' is J-Lipschitz. With J = a(omega) omega^3 + |C| e^{-zeta a}
(:func:`grazing_control.oscillator.flow.amplitude_bound`) the bound is rigorous. On such an
interval g is convex or concave, so it has at most one maximum, located by a
safeguarded Newton iteration on v = g'; whether g reaches 0 is then decided by the
sign of g at that maximum, computed without cancellation in deviation coordinates.
An interval whose upper bound from the chord, max(g(a), g(b)) + K h^2 / 8 with
K = max(0, -min g'') >= 0 and min g'' >= (g''(a) + g''(b) - J h) / 2, is below 0 has no
impact. Intervals that cannot be certified are bisected. A window is first excluded as
a whole when sup g <= -Delta d + |C| < 0. Every exclusion carries a margin for the
rounding of the computed g and g'' (docs/theory.md, "Rounding"), so it holds for the
exact trajectory of the rounded start state.

Contacts below rounding
-----------------------
A contact whose approach velocity is within the velocity's rounding of 0 is a contact
at rest: not an impact when the wall force cos tau - d <= 0 (a tangency), a sticking
event with v- = v+ = 0 when it pushes into the wall. Every other reported impact has
v- > 0 (docs/theory.md, "Tangency below rounding"). A mass at rest on the wall at the
start of a call (stuck across a Pi2 sample) is recognised to the rounding of the phase
and stays stuck. A flight that starts within the gap's rounding below the wall while
leaving it (v < 0, after every bounce) starts on the wall: its search never takes its
own start for a root (docs/theory.md, "A start on the wall").

Chattering and sticking
-----------------------
After an impact at phase tau_i with the wall force cos tau_i - d > 0 (mass pushed
into the wall), the impacts form a geometric sequence v_{k+1} = r v_k that ends at
t_inf ~ 2 r v- / ((1 - r)(cos tau_i - d)). When that time is below ``chatter_time``,
or the next bounce is lower than ~1e3 ulps of the gap (not resolvable), the sequence
is summed in closed form and the mass sticks (x = d, v = 0) until the
contact force cos tau - d changes sign; it is then released with zero velocity.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from .flow import amplitude_bound, matmul2, transition_matrix
from .params import OscillatorParams

__all__ = [
    "Impact",
    "Segment",
    "ImpactCapError",
    "InitialStateError",
    "NonFiniteStateError",
    "check_state",
    "MAX_AMPLITUDE",
    "next_impact",
    "saltation_matrix",
    "advance",
]

TWO_PI = 2.0 * math.pi
_MAX_DEPTH = 64
_EPS = 2.0 ** -52
#: Largest deviation amplitude |C| (flow.amplitude_bound) accepted: beyond it the gap's
#: rounding exceeds any physical scale and squared velocities overflow.
MAX_AMPLITUDE = 1e150


class Impact(NamedTuple):
    """One impact: time since the start of the segment, phase, velocities.

    ``sticking`` marks the end of a chattering sequence: the mass then rests on the
    wall until ``release`` (time since the segment start; inf if not in the segment).
    """

    dt: float
    phase: float
    v_minus: float
    v_plus: float
    sticking: bool = False
    release: float = math.nan


class Segment(NamedTuple):
    """Result of :func:`advance`: final deviation, impacts, and monodromy if asked."""

    dx: float
    dv: float
    impacts: list
    monodromy: tuple | None


class ImpactCapError(RuntimeError):
    """More impacts than ``max_impacts`` in one call: the motion is not resolvable."""


class InitialStateError(ValueError):
    """The state lies beyond the wall (x > d)."""


class NonFiniteStateError(ValueError):
    """A state (or a time) is not finite, or absurdly large (deviation |C| > MAX_AMPLITUDE).

    Raised before any search starts, so that an overflow (a gain of 1e308, noise of
    1e308) stops with a message naming the value instead of hanging the search.
    """


def check_state(dx: float, dv: float, zeta: float, where: str = "the state") -> None:
    """Raise :class:`NonFiniteStateError` unless (dx, dv) is finite with |C| <= MAX_AMPLITUDE."""
    if not (math.isfinite(dx) and math.isfinite(dv)):
        raise NonFiniteStateError(
            f"{where} is not finite: deviation (dx, dv) = ({dx!r}, {dv!r})")
    size = amplitude_bound(zeta, dx, dv)
    if not size <= MAX_AMPLITUDE:
        raise NonFiniteStateError(
            f"{where} is absurdly large: deviation amplitude |C| = {size:.3e} > "
            f"{MAX_AMPLITUDE:.0e} (dx, dv) = ({dx!r}, {dv!r}); an input overflowed")


def check_times(tau0: float, name: str, value: float) -> None:
    """Raise :class:`NonFiniteStateError` unless the start phase ``tau0`` and the length
    ``name`` = ``value`` of the window are finite."""
    if not (math.isfinite(tau0) and math.isfinite(value)):
        raise NonFiniteStateError(f"tau0={tau0!r} and {name}={value!r} must be finite")


def _wall_rounding(p: OscillatorParams, tau: float, dx: float, dv: float):
    """Rounding (gap, velocity) of a state at phase tau in deviation coordinates
    (:func:`wall_rounding` of the 1-DOF oscillator)."""
    return wall_rounding(tau, p.lag, p.amplitude, p.omega, p.delta_d, dx, dv)


def wall_rounding(tau: float, lag: float, amp: float, omega: float, delta_d: float,
                  dx: float, dv: float):
    """Rounding (gap, velocity) of the wall coordinate at phase tau, for any model: its
    deviation position ``dx`` and velocity ``dv``, the periodic response's lag tau* and
    amplitude d* (``lag``, ``amp``), the forcing's ``omega``, the wall offset ``delta_d``.

    The gap g = dx - Delta d - 2 d* sin^2(psi / 2) and the velocity v = v_p + dv carry
    the rounding of their terms and of the phase psi = tau - tau*, which is known to
    ~eps (|tau| + |tau*| + 2 pi) (phases are reduced modulo 2 pi after each step).
    """
    psi = tau - lag
    s2 = 2.0 * amp * math.sin(0.5 * psi) ** 2
    vp = -amp * omega * math.sin(psi)
    phase = abs(tau) + abs(lag) + TWO_PI + 1.0
    eg = 8.0 * _EPS * (abs(dx) + abs(delta_d) + s2 + math.sqrt(2.0 * amp * s2) * phase)
    ev = 8.0 * _EPS * (abs(vp) + abs(dv) + amp * omega * phase)
    return eg, ev


class GapEvaluator:
    """What every model's gap evaluator shares (this module's :class:`_Eval`, the n-DOF
    one of oscillator/ndof/impact.py): the forcing's frequency ``omega``, the periodic
    response's lag and amplitude (``lag`` = tau*, ``amp`` = d*), the wall offset ``dd`` =
    Delta d and the start phase ``tau0``, so the gap's harmonic part is
    -Delta d - 2 d* sin^2(psi / 2) with psi = tau0 + omega h - tau*. The search
    (:func:`_scan_window`, :func:`_search`) needs of an evaluator this, ``__call__``
    (g, v, acc, ...) at h, ``jerk_bound``, ``gap_rounding``, ``cabs``, ``acc_err``,
    ``m0``, ``m1``."""

    __slots__ = ("omega", "lag", "amp", "dd", "tau0")

    def __init__(self, omega: float, lag: float, amp: float, dd: float, tau0: float):
        self.omega = omega
        self.lag = lag
        self.amp = amp
        self.dd = dd
        self.tau0 = tau0

    def psi(self, h: float) -> float:
        """Phase psi = tau0 + omega h - tau* of the forcing, as in the gap."""
        return self.tau0 + self.omega * h - self.lag


class _Eval(GapEvaluator):
    """Gap, velocity and acceleration along the flow from one start state."""

    __slots__ = ("zeta", "wd", "dx0", "c2", "aw2", "aw3", "cabs", "acc_err", "m0", "m1")

    def __init__(self, p: OscillatorParams, tau0: float, dx0: float, dv0: float):
        self.zeta = p.zeta
        self.wd = p.omega_d
        super().__init__(p.omega, p.lag, p.amplitude, p.delta_d, tau0)
        self.dx0 = dx0
        self.c2 = (dv0 + p.zeta * dx0) / self.wd
        self.aw2 = self.amp * p.omega * p.omega
        self.aw3 = self.aw2 * p.omega
        self.cabs = math.hypot(dx0, self.c2)
        # rounding of the computed acceleration (docs/theory.md, "Rounding"): products of a
        # few correctly rounded factors; the phases carry ~eps (|tau0| + |phi| + omega h)
        self.acc_err = 8.0 * _EPS * (self.aw2 * (4.0 + abs(tau0) + abs(self.lag))
                                     + 4.0 * self.cabs)
        # gap_rounding(h) <= m0 + m1 h for every h (s2 <= 2 a): a cheap first test
        phase0 = abs(tau0) + abs(self.lag) + 1.0
        self.m0 = 8.0 * _EPS * (2.0 * self.cabs + abs(self.dd) + 2.0 * self.amp * (1.0 + phase0))
        self.m1 = 8.0 * _EPS * (self.cabs * self.wd + 2.0 * self.amp * self.omega)

    def __call__(self, h: float):
        """(g, v, acc, dx, dv) at time h: exact closed form."""
        e = math.exp(-self.zeta * h)
        c = math.cos(self.wd * h)
        s = math.sin(self.wd * h)
        c1 = self.dx0
        c2 = self.c2
        dx = e * (c1 * c + c2 * s)
        dv = e * ((self.wd * c2 - self.zeta * c1) * c - (self.wd * c1 + self.zeta * c2) * s)
        psi = self.tau0 + self.omega * h - self.lag
        sh = math.sin(0.5 * psi)
        g = dx - self.dd - 2.0 * self.amp * sh * sh
        v = -self.amp * self.omega * math.sin(psi) + dv
        acc = -self.aw2 * math.cos(psi) - 2.0 * self.zeta * dv - dx
        return g, v, acc, dx, dv

    def jerk_bound(self, h: float) -> float:
        """J >= max |g'''| on [h, inf)."""
        return self.aw3 + self.cabs * math.exp(-self.zeta * h)

    def gap_rounding(self, h: float, vals) -> float:
        """Bound on |computed g(h) - exact g(h)| (docs/theory.md, "Rounding").

        z_x is a sum of terms of size |C| whose phase omega_d h carries ~eps h, and
        x_p - d* = -2 a sin^2(psi / 2) has a phase psi = tau0 + omega h - phi rounded to
        ~eps (|tau0| + omega h + |phi|), which moves it by a |sin psi| <= sqrt(2 a s2)
        times that (s2 = 2 a sin^2(psi / 2)).
        """
        g, dx = vals[0], vals[3]
        s2 = abs(dx - self.dd - g)
        phase = abs(self.tau0) + self.omega * h + abs(self.lag) + 1.0
        return 8.0 * _EPS * (self.cabs * (2.0 + self.wd * h) + abs(self.dd) + s2
                             + math.sqrt(2.0 * self.amp * s2) * phase)


def _bracket(f, lo, hi, which, sign, flo, fhi):
    """Root of component ``which`` of f (0: gap g, 1: velocity v) in [lo, hi].

    Safeguarded Newton (the derivative of g is v, of v is the acceleration) that keeps
    the bracket: sign * f(lo) < 0 <= sign * f(hi), sign = +1 for an increasing and
    -1 for a decreasing component. Returns the bracket's right end once it is a few
    ulps wide: for the gap, the first time at which g >= 0 in floating point.

    ``flo``, ``fhi``: the component at lo and hi (every caller has them); the iteration
    starts at their secant point. Newton converging from one side only moves that end
    of the bracket; a step shorter than 2 ulps is therefore replaced by a step of 2 ulps
    past the root, which closes the bracket from the other side (docs/theory.md,
    "Impact detection": about 5 evaluations per root instead of the ~40 bisections that
    closing it otherwise took). Where g is flat to rounding and such a probe does not
    change sign, the next step bisects, so the bracket at least halves every two steps.
    """
    d = flo - fhi
    x = lo + (hi - lo) * (flo / d) if d != 0.0 else 0.5 * (lo + hi)
    if not lo < x < hi:
        x = 0.5 * (lo + hi)
    probed = False
    while hi - lo > 4.0 * math.ulp(hi):
        vals = f(x)
        fx = sign * vals[which]
        if fx >= 0.0:
            hi = x
        else:
            lo = x
        dfx = sign * vals[which + 1]
        xn = x - fx / dfx if dfx > 0.0 else lo
        probe = 2.0 * math.ulp(x)
        if abs(xn - x) < probe:  # 2 ulps past the root; bisect if the last probe failed
            xn = 0.5 * (lo + hi) if probed else (x - probe if fx >= 0.0 else x + probe)
            probed = not probed
        else:
            probed = False
        if not lo < xn < hi:
            xn = 0.5 * (lo + hi)
        if xn == x:
            xn = 0.5 * (lo + hi)
            if xn == x:
                break
        x = xn
    return hi


def _search(f, a, b, fa, fb, depth):
    """First impact time in (a, b], or None.

    Precondition g(a) <= 0. If g(a) = 0 (on the wall) the mass is leaving or at rest:
    an impact is the next return to g >= 0, or an immediate one when the mass is at
    rest on the wall with the acceleration pointing into it (sticking).
    """
    ga, va, acca = fa[0], fa[1], fa[2]
    gb, vb, accb = fb[0], fb[1], fb[2]
    # J (b - a), rounded up, plus the rounding of the two accelerations (docs/theory.md)
    jw = f.jerk_bound(a) * (b - a) * (1.0 + 1e-12) + 2.0 * f.acc_err
    concave = acca < 0.0 and accb < 0.0 and -(acca + accb) > jw
    convex = acca > 0.0 and accb > 0.0 and (acca + accb) > jw
    if concave:  # v decreasing: at most one maximum
        if va <= 0.0:
            return None
        if vb >= 0.0:
            return _bracket(f, a, b, 0, 1.0, ga, gb) if gb >= 0.0 else None
        tm = _bracket(f, a, b, 1, -1.0, va, vb)
        gm = f(tm)[0]
        return _bracket(f, a, tm, 0, 1.0, ga, gm) if gm >= 0.0 else None
    if convex:  # v increasing: g below the chord unless it ends above 0
        if gb < 0.0:
            return None
        if ga < 0.0:
            return _bracket(f, a, b, 0, 1.0, ga, gb)
        if va >= 0.0:  # at rest on the wall and pushed into it
            return a
        tmin = _bracket(f, a, b, 1, 1.0, va, vb) if vb > 0.0 else b
        fmin = f(tmin)
        if fmin[0] >= 0.0:  # the dip below the wall is below rounding: at rest, pushed in
            return tmin
        return _bracket(f, tmin, b, 0, 1.0, fmin[0], gb) if fmin[0] < 0.0 <= gb else None
    # below the chord plus the curvature allowance (docs/theory.md, "Impact detection"):
    # g <= chord + K h^2 / 8 with K = max(0, -min g''), and since g'' is J-Lipschitz,
    # min g'' >= (g''(a) + g''(b) - J h) / 2; certifies intervals around inflections
    # the computed ends are within their rounding of the exact ones, hence the margin
    curvature = max(0.0, 0.5 * (jw - acca - accb))
    upper = max(ga, gb) + 0.125 * (b - a) ** 2 * curvature
    if upper < 0.0 and (upper + f.m0 + f.m1 * b < 0.0 or
                        upper + max(f.gap_rounding(a, fa), f.gap_rounding(b, fb)) < 0.0):
        return None
    if depth >= _MAX_DEPTH or b - a <= 4.0 * math.ulp(b):
        return _bracket(f, a, b, 0, 1.0, ga, gb) if ga < 0.0 <= gb else None
    mid = 0.5 * (a + b)
    fm = f(mid)
    found = _search(f, a, mid, fa, fm, depth + 1)
    if found is not None:
        return found
    return _search(f, mid, b, fm, fb, depth + 1)


def next_impact(p: OscillatorParams, tau0: float, dx0: float, dv0: float, horizon: float,
                max_step: float | None = None):
    """Time of the first impact in (0, horizon], or None.

    Parameters
    ----------
    p : OscillatorParams
    tau0 : float
        Forcing phase at the start.
    dx0, dv0 : float
        Deviation from x_p at the start (see :mod:`grazing_control.oscillator.flow`). The start
        may be on the wall (g = 0); then a root at h = 0 is reported only if v > 0.
    horizon : float
        Length of the window, > 0.
    max_step : float, optional
        Initial subdivision of the window (default T / 8).

    Returns
    -------
    float or None
        Time since the start of the first impact.
    """
    check_state(dx0, dv0, p.zeta, "the start state")
    check_times(tau0, "horizon", horizon)
    return _next_impact(p, tau0, dx0, dv0, horizon, max_step)


def _next_impact(p, tau0, dx0, dv0, horizon, max_step=None):
    """:func:`next_impact` without the checks of its inputs (advance has made them)."""
    if horizon <= 0.0:
        return None
    # whole-window exclusion: g <= |z_x| - Delta d <= |C| - Delta d (|C| rounded up)
    if amplitude_bound(p.zeta, dx0, dv0) * (1.0 + 4.0 * _EPS) < p.delta_d:
        return None
    f = _Eval(p, tau0, dx0, dv0)
    step = max_step or p.period / 8.0
    n = max(1, int(math.ceil(horizon / step)))
    return _scan_window(f, horizon, n, lambda fa: _wall_rounding(p, tau0, dx0, dv0)[0], "x")


def _scan_window(f, horizon: float, count: int, start_rounding, coordinate: str):
    """The first root of the gap in (0, horizon], or None: the window cut into ``count``
    pieces, each searched by :func:`_search` unless its phases are far from the wall.

    ``f`` is an evaluator with the interface of :class:`_Eval` (the n-DOF one is
    oscillator/ndof/impact.py's), ``start_rounding(f(0))`` the gap's rounding at the
    start, ``coordinate`` the name of the wall coordinate in the error message.
    """
    a = 0.0
    fa = f(0.0)
    # on the wall up to rounding: a start above it, or below it while leaving (v < 0),
    # whose flight must not find its own start as a root (docs/theory.md, "A start on
    # the wall")
    if (fa[0] > 0.0 or fa[0] < 0.0 and fa[1] < 0.0) and abs(fa[0]) <= start_rounding(fa):
        fa = (0.0,) + fa[1:]
    if fa[0] > 0.0:
        raise InitialStateError(
            f"state beyond the wall: {coordinate} - d = {fa[0]:.3e} > 0 (valid: {coordinate} <= d)"
        )
    if fa[0] == 0.0 and fa[1] > 0.0:
        return 0.0  # on the wall, moving into it
    w = _danger_halfwidth(f, horizon)
    for k in range(1, count + 1):
        b = horizon if k == count else k * (horizon / count)
        if k > 1 and w is not None and _far_from_wall(f.psi(a), f.psi(b), w):
            a, fa = b, None  # g < 0 on all of [a, b]: the search would find nothing
            continue
        if fa is None:
            fa = f(a)
        fb = f(b)
        r = _search(f, a, b, fa, fb, 0)
        if r is not None:
            return r
        a, fa = b, fb
    return None


def _danger_halfwidth(f: _Eval, horizon: float):
    """Half-width w such that the computed g < 0 at every h <= horizon whose phase psi is
    farther than w from every multiple of 2 pi; None when no phase is that far.

    g = z_x - Delta d - 2 a sin^2(psi / 2) with |z_x| <= |C| e^{-zeta h} <= |C|, and the
    computed g is within m0 + m1 h of the exact one, so the computed g < 0 wherever
    2 a sin^2(psi / 2) > |C| (1 + 4 eps) - Delta d + m0 + m1 horizon. sin^2(psi / 2) grows
    with the distance of psi to 2 pi Z, so that holds beyond w = 2 asin(sqrt(s)), s the
    right-hand side over 2a; w carries a margin of 1e-9 for the rounding of asin, sqrt
    and of the phases (docs/theory.md, "Phases far from the wall").
    """
    s = (f.cabs * (1.0 + 4.0 * _EPS) - f.dd + f.m0 + f.m1 * horizon) / (2.0 * f.amp)
    if s >= 1.0:
        return None
    return 2.0 * math.asin(math.sqrt(max(s, 0.0))) + 1e-9


def _far_from_wall(psi_a: float, psi_b: float, w: float) -> bool:
    """No phase of [psi_a, psi_b] lies within w of a multiple of 2 pi."""
    k = math.ceil((psi_a - w) / TWO_PI)  # the first multiple whose zone ends after psi_a
    return TWO_PI * k - w > psi_b


def saltation_matrix(p: OscillatorParams, phase: float, v_minus: float):
    """Saltation matrix of the impact x = d, v+ = -r v- (spec section 5).

    S = [[-r, 0], [(1 + r)(cos tau_i - d) / v-, -r]]: the Jacobian of the impact
    law corrected for the jump of the vector field, so that perturbations map as
    dz+ = S dz- across the impact. Returns (S11, S12, S21, S22).
    """
    r = p.r
    return (-r, 0.0, (1.0 + r) * (math.cos(phase) - p.d) / v_minus, -r)


def _release_time(p: OscillatorParams, tau: float, horizon: float):
    """Time after phase tau until cos(tau) - d falls below 0 (end of sticking)."""
    d = p.d
    if d >= 1.0:
        return 0.0
    if d <= -1.0:
        return math.inf
    alpha = math.acos(d)  # contact force cos tau - d > 0 for tau in (-alpha, alpha)
    t = tau % TWO_PI
    rel = alpha - t if t < alpha else alpha + TWO_PI - t
    if math.cos(tau) - d <= 0.0 and rel > 1e-14:
        return 0.0
    return rel / p.omega


def _resting_on_wall(p: OscillatorParams, tau: float, dx: float, dv: float) -> bool:
    """x = d and v = 0 up to the rounding of the deviation coordinates and of the phase.

    A mass stuck on the wall across a Pi2 sample comes back at phase tau2 with the
    state of the wall at phase (tau2 + omega T) mod 2 pi, a few ulps of 2 pi away: the
    tolerances include that phase rounding, so the sticking carries over the sample.
    """
    eg, ev = _wall_rounding(p, tau, dx, dv)
    s = math.sin(0.5 * (tau - p.lag))
    g = dx - p.delta_d - 2.0 * p.amplitude * s * s
    vp = -p.amplitude * p.omega * math.sin(tau - p.lag)
    return abs(g) <= eg and abs(vp + dv) <= ev


def _release_skip(p: OscillatorParams, tau: float, dx: float) -> float:
    """Time after leaving the wall at rest during which the gap is below its rounding.

    From x = d, v = 0 the gap is g ~ F h^2 / 2 + F' h^3 / 6 with F = cos tau - d <= 0
    and F' = -omega sin tau; no impact is possible while |g| < eps, the gap's rounding.
    """
    eps = 8.0 * math.ulp(abs(dx) + abs(p.delta_d) + 2.0 * p.amplitude)
    force = abs(math.cos(tau) - p.d)
    jerk = abs(p.omega * math.sin(tau))
    times = [math.sqrt(2.0 * eps / force)] if force > 0.0 else []
    if jerk > 0.0:
        times.append((6.0 * eps / jerk) ** (1.0 / 3.0))
    return min(times) if times else 0.0


def _on_wall_at_rest(p: OscillatorParams, tau: float):
    """Deviation of (x, v) = (d, 0) at phase tau."""
    xp_minus_d = -2.0 * p.amplitude * math.sin(0.5 * (tau - p.lag)) ** 2 - p.delta_d
    return -xp_minus_d, p.amplitude * p.omega * math.sin(tau - p.lag)


def advance(p: OscillatorParams, tau0: float, dx: float, dv: float, duration: float, *,
            monodromy: bool = False, max_impacts: int = 10000,
            chatter_time: float | None = None) -> Segment:
    """Flow with impacts for a fixed time: the exact event-driven trajectory segment.

    Parameters
    ----------
    p : OscillatorParams
    tau0 : float
        Forcing phase at the start.
    dx, dv : float
        Deviation from x_p at the start (x <= d required).
    duration : float
        Time to advance, >= 0.
    monodromy : bool
        Also return the Jacobian of the end state with respect to the start state:
        the product of Phi over each smooth segment and S at each impact in time
        order (spec section 5). Through a sticking phase it is 0 (perturbations die).
    max_impacts : int
        Cap on contacts (impacts and tangencies) in this call; exceeding it raises
        :class:`ImpactCapError`.
    chatter_time : float, optional
        Accumulation-time threshold below which a chattering sequence is summed and
        the mass sticks (default 1e-6 T; the error of the summation is O(t_inf^2)).
        The sequence is also summed once the next bounce height v+^2 / (2 F) is within
        1e3 ulps of the gap's rounding, where single bounces cannot be resolved.

    Returns
    -------
    Segment
        (dx, dv) at the end, the list of :class:`Impact`, and the monodromy
        (M11, M12, M21, M22) or None.

    Notes
    -----
    Contacts below rounding (docs/theory.md, "Tangency below rounding"): a contact
    whose approach velocity is within the velocity's rounding of 0 is a contact at
    rest. With the wall force F = cos tau - d <= 0 it is a tangency, not an impact:
    v- = 0 leaves the state unchanged, nothing is reported and the flow goes on. With
    F > 0 the mass sticks, reported as a sticking :class:`Impact` with v- = v+ = 0.
    Every other reported impact has v- > 0.

    Raises
    ------
    NonFiniteStateError
        The start state, tau0 or duration is not finite, or the state is absurdly
        large (see :func:`check_state`).
    """
    check_state(dx, dv, p.zeta, "the start state")
    check_times(tau0, "duration", duration)
    zeta, r, omega = p.zeta, p.r, p.omega
    aw, lag_abs, wd = p.amplitude * omega, abs(p.lag), p.omega_d
    chatter = chatter_time if chatter_time is not None else 1e-6 * p.period
    impacts = []
    mono = (1.0, 0.0, 0.0, 1.0) if monodromy else None
    t = 0.0
    tau = tau0
    contacts = 0
    # at rest on the wall (to rounding): a contact at rest now, handled in the loop
    h = 0.0 if _resting_on_wall(p, tau, dx, dv) else \
        (_next_impact(p, tau, dx, dv, duration) if duration > 0.0 else None)
    while True:
        remaining = duration - t
        if h is None or remaining <= 0.0:
            if remaining > 0.0:
                f11, f12, f21, f22 = transition_matrix(zeta, remaining)
                dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
                if monodromy:
                    mono = matmul2((f11, f12, f21, f22), mono)
            return Segment(dx, dv, impacts, mono)
        if contacts >= max_impacts:
            raise ImpactCapError(
                f"more than max_impacts={max_impacts} impacts in {duration:.6g} time units "
                f"at phase {tau % TWO_PI:.6f}: the motion is not resolvable at this cap"
            )
        contacts += 1
        # velocity rounding after the flow: terms of size |C| <= |dx| + |dv + zeta dx| / omega_d
        flow_err = 8.0 * _EPS * (abs(dx) + abs(dv + zeta * dx) / wd) * (2.0 + h)
        f11, f12, f21, f22 = transition_matrix(zeta, h)
        dx, dv = f11 * dx + f12 * dv, f21 * dx + f22 * dv
        if monodromy:
            mono = matmul2((f11, f12, f21, f22), mono)
        t += h
        tau = (tau + omega * h) % TWO_PI
        wall_dx, wall_dv = _on_wall_at_rest(p, tau)  # (d, 0) at this phase
        vp = -wall_dv
        v_minus = vp + dv
        force = math.cos(tau) - p.d
        # the velocity's rounding (_wall_rounding) plus that of the flow
        v_tol = 8.0 * _EPS * (abs(vp) + abs(dv) + aw * (tau + lag_abs + TWO_PI + 1.0)) + flow_err
        dx = wall_dx  # on the wall exactly
        if v_minus <= v_tol:  # contact at rest, below the velocity's rounding
            dv = wall_dv
            if force <= 0.0:  # tangency: v- = 0 changes nothing; leave the wall
                t, tau, dx, dv, mono = _leave_wall(p, tau0, t, duration, dx, dv, mono)
                h = _next_impact(p, tau, dx, dv, duration - t) if t < duration else None
                continue
            v_minus, t_inf, height = 0.0, 0.0, 0.0  # pushed into the wall: sticks
        else:
            t_inf = max(0.0, 2.0 * r * v_minus / ((1.0 - r) * force)) if force > 0.0 else math.inf
            # the next bounce rises v+^2 / (2 F): below ~1e3 ulps of the gap, not resolvable
            height = (r * v_minus) ** 2 / (2.0 * force) if force > 0.0 else math.inf
        v_plus = -r * v_minus if v_minus > 0.0 else 0.0  # at rest: +0.0, not -0.0
        dv = v_plus - vp
        if t_inf < chatter or height < 1e3 * math.ulp(abs(dx) + abs(p.delta_d) + p.amplitude):
            # chattering: sum the geometric sequence and stick (velocity -> 0)
            t_hit, tau_hit = t, tau
            t += t_inf
            tau = (tau + omega * t_inf) % TWO_PI
            stick = _release_time(p, tau, duration - t)
            release = t + stick if t + stick <= duration else math.inf
            impacts.append(Impact(t_hit, tau_hit, v_minus, v_plus, True, release))
            t = min(duration, t + stick)
            tau = (tau0 + omega * t) % TWO_PI
            dx, dv = _on_wall_at_rest(p, tau)
            if monodromy:
                mono = (0.0, 0.0, 0.0, 0.0)
            if t < duration:
                t, tau, dx, dv, mono = _leave_wall(p, tau0, t, duration, dx, dv, mono)
            h = _next_impact(p, tau, dx, dv, duration - t) if t < duration else None
            continue
        impacts.append(Impact(t, tau, v_minus, v_plus, False))
        if monodromy:
            mono = matmul2(saltation_matrix(p, tau, v_minus), mono)
        h = _next_impact(p, tau, dx, dv, duration - t) if t < duration else None


def _leave_wall(p: OscillatorParams, tau0: float, t: float, duration: float, dx: float,
                dv: float, mono):
    """Leave the wall from rest at time t: flow, without searching, while the gap is
    below its rounding (g ~ F h^2 / 2 + F' h^3 / 6, no impact is possible there)."""
    skip = min(duration - t, _release_skip(p, (tau0 + p.omega * t) % TWO_PI, dx))
    f = transition_matrix(p.zeta, skip)
    dx, dv = f[0] * dx + f[1] * dv, f[2] * dx + f[3] * dv
    if mono is not None:
        mono = matmul2(f, mono)
    t += skip
    return t, (tau0 + p.omega * t) % TWO_PI, dx, dv, mono

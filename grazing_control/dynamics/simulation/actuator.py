"""A first-order actuator with latency between the commanded pulse and the force, exactly
(issue 29 section 4; docs/theory_pulse.md sections 5-8).

The force on the mass f(t) follows the commanded force u(t) through a lag of time
constant tau_a (bandwidth 1 / tau_a) after a pure latency L:

    tau_a f' = u(t - L) - f,

u = F on the commanded pulse [s, s + w] and 0 elsewhere. On each piece where u is
constant, f(t) = F_inf + C exp(-(t - t0) / tau_a), and the linear oscillator under
such a force has the particular solution

    x_f(t) = F_inf + K exp(-(t - t0) / tau_a),    K = C tau_a^2 / (tau_a^2 - 2 zeta tau_a + 1)

(the denominator is > 0 for zeta < 1), so the deviation from x_p + x_f obeys the free
flow z'(t) = Phi(t - t0) z'(t0) again (the constant-force trick of
:mod:`grazing_control.dynamics.simulation.actuation`, with a moving shift). The gap to the wall,

    x - d = z'_x(t) + x_f(t) - Delta d - 2 a sin^2(psi / 2),

is searched for its first zero with a certified bound on its second derivative
(:func:`_first_impact`), and the impact law x = d, v+ = -r v- restarts the piece. The
force decays into the next period: the period map's state is (dx, dv, f) at the
section, f the actuator's force there (:func:`actuated_step`).

tau_a = 0 and L = 0 is the ideal pulse of :func:`grazing_control.dynamics.simulation.actuation.pulse_step`;
the force's impulse is F w whatever tau_a (the lag has unit DC gain) and its centre of
mass is shifted by L + tau_a, so to first order in tau_a the actuator is the ideal pulse
delayed by L + tau_a (:func:`equivalent_delay`; the O(tau_a) and O(tau_a^2) orders are
measured in tests/test_actuator.py), and :func:`actuated_c1` is the exact design for the
force profile (N_g,12 = 0 with the kick direction replaced by the profile's). :func:`actuated_orbit` is the closed loop's 1/1
orbit with its 3x3 multipliers (the margin charted against the bandwidth by
benchmarks/chart_actuator.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import Impact
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.actuation import (OrbitMultipliers, newton_fixed_point, pulse_force, pulse_start,
                        pulse_step)
from grazing_control.dynamics.estimation.motion import phi_rows

__all__ = ["Actuator", "IDEAL_ACTUATOR", "actuated_step", "equivalent_delay", "actuated_c1",
           "ActuatedOrbit", "actuated_orbit", "bandwidth_actuator", "LagFlow",
           "LagPiece", "lag_flow", "lag_states", "actuated_design",
           "actuated_orbit_for", "command_period"]

TWO_PI = 2.0 * math.pi
#: Below this impact velocity the motion chatters: not resolved here (ValueError).
MIN_IMPACT_VELOCITY = 1e-9


@dataclass(frozen=True)
class Actuator:
    """A first-order actuator: ``time_constant`` tau_a >= 0 (0: the force follows the
    command at once) and ``latency`` L >= 0, both in model time units."""

    time_constant: float = 0.0
    latency: float = 0.0

    def __post_init__(self):
        for name in ("time_constant", "latency"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ParameterError(f"actuator_{name}={value!r} is invalid: valid range is a "
                                     f"finite actuator_{name} >= 0")
        if not self.ideal:
            # the lag's first impact ends in scipy's brentq (_first_impact): loaded with
            # the actuator, at a node's start, not at the scene's first impact (a
            # realtime simulator or controller imported scipy.optimize in mid-scene)
            import scipy.optimize  # noqa: F401

    @property
    def ideal(self) -> bool:
        return self.time_constant == 0.0 and self.latency == 0.0


#: The ideal actuator of the pulse scenes.
IDEAL_ACTUATOR = Actuator()


def bandwidth_actuator(p: OscillatorParams, ratio: float, latency: float = 0.0) -> Actuator:
    """The actuator whose bandwidth (1 / tau_a, rad per time unit) is ``ratio`` times
    the forcing frequency omega: tau_a = 1 / (ratio omega)."""
    if not (math.isfinite(ratio) and ratio > 0.0):
        raise ParameterError(f"bandwidth ratio={ratio!r} is invalid: valid range is > 0")
    return Actuator(1.0 / (ratio * p.omega), latency)


def equivalent_delay(actuator: Actuator) -> float:
    """The shift of the force's centre of mass against the command: L + tau_a (the first
    moment of the lag's impulse response exp(-t / tau_a) / tau_a). A design for the
    delay delta + L + tau_a with the command centred at delta matches the actuator to
    first order in tau_a (docs/theory_pulse.md section 6)."""
    return actuator.latency + actuator.time_constant


def actuated_c1(p: OscillatorParams, c2: float, actuator: Actuator, start: float,
                width: float) -> float:
    """c1 that makes N_g,12 = 0 for a pulse commanded on [start, start + width] after Pi2
    through ``actuator`` (docs/theory_pulse.md section 7, (P1)): the delayed kick's
    condition (D5), N_g,12 = Phi12(T) + h (c1 Phi12(s) + c2 Phi22(s)) = 0, with the kick's
    h = Phi12(T - s - delta) replaced by the force profile's

        h_f = int_0^{T - s} Phi12(T - s - t) f(t) dt,     int f = 1,

    f the actuator's response to the unit-impulse command (quadrature, 1e-12 relative).
    The force left after the grazing phase T - s (a share e^{-(T - s - start - L - w) /
    tau_a} of it) acts after the impact and is not in N_g: :func:`actuated_orbit`
    measures what it costs. With the ideal actuator this is the exact design for the
    pulse itself (the O(w^2) of docs/theory_pulse.md section 2 removed).

    Raises ParameterError when the command does not end before the grazing phase or
    h_f = 0 (no c1 exists).
    """
    from scipy.integrate import quad

    from grazing_control.dynamics.design.gains import max_design_delay
    from grazing_control.oscillator.flow import transition_matrix

    top = max_design_delay(p)
    tau, a = actuator.time_constant, start + actuator.latency
    b = a + width
    if not (0.0 <= a and width > 0.0 and b < top):
        raise ParameterError(f"start={start!r} is invalid with width={width!r} and latency="
                             f"{actuator.latency!r}: valid range is 0 <= start and start + "
                             f"latency + width < T - s = {top!r} (before the grazing phase)")
    wd = p.omega_d

    def phi12(u):
        return math.exp(-p.zeta * u) * math.sin(wd * u) / wd

    def force(t):                      # the response to a command of impulse 1
        if tau == 0.0:
            return 1.0 / width if t < b else 0.0
        if t < b:
            return -math.expm1(-(t - a) / tau) / width
        return -math.expm1(-width / tau) * math.exp(-(t - b) / tau) / width

    h = sum(quad(lambda t: phi12(top - t) * force(t), lo, hi, epsabs=0.0, epsrel=1e-12,
                 limit=200)[0] for lo, hi in ((a, b), (b, top)) if hi > lo)
    s = p.pi2_offset / p.omega
    _p11, p12, _p21, p22 = transition_matrix(p.zeta, s)
    n12 = transition_matrix(p.zeta, p.period)[1]
    if h == 0.0 or p12 == 0.0:
        raise ParameterError(f"start={start!r}: the force profile's h_f = {h!r}, no gain c1 "
                             "makes N_g,12 = 0")
    return -(n12 / h + c2 * p22) / p12


def _gap_parts(p, tau0, zp, f_inf, k, tau_a):
    """The gap g(h) = z'_x(h) + F_inf + K e^{-h/tau_a} - Delta d - 2a sin^2(psi/2) and
    its derivative, h from the piece's start, as vectorised closures."""
    wd = p.omega_d
    zeta = p.zeta
    # z'_x(h) = e^{-zeta h} (alpha cos wd h + beta sin wd h)
    alpha = zp[0]
    beta = (zp[1] + zeta * zp[0]) / wd
    a, om, lag = p.amplitude, p.omega, p.lag

    def g(h):
        e = math.exp(-zeta * h)
        c, s = math.cos(wd * h), math.sin(wd * h)
        psi = tau0 + om * h - lag
        force = k * math.exp(-h / tau_a) if tau_a > 0.0 else 0.0
        return e * (alpha * c + beta * s) + f_inf + force - p.delta_d - a * (1.0 - math.cos(psi))

    amp = math.hypot(alpha, beta)
    return g, amp


def _first_impact(p, tau0, zp, f_inf, k, tau_a, duration):
    """The first time h in (0, duration] where the gap reaches 0 from below, or None.

    Certified: on a cell [u, v] the gap is at most max(g(u), g(v)) + M (v - u)^2 / 8
    with M >= |g''| = R (1 + zeta)^2 + |K| / tau_a^2 e^{-u/tau_a} + a omega^2 (R the
    amplitude of the free part); a cell whose bound is < 0 holds no impact, else it is
    halved, down to 1e-12 where the root is bracketed by brentq (xtol 1e-16)."""
    g, amp = _gap_parts(p, tau0, zp, f_inf, k, tau_a)
    m_free = amp * (1.0 + p.zeta) ** 2 + p.amplitude * p.omega ** 2

    def m_bound(u):
        return m_free + (abs(k) * (1.0 / tau_a) ** 2 * math.exp(-u / tau_a) if tau_a > 0.0 else 0.0)

    cells = max(1, math.ceil(duration / 0.05))
    edges = [float(e) for e in np.linspace(0.0, duration, cells + 1)]
    vals = [g(e) for e in edges]
    # depth first, earliest cell on top: the first cell that keeps a crossing is the first
    stack = [(edges[i], edges[i + 1], vals[i], vals[i + 1]) for i in range(cells - 1, -1, -1)]
    while stack:
        u, v, gu, gv = stack.pop()
        if v - u <= 1e-12:
            if gu < 0.0 <= gv:
                from scipy.optimize import brentq   # here: the nodes import no solver

                return brentq(g, u, v, xtol=1e-16)
            continue                   # a tangency below the resolution, or leaving the wall
        if max(gu, gv) + m_bound(u) * (v - u) ** 2 / 8.0 < 0.0:
            continue                   # certainly below the wall throughout
        mid = 0.5 * (u + v)
        gm = g(mid)
        stack.append((mid, v, gm, gv))
        stack.append((u, mid, gu, gm))
    return None


class LagPiece(NamedTuple):
    """One stretch of :func:`lag_flow` between impacts: from ``h0`` (since the flow's
    start) at forcing phase ``tau``, the shifted deviation ``zp`` = z - (x_f, v_f) and
    the particular solution's amplitude ``k`` there (module docstring)."""

    h0: float
    tau: float
    zp: tuple
    k: float


class LagFlow(NamedTuple):
    """The exact motion under the force F_inf + C e^{-h / tau_a} for a duration: the
    deviation (dx, dv) and the force at the end, the ``impacts`` (``dt`` since the
    start), and the ``pieces`` between them (:func:`lag_states` evaluates them)."""

    dx: float
    dv: float
    force: float
    impacts: tuple
    pieces: tuple
    f_inf: float
    tau_a: float


def lag_flow(p: OscillatorParams, tau0: float, dx: float, dv: float, duration: float,
             f_inf: float, c: float, tau_a: float) -> LagFlow:
    """The exact motion for ``duration`` from deviation (dx, dv) at phase tau0 under the
    force F_inf + C e^{-h / tau_a} (module docstring; tau_a = 0 only with C = 0, a
    constant force): the free flow of the shifted deviation, impacts searched by
    :func:`_first_impact` and restarted by the impact law, C scaled by e^{-h / tau_a}
    at each. ValueError on a chattering or sticking motion."""
    if tau_a == 0.0 and c != 0.0:
        raise ValueError("a force transient needs tau_a > 0")
    z = np.array((dx, dv), dtype=float)
    h_done = 0.0
    impacts, pieces = [], []
    while True:
        # K = C tau_a^2 / (tau_a^2 - 2 zeta tau_a + 1), written to stay finite for any tau_a
        kk = c / (1.0 + (1.0 / tau_a) * (1.0 / tau_a - 2.0 * p.zeta)) if tau_a > 0.0 else 0.0
        # shifted state z' = z - (x_f, v_f) at the piece's start
        zp = z - np.array([f_inf + kk, -kk / tau_a if tau_a > 0.0 else 0.0])
        pieces.append(LagPiece(h_done, tau0, (float(zp[0]), float(zp[1])), kk))
        rest = duration - h_done
        hit = _first_impact(p, tau0, zp, f_inf, kk, tau_a, rest)
        if hit is None:
            e = math.exp(-rest / tau_a) if tau_a > 0.0 else 0.0
            zf = phi_rows(p.zeta, np.array([rest]))[0] @ zp \
                + np.array([f_inf + kk * e, -kk * e / tau_a if tau_a > 0.0 else 0.0])
            return LagFlow(float(zf[0]), float(zf[1]), f_inf + c * e, tuple(impacts),
                           tuple(pieces), f_inf, tau_a)
        e = math.exp(-hit / tau_a) if tau_a > 0.0 else 0.0
        zh = phi_rows(p.zeta, np.array([hit]))[0] @ zp \
            + np.array([f_inf + kk * e, -kk * e / tau_a if tau_a > 0.0 else 0.0])
        phase = (tau0 + p.omega * hit) % TWO_PI
        psi = phase - p.lag
        v_minus = zh[1] - p.amplitude * p.omega * math.sin(psi)
        if v_minus < MIN_IMPACT_VELOCITY:
            raise ValueError(f"impact velocity {v_minus:.3g} under the actuator's force: a "
                             "chattering or sticking motion, not resolved by lag_flow")
        v_plus = -p.r * v_minus
        impacts.append(Impact(h_done + hit, phase, v_minus, v_plus))
        z = np.array([p.d - p.amplitude * math.cos(psi),
                      v_plus + p.amplitude * p.omega * math.sin(psi)])
        c = c * e
        h_done += hit
        tau0 = phase


def lag_states(p: OscillatorParams, flow: LagFlow, times) -> np.ndarray:
    """Dense output of :func:`lag_flow`: physical (x, v) at ``times`` (since the flow's
    start, sorted), the closed form of the piece each falls in (so, like
    :func:`grazing_control.dynamics.simulation.simulate.states_between`, never altering the
    trajectory)."""
    times = np.asarray(times, dtype=float)
    out = np.empty((times.size, 2))
    starts = np.array([pc.h0 for pc in flow.pieces])
    which = np.searchsorted(starts, times, side="right") - 1
    for i, pc in enumerate(flow.pieces):
        mask = which == i
        if not mask.any():
            continue
        hh = times[mask] - pc.h0
        z = phi_rows(p.zeta, hh) @ np.asarray(pc.zp)
        e = np.exp(-hh / flow.tau_a) if flow.tau_a > 0.0 else np.zeros_like(hh)
        psi = pc.tau + p.omega * hh - p.lag
        a = p.amplitude
        out[mask, 0] = a * np.cos(psi) + z[:, 0] + flow.f_inf + pc.k * e
        out[mask, 1] = -a * p.omega * np.sin(psi) + z[:, 1] + (
            -pc.k * e / flow.tau_a if flow.tau_a > 0.0 else 0.0)
    return out


def _piece(p: OscillatorParams, tau0: float, z, duration: float, f_inf: float, c: float,
           tau_a: float, t_offset: float, impacts: list):
    """:func:`lag_flow` with its impacts appended to ``impacts`` (times + t_offset).
    Returns the deviation at the end."""
    flow = lag_flow(p, tau0, float(z[0]), float(z[1]), duration, f_inf, c, tau_a)
    impacts.extend(i._replace(dt=i.dt + t_offset) for i in flow.impacts)
    return np.array([flow.dx, flow.dv])


def command_period(p: OscillatorParams, dx: float, dv: float, force: float,
                   dv_correction: float, start: float, width: float, actuator: Actuator,
                   force_limit: float, flow, on_piece=None):
    """One period from the Pi2 deviation (dx, dv), the actuator's force ``force`` there,
    with the correction commanded at ``start`` through ``actuator``, piece by piece: a
    pulse F = Delta v / w on [start, start + w] (w = 0: an impulse Delta v, adding
    Delta v / tau_a to the force, or with tau_a = 0 a velocity jump) reaching the lag L
    later; on each piece between the switches the force is F_inf + C e^{-h / tau_a}
    and the motion ``flow(tau, dx, dv, duration, F_inf, C, tau_a)``'s (:func:`lag_flow`
    for the wall, a compliant stop's ``lag_flow``; it returns dx, dv, force, impacts).
    ``on_piece(h, end, tau, dx, dv, u, c, result)`` sees each piece (sim_node's engine
    publishes its events). Returns (dx, dv, force at the next section, impacts: times
    from the sample)."""
    tau_a = actuator.time_constant
    on = start + actuator.latency
    if width > 0.0:
        switches = ((on, pulse_force(dv_correction, width, force_limit), 0.0),
                    (on + width, 0.0, 0.0))
    else:
        switches = ((on, 0.0, dv_correction),)
    f, u, h, impacts = force, 0.0, 0.0, []
    for end, u_next, impulse in switches + ((p.period, 0.0, 0.0),):
        if end > h:
            tau = (p.tau2 + p.omega * h) % TWO_PI
            c = f - u if tau_a > 0.0 else 0.0
            piece = flow(tau, dx, dv, end - h, u, c, tau_a)
            if on_piece is not None:
                on_piece(h, end, tau, dx, dv, u, c, piece)
            impacts += [i._replace(dt=i.dt + h) for i in piece.impacts]
            dx, dv, f = piece.dx, piece.dv, piece.force
        if impulse:                 # an impulse command: through the lag, or a jump
            if tau_a > 0.0:
                f += impulse / tau_a
            else:
                dv += impulse
        h, u = max(h, end), u_next
        f = f if tau_a > 0.0 else u
    return dx, dv, f, impacts


def actuated_step(p: OscillatorParams, dx: float, dv: float, force: float,
                  dv_correction: float = 0.0, *, start: float = 0.0, width: float = 0.0,
                  actuator: Actuator = IDEAL_ACTUATOR, force_limit: float = math.inf):
    """One forcing period from a Pi2 sample (deviation (dx, dv), actuator force
    ``force`` there) with the correction commanded as a pulse on [start, start + width]
    through ``actuator`` (module docstring). Returns (dx, dv, force at the next section,
    impacts: times from the sample).

    The ideal actuator is :func:`grazing_control.dynamics.simulation.actuation.pulse_step` (then
    ``force`` must be 0). The command reaches the mass L later, and must end within the
    period: start + L + width < T.

    Raises
    ------
    ParameterError
        start, width or the latency out of range (named with the valid range), or a
        force left over from an ideal actuator.
    ValueError
        A chattering or sticking motion during the period.
    """
    lat, tau_a = actuator.latency, actuator.time_constant
    if not (math.isfinite(width) and width > 0.0 or width == 0.0 and actuator.ideal):
        raise ParameterError(f"width={width!r} is invalid: valid range is a finite width > 0 "
                             "(0 only with the ideal actuator)")
    if not (math.isfinite(start) and start >= 0.0 and start + lat + width < p.period):
        raise ParameterError(f"start={start!r} is invalid with width={width!r} and latency="
                             f"{lat!r}: valid range is 0 <= start and start + latency + width "
                             f"< T = {p.period!r}")
    if tau_a == 0.0:
        if force != 0.0:
            raise ParameterError(f"force={force!r} is invalid: an actuator without lag leaves "
                                 "no force at the section, valid value is 0")
        seg = pulse_step(p, dx, dv, dv_correction, start=start + lat, width=width,
                         force_limit=force_limit)
        return seg.dx, seg.dv, 0.0, list(seg.impacts)
    f_cmd = pulse_force(dv_correction, width, force_limit)
    on, off = start + lat, start + lat + width
    impacts = []
    z = (dx, dv)
    f = force
    t = 0.0
    for end, u in ((on, 0.0), (off, f_cmd), (p.period, 0.0)):
        duration = end - t
        if duration > 0.0:
            tau0 = (p.tau2 + p.omega * t) % TWO_PI
            z = _piece(p, tau0, z, duration, u, f - u, tau_a, t, impacts)
            f = u + (f - u) * math.exp(-duration / tau_a)
        t = end
    return float(z[0]), float(z[1]), float(f), impacts


@dataclass(frozen=True)
class ActuatedOrbit(OrbitMultipliers):
    """The 1/1 orbit of the loop closed through an actuator (:func:`actuated_orbit`):
    ``state`` (dx, dv, f) on Pi2 before the correction, its ``correction``, ``impacts``
    of one period, the 3x3 ``monodromy`` (central differences of the exact map) and the
    ``residual`` |P(z) - z| left; ``input``: d P / d(Delta v) at the orbit with the
    state held (how an error of the commanded correction enters the next section)."""

    state: tuple
    correction: float
    impacts: tuple
    monodromy: np.ndarray = field(repr=False)
    residual: float
    input: np.ndarray = field(repr=False, default=None)
    reference: tuple = (0.0, 0.0)

    @property
    def pi2_deviation(self) -> tuple:
        """(x - x**, v - v**) on Pi2 (the state less the force)."""
        return self.state[0], self.state[1]

    @property
    def pi2(self) -> tuple:
        """(x, v) on Pi2: X** (``reference``) plus the deviation."""
        return self.reference[0] + self.state[0], self.reference[1] + self.state[1]


    @property
    def spectral_radius(self) -> float:
        """The largest multiplier's modulus: the loop's margin is 1 minus it."""
        return float(np.max(np.abs(np.linalg.eigvals(self.monodromy))))

    def noise_covariance(self, gains: Gains, measurement=None) -> np.ndarray:
        """The stationary covariance of (dx, dv, f) per unit measurement variance: the
        Lyapunov equation of grazing_control.dynamics.design.noise with this loop's J and input
        direction, Sigma = J Sigma J^T + b b^T (k^T R k) (R: the estimate's error
        covariance per unit sigma^2, default I). ValueError when not stable."""
        from scipy.linalg import solve_discrete_lyapunov

        if not self.spectral_radius < 1.0:
            raise ValueError(f"the actuated loop is not stable (largest multiplier "
                             f"{self.spectral_radius:.6g}): no stationary spread")
        r = np.eye(2) if measurement is None else np.asarray(measurement, dtype=float)
        k = np.array([gains.c1, gains.c2])
        return solve_discrete_lyapunov(self.monodromy,
                                       float(k @ r @ k) * np.outer(self.input, self.input))


def actuated_orbit(p: OscillatorParams, gains: Gains, width: float, actuator: Actuator, *,
                   command_delay: float | None = None, guess=None,
                   max_iter: int = 30) -> ActuatedOrbit:
    """The controlled 1/1 orbit when Eq. 28's correction (``gains``) is commanded as a
    pulse of ``width`` centred ``command_delay`` after the sample (default
    ``gains.delay``; :func:`grazing_control.dynamics.simulation.actuation.pulse_start`) through
    ``actuator``: the fixed point of the exact 3-state map (dx, dv, f) by Newton from
    ``guess`` (default the ideal pulse's orbit; a slow actuator moves the orbit far from
    it: continue in the bandwidth, benchmarks/chart_actuator.py), Jacobian by central
    differences (as
    :func:`grazing_control.dynamics.simulation.actuation.pulse_orbit`).

    Raises OrbitNotFound when Newton does not reach the rounding level or the orbit has
    not one impact per period.
    """
    from grazing_control.dynamics.simulation.actuation import pulse_orbit
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    delay = gains.delay if command_delay is None else command_delay
    start = pulse_start(p.period, delay, width)
    if guess is None:
        ideal = pulse_orbit(p, Gains(gains.c1, gains.c2, delay), width)
        z = np.array([*ideal.pi2_deviation, 0.0])
        v_minus = ideal.v_minus
    else:
        z = np.array(guess, dtype=float)
        v_minus = None

    def step(z, extra=0.0):
        dvc = gains.c1 * z[0] + gains.c2 * z[1] + extra
        x, v, f, imps = actuated_step(p, float(z[0]), float(z[1]), float(z[2]), dvc,
                                      start=start, width=width, actuator=actuator)
        return np.array([x, v, f]), imps

    if v_minus is None:
        imps = step(z)[1]
        v_minus = imps[0].v_minus if imps else 1e-2
    h = max(1e-3 * v_minus ** 2, 1e-13)

    z, imps, residual, jacobian = newton_fixed_point(step, z, h, max_iter)
    if residual > 1e-12 or len(imps) != 1:
        raise OrbitNotFound(f"no 1/1 orbit through the actuator (tau_a "
                            f"{actuator.time_constant!r}, latency {actuator.latency!r}): "
                            f"residual {residual:.1e}, {len(imps)} impacts per period")
    b = (step(z, h)[0] - step(z, -h)[0]) / (2.0 * h)
    return ActuatedOrbit(tuple(float(c) for c in z), float(gains.c1 * z[0] + gains.c2 * z[1]),
                         tuple(imps), jacobian(z), residual, b, (p.x_ref, p.v_ref))


def actuated_orbit_for(p: OscillatorParams, gains: Gains, width: float,
                       actuator: Actuator) -> ActuatedOrbit:
    """The loop's orbit through ``actuator`` for any ``gains`` (a scene's, e.g. the ideal
    actuator's design): :func:`actuated_orbit` from the ideal pulse's orbit, or, where
    Newton misses it from there, continued in c1 (8 steps) from the orbit of the exact
    design (P1) with the same c2 (:func:`actuated_design`). Raises OrbitNotFound."""
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    try:
        return actuated_orbit(p, gains, width, actuator)
    except (OrbitNotFound, ValueError, ArithmeticError):
        pass
    exact, orbit, _spread = actuated_design(p, gains.c2, gains.delay, width, actuator)
    if orbit is None:
        raise OrbitNotFound(f"no 1/1 orbit through the actuator (tau_a "
                            f"{actuator.time_constant!r}) for the exact design with c2 "
                            f"{gains.c2!r}, where the continuation in c1 would start")
    for share in np.linspace(0.0, 1.0, 9)[1:]:
        c1 = exact.c1 + float(share) * (gains.c1 - exact.c1)
        orbit = actuated_orbit(p, Gains(c1 if share < 1.0 else gains.c1, gains.c2, gains.delay),
                               width, actuator, guess=orbit.state)
    return orbit


def actuated_design(p: OscillatorParams, c2: float, delay: float, width: float,
                    actuator: Actuator, measurement=None):
    """The design through ``actuator`` (the `grazing design --actuator-bandwidth` route):
    c1 of the exact condition (P1) (:func:`actuated_c1`) for the pulse of ``width``
    centred at ``delay``, and at p.delta_d < 0 the loop's orbit (:func:`actuated_orbit`
    from the ideal pulse's) with its predicted spread: the standard deviations of
    (x, v, f) on Pi2 per unit sigma, :meth:`ActuatedOrbit.noise_covariance` with the
    estimate's covariance ``measurement`` (default I: x and v each measured with sigma).
    The orbit is continued in tau_a from a tenth of it (8 steps). Returns (gains, orbit, spread);
    orbit None where no 1/1 orbit is found, spread None where it is not stable."""
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound

    start = pulse_start(p.period, delay, width)
    gains = Gains(actuated_c1(p, c2, actuator, start, width), c2, delay)
    guess = None
    # continued in tau_a from a tenth of it, each step with its own (P1) gains (a slow
    # actuator moves the orbit far from the ideal pulse's, where Newton would start)
    shares = np.geomspace(0.1, 1.0, 8) if actuator.time_constant > 0.0 else (1.0,)
    for share in shares:
        step = Actuator(actuator.time_constant * float(share), actuator.latency)
        g = gains if share == shares[-1] else Gains(
            actuated_c1(p, c2, step, start, width), c2, delay)
        try:
            orbit = actuated_orbit(p, g, width, step, guess=guess)
        except (OrbitNotFound, ValueError, ArithmeticError):
            return gains, None, None
        guess = orbit.state
    try:
        spread = np.sqrt(np.diag(orbit.noise_covariance(gains, measurement)))
    except ValueError:
        return gains, orbit, None
    return gains, orbit, spread

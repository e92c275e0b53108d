"""A correction delivered as a force pulse of finite width, exactly.

A rig's actuator does not jump the velocity: it pushes with a force F for a time w.
With a constant extra force the equation of motion (spec Eq. 1)

    x'' + 2 zeta x' + x = cos(tau) + F

has the particular solution x_p + F, so the deviation from the *shifted* periodic
motion, z' = (x - x_p - F, v - v_p), obeys the free flow again; and the gap to the
wall is x - d = z'_x - (Delta d - F) - 2 a sin^2(psi / 2). During the pulse the exact
flow with impacts is therefore :func:`grazing_control.oscillator.impact.advance` of
the same oscillator with the clearance Delta d - F, started from z - (F, 0) and
shifted back by (F, 0) at the end (docs/theory_pulse.md): the contact force of the
sticking test becomes cos tau + F - d = cos tau - (d - F) as well, so chattering and
sticking during the pulse stay exact too. No ODE solver, nothing approximated.

The pulse carrying the correction Delta v has F = Delta v / w (impulse F w = Delta v,
the commanded correction); with a force limit |F| <= F_max it is clipped and the impulse
delivered is F_max w sign(Delta v). Width 0 is the instantaneous kick of Eq. 28,
bit for bit (:func:`grazing_control.dynamics.simulation.simulate.period_step`).

Kick versus pulse: a pulse of width w starting at s delivers, to first order in w,
the kick Delta v at its centre s + w/2; the difference is O(w^2) (docs/theory_pulse.md).
A design for an actuation delay delta therefore matches a pulse *centred* delta after
the sample, i.e. starting at delta - w/2 (:func:`pulse_start`).

The loop closed with a pulse has its own 1/1 orbit, O(w^2) away from the kick's
(:func:`pulse_orbit`: the fixed point of the exact pulse map by Newton, docs/theory_pulse.md
section 4); a recording of a pulse scene is compared with it, not with the kick's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from grazing_control.oscillator import kernel as _kernel
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import Segment
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from grazing_control.dynamics.simulation.simulate import period_step

__all__ = ["pulse_force", "pulse_start", "pulse_step", "flow_with_force", "PulseOrbit",
           "OrbitMultipliers", "pulse_orbit", "newton_fixed_point"]

TWO_PI = 2.0 * math.pi


def pulse_force(dv_correction: float, width: float, force_limit: float = math.inf) -> float:
    """The constant force of a pulse of ``width`` > 0 carrying ``dv_correction``:
    Delta v / w, clipped to [-force_limit, force_limit]."""
    force = dv_correction / width
    return max(-force_limit, min(force_limit, force))


def pulse_start(period: float, delay: float, width: float) -> float:
    """When a pulse of ``width`` carrying a correction designed to act ``delay`` after the
    sample starts: centred at the delay (module docstring), kept within [0, T - w);
    ``delay`` itself for the kick (width 0). The simulator's rule
    (:meth:`grazing_control.plant.engine.Engine.actuation_start`)."""
    if width == 0.0:
        return delay
    return min(max(delay - 0.5 * width, 0.0), math.nextafter(period - width, 0.0))


def flow_with_force(p: OscillatorParams, tau0: float, dx: float, dv: float, duration: float,
                    force: float, advance=None) -> Segment:
    """The exact flow with impacts for ``duration`` under an extra constant ``force``.

    (dx, dv) is the deviation from x_p (the usual coordinates); the flow is ``advance``
    of the oscillator with clearance Delta d - F from z - (F, 0), shifted back
    (module docstring). Impact times count from the start.
    """
    advance = advance or _kernel.exact_advance()
    if force == 0.0:
        return advance(p, tau0, dx, dv, duration)
    shifted = p.with_(delta_d=p.delta_d - force)
    seg = advance(shifted, tau0, dx - force, dv, duration)
    return seg._replace(dx=seg.dx + force)


def pulse_step(p: OscillatorParams, dx: float, dv: float, dv_correction: float = 0.0, *,
               start: float = 0.0, width: float = 0.0,
               force_limit: float = math.inf) -> Segment:
    """One forcing period from a Pi2 sample with the correction as a force pulse.

    The pulse acts on [start, start + width] after the sample (0 <= start,
    start + width < T); width 0 is :func:`period_step` with ``delay=start`` (the kick),
    bit for bit. Impact times count from the sample.

    Raises
    ------
    ParameterError
        width < 0, start < 0, start + width >= T, or force_limit <= 0 (each named with
        its valid range).
    """
    if not (math.isfinite(width) and width >= 0.0):
        raise ParameterError(f"width={width!r} is invalid: valid range is a finite width >= 0")
    if not (math.isfinite(start) and start >= 0.0 and start + width < p.period):
        raise ParameterError(f"start={start!r} is invalid with width={width!r}: valid range is "
                             f"0 <= start and start + width < T = {p.period!r}")
    if not force_limit > 0.0:
        raise ParameterError(f"force_limit={force_limit!r} is invalid: valid range is > 0")
    if width == 0.0:
        return period_step(p, dx, dv, dv_correction, delay=start)
    advance = _kernel.exact_advance()
    force = pulse_force(dv_correction, width, force_limit)
    pieces = ((start, 0.0), (width, force), (p.period - start - width, 0.0))
    tau, t, impacts = p.tau2, 0.0, []
    for duration, f in pieces:
        if duration == 0.0:
            continue
        seg = flow_with_force(p, tau, dx, dv, duration, f, advance)
        impacts += [i._replace(dt=i.dt + t, release=i.release + t) for i in seg.impacts]
        dx, dv = seg.dx, seg.dv
        t += duration
        tau = (p.tau2 + p.omega * t) % TWO_PI
    return Segment(dx, dv, impacts, None)


def newton_fixed_point(step, z, h: float, max_iter: int = 30):
    """Newton on z = P(z) for an exact period map ``step(z) -> (P(z), aux)``, the
    Jacobian by central differences of step h: until the residual |P(z) - z| is at the
    rounding of the O(1) states (1e-15) or a step no longer lowers it.
    Returns (z, aux at z, residual, jacobian: z -> dP/dz)."""
    n = z.size

    def jacobian(z):
        jac = np.empty((n, n))
        for i in range(n):
            e = np.zeros(n)
            e[i] = h
            jac[:, i] = (step(z + e)[0] - step(z - e)[0]) / (2.0 * h)
        return jac

    # the states are of order 1 (x** and the forcing), so the map rounds at ~1e-16
    # absolute: Newton stops there, or when a step no longer lowers the residual
    fz, aux = step(z)
    residual = float(np.max(np.abs(fz - z)))
    for _ in range(max_iter):
        if residual <= 1e-15:
            break
        trial = z - np.linalg.solve(jacobian(z) - np.eye(n), fz - z)
        ft, at = step(trial)
        res_t = float(np.max(np.abs(ft - trial)))
        if res_t >= residual:
            break
        z, fz, aux, residual = trial, ft, at, res_t
    return z, aux, residual, jacobian


class OrbitMultipliers:
    """What an orbit with a ``monodromy`` and the ``impacts`` of its period says: its
    multipliers and impact velocity (shared by :class:`PulseOrbit` and
    :class:`grazing_control.dynamics.simulation.actuator.ActuatedOrbit`)."""

    @property
    def multipliers(self) -> np.ndarray:
        """Eigenvalues of the monodromy, largest modulus first."""
        mult = np.linalg.eigvals(self.monodromy)
        return mult[np.argsort(-np.abs(mult))]

    @property
    def v_minus(self) -> float:
        """Impact velocity of the orbit's impact."""
        return self.impacts[0].v_minus


@dataclass(frozen=True)
class PulseOrbit(OrbitMultipliers):
    """The 1/1 orbit of the loop closed with a force pulse (:func:`pulse_orbit`).

    ``pi2``: (x, v) on Pi2 before the correction; ``pi2_deviation``: (x - x**, v - v**);
    ``correction``: the Delta v the controller answers there; ``impacts``: the impacts of
    one period (times from the sample); ``monodromy``: the Jacobian of the closed-loop
    period map there (central differences of the exact map); ``residual``: the largest
    |P(z) - z| left; ``start``, ``width``: the pulse.
    """

    pi2: tuple
    pi2_deviation: tuple
    correction: float
    impacts: tuple
    monodromy: np.ndarray = field(repr=False)
    residual: float
    start: float
    width: float



def pulse_orbit(p: OscillatorParams, gains: Gains, width: float, *,
                force_limit: float = math.inf, saturation: float = math.inf,
                max_iter: int = 30) -> PulseOrbit:
    """The controlled 1/1 orbit when each correction acts as a force pulse of ``width``.

    The closed-loop period map is z -> :func:`pulse_step` (z, Delta v(z)) with the
    correction of Eq. 28, Delta v = c1 z_x + c2 z_v clipped to +-``saturation`` (as the
    controller answers), carried by a pulse centred ``gains.delay`` after the sample
    (:func:`pulse_start`, as the simulator applies it). Its fixed point is found by Newton
    from the kick's orbit (:func:`grazing_control.dynamics.orbits.orbits.orbit_11` with the
    same delay, O(w^2) away: docs/theory_pulse.md), with the Jacobian by central
    differences of the exact map, until the step is at the rounding level; the orbit must
    have exactly one impact per period. Width 0 gives the kick's orbit to rounding.

    Raises
    ------
    OrbitNotFound
        No kick orbit to start from, Newton does not converge, or the fixed point does
        not have one impact per period.
    ParameterError
        A pulse that does not fit in the period (:func:`pulse_step`).
    """
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11

    start = pulse_start(p.period, gains.delay, width)
    pulse_step(p, 0.0, 0.0, 0.0, start=start, width=width, force_limit=force_limit)  # checks
    kick = orbit_11(p, gains, branch="grazing")
    z = np.array(kick.pi2_deviation, dtype=float)

    def correction(z):
        return max(-saturation, min(saturation, gains.c1 * z[0] + gains.c2 * z[1]))

    def step(z):
        seg = pulse_step(p, float(z[0]), float(z[1]), correction(z), start=start,
                         width=width, force_limit=force_limit)
        return np.array([seg.dx, seg.dv]), seg

    # a difference step well inside the region of one transversal impact: its size in
    # position is of order v-^2 (the gap's parabola at the impact), its rounding error
    # eps |z| / h
    h = max(1e-3 * kick.v_minus ** 2, 1e-7 * float(np.max(np.abs(z))), 1e-13)

    z, seg, residual, jacobian = newton_fixed_point(step, z, h, max_iter)
    if residual > 1e-12 or len(seg.impacts) != 1:
        raise OrbitNotFound(f"no 1/1 pulse orbit (width {width!r}) near the kick's: residual "
                            f"{residual:.1e}, {len(seg.impacts)} impacts per period")
    x, v = p.x_ref + z[0], p.v_ref + z[1]
    return PulseOrbit((float(x), float(v)), (float(z[0]), float(z[1])), correction(z),
                      tuple(seg.impacts), jacobian(z), residual, start, width)

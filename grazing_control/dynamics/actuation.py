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
bit for bit (:func:`grazing_control.dynamics.simulate.period_step`).

Kick versus pulse: a pulse of width w starting at s delivers, to first order in w,
the kick Delta v at its centre s + w/2; the difference is O(w^2) (docs/theory_pulse.md).
A design for an actuation delay delta therefore matches a pulse *centred* delta after
the sample, i.e. starting at delta - w/2.
"""

from __future__ import annotations

import math

from grazing_control.oscillator import kernel as _kernel
from grazing_control.oscillator.impact import Segment
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from .simulate import period_step

__all__ = ["pulse_force", "pulse_step", "flow_with_force"]

TWO_PI = 2.0 * math.pi


def pulse_force(dv_correction: float, width: float, force_limit: float = math.inf) -> float:
    """The constant force of a pulse of ``width`` > 0 carrying ``dv_correction``:
    Delta v / w, clipped to [-force_limit, force_limit]."""
    force = dv_correction / width
    return max(-force_limit, min(force_limit, force))


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

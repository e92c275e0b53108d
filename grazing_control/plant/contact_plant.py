"""The simulator's stop: the rigid wall, or a compliant stop with dry friction (issue 31).

sim_node's ``contact`` parameters (docs/nodes.md) select the law the engine integrates
each period with: ``rigid`` (the wall of the study, the engine's own exact flow: nothing
here is used), ``kelvin_voigt`` (:mod:`grazing_control.oscillator.contact`, exact per
region, optional Coulomb friction) or ``hertz`` (:mod:`grazing_control.oscillator.hertz`,
DOP853 in contact). :class:`ContactPlant` gives the engine what it takes from the rigid
core: one period from a Pi2 sample with the correction on Pi2 (the contacts as impacts:
entry time, phase, v-, v+), and the states published between two samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.simulation.actuation import flow_with_force, pulse_force
from grazing_control.dynamics.simulation.actuator import command_period
from grazing_control.oscillator.contact import (MAX_FRICTION, MAX_STIFFNESS, Coulomb,
                                                KelvinVoigt, LagForce, advance_compliant)
from grazing_control.oscillator.flow import to_deviation, to_physical
from grazing_control.oscillator.hertz import HuntCrossley, advance_hertz
from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["CONTACTS", "ContactPlant", "contact_from_values"]

#: the values of sim_node's ``contact`` parameter
CONTACTS = ("rigid", "kelvin_voigt", "hertz")
TWO_PI = 2.0 * math.pi


class ContactImpact(NamedTuple):
    """A contact as the engine publishes an impact: entry time from the segment's start,
    forcing phase at entry, x' at entry (v-) and at exit (v+; nan if it lasts past the
    segment)."""

    dt: float
    phase: float
    v_minus: float
    v_plus: float


class ContactLagFlow(NamedTuple):
    """The stop's flow under the actuator's force F_inf + C e^{-h / tau_a} for a
    duration (:meth:`ContactPlant.lag_flow`, the fields the engine reads of
    :class:`~grazing_control.dynamics.simulation.actuator.LagFlow`): the deviation and the
    force at the end, and the contacts as impacts."""

    dx: float
    dv: float
    force: float
    impacts: tuple


class ContactStep(NamedTuple):
    """One period: the deviation at the next sample, and the contacts."""

    dx: float
    dv: float
    impacts: tuple


@dataclass(frozen=True)
class ContactPlant:
    """A compliant stop (and friction) for the engine: ``law`` is a KelvinVoigt or a
    HuntCrossley stop, ``friction`` a Coulomb law or None."""

    law: KelvinVoigt | HuntCrossley
    friction: Coulomb | None = None

    def advance(self, p: OscillatorParams, tau: float, dx: float, dv: float,
                duration: float, force: LagForce | None = None) -> ContactStep:
        """The flow for ``duration`` from the deviation (dx, dv) at phase ``tau``
        (``force``: an external force on the mass, the actuator's)."""
        return self._flow(p, tau, dx, dv, duration, force, None)[0]

    def _flow(self, p, tau, dx, dv, duration, force, times):
        """(ContactStep, the stop's segment) of the flow, with the dense output at
        ``times`` (None: none)."""
        x, v = to_physical(p, tau, dx, dv)
        if isinstance(self.law, HuntCrossley):
            seg = advance_hertz(p, self.law, tau, x, v, duration, friction=self.friction,
                                force=force, times=times)
        else:
            seg = advance_compliant(p, self.law, tau, x, v, duration, friction=self.friction,
                                    force=force, times=times)
        tau1 = tau + p.omega * duration
        ex, ev = to_deviation(p, tau1, seg.x, seg.v)
        impacts = tuple(ContactImpact(c.dt, c.phase, c.v_minus, c.v_plus)
                        for c in seg.contacts)
        return ContactStep(ex, ev, impacts), seg

    def period_step(self, p: OscillatorParams, dx: float, dv: float,
                    dv_correction: float = 0.0) -> ContactStep:
        """One period from the Pi2 deviation (dx, dv), the correction applied on Pi2
        (Eq. 28): :func:`~grazing_control.oscillator.contact.compliant_period_step`'s
        shape, with the deviation re-expressed at the next sample."""
        return self.advance(p, p.tau2, dx, dv + dv_correction, p.period)

    def pulse_step(self, p: OscillatorParams, dx: float, dv: float, dv_correction: float,
                   start: float, width: float, force_limit: float = math.inf) -> ContactStep:
        """One period from the Pi2 deviation with the correction as a force pulse on
        [start, start + width] (width 0: the kick at ``start``): the stop's flow to the
        pulse, under its constant force (the stop shifted as the wall is,
        :func:`~grazing_control.dynamics.simulation.actuation.flow_with_force`), on to the
        next sample, as ``actuation.pulse_step`` for the wall. Contacts count from the
        sample."""
        force = pulse_force(dv_correction, width, force_limit) if width > 0.0 else 0.0
        pieces = ((start, 0.0, 0.0), (width, force, 0.0 if width > 0.0 else dv_correction),
                  (p.period - start - width, 0.0, 0.0))
        t, impacts = 0.0, []
        for duration, f, kick in pieces:
            if duration > 0.0:
                seg = flow_with_force(p, (p.tau2 + p.omega * t) % TWO_PI, dx, dv, duration,
                                      f, self.advance)
                impacts += [i._replace(dt=i.dt + t) for i in seg.impacts]
                dx, dv, t = seg.dx, seg.dv, t + duration
            dv += kick
        return ContactStep(dx, dv, tuple(impacts))

    def advance_with_states(self, p: OscillatorParams, tau: float, dx: float, dv: float,
                            duration: float, rel):
        """:meth:`advance` and the physical (x, v) at the times ``rel`` (increasing, in
        (0, duration]) in the same integration: the flow's dense output as it passes
        (:class:`~grazing_control.oscillator.contact._Dense`, DOP853's interpolant in a
        Hertz contact), so a piece and its published states cost one integration, not
        two (the end state is :meth:`advance`'s bit for bit: the dense output never
        alters the steps). Returns (ContactStep, array (len(rel), 2))."""
        step, seg = self._flow(p, tau, dx, dv, duration, None, list(rel) if len(rel) else None)
        return step, np.array(seg.states or [], dtype=float).reshape(len(rel), 2)

    def lag_flow(self, p: OscillatorParams, tau: float, dx: float, dv: float,
                 duration: float, f_inf: float, c: float, tau_a: float) -> ContactLagFlow:
        """The stop's flow for ``duration`` under the first-order actuator's force
        F_inf + C e^{-h / tau_a} (tau_a = 0 only with C = 0): what
        :func:`~grazing_control.dynamics.simulation.actuator.lag_flow` is for the wall
        (docs/theory_contact.md §21)."""
        force = _lag_force(f_inf, c, tau_a)
        seg = self.advance(p, tau, dx, dv, duration, force)
        return ContactLagFlow(seg.dx, seg.dv, force.at(duration), seg.impacts)

    def actuated_step(self, p: OscillatorParams, dx: float, dv: float, force: float,
                      dv_correction: float, start: float, width: float, actuator,
                      force_limit: float = math.inf):
        """One period from the Pi2 deviation (dx, dv) with the actuator's force ``force``
        there and the correction commanded on [start, start + width] (width 0: an
        impulse) through ``actuator``: the engine's pieces
        (:func:`~grazing_control.dynamics.simulation.actuator.command_period`) with this
        stop's :meth:`lag_flow`. Returns (dx, dv, force at the next section, impacts:
        times from the sample)."""
        return command_period(p, dx, dv, force, dv_correction, start, width, actuator,
                              force_limit, lambda *a: self.lag_flow(p, *a))

    def lag_states(self, p: OscillatorParams, tau: float, dx: float, dv: float,
                   f_inf: float, c: float, tau_a: float, rel) -> np.ndarray:
        """Physical (x, v) at the times ``rel`` of a :meth:`lag_flow` piece (dense output,
        as :meth:`states_between`)."""
        return self.states_between(p, tau, dx, dv, rel, _lag_force(f_inf, c, tau_a))

    def states_between(self, p: OscillatorParams, tau: float, dx: float, dv: float,
                       rel, force: LagForce | None = None) -> np.ndarray:
        """Physical (x, v) at the times ``rel`` (increasing, in (0, the segment's length]
        from its start at phase ``tau`` with deviation (dx, dv)): the stop's flow from the
        start once, each time evaluated on the piece that holds it (the dense output of
        ``advance_compliant`` / ``advance_hertz``: the closed form of its region, a stick,
        DOP853's interpolant in a Hertz contact). The published states never alter the
        trajectory: the period itself is :meth:`period_step` in one call."""
        if len(rel) == 0:
            return np.empty((0, 2))
        seg = self._flow(p, tau, dx, dv, float(rel[-1]), force, rel)[1]
        return np.array(seg.states, dtype=float).reshape(len(rel), 2)


def _lag_force(f_inf: float, c: float, tau_a: float) -> LagForce:
    if tau_a == 0.0 and c != 0.0:
        raise ValueError("a force transient needs tau_a > 0")
    return LagForce(f_inf, c, 1.0 / tau_a if tau_a > 0.0 else 0.0)


def contact_from_values(values: dict, p: OscillatorParams) -> ContactPlant | None:
    """The stop of sim_node's parameters ``contact``, ``contact_stiffness``,
    ``contact_damping`` (Kelvin-Voigt c_c, or Hunt-Crossley alpha for hertz),
    ``friction`` and ``friction_static`` (0 = friction); None for the rigid wall.
    Every value is checked against its range whatever the law (as the node's
    descriptors state it); raises ParameterError naming the parameter and its range."""
    kind = str(values["contact"])
    if kind not in CONTACTS:
        raise ParameterError(f"contact={kind!r} is invalid: valid values are "
                             f"{', '.join(CONTACTS)}")
    stiffness, damping = float(values["contact_stiffness"]), float(values["contact_damping"])
    kinetic, static = float(values["friction"]), float(values["friction_static"])
    for name, value, ok, valid in (
            ("contact_stiffness", stiffness, 0.0 < stiffness <= MAX_STIFFNESS,
             f"0 < contact_stiffness <= {MAX_STIFFNESS:g}"),
            ("contact_damping", damping, damping >= 0.0, "a finite damping >= 0"),
            ("friction", kinetic, 0.0 <= kinetic <= MAX_FRICTION,
             f"0 <= friction <= {MAX_FRICTION:g} (0 = none)"),
            ("friction_static", static, 0.0 <= static <= MAX_FRICTION,
             f"0 (= friction) or friction <= F_s <= {MAX_FRICTION:g}")):
        if not (math.isfinite(value) and ok):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is {valid}")
        if name.startswith("friction") and value != 0.0 and kind == "rigid":
            raise ParameterError(f"{name}={value!r} is invalid with contact={kind!r}: valid "
                                 "there is 0 (friction is simulated with a compliant stop)")
    if static != 0.0 and static < kinetic:
        raise ParameterError(f"friction_static={static!r} is invalid: valid range is 0 "
                             f"(= friction) or F_s >= friction = {kinetic!r}")
    if kind == "rigid":
        return None
    friction = Coulomb(kinetic, static or kinetic) if kinetic > 0.0 or static > 0.0 else None
    if kind == "hertz":
        return ContactPlant(HuntCrossley(stiffness, damping), friction)
    if not (2.0 * p.zeta + damping) ** 2 < 4.0 * (1.0 + stiffness):
        raise ParameterError(
            f"contact_damping={damping!r} is invalid with contact_stiffness={stiffness!r}: "
            "valid range is (2 zeta + c_c)^2 < 4 (1 + k_c) (an underdamped contact, "
            "docs/theory_contact.md C2)")
    if not damping < 2.0 * math.sqrt(stiffness):
        raise ParameterError(f"contact_damping={damping!r} is invalid: valid range is "
                             f"0 <= c_c < 2 sqrt(contact_stiffness) = "
                             f"{2.0 * math.sqrt(stiffness)!r}")
    return ContactPlant(KelvinVoigt(stiffness, damping), friction)

"""The n-DOF oscillator as the plant engine's model: what differs from the 1-DOF closed form.

The simulator's engine (:class:`grazing_control.plant.engine.Engine`) keeps the sample
bookkeeping, the faults, the stream's grid and the loops' interface once for every n; of
a model it needs only the pieces below, which the 1-DOF closed form provides through the
kernel (``kernel.exact_advance``, ``simulate.states_between``) and an n-DOF model file
through :class:`NdofSection` (issue 32):

* the state at sample 0: the deviation z = 0 in R^{2n} from the periodic response at
  Pi2 (the grazing point X**), or z = X0 - X_p(tau2) from a physical start X0
  (``state0``, validated by :func:`start_state`);
* the flow of a piece: :func:`grazing_control.oscillator.ndof.impact.advance` from phase
  tau for a time h, with its impacts;
* the kick: z + e_{n + i_a} Delta v, on the actuated coordinate's velocity; the
  velocity noise at Pi2 (``noise``) is such a kick, one draw per sample, as the 1-DOF
  scene's on its one velocity (for n = 1 the same draws);
* the physical state X = X_p(tau) + z of the n coordinates;
* the states between samples, from a piece's impact list without changing the
  trajectory: between impacts the deviation flows linearly, z(t + h) = Phi(h) z(t) (the
  periodic response absorbs the forcing; docs/ndof_model.md), and an impact changes only
  the wall coordinate's velocity, by v+ - v-, which adds (v+ - v-) e_{n + i_w} to z. A
  piece with a sticking impact is evaluated by ``advance`` from its start instead.
  Under a pulse's force F the same holds for z - sigma F against the clearance
  Delta d - sigma_w F (sigma the static deflection, oscillator/ndof/forced.py); under
  a first-order actuator's force u + c e^{-h / tau_a} the deviation is
  Phi(h) (z - sigma u - q) + sigma u + q e^{-h / tau_a} between impacts, each impact
  putting x_w on the wall with v_w+ = -r v_w- and scaling c by e^{-h / tau_a}
  (:func:`~grazing_control.oscillator.ndof.forced.lag_advance`'s closed form);
* the sensor's measurement of the n coordinates: sample j's coordinate i is the sensor's
  draw number j n + i (:func:`measure_coordinates`), a pure function of (seed, j) as in
  1-DOF, and for n = 1 the 1-DOF sensor's draws bit for bit.

A lockstep run with the law Delta v = k^T z therefore repeats
:class:`grazing_control.dynamics.maps.modal_map.ModalMap`'s iterates bit for bit (the same
calls). No ROS, no plant: this is the model layer.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.forced import (actuated_mass, advance_with_force,
                                                    forced_flow, lag_advance, lag_particular,
                                                    static_deflection)
from grazing_control.oscillator.ndof.impact import advance, check_state
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.impact import MAX_AMPLITUDE, NonFiniteStateError
from grazing_control.oscillator.params import ParameterError

__all__ = ["NdofSection", "measure_coordinates", "start_state"]

TWO_PI = 2.0 * math.pi


def measure_coordinates(sensor, j0: int, x, v):
    """What ``sensor`` (a :class:`~grazing_control.plant.sensor.SensorModel`) measures of
    the stream samples j0, j0 + 1, ... with true positions ``x`` and velocities ``v``
    (m, n): coordinate i of sample j is the sensor's sample j n + i (its draws, bias,
    quantum), velocities NaN for a position-only sensor. Returns (x~, v~), (m, n)."""
    x = np.asarray(x, dtype=float)
    v = np.asarray(v, dtype=float)
    m, n = x.shape
    xm, vm = sensor.measure(j0 * n, x.reshape(-1), v.reshape(-1))
    return xm.reshape(m, n), vm.reshape(m, n)


def start_state(value, model: NdofModel) -> tuple:
    """An n-DOF scene's ``state0`` validated against its model: () (None or empty: the
    grazing point X**), or the 2n finite values of the physical state
    [x_0..x_{n-1}, v_0..v_{n-1}] on Pi2 with the wall coordinate not beyond the wall
    (gap x_{i_w} - d <= 0 at Pi2's phase, :meth:`NdofFlow.gap`, as the flow requires);
    ParameterError naming state0 and its valid range."""
    if value is None or len(value) == 0:
        return ()
    n = model.n
    names = ([f"x_{i}" for i in range(n)] + [f"v_{i}" for i in range(n)])
    valid = f"2n = {2 * n} finite values [{', '.join(names)}] (the physical state on Pi2), " \
            "or empty for X**"
    if isinstance(value, str) or len(value) != 2 * n:
        raise ParameterError(f"state0={_listed(value)} is invalid: valid is {valid}")
    try:
        state = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ParameterError(f"state0={_listed(value)} is invalid: valid is {valid}") from None
    for name, v in zip(names, state):
        if not math.isfinite(v):
            raise ParameterError(f"state0={_listed(value)} is invalid: {name}={v!r} is not "
                                 f"finite; valid is {valid}")
    flow = NdofFlow.of(model)
    z = flow.to_deviation(flow.tau2, state)
    try:                    # the core's own bound, so that the start is refused by name
        check_state(flow, z, "state0")          # and not at t = 0 (issue 32, found by hand)
    except NonFiniteStateError:
        size = flow.condition * float(np.max(np.abs(z)))
        raise ParameterError(f"state0={_listed(value)} is invalid: its deviation from X** is "
                             f"absurdly large (cond(V) max|z| = {size:.3e}); valid range is "
                             f"cond(V) max|z| <= {MAX_AMPLITUDE:.0e}") from None
    if flow.gap(flow.tau2, z) > 0.0:
        i = model.i_w
        raise ParameterError(f"state0={_listed(value)} is invalid: x_{i}={state[i]!r} lies "
                             f"beyond the wall; valid range is x_{i} <= d = d* + delta_d = "
                             f"{flow.d_star + model.delta_d!r} (the wall coordinate i_w={i})")
    return state


def _listed(value) -> str:
    """A parameter's list value as written: [a, b, ...]."""
    if isinstance(value, str):
        return repr(value)
    try:
        return repr([float(v) if not isinstance(v, str) else v for v in value])
    except (TypeError, ValueError):
        return repr(value)


class NdofSection:
    """An n-DOF model file's oscillator as the engine's model (module docstring).

    ``period``, ``omega``, ``tau2``, ``tau_star`` are what the engine and its loops read
    of a model (as of :class:`~grazing_control.oscillator.params.OscillatorParams`);
    ``model`` the :class:`NdofModel`, ``flow`` its :class:`NdofFlow`.
    """

    def __init__(self, model: NdofModel):
        self.model = model
        self.flow = NdofFlow.of(model)
        self.n = model.n
        self.period = model.period
        self.omega = model.omega
        self.tau2 = self.flow.tau2
        self.tau_star = self.flow.tau_star

    def with_delta_d(self, delta_d: float) -> "NdofSection":
        """The same oscillator with the wall at ``delta_d``: the flow's periodic response
        and modal decomposition do not depend on Delta d (docs/theory_ndof_flow.md,
        sections 1-2) and are kept, as
        :func:`~grazing_control.oscillator.ndof.forced.forced_flow` keeps them; the
        section is :class:`NdofSection` of the model at ``delta_d``."""
        model = dataclasses.replace(self.model, delta_d=float(delta_d))
        out = copy.copy(self)
        out.model, out.flow = model, dataclasses.replace(self.flow, model=model)
        return out

    def start(self, state0: tuple = ()) -> np.ndarray:
        """The deviation at sample 0: z = X0 - X_p(tau2) of the physical start ``state0``
        (:func:`start_state`), or the grazing point X** (z = 0) where it is empty."""
        if len(state0) == 0:
            return np.zeros(2 * self.n)
        return self.flow.to_deviation(self.tau2, state0)

    def advance(self, tau: float, z, duration: float):
        """The exact flow with impacts from (tau, z) for ``duration``: ``.z``, ``.impacts``."""
        return advance(self.flow, tau, z, duration)

    def pulse_force(self, dv: float, width: float, limit: float = math.inf) -> float:
        """F = m_a Delta v / w clipped to +-``limit``: the pulse carrying Delta v
        (as :func:`grazing_control.dynamics.maps.modal_map.pulse_step`)."""
        return max(-limit, min(limit, actuated_mass(self.flow) * dv / width))

    def pushed(self, tau: float, z, duration: float, force: float):
        """The exact flow with impacts under the constant ``force`` on the actuated
        coordinate (:func:`~grazing_control.oscillator.ndof.forced.advance_with_force`)."""
        return advance_with_force(self.flow, tau, z, duration, force)

    def lagged(self, tau: float, z, duration: float, command: float, transient: float,
               tau_a: float):
        """The exact flow under the actuator's force command + transient e^{-h / tau_a}
        (:func:`~grazing_control.oscillator.ndof.forced.lag_advance`): ``.z``, ``.force``,
        ``.impacts``."""
        return lag_advance(self.flow, tau, z, duration, command, transient, tau_a)

    def lag_deviations_between(self, tau: float, z, impacts, times, command: float,
                               transient: float, tau_a: float) -> np.ndarray:
        """z at ``times`` (sorted, since the piece's start) of a :meth:`lagged` piece from
        its ``impacts`` (module docstring); (len(times), 2n)."""
        flow, m = self.flow, self.model
        n, w = self.n, m.i_w
        sigma_u = static_deflection(flow) * command if command != 0.0 else np.zeros(2 * n)
        out = np.empty((len(times), 2 * n))
        z, c, t0, k = np.array(z, dtype=float), float(transient), 0.0, 0

        def at(h):
            q = lag_particular(flow, c, tau_a)
            return flow.transition(h) @ (z - sigma_u - q) + sigma_u + q * math.exp(-h / tau_a)

        for j, h in enumerate(times):
            while k < len(impacts) and impacts[k].dt <= h:
                imp = impacts[k]
                z = at(imp.dt - t0)
                wall_x, rest_v = flow.on_wall(imp.phase)
                z[w], z[n + w] = wall_x, rest_v + imp.v_plus
                c *= math.exp(-(imp.dt - t0) / tau_a)
                t0 = imp.dt
                k += 1
            out[j] = at(h - t0)
        return out

    def kicked(self, z, dv: float) -> np.ndarray:
        """z + e_{n + i_a} Delta v (the kick on the actuated velocity)."""
        z = np.array(z, dtype=float)
        z[self.n + self.model.i_a] += dv
        return z

    def physical(self, tau: float, z) -> tuple:
        """(x, v): tuples of the n physical positions and velocities at phase tau."""
        X = self.flow.to_physical(tau, z)
        n = self.n
        return tuple(float(a) for a in X[:n]), tuple(float(a) for a in X[n:])

    def deviations_between(self, tau: float, z, impacts, times,
                           force: float = 0.0) -> np.ndarray:
        """z at ``times`` (sorted, since the piece's start at phase ``tau`` with deviation
        ``z``) from the piece's ``impacts`` (module docstring), under a pulse's constant
        ``force``; (len(times), 2n)."""
        if force != 0.0:    # z - sigma F flows freely against the moved wall (section 15)
            shift = static_deflection(self.flow) * force
            return self._between(forced_flow(self.flow, force), tau,
                                 np.asarray(z, dtype=float) - shift, impacts, times) + shift
        return self._between(self.flow, tau, z, impacts, times)

    def _between(self, flow: NdofFlow, tau: float, z, impacts, times) -> np.ndarray:
        out = np.empty((len(times), 2 * self.n))
        if any(i.sticking for i in impacts):
            for j, h in enumerate(times):
                out[j] = advance(flow, tau, z, h).z
            return out
        jump = self.n + self.model.i_w
        t0, z, k = 0.0, np.asarray(z, dtype=float), 0
        for j, h in enumerate(times):
            while k < len(impacts) and impacts[k].dt <= h:
                imp = impacts[k]
                z = flow.transition(imp.dt - t0) @ z
                z[jump] += imp.v_plus - imp.v_minus
                t0 = imp.dt
                k += 1
            out[j] = flow.transition(h - t0) @ z
        return out

"""The period map of a model file over its modal flow, for any n: a
:class:`~grazing_control.dynamics.maps.model.PeriodMap`.

:class:`ModalMap` is the model protocol's second implementation beside the 1-DOF closed
form :class:`~grazing_control.dynamics.maps.model.OneDOF` (issues 17, 32;
docs/theory_ndof_flow.md, section 7). Its name says what it steps: the motion of a model
file (an :class:`NdofModel` of any n, n = 1 included) as a sum of damped modes
(:class:`NdofFlow`), with certified impacts, the kick or pulse or actuator of the
correction; the 1-DOF oscillator's parameters have their own closed form. The state is the deviation
z = X - X** sampled on Pi2 = {tau = tau* + pi2_offset} *before* the controller acts, X**
the grazing orbit's point there (so the grazing orbit is z = 0). One step

1. applies the kick on the actuated velocity, v_{i_a} += k^T z, i.e. z <- G z with
   G = I + b k^T, b = e_{n + i_a} (k a length-2n gain vector; none: G = I);
2. flows one forcing period T with impacts
   (:func:`grazing_control.oscillator.ndof.impact.advance`).

With an actuation ``delay`` (0 < delay < T) the kick k^T z computed from the sample acts
``delay`` later: flow ``delay`` with impacts, kick, flow T - delay; the Jacobian is then
M2 (M1 + b k^T) (M1, M2 the monodromies of the two pieces; docs/theory_delay.md (D3),
the same for every n), and det DP has no product formula (an impact inside the delay
window breaks it): :meth:`ModalMap.jacobian_det` returns None.

With a pulse ``width`` w > 0 the correction k^T z is a force pulse on the actuated
coordinate instead of the kick: F = m_a k^T z / w on [start, start + w], centred
``delay`` after the sample (start = :func:`grazing_control.dynamics.simulation.actuation.pulse_start`,
the 1-DOF rule), flowed exactly with impacts (:func:`pulse_step`,
oscillator/ndof/forced.py; docs/theory_ndof.md section 15); through a first-order
actuator the force is a third kind of state (:func:`actuated_step`).

Its Jacobian is the product in time order of the transition matrices Phi over the smooth
pieces, the saltation matrices S at the impacts and G:
DP = Phi(T - t_m) S_m ... S_1 Phi(t_1) G, with

    det DP = e^{tr(A) T} r^(2 m) (1 + k_{n + i_a})

(det Phi(t) = e^{tr(A) t}, det S = r^2, det G = 1 + k^T b), which
:meth:`ModalMap.jacobian_det` returns for P^n with m impacts.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.control import gain_vector
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.forced import (actuated_mass, advance_with_force,
                                                    forced_flow, lag_advance, lag_particular,
                                                    static_deflection)
from grazing_control.oscillator.ndof.impact import advance, saltation_matrix
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.maps.model import SectionMap, Step

__all__ = ["ModalMap", "MODEL_PARAMETERS", "pulse_step", "actuated_step", "check_pulse"]

TWO_PI = 2.0 * math.pi

#: Model fields :meth:`ModalMap.with_parameter` may change (besides the gains k0 .. k{2n-1}
#: and the actuation ``delay``).
MODEL_PARAMETERS = ("delta_d", "omega", "r", "phase", "pi2_offset")


def _gain_vector(gains, n: int):
    """The map's read-only k (:func:`~grazing_control.oscillator.control.gain_vector`),
    None uncontrolled."""
    if gains is None:
        return None
    k = gain_vector(gains, n)
    k.setflags(write=False)
    return k


@dataclass(frozen=True, eq=False)
class ModalMap(SectionMap):
    """The n-DOF oscillator on Pi2, optionally with the kick controller (module docstring).

    Parameters
    ----------
    model : NdofModel
    gains : (2n,) array_like, optional
        k: the kick v_{i_a} += k^T z on Pi2 (z the deviation from X**); None: uncontrolled.
    delay : float
        Actuation delay: the kick acts this long after the sample, 0 <= delay < T
        (module docstring).
    width : float
        Pulse width w >= 0: the correction is a force pulse of this width centred
        ``delay`` after the sample (0: the kick; module docstring).

    Attributes
    ----------
    flow : NdofFlow
        The model's exact flow (built once).
    dimension : int
        2n.
    """

    model: NdofModel
    gains: np.ndarray | None = None
    delay: float = 0.0
    width: float = 0.0
    flow: NdofFlow = field(init=False, repr=False)
    dimension: int = field(init=False)

    def __post_init__(self):
        if not isinstance(self.model, NdofModel):
            raise ParameterError(f"model={self.model!r} is invalid: expected an NdofModel")
        object.__setattr__(self, "gains", _gain_vector(self.gains, self.model.n))
        delay = self.delay
        if isinstance(delay, bool) or not isinstance(delay, (int, float, np.floating)) \
                or not 0.0 <= float(delay) < self.model.period:
            raise ParameterError(f"delay={delay!r} is invalid: valid range is 0 <= delay < "
                                 f"T = {self.model.period:.10g}")
        object.__setattr__(self, "delay", float(delay))
        object.__setattr__(self, "flow", NdofFlow.of(self.model))
        object.__setattr__(self, "width", _pulse_width(self.model, self.width))
        if self.width != 0.0:
            check_pulse(self.model, self.pulse_start, self.width)
            static_deflection(self.flow)       # K invertible, else ParameterError
        object.__setattr__(self, "dimension", 2 * self.model.n)

    # ------------------------------------------------------------- the protocol
    @property
    def section(self) -> NdofFlow:
        """The flow: T and tau2 (:class:`~grazing_control.dynamics.maps.model.SectionMap`)."""
        return self.flow

    @property
    def coordinates(self) -> tuple:
        n = self.model.n
        return (tuple(f"x{i} - x{i}**" for i in range(n))
                + tuple(f"v{i} - v{i}**" for i in range(n)))

    def gain_matrix(self) -> np.ndarray:
        """G = I + b k^T, b = e_{n + i_a} (the identity without gains)."""
        G = np.eye(self.dimension)
        if self.gains is not None:
            G[self.model.n + self.model.i_a] += self.gains
        return G

    def step(self, state, jacobian: bool = False) -> Step:
        """One period of the Pi2 map: kick, then flow T with impacts (module docstring)."""
        z = np.array(state, dtype=float).reshape(-1)
        if z.shape != (self.dimension,):
            raise ParameterError(f"state has {z.size} entries: valid is 2n = {self.dimension}")
        if self.width != 0.0 and self.gains is not None:
            return self._pulse_step(z, jacobian)
        if self.delay != 0.0 and self.gains is not None:
            return self._delayed_step(z, jacobian)
        if self.gains is not None:
            z[self.model.n + self.model.i_a] += float(self.gains @ z)
        seg = advance(self.flow, self.flow.tau2, z, self.model.period, monodromy=jacobian)
        jac = seg.monodromy @ self.gain_matrix() if jacobian else None
        return Step(seg.z, jac, tuple(seg.impacts))

    def _delayed_step(self, z: np.ndarray, jacobian: bool) -> Step:
        """Flow ``delay``, kick by k^T z (z the sample), flow T - delay; DP = M2 (M1 + b k^T)
        (module docstring)."""
        m, flow = self.model, self.flow
        kick = float(self.gains @ z)
        first = advance(flow, flow.tau2, z, self.delay, monodromy=jacobian)
        mid = np.array(first.z, dtype=float)
        mid[m.n + m.i_a] += kick
        second = advance(flow, (flow.tau2 + m.omega * self.delay) % (2.0 * math.pi), mid,
                         m.period - self.delay, monodromy=jacobian)
        jac = None
        if jacobian:
            inner = np.array(first.monodromy, dtype=float)
            inner[m.n + m.i_a] += self.gains
            jac = second.monodromy @ inner
        shifted = [i._replace(dt=i.dt + self.delay) for i in second.impacts]
        return Step(second.z, jac, tuple(first.impacts) + tuple(shifted))

    @property
    def pulse_start(self) -> float:
        """When the pulse starts after the sample: centred at ``delay``, within [0, T - w)
        (:func:`grazing_control.dynamics.simulation.actuation.pulse_start`)."""
        from grazing_control.dynamics.simulation.actuation import pulse_start

        return pulse_start(self.model.period, self.delay, float(self.width))

    def _pulse_step(self, z: np.ndarray, jacobian: bool) -> Step:
        """The correction k^T z as a pulse: :func:`pulse_step`, Jacobian with the force's
        dependence on z (F = m_a k^T z / w)."""
        out = pulse_step(self.flow, z, float(self.gains @ z), start=self.pulse_start,
                         width=self.width, jacobian=jacobian)
        jac = None
        if jacobian:
            jac = out.jacobian + np.outer(out.input, self.gains)
        return Step(out.state, jac, out.impacts)

    def _names(self) -> tuple:
        return MODEL_PARAMETERS + tuple(f"k{j}" for j in range(self.dimension)) + \
            ("delay", "width")

    def parameter(self, name: str) -> float:
        """A model field of :data:`MODEL_PARAMETERS`, a gain entry ``k0`` .. ``k{2n-1}`` or
        the actuation ``delay``."""
        if name in ("delay", "width"):
            return float(getattr(self, name))
        if isinstance(name, str) and name.startswith("k") and name[1:].isdigit() \
                and int(name[1:]) < self.dimension:
            if self.gains is None:
                raise ParameterError(f"parameter {name!r} is invalid without gains: valid names "
                                     f"are {', '.join(MODEL_PARAMETERS)}")
            return float(self.gains[int(name[1:])])
        if name in MODEL_PARAMETERS:
            return float(getattr(self.model, name))
        raise ParameterError(f"parameter {name!r} is invalid: valid names are "
                             f"{', '.join(self._names())}")

    def with_parameter(self, name: str, value: float) -> "ModalMap":
        """The same map with one parameter changed (validated again: a bad value raises
        ParameterError naming it)."""
        self.parameter(name)
        if name in ("delay", "width"):
            return dataclasses.replace(self, **{name: value})
        if name in MODEL_PARAMETERS:
            return dataclasses.replace(self, model=dataclasses.replace(self.model,
                                                                       **{name: value}))
        k = np.array(self.gains, dtype=float)
        k[int(name[1:])] = value
        return dataclasses.replace(self, gains=k)

    def jacobian_det(self, periods: int, impacts: int) -> float | None:
        """det D(P^periods) with ``impacts`` impacts: e^{tr(A) periods T} r^(2 m)
        (1 + k_{n + i_a})^periods (module docstring); None with an actuation delay or a
        pulse."""
        if (self.delay != 0.0 or self.width != 0.0) and self.gains is not None:
            return None
        m = self.model
        g = 1.0 if self.gains is None else 1.0 + float(self.gains[m.n + m.i_a])
        return math.exp(float(np.trace(self.flow.A)) * periods * m.period) * m.r ** (2 * impacts) \
            * g ** periods


# -------------------------------------------------------------------- the force pulse

def _pulse_width(model: NdofModel, width) -> float:
    """``width`` as a float: a finite real number, 0 <= width < T."""
    ok = (not isinstance(width, bool) and isinstance(width, (int, float, np.floating, np.integer))
          and math.isfinite(width) and 0.0 <= width < model.period)
    if not ok:
        raise ParameterError(f"width={width!r} is invalid: valid range is a finite width, "
                             f"0 <= width < T = {model.period:.10g}")
    return float(width)


def check_pulse(model: NdofModel, start: float, width: float, latency: float = 0.0) -> float:
    """``width``, checked with its ``start`` (and the actuator's ``latency``): finite,
    0 <= width < T, start >= 0 and start + latency + width < T. Returns width as a
    float."""
    width = _pulse_width(model, width)
    if not (math.isfinite(start) and start >= 0.0 and start + latency + width < model.period):
        raise ParameterError(f"width={width!r} is invalid with start={start!r} and latency="
                             f"{latency!r}: valid range is 0 <= start and start + latency + "
                             f"width < T = {model.period:.10g}")
    return float(width)


class PulseStep(NamedTuple):
    """Result of :func:`pulse_step`: the deviation at the next section (2n,), the impacts
    (times from the sample), and with ``jacobian`` d state / d z0 at a fixed correction
    and ``input`` = d state / d(Delta v) (the pulse's input vector through the period)."""

    state: np.ndarray
    impacts: tuple
    jacobian: np.ndarray | None = None
    input: np.ndarray | None = None


def pulse_step(flow: NdofFlow, z, correction: float, *, start: float, width: float,
               jacobian: bool = False, force_limit: float = math.inf) -> PulseStep:
    """One forcing period from the Pi2 deviation z with the correction Delta v as a force
    pulse on the actuated coordinate: F = m_a Delta v / w on [start, start + w]
    (docs/theory_ndof.md section 15; m_a = 1 / (M^-1)_aa, so the impulse moves the
    actuated velocity by Delta v), flowed exactly with impacts before, in and after the
    pulse. Width 0 is the kick at ``start``. The force is clipped to +-``force_limit``
    (then it does not depend on Delta v). For n = 1 this is the 1-DOF
    :func:`grazing_control.dynamics.simulation.actuation.pulse_step`.

    With ``jacobian``: d state / d z = M3 M_p M1 (the monodromies of the three pieces,
    the correction held) and d state / d(Delta v) = M3 ((I - M_p) sigma - g sigma_w)
    m_a / w, g the pulse piece's sensitivity to its clearance Delta d - sigma_w F
    (oscillator/ndof/forced.py, :func:`advance_with_force`).
    """
    m = flow.model
    n = m.n
    width = check_pulse(m, start, width)
    z = np.array(z, dtype=float).reshape(-1)
    eye = np.eye(2 * n)
    if not force_limit > 0.0:
        raise ParameterError(f"force_limit={force_limit!r} is invalid: valid range is > 0")
    ma = actuated_mass(flow)
    force = max(-force_limit, min(force_limit, ma * correction / width)) if width else 0.0
    gain = ma / width if width and abs(ma * correction / width) < force_limit else 0.0
    # legs (from, to, force, kick): before, in and after the pulse (or the kick at start)
    if width == 0.0:
        legs = ((0.0, start, 0.0, False), (start, m.period, 0.0, True))
    else:
        legs = ((0.0, start, 0.0, False), (start, start + width, force, None),
                (start + width, m.period, 0.0, False))
    jac, inp, impacts = eye.copy(), np.zeros(2 * n), []
    for t0, t1, force, kick in legs:
        if kick:
            z[n + m.i_a] += correction
            inp = inp + eye[n + m.i_a]
        if t1 <= t0:
            continue
        tau = (flow.tau2 + m.omega * t0) % TWO_PI
        if kick is None and jacobian:          # the pulse: its force depends on Delta v
            seg, g = advance_with_force(flow, tau, z, t1 - t0, force, monodromy=True, wall=True)
            sigma = static_deflection(flow)
            mp = seg.monodromy
            inp = mp @ inp + ((eye - mp) @ sigma - g * sigma[m.i_w]) * gain
            jac = mp @ jac
        else:
            seg = advance_with_force(flow, tau, z, t1 - t0, force, monodromy=jacobian)
            if jacobian:
                jac, inp = seg.monodromy @ jac, seg.monodromy @ inp
        impacts += [i._replace(dt=i.dt + t0) for i in seg.impacts]
        z = np.array(seg.z, dtype=float)
    return PulseStep(z, tuple(impacts), jac if jacobian else None, inp if jacobian else None)


def actuated_step(flow: NdofFlow, z, force: float, correction: float, *, start: float,
                  width: float, time_constant: float = 0.0, latency: float = 0.0,
                  force_limit: float = math.inf, jacobian: bool = False):
    """One forcing period from the Pi2 deviation z and the actuator's force ``force``
    there, the correction commanded as a pulse of ``width`` > 0 on [start, start + w]
    through a first-order actuator (time constant tau_a, ``latency`` L): the force on the
    actuated coordinate obeys tau_a F' = u(t - L) - F, u = m_a Delta v / w on the pulse
    clipped to +-``force_limit``
    (oscillator/ndof/forced.py, :func:`~grazing_control.oscillator.ndof.forced.lag_advance`;
    docs/theory_ndof.md section 15). Returns (z, force at the next section, impacts: times
    from the sample). tau_a = 0 is :func:`pulse_step` at start + L (force must be 0).
    For n = 1 this is the 1-DOF
    :func:`grazing_control.dynamics.simulation.actuator.actuated_step`.

    With ``jacobian`` it returns (z, force, impacts, jac, input) with the exact
    derivatives of y = (z, force) at the next section (2n + 1): ``jac`` = d y / d (z, force)
    at a fixed correction, ``input`` = d y / d(Delta v) (:func:`_lag_sensitivity`,
    docs/theory_ndof.md section 17); for tau_a = 0 they are :func:`pulse_step`'s with
    the force's row and column 0.

    Raises ParameterError for a pulse that does not fit in the period or a bad actuator,
    ValueError on a chattering or sticking motion under the actuator's force.
    """
    m = flow.model
    for name, value in (("actuator_time_constant", time_constant), ("actuator_latency", latency)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) \
                or not (math.isfinite(value) and value >= 0.0):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite "
                                 f"{name} >= 0")
    if not (isinstance(width, (int, float, np.floating)) and width > 0.0):
        raise ParameterError(f"width={width!r} is invalid: valid range is a finite width > 0 "
                             "through an actuator")
    check_pulse(m, start, width, latency)
    z = np.array(z, dtype=float).reshape(-1)
    if time_constant == 0.0:
        if force != 0.0:
            raise ParameterError(f"force={force!r} is invalid: an actuator without lag leaves "
                                 "no force at the section, valid value is 0")
        out = pulse_step(flow, z, correction, start=start + latency, width=width,
                         force_limit=force_limit, jacobian=jacobian)
        if not jacobian:
            return out.state, 0.0, list(out.impacts)
        d = 2 * m.n
        jac, inp = np.zeros((d + 1, d + 1)), np.zeros(d + 1)
        jac[:d, :d], inp[:d] = out.jacobian, out.input
        return out.state, 0.0, list(out.impacts), jac, inp
    if not force_limit > 0.0:
        raise ParameterError(f"force_limit={force_limit!r} is invalid: valid range is > 0")
    raw = actuated_mass(flow) * correction / width
    command = max(-force_limit, min(force_limit, raw))
    # d u / d(Delta v) on the pulse's leg (0 where the command is clipped)
    slope = actuated_mass(flow) / width if abs(raw) < force_limit else 0.0
    on, off = start + latency, start + latency + width
    t, f, impacts = 0.0, float(force), []
    sens = _LagSensitivity(flow, time_constant) if jacobian else None
    for end, u, du in ((on, 0.0, 0.0), (off, command, slope), (m.period, 0.0, 0.0)):
        if end > t:
            tau = (flow.tau2 + m.omega * t) % TWO_PI
            seg = lag_advance(flow, tau, z, end - t, u, f - u, time_constant)
            if sens is not None:
                sens.leg(z, f, u, du, seg.impacts, end - t)
            impacts += [i._replace(dt=i.dt + t) for i in seg.impacts]
            z, f = np.array(seg.z, dtype=float), float(seg.force)
        t = end
    if sens is None:
        return z, f, impacts
    return z, f, impacts, sens.jacobian, sens.input


class _LagSensitivity:
    """The exact derivatives of one period of :func:`actuated_step` through the lag
    (docs/theory_ndof.md section 17): the variation V of z (2n x (2n + 2), the columns
    d / d(z0, F0, Delta v)) and dF of the force (2n + 2), carried leg by leg.

    On a leg with command u (du = d u / d(Delta v)) and force F = u + c e^{-h / tau_a}
    the motion is z(h) = Phi(h)(z_e - sigma u - q1 c) + sigma u + q1 c e^{-h / tau_a}
    (q1 = :func:`lag_particular` of a unit transient), linear in (z_e, u, c), so

        V(h) = Phi(h)(V_e - sigma du - q1 dc) + sigma du + q1 dc e^{-h / tau_a},
        dc = dF_e - du;

    at an impact V <- S V (S the saltation matrix under the force there: the wall and
    the impact law do not depend on F, so the variations of the force pass through it
    as those of the state), and dc <- dc e^{-h_i / tau_a} with c."""

    def __init__(self, flow: NdofFlow, tau_a: float):
        self.flow, self.tau_a = flow, tau_a
        d = 2 * flow.n
        self.v = np.hstack([np.eye(d), np.zeros((d, 2))])
        self.df = np.zeros(d + 2)
        self.df[d] = 1.0
        self.sigma = static_deflection(flow)
        self.q1 = lag_particular(flow, 1.0, tau_a)

    def leg(self, z, f, u, du, impacts, duration):
        """Carry (V, dF) over one leg from the state z and force f (the leg's impacts
        from :func:`lag_advance`)."""
        flow, m = self.flow, self.flow.model
        n, w = m.n, m.i_w
        d = 2 * n
        rate = 1.0 / self.tau_a
        dvec = np.zeros(d + 2)
        dvec[d + 1] = du
        sig_u = self.sigma * u
        c, dc = f - u, self.df - dvec
        ze, ve, t_e = np.array(z, dtype=float), self.v, 0.0
        for imp in impacts:
            h = imp.dt - t_e
            decay = math.exp(-h * rate)
            phi = flow.transition(h)
            z_minus = phi @ (ze - sig_u - self.q1 * c) + sig_u + self.q1 * c * decay
            v_minus = phi @ (ve - np.outer(self.sigma, dvec) - np.outer(self.q1, dc)) \
                + np.outer(self.sigma, dvec) + np.outer(self.q1, dc) * decay
            force = u + c * decay
            fl = forced_flow(flow, force)
            zs = z_minus - self.sigma * force
            wall_x, rest_v = fl.on_wall(imp.phase)
            zs[w], zs[n + w] = wall_x, imp.v_minus + rest_v
            ve = saltation_matrix(fl, imp.phase, zs) @ v_minus
            ze = zs + self.sigma * force
            ze[n + w] = imp.v_plus + rest_v + self.sigma[n + w] * force
            c, dc, t_e = c * decay, dc * decay, imp.dt
        h = duration - t_e
        decay = math.exp(-h * rate)
        self.v = flow.transition(h) @ (ve - np.outer(self.sigma, dvec)
                                       - np.outer(self.q1, dc)) \
            + np.outer(self.sigma, dvec) + np.outer(self.q1, dc) * decay
        self.df = dvec + dc * decay

    @property
    def jacobian(self) -> np.ndarray:
        """d (z, F)_{k+1} / d (z, F)_k at a fixed correction, (2n + 1) x (2n + 1)."""
        d = self.v.shape[0]
        return np.vstack([self.v[:, :d + 1], self.df[:d + 1]])

    @property
    def input(self) -> np.ndarray:
        """d (z, F)_{k+1} / d(Delta v), (2n + 1)."""
        return np.append(self.v[:, -1], self.df[-1])

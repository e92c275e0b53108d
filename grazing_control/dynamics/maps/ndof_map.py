"""The n-DOF impact oscillator on Pi2: a :class:`~grazing_control.dynamics.maps.model.PeriodMap`.

:class:`NdofMap` is the n-DOF counterpart of :class:`~grazing_control.dynamics.maps.model.OneDOF`
(issue 17; docs/theory_ndof_flow.md, section 7): the state is the deviation
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
window breaks it): :meth:`NdofMap.jacobian_det` returns None.

Its Jacobian is the product in time order of the transition matrices Phi over the smooth
pieces, the saltation matrices S at the impacts and G:
DP = Phi(T - t_m) S_m ... S_1 Phi(t_1) G, with

    det DP = e^{tr(A) T} r^(2 m) (1 + k_{n + i_a})

(det Phi(t) = e^{tr(A) t}, det S = r^2, det G = 1 + k^T b), which
:meth:`NdofMap.jacobian_det` returns for P^n with m impacts.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.impact import advance
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.maps.model import SectionMap, Step

__all__ = ["NdofMap", "MODEL_PARAMETERS"]

#: Model fields :meth:`NdofMap.with_parameter` may change (besides the gains k0 .. k{2n-1}
#: and the actuation ``delay``).
MODEL_PARAMETERS = ("delta_d", "omega", "r", "phase", "pi2_offset")


def _gain_vector(gains, n: int):
    if gains is None:
        return None
    try:
        k = np.array(gains, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError(f"gains={gains!r} is invalid: expected {2 * n} finite real numbers") from None
    if k.shape != (2 * n,) or not np.all(np.isfinite(k)):
        raise ParameterError(f"gains={gains!r} is invalid: expected {2 * n} finite real numbers "
                             f"(a gain on each deviation coordinate)")
    k.setflags(write=False)
    return k


@dataclass(frozen=True, eq=False)
class NdofMap(SectionMap):
    """The n-DOF oscillator on Pi2, optionally with the kick controller (module docstring).

    Parameters
    ----------
    model : NdofModel
    gains : (2n,) array_like, optional
        k: the kick v_{i_a} += k^T z on Pi2 (z the deviation from X**); None: uncontrolled.
    delay : float
        Actuation delay: the kick acts this long after the sample, 0 <= delay < T
        (module docstring).

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

    def _names(self) -> tuple:
        return MODEL_PARAMETERS + tuple(f"k{j}" for j in range(self.dimension)) + ("delay",)

    def parameter(self, name: str) -> float:
        """A model field of :data:`MODEL_PARAMETERS`, a gain entry ``k0`` .. ``k{2n-1}`` or
        the actuation ``delay``."""
        if name == "delay":
            return self.delay
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

    def with_parameter(self, name: str, value: float) -> "NdofMap":
        """The same map with one parameter changed (validated again: a bad value raises
        ParameterError naming it)."""
        self.parameter(name)
        if name == "delay":
            return NdofMap(self.model, self.gains, value)
        if name in MODEL_PARAMETERS:
            return NdofMap(dataclasses.replace(self.model, **{name: value}), self.gains,
                           self.delay)
        k = np.array(self.gains, dtype=float)
        k[int(name[1:])] = value
        return NdofMap(self.model, k, self.delay)

    def jacobian_det(self, periods: int, impacts: int) -> float | None:
        """det D(P^periods) with ``impacts`` impacts: e^{tr(A) periods T} r^(2 m)
        (1 + k_{n + i_a})^periods (module docstring); None with an actuation delay."""
        if self.delay != 0.0 and self.gains is not None:
            return None
        m = self.model
        g = 1.0 if self.gains is None else 1.0 + float(self.gains[m.n + m.i_a])
        return math.exp(float(np.trace(self.flow.A)) * periods * m.period) * m.r ** (2 * impacts) \
            * g ** periods

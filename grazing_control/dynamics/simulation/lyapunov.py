"""Lyapunov exponents of the motion on Pi2: tangent propagation through the exact flow.

The Pi2 map's Jacobian along an orbit is the product of the flow's transition matrices,
the impacts' saltation matrices and the controller's kick (spec section 5; the model
protocol's ``step(z, jacobian=True)``). An orthonormal frame Q is carried through it
and re-orthonormalised every period (DP_k Q_k = Q_{k+1} R_k, QR), and

    lambda_i = (1 / N) sum_k log |R_k,ii|          (per forcing period; / T per unit time)

is the i-th exponent (Benettin et al. 1980; docs/theory_lyapunov.md). Their sum obeys
an exact identity, checked in the tests and reported with every result: det Phi(h) =
e^{-2 zeta h}, det S = r^2 for every impact, det G = 1 + c2 for every kick, so

    lambda_1 + lambda_2 = -2 zeta T + 2 nu ln r + (controlled share) ln |1 + c2|   (L3)

with nu the mean number of impacts per period. A sticking impact makes the map singular
(all nearby states leave the wall together): then both exponents are -inf and the
identity does not apply (``stuck_periods`` says how many periods stuck).

Two routes: :func:`lyapunov_spectrum`, generic over any :class:`.model.PeriodMap`
(numpy QR; the reference), and :func:`lyapunov_exact` for the 1-DOF oscillator on the
compiled kernel (``oscillator.kernel.lyapunov_sums``: the orbit of ``run_point``, the
same floats as a sweep, with a 2x2 Gram-Schmidt) or on the pure-Python core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import advance
from grazing_control.oscillator.params import OscillatorParams

from grazing_control.dynamics.maps.maps import pi2_map
from grazing_control.dynamics.maps.model import PeriodMap

__all__ = ["LyapunovSpectrum", "lyapunov_spectrum", "lyapunov_exact", "determinant_sum"]


@dataclass(frozen=True)
class LyapunovSpectrum:
    """Lyapunov exponents per forcing period, largest first, over ``periods`` periods.

    ``impacts_per_period``: nu; ``stuck_periods``: periods with a sticking impact (then
    the exponents are -inf); ``expected_sum``: the right-hand side of (L3) for this
    orbit (nan when it does not apply: sticking, or a model that does not know its
    determinant); ``final``: the state after the last period.
    """

    exponents: tuple
    periods: int
    impacts_per_period: float
    stuck_periods: int
    expected_sum: float
    final: tuple

    @property
    def maximum(self) -> float:
        return self.exponents[0]

    @property
    def sum_residual(self) -> float:
        """sum(exponents) - expected_sum: zero to rounding (L3)."""
        return float(sum(self.exponents) - self.expected_sum)


def determinant_sum(p: OscillatorParams, impacts: int, periods: int, kicked_log: float = 0.0):
    """(L3)'s right-hand side: (-2 zeta T periods + 2 impacts ln r + kicked_log) / periods,
    ``kicked_log`` the sum of ln|1 + c2| over the controlled periods."""
    return (-2.0 * p.zeta * p.period * periods + 2.0 * impacts * math.log(p.r)
            + kicked_log) / periods


def _check(periods, transient):
    for name, value, low in (("periods", periods, 1), ("transient", transient, 0)):
        if isinstance(value, bool) or int(value) != value or value < low:
            raise ValueError(f"{name}={value!r} is invalid: valid range is an integer >= {low}")
    if not transient < periods:
        raise ValueError(f"transient={transient!r} is invalid: valid range is 0 <= transient "
                         f"< periods = {periods!r}")


def lyapunov_spectrum(model: PeriodMap, state, periods: int, transient: int = 0, *,
                      before: PeriodMap | None = None, switch: int = 0) -> LyapunovSpectrum:
    """The spectrum by numpy QR over any model (the reference route).

    Periods 0..periods-1 from ``state``; the exponents average periods
    transient..periods-1. ``before`` (optional) is the map used for periods < ``switch``
    (the uncontrolled oscillator before the controller is switched on).
    """
    _check(periods, transient)
    z = np.asarray(state, dtype=float)
    n = model.dimension
    q = np.eye(n)
    logs = np.zeros(n)
    impacts = stuck = 0
    logdet = 0.0      # sum over periods of log|det DP_k| when the model knows it (L3)
    for k in range(periods):
        m = before if (before is not None and k < switch) else model
        measure = k >= transient
        step = m.step(z, jacobian=measure)
        if measure:
            q, r = np.linalg.qr(step.jacobian @ q)
            d = np.abs(np.diag(r))
            with np.errstate(divide="ignore"):
                logs += np.log(d)
            impacts += len(step.impacts)
            stuck += any(i.sticking for i in step.impacts)
            det = m.jacobian_det(1, len(step.impacts))
            logdet += math.nan if det is None else \
                (math.log(abs(det)) if det != 0.0 else -math.inf)
        z = step.state
    count = periods - transient
    exps = tuple(sorted((float(x) / count for x in logs), reverse=True))
    expected = math.nan if stuck else logdet / count
    return LyapunovSpectrum(exps, count, impacts / count, stuck, expected,
                            tuple(float(x) for x in z))


def lyapunov_exact(p: OscillatorParams, start, periods: int, transient: int = 0,
                   gains: Gains | None = None, control_after: int | None = 0, *,
                   engine: str = "kernel") -> LyapunovSpectrum:
    """The 1-DOF spectrum on Pi2 along the orbit from ``start`` (a Pi2 deviation).

    The controller (``gains``) acts from sample ``control_after`` on (None: never), with
    its actuation delay, as in :func:`grazing_control.dynamics.simulation.simulate.simulate`.
    ``engine``: "kernel" (compiled) or "python" (the pure-Python core through
    :func:`.maps.pi2_map`'s monodromy).
    """
    _check(periods, transient)
    if engine not in ("kernel", "python"):
        raise ValueError(f"engine={engine!r} is invalid: valid values are 'kernel', 'python'")
    c1, c2, delay = (math.nan, math.nan, 0.0) if gains is None else \
        (gains.c1, gains.c2, gains.delay)
    if engine == "kernel":
        from grazing_control.oscillator.kernel import lyapunov_sums

        l1, l2, imps, stuck, lg, final = lyapunov_sums(p, periods, transient, start[0], start[1],
                                                       c1, c2, control_after, delay)
        logs = (l1, l2)
    else:
        logs, imps, stuck, lg, final = _python_sums(p, start, periods, transient, gains,
                                                    control_after)
    count = periods - transient
    exps = tuple(sorted((x / count for x in logs), reverse=True))
    # (L3) is exact without an actuation delay; with one, det G_delta = 1 + k^T b_delta
    # holds only for periods without an impact inside the delay (docs/theory_delay.md)
    expected = math.nan if stuck or delay != 0.0 else determinant_sum(p, imps, count, lg)
    return LyapunovSpectrum(exps, count, imps / count, stuck, expected, tuple(final))


def _python_sums(p, start, periods, transient, gains, control_after):
    """Gram-Schmidt as the kernel's, on pi2_map's monodromy (the pure-Python core)."""
    dx, dv = float(start[0]), float(start[1])
    q = np.eye(2)
    logs = np.zeros(2)
    imps = stuck = 0
    lg = 0.0
    for k in range(periods):
        on = gains is not None and control_after is not None and k >= control_after
        measure = k >= transient
        if on and gains.delay != 0.0:
            seg = pi2_map(p, dx, dv, gains, monodromy=measure)
            m = np.array(seg.monodromy).reshape(2, 2) if measure else None
        else:   # simulate's arithmetic: dv + (c1 dx + c2 dv), then M G (pi2_map: dv + c1 dx + c2 dv)
            dvc = gains.c1 * dx + gains.c2 * dv if on else 0.0
            seg = advance(p, p.tau2, dx, dv + dvc, p.period, monodromy=measure)
            if measure:
                m = np.array(seg.monodromy).reshape(2, 2)
                if on:
                    m = m @ np.array([[1.0, 0.0], [gains.c1, 1.0 + gains.c2]])
        if measure:
            q, r = np.linalg.qr(m @ q)
            with np.errstate(divide="ignore"):
                logs += np.log(np.abs(np.diag(r)))
            imps += len(seg.impacts)
            stuck += any(i.sticking for i in seg.impacts)
            if on:
                lg += math.log(abs(1.0 + gains.c2))
        dx, dv = seg.dx, seg.dv
    return tuple(float(x) for x in logs), imps, stuck, lg, (dx, dv)

"""Two-parameter continuation of the 1/1 orbit's period-doubling and fold curves.

The plane is (mu, Delta d), mu one of :data:`PARAMETERS` (omega, zeta, r, or the gain
c2 of the controlled orbit, c1 held); Delta d = d - d*(mu) is measured from the grazing
clearance, so the **grazing curve** is Delta d = 0, i.e. d = d*(mu) = a(omega) in the
absolute clearance (spec section 2, Eq. 2). Derivation: docs/theory_two_parameter.md.

The 1/1 branch is explicit in the impact phase psi (docs/theory.md section 5,
:func:`grazing_control.dynamics.orbits.orbits.wall_offset_at_phase`): psi -> (Delta d, v-, M). Its
monodromy J = M S has tr J = -r tr M + M12 K / v-, K = (1 + r)(cos theta - d), and the
exact det J (spec section 5). The period-doubling and fold conditions det(J + I) = 0,
det(J - I) = 0 are multiplied by v- (docs/theory_two_parameter.md, (T1)):

    g_PD(psi, mu) = v- (1 + det J - r tr M) + M12 K,
    g_F (psi, mu) = v- (1 + det J + r tr M) - M12 K,

smooth through psi = 0, where v- = 0 and g = N12 K. So each curve is the zero set of
one smooth scalar function of (psi, mu), continued by pseudo-arclength
(:func:`continue_curve`: secant-free tangent predictor, Newton corrector on
[g; t . (y - y_pred)] = 0), and mapped to the plane by Delta d(psi; mu).

**Codimension two.** At psi = 0, g = N12 K with K = (1 + r) a* != 0 (regular grazing,
Eq. 3): a PD or fold curve meets the grazing curve exactly where N_g,12(mu) = 0, the
degenerate grazing of Eq. 33 (uncontrolled: omega* = 2 omega_d / m). Along a continued
curve the meeting is detected as a sign change of psi and refined by Brent's method on
g(0, mu) = 0 (:func:`codim2_points` finds the same points by a scan of N_g,12).
Near such a point both curves leave the grazing curve tangentially,
Delta d = kappa (mu - mu*)^2 + O((mu - mu*)^3), PD on one side of mu* and fold on the
other, with kappa from the ZDM series (:func:`asymptotic_coefficient`, (T4)-(T6)).

**The family of designs** (``Family(..., 'c2', design=True)``: c1 from Eq. 38 at every
c2). There N_g,12 = 0 for every c2, g vanishes on the whole line psi = 0, and the
curves are continued as h = g / psi = 0 ((T8)): they meet grazing where lambda0 = -1
(PD) or +1 (fold), the ends of the admissible c2 set; the PD leaves quadratically (T9),
the fold cubically (T10, where gamma1 = 0 as well).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.orbits.continuation import branch_monodromy
from grazing_control.dynamics.maps.maps import period_matrix
from grazing_control.dynamics.orbits.orbits import (OrbitNotFound, _orbit_from_phase,
                                                    monodromy_det, multipliers,
                                                    wall_offset_at_phase)

__all__ = ["PARAMETERS", "KINDS", "Family", "regular_tests", "codim2_points",
           "branch_seeds", "curve_point", "CurvePoint", "Curve", "continue_curve",
           "asymptotic_coefficient", "Asymptotics", "local_shape", "fitted_exponent",
           "SHAPE_OFFSETS", "Codim2Point", "two_parameter_diagram", "Diagram"]

#: The second parameter of the plane (the first is Delta d).
PARAMETERS = ("omega", "zeta", "r", "c2")
#: The curves continued: multiplier -1 and multiplier +1 of the 1/1 orbit.
KINDS = ("period-doubling", "fold")

TWO_PI = 2.0 * math.pi
_EPS = np.finfo(float).eps
#: Most degenerate grazing points one diagram looks for (each seeds two curves).
MAX_CODIM2 = 50


@dataclass(frozen=True)
class Family:
    """The system as a function of one parameter ``name`` (the others from ``params``,
    ``gains``). For 'c2' the gains are required and c1 is held at ``gains.c1``, or, with
    ``design``, follows c2 by the degenerate condition (Eq. 38): the study's family of
    designs, N_g,12 = 0 at every c2 (docs/theory_two_parameter.md section 6)."""

    params: OscillatorParams
    gains: Gains | None
    name: str
    design: bool = False

    def __post_init__(self):
        if self.name not in PARAMETERS:
            raise ParameterError(f"parameter={self.name!r} is invalid: valid values are "
                                 f"{', '.join(PARAMETERS)}")
        if self.name == "c2" and self.gains is None:
            raise ParameterError("parameter='c2' needs the controller's gains: give --c2 "
                                 "(and optionally --c1, held fixed)")
        if self.design and self.name != "c2":
            raise ParameterError(f"design=True is invalid with parameter={self.name!r}: the "
                                 "degenerate design family is continued in c2 only")

    @property
    def base(self) -> float:
        """The parameter's value in ``params`` / ``gains``."""
        if self.name == "c2":
            return self.gains.c2
        return getattr(self.params, self.name)

    def at(self, value: float):
        """(params, gains) at parameter ``value`` (validated: ParameterError outside)."""
        value = float(value)
        if self.name == "c2":
            g = self.gains
            if self.design:
                from grazing_control.dynamics.design.gains import degenerate_c1

                return self.params, Gains(degenerate_c1(self.params, value, g.delay), value,
                                          g.delay)
            return self.params, Gains(g.c1, value, g.delay)
        return self.params.with_(**{self.name: value}), self.gains


def regular_tests(p: OscillatorParams, gains: Gains | None, psi: float):
    """(Delta d, v-, g_PD, g_F) on the 1/1 branch at impact phase tau* + psi ((T1)).

    g = v- det(J +- I): smooth at psi = 0 (v- = 0), where both equal +-N_g,12 K.
    """
    dd, v, m = wall_offset_at_phase(p, psi, gains)
    theta = (p.tau_star + psi) % TWO_PI
    k = (1.0 + p.r) * (math.cos(theta) - (p.d_star + dd))
    det = monodromy_det(p, gains, 1, 1)
    rtr = p.r * (m[0] + m[3])
    return dd, v, v * (1.0 + det - rtr) + m[1] * k, v * (1.0 + det + rtr) - m[1] * k


#: Along the design family g = psi h: below this |psi| h is its Taylor polynomial
#: from g at +-_PSI0 and +-_PSI0/2 (T8).
_PSI0 = 2e-6


def _g(fam: Family, kind: str, psi: float, value: float) -> float:
    p, gains = fam.at(value)
    i = 2 if kind == KINDS[0] else 3
    if not fam.design:
        return regular_tests(p, gains, psi)[i]
    # N_g,12 = 0 for every c2: g vanishes on psi = 0, the curve is h = g / psi = 0 (T8)
    if abs(psi) >= _PSI0:
        return regular_tests(p, gains, psi)[i] / psi
    g = {x: regular_tests(p, gains, x)[i] for x in (_PSI0, -_PSI0, 0.5 * _PSI0, -0.5 * _PSI0)}
    d1 = (g[_PSI0] - g[-_PSI0]) / (2.0 * _PSI0)            # h1 + h3 PSI0^2 + ...
    d2 = (g[0.5 * _PSI0] - g[-0.5 * _PSI0]) / _PSI0        # h1 + h3 PSI0^2 / 4 + ...
    h1 = (4.0 * d2 - d1) / 3.0                             # Richardson: h3 (~1e5) cancels
    h3 = (d1 - d2) / (0.75 * _PSI0 * _PSI0)
    h2 = (g[_PSI0] + g[-_PSI0]) / (2.0 * _PSI0 * _PSI0)
    return h1 + psi * (h2 + psi * h3)


def _grazing_test(fam: Family, kind: str, value: float) -> float:
    """The function of mu whose zeros are where the ``kind`` curve meets grazing:
    N_g,12 (g(0, mu) / (+-K), the degenerate condition Eq. 33, the same for both kinds);
    along the design family 1 + tr J0 + det J0 (PD) or 1 - tr J0 + det J0 (fold), lambda0
    at -1 or +1 (Eq. 23, :func:`grazing_control.dynamics.design.gains.limit_monodromy`; (T8))."""
    p, gains = fam.at(value)
    if not fam.design:
        return period_matrix(p, gains)[1]
    from grazing_control.dynamics.design.gains import limit_monodromy

    j0 = limit_monodromy(p, gains)
    tr0, det0 = j0[0, 0], -j0[0, 1]
    return 1.0 + det0 + (tr0 if kind == KINDS[0] else -tr0)


def codim2_points(fam: Family, lo: float, hi: float, n: int = 400,
                  kind: str = KINDS[0]) -> list:
    """Parameter values in [lo, hi] where N_g,12 = 0: the degenerate grazing points, where
    the PD and fold curves meet the grazing curve (``kind`` matters only along the design
    family, where the ``kind`` curve meets grazing at lambda0 = -1 or +1,
    :func:`_grazing_test`). A scan of ``n`` points, each sign
    change refined by Brent's method to a few ulps. In omega the scan is uniform in the
    period T with at least 8 points per half-period of the damped motion (N_g,12
    oscillates like sin(omega_d T): the points 2 omega_d / m crowd towards omega = 0);
    more than :data:`MAX_CODIM2` points is refused (narrow the range)."""
    if fam.name == "omega":
        p = fam.params
        t_lo, t_hi = TWO_PI / hi, TWO_PI / lo
        halves = p.omega_d * (t_hi - t_lo) / math.pi
        if halves > MAX_CODIM2 + 2:
            raise ParameterError(
                f"range=({lo!r}, {hi!r}) is invalid: it holds about {halves:.0f} degenerate "
                f"grazing points (omega = 2 omega_d / m), valid: at most {MAX_CODIM2}; "
                "narrow the range")
        grid = TWO_PI / np.linspace(t_hi, t_lo, max(n, int(8 * halves) + 2))
        grid[0], grid[-1] = lo, hi
    else:
        grid = np.linspace(lo, hi, n)
    vals = [_grazing_test(fam, kind, float(x)) for x in grid]
    out = []
    for a, b, fa, fb in zip(grid[:-1], grid[1:], vals[:-1], vals[1:]):
        if fa == 0.0:
            out.append(float(a))
        elif fa * fb < 0.0:
            out.append(float(brentq(lambda x: _grazing_test(fam, kind, x), a, b, xtol=1e-300,
                                    rtol=4.0 * _EPS, maxiter=200)))
    if vals[-1] == 0.0:
        out.append(float(grid[-1]))
    return out


def branch_seeds(fam: Family, kinds=KINDS, n: int = 241) -> list:
    """(kind, psi) of the PD and fold points of the 1/1 branch at the base value.

    The regularised tests on both sides of grazing on a logarithmic grid of |psi|
    (1e-12 ... pi), each sign change where v- > 0 refined by Brent's method: every PD and
    fold point of the 1/1 solution curve at this parameter value.
    """
    p, gains = fam.at(fam.base)
    mags = np.logspace(-12.0, math.log10(math.pi * 0.999), n)
    out = []
    for sign in (-1.0, 1.0):
        rows = [(sign * m, regular_tests(p, gains, sign * m)) for m in mags]
        for (sa, ta), (sb, tb) in zip(rows[:-1], rows[1:]):
            if not (ta[1] > 0.0 and tb[1] > 0.0):
                continue
            for i, kind in ((2, KINDS[0]), (3, KINDS[1])):
                if kind in kinds and ta[i] * tb[i] < 0.0:
                    lo, hi = sorted((sa, sb))
                    psi = brentq(lambda s, i=i: regular_tests(p, gains, s)[i], lo, hi,
                                 xtol=1e-300, rtol=4.0 * _EPS, maxiter=200)
                    out.append((kind, float(psi)))
    return out


def _psi_step(fam: Family, psi: float) -> float:
    """Central-difference step in psi: 1e-7 max(|psi|, 1e-2), or 1e-4 along the design
    family, whose h = g / psi carries an absolute rounding of ~1e-11 (T8)."""
    return 1e-4 if fam.design else 1e-7 * max(abs(psi), 1e-2)


def curve_point(fam: Family, kind: str, value: float, psi_guess: float,
                max_iter: int = 30) -> float:
    """psi with g_kind(psi, value) = 0 near ``psi_guess`` (the curve at a fixed parameter
    value): Newton's method with a central-difference derivative until its step stops
    shrinking, then a bracket around that point (widened by 2 until g changes sign, 60
    times at most) refined by Brent's method to a few ulps, so that the root is located
    to g's own rounding whatever its size."""
    psi, last = float(psi_guess), math.inf
    for _ in range(max_iter):
        f = _g(fam, kind, psi, value)
        if f == 0.0:
            return psi
        h = _psi_step(fam, psi)
        df = (_g(fam, kind, psi + h, value) - _g(fam, kind, psi - h, value)) / (2.0 * h)
        if not (math.isfinite(f) and math.isfinite(df)) or df == 0.0:
            break
        step = f / df
        psi -= step
        if abs(step) >= 0.5 * last or abs(step) <= 1e-15 * abs(psi):
            break
        last = abs(step)
    if not math.isfinite(psi):
        raise OrbitNotFound(f"no {kind} point near psi={psi_guess!r} at {fam.name}={value!r}")
    width = max(abs(psi) * 1e-12, 1e-300)
    f0 = _g(fam, kind, psi, value)
    if f0 == 0.0:
        return psi
    for _ in range(60):
        for other in (psi - width, psi + width):
            f1 = _g(fam, kind, other, value)
            if math.isfinite(f1) and f1 * f0 <= 0.0:
                lo, hi = sorted((psi, other))
                return float(brentq(lambda x: _g(fam, kind, x, value), lo, hi, xtol=1e-300,
                                    rtol=4.0 * _EPS, maxiter=200))
        width *= 2.0
        if width > 0.5 * max(abs(psi), 1e-6):
            break
    raise OrbitNotFound(f"no {kind} point near psi={psi_guess!r} at {fam.name}={value!r}")


@dataclass(frozen=True)
class CurvePoint:
    """One point of a PD or fold curve: the parameter, the impact phase offset psi, the
    clearance (Delta d and absolute d = d*(mu) + Delta d), v-, the multipliers, and
    whether it is a physical 1/1 orbit (v- > 0, one impact per period by the exact flow)."""

    value: float
    psi: float
    delta_d: float
    d: float
    v_minus: float
    multipliers: np.ndarray
    physical: bool


@dataclass(frozen=True)
class Curve:
    """A PD or fold curve, points in the order continued from ``seed``; ``ends`` says why
    each direction stopped; ``codim2``: parameter values where it met the grazing curve."""

    kind: str
    parameter: str
    seed: str
    points: tuple
    ends: tuple
    codim2: tuple


def _point(fam: Family, psi: float, value: float, check: bool = True) -> CurvePoint:
    p, gains = fam.at(value)
    if psi == 0.0:   # on the grazing curve: v- = 0, the multipliers are not defined
        lam, dd, v = np.array([math.inf, math.inf], dtype=complex), 0.0, 0.0
    else:
        dd, v, tr, det = branch_monodromy(p, psi, gains)
        lam = multipliers(np.array([[tr, -det], [1.0, 0.0]]), det)
    physical = v > 0.0
    if physical and check:
        try:
            _orbit_from_phase(p, psi, gains, check=True)
        except (OrbitNotFound, ValueError, ArithmeticError):
            physical = False
    return CurvePoint(float(value), float(psi), float(dd), float(p.d_star + dd), float(v),
                      lam, physical)


def _gradient(fam, kind, y):
    psi, mu = y
    hp = _psi_step(fam, psi)
    hm = 1e-7 * max(abs(mu), 1.0)
    gp = (_g(fam, kind, psi + hp, mu) - _g(fam, kind, psi - hp, mu)) / (2.0 * hp)
    gm = (_g(fam, kind, psi, mu + hm) - _g(fam, kind, psi, mu - hm)) / (2.0 * hm)
    return np.array([gp, gm])


def _tangent(fam, kind, y, previous=None):
    gp, gm = _gradient(fam, kind, y)
    t = np.array([-gm, gp])
    t /= np.hypot(*t)
    if previous is not None and float(t @ previous) < 0.0:
        t = -t
    return t


def _correct(fam, kind, y_pred, t, max_iter=8):
    """Newton on [g(y); t . (y - y_pred)] = 0 (the pseudo-arclength corrector)."""
    y = y_pred.copy()
    for it in range(max_iter):
        f = _g(fam, kind, y[0], y[1])
        grad = _gradient(fam, kind, y)
        jac = np.array([grad, t])
        rhs = -np.array([f, float(t @ (y - y_pred))])
        det = jac[0, 0] * jac[1, 1] - jac[0, 1] * jac[1, 0]
        if not (math.isfinite(f) and math.isfinite(det)) or det == 0.0:
            return None, it
        step = np.array([(rhs[0] * jac[1, 1] - jac[0, 1] * rhs[1]) / det,
                         (jac[0, 0] * rhs[1] - rhs[0] * jac[1, 0]) / det])
        y = y + step
        if np.max(np.abs(step)) <= 1e-13 * (1.0 + np.max(np.abs(y))):
            return y, it + 1
    return None, max_iter


def _meets_grazing(fam, kind, a, b):
    """The parameter value between a[1] and b[1] where g(0, mu) = 0 (psi crossed 0)."""
    f = lambda mu: _grazing_test(fam, kind, mu)  # noqa: E731 (g(0, mu) = +-K N12, K != 0)
    lo, hi = sorted((float(a[1]), float(b[1])))
    if f(lo) * f(hi) > 0.0:
        return None
    return float(brentq(f, lo, hi, xtol=1e-300, rtol=4.0 * _EPS, maxiter=200))


def _v_minus(fam, psi, value):
    p, gains = fam.at(value)
    return wall_offset_at_phase(p, psi, gains)[1]


def _walk(fam, kind, y0, t0, lo, hi, step, max_step, max_points):
    """Pseudo-arclength from y0 = (psi, mu) along t0: (points, why it stopped, mu*)."""
    kick = None
    if fam.gains is not None:
        kick = (fam.params.pi2_offset + math.pi) % TWO_PI - math.pi
    y, t, h = np.array(y0, dtype=float), np.array(t0, dtype=float), step
    out = []
    against_kick = False     # a step since the last point was refused across the kick
    def land(y, y_far):
        """The last point: the curve solved on the range's end between y and y_far."""
        bound = hi if y_far[1] > hi else lo
        frac = (bound - y[1]) / (y_far[1] - y[1])
        try:
            psi = curve_point(fam, kind, bound, y[0] + frac * (y_far[0] - y[0]))
        except (OrbitNotFound, ParameterError):
            return out, "range", None
        y_end = np.array([psi, bound])
        if y[0] != 0.0 and y_end[0] * y[0] < 0.0:
            mu = _meets_grazing(fam, kind, y, y_end)
            if mu is not None:
                return out + [np.array([0.0, mu])], "grazing", mu
        return out + [y_end], "range", None

    while len(out) < max_points:
        y_pred = y + h * t
        if not lo <= y_pred[1] <= hi:
            return land(y, y_pred)
        try:
            y_new, its = _correct(fam, kind, y_pred, t)
        except ParameterError:
            y_new, its = None, 0
        if y_new is not None and not lo <= y_new[1] <= hi:
            return land(y, y_new)   # the corrector left the range
        t_new = None
        if y_new is not None:
            t_new = _tangent(fam, kind, y_new, t)
            if np.hypot(*(y_new - y)) > 2.0 * h or float(t_new @ t) < 0.9:
                y_new = None
        if y_new is None:
            if kick is not None and (y[0] - kick) * (y_pred[0] - kick) <= 0.0:
                against_kick = True
            h *= 0.5
            if h < 1e-12:
                # a curve running into the kick's phase, where the branch jumps, stalls
                # there (docs/theory_two_parameter.md section 5, "How a curve ends")
                return out, "controller phase" if against_kick else "step size", None
            continue
        if y[0] != 0.0 and y_new[0] * y[0] <= 0.0:
            mu = _meets_grazing(fam, kind, y, y_new)
            if mu is not None:
                return out + [np.array([0.0, mu])], "grazing", mu
        if kick is not None and (y[0] - kick) * (y_new[0] - kick) <= 0.0:
            return out, "controller phase", None
        if abs(y_new[0]) >= math.pi:
            return out, "phase", None
        out.append(y_new)
        y, t, against_kick = y_new, t_new, False
        if its <= 3:
            h = min(1.5 * h, max_step)
    return out, "points", None


def continue_curve(fam: Family, kind: str, psi: float, value: float, lo: float, hi: float, *,
                   step: float = 1e-4, max_step: float | None = None, max_points: int = 400,
                   check: bool = True, seed: str = "") -> Curve:
    """Continue the ``kind`` curve (:data:`KINDS`) through (psi, value) in both directions
    by pseudo-arclength in (psi, mu), mu within [lo, hi] (module docstring).

    A seed on the grazing curve (psi = 0, a codimension-two point) is continued only
    into v- > 0, the physical side. Each direction stops at the range's end, where psi
    crosses 0 (the curve meets the grazing curve: the parameter value refined by
    Brent's method on N_g,12 = 0 is recorded in ``codim2``), at |psi| = pi, where the
    impact reaches the controller's phase (M(theta) jumps there; also where the step
    falls below 1e-12 after a step across that phase was refused: the curve runs into
    it), after ``max_points``, or where the step falls below 1e-12 ("step size").
    """
    if kind not in KINDS:
        raise ValueError(f"kind={kind!r} is invalid: valid values are {', '.join(KINDS)}")
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ParameterError(f"range=({lo!r}, {hi!r}) is invalid: valid range is finite lo < hi")
    max_step = (hi - lo) / 50.0 if max_step is None else max_step
    y0 = np.array([float(psi), float(value)])
    t0 = _tangent(fam, kind, y0)
    directions = (1.0, -1.0)
    if psi == 0.0:
        # into the physical side only: v- > 0 a short step along +-t0
        probe = [_v_minus(fam, s * step * t0[0], value + s * step * t0[1])
                 if lo <= value + s * step * t0[1] <= hi else -1.0 for s in directions]
        directions = tuple(s for s, v in zip(directions, probe) if v > 0.0)
    legs, ends, met = {}, [], []
    for s in (1.0, -1.0):
        if s not in directions:
            legs[s], why = [], "unphysical side (v- < 0)"
        else:
            legs[s], why, mu = _walk(fam, kind, y0, s * t0, lo, hi, step, max_step, max_points)
            if mu is not None:
                met.append(mu)
        ends.append(why)
    if psi == 0.0:
        met.append(float(value))
    ys = list(reversed(legs[-1.0])) + [y0] + legs[1.0]
    points = tuple(_point(fam, float(a), float(b), check) for a, b in ys)
    return Curve(kind, fam.name, seed, points, (ends[1], ends[0]), tuple(sorted(met)))


# ------------------------------------------------------------ near a codimension-two point
@dataclass(frozen=True)
class Asymptotics:
    """The leading order of a curve next to a degenerate grazing point mu* ((T5), (T6)):
    Delta d = kappa |mu - mu*|^exponent on the side ``side`` (+1: mu > mu*, -1: mu < mu*),
    where the impact velocity is v- = rate |mu - mu*| > 0. The exponent is 2, except for
    the fold along the design family, 3 ((T10))."""

    kind: str
    value: float
    kappa: float
    side: int
    rate: float
    exponent: int = 2


def asymptotic_coefficient(fam: Family, kind: str, value: float, h: float | None = None
                           ) -> Asymptotics:
    """kappa of Delta d = kappa (mu - mu*)^2 for the ``kind`` curve at mu* = ``value``
    (N_g,12(mu*) = 0), from the ZDM series of the 1/1 motion (docs/theory_zdm.md
    (P3), (P6), (P8); docs/theory_two_parameter.md (T4)-(T6)).

    kappa1 and chi_{-1} are proportional to N_g,12, so linear in mu - mu*: their
    derivatives k1', x' by central differences (step ``h``, default 1e-6 max(1, |mu*|));
    chi0, psi0, kappa2 are taken at mu*. Then v- = c (mu - mu*) with
    c = -x' / (1 + chi0 + psi0) (PD) or x' / (1 + psi0 - chi0) (fold), and
    kappa = k1' c + kappa2 c^2.
    """
    from grazing_control.dynamics.maps.perturbation import series_coefficients

    if kind not in KINDS:
        raise ValueError(f"kind={kind!r} is invalid: valid values are {', '.join(KINDS)}")
    h = 1e-6 * max(1.0, abs(value)) if h is None else h
    at = series_coefficients(*fam.at(value))
    up, down = series_coefficients(*fam.at(value + h)), series_coefficients(*fam.at(value - h))
    if fam.design and kind == KINDS[1]:
        return _design_fold(fam, value, at, up, down, h)
    if fam.design:
        # kappa1 = chi_{-1} = 0 at every c2: 1 +- (chi0 + chi1 delta2) + psi0 = 0 (T9)
        s = 1.0
        slope = ((up.psi0 + s * up.chi0) - (down.psi0 + s * down.chi0)) / (2.0 * h)
        c = -slope / (s * at.chi1)
        return Asymptotics(kind, float(value), float(at.kappa2 * c * c), 1 if c > 0.0 else -1,
                           float(abs(c)))
    k1 = (up.kappa1 - down.kappa1) / (2.0 * h)
    xm1 = (up.chi_m1 - down.chi_m1) / (2.0 * h)
    if kind == KINDS[0]:
        c = -xm1 / (1.0 + at.chi0 + at.psi0)
    else:
        c = xm1 / (1.0 + at.psi0 - at.chi0)
    return Asymptotics(kind, float(value), float(k1 * c + at.kappa2 * c * c),
                       1 if c > 0.0 else -1, float(abs(c)))


def _design_fold(fam, value, at, up, down, h):
    """(T10): along the design family lambda0 = +1 where gamma1 = -kappa2 = 0, and the
    fold is the turning point of Delta d = kappa2 v^2 + kappa3 v^3 with kappa2 =
    kappa2' (c2 - c2*): v = -2 kappa2' delta / (3 kappa3),
    Delta d = 4 kappa2'^3 delta^3 / (27 kappa3^2). kappa3 = lim Delta d / v^3 on the
    exact branch at c2* (wall_offset_at_phase at |psi| = 1e-3, 1e-4 where v > 0, Richardson)."""
    p, gains = fam.at(value)
    k2 = (up.kappa2 - down.kappa2) / (2.0 * h)
    sign = 1.0 if wall_offset_at_phase(p, 1e-3, gains)[1] > 0.0 else -1.0
    ratio = []
    for psi in (1e-3, 1e-4):
        dd, v, _m = wall_offset_at_phase(p, sign * psi, gains)
        ratio.append(dd / v ** 3)
    k3 = (10.0 * ratio[1] - ratio[0]) / 9.0      # the error is O(v), v ~ psi
    c = -2.0 * k2 / (3.0 * k3)
    kappa = 4.0 * k2 ** 3 / (27.0 * k3 * k3)
    side = 1 if c > 0.0 else -1
    return Asymptotics(KINDS[1], float(value), float(kappa * side), side, float(abs(c)), 3)


def local_shape(fam: Family, kind: str, value: float, offsets) -> np.ndarray:
    """Exact points of the ``kind`` curve at mu* + side * delta for each delta in
    ``offsets`` (side from :func:`asymptotic_coefficient`): rows (delta, Delta d, psi).

    Each is :func:`curve_point` at the fixed parameter value, started from the tangent
    of the curve at (psi, mu) = (0, mu*) and then from the previous point."""
    side = asymptotic_coefficient(fam, kind, value).side
    t = _tangent(fam, kind, np.array([0.0, value]))
    slope = t[0] / t[1]
    rows = []
    guess = None
    for delta in sorted(float(x) for x in offsets):
        mu = value + side * delta
        psi0 = slope * (mu - value) if guess is None else guess * delta / rows[-1][0]
        psi = curve_point(fam, kind, mu, psi0)
        p, gains = fam.at(mu)
        rows.append((delta, wall_offset_at_phase(p, psi, gains)[0], psi))
        guess = psi
    return np.array(rows)


def fitted_exponent(shape: np.ndarray, exponent: int = 2):
    """(p, kappa): p the log-log slope of |Delta d| against delta through the two smallest
    offsets of a :func:`local_shape` table, kappa = Delta d / delta^exponent at the
    smallest (the derived exponent, :class:`Asymptotics`)."""
    (d0, f0, _), (d1, f1, _) = shape[0], shape[1]
    return math.log(abs(f1 / f0)) / math.log(d1 / d0), f0 / d0 ** exponent


# ------------------------------------------------------------------------------ diagram
#: Offsets |mu - mu*| at which the local shape is measured (times max(1, |mu*|)).
SHAPE_OFFSETS = (1e-6, 1e-5, 1e-4, 1e-3)


@dataclass(frozen=True)
class Codim2Point:
    """A degenerate grazing point mu* (N_g,12 = 0) and, per curve kind, the predicted
    :class:`Asymptotics` with the measured local shape (:func:`local_shape` rows) and its
    fitted (exponent, kappa); ``shape`` is empty where the curve could not be solved."""

    value: float
    asymptotics: tuple
    shapes: tuple
    fits: tuple


@dataclass(frozen=True)
class Diagram:
    """The two-parameter diagram over mu in [lo, hi]: the grazing curve sampled as rows
    (mu, d*(mu)) (Delta d = 0), the degenerate grazing points, and the PD and fold curves."""

    parameter: str
    lo: float
    hi: float
    base: float
    grazing: np.ndarray
    codim2: tuple
    curves: tuple
    design: bool = False


def _passes(curve: Curve, fam: Family, psi: float, value: float) -> bool:
    """Whether ``curve`` goes through (psi, value): solved at ``value`` from the
    interpolation between its two points around it."""
    pts = curve.points
    for a, b in zip(pts[:-1], pts[1:]):
        if (a.value - value) * (b.value - value) <= 0.0 and a.value != b.value:
            w = (value - a.value) / (b.value - a.value)
            try:
                at = curve_point(fam, curve.kind, value, a.psi + w * (b.psi - a.psi))
            except OrbitNotFound:
                continue
            if abs(at - psi) <= 1e-8 * max(abs(psi), 1e-6):
                return True
    return False


def two_parameter_diagram(fam: Family, lo: float, hi: float, kinds=KINDS, *,
                          max_points: int = 400, samples: int = 401,
                          check: bool = True) -> Diagram:
    """The PD and fold curves of the 1/1 orbit over mu in [lo, hi] (module docstring).

    Seeds, each curve continued once: every degenerate grazing point in the range
    (:func:`codim2_points`), then every PD and fold point of the 1/1 branch at the base
    value (:func:`branch_seeds`) that no curve found so far goes through. A seed on the
    grazing curve that an earlier curve of its kind ended at is not continued again.
    """
    for kind in kinds:
        if kind not in KINDS:
            raise ValueError(f"kind={kind!r} is invalid: valid values are {', '.join(KINDS)}")
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ParameterError(f"range=({lo!r}, {hi!r}) is invalid: valid range is finite "
                             "from < to")
    fam.at(lo), fam.at(hi)    # both ends valid parameter values, else ParameterError
    meets = {kind: codim2_points(fam, lo, hi, kind=kind) for kind in kinds}
    stars = sorted({mu for kind in kinds for mu in meets[kind]})
    curves = []

    def known(kind, mu):
        return any(c.kind == kind and any(abs(m - mu) <= 1e-12 * max(1.0, abs(mu))
                                          for m in c.codim2) for c in curves)

    for mu in stars:
        for kind in kinds:
            if mu in meets[kind] and not known(kind, mu):
                curves.append(continue_curve(fam, kind, 0.0, mu, lo, hi, max_points=max_points,
                                             check=check, seed="degenerate grazing"))
    if lo <= fam.base <= hi:
        base_p, base_gains = fam.at(fam.base)
        for kind, psi in branch_seeds(fam, kinds):
            try:   # a 1/1 orbit: one impact per period by the exact flow
                _orbit_from_phase(base_p, psi, base_gains, check=True)
            except (OrbitNotFound, ValueError, ArithmeticError):
                continue
            if not any(c.kind == kind and _passes(c, fam, psi, fam.base) for c in curves):
                curves.append(continue_curve(fam, kind, psi, fam.base, lo, hi,
                                             max_points=max_points, check=check,
                                             seed="1/1 branch at the base value"))
    points = []
    for mu in stars:
        scale = max(1.0, abs(mu))
        asym, shapes, fits = [], [], []
        for kind in (k for k in kinds if mu in meets[k]):
            asym.append(asymptotic_coefficient(fam, kind, mu))
            try:
                shape = local_shape(fam, kind, mu, [scale * x for x in SHAPE_OFFSETS])
                fit = fitted_exponent(shape, asym[-1].exponent)
            except (OrbitNotFound, ParameterError, ArithmeticError):
                shape, fit = np.empty((0, 3)), (math.nan, math.nan)
            shapes.append(shape)
            fits.append(tuple(float(x) for x in fit))
        points.append(Codim2Point(mu, tuple(asym), tuple(shapes), tuple(fits)))
    grid = np.linspace(lo, hi, samples)
    grazing = np.array([(x, fam.at(float(x))[0].d_star) for x in grid])
    return Diagram(fam.name, float(lo), float(hi), float(fam.base), grazing, tuple(points),
                   tuple(curves), fam.design)

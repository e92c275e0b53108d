"""Continuation of the 1/1 branch in Delta d and location of its bifurcations.

The branch is explicit in the impact phase offset psi = theta - tau*
(:func:`grazing_control.dynamics.orbits.orbits.wall_offset_at_phase`): psi -> (Delta d, v-, J).
Continuation therefore steps in psi, which passes folds of Delta d(psi) without special care, on
a logarithmic grid in |psi| so that points crowd towards grazing (|Delta d| down to
1e-12 and below).

Bifurcations are zeros of test functions of the exact monodromy J = M S, evaluated
from its trace and (exact) determinant (docs/theory.md, "Continuation"):

* period-doubling: det(J + I) = 1 + tr J + det J = 0 (a multiplier at -1);
* fold: det(J - I) = 1 - tr J + det J = 0 (a multiplier at +1);
* Neimark-Sacker: det J - 1 = 0 with tr^2 < 4 det (a complex pair on |lambda| = 1);
* grazing: v- = 0, at psi = 0, where Delta d = 0 exactly (the branch's end).

Each sign change between grid points is refined with Brent's method in psi to a few
ulps, so Delta d at the bifurcation is located to ~1e-14 relative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.control import Gains, gain_determinant
from grazing_control.oscillator.flow import matmul2
from grazing_control.oscillator.impact import saltation_matrix
from grazing_control.dynamics.orbits.orbits import (OrbitNotFound, _orbit_from_phase,
                                                    find_branch_phase, multipliers,
                                                    wall_offset_at_phase)
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["BranchPoint", "Bifurcation", "Branch", "continue_11", "branch_monodromy",
           "OrbitPoint", "OrbitBifurcation", "OrbitBranch", "continue_orbit"]

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class BranchPoint:
    """One point of the 1/1 branch."""

    delta_d: float
    psi: float
    v_minus: float
    multipliers: np.ndarray

    @property
    def stable(self) -> bool:
        return bool(np.max(np.abs(self.multipliers)) < 1.0)


@dataclass(frozen=True)
class Bifurcation:
    """A located bifurcation: 'period-doubling', 'fold', 'neimark-sacker' or 'grazing'."""

    type: str
    delta_d: float
    psi: float
    multipliers: np.ndarray


@dataclass(frozen=True)
class Branch:
    """Points ordered from ``start`` to ``stop``, and the bifurcations between them."""

    points: list
    bifurcations: list


def branch_monodromy(p: OscillatorParams, psi: float, gains: Gains | None = None):
    """(Delta d, v-, trace J, det J) on the 1/1 branch at impact phase tau* + psi."""
    dd, v, m = wall_offset_at_phase(p, psi, gains)
    q = p.with_(delta_d=dd)
    theta = (p.tau_star + psi) % TWO_PI
    j = matmul2(m, saltation_matrix(q, theta, v))
    g = gain_determinant(gains, p.zeta)
    det = math.exp(-2.0 * p.zeta * p.period) * p.r ** 2 * g
    return dd, v, j[0] + j[3], det


def _tests(tr, det):
    return {
        "period-doubling": 1.0 + tr + det,
        "fold": 1.0 - tr + det,
        "neimark-sacker": (det - 1.0) if tr * tr < 4.0 * det else math.nan,
    }


def _mults(tr, det):
    return multipliers(np.array([[tr, -det], [1.0, 0.0]]), det)


def continue_11(p: OscillatorParams, start: float, stop: float, gains: Gains | None = None,
                points: int = 200, check: bool = False, values=None) -> Branch:
    """Continue the 1/1 orbit born at grazing from Delta d = start to stop.

    Parameters
    ----------
    p : OscillatorParams
        The other parameters (its delta_d is ignored).
    start, stop : float
        Ends of the range, <= 0; an end equal to 0 is the grazing point itself.
    gains : Gains, optional
        Controller in the loop.
    points : int
        Number of grid points (logarithmic in |psi|), >= 2.
    check : bool
        Verify every point with the exact flow (one impact per period, periodic).
    values : sequence of float, optional
        The points' Delta d instead of the grid in psi (each one's phase by
        :func:`~grazing_control.dynamics.orbits.orbits.find_branch_phase`; a Delta d of 0 is
        the grazing orbit's phase 0 and is left out): ``grazing continue``'s grid, the same
        for every model (``one_one.continuation_values``, issue 32: the n = 1 model
        file gives the 1-DOF points).

    Returns
    -------
    Branch
    """
    if not (math.isfinite(start) and math.isfinite(stop)) or start > 0.0 or stop > 0.0:
        raise ValueError(f"start={start!r}, stop={stop!r} are invalid: valid range is "
                         "finite Delta d <= 0 (the 1/1 branch lives on the impacting side)")
    if points < 2:
        raise ValueError(f"points={points!r} is invalid: valid range is points >= 2")
    if start == stop:
        raise ValueError("start and stop must differ")
    psis = [find_branch_phase(p, dd, gains) if dd != 0.0 else 0.0 for dd in (start, stop)]
    nonzero = [s for s in psis if s != 0.0]
    sign = math.copysign(1.0, nonzero[0])
    mags = [abs(s) for s in psis]
    hi_mag = max(mags)
    # an end at grazing (psi = 0) is approached to 1e-12 of the other end's phase
    lo_mag = min(mags) if 0.0 not in mags else hi_mag * 1e-12
    grid = np.logspace(math.log10(lo_mag), math.log10(hi_mag), points)
    if mags[0] > mags[1]:
        grid = grid[::-1]
    phases = [sign * float(m) for m in grid] if values is None else \
        _phases_of(p, values, gains)
    pts = []
    for psi in phases:
        dd, v, tr, det = branch_monodromy(p, psi, gains)
        if check:
            try:
                _orbit_from_phase(p, psi, gains, check=True)
            except OrbitNotFound:
                continue
        pts.append(BranchPoint(dd, psi, v, _mults(tr, det)))
    bifs = []
    for a, b in zip(pts[:-1], pts[1:]):
        ta = _tests(*branch_monodromy(p, a.psi, gains)[2:])
        tb = _tests(*branch_monodromy(p, b.psi, gains)[2:])
        for kind in ta:
            fa, fb = ta[kind], tb[kind]
            if not (math.isfinite(fa) and math.isfinite(fb)) or fa * fb > 0.0 or fa == fb:
                continue

            def f(psi, kind=kind):
                return _tests(*branch_monodromy(p, psi, gains)[2:])[kind]

            lo, hi = sorted((a.psi, b.psi))
            psi = brentq(f, lo, hi, xtol=1e-300, rtol=4.0 * np.finfo(float).eps, maxiter=400)
            dd, v, tr, det = branch_monodromy(p, psi, gains)
            bifs.append(Bifurcation(kind, dd, psi, _mults(tr, det)))
    if 0.0 in (start, stop):
        lam = np.array([math.inf, math.inf], dtype=complex)
        if gains is not None:
            from grazing_control.dynamics.design.gains import limit_multipliers

            lam = limit_multipliers(p, gains)
        bifs.append(Bifurcation("grazing", 0.0, 0.0, lam))
    return Branch(pts, bifs)


def _phases_of(p: OscillatorParams, values, gains):
    """The impact phases of the branch's points at the Delta d ``values`` of
    :func:`continue_11` (0 and a Delta d without a 1/1 orbit on the branch left out, as
    ``check`` leaves out a point that the flow does not confirm)."""
    phases = []
    for dd in values:
        if dd != 0.0:
            try:
                phases.append(find_branch_phase(p, float(dd), gains))
            except OrbitNotFound:
                continue
    return phases


# ----------------------------------------------------------- any model, by shooting
#: The end of a branch continued by shooting is a grazing when its smallest impact
#: velocity has fallen below this fraction of the branch's largest.
GRAZED = 1e-3
#: Halvings of one failed continuation step before the branch is declared ended there.
MAX_HALVINGS = 60


@dataclass(frozen=True)
class OrbitPoint:
    """One point of a branch continued by shooting: the parameter value, the orbit's
    section state, its multipliers, and the smallest impact velocity of its impacts."""

    value: float
    state: np.ndarray
    multipliers: np.ndarray
    impacts: int
    v_min: float

    @property
    def stable(self) -> bool:
        return bool(np.max(np.abs(self.multipliers)) < 1.0)


@dataclass(frozen=True)
class OrbitBifurcation:
    """A bifurcation located on a branch continued by shooting: 'period-doubling', 'fold',
    'neimark-sacker' or 'grazing', at ``value`` of the continued parameter."""

    type: str
    value: float
    multipliers: np.ndarray


@dataclass(frozen=True)
class OrbitBranch:
    """Points in the order continued, the bifurcations located between them, and why the
    continuation stopped ('end' of the values, or the reason shooting failed)."""

    parameter: str
    periods: int
    points: list
    bifurcations: list
    stopped: str


def continue_orbit(model, name: str, values, guess, periods: int = 1, *,
                   tol: float = 1e-14) -> OrbitBranch:
    """Continue a p/n orbit of any model in one parameter, by Newton shooting.

    Written once over the model protocol (:class:`grazing_control.dynamics.maps.model.PeriodMap`):
    at each value of ``name`` (in the order given) the orbit is found by
    :func:`~grazing_control.dynamics.orbits.shooting.find_periodic` from a secant predictor
    through the last two points (the first from ``guess``). Between neighbours the test
    functions of :func:`~grazing_control.dynamics.orbits.shooting.bifurcation_tests` are
    compared; a sign change is refined by Brent's method in the parameter, each
    evaluation a shooting from the nearer neighbour. A step where shooting fails or the
    orbit's number of impacts changes is halved and retried with the secant predictor
    from the last orbit, and after a success the continuation goes on (a predictor from
    too far can land on a coexisting orbit: the non-impacting one next to a grazing
    with Delta d > 0, issue 17); the continuation stops where the step has been halved
    :data:`MAX_HALVINGS` times: past its last point the orbit has grazed (an impact
    velocity went to 0) or changed type (every orbit found on the way is kept, so
    points between the given values may appear). A 'grazing' event is then located where v-_min,
    extrapolated as v-_min^2 linear in the parameter through the last point and the
    last with twice its v-_min (the
    square-root law of grazing, docs/theory.md section 5), vanishes, when it falls
    towards 0 and the end's v-_min is below :data:`GRAZED` times the branch's largest (a
    fold, or a Newton failure in the singular regime next to grazing, ends the branch
    without a grazing event: the 1-DOF 1/1 branch without control is found only down to
    |Delta d| ~ 1e-6 by shooting, its multiplier growing like |Delta d|^(-1) (v- is
    linear in Delta d there, measured: docs/theory_ndof_flow.md, section 8); the
    explicit route reaches 1e-12). Where v- is linear in the parameter the square-root
    extrapolation puts the grazing 2/3 of the last point's distance from it: the halved
    steps make that distance small.

    For the 1-DOF 1/1 branch the explicit impact-phase route (:func:`continue_11`) is
    exact to rounding; this one agrees with it to the shooting tolerance (tests).
    """
    from grazing_control.dynamics.orbits.shooting import (TEST_FUNCTIONS, ShootingFailed, bifurcation_tests, find_periodic,
                           floquet_multipliers)

    values = [float(v) for v in values]
    if len(values) < 2 or not all(math.isfinite(v) for v in values):
        raise ValueError("values are invalid: expected at least two finite parameter values")
    model.parameter(name)    # a parameter of the model, else ValueError naming the valid ones

    def solve(value, start):
        m = model.with_parameter(name, value)
        o = find_periodic(m, start, periods, tol=tol)
        det = m.jacobian_det(periods, len(o.impacts))
        if any(getattr(i, "sticking", False) for i in o.impacts):
            det = None
        lam = floquet_multipliers(o.monodromy, det)
        v_min = min((i.v_minus for i in o.impacts), default=math.inf)
        return OrbitPoint(value, o.state, lam, len(o.impacts), v_min)

    def predict(value):
        """Secant through the last two points (the first from ``guess``)."""
        if len(points) >= 2:
            a, b = points[-2], points[-1]
            t = (value - b.value) / (b.value - a.value)
            return b.state + t * (b.state - a.state)
        return points[-1].state if points else guess

    points, stopped, failed_at = [], "end", None
    for value in values:
        # step to ``value``; a failed step (shooting fails, or the orbit's impact count
        # changes: a poor predictor can land in the basin of a coexisting orbit) is halved
        # and retried from the last orbit with the secant predictor, and after a success
        # the continuation goes on to ``value``: a real end of the branch is where the
        # step has been halved MAX_HALVINGS times (docs/theory_ndof_flow.md, section 8)
        trial, halvings, first = value, 0, None
        while failed_at is None:
            try:
                pt, reason = solve(trial, predict(trial)), None
            except (ShootingFailed, ValueError, ArithmeticError) as exc:
                pt, reason = None, f"shooting failed at {name}={trial!r}: {exc}"
            if pt is not None and points and pt.impacts != points[-1].impacts:
                reason = (f"the orbit changed from {points[-1].impacts} to {pt.impacts} impacts "
                          f"between {name}={points[-1].value!r} and {trial!r}")
                pt = None
            if pt is not None:
                points.append(pt)
                if trial == value:
                    break
                trial = value
                continue
            first = first if halvings else reason  # the failure at the value itself
            mid = 0.5 * (points[-1].value + trial) if points else trial
            if not points or halvings >= MAX_HALVINGS or mid in (points[-1].value, trial):
                stopped, failed_at = first, trial
                break
            trial, halvings = mid, halvings + 1
        if failed_at is not None:
            break

    bifs = []
    for a, b in zip(points[:-1], points[1:]):
        ta, tb = bifurcation_tests(a.multipliers), bifurcation_tests(b.multipliers)
        for kind in TEST_FUNCTIONS:
            fa, fb = ta[kind], tb[kind]
            if not (math.isfinite(fa) and math.isfinite(fb)) or fa * fb > 0.0 or fa == fb:
                continue

            def f(value, kind=kind, a=a, b=b):
                near = a if abs(value - a.value) <= abs(value - b.value) else b
                return bifurcation_tests(solve(value, near.state).multipliers)[kind]

            try:
                at = brentq(f, a.value, b.value, xtol=1e-300, rtol=1e-13, maxiter=200)
                pt = solve(at, a.state)
            except (ShootingFailed, ValueError, ArithmeticError):
                continue
            bifs.append(OrbitBifurcation(kind, float(at), pt.multipliers))
    if failed_at is not None and len(points) >= 2:
        b = points[-1]   # a: the last point whose v-_min is resolved against b's
        a = next((q for q in reversed(points[:-1]) if q.v_min >= 2.0 * b.v_min), points[-2])
        at = math.nan
        if 0.0 < b.v_min < a.v_min:
            at = b.value - b.v_min ** 2 * (b.value - a.value) / (b.v_min ** 2 - a.v_min ** 2)
        v_scale = max(q.v_min for q in points)
        if b.v_min <= GRAZED * v_scale and math.isfinite(at):
            bifs.append(OrbitBifurcation("grazing", float(at),
                                         np.array([math.inf, math.inf], dtype=complex)))
    return OrbitBranch(name, int(periods), points, bifs, stopped)

"""Impacts of the n-DOF oscillator: certified detection, impact law, saltation (issue 17).

The flow between impacts is the exact modal flow of
:class:`~grazing_control.oscillator.ndof.flow.NdofFlow` in deviation coordinates. An
impact is the first h > 0 with gap g(h) = x_w(h) - d = 0 and v_w >= 0; the search must
never miss a low-velocity (near-grazing) impact and never report a spurious one.

Certified search (docs/theory_ndof_flow.md, section 4)
-----------------------------------------------------
The gap is the forced harmonic plus a sum of damped modes,

    g(h) = sum_k Re(c_k e^{lambda_k h}) - Delta d - 2 d* sin^2(psi / 2),
    psi = tau0 + omega h - tau*,

(c_k = w_k V_{i_w k} (V^-1 z0)_k, one term per real eigenvalue or conjugate pair), so

    |g'''(h)| <= d* omega^3 + sum_k |c_k| |lambda_k|^3 e^{Re(lambda_k) h}

bounds the jerk on [h, inf) (Re lambda_k <= 0). With this J the interval logic of the
1-DOF search (oscillator/impact.py, docs/theory.md section 2: convex/concave intervals,
the chord bound, bisection, bracketed Newton) applies unchanged and is reused from
there; only the evaluator, its bounds and its rounding margins are n-DOF.

The impact law v_w+ = -r v_w- (other velocities unchanged) at x_w = d is applied in
deviation coordinates; :func:`saltation_matrix` is its (2n x 2n) saltation matrix.

Chattering and sticking (issue 32; docs/theory_ndof.md, section 16)
-------------------------------------------------------------------
As in 1-DOF (oscillator/impact.py): a contact at rest pushed into the wall, or a
chattering sequence that would accumulate (t_inf = 2 r v- / ((1 - r) F) below
``chatter_time``, or a next bounce below resolution; F the free acceleration of x_w at
rest on the wall), is summed and the wall coordinate sticks: x_w = d, v_w = 0 while the
other coordinates move by the constrained flow of :mod:`.sticking`, until the contact
force changes sign (a certified root search); it is reported as a sticking impact with
its release. Only a stuck motion that cannot be modelled (:class:`.sticking.StuckFlow`'s
refusals) raises :class:`ChatteringError`; any other accumulation of contacts hits the
cap ``max_impacts`` (:class:`ImpactCapError`). The trajectory never passes through the
wall and the search never hangs.
"""

from __future__ import annotations

import cmath
import functools
import math
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator import kernel
from grazing_control.oscillator.impact import (MAX_AMPLITUDE, GapEvaluator, Impact,
                                               ImpactCapError, InitialStateError,
                                               NonFiniteStateError, _scan_window, check_times,
                                               wall_rounding)
from grazing_control.oscillator.params import ParameterError

from .flow import NdofFlow, matvec
from .sticking import stuck_flow

__all__ = ["NdofImpact", "NdofSegment", "ChatteringError", "ImpactCapError",
           "InitialStateError", "NonFiniteStateError", "check_state", "next_impact",
           "saltation_matrix", "saltation_parts", "advance"]

TWO_PI = 2.0 * math.pi
_EPS = 2.0 ** -52


#: One impact (:class:`grazing_control.oscillator.impact.Impact`, the same for every n):
#: ``sticking`` marks a stick (the end of a summed chattering sequence, or a contact at
#: rest pushed into the wall), ``release`` its end (time since the segment's start; inf
#: if still stuck at the segment's end; nan for other impacts).
NdofImpact = Impact


class NdofSegment(NamedTuple):
    """Result of :func:`advance`: final deviation z (2n,), final phase, impacts, and the
    monodromy d z(end) / d z(start) ((2n, 2n)) or None."""

    z: np.ndarray
    tau: float
    impacts: list
    monodromy: np.ndarray | None


class ChatteringError(RuntimeError):
    """The wall coordinate sticks but its constrained motion cannot be modelled (the
    refusals of :class:`.sticking.StuckFlow`: the others without a static equilibrium,
    a resonance or a defective reduced flow). The message names the time."""


def check_state(flow: NdofFlow, z, where: str = "the state") -> np.ndarray:
    """z as a float array of shape (2n,), finite and not absurdly large, else raise.

    Raises
    ------
    ParameterError
        Wrong shape.
    NonFiniteStateError
        Not finite, or its modal size cond(V) max|z| exceeds
        :data:`~grazing_control.oscillator.impact.MAX_AMPLITUDE`.
    """
    try:
        a = np.array(z, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError(f"{where}={z!r} is invalid: expected {2 * flow.n} real numbers") from None
    if a.shape != (2 * flow.n,):
        raise ParameterError(f"{where} has {a.size} entries: valid is 2n = {2 * flow.n}")
    largest = float(np.abs(a).max())     # nan or inf where an entry is
    if not math.isfinite(largest):
        raise NonFiniteStateError(f"{where} is not finite: deviation z = {a.tolist()!r}")
    size = flow.condition * largest
    if not size <= MAX_AMPLITUDE:
        raise NonFiniteStateError(
            f"{where} is absurdly large: cond(V) max|z| = {size:.3e} > {MAX_AMPLITUDE:.0e}; "
            f"an input overflowed")
    return a


def _velocity_sizes(k: "SearchConstants", z) -> tuple:
    """(sum_k |w_k V_wk| |lambda_k| sum_l |U_kl z_l|, |z|): the bound of the terms of v_w
    and the deviation's size (section 5, "Rounding"), from the flow's
    :func:`search_constants`, in Python floats (the terms of z_w are the evaluator's
    ``zmag``)."""
    size = norm2 = 0.0
    zs = [float(x) for x in z]
    for va, lam, row_abs in zip(k.vw_abs, k.lam, k.inverse_abs):
        s = 0.0
        for ua, zl in zip(row_abs, zs):
            s += ua * abs(zl)
        size += va * abs(lam) * s
    for zl in zs:
        norm2 += zl * zl
    return size, math.sqrt(norm2)


class SearchConstants(NamedTuple):
    """What the certified search needs of a flow that does not depend on the start
    (:func:`search_constants`, computed once per flow): the eigenvalues ``lam`` (one per
    real eigenvalue or conjugate pair), the wall coordinate's row of the weighted modes
    ``vw`` and the left eigenvectors ``inverse`` (rows), as Python complex numbers (lists);
    |vw_k|, |inverse_kl|, |lambda_k|^3 and rho = max |lambda_k|; d* omega^3; the drift
    scale defect cond(V)^2 (docs/theory_ndof_flow.md, section 5); the default initial
    window min(T / 8, pi / (4 rho)); and, for the compiled search
    (oscillator/kernel/compiled_modal.py), the same in two float arrays: ``table``, a row
    a mode (Re lam, Im lam, Re vw, Im vw, |vw|, |lam|^3, then Re, Im and |.| of the row of
    the inverse, 2n columns each), and ``scalars`` (omega, tau*, d*, Delta d, n,
    d* omega^3, defect cond(V)^2, omega^2, rho, rho^2, the default window, 2.0, then for
    the compiled :func:`advance`: r, i_w, cond(V), MAX_AMPLITUDE) (powers computed here,
    as the evaluator computes them, so that both use the same floats); and for the
    compiled :func:`advance`, :meth:`NdofFlow.transition`'s operands (Re and Im of the
    weighted modes and of the inverse's rows) and A, as fresh float arrays."""

    lam: list
    vw: list
    inverse: list
    vw_abs: list
    inverse_abs: list
    lam3: list
    rho: float
    aw3: float
    drift_scale: float
    step: float
    table: np.ndarray
    scalars: np.ndarray
    modes_re: np.ndarray
    modes_im: np.ndarray
    inverse_re: np.ndarray
    inverse_im: np.ndarray
    A: np.ndarray


@functools.lru_cache(maxsize=64)
def search_constants(flow: NdofFlow) -> SearchConstants:
    """The :class:`SearchConstants` of ``flow`` (kept for the 64 flows used last; a flow
    is hashed by identity)."""
    m = flow.model
    lam = [complex(x) for x in flow.eigenvalues]
    vw = [complex(x) for x in flow.modes[m.i_w]]
    inverse = [[complex(x) for x in row] for row in flow.inverse]
    vw_abs = [abs(x) for x in vw]
    inverse_abs = [[abs(x) for x in row] for row in inverse]
    lam3 = [abs(x) ** 3 for x in lam]
    rho = max(abs(x) for x in lam)
    table = np.array([[l.real, l.imag, v.real, v.imag, va, l3] + [x.real for x in row]
                      + [x.imag for x in row] + row_abs
                      for l, v, va, l3, row, row_abs in zip(lam, vw, vw_abs, lam3, inverse,
                                                            inverse_abs)], dtype=float)
    aw3 = flow.d_star * m.omega ** 3
    drift_scale = flow.defect * flow.condition ** 2
    step = min(m.period / 8.0, 0.25 * math.pi / rho)
    scalars = np.array([m.omega, flow.tau_star, flow.d_star, m.delta_d, m.n, aw3,
                        drift_scale, m.omega ** 2, rho, rho ** 2, step, 2.0, m.r, m.i_w,
                        flow.condition, MAX_AMPLITUDE])
    modes, inv = flow.modes, flow.inverse
    return SearchConstants(lam, vw, inverse, vw_abs, inverse_abs, lam3, rho, aw3, drift_scale,
                           step, table, scalars, modes.real.copy(), modes.imag.copy(),
                           inv.real.copy(), inv.imag.copy(), np.array(flow.A, dtype=float))


class _Eval(GapEvaluator):
    """Gap, velocity and acceleration of the wall coordinate along the free flow from one
    start (docs/theory_ndof_flow.md, section 4); the interface of the 1-DOF evaluator that
    oscillator.impact._search and _bracket use.

    Its set-up is written out term by term in Python floats (no NumPy reduction, whose
    order of summation is NumPy's and its BLAS's): the compiled search
    (oscillator/kernel/compiled_modal.py) mirrors it operation for operation, and so gives
    the same floats (tests/test_ndof_compiled.py)."""

    __slots__ = ("terms", "cabs", "jerk_terms", "aw3", "acc_err", "m0", "m1", "zmag", "rho",
                 "drift", "n", "horizon")

    def __init__(self, flow: NdofFlow, tau0: float, z0, horizon: float,
                 transient: tuple | None = None):
        m = flow.model
        k = search_constants(flow)
        zs = [float(x) for x in z0]
        lam, vw_abs, lam3 = list(k.lam), list(k.vw_abs), list(k.lam3)
        c, sizes = [], []
        for vwk, row, row_abs in zip(k.vw, k.inverse, k.inverse_abs):
            br = bi = s = 0.0
            for u, ua, zl in zip(row, row_abs, zs):      # beta_k = (V^-1 z0)_k
                br += u.real * zl
                bi += u.imag * zl
                s += ua * abs(zl)
            c.append(complex(vwk.real * br - vwk.imag * bi, vwk.real * bi + vwk.imag * br))
            sizes.append(s)
        rho = k.rho
        if transient is not None:     # one more decaying real mode of the gap, coef e^{-rate h}
            rate, coef = transient    # (an actuator's lag, oscillator/ndof/forced.py)
            lam.append(complex(-rate))
            c.append(complex(coef))
            lam3.append(rate ** 3)
            rho = max(rho, rate)
        self.terms = [(l, ck, ck * l, ck * l * l) for l, ck in zip(lam, c)]
        super().__init__(m.omega, flow.tau_star, flow.d_star, m.delta_d, tau0)
        self.horizon = horizon
        self.n = m.n
        # 1 unless rounding made Re lambda > 0
        grow = [math.exp(max(l.real, 0.0) * horizon) for l in lam]
        cabs = 0.0
        for ck, g in zip(c, grow):
            cabs += abs(ck) * g
        self.cabs = cabs
        self.jerk_terms = [(l.real, abs(ck) * l3, g) for l, ck, l3, g in zip(lam, c, lam3, grow)]
        self.aw3 = k.aw3
        # rounding (docs/theory_ndof_flow.md, section 5): terms of size zmag, and the
        # decomposition's defect, which moves z by <= t defect cond(V)^2 |z0| after time t
        zmag = 0.0
        for va, s in zip(vw_abs, sizes):
            zmag += va * s
        self.zmag = zmag * max(grow) + (abs(transient[1]) if transient is not None else 0.0)
        self.rho = rho
        norm2 = 0.0
        for zl in zs:
            norm2 += zl * zl
        self.drift = k.drift_scale * math.sqrt(norm2)
        n2 = 2.0 * self.n + 2.0
        phase0 = abs(tau0) + abs(self.lag) + 1.0
        self.acc_err = (8.0 * _EPS * (self.amp * self.omega ** 2 * (4.0 + phase0 + self.omega * horizon)
                                      + self.zmag * self.rho ** 2 * (n2 + self.rho * horizon))
                        + 2.0 * horizon * self.drift * self.rho ** 2)
        self.m0 = 8.0 * _EPS * (self.zmag * n2 + abs(self.dd) + 2.0 * self.amp * (1.0 + phase0))
        self.m1 = 8.0 * _EPS * (self.zmag * self.rho + 2.0 * self.amp * self.omega) + 2.0 * self.drift

    def __call__(self, h: float):
        """(g, v, acc, z_w) at time h: the exact closed form."""
        zx = v = a = 0.0
        for lam, c, cl, cl2 in self.terms:
            e = cmath.exp(lam * h)
            zx += (c * e).real
            v += (cl * e).real
            a += (cl2 * e).real
        psi = self.tau0 + self.omega * h - self.lag
        sh = math.sin(0.5 * psi)
        g = zx - self.dd - 2.0 * self.amp * sh * sh
        vel = -self.amp * self.omega * math.sin(psi) + v
        acc = -self.amp * self.omega * self.omega * math.cos(psi) + a
        return g, vel, acc, zx

    def jerk_bound(self, h: float) -> float:
        """J >= max |g'''| on [h, horizon]: d* omega^3 + sum |c_k| |lambda_k|^3 e^{Re lambda_k h}."""
        j = self.aw3
        for re, a, grow in self.jerk_terms:
            j += a * (math.exp(re * h) if re <= 0.0 else grow)
        return j

    def gap_rounding(self, h: float, vals) -> float:
        """Bound on |computed g(h) - exact g(h)| (docs/theory_ndof_flow.md, section 5)."""
        g, zx = vals[0], vals[3]
        s2 = abs(zx - self.dd - g)
        phase = abs(self.tau0) + self.omega * h + abs(self.lag) + 1.0
        return (8.0 * _EPS * (self.zmag * (2.0 * self.n + 2.0 + self.rho * h) + abs(self.dd) + s2
                              + math.sqrt(2.0 * self.amp * s2) * phase)
                + 2.0 * h * self.drift)


def next_impact(flow: NdofFlow, tau0: float, z0, horizon: float,
                max_step: float | None = None) -> float | None:
    """Time of the first impact in (0, horizon] from deviation z0 at phase tau0, or None.

    Certified (module docstring): a low-velocity impact is never missed, a spurious one
    never reported, up to the rounding margins of docs/theory_ndof_flow.md section 5. The
    start may be on the wall (g = 0); a root at h = 0 is reported only if v_w > 0.

    Parameters
    ----------
    flow : NdofFlow
    tau0 : float
        Forcing phase at the start.
    z0 : (2n,) array_like
        Deviation from X_p at the start (x_w <= d required).
    horizon : float
        Length of the window.
    max_step : float, optional
        Initial subdivision (default min(T / 8, pi / (4 max|lambda|))).

    Returns
    -------
    float or None
        Time since the start of the first impact.
    """
    z = check_state(flow, z0, "the start state")
    check_times(tau0, "horizon", horizon)
    return _next_impact(flow, tau0, z, horizon, max_step)


def _next_impact(flow, tau0, z0, horizon, max_step=None):
    """:func:`next_impact` without the checks of its inputs: compiled
    (oscillator/kernel/compiled_modal.py, the same floats) once
    :func:`grazing_control.oscillator.kernel.warm_up_modal` has loaded it and while the
    kernel is in use, else this module's search."""
    if horizon <= 0.0:
        return None
    compiled = kernel.modal_search()
    if compiled is not None:
        k = search_constants(flow)
        h, beyond = compiled(k.table, k.scalars, float(tau0), z0, float(horizon),
                             float(max_step or 0.0))
        if beyond is not None:
            _beyond_wall(beyond)
        return h
    f = _Eval(flow, tau0, z0, horizon)
    # whole-window exclusion: g <= sup |z_w| - Delta d <= sum |c_k| - Delta d
    if f.cabs * (1.0 + 4.0 * _EPS) + f.m0 + f.m1 * horizon < f.dd:
        return None
    step = max_step or search_constants(flow).step
    count = max(1, int(math.ceil(horizon / step)))
    return _scan_window(f, horizon, count, lambda fa: f.gap_rounding(0.0, fa), "x_w")


def _beyond_wall(gap: float):
    """Raise the :class:`InitialStateError` of oscillator.impact._scan_window for the
    computed gap ``gap`` > 0 at the start."""
    raise InitialStateError(f"state beyond the wall: x_w - d = {gap:.3e} > 0 (valid: x_w <= d)")


def saltation_matrix(flow: NdofFlow, phase: float, z_minus) -> np.ndarray:
    """Saltation matrix of the impact x_w = d, v_w+ = -r v_w- (docs/theory_ndof_flow.md,
    section 6), (2n, 2n), from the deviation z_minus just before it at ``phase``.

    S = R + (F+ - R F-) e_w^T / (e_w^T F-), R = I - (1 + r) e_{n+w} e_{n+w}^T, which
    reduces to S = R + u e_w^T with

        u = (1 + r) (-e_w ; M^-1 C e_w + (a_w- / v_w-) e_w),

    a_w-, v_w- the wall coordinate's acceleration and velocity before the impact; for
    n = 1 this is [[-r, 0], [(1 + r)(cos tau - d) / v-, -r]] (docs/theory.md, section 3).
    det S = r^2. It is :func:`saltation_parts` with its singular entry added.
    """
    S, singular = saltation_parts(flow, phase, z_minus)
    m = flow.model
    S[m.n + m.i_w, m.i_w] += singular
    return S


def saltation_parts(flow: NdofFlow, phase: float, z_minus, v_minus: float | None = None):
    """(S0, s): the saltation matrix as S = S0 + s e_{n+w} e_w^T, with S0 bounded and
    s = (1 + r) a_w- / v_w- the entry that grows like 1/v- near grazing
    (:func:`saltation_matrix`). Kept apart, the rank-one singular term lets the
    multipliers of a near-grazing orbit be computed without the loss of digits of
    an eigen-solver on a matrix with an entry ~1/v- (dynamics/orbits/modal_branch.py,
    ``structured_multipliers``). ``v_minus``: v_w- where it is known better than from
    the phase (near grazing v_w- = -d* omega sin(phase - tau*) + z_{n+w} loses the
    relative digits that the rounding of phase ~ tau* takes from a small phase - tau*;
    the 1/1 branch has it free of that rounding).
    """
    m = flow.model
    n, w, r = m.n, m.i_w, m.r
    z = np.asarray(z_minus, dtype=float)
    v = flow.wall_velocity(phase, z) if v_minus is None else float(v_minus)
    if not v > 0.0:
        raise ValueError(f"v_minus={v!r} is invalid: the saltation matrix needs v_w- > 0")
    a = flow.wall_acceleration(phase, z)
    S = np.eye(2 * n)
    S[n + w, n + w] = -r
    S[w, w] -= 1.0 + r
    S[n:, w] -= (1.0 + r) * flow.A[n:, n + w]
    return S, (1.0 + r) * a / v


def _jerk_at_rest(flow: NdofFlow, tau: float, z: np.ndarray) -> float:
    """g''' at (tau, z): d* omega^3 sin psi + (A^2 z)_{n+w}."""
    m = flow.model
    row = flow.A[m.n + m.i_w] @ flow.A
    return flow.d_star * m.omega ** 3 * math.sin(tau - flow.tau_star) + float(row @ z)


def _release_skip(flow: NdofFlow, tau: float, z: np.ndarray) -> float:
    """Time after leaving the wall at rest during which the gap stays below its rounding
    (g ~ F h^2 / 2 + F' h^3 / 6, F <= 0): no impact is possible there."""
    m = flow.model
    eps = 8.0 * math.ulp(abs(z[m.i_w]) + abs(m.delta_d) + 2.0 * flow.d_star)
    force = abs(flow.wall_acceleration(tau, z))
    jerk = abs(_jerk_at_rest(flow, tau, z))
    times = [math.sqrt(2.0 * eps / force)] if force > 0.0 else []
    if jerk > 0.0:
        times.append((6.0 * eps / jerk) ** (1.0 / 3.0))
    return min(times) if times else 0.0


def _roundings(flow: NdofFlow, tau: float, z: np.ndarray):
    """(gap, velocity) rounding of a state at phase tau (docs/theory_ndof_flow.md, section 5):
    :func:`grazing_control.oscillator.impact.wall_rounding` of the wall coordinate."""
    m = flow.model
    return wall_rounding(tau, flow.tau_star, flow.d_star, m.omega, m.delta_d,
                         z[m.i_w], z[m.n + m.i_w])


def _resting_on_wall(flow: NdofFlow, tau: float, z: np.ndarray) -> bool:
    """x_w = d and v_w = 0 up to the rounding of the deviation coordinates and the phase."""
    eg, ev = _roundings(flow, tau, z)
    return abs(flow.gap(tau, z)) <= eg and abs(flow.wall_velocity(tau, z)) <= ev


def advance(flow: NdofFlow, tau0: float, z0, duration: float, *, monodromy: bool = False,
            max_impacts: int = 10000, chatter_time: float | None = None) -> NdofSegment:
    """Flow with impacts for a fixed time: the exact event-driven trajectory segment.

    Parameters
    ----------
    flow : NdofFlow
    tau0 : float
        Forcing phase at the start.
    z0 : (2n,) array_like
        Deviation from X_p at the start (x_w <= d).
    duration : float
        Time to advance, >= 0.
    monodromy : bool
        Also return d z(end) / d z(start): Phi over each smooth piece and S at each impact,
        in time order (docs/theory_ndof_flow.md, section 7).
    max_impacts : int
        Cap on contacts (impacts and tangencies) in this call: :class:`ImpactCapError`.
    chatter_time : float, optional
        A chattering sequence whose accumulation time 2 r v- / ((1 - r) F) is below this
        (default 1e-6 T), or whose next bounce v+^2 / (2 F) is below ~1e3 ulps of the gap,
        is summed and x_w sticks (F > 0: the free acceleration of x_w at rest on the wall
        pushes into it), as in 1-DOF.

    Returns
    -------
    NdofSegment

    Notes
    -----
    Without the monodromy it runs compiled once
    :func:`grazing_control.oscillator.kernel.warm_up_modal` has loaded the kernel and while
    it is in use (:func:`grazing_control.oscillator.kernel.modal_advance`, the same floats:
    tests/test_ndof_compiled.py); a stick, a contact at rest or a refused start is left
    to this function's own loop, from the start.

    A contact whose approach velocity is within the velocity's rounding of 0 is a
    contact at rest (docs/theory.md, "Tangency below rounding"): with F <= 0 a tangency,
    not an impact (nothing reported, the flow goes on); with F > 0 it sticks. A stick is
    reported as an impact with ``sticking`` True (v- = v+ = 0 for a contact at rest) and
    its ``release``; meanwhile the others move by the constrained flow
    (docs/theory_ndof.md, section 16) and the monodromy is that flow's on the others (the
    wall coordinate's perturbations die). Every other reported impact has v- > 0.

    Raises
    ------
    NonFiniteStateError, ParameterError
        Bad start state, tau0 or duration.
    InitialStateError
        The start lies beyond the wall.
    ImpactCapError
        See above.
    ChatteringError
        A stick whose constrained motion cannot be modelled (:class:`ChatteringError`).
    """
    z = check_state(flow, z0, "the start state")
    check_times(tau0, "duration", duration)
    m = flow.model
    n, w, r, omega = m.n, m.i_w, m.r, m.omega
    chatter = chatter_time if chatter_time is not None else 1e-6 * m.period
    consts = search_constants(flow)
    compiled = None if monodromy else kernel.modal_advance()
    if compiled is not None:     # the same floats (oscillator/kernel/compiled_modal.py)
        out = compiled(consts, float(tau0), z, float(duration), float(chatter),
                       int(max_impacts))
        if out is not None:
            return NdofSegment(out[0], out[1], [NdofImpact(*row) for row in out[2]], None)
    rho = consts.rho
    impacts = []
    mono = np.eye(2 * n) if monodromy else None
    t = 0.0
    tau = tau0
    contacts = 0
    h = 0.0 if _resting_on_wall(flow, tau, z) else \
        (_next_impact(flow, tau, z, duration) if duration > 0.0 else None)
    while True:
        remaining = duration - t
        if h is None or remaining <= 0.0:
            if remaining > 0.0:
                phi = flow.transition(remaining)
                z = matvec(phi, z)
                if monodromy:
                    mono = phi @ mono
                tau = (tau + omega * remaining) % TWO_PI
            return NdofSegment(z, tau, impacts, mono)
        if contacts >= max_impacts:
            raise ImpactCapError(
                f"more than max_impacts={max_impacts} impacts in {duration:.6g} time units "
                f"at phase {tau % TWO_PI:.6f}: the motion is not resolvable at this cap")
        contacts += 1
        # velocity rounding after the flow (docs/theory_ndof_flow.md, section 5)
        size, norm = _velocity_sizes(consts, z)
        flow_err = (8.0 * _EPS * size * (2.0 * n + 2.0 + rho * h)
                    + 2.0 * h * rho * consts.drift_scale * norm)
        phi = flow.transition(h)
        z = matvec(phi, z)
        if monodromy:
            mono = phi @ mono
        t += h
        tau = (tau + omega * h) % TWO_PI
        wall_x, rest_v = flow.on_wall(tau)  # x_w = d, v_w = 0 at this phase
        vp = -rest_v
        v_minus = vp + z[n + w]
        v_tol = _roundings(flow, tau, z)[1] + flow_err
        if v_minus <= v_tol:  # contact at rest, below the velocity's rounding
            z[w] = wall_x
            z[n + w] = rest_v
            if flow.wall_acceleration(tau, z) > 0.0:  # pushed into the wall: sticks
                t_hit, tau_hit = t, tau
                t, tau, z, mono, release = _stick(flow, tau0, t, 0.0, duration, z, mono)
                impacts.append(NdofImpact(t_hit, tau_hit, 0.0, 0.0, True, release))
                h = _next_impact(flow, tau, z, duration - t) if t < duration else None
                continue
            t, tau, z, mono = _leave_wall(flow, tau0, t, duration, z, mono)
            h = _next_impact(flow, tau, z, duration - t) if t < duration else None
            continue
        z_minus, z, v_minus, delta = _impact_law(flow, tau, z, wall_x, v_minus)
        v_plus = -r * v_minus
        tau_i = (tau - omega * delta) % TWO_PI
        rest = z_minus.copy()
        rest[n + w] = flow.on_wall(tau_i)[1]
        force = flow.wall_acceleration(tau_i, rest)  # free acceleration of x_w at rest on the wall
        if force > 0.0:
            t_inf = 2.0 * r * v_minus / ((1.0 - r) * force) if r < 1.0 else math.inf
            height = (r * v_minus) ** 2 / (2.0 * force)
            if t_inf < chatter or height < 1e3 * math.ulp(abs(z[w]) + abs(m.delta_d) + flow.d_star):
                # chattering: the geometric sequence is summed and x_w sticks (docs/theory.md
                # "Chattering and sticking"; docs/theory_ndof.md section 16)
                t_hit = t - delta
                # r = 1 never accumulates (t_inf = inf): bounces below resolution stick now
                t, tau, z, mono, release = _stick(flow, tau0, t, t_inf if t_inf < math.inf else 0.0,
                                                  duration, z, mono)
                impacts.append(NdofImpact(t_hit, tau_i, v_minus, v_plus, True, release))
                h = _next_impact(flow, tau, z, duration - t) if t < duration else None
                continue
        impacts.append(NdofImpact(t - delta, tau_i, v_minus, v_plus, False))
        if monodromy:
            mono = saltation_matrix(flow, tau_i, z_minus) @ mono
        h = _next_impact(flow, tau, z, duration - t) if t < duration else None


def _impact_law(flow: NdofFlow, tau: float, z: np.ndarray, wall_x: float, v: float):
    """The impact law applied at the exact impact time t - delta, seen at the float time t
    the search returned (docs/theory_ndof_flow.md, section 6).

    The flight has overshot the wall by g = z_w - wall_x (a few ulps of time: delta = g / v,
    either sign). To first order in delta the exact state before the impact is
    z- = z - delta A z, with v- = v - delta a_w, and the state at t after it is
    z+ = R z + u g in physical terms: v_w -> -r v_w, plus the saltation column
    u = (1 + r)(-e_w ; M^-1 C e_w + (a_w / v) e_w) times the overshoot. A correction that
    would not be small (|delta a_w| > 1e-6 v) is not made: the state is put on the wall.

    Returns (z-, z+, v-, delta).
    """
    m = flow.model
    n, w, r = m.n, m.i_w, m.r
    overshoot = float(z[w] - wall_x)
    acc = flow.wall_acceleration(tau, z)
    delta = overshoot / v
    if not abs(delta * acc) <= 1e-6 * v:
        overshoot = delta = 0.0
    # before the impact, at phase tau - omega delta (deviation coordinates: z' = A z)
    z_minus = z - delta * matvec(flow.A, z)
    z_minus[w] = flow.on_wall(tau - m.omega * delta)[0]
    v_minus = v - delta * acc
    z_plus = z.copy()
    z_plus[n + w] -= (1.0 + r) * v
    if overshoot != 0.0:
        z_plus[w] -= (1.0 + r) * overshoot
        z_plus[n:] -= (1.0 + r) * overshoot * flow.A[n:, n + w]
        z_plus[n + w] += (1.0 + r) * overshoot * acc / v
    else:
        z_plus[w] = wall_x
    return z_minus, z_plus, v_minus, delta


def _stick(flow: NdofFlow, tau0: float, t: float, t_inf: float, duration: float,
           z: np.ndarray, mono):
    """x_w sticks from time t (docs/theory_ndof.md, section 16): the other coordinates
    move by the constrained flow (oscillator/ndof/sticking.py) until the contact force
    turns non-positive, searched from t + t_inf (the summed chattering sequence ends
    there), or to the end of the segment. As in 1-DOF (oscillator/impact.py) the wall
    coordinate leaves from rest and flows without a search while its gap is below the
    rounding. The monodromy through the stick is the constrained flow's on the others
    (the wall coordinate's perturbations die).

    Returns (t, tau, z, mono, release), release the time of the release since the
    segment's start, inf if still stuck at its end.

    Raises
    ------
    ChatteringError
        The constrained motion cannot be modelled (:class:`StuckFlow`'s refusals).
    """
    try:
        stuck = stuck_flow(flow)
    except ParameterError as exc:
        raise ChatteringError(f"the wall coordinate x{flow.model.i_w} sticks at t={t:.9g}: "
                              f"{exc}") from None
    omega = flow.model.omega
    tau = (tau0 + omega * t) % TWO_PI
    Y0 = stuck.reduce(tau, z)
    remaining = duration - t
    h = stuck.release(tau, Y0, min(t_inf, remaining), remaining)
    release = math.inf if h is None else t + h
    h = remaining if h is None else h
    Y = stuck.state(tau, Y0, h)
    if mono is not None:
        mono = stuck.embedded(h) @ mono
    t = t + h if h < remaining else duration
    tau = (tau0 + omega * t) % TWO_PI
    z = stuck.expand(tau, Y)
    if release <= duration and t < duration:
        t, tau, z, mono = _leave_wall(flow, tau0, t, duration, z, mono)
    return t, tau, z, mono, release


def _leave_wall(flow: NdofFlow, tau0: float, t: float, duration: float, z: np.ndarray, mono):
    """Leave the wall from rest at time t: flow, without searching, while the gap is below
    its rounding (no impact is possible there)."""
    tau = (tau0 + flow.model.omega * t) % TWO_PI
    skip = min(duration - t, _release_skip(flow, tau, z))
    phi = flow.transition(skip)
    z = matvec(phi, z)
    if mono is not None:
        mono = phi @ mono
    t += skip
    return t, (tau0 + flow.model.omega * t) % TWO_PI, z, mono

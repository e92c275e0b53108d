"""Compiled mirror of the n-DOF certified event search
(:func:`grazing_control.oscillator.ndof.impact.next_impact`), of the flow with impacts
(``advance``) and of the model filter's events of a period (issue 32: the rig of n
masses at physical speed).

The same algorithm as the pure path, function by function and in the same floating
point operations and order, so that it returns the same floats (tests/test_ndof_compiled.py,
thousands of seeded cases against the pure path, near-grazing ones included):

=====================  ==========================================================
here                   the pure path
=====================  ==========================================================
:func:`make_eval`      ``ndof.impact._Eval.__init__`` (written out term by term there)
:func:`evaluate`       ``_Eval.__call__`` (``cmath.exp(lam * h)`` as CPython computes it)
:func:`jerk_bound`     ``_Eval.jerk_bound``
:func:`gap_rounding`   ``_Eval.gap_rounding``
:func:`bracket`        ``oscillator.impact._bracket``
:func:`search`         ``oscillator.impact._search`` (its recursion on an explicit stack)
:func:`next_impact`    ``ndof.impact._next_impact`` with ``oscillator.impact._scan_window``,
                       ``_danger_halfwidth``, ``_far_from_wall``
:func:`transition`     ``ndof.flow.NdofFlow.transition`` (real operations, cmath.exp)
:func:`matvec`         ``ndof.flow.matvec`` and ``matmul``
:func:`advance`        ``ndof.impact.advance`` without the monodromy, with
                       ``_impact_law``, ``_roundings``, ``_velocity_sizes`` and
                       the flow's ``on_wall``, ``wall_velocity``,
                       ``wall_acceleration``; what it does not handle (a stick, a
                       contact at rest, a refused start, the cap) comes back as
                       ``STATUS_FALLBACK`` and the pure path runs from the start
:func:`modal_events`   ``dynamics.estimation.motion._modal_events`` (the model
                       filter's legs, impacts and Jacobians, with
                       :func:`saltation_matrix`)
=====================  ==========================================================

The interval search (:func:`bracket`, :func:`search`, the window's ``danger_halfwidth``
and ``far_from_wall``) is the 1-DOF kernel's, written once for both models in
:mod:`.interval_search` and imported here: it reaches this model's :func:`evaluate`,
:func:`jerk_bound` and :func:`gap_rounding` (``terms`` the array of modes), as the pure
path's ``_search`` runs over either evaluator.

CPython's arithmetic, written out: a complex times a float promotes the float to a
complex (Python 3.11), ``(a + ib) h = (a h - b 0) + i (a 0 + b h)``; a product of two
complex numbers is ``(ac - bd) + i (ad + bc)``; ``cmath.exp(x + iy)`` is
``(e^x cos y, e^x sin y)`` (below e^709, which a decaying mode never reaches);
``abs`` of a complex number is libm's ``hypot``; ``x ** 2`` is libm's ``pow``, which this
module calls with the exponent passed at run time (``two``: a literal 2 would become a
multiplication, oscillator/kernel/compiled.py ``power``). The powers of the model's
numbers and everything else that depends on the flow only come computed by the pure
path's :func:`~grazing_control.oscillator.ndof.impact.search_constants`. The pure flow's
products (``NdofFlow.transition``, ``matvec``) are NumPy's elementwise operations, each
rounded once as here (numba fuses no multiply-add without fastmath), not BLAS.

numba's on-disk cache of these functions is stamped by every file of the kernel folder
(:mod:`.caching`), so an edit of the search recompiles this module's callers of it. A
start beyond the wall comes back as
``STATUS_BEYOND_WALL`` with the gap, through
:func:`grazing_control.oscillator.kernel.modal_search`'s function, and ndof.impact raises
the pure path's error with it.
"""

from __future__ import annotations

import math

import numpy as np

from .caching import jit
from .interval_search import (NONE, bracket, danger_halfwidth, scan_windows, search,
                              search_stack, ulp)

__all__ = ["make_eval", "evaluate", "jerk_bound", "gap_rounding", "bracket", "search",
           "search_stack", "next_impact", "transition", "matvec", "matmul", "on_wall",
           "wall_velocity", "wall_acceleration", "wall_rounding", "saltation_matrix",
           "advance", "modal_events", "NONE", "STATUS_OK", "STATUS_BEYOND_WALL",
           "STATUS_FALLBACK"]

TWO_PI = 2.0 * math.pi
_EPS = 2.0 ** -52
STATUS_OK = 0
STATUS_BEYOND_WALL = 2  # InitialStateError (info: the gap at the start)
STATUS_FALLBACK = 3  # what advance does not handle: the pure path runs (advance's docstring)

# the search constants' scalars (ndof.impact.SearchConstants.scalars), in this order
(_OMEGA, _LAG, _AMP, _DD, _N, _AW3, _DRIFT, _OMEGA2, _RHO, _RHO2, _STEP, _TWO, _R, _W, _COND,
 _MAXAMP) = range(16)
# the evaluator: ev = (omega, lag, amp, dd, tau0, n, aw3, cabs, acc_err, m0, m1, zmag, rho,
# drift, two) and the terms, one row a mode: (Re lam, Im lam, Re c, Im c, Re c lam,
# Im c lam, Re c lam^2, Im c lam^2, |c| |lam|^3, e^{max(Re lam, 0) horizon})
_CABS, _ACC_ERR, _M0, _M1, _ZMAG = 7, 8, 9, 10, 11



@jit
def make_eval(table, S, tau0, z0, horizon):
    """ndof.impact._Eval.__init__ (without the lag's transient): (ev, terms), the comment
    above. ``table``, ``S``: the flow's ``SearchConstants.table`` and ``.scalars``."""
    m, n2 = table.shape[0], z0.shape[0]
    terms = np.empty((m, 10))
    zmag = 0.0
    for k in range(m):
        br = 0.0
        bi = 0.0
        s = 0.0
        for j in range(n2):                   # beta_k = (V^-1 z0)_k
            zl = z0[j]
            br += table[k, 6 + j] * zl
            bi += table[k, 6 + n2 + j] * zl
            s += table[k, 6 + 2 * n2 + j] * abs(zl)
        vr, vi = table[k, 2], table[k, 3]
        cr = vr * br - vi * bi
        ci = vr * bi + vi * br
        lr, li = table[k, 0], table[k, 1]
        c1r = cr * lr - ci * li               # c lambda
        c1i = cr * li + ci * lr
        terms[k, 0], terms[k, 1], terms[k, 2], terms[k, 3] = lr, li, cr, ci
        terms[k, 4], terms[k, 5] = c1r, c1i
        terms[k, 6] = c1r * lr - c1i * li     # (c lambda) lambda
        terms[k, 7] = c1r * li + c1i * lr
        terms[k, 8] = math.hypot(cr, ci) * table[k, 5]
        terms[k, 9] = math.exp(max(lr, 0.0) * horizon)
        zmag += table[k, 4] * s
    cabs = 0.0
    grow = 0.0
    for k in range(m):
        cabs += math.hypot(terms[k, 2], terms[k, 3]) * terms[k, 9]
        grow = terms[k, 9] if k == 0 or terms[k, 9] > grow else grow
    zmag = zmag * grow + 0.0
    norm2 = 0.0
    for j in range(n2):
        norm2 += z0[j] * z0[j]
    drift = S[_DRIFT] * math.sqrt(norm2)
    omega, lag, amp, dd, rho, rho2 = S[_OMEGA], S[_LAG], S[_AMP], S[_DD], S[_RHO], S[_RHO2]
    n = 2.0 * S[_N] + 2.0
    phase0 = abs(tau0) + abs(lag) + 1.0
    acc_err = (8.0 * _EPS * (amp * S[_OMEGA2] * (4.0 + phase0 + omega * horizon)
                             + zmag * rho2 * (n + rho * horizon))
               + 2.0 * horizon * drift * rho2)
    m0 = 8.0 * _EPS * (zmag * n + abs(dd) + 2.0 * amp * (1.0 + phase0))
    m1 = 8.0 * _EPS * (zmag * rho + 2.0 * amp * omega) + 2.0 * drift
    ev = (omega, lag, amp, dd, tau0, S[_N], S[_AW3], cabs, acc_err, m0, m1, zmag, rho, drift,
          S[_TWO])
    return ev, terms


@jit
def evaluate(ev, terms, h):
    """_Eval.__call__: (g, v, acc, z_w) at time h, the exact closed form."""
    zx = 0.0
    v = 0.0
    a = 0.0
    for k in range(terms.shape[0]):
        lr, li = terms[k, 0], terms[k, 1]
        xr = lr * h - li * 0.0                # lam * h, h promoted to complex
        xi = lr * 0.0 + li * h
        el = math.exp(xr)                     # cmath.exp
        er = el * math.cos(xi)
        ei = el * math.sin(xi)
        zx += terms[k, 2] * er - terms[k, 3] * ei
        v += terms[k, 4] * er - terms[k, 5] * ei
        a += terms[k, 6] * er - terms[k, 7] * ei
    omega, lag, amp, dd, tau0 = ev[0], ev[1], ev[2], ev[3], ev[4]
    psi = tau0 + omega * h - lag
    sh = math.sin(0.5 * psi)
    g = zx - dd - 2.0 * amp * sh * sh
    vel = -amp * omega * math.sin(psi) + v
    acc = -amp * omega * omega * math.cos(psi) + a
    return g, vel, acc, zx


@jit
def jerk_bound(ev, terms, h):
    """_Eval.jerk_bound: J >= max |g'''| on [h, horizon]."""
    j = ev[6]
    for k in range(terms.shape[0]):
        re = terms[k, 0]
        j += terms[k, 8] * (math.exp(re * h) if re <= 0.0 else terms[k, 9])
    return j


@jit
def gap_rounding(ev, h, g, zx):
    """_Eval.gap_rounding: bound on |computed g(h) - exact g(h)|."""
    dd = ev[3]
    s2 = abs(zx - dd - g)
    phase = abs(ev[4]) + ev[0] * h + abs(ev[1]) + 1.0
    return (8.0 * _EPS * (ev[_ZMAG] * (2.0 * ev[5] + 2.0 + ev[12] * h) + abs(dd) + s2
                          + math.sqrt(2.0 * ev[2] * s2) * phase)
            + 2.0 * h * ev[13])


@jit
def next_impact(table, S, tau0, z0, horizon, max_step, stack):
    """ndof.impact._next_impact (inputs checked, horizon > 0): (time of the first impact
    in (0, horizon] or NONE, status, info); ``max_step`` <= 0: the default window;
    STATUS_BEYOND_WALL with info = the gap where the pure path raises InitialStateError."""
    ev, terms = make_eval(table, S, tau0, z0, horizon)
    # whole-window exclusion: g <= sup |z_w| - Delta d <= sum |c_k| - Delta d
    if ev[_CABS] * (1.0 + 4.0 * _EPS) + ev[_M0] + ev[_M1] * horizon < ev[3]:
        return NONE, STATUS_OK, 0.0
    step = max_step if max_step > 0.0 else S[_STEP]
    count = max(1, int(math.ceil(horizon / step)))
    # impact._scan_window (its loop: interval_search.scan_windows)
    ga, va, acca, zxa = evaluate(ev, terms, 0.0)
    # on the wall up to rounding: above it, or below it while leaving (v < 0)
    if (ga > 0.0 or ga < 0.0 and va < 0.0) and abs(ga) <= gap_rounding(ev, 0.0, ga, zxa):
        ga = 0.0
    if ga > 0.0:
        return NONE, STATUS_BEYOND_WALL, ga
    if ga == 0.0 and va > 0.0:
        return 0.0, STATUS_OK, 0.0  # on the wall, moving into it
    fa = (ga, va, acca, zxa)
    w = danger_halfwidth(ev[_CABS], ev[3], ev[2], ev[_M0], ev[_M1], horizon)
    # no grid of window ends for the modal sum: an empty view of the stack stands for it
    return (scan_windows(ev, terms, horizon, count, w, tau0, ev[0], ev[1], fa, stack,
                         stack[:0], False), STATUS_OK, 0.0)


# -- the flow with impacts: ndof.impact.advance (issue 32: the rig of n masses) ---------

@jit
def transition(table, vr, vi, ur, ui, h, phi):
    """NdofFlow.transition: Phi(h) into ``phi`` ((2n, 2n)), e_k = cmath.exp(lambda_k h)
    as CPython computes it (module docstring), then sum over k from 0.0 of
    Re((v_ik e_k) u_kj), the products written out as there."""
    m, n2 = table.shape[0], vr.shape[0]
    er = np.empty(m)
    ei = np.empty(m)
    for k in range(m):
        lr, li = table[k, 0], table[k, 1]
        el = math.exp(lr * h - li * 0.0)
        xi = lr * 0.0 + li * h
        er[k] = el * math.cos(xi)
        ei[k] = el * math.sin(xi)
    for i in range(n2):
        for j in range(n2):
            acc = 0.0
            for k in range(m):
                pr = vr[i, k] * er[k] - vi[i, k] * ei[k]
                pi = vr[i, k] * ei[k] + vi[i, k] * er[k]
                acc = (pr * ur[k, j] - pi * ui[k, j]) + acc
            phi[i, j] = acc


@jit
def matvec(a, x):
    """ndof.flow.matvec: a @ x summed over j from 0.0."""
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        acc = 0.0
        for j in range(a.shape[1]):
            acc = acc + a[i, j] * x[j]
        out[i] = acc
    return out


@jit
def matmul(a, b):
    """ndof.flow.matmul: a @ b in the order of :func:`matvec`."""
    out = np.empty((a.shape[0], b.shape[1]))
    for i in range(a.shape[0]):
        for c in range(b.shape[1]):
            acc = 0.0
            for j in range(a.shape[1]):
                acc = acc + a[i, j] * b[j, c]
            out[i, c] = acc
    return out


@jit
def on_wall(S, tau):
    """NdofFlow.on_wall: (z_w, z_{n+w}) of x_w = d, v_w = 0 at phase tau."""
    psi = tau - S[_LAG]
    s = math.sin(0.5 * psi)
    return S[_DD] + 2.0 * S[_AMP] * s * s, S[_AMP] * S[_OMEGA] * math.sin(psi)


@jit
def wall_acceleration(S, A, tau, z):
    """NdofFlow.wall_acceleration: -d* omega^2 cos(tau - tau*) + (A z)_{n+w}."""
    row = z.size // 2 + int(S[_W])
    s = 0.0
    for j in range(z.size):
        s += A[row, j] * z[j]
    return -S[_AMP] * S[_OMEGA2] * math.cos(tau - S[_LAG]) + s


@jit
def wall_rounding(S, tau, dx, dv):
    """oscillator.impact.wall_rounding of the wall coordinate: (gap, velocity) rounding."""
    lag, amp, omega = S[_LAG], S[_AMP], S[_OMEGA]
    psi = tau - lag
    s2 = 2.0 * amp * math.pow(math.sin(0.5 * psi), S[_TWO])
    vp = -amp * omega * math.sin(psi)
    phase = abs(tau) + abs(lag) + TWO_PI + 1.0
    eg = 8.0 * _EPS * (abs(dx) + abs(S[_DD]) + s2 + math.sqrt(2.0 * amp * s2) * phase)
    ev = 8.0 * _EPS * (abs(vp) + abs(dv) + amp * omega * phase)
    return eg, ev


@jit
def _resting_on_wall(S, tau, z):
    """ndof.impact._resting_on_wall: x_w = d and v_w = 0 up to the rounding."""
    n, w = z.size // 2, int(S[_W])
    eg, ev = wall_rounding(S, tau, z[w], z[n + w])
    s = math.sin(0.5 * (tau - S[_LAG]))
    gap = z[w] - S[_DD] - 2.0 * S[_AMP] * s * s
    vel = -S[_AMP] * S[_OMEGA] * math.sin(tau - S[_LAG]) + z[n + w]
    return abs(gap) <= eg and abs(vel) <= ev


@jit
def _velocity_sizes(table, z):
    """ndof.impact._velocity_sizes: (sum_k |w_k V_wk| |lambda_k| sum_l |U_kl z_l|, |z|)."""
    n2 = z.size
    size = 0.0
    for k in range(table.shape[0]):
        s = 0.0
        for j in range(n2):
            s += table[k, 6 + 2 * n2 + j] * abs(z[j])
        size += table[k, 4] * math.hypot(table[k, 0], table[k, 1]) * s
    norm2 = 0.0
    for j in range(n2):
        norm2 += z[j] * z[j]
    return size, math.sqrt(norm2)


@jit
def _impact_law(S, A, tau, z, wall_x, v):
    """ndof.impact._impact_law: (z-, z+, v-, delta) at the impact seen at the float time."""
    n, w, r = z.size // 2, int(S[_W]), S[_R]
    overshoot = z[w] - wall_x
    acc = wall_acceleration(S, A, tau, z)
    delta = overshoot / v
    if not abs(delta * acc) <= 1e-6 * v:
        overshoot = 0.0
        delta = 0.0
    az = matvec(A, z)
    z_minus = np.empty(z.size)
    for i in range(z.size):
        z_minus[i] = z[i] - delta * az[i]
    z_minus[w] = on_wall(S, tau - S[_OMEGA] * delta)[0]
    v_minus = v - delta * acc
    z_plus = z.copy()
    z_plus[n + w] -= (1.0 + r) * v
    if overshoot != 0.0:
        z_plus[w] -= (1.0 + r) * overshoot
        c = (1.0 + r) * overshoot
        for i in range(n):
            z_plus[n + i] -= c * A[n + i, n + w]
        z_plus[n + w] += (1.0 + r) * overshoot * acc / v
    else:
        z_plus[w] = wall_x
    return z_minus, z_plus, v_minus, delta


@jit
def _state_ok(S, z):
    """ndof.impact.check_state's test: z finite and cond(V) max|z| <= MAX_AMPLITUDE."""
    largest = 0.0
    for x in z:
        if not math.isfinite(x):
            return False
        largest = max(largest, abs(x))
    return S[_COND] * largest <= S[_MAXAMP]


@jit
def advance(table, S, vr, vi, ur, ui, A, tau0, z0, duration, chatter, max_impacts, stack):
    """ndof.impact.advance without the monodromy: (status, z, tau, impacts (count, 4): time,
    phase, v-, v+). STATUS_FALLBACK where the pure path must run instead: a start that
    check_state or check_times refuses, or beyond the wall; a contact at rest or resting on
    the wall; a chattering sequence that sticks; more than ``max_impacts`` contacts (the
    pure path sticks, releases or raises there)."""
    n2 = z0.size
    n, w, r, omega = n2 // 2, int(S[_W]), S[_R], S[_OMEGA]
    imps = np.empty((8, 4))
    count = 0
    z = z0.copy()
    if not (_state_ok(S, z) and math.isfinite(tau0) and math.isfinite(duration)):
        return STATUS_FALLBACK, z, tau0, imps[:0]
    phi = np.empty((n2, n2))
    t = 0.0
    tau = tau0
    h = NONE
    if _resting_on_wall(S, tau, z):
        return STATUS_FALLBACK, z, tau, imps[:0]
    if duration > 0.0:
        h, status, _info = next_impact(table, S, tau, z, duration, 0.0, stack)
        if status != STATUS_OK:
            return STATUS_FALLBACK, z, tau, imps[:0]
    while True:
        remaining = duration - t
        if h == NONE or remaining <= 0.0:
            if remaining > 0.0:
                transition(table, vr, vi, ur, ui, remaining, phi)
                z = matvec(phi, z)
                tau = (tau + omega * remaining) % TWO_PI
            return STATUS_OK, z, tau, imps[:count]
        if count >= max_impacts:
            return STATUS_FALLBACK, z, tau, imps[:0]
        size, norm = _velocity_sizes(table, z)
        flow_err = (8.0 * _EPS * size * (2.0 * S[_N] + 2.0 + S[_RHO] * h)
                    + 2.0 * h * S[_RHO] * S[_DRIFT] * norm)
        transition(table, vr, vi, ur, ui, h, phi)
        z = matvec(phi, z)
        t += h
        tau = (tau + omega * h) % TWO_PI
        wall_x, rest_v = on_wall(S, tau)
        v_minus = -rest_v + z[n + w]
        v_tol = wall_rounding(S, tau, z[w], z[n + w])[1] + flow_err
        if v_minus <= v_tol:  # contact at rest
            return STATUS_FALLBACK, z, tau, imps[:0]
        z_minus, z, v_minus, delta = _impact_law(S, A, tau, z, wall_x, v_minus)
        v_plus = -r * v_minus
        tau_i = (tau - omega * delta) % TWO_PI
        z_minus[n + w] = on_wall(S, tau_i)[1]
        force = wall_acceleration(S, A, tau_i, z_minus)
        if force > 0.0:
            t_inf = 2.0 * r * v_minus / ((1.0 - r) * force) if r < 1.0 else math.inf
            height = math.pow(r * v_minus, S[_TWO]) / (2.0 * force)
            if t_inf < chatter or height < 1e3 * ulp(abs(z[w]) + abs(S[_DD]) + S[_AMP]):
                return STATUS_FALLBACK, z, tau, imps[:0]  # chattering: sticks
        if count == imps.shape[0]:
            grown = np.empty((2 * count, 4))
            grown[:count] = imps
            imps = grown
        imps[count, 0], imps[count, 1] = t - delta, tau_i
        imps[count, 2], imps[count, 3] = v_minus, v_plus
        count += 1
        h = NONE
        if t < duration:
            h, status, _info = next_impact(table, S, tau, z, duration - t, 0.0, stack)
            if status != STATUS_OK:
                return STATUS_FALLBACK, z, tau, imps[:0]


@jit
def wall_velocity(S, tau, z):
    """NdofFlow.wall_velocity: v_w = -d* omega sin(tau - tau*) + z_{n+w}."""
    return -S[_AMP] * S[_OMEGA] * math.sin(tau - S[_LAG]) + z[z.size // 2 + int(S[_W])]


@jit
def saltation_matrix(S, A, phase, z_minus, v):
    """ndof.impact.saltation_matrix, S0 + s e_{n+w} e_w^T, with v = v_w- > 0 (the caller's
    :func:`wall_velocity`; the pure path refuses v <= 0 with a ValueError)."""
    n2 = z_minus.size
    n, w, r = n2 // 2, int(S[_W]), S[_R]
    a = wall_acceleration(S, A, phase, z_minus)
    out = np.eye(n2)
    out[n + w, n + w] = -r
    out[w, w] -= 1.0 + r
    for i in range(n):
        out[n + i, w] -= (1.0 + r) * A[n + i, n + w]
    out[n + w, w] += (1.0 + r) * a / v
    return out


@jit
def modal_events(table, S, vr, vi, ur, ui, A, tau2, i_a, z0, legs, shifts, chatter, stack):
    """dynamics.estimation.motion.modal_trajectory's events (its loop over the legs of the
    period, the Jacobian through each impact): (status, times (E,), z_e (E, 2n),
    M_e (E, 2n, 2n), shifts (E, 2n), z at the end, M at the end, impacts (K, 4): time,
    phase, v-, v+). ``legs`` rows (start, end, kick, Delta d of the leg's forced flow),
    ``shifts`` the legs' static deflections sigma F; STATUS_FALLBACK where :func:`advance`
    falls back or v_w- <= 0 at an impact (the pure path raises or sticks there)."""
    n2 = z0.size
    n, w, omega = n2 // 2, int(S[_W]), S[_OMEGA]
    nl = legs.shape[0]
    Sl = S.copy()
    phi = np.empty((n2, n2))
    # the legs' motion: start states (after the kick, less the shift) and impacts
    starts = np.empty((nl, n2))
    found = []
    total = 0
    z = z0.copy()
    for leg in range(nl):
        start, end, kick = legs[leg, 0], legs[leg, 1], legs[leg, 2]
        Sl[_DD] = legs[leg, 3]
        z[n + i_a] += kick
        for i in range(n2):
            starts[leg, i] = z[i] - shifts[leg, i]
        status, z_end, _tau, imps = advance(table, Sl, vr, vi, ur, ui, A,
                                            (tau2 + omega * start) % TWO_PI, starts[leg],
                                            end - start, chatter, 10000, stack)
        if status != STATUS_OK:
            return (STATUS_FALLBACK, np.empty(0), starts, np.empty((0, n2, n2)), starts, z,
                    np.eye(n2), np.empty((0, 4)))
        found.append(imps)
        total += imps.shape[0]
        for i in range(n2):
            z[i] = z_end[i] + shifts[leg, i]
    # the events: each leg's start and each impact, with the Jacobian there
    times = np.empty(nl + total)
    zs = np.empty((nl + total, n2))
    ms = np.empty((nl + total, n2, n2))
    sh = np.empty((nl + total, n2))
    impacts = np.empty((total, 4))
    m = np.eye(n2)
    e = 0
    q = 0
    for leg in range(nl):
        start, end = legs[leg, 0], legs[leg, 1]
        Sl[_DD] = legs[leg, 3]
        times[e], zs[e], ms[e], sh[e] = start, starts[leg], m, shifts[leg]
        e += 1
        t_e = start
        z_e = starts[leg].copy()
        imps = found[leg]
        for j in range(imps.shape[0]):
            ti = start + imps[j, 0]
            phase, v_minus, v_plus = imps[j, 1], imps[j, 2], imps[j, 3]
            transition(table, vr, vi, ur, ui, ti - t_e, phi)
            wall_x, rest_v = on_wall(Sl, phase)
            z_minus = matvec(phi, z_e)
            z_minus[w], z_minus[n + w] = wall_x, v_minus + rest_v
            v = wall_velocity(Sl, phase, z_minus)
            if not v > 0.0:
                return (STATUS_FALLBACK, np.empty(0), starts, np.empty((0, n2, n2)), starts,
                        z, m, np.empty((0, 4)))
            m = matmul(matmul(saltation_matrix(Sl, A, phase, z_minus, v), phi), m)
            z_e = z_minus.copy()
            z_e[n + w] = v_plus + rest_v
            t_e = ti
            times[e], zs[e], ms[e], sh[e] = ti, z_e, m, shifts[leg]
            e += 1
            impacts[q, 0], impacts[q, 1], impacts[q, 2], impacts[q, 3] = (ti, phase, v_minus,
                                                                          v_plus)
            q += 1
        transition(table, vr, vi, ur, ui, end - t_e, phi)
        m = matmul(phi, m)
    return STATUS_OK, times, zs, ms, sh, z, m, impacts

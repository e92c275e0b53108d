"""The certified interval search, compiled once for both models.

:func:`grazing_control.oscillator.impact._search` and ``_bracket`` (with
``_danger_halfwidth`` and ``_far_from_wall``) in numba, in the same floating point
operations and order, so that they return the same floats. The pure path runs them over
an evaluator object, the 1-DOF ``impact._Eval`` or the n-DOF ``ndof.impact._Eval``; here
the evaluator is the pair ``(ev, terms)`` of the model's compiled ``make_eval``:

* ``terms`` None: the 1-DOF closed form (:mod:`.compiled`; ``ev`` its 16-tuple);
* ``terms`` an array, one row a mode: the modal sum (:mod:`.compiled_modal`).

What the search asks of the model are the five functions of "the models" below
(:func:`values`, :func:`jerk_argument`, :func:`jerk_bound`, :func:`gap_rounding`,
:func:`margins`), each implemented for both types of ``terms`` with numba's
``@overload``: numba compiles the search once per model with that model's evaluator in
it, as if written out in the model's module (docs/theory_ndof_flow.md section 4). Only
how the models are reached differs: the 1-DOF evaluation carries e^{-zeta h}, which its
jerk bound reuses, while the modal jerk bound sums its modes at h; the margins sit at
other places of ``ev``.

The search crosses files, and numba's cache keys a function on its own file: the
kernel's :func:`~.caching.jit` stamps it by every file of the folder instead.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.extending import overload

from .caching import jit

__all__ = ["NONE", "ulp", "values", "jerk_argument", "jerk_bound", "gap_rounding",
           "margins", "window_values", "bracket", "search", "search_stack",
           "danger_halfwidth", "far_from_wall", "scan_windows"]

TWO_PI = 2.0 * math.pi
_MAX_DEPTH = 64
_EPS = 2.0 ** -52
NONE = -1.0  # "no impact" (times are >= 0)
#: the models' functions below compile as the kernel's own (caching.jit)
_OPTIONS = {"nogil": True, "error_model": "numpy"}


# ------------------------------------------------------------------ the models
def values(ev, terms, h):
    """_Eval.__call__: the model's values at time h, a tuple beginning (g, v, acc, w), w
    the wall coordinate's deviation that :func:`gap_rounding` takes."""
    raise NotImplementedError("compiled only (numba's overload below)")


def jerk_argument(terms, h, f):
    """What :func:`jerk_bound` takes for an interval starting at h, where the values are
    f: the 1-DOF e^{-zeta h} that f carries (computed once per interval), the modal h."""
    raise NotImplementedError("compiled only (numba's overload below)")


def jerk_bound(ev, terms, j):
    """_Eval.jerk_bound: J >= max |g'''| from the interval's start on, given
    :func:`jerk_argument` there."""
    raise NotImplementedError("compiled only (numba's overload below)")


def gap_rounding(ev, terms, h, g, w):
    """_Eval.gap_rounding: bound on |computed g(h) - exact g(h)|."""
    raise NotImplementedError("compiled only (numba's overload below)")


def margins(ev, terms):
    """(_Eval.acc_err, .m0, .m1, 2.0): the rounding of an acceleration, the uniform bound
    m0 + m1 h of the gap's rounding, and the exponent 2 passed at run time (``x ** 2`` is
    libm's pow in the pure path; a literal 2 would compile to a multiplication)."""
    raise NotImplementedError("compiled only (numba's overload below)")


def _closed_form(terms) -> bool:
    """``terms`` None: the 1-DOF closed form (:mod:`.compiled`), an array: the modal sum
    (:mod:`.compiled_modal`). Their functions are imported when numba compiles the
    search for one of them (the model modules import this one)."""
    if isinstance(terms, types.NoneType):
        return True
    if isinstance(terms, types.Array):
        return False
    raise TypeError(f"terms of type {terms}: valid are None (1-DOF) or an array (modal)")


@overload(values, jit_options=_OPTIONS)
def _values(ev, terms, h):
    if _closed_form(terms):
        from .compiled import evaluate
        return lambda ev, terms, h: evaluate(ev, h)  # (g, v, acc, dx, dv, e^{-zeta h})
    from .compiled_modal import evaluate as modal
    return lambda ev, terms, h: modal(ev, terms, h)  # (g, v, acc, z_w)


@overload(jerk_argument, jit_options=_OPTIONS)
def _jerk_argument(terms, h, f):
    if _closed_form(terms):
        return lambda terms, h, f: f[5]
    return lambda terms, h, f: h


@overload(jerk_bound, jit_options=_OPTIONS)
def _jerk_bound(ev, terms, j):
    if _closed_form(terms):
        from .compiled import jerk_bound as closed
        return lambda ev, terms, j: closed(ev, j)
    from .compiled_modal import jerk_bound as modal
    return lambda ev, terms, j: modal(ev, terms, j)


@overload(gap_rounding, jit_options=_OPTIONS)
def _gap_rounding(ev, terms, h, g, w):
    if _closed_form(terms):
        from .compiled import gap_rounding as closed
        return lambda ev, terms, h, g, w: closed(ev, h, g, w)
    from .compiled_modal import gap_rounding as modal
    return lambda ev, terms, h, g, w: modal(ev, h, g, w)


@overload(margins, jit_options=_OPTIONS)
def _margins(ev, terms):
    if _closed_form(terms):  # compiled.make_eval's (ev[13], ev[14], ev[15]), P's 2.0
        return lambda ev, terms: (ev[13], ev[14], ev[15], ev[12])
    # compiled_modal.make_eval's (ev[_ACC_ERR], ev[_M0], ev[_M1]), its scalars' 2.0
    return lambda ev, terms: (ev[8], ev[9], ev[10], ev[14])


# ------------------------------------------------------------------ the search
def window_values(ev, terms, grid, cached, k, h):
    """The values at the end h of window k of :func:`scan_windows` (:func:`values`; the
    1-DOF closed form reads them from its grid of the window ends where ``cached``)."""
    raise NotImplementedError("compiled only (numba's overload below)")


@overload(window_values, jit_options=_OPTIONS)
def _window_values(ev, terms, grid, cached, k, h):
    if _closed_form(terms):
        from .compiled import evaluate, evaluate_row
        return lambda ev, terms, grid, cached, k, h: (evaluate_row(ev, grid, k) if cached
                                                      else evaluate(ev, h))
    from .compiled_modal import evaluate as modal
    return lambda ev, terms, grid, cached, k, h: modal(ev, terms, h)


@jit
def ulp(x):
    """math.ulp(x) for finite x: the gap from |x| to the next float up."""
    a = abs(x)
    return np.nextafter(a, np.inf) - a


@jit
def bracket(ev, terms, lo, hi, which, sign, flo, fhi):
    """impact._bracket: root of g (which = 0) or v (which = 1) in [lo, hi]."""
    d = flo - fhi
    x = lo + (hi - lo) * (flo / d) if d != 0.0 else 0.5 * (lo + hi)
    if not lo < x < hi:
        x = 0.5 * (lo + hi)
    probed = False
    while hi - lo > 4.0 * ulp(hi):
        f = values(ev, terms, x)
        if which == 0:
            fx, dfx = sign * f[0], sign * f[1]
        else:
            fx, dfx = sign * f[1], sign * f[2]
        if fx >= 0.0:
            hi = x
        else:
            lo = x
        xn = x - fx / dfx if dfx > 0.0 else lo
        probe = 2.0 * ulp(x)
        if abs(xn - x) < probe:  # 2 ulps past the root; bisect if the last probe failed
            xn = 0.5 * (lo + hi) if probed else (x - probe if fx >= 0.0 else x + probe)
            probed = not probed
        else:
            probed = False
        if not lo < xn < hi:
            xn = 0.5 * (lo + hi)
        if xn == x:
            xn = 0.5 * (lo + hi)
            if xn == x:
                break
        x = xn
    return hi


@jit
def _certified(ev, terms, a, b, ja, ga, va, acca, wa, gb, vb, accb, wb):
    """The certified cases of impact._search on [a, b] (values (g, v, acc, w) at a and b,
    ``ja`` the :func:`jerk_argument` at a).

    Returns (decided, time): decided = 1 with time >= 0 (impact) or NONE (none), or
    decided = 0 when the interval must be split.
    """
    acc_err, m0, m1, two = margins(ev, terms)
    # J (b - a), rounded up, plus the rounding of the two accelerations (docs/theory.md)
    jw = jerk_bound(ev, terms, ja) * (b - a) * (1.0 + 1e-12) + 2.0 * acc_err
    concave = acca < 0.0 and accb < 0.0 and -(acca + accb) > jw
    convex = acca > 0.0 and accb > 0.0 and (acca + accb) > jw
    if concave:  # v decreasing: at most one maximum
        if va <= 0.0:
            return 1, NONE
        if vb >= 0.0:
            return 1, (bracket(ev, terms, a, b, 0, 1.0, ga, gb) if gb >= 0.0 else NONE)
        tm = bracket(ev, terms, a, b, 1, -1.0, va, vb)
        gm = values(ev, terms, tm)[0]
        return 1, (bracket(ev, terms, a, tm, 0, 1.0, ga, gm) if gm >= 0.0 else NONE)
    if convex:  # v increasing: g below the chord unless it ends above 0
        if gb < 0.0:
            return 1, NONE
        if ga < 0.0:
            return 1, bracket(ev, terms, a, b, 0, 1.0, ga, gb)
        if va >= 0.0:  # at rest on the wall and pushed into it
            return 1, a
        tmin = bracket(ev, terms, a, b, 1, 1.0, va, vb) if vb > 0.0 else b
        gmin = values(ev, terms, tmin)[0]
        if gmin >= 0.0:  # the dip below the wall is below rounding: at rest, pushed in
            return 1, tmin
        return 1, (bracket(ev, terms, tmin, b, 0, 1.0, gmin, gb) if gmin < 0.0 <= gb
                   else NONE)
    # below the chord plus the curvature allowance, with the rounding margin of the ends
    # (a uniform bound m0 + m1 b first, the precise one only when needed)
    curvature = max(0.0, 0.5 * (jw - acca - accb))
    upper = max(ga, gb) + 0.125 * math.pow(b - a, two) * curvature
    if upper < 0.0 and (upper + m0 + m1 * b < 0.0 or
                        upper + max(gap_rounding(ev, terms, a, ga, wa),
                                    gap_rounding(ev, terms, b, gb, wb)) < 0.0):
        return 1, NONE
    return 0, NONE


@jit
def search(ev, terms, a, b, fa, fb, stack):
    """impact._search(f, a, b, fa, fb, 0): first impact time in (a, b], or NONE.

    ``fa``, ``fb``: the model's :func:`values` at a and b. The recursion (left half first,
    then the right half) runs on an explicit stack of pending right halves (``stack``,
    from :func:`search_stack`), which visits the intervals in the same order.
    """
    top = 0
    ja = jerk_argument(terms, a, fa)
    ga, va, acca, wa = fa[0], fa[1], fa[2], fa[3]
    gb, vb, accb, wb = fb[0], fb[1], fb[2], fb[3]
    depth = 0
    while True:
        decided, t = _certified(ev, terms, a, b, ja, ga, va, acca, wa, gb, vb, accb, wb)
        if not decided:
            if depth >= _MAX_DEPTH or b - a <= 4.0 * ulp(b):
                decided = 1
                t = bracket(ev, terms, a, b, 0, 1.0, ga, gb) if ga < 0.0 <= gb else NONE
        if decided:
            if t != NONE:
                return t
            if top == 0:
                return NONE
            top -= 1  # the pending right half of the nearest ancestor
            a, b, ja = stack[top, 0], stack[top, 1], stack[top, 2]
            ga, va, acca, wa = stack[top, 3], stack[top, 4], stack[top, 5], stack[top, 6]
            gb, vb, accb, wb = stack[top, 7], stack[top, 8], stack[top, 9], stack[top, 10]
            depth = int(stack[top, 11])
            continue
        mid = 0.5 * (a + b)
        fm = values(ev, terms, mid)
        stack[top, 0], stack[top, 1], stack[top, 2] = mid, b, jerk_argument(terms, mid, fm)
        stack[top, 3], stack[top, 4], stack[top, 5], stack[top, 6] = fm[0], fm[1], fm[2], fm[3]
        stack[top, 7], stack[top, 8], stack[top, 9], stack[top, 10] = gb, vb, accb, wb
        stack[top, 11] = depth + 1
        top += 1
        b, gb, vb, accb, wb = mid, fm[0], fm[1], fm[2], fm[3]
        depth += 1


def search_stack():
    """The work array of :func:`search`: one row per pending interval (a, b, the jerk
    argument at a, (g, v, acc, w) at a and at b, the depth)."""
    return np.empty((_MAX_DEPTH + 2, 12))


# ------------------------------------------------------------------ _scan_window's
@jit
def danger_halfwidth(cabs, dd, amp, m0, m1, horizon):
    """impact._danger_halfwidth over the evaluator's |C| (the modal sum of |c_k|), Delta d,
    d*, m0 and m1; -1.0 for None."""
    s = (cabs * (1.0 + 4.0 * _EPS) - dd + m0 + m1 * horizon) / (2.0 * amp)
    if s >= 1.0:
        return -1.0
    return 2.0 * math.asin(math.sqrt(max(s, 0.0))) + 1e-9


@jit
def far_from_wall(psi_a, psi_b, w):
    """impact._far_from_wall."""
    k = math.ceil((psi_a - w) / TWO_PI)
    return TWO_PI * k - w > psi_b


@jit
def scan_windows(ev, terms, horizon, count, w, phase0, omega, lag, fa, stack, grid, cached):
    """impact._scan_window's loop over ``count`` equal windows of (0, horizon]: the first
    impact time or NONE. A window whose phases phase0 + omega t - lag lie where the gap
    cannot reach the wall (:func:`far_from_wall`, half-width ``w``; w < 0: none such) is
    skipped unevaluated; the others are searched (:func:`search`) from ``fa``, the
    values at their start (at 0 for the first)."""
    a = 0.0
    valid = True  # fa holds the values at a
    for k in range(1, count + 1):
        b = horizon if k == count else k * (horizon / count)
        if k > 1 and w >= 0.0 and far_from_wall(phase0 + omega * a - lag,
                                                phase0 + omega * b - lag, w):
            a, valid = b, False  # g < 0 on all of [a, b]: the search would find nothing
            continue
        if not valid:
            fa = window_values(ev, terms, grid, cached, k - 1, a)
            valid = True
        fb = window_values(ev, terms, grid, cached, k, b)
        r = search(ev, terms, a, b, fa, fb, stack)
        if r != NONE:
            return r
        a, fa = b, fb
    return NONE

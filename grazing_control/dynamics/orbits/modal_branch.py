"""The controlled 1/1 branch of a model file (any n), explicit in the impact phase.

The model file's implementation of the 1/1 branch behind the one entry
(:mod:`.one_one`: ``orbit``, ``branch``), beside the 1-DOF closed form's (:mod:`.orbits`:
``orbit_11``, ``wall_offset_at_phase``); for n = 1 the two agree to rounding
(tests/test_one_one.py, tests/test_n1_model_file.py).

docs/theory_ndof.md §5 (the n-DOF form of docs/theory.md §5). Take the wall as the
section: an impact at forcing phase tau* + psi, just before it the deviation
z- = X- - X_p has wall position Delta d + 2 d* sin^2(psi/2) and wall velocity
v- + d* omega sin psi; after it z+ = z- - (1 + r) v- e_v. Over one period
z- = M(psi) z+, M(psi) = Phi(T - sigma)(I + b k^T) Phi(sigma), sigma = s - psi/omega
the time from the impact to Pi2. Periodicity (M - I) z- = (1 + r) v- M e_v gives, for a
given psi, z- = (1 + r) v- (I + R) e_v with R = (M - I)^-1; its wall velocity and position
components fix v- and Delta d:

    v- = d* omega sin(psi) / (r + (1 + r) e_v^T R e_v),
    Delta d = (1 + r) v- w^T R e_v - 2 d* sin^2(psi/2),

so the branch is an explicit curve psi -> (Delta d, v-, z-), exact up to rounding. Its
monodromy at the impact is J = M S, S the saltation matrix (oscillator/ndof/impact.py).
This is the exact reference for the limit multipliers and the existence coefficient of
family (no shooting, no expansion); it assumes the one impact of the period is the only contact (a local
statement: the orbit near grazing; shooting on the exact period map is the global check).

Every function takes ``delay``: the kick's actuation delay (b -> b_delta = Phi(-delay) b,
§14), or a pulse as a :class:`~grazing_control.dynamics.design.family.Actuation`
(b -> b_w, the pulse as a jump on the section its end later, §18, (N13)-(N15)); the
branch holds while no impact lies in the window where the correction acts
(:func:`acted_by`), and :func:`other_contacts` flows that window exactly.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from grazing_control.oscillator.control import gain_vector
from grazing_control.oscillator.ndof.forced import actuated_mass, advance_with_force
from grazing_control.oscillator.ndof.impact import (ChatteringError, ImpactCapError, advance,
                                                    saltation_matrix, saltation_parts)
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.orbits.continuation import OrbitBifurcation, OrbitBranch, OrbitPoint
from grazing_control.dynamics.design.family import (Actuation, _flow, _transition, _vectors,
                                                     smooth_map)
from grazing_control.dynamics.orbits.shooting import TEST_FUNCTIONS, bifurcation_tests

__all__ = ["PhasePoint", "orbit_at_phase", "branch_coefficients", "orbit_at", "branch_fold",
           "pi2_factors", "structured_multipliers", "branch_multipliers", "other_contacts",
           "continue_branch", "acted_by", "RETURN_MARGIN"]


class PhasePoint(NamedTuple):
    """One 1/1 orbit on the branch: impact phase psi (after tau*), wall offset Delta d,
    impact velocity v-, the deviation z- just before the impact, its monodromy J there
    (None where v- <= 0: not a physical orbit), and the Pi2 state (before the kick) of
    the same orbit."""

    psi: float
    delta_d: float
    v_minus: float
    state: np.ndarray
    monodromy: np.ndarray
    pi2_state: np.ndarray


def _impact_map(model: NdofModel, k: np.ndarray, psi: float, delay: float = 0.0):
    """(M(psi), Phi(sigma)): the period map from an impact at tau* + psi to the next,
    M = Phi(T - sigma)(I + b k^T) Phi(sigma), sigma = s - psi/omega (module docstring);
    with an actuation delay b = Phi(-delay) e_{n + i_a}, valid while the kick acts before
    the next impact, sigma + delay < T (docs/theory_ndof.md §14); for a pulse
    (:class:`~grazing_control.dynamics.design.family.Actuation`) b = b_w, valid
    while the pulse ends before it, sigma + end < T (§15)."""
    om = model.omega
    s = model.pi2_offset / om
    sigma = s - psi / om
    reach = acted_by(model, delay)
    if not (0.0 < sigma < model.period - reach) or not math.isfinite(psi):
        raise ParameterError(f"psi={psi!r} is invalid: valid range is "
                             f"{-om * (model.period - s - reach)!r} < psi < {om * s!r} "
                             f"(impact between the kicks)")
    _w, _ev, b = _vectors(model, delay)
    pm = _transition(model, sigma)
    eye = np.eye(2 * model.n)
    return _transition(model, model.period - sigma) @ (eye + np.outer(b, k)) @ pm, pm


def acted_by(model: NdofModel, delay=0.0) -> float:
    """How long after the sample the correction has acted: a kick's ``delay`` (§14), or
    the end start + L + w of a pulse (an :class:`Actuation`, §15). The branch explicit in
    the impact phase holds while no impact lies in that window (docs/theory_ndof.md §18)."""
    return delay.end(model) if isinstance(delay, Actuation) else float(delay)


def orbit_at_phase(model: NdofModel, gains, psi: float, delay: float = 0.0) -> PhasePoint:
    """The 1/1 orbit with its impact at phase tau* + psi (§5, Eq. (N5)), as a
    :class:`PhasePoint` (the 1-DOF closed form's Delta d, v- and period matrix at the
    phase: :func:`.orbits.wall_offset_at_phase`; at a given Delta d: :func:`orbit_at`).

    Periodicity (M - I) z- = (1 + r) v- M e_v gives z- = (1 + r) v- (e_v + R e_v),
    R = (M - I)^-1, whose wall velocity and position components are

        v- = d* omega sin(psi) / (r + (1 + r) e_v^T R e_v),
        Delta d = (1 + r) v- w^T R e_v - 2 d* sin^2(psi/2).

    psi must put the impact between the Pi2 kicks: -omega (T - s) < psi < omega s. With an
    actuation ``delay`` the kick acts delay after Pi2 (before the next impact:
    -omega (T - s - delay) < psi, §14); the Pi2 state is the sample, before the kick.
    """
    k = gain_vector(gains, model.n)
    psi = float(psi)
    m, pm = _impact_map(model, k, psi, delay)
    w, ev, _b = _vectors(model)
    dstar, om, r = _flow(model).d_star, model.omega, model.r
    try:
        rev = np.linalg.solve(m - np.eye(2 * model.n), ev)
    except np.linalg.LinAlgError:
        raise ParameterError(f"psi={psi!r} is invalid: the period map M(psi) has the "
                             f"eigenvalue 1 there (no isolated 1/1 orbit)") from None
    v = dstar * om * math.sin(psi) / (r + (1.0 + r) * float(ev @ rev))
    dd = (1.0 + r) * v * float(w @ rev) - 2.0 * dstar * math.sin(0.5 * psi) ** 2
    z = (1.0 + r) * v * (ev + rev)
    flow = _flow(model)
    jac = m @ saltation_matrix(flow, flow.tau_star + psi, z) if v > 0.0 else None
    z2 = pm @ (z - (1.0 + r) * v * ev)
    return PhasePoint(psi, dd, v, z, jac, z2)


def branch_coefficients(model: NdofModel, gains, delay: float = 0.0):
    """(d1, gamma1, v1): Delta d = d1 psi - gamma1 psi^2 + O(psi^3), v- = v1 psi + O(psi^2)
    on the 1/1 branch born at grazing, for any gains (§7, Eq. (N7')).

    With N = N(k), R = (N - I)^-1, M' = [A, N]/omega, q0 = r + (1 + r) e_v^T R e_v:
    v1 = d* omega / q0, d1 = (1 + r) v1 w^T R e_v (proportional to G(1) of §2: zero iff
    the branch is smooth), gamma1 = d*/2 - (1 + r)(v1 b1 + v2 b0) with b0 = w^T R e_v,
    b1 = -w^T R M' R e_v, v2 = -(1 + r) v1 a1' / q0, a1' = -e_v^T R M' R e_v.
    On the family (w^T N = mu w^T) gamma1 is family.existence_coefficient. With an
    actuation ``delay``, N = N(k; delay) (§14).
    """
    k = gain_vector(gains, model.n)
    n_mat = smooth_map(model, k, delay)
    w, ev, _b = _vectors(model)
    a = _flow(model).A
    dstar, om, r = _flow(model).d_star, model.omega, model.r
    res = np.linalg.inv(n_mat - np.eye(2 * model.n))
    mp = (a @ n_mat - n_mat @ a) / om
    q0 = r + (1.0 + r) * float(ev @ res @ ev)
    v1 = dstar * om / q0
    b0 = float(w @ res @ ev)
    b1 = -float(w @ res @ mp @ res @ ev)
    a1p = -float(ev @ res @ mp @ res @ ev)
    v2 = -(1.0 + r) * v1 * a1p / q0
    return (1.0 + r) * v1 * b0, 0.5 * dstar - (1.0 + r) * (v1 * b1 + v2 * b0), v1


def orbit_at(model: NdofModel, gains, delta_d: float, psi_max: float = 0.3,
             delay: float = 0.0) -> PhasePoint:
    """The 1/1 orbit born at grazing at the wall offset ``delta_d`` (< 0), v- > 0.

    Walks |psi| outwards on both sides of grazing (1e-12 .. psi_max, logarithmic) and
    solves Delta d(psi) = delta_d by Brent's method on the first bracket with v- > 0 on
    the side nearer grazing. Raises ValueError when no such orbit is found. The walk's
    values are the same at every Delta d (:func:`_psi_walk`).
    """
    k = gain_vector(gains, model.n)
    best = None
    for sign in (1.0, -1.0):
        prev = None
        for a, dd, v, error in _psi_walk(model, k, sign, psi_max, delay):
            if error is not None:
                raise error[0](*error[1])
            if v <= 0.0:
                break
            val = dd - delta_d
            if prev is not None and (val > 0.0) != (prev[1] > 0.0):
                if best is None or a < best[2]:
                    best = (prev[0], sign * a, a)
                break
            prev = (sign * a, val)
    if best is None:
        raise ValueError(f"delta_d={delta_d!r}: no 1/1 orbit born at grazing with v- > 0 "
                         f"for |psi| <= {psi_max!r}")
    psi = brentq(lambda x: orbit_at_phase(model, k, x, delay).delta_d - delta_d, best[0], best[1],
                 xtol=1e-300, rtol=4.0 * 2.0 ** -52, maxiter=400)
    return orbit_at_phase(model, k, psi, delay)


def _psi_walk(model: NdofModel, k: np.ndarray, sign: float, psi_max: float, delay) -> tuple:
    """:func:`orbit_at`'s walk on one side: (|psi|, Delta d, v-, None) of
    :func:`orbit_at_phase` at sign |psi|, |psi| on 400 logarithmic steps from 1e-12 to
    ``psi_max``, up to the first v- <= 0, or up to a point where orbit_at_phase raised
    (its error as (type, args) in the last row). orbit_at_phase does not read
    model.delta_d (it is the unknown), so the walk is made once per model content but
    Delta d, gains, side and window (:func:`_psi_walk_of`): a sweep over Delta d (the
    mismatch bands' ~60 orbits a plant) walked each orbit's 800 phases anew
    (tests/test_modal_branch.py checks the same floats at another Delta d)."""
    key = (model.M.tobytes(), model.C.tobytes(), model.K.tobytes(), model.f.tobytes(),
           model.M.shape, model.omega, model.i_w, model.r, model.i_a, model.phase,
           model.pi2_offset, k.tobytes(), sign, psi_max, type(delay), delay)
    return _psi_walk_of(key, model, k, sign, psi_max, delay)


#: the walks made, by key (the last 64), and the lock of its changes (threads may ask)
_WALKS: dict = {}
_WALKS_LOCK = threading.Lock()


def _psi_walk_of(key, model, k, sign, psi_max, delay) -> tuple:
    """:func:`_psi_walk` by its key, from the walks made. ``type(delay)`` is in the key:
    a delay True is refused by orbit_at_phase, not taken for the delay 1."""
    with _WALKS_LOCK:
        rows = _WALKS.get(key)
    if rows is None:
        rows = []
        for a in np.geomspace(1e-12, psi_max, 400):
            try:
                bp = orbit_at_phase(model, k, sign * a, delay)
            except Exception as exc:     # noqa: BLE001 - raised again where it was met
                rows.append((a, math.nan, math.nan, (type(exc), exc.args)))
                break
            rows.append((a, bp.delta_d, bp.v_minus, None))
            if bp.v_minus <= 0.0:
                break
        rows = tuple(rows)
        with _WALKS_LOCK:
            if len(_WALKS) >= 64:
                _WALKS.pop(next(iter(_WALKS)))
            _WALKS[key] = rows
    return rows


def branch_fold(model: NdofModel, gains, steps: int = 2000, delay: float = 0.0):
    """The first fold of the branch born at grazing (``gains`` None: uncontrolled),
    walking away from grazing in the impact phase, or None if there is none before v-
    or the window of psi ends.

    A fold is a turning point of Delta d(psi) (§5): there d(Delta d)/dpsi = 0 and the
    orbit is not isolated in Delta d, so its monodromy has the multiplier 1. Where a
    continuation in Delta d stops (it cannot pass a turning point), this names it.
    The side of grazing is that of v- ~ v1 psi > 0 (``branch_coefficients``); the fold
    is bracketed on a grid of ``steps`` phases up to the end of the window
    -omega (T - s) < psi < omega s and located by Brent's method on a central-difference
    slope. With an actuation ``delay`` the delayed kick's branch (§14), whose window
    ends where the impact enters the delay.
    """
    k = gain_vector(np.zeros(2 * model.n) if gains is None else gains, model.n)
    sgn = math.copysign(1.0, branch_coefficients(model, k, delay)[2])
    s = model.pi2_offset / model.omega
    bound = model.omega * s if sgn > 0 else \
        model.omega * (model.period - s - acted_by(model, delay))
    grid = sgn * np.linspace(1e-6 * bound, 0.999 * bound, steps)

    def slope(psi):
        h = 1e-7 * max(1e-3, abs(psi))
        return (orbit_at_phase(model, k, psi + h, delay).delta_d
                - orbit_at_phase(model, k, psi - h, delay).delta_d) / (2.0 * h)

    first = slope(grid[0]) > 0.0
    prev = grid[0]
    for psi in grid[1:]:
        try:
            if orbit_at_phase(model, k, psi, delay).v_minus <= 0.0:
                return None
            turned = (slope(psi) > 0.0) != first
        except ParameterError:
            return None
        if turned:
            return orbit_at_phase(model, k, brentq(slope, prev, psi, xtol=1e-13), delay)
        prev = psi
    return None


# ------------------------------------------------- the orbit on Pi2, its multipliers
#: The global check of a branch orbit (:func:`other_contacts`) searches the period up to
#: this fraction of T before the orbit's own impact; on that last stretch the approach
#: is the parabola of a regular grazing (v_w > 0, decelerating) and has no other root.
RETURN_MARGIN = 1e-4


def _sigma(model: NdofModel, psi: float) -> float:
    """Time from the impact at tau* + psi to Pi2: sigma = pi2_offset / omega - psi / omega."""
    return (model.pi2_offset - psi) / model.omega


def pi2_factors(model: NdofModel, gains, point: PhasePoint, delay: float = 0.0):
    """(B, p, q, s): the Pi2 monodromy of the branch orbit as DP = B + s p q^T.

    From Pi2 (before the kick) one period is: the kick G = I + b k^T, the flow
    Phi(T - sigma) to the impact, its saltation S = S0 + s e_v e_w^T
    (``oscillator.ndof.impact.saltation_parts``: s = (1 + r) a_w- / v- grows like 1/v-),
    the flow Phi(sigma) back to Pi2. So DP = Phi(sigma) S Phi(T - sigma) G with
    B = Phi(sigma) S0 Phi(T - sigma) G, p = Phi(sigma) e_v, q^T = e_w^T Phi(T - sigma) G:
    bounded factors and one scalar that carries the singularity of grazing. With an
    actuation ``delay`` (no impact inside it: the branch's window) G = I + b_delay k^T,
    b_delay = Phi(-delay) e_{n + i_a} (docs/theory_ndof.md §14, (N8)): the delayed map's
    Jacobian M2 (M1 + e k^T), M1 = Phi(delay), M2 = Phi(sigma) S Phi(T - sigma - delay),
    is Phi(sigma) S Phi(T - sigma) (I + b_delay k^T).
    """
    k = gain_vector(gains, model.n)
    flow = _flow(model)
    sigma = _sigma(model, point.psi)
    _w, _ev, b = _vectors(model, delay)
    n, w = model.n, model.i_w
    after = _transition(model, sigma)
    before = _transition(model, model.period - sigma) @ (np.eye(2 * n) + np.outer(b, k))
    s0, s = saltation_parts(flow, flow.tau_star + point.psi, point.state, point.v_minus)
    return after @ s0 @ before, after[:, n + w].copy(), before[w].copy(), s


def structured_multipliers(B, p, q, s, det: float) -> np.ndarray:
    """Eigenvalues of J = B + s p q^T (decreasing modulus) without the loss of digits that
    an eigen-solver on J itself suffers when s is large (near grazing s ~ 1/v-).

    LAPACK on J has a backward error eps ||J|| ~ eps s: a multiplier of modulus ~1 gets
    an error ~eps s, and the multiplier that goes to 0 like v- (the product of all is
    det J, fixed, and one grows like s) loses every digit once v-^2 ~ eps (issue 32:
    4x off at v- = 3e-8). Here

    * (J - lambda) x = 0 is the pencil [[B, p], [q^T, -1/s]] - lambda diag(I, 0) on
      (x, eta = s q^T x), whose entries are bounded: QZ (scipy.linalg.eig) gives its 2n
      finite eigenvalues with an error ~eps, and one infinite one (dropped);
    * the large multiplier ~ s q^T p comes from the trace, tr J = tr B + s q^T p, minus
      the others (no cancellation: it dominates);
    * a real multiplier much smaller than every other (modulus below 1e-3 of the next)
      comes from the determinant, lambda_min = det J / prod(others), ``det`` exact
      (e^{tr(A) T} r^2 (1 + k_{n+i_a})), so it keeps its relative digits.
    """
    import scipy.linalg

    B = np.asarray(B, dtype=float)
    m = B.shape[0]
    pencil = np.zeros((m + 1, m + 1))
    pencil[:m, :m] = B
    pencil[:m, m] = p
    pencil[m, :m] = q
    pencil[m, m] = -1.0 / s if s != 0.0 else -math.inf
    if not math.isfinite(pencil[m, m]):
        lam = np.linalg.eigvals(B).astype(complex)
    else:
        ident = np.eye(m + 1)
        ident[m, m] = 0.0
        alpha, beta = scipy.linalg.eig(pencil, ident, right=False, homogeneous_eigvals=True)
        ratio = np.abs(beta) / np.maximum(np.abs(alpha), 1e-300)
        keep = np.ones(m + 1, dtype=bool)
        keep[int(np.argmin(ratio))] = False          # the infinite eigenvalue
        lam = _conjugate_pairs((alpha[keep] / beta[keep]).astype(complex))
        big = int(np.argmax(np.abs(lam)))
        rest = np.delete(lam, big)
        if abs(lam[big]) > 1e3 * max(1.0, float(np.max(np.abs(rest), initial=0.0))):
            lam[big] = (np.trace(B) + s * float(q @ p) - rest.sum()).real
    order = np.argsort(-np.abs(lam), kind="stable")
    lam = lam[order]
    if m >= 2 and lam[-1].imag == 0.0 and abs(lam[-1]) < 1e-3 * abs(lam[-2]) and det != 0.0:
        lam[-1] = det / np.prod(lam[:-1]).real
    return lam


def _conjugate_pairs(lam: np.ndarray) -> np.ndarray:
    """The eigenvalues of a real matrix as exact conjugate pairs (each pair's mean) and
    exactly real values: the division alpha / beta of QZ leaves them a rounding apart."""
    pos = lam[lam.imag > 0.0]
    neg = list(lam[lam.imag < 0.0])
    if len(pos) != len(neg):
        return lam
    pairs = []
    for z in pos:
        j = int(np.argmin([abs(z - np.conj(x)) for x in neg]))
        pairs.append(0.5 * (z + np.conj(neg.pop(j))))
    real = lam[lam.imag == 0.0].real.astype(complex)
    return np.concatenate([real, pairs, np.conj(pairs)]).astype(complex)


def branch_multipliers(model: NdofModel, gains, point: PhasePoint,
                       delay: float = 0.0) -> np.ndarray:
    """The Floquet multipliers of the branch orbit (:func:`structured_multipliers` on
    :func:`pi2_factors`, det J = e^{tr(A) T} r^2 (1 + k^T b), the exact determinant
    of one period with one impact; b = e_{n+i_a}, or b_delay = Phi(-delay) e_{n+i_a}
    with an actuation ``delay``, §14)."""
    k = gain_vector(gains, model.n)
    flow = _flow(model)
    _w, _ev, b = _vectors(model, delay)
    det = (math.exp(float(np.trace(flow.A)) * model.period) * model.r ** 2
           * (1.0 + float(k @ b)))
    return structured_multipliers(*pi2_factors(model, k, point, delay), det)


def other_contacts(model: NdofModel, gains, point: PhasePoint, delay: float = 0.0) -> int:
    """How many contacts the branch orbit makes besides its one impact (0 for a true
    1/1 orbit), by the certified search of the exact flow (``oscillator.ndof.impact``).

    The explicit branch assumes that the impact at tau* + psi is the period's only
    contact; this is the global check. From the state just after the impact the flow
    runs sigma to Pi2, takes the kick (with an actuation ``delay``: runs on ``delay``
    and takes the kick k^T z of the Pi2 sample there, §14; with a pulse, an
    :class:`Actuation`, runs on to its start and through it under its force, §18), and
    runs on until :data:`RETURN_MARGIN` T before
    the orbit's next impact; every impact found on the way counts, and a chattering or
    sticking contact counts as one. On the last stretch x_w rises monotonically to the
    impact where the wall coordinate decelerates there (regular grazing); where it
    accelerates into the wall and v- is too small to rule out an earlier touch within
    the stretch, the orbit is not certified (counted as one contact). A check of the orbit, not a shooting: the branch
    point is exact to rounding whatever v-, where the event search on the period map
    cannot resolve an impact of v-^2 below the gap's rounding (v- ~ 1e-8).
    """
    k = gain_vector(gains, model.n)
    model = dataclasses.replace(model, delta_d=float(point.delta_d))
    flow = _flow(model)
    n, w = model.n, model.i_w
    sigma = _sigma(model, point.psi)
    z = np.array(point.state, dtype=float)
    tau = flow.tau_star + point.psi
    push = flow.wall_acceleration(tau, z)
    if push > 0.0 and point.v_minus < push * RETURN_MARGIN * model.period:
        return 1     # accelerating into the wall: the last stretch is not a plain approach
    z[n + w] -= (1.0 + model.r) * point.v_minus
    reach = acted_by(model, delay)
    try:
        first = advance(flow, tau, z, sigma)
        z2, inside = _act(flow, k, np.array(first.z), delay)
        rest = model.period - sigma - reach - RETURN_MARGIN * model.period
        tau_acted = (flow.tau2 + model.omega * reach) % (2.0 * math.pi)
        second = advance(flow, tau_acted, z2, rest) if rest > 0.0 else None
    except (ChatteringError, ImpactCapError):
        return 1
    return len(first.impacts) + inside + (0 if second is None else len(second.impacts))


def _act(flow, k: np.ndarray, z: np.ndarray, delay):
    """(the state when the correction k^T z of the sample z has acted, the impacts in
    that window) by the exact flow: the kick ``delay`` later (flow ``delay``, kick; §14),
    or the ideal pulse of an :class:`Actuation`: flow to start + L, then the constant
    force F = m_a k^T z / w over the width (``forced.advance_with_force``, §15). A pulse
    through a lag (time_constant > 0) is refused: its force outlives the window."""
    m = flow.model
    correction = float(k @ z)
    if not isinstance(delay, Actuation):
        window = advance(flow, flow.tau2, z, delay) if delay > 0.0 else None
        if window is not None:
            z = np.array(window.z)
        z[m.n + m.i_a] += correction
        return z, 0 if window is None else len(window.impacts)
    if delay.time_constant != 0.0:
        raise ParameterError(f"time_constant={delay.time_constant!r} is invalid here: the "
                             "branch's global check flows the ideal pulse (valid: 0)")
    start = delay.start(m) + delay.latency
    force = actuated_mass(flow) * correction / delay.width
    inside = 0
    for t0, duration, f in ((0.0, start, 0.0), (start, delay.width, force)):
        if duration > 0.0:
            seg = advance_with_force(flow, (flow.tau2 + m.omega * t0) % (2.0 * math.pi), z,
                                     duration, f)
            z, inside = np.array(seg.z), inside + len(seg.impacts)
    return z, inside


# ------------------------------------------------- continuation along the branch
def _orbit_point(model: NdofModel, k, point: PhasePoint, delay: float = 0.0) -> OrbitPoint:
    return OrbitPoint(point.delta_d, np.array(point.pi2_state),
                      branch_multipliers(model, k, point, delay), 1, point.v_minus)


def continue_branch(model: NdofModel, gains, values, *, growth: float = 10 ** (1 / 16),
                    psi_max: float = 0.3, delay: float = 0.0) -> OrbitBranch:
    """The 1/1 branch born at grazing at each Delta d of ``values`` (in order), each
    point exact to rounding, with its multipliers and the bifurcations between them.

    The branch is explicit in the impact phase (module docstring), so the
    continuation steps in psi, not in Delta d: from the last point's psi it walks |psi|
    geometrically (factor ``growth``; towards grazing when the next value is nearer it)
    until Delta d(psi) passes the next value, and solves Delta d(psi) = value there by
    Brent's method to a few ulps of psi. Every point is a converged orbit whatever its
    distance to grazing (the error of issue 32 - points 1e-2 off near |Delta d| = 3e-8
    by shooting - has nowhere to come from), and every point is checked globally
    (:func:`other_contacts`). The continuation stops, saying why in ``stopped``, where
    Delta d(psi) turns back before the next value (a fold), the orbit gains another
    contact, v- falls to 0 (grazing: the next value lies beyond psi = 0) or the window
    of psi ends. Bifurcations: sign changes of the test functions
    (``shooting.bifurcation_tests``) of consecutive points, refined by Brent in psi.
    With an actuation ``delay`` the branch is the delayed kick's (§14): the window of
    psi keeps the impact out of the delay (:func:`orbit_at_phase`).
    """
    k = gain_vector(np.zeros(2 * model.n) if gains is None else gains, model.n)
    values = [float(v) for v in values]
    if len(values) < 2 or not all(math.isfinite(v) for v in values):
        raise ValueError("values are invalid: expected at least two finite Delta d values")
    start = orbit_at(model, k, values[0], psi_max, delay)
    points, psis, stopped = [], [], "end"
    if other_contacts(model, k, start, delay):
        return OrbitBranch("delta_d", 1, [], [], f"the orbit at delta_d={values[0]!r} touches "
                           "the wall again within the period: not a 1/1 orbit")
    points.append(_orbit_point(model, k, start, delay))
    psis.append(start.psi)
    for value in values[1:]:
        psi, dd = psis[-1], points[-1].value
        found, why = _walk(model, k, psi, dd, value, growth, psi_max, delay)
        if found is None:
            stopped = why
            break
        if other_contacts(model, k, found, delay):
            stopped = (f"at delta_d={value!r} the orbit of the branch touches the wall again "
                       "within the period: not a 1/1 orbit beyond "
                       f"delta_d={points[-1].value!r}")
            break
        points.append(_orbit_point(model, k, found, delay))
        psis.append(found.psi)
    return OrbitBranch("delta_d", 1, points, _bifurcations(model, k, points, psis, delay),
                       stopped)


def _walk(model, k, psi, dd, target, growth, psi_max, delay=0.0):
    """(the branch point at Delta d = target beyond psi, None) or (None, why): walk |psi|
    by the factor ``growth`` from psi in the direction in which Delta d moves towards
    the target, bracket the crossing and solve it by Brent."""
    def delta(x):
        return orbit_at_phase(model, k, x, delay).delta_d

    if target == dd:
        return orbit_at_phase(model, k, psi, delay), None
    h = 1e-6 * abs(psi)
    slope = (delta(psi + h) - delta(psi - h)) / (2.0 * h)
    outward = (slope * psi > 0.0) == (target > dd)      # |psi| grows towards the target
    factor = growth if outward else 1.0 / growth
    prev, f_prev = psi, dd - target
    while True:
        nxt = prev * factor
        if abs(nxt) > psi_max:
            return None, f"the window |psi| <= {psi_max!r} of the branch ends before delta_d={target!r}"
        if abs(nxt) < 1e-300:
            return None, f"grazing (v- -> 0) before delta_d={target!r}"
        try:
            bp = orbit_at_phase(model, k, nxt, delay)
        except ParameterError as exc:
            return None, str(exc)
        if not bp.v_minus > 0.0:
            return None, f"v- <= 0 at psi={nxt!r}: the branch ends before delta_d={target!r}"
        f_nxt = bp.delta_d - target
        if (f_nxt > 0.0) != (f_prev > 0.0) or f_nxt == 0.0:
            x = brentq(lambda t: delta(t) - target, prev, nxt, xtol=1e-300,
                       rtol=4.0 * 2.0 ** -52, maxiter=400)
            return orbit_at_phase(model, k, x, delay), None
        if abs(f_nxt) > abs(f_prev):
            return None, (f"a fold: Delta d turns back at {bp.delta_d!r} (psi={nxt!r}) before "
                          f"delta_d={target!r}")
        prev, f_prev = nxt, f_nxt


def _bifurcations(model, k, points, psis, delay=0.0):
    """Sign changes of the test functions between consecutive points, refined in psi."""
    out = []
    for (a, pa), (b, pb) in zip(zip(points[:-1], psis[:-1]), zip(points[1:], psis[1:])):
        ta, tb = bifurcation_tests(a.multipliers), bifurcation_tests(b.multipliers)
        for kind in TEST_FUNCTIONS:
            fa, fb = ta[kind], tb[kind]
            if not (math.isfinite(fa) and math.isfinite(fb)) or fa * fb > 0.0 or fa == fb:
                continue

            def f(x, kind=kind):
                bp = orbit_at_phase(model, k, x, delay)
                return bifurcation_tests(branch_multipliers(model, k, bp, delay))[kind]

            try:
                at = brentq(f, pa, pb, xtol=1e-300, rtol=4.0 * 2.0 ** -52, maxiter=200)
            except ValueError:
                continue
            bp = orbit_at_phase(model, k, at, delay)
            out.append(OrbitBifurcation(kind, float(bp.delta_d),
                                        branch_multipliers(model, k, bp, delay)))
    return out

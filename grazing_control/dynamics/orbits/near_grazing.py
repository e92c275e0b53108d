"""A model file's 1/1 orbit near grazing (any n): the local map's prediction, and shooting
from it where the branch explicit in the impact phase has no orbit; the model file's
implementation behind the one entry :func:`.one_one.orbit` (issue 32; moved from
studies/near_grazing/branch.py).

The prediction is the local map near grazing of docs/theory_ndof.md ("Local map near
grazing"), written on Pi2 and carried to order H (docs/ndof_commands.md, "The starting
guess"). With the state z sampled on Pi2 before the kick (deviation from the grazing
orbit), the kick K = I + b k^T, the flow Phi_a from Pi2 to the next Pi1 and Phi_b from
Pi1 to Pi2, P(z) = Phi_b D(Phi_a K z), where on Pi1, for the free flight
x_w(t) = y_w + v_w t - |a| t^2 / 2 of the wall coordinate (|a| = omega^2 d*, the
grazing acceleration of the harmonic response),

    H = y_w + v_w^2 / (2 |a|) - Delta d            (largest penetration)
    v- = sqrt(2 |a| H),  t_i = (v_w - v-) / |a|     (impact velocity and time)
    D(y) = y - (1 + r) v- e_{v_w} + (1 + r) v- t_i e_{x_w}     (H > 0; else D(y) = y)

(the velocity jump of the impact, and the position it leaves at the section time when
flowed back along the parabola). Leading order, D(y) = y + u s, u = -(1 + r) sqrt(2|a|)
e_{v_w}, s = sqrt(H); with N = Phi_a K Phi_b a fixed point has y = (I - N)^-1 N u s and
s^2 (1 - c) = G(1) s - Delta d, G(1) = w^T (I - N)^-1 N u, c = (e_v^T (I - N)^-1 N u)^2
/ (2 |a|). Newton's method on y = N D(y) refines that closed form. Both order-H terms
matter on the design family, where G == 0 makes w^T y of order H: without the velocity
term the guess was 40 % off on the n = 1 file at c2 = -1, without the position term
80 % off on a 3-mass chain at mu = 0.3 (both independent of Delta d). Newton shooting
(:func:`grazing_control.dynamics.orbits.shooting.find_periodic`) on the exact map then gives the
orbit and its monodromy; the prediction is only its starting guess.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits.one_one import EXPLICIT, Orbit11
from grazing_control.dynamics.orbits.orbits import OrbitNotFound
from grazing_control.dynamics.orbits.shooting import (ShootingFailed, find_periodic,
                                                      floquet_multipliers)
from grazing_control.oscillator.control import gain_vector
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.params import ParameterError

__all__ = ["fold_beyond", "with_delta_d", "kick_matrix", "kick_vector", "pi1_factors",
           "local_map", "predicted_orbit", "grazing_side", "model_file_orbit",
           "closed_loop_map", "NEAR"]

TWO_PI = 2.0 * math.pi
#: An orbit within this relative distance of the local map's prediction is the one born
#: at grazing (measured offsets: O(sqrt|Delta d|), below 1e-2 at |Delta d| = 1e-4 on the
#: shipped models and a 3-mass chain; another 1/1 orbit is O(1) or more away).
NEAR = 0.25


def with_delta_d(model, delta_d: float):
    """The same model with the wall at Delta d (validated by the model)."""
    return dataclasses.replace(model, delta_d=float(delta_d))


def closed_loop_map(model, gains=None, delay=0.0) -> ModalMap:
    """The exact period map of the loop: ``ModalMap(model, k, delay)`` for the kick
    ``delay`` after the sample, ``ModalMap(model, k, delay, width)`` for the ideal pulse
    of an :class:`~grazing_control.dynamics.design.family.Actuation` (§15); the map
    without gains uncontrolled. A pulse through an actuator (time constant or latency)
    is refused naming it: its period map has the force as a state
    (``modal_map.actuated_step``), not this one."""
    from grazing_control.dynamics.design.family import Actuation

    if gains is None:
        return ModalMap(model)
    if not isinstance(delay, Actuation):
        return ModalMap(model, gains, delay)
    for name in ("time_constant", "latency"):
        if getattr(delay, name) != 0.0:
            raise ParameterError(f"{name}={getattr(delay, name)!r} is invalid here: the 1/1 "
                                 "orbit is that of the kick or the ideal pulse (valid: 0, no "
                                 "actuator)")
    return ModalMap(model, gains, delay.delay, delay.width)


def kick_matrix(model, gains, delay: float = 0.0) -> np.ndarray:
    """K = I + b k^T, b the velocity unit vector of the actuated coordinate (the kick
    v[i_a] += k^T z at Pi2; issue 17, "The design"); I without gains. With an actuation
    ``delay`` (no impact inside it) b = Phi(-delay) e_{n + i_a} (docs/theory_ndof.md §14,
    (N8))."""
    n2 = 2 * model.n
    K = np.eye(n2)
    if gains is not None:
        K += np.outer(kick_vector(model, delay), gain_vector(gains, model.n))
    return K


def kick_vector(model, delay: float = 0.0) -> np.ndarray:
    """b: e_{n + i_a}, or b_delay = Phi(-delay) e_{n + i_a} with an actuation ``delay``
    (docs/theory_ndof.md §14, (N8); ``family``'s, which checks 0 <= delay < T - s)."""
    from grazing_control.dynamics.design.family import _vectors

    return _vectors(model, delay)[2]


def pi1_factors(model, gains=None, delay: float = 0.0):
    """(N, Phi_a, Phi_b, K): the smooth return map on Pi1 N = Phi_a K Phi_b and its
    factors (module docstring; K of :func:`kick_matrix`). N alone, for every model, is
    :func:`grazing_control.dynamics.maps.zdm.smooth_map`."""
    flow = NdofFlow.of(model)
    off = model.pi2_offset / model.omega
    phi_a = flow.transition(model.period - off)
    phi_b = flow.transition(off)
    K = kick_matrix(model, gains, delay)
    return phi_a @ K @ phi_b, phi_a, phi_b, K


def local_map(model, y, delta_d: float, jacobian: bool = False):
    """The discontinuity map D on Pi1 to order H (module docstring): identity when the
    free flight misses the wall (H <= 0), else the jump of the parabola's impact. With
    ``jacobian``, (D(y), dD/dy): with g = dH/dy = e_w + (v_w / |a|) e_v and
    dv-/dy = |a| g / v-, dD/dy = I - (1 + r) e_v dv-^T
    + ((1 + r) / |a|) e_w ((v_w - 2 v-) dv-^T + v- e_v^T)."""
    flow = NdofFlow.of(model)
    w, v = model.i_w, model.n + model.i_w
    acc = model.omega ** 2 * flow.d_star
    h = y[w] + y[v] ** 2 / (2.0 * acc) - delta_d
    out = np.array(y, dtype=float)
    jac = np.eye(out.size)
    if h > 0.0:
        vm = math.sqrt(2.0 * acc * h)
        out[v] -= (1.0 + model.r) * vm
        out[w] += (1.0 + model.r) * vm * (y[v] - vm) / acc
        if jacobian:
            g = np.zeros(out.size)
            g[w], g[v] = 1.0, y[v] / acc
            dvm = acc * g / vm
            jac[v] -= (1.0 + model.r) * dvm
            jac[w] += (1.0 + model.r) / acc * ((y[v] - 2.0 * vm) * dvm)
            jac[w, v] += (1.0 + model.r) / acc * vm
    return (out, jac) if jacobian else out


def predicted_orbit(model, gains=None, delta_d: float | None = None, delay: float = 0.0):
    """The 1/1 orbit of the local map on Pi2 and its s = sqrt(H) (module docstring), or
    (None, nan) when the local map has no impacting fixed point there.

    First the leading order (closed form in s), then Newton's method on
    y = N D(y) with :func:`local_map` and its Jacobian. With an actuation ``delay`` the
    kick is the delayed one seen on Pi2 (:func:`kick_matrix`)."""
    dd = model.delta_d if delta_d is None else float(delta_d)
    flow = NdofFlow.of(model)
    n, n2 = model.n, 2 * model.n
    N, _phi_a, phi_b, _K = pi1_factors(model, gains, delay)
    acc = model.omega ** 2 * flow.d_star
    u = np.zeros(n2)
    u[n + model.i_w] = -(1.0 + model.r) * math.sqrt(2.0 * acc)
    try:
        y_unit = np.linalg.solve(np.eye(n2) - N, N @ u)
    except np.linalg.LinAlgError:
        return None, math.nan
    g1 = float(y_unit[model.i_w])
    c = float(y_unit[n + model.i_w]) ** 2 / (2.0 * acc)
    s = math.nan
    for a in ((1.0 - c), 1.0):   # the smallest positive root: the orbit born at grazing
        disc = g1 * g1 - 4.0 * a * dd
        if a > 0.0 and disc >= 0.0:
            roots = [x for x in ((g1 - math.sqrt(disc)) / (2.0 * a),
                                 (g1 + math.sqrt(disc)) / (2.0 * a)) if x > 0.0]
            if roots:
                s = min(roots)
                break
    if not s > 0.0:
        return None, math.nan
    y = y_unit * s
    eye = np.eye(n2)
    converged = False
    for _ in range(12):   # Newton on y = N D(y), the order-H local map
        d, jac = local_map(model, y, dd, jacobian=True)
        try:
            step = np.linalg.solve(N @ jac - eye, y - N @ d)
        except np.linalg.LinAlgError:
            break
        y = y + step
        if not np.all(np.isfinite(y)):
            break
        if float(np.max(np.abs(step))) <= 1e-13 * max(float(np.max(np.abs(y))), 1e-300):
            converged = True
            break
    if not converged and np.all(np.isfinite(y)):   # stagnated at rounding: the residual
        res = N @ local_map(model, y, dd) - y
        converged = float(np.max(np.abs(res))) <= 1e-10 * float(np.max(np.abs(y)))
    h = y[model.i_w] + y[n + model.i_w] ** 2 / (2.0 * acc) - dd if converged else -1.0
    if not h > 0.0:   # Newton found no impacting orbit of the local map near y0
        return None, math.nan
    return phi_b @ local_map(model, y, dd), math.sqrt(h)


def grazing_side(model, gains=None, size: float = 1e-6, delay: float = 0.0) -> float:
    """-1 or +1: the sign of Delta d on which the local map has a 1/1 orbit born at
    grazing, i.e. the side whose predicted s at |Delta d| = ``size`` is the smaller
    (s ~ |Delta d| or sqrt|Delta d| there, O(1) on the other side); -1 when neither has
    one."""
    found = []
    for sign in (-1.0, 1.0):
        _z, s = predicted_orbit(model, gains, sign * size, delay)
        if s > 0.0:
            found.append((s, sign))
    return min(found)[1] if found else -1.0


def _monodromy_det(model, gains, impacts: int, delay: float = 0.0) -> float:
    """det of DP over one period with ``impacts`` impacts: det Phi(T) = e^{T tr A} =
    e^{-T tr(M^-1 C)}, det S = r^2 per impact (the saltation matrix, docs/theory_ndof_flow.md)
    and det K = 1 + k^T b (matrix determinant lemma; b of :func:`kick_matrix`, with an
    actuation ``delay`` valid when no impact lies inside it); the n-DOF counterpart of
    OneDOF.jacobian_det (dynamics/maps/model.py)."""
    det_k = 1.0 if gains is None else \
        1.0 + float(gain_vector(gains, model.n) @ kick_vector(model, delay))
    trace = float(np.trace(np.linalg.solve(model.M, model.C)))
    return math.exp(-trace * model.period) * model.r ** (2 * impacts) * det_k


def _multipliers(pmap, model, gains, monodromy, impacts, delay=0.0):
    """Floquet multipliers; the exact determinant (the map's, else :func:`_monodromy_det`)
    keeps the small multiplier of a 2x2 monodromy accurate when the large one grows like
    1/v- (dynamics/shooting.floquet_multipliers). None (no product formula) with a
    sticking impact or an impact inside the window where the correction acts (the
    delay, or the pulse up to its end: docs/theory_delay.md (D3), docs/theory_ndof.md
    §18)."""
    from grazing_control.dynamics.orbits.modal_branch import acted_by

    det = None
    reach = acted_by(model, delay) if gains is not None else 0.0
    inside = any(i.dt <= reach for i in impacts)
    if not any(getattr(i, "sticking", False) for i in impacts) and not inside:
        jd = getattr(pmap, "jacobian_det", None)
        det = jd(1, len(impacts)) if jd is not None else None
        if det is None:
            det = _monodromy_det(model, gains, len(impacts), delay)
    return floquet_multipliers(monodromy, det)


def _offset(state, pred) -> float:
    """Relative distance of an orbit's Pi2 state to the local map's prediction."""
    return math.inf if pred is None else float(
        np.linalg.norm(state - pred) / max(np.linalg.norm(pred), 1e-300))


def _orbit(model, state, multipliers, monodromy, dt, phase, v_minus, route,
           offset) -> Orbit11:
    """The one result type of the 1/1 orbit (:class:`.one_one.Orbit11`): born at grazing
    when found on the explicit branch (connected to psi = 0 by construction) or within
    :data:`NEAR` of the local map's prediction, else 'other'."""
    flow = NdofFlow.of(model)
    born = route == EXPLICIT or offset < NEAR
    return Orbit11(model.delta_d, state, flow.to_physical(flow.tau2, state), multipliers,
                   monodromy, float(dt), float(phase), float(v_minus),
                   "grazing" if born else "other", route, offset)


def _on_branch(model, gains, pred, delay: float = 0.0):
    """(the 1/1 orbit at the model's Delta d on the branch explicit in the impact phase,
    None), or (None, why not) (dynamics/orbits/modal_branch.py: ``orbit_at``, the global check
    ``other_contacts``, the multipliers from ``pi2_factors``; with an actuation ``delay``
    the delayed kick's branch, its impact outside the delay, docs/theory_ndof.md §14)."""
    from grazing_control.dynamics.orbits.modal_branch import (branch_multipliers, orbit_at,
                                                      other_contacts, pi2_factors)

    k = np.zeros(2 * model.n) if gains is None else gain_vector(gains, model.n)
    try:
        bp = orbit_at(model, k, model.delta_d, delay=delay)
    except (ValueError, ParameterError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return None, " ".join(str(exc).split())[:120]
    contacts = other_contacts(model, k, bp, delay)
    if contacts:
        return None, (f"the orbit at psi={bp.psi:.6g} touches the wall {contacts} more "
                      "time(s) per period")
    B, p, q, s = pi2_factors(model, k, bp, delay)
    flow = NdofFlow.of(model)
    sigma = (model.pi2_offset - bp.psi) / model.omega
    state = np.array(bp.pi2_state)
    return _orbit(model, state, branch_multipliers(model, k, bp, delay),
                  B + s * np.outer(p, q), model.period - sigma,
                  (flow.tau_star + bp.psi) % TWO_PI, bp.v_minus, EXPLICIT,
                  _offset(state, pred)), None


def model_file_orbit(model, gains=None, delta_d: float | None = None, *,
                     tol: float = 1e-14, extra_guesses=(), delay: float = 0.0) -> Orbit11:
    """A model file's 1/1 orbit at ``delta_d`` (default the model's), the implementation
    behind :func:`.one_one.orbit`: on the branch explicit in the impact phase where it has
    one, else by Newton shooting.

    First the branch explicit in the impact phase psi (:func:`_on_branch`): the orbit
    with Delta d(psi) = delta_d nearest grazing, exact to rounding whatever v-, checked
    globally for other contacts with the exact flow, its multipliers from the
    monodromy's factors. Shooting on the period map cannot take its place near
    grazing: its event search resolves an impact only where v-^2 exceeds the gap's
    rounding (v- ~ 1e-8), and there it stopped converging (issue 32: the 2-mass chain
    failed for |Delta d| <= 1.28e-8, a 3-mass chain at +1e-10 converged to the
    non-impacting orbit instead). Then Newton shooting from the starting guesses, in
    order: the leading-order prediction (:func:`predicted_orbit`), ``extra_guesses``
    (name, state pairs), the grazing point z = 0, and the end of a 200-period
    simulation from the prediction. The first that converges to an orbit with exactly
    one impact per period wins. With an actuation ``delay`` (the kick k^T z of the sample
    acts ``delay`` later) both routes are the delayed kick's: the explicit branch where
    the impact lies outside the delay (docs/theory_ndof.md §14), shooting on the exact
    delayed map ``ModalMap(model, k, delay)`` otherwise. With an
    :class:`~grazing_control.dynamics.design.family.Actuation` as ``delay`` (the ideal
    pulse of width w centred delay after the sample) both routes are the pulse's: the
    branch with b_w where the impact lies after the pulse's end (§18), shooting on
    ``ModalMap(model, k, delay, w)`` otherwise (:func:`closed_loop_map`).

    Raises
    ------
    OrbitNotFound
        None converged to a 1/1 orbit (the message lists why each failed).
    """
    if delta_d is not None:
        model = with_delta_d(model, delta_d)
    from grazing_control.dynamics.design.family import Actuation

    if gains is None:
        delay = 0.0
    elif not isinstance(delay, Actuation):
        delay = float(delay)
    pmap = closed_loop_map(model, gains, delay)
    try:
        pred, _s = predicted_orbit(model, gains, delay=delay)
    except ParameterError:     # a correction past the grazing phase: no local map (§14)
        pred = None
    explicit, reason = _on_branch(model, gains, pred, delay)
    if explicit is not None:
        return explicit
    guesses = [] if pred is None else [("discontinuity map", pred)]
    guesses += list(extra_guesses)
    guesses.append(("grazing point", np.zeros(pmap.dimension)))
    why = [f"impact phase: {reason}"]
    tried_simulation = False
    i = 0
    while i < len(guesses):
        name, guess = guesses[i]
        i += 1
        try:
            o = find_periodic(pmap, guess, 1, tol=tol)
        except (ShootingFailed, ValueError, ArithmeticError) as exc:
            why.append(f"{name}: {' '.join(str(exc).split())[:120]}")
        else:
            if len(o.impacts) == 1 and o.impacts[0].v_minus > 0.0:
                imp = o.impacts[0]
                lam = _multipliers(pmap, model, gains, o.monodromy, o.impacts, delay)
                return _orbit(model, o.state, lam, o.monodromy, imp.dt, imp.phase,
                              imp.v_minus, name, _offset(o.state, pred))
            why.append(f"{name}: converged to an orbit with {len(o.impacts)} impacts per period")
        if i == len(guesses) and not tried_simulation:
            tried_simulation = True
            try:
                z = _simulated_guess(pmap, pred if pred is not None else guesses[-1][1],
                                     SIMULATED_PERIODS, DIVERGED * NdofFlow.of(model).d_star)
                guesses.append(("simulation", z))
            except (ValueError, ArithmeticError, RuntimeError) as exc:
                why.append(f"simulation: {' '.join(str(exc).split())[:120]}")
    raise OrbitNotFound(f"no 1/1 orbit found at delta_d={model.delta_d!r} "
                        f"({'; '.join(why)})")


#: The simulation that gives model_file_orbit its last starting guess: periods, and the size of a
#: state (times d*, the wall coordinate's amplitude) beyond which the motion is taken as
#: diverging. A 1/1 orbit near grazing lies within a few d* of the grazing point; an
#: unstable loop (the 2-mass chain at mu = 0 with a delay of 2: gains ~170) grew 6x a
#: period, and at |z| ~ 1e25 each period's certified impact search took 11-39 s (the
#: rounding of the gap grows with the state), so `grazing orbit` ran for minutes.
SIMULATED_PERIODS, DIVERGED = 200, 1e3


def _simulated_guess(pmap, start, periods: int, bound: float) -> np.ndarray:
    """The state ``periods`` periods after ``start`` (no Jacobian: a guess only);
    ArithmeticError once a state is not finite or leaves ``max |z| <= bound``."""
    z = np.asarray(start, dtype=float)
    for k in range(periods):
        z = pmap.step(z).state
        if not (np.all(np.isfinite(z)) and np.max(np.abs(z)) <= bound):
            raise ArithmeticError(f"the motion left |z| <= {bound:.3g} at period {k + 1} "
                                  "(diverging: no attractor to start shooting from)")
    return z


def fold_beyond(model, gains, branch, stop: float, delay: float = 0.0):
    """The fold where a continuation in Delta d stopped short of ``stop``, or None.

    A continuation in Delta d cannot pass a turning point of the branch; the branch
    explicit in the impact phase can (``dynamics.orbits.modal_branch.branch_fold``). The fold is
    reported only if it lies beyond the last point reached, towards ``stop``, and its
    orbit is an orbit of the exact map (one period of ``ModalMap`` from its Pi2 state
    returns there to 1e-8 with one impact: the explicit branch assumes that impact is the
    period's only contact). Returns a dict: delta_d, psi, v_minus, the multiplier nearest
    1 and the exact map's residual.
    """
    from grazing_control.dynamics.orbits.modal_branch import branch_fold

    if not branch.points or branch.stopped == "end":
        return None
    last = branch.points[-1].value
    try:
        fold = branch_fold(model, gains, delay=delay)
    except (ValueError, ParameterError, np.linalg.LinAlgError):
        return None
    if fold is None or fold.monodromy is None or (fold.delta_d - last) * (stop - last) < 0.0:
        return None
    step = closed_loop_map(with_delta_d(model, fold.delta_d), gains,
                           delay).step(fold.pi2_state)
    size = max(1.0, float(np.max(np.abs(fold.pi2_state))))
    residual = float(np.max(np.abs(step.state - fold.pi2_state))) / size
    if residual > 1e-8 or len(step.impacts) != 1:
        return None
    lam = np.linalg.eigvals(fold.monodromy)
    near = lam[np.argmin(np.abs(lam - 1.0))]
    return {"delta_d": float(fold.delta_d), "psi": float(fold.psi),
            "v_minus": float(fold.v_minus), "multiplier_near_1": [near.real, near.imag],
            "residual": residual}

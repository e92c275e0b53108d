"""The degenerate grazing gain family k(mu) of a model file, any n: the design (issues 17, 32).

The family w^T N(k) = mu w^T is the design of every model file, n = 1 included, where it
is the 1-DOF (c1, c2) family of :mod:`.gains` (the closed form, parametrised by c2;
tests/test_n1_model_file.py: the same multipliers to 1e-12); :mod:`.model_design` is the
one entry over both that callers use.

Derived in docs/theory_ndof.md (sections cited as §N). State z in R^{2n}: the deviation
(positions, velocities) from the non-impacting periodic response; on
Pi1 = {tau = tau*} the wall coordinate ``i_w`` is at its grazing maximum. With
P = Phi(s), Q = Phi(T - s) (s = pi2_offset / omega, T = 2 pi / omega, Phi(t) = exp(A t))
and a kick Delta v_{i_a} = k^T z on Pi2 (b = e_{n + i_a}), the smooth map through
grazing on Pi1 is (§2)

    N(k) = Q (I + b k^T) P = Phi(T) + g k^T P,       g = Q b.

* Gain family (§3): w^T N(k) = mu w^T (w = e_{i_w}) kills every Markov parameter
  w^T N^j u of the singular term; it is 2n - 1 linear equations in k, solved by
  k(mu) = (mu Phi(-s)^T w - Q^T w) / c, c = w^T Q b != 0.
* Transmission zeros (§4): on the family spec N = {mu} U zeros of (Phi(T), g, w^T),
  the generalized eigenvalues of the Rosenbrock pencil.
* Limit multipliers (§6): the 2n eigenvalues of the controlled 1/1 orbit as
  Delta d -> 0-, eigenvalues of the limit monodromy J0(mu) (closed form, affine in mu);
  for n = 1 this is study Eq. 23 (docs/theory_delay.md (D8)).
* Existence (§7): Delta d = -gamma1 psi^2 + O(psi^3) on the 1/1 branch born at
  grazing, gamma1 > 0 the n-DOF Eq. 36 (for n = 1, (D9)).
* Admissible mu (§8): where the limit spectrum is inside the unit circle, gamma1 > 0
  ('impacting') and spec N(k(mu)) inside ('non-impacting'); ends from roots.
* A known actuation delay (§14): the kick computed from the sample on Pi2 acts
  ``delay`` later; for 0 <= delay < T - s (before the grazing phase) everything above
  holds with b replaced by b_delay = Phi(-delay) e_{n + i_a} (every function takes
  ``delay``, default 0: today's design, the same floats).
* A force pulse, maybe through a first-order actuator (§15): ``delay`` may be an
  :class:`Actuation` (the pulse of ``width`` centred ``delay`` after the sample, the
  actuator's time constant and latency); b is then the pulse's effective input vector
  b_w (Eq. (N10)), everything else unchanged; :func:`pulse_design` is the entry point.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from grazing_control.oscillator.control import gain_vector
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.design.gains import admissible_intervals

__all__ = [
    "CONDITIONS",
    "MU_LIMIT",
    "smooth_map",
    "markov_parameters",
    "gain_family",
    "family_mu",
    "default_mu",
    "transmission_zeros",
    "sections_with_stable_zeros",
    "limit_monodromy",
    "limit_multipliers",
    "existence_coefficient",
    "free_multipliers",
    "FamilyDesign",
    "evaluate_design",
    "admissible_mu",
    "cancel_first_markov",
    "controller_parameters",
    "write_gain_yaml",
    "Actuation",
    "pulse_design",
    "design_actuation",
    "actuation_parameters",
]

#: Condition sets of :func:`admissible_mu` (as dynamics/design/gains.py): 'impacting' = the
#: limit spectrum inside the unit circle and gamma1 > 0; 'non-impacting' = spec N(k)
#: inside (|mu| < 1 and the transmission zeros); 'combined' = both.
CONDITIONS = ("combined", "impacting", "non-impacting")

#: The admissible set is searched in |mu| < MU_LIMIT; a set still open there gets an
#: infinite end.
MU_LIMIT = 1e6


# -- the smooth flow -------------------------------------------------------------------

@functools.lru_cache(maxsize=32)
def _flow(model: NdofModel) -> NdofFlow:
    """The model's exact flow (NdofFlow.of, built once per model object)."""
    return NdofFlow.of(model)


def _transition(model: NdofModel, t: float) -> np.ndarray:
    """Phi(t) = exp(A t) of the deviation, A = [[0, I], [-M^-1 K, -M^-1 C]] (§1)."""
    return _flow(model).transition(t)


@dataclass(frozen=True)
class Actuation:
    """How the correction k^T z acts (§15): a force pulse of ``width`` w > 0 on the
    actuated coordinate centred ``delay`` after the sample (it starts at
    :func:`grazing_control.dynamics.simulation.actuation.pulse_start`), carrying the
    impulse m_a k^T z, through a first-order actuator of ``time_constant`` tau_a >= 0 and
    ``latency`` L >= 0 (0, 0: the ideal pulse). Passed as ``delay`` to every function of
    this module."""

    delay: float = 0.0
    width: float = 0.0
    time_constant: float = 0.0
    latency: float = 0.0

    def __post_init__(self):
        for name in ("delay", "width", "time_constant", "latency"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating,
                                                                 np.integer)) \
                    or not (math.isfinite(value) and value >= 0.0):
                raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite "
                                     f"{name} >= 0")
            object.__setattr__(self, name, float(value))
        if not self.width > 0.0:
            raise ParameterError(f"width={self.width!r} is invalid: valid range is a pulse "
                                 f"width > 0 (width 0 is the kick: pass the delay itself)")

    def start(self, model: NdofModel) -> float:
        """When the commanded pulse starts after the sample (centred at ``delay``)."""
        from grazing_control.dynamics.simulation.actuation import pulse_start

        return pulse_start(model.period, self.delay, self.width)

    def end(self, model: NdofModel) -> float:
        """When the commanded pulse reaches its end at the mass: start + L + w."""
        return self.start(model) + self.latency + self.width


@functools.lru_cache(maxsize=64, typed=True)
def _vectors(model: NdofModel, delay: float = 0.0):
    """(w, e_v, b): the wall coordinate's position and velocity rows, the kick direction
    seen on Pi2, b = Phi(-delay) e_{n + i_a} (§14; e_{n + i_a} itself without delay); for
    an :class:`Actuation` the pulse's effective input vector b_w (§15, (N10)).

    Formed once a model and delay (the model's identity: NdofModel compares by identity;
    ``typed``: a delay True is not the delay 1 and is refused) and read-only: the design's
    searches over mu ask for them hundreds of thousands of times (issue 30, the suite's
    CPU)."""
    n = model.n
    eye = np.eye(2 * n)
    b = eye[n + model.i_a]
    if isinstance(delay, Actuation):
        b = _pulse_vector(model, delay)
    elif delay != 0.0:
        b = _transition(model, -_delay(model, delay)) @ b
    return _read_only(eye[model.i_w], eye[n + model.i_w], b)


def _read_only(*arrays):
    """The arrays, made read-only (a cached value no caller may change)."""
    for a in arrays:
        a.flags.writeable = False
    return arrays


def _pulse_vector(model: NdofModel, act: Actuation) -> np.ndarray:
    """b_w of the pulse (and actuator) ``act``, checked to end before the grazing phase:
    start + L + w < T - s (§15)."""
    from grazing_control.oscillator.ndof.forced import actuated_input

    reach = model.period - model.pi2_offset / model.omega
    start = act.start(model)
    if not act.end(model) < reach:
        raise ParameterError(
            f"width={act.width!r} is invalid with delay={act.delay!r} and latency="
            f"{act.latency!r}: valid range is start + latency + width < T - s = {reach:.10g} "
            f"(the pulse must act before the grazing phase, docs/theory_ndof.md §15)")
    return actuated_input(_flow(model), start + act.latency, act.width, act.time_constant,
                          reach)


def _delay(model: NdofModel, delay) -> float:
    """The actuation delay, checked: 0 <= delay < T - s (§14: a kick after the grazing
    phase cannot remove the singular multiplier)."""
    reach = model.period - model.pi2_offset / model.omega
    if isinstance(delay, bool) or not isinstance(delay, (int, float, np.floating, np.integer)) \
            or not 0.0 <= float(delay) < reach:
        raise ParameterError(
            f"delay={delay!r} is invalid: valid range is 0 <= delay < T - s = {reach:.10g} "
            f"(the kick must act before the grazing phase, docs/theory_ndof.md §14)")
    return float(delay)


@functools.lru_cache(maxsize=32)
def _sections(model: NdofModel):
    """(P, Q, Phi(-s)) with P = Phi(s), Q = Phi(T - s), s = pi2_offset / omega; formed once
    a model and read-only (as :func:`_vectors`)."""
    s = model.pi2_offset / model.omega
    return _read_only(_transition(model, s), _transition(model, model.period - s),
                      _transition(model, -s))


def smooth_map(model: NdofModel, gains=None, delay: float = 0.0) -> np.ndarray:
    """N(k) = Phi(T - s)(I + b k^T) Phi(s), the Pi1 map through grazing (§2; with a delay
    b = Phi(-delay) e_{n + i_a}, §14); Phi(T) without gains."""
    p, q, _ = _sections(model)
    if gains is None:
        return q @ p
    k = gain_vector(gains, model.n)
    _w, _ev, b = _vectors(model, delay)
    return q @ (np.eye(2 * model.n) + np.outer(b, k)) @ p


def markov_parameters(model: NdofModel, gains=None, delay: float = 0.0) -> np.ndarray:
    """w^T N^j e_v for j = 1 .. 2n (§2): the singular term of the near-grazing
    characteristic polynomial vanishes identically iff all are 0."""
    n_mat = smooth_map(model, gains, delay)
    w, ev, _b = _vectors(model)
    out, row = [], w
    for _ in range(2 * model.n):
        row = row @ n_mat
        out.append(float(row @ ev))
    return np.array(out)


# -- the family and its zeros (§3, §4) ---------------------------------------------------

def _reach_value(model: NdofModel, delay: float = 0.0) -> float:
    """c = w^T Phi(T - s) b: how a kick on Pi2 moves the wall coordinate at tau* (§3);
    with a delay c = w^T Phi(T - s - delay) e_{n + i_a} (§14)."""
    w, _ev, b = _vectors(model, delay)
    return float(w @ _sections(model)[1] @ b)


def _reach(model: NdofModel, delay: float = 0.0) -> float:
    """c = w^T Phi(T - s) b, refused when the kick cannot reach the wall coordinate."""
    c = _reach_value(model, delay)
    if not abs(c) > 1e-12 * max(1.0, float(np.abs(_sections(model)[1]).max())):
        if delay != 0.0:
            raise ParameterError(
                f"delay={delay!r} is invalid with this model: w^T Phi(T - s - delay) b = {c!r}, "
                f"a kick acting then does not reach the wall coordinate's position at the "
                f"grazing phase (a singular delay, docs/theory_ndof.md §14); choose another")
        raise ParameterError(
            f"pi2_offset={model.pi2_offset!r} is invalid with i_a={model.i_a}, i_w={model.i_w}: "
            f"w^T Phi(T - s) b = {c!r}, a kick on Pi2 does not reach the wall coordinate's "
            f"position at the grazing phase (no gain family exists); choose another "
            f"0 < pi2_offset < 2 pi or actuated coordinate")
    return c


def gain_family(model: NdofModel, mu: float, delay: float = 0.0) -> np.ndarray:
    """k(mu) = (mu Phi(-s)^T w - Phi(T - s)^T w) / c: the gains with w^T N = mu w^T (§3);
    with an actuation delay c = w^T Phi(T - s - delay) e_{n + i_a} (§14, Eq. (N9)).

    Raises ParameterError where c = 0 (no family), mu is not finite or the delay is
    outside 0 <= delay < T - s.
    """
    mu = _mu(mu)
    c = _reach(model, delay)
    _p, q, pinv = _sections(model)
    w, _ev, _b = _vectors(model)
    return (mu * (pinv.T @ w) - q.T @ w) / c


def family_mu(model: NdofModel, gains, delay: float = 0.0) -> float:
    """mu = N(k)_{i_w, i_w}: the family's parameter of a gain on it (for n = 1 the 1-DOF
    N_g,11 = u0 + sigma c2, §3)."""
    return float(smooth_map(model, gains, delay)[model.i_w, model.i_w])


def _mu(mu) -> float:
    if isinstance(mu, bool) or not isinstance(mu, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(mu)) or abs(float(mu)) > MU_LIMIT:
        raise ParameterError(f"mu={mu!r} is invalid: valid range is |mu| <= {MU_LIMIT:g} "
                             "(the family's search range; a stable design has |mu| < 1)")
    return float(mu)


@functools.lru_cache(maxsize=64, typed=True)
def transmission_zeros(model: NdofModel, delay: float = 0.0) -> np.ndarray:
    """The 2n - 1 transmission zeros of (Phi(T), Phi(T - s) b, w^T) (§4; with a delay
    b = Phi(-delay) e_{n + i_a}, so they move with the delay, §14).

    Finite generalized eigenvalues of the Rosenbrock pencil
    [[Phi(T), g], [w^T, 0]] - lambda [[I, 0], [0, 0]] (the pencil has two infinite ones,
    relative degree 1 since c = w^T g != 0), sorted by decreasing modulus. The same for
    every mu: formed once a model and delay, read-only (as :func:`_vectors`).
    """
    _reach(model, delay)
    p, q, _ = _sections(model)
    w, _ev, b = _vectors(model, delay)
    d = 2 * model.n
    a = np.zeros((d + 1, d + 1))
    a[:d, :d] = q @ p
    a[:d, d] = q @ b
    a[d, :d] = w
    bb = np.zeros_like(a)
    bb[:d, :d] = np.eye(d)
    alpha, beta = scipy.linalg.eig(a, bb, right=False, homogeneous_eigvals=True)
    ratio = np.where(beta != 0, np.abs(alpha) / np.maximum(np.abs(beta), 1e-300), np.inf)
    keep = np.argsort(ratio, kind="stable")[: d - 1]
    z = (alpha[keep] / beta[keep]).astype(complex)
    return _read_only(z[np.argsort(-np.abs(z), kind="stable")])[0]


def _zeros_radius_at(model: NdofModel, offset: float, delay: float = 0.0) -> float:
    """max |zero| with Pi2 at ``offset`` after Pi1 (inf where the kick cannot reach the
    wall coordinate by the grazing section, w^T Phi(T - s - delay) b = 0, or acts after
    it, delay >= T - s)."""
    import dataclasses

    try:
        z = transmission_zeros(dataclasses.replace(model, pi2_offset=offset), delay)
    except ParameterError:
        return math.inf
    return float(np.max(np.abs(z))) if z.size else 0.0


def sections_with_stable_zeros(model: NdofModel, points: int = 720,
                               tol: float = 1e-9, delay: float = 0.0) -> list:
    """The intervals of ``pi2_offset`` in (0, 2 pi) where every transmission zero lies
    inside the unit circle (§4): where the section Pi2 may be placed for a design to
    exist (the zeros are fixed by the plant, the actuated coordinate and the section,
    whatever the gain). A scan of ``points`` offsets with each switch bisected to
    ``tol``: a design aid, not a certified set (an interval narrower than the scan's
    step, 2 pi / points, can be missed). With an actuation ``delay`` the zeros are the
    delayed kick's (§14), and offsets with delay >= T - s have none inside.
    """
    if isinstance(points, bool) or not isinstance(points, int) or points < 2:
        raise ParameterError(f"points={points!r} is invalid: valid range is an integer >= 2")
    grid = np.linspace(0.0, 2.0 * math.pi, points + 1)[1:-1]
    inside = [_zeros_radius_at(model, float(s), delay) < 1.0 for s in grid]

    def switch(a, b, a_in):
        while b - a > tol:
            m = 0.5 * (a + b)
            if (_zeros_radius_at(model, m, delay) < 1.0) == a_in:
                a = m
            else:
                b = m
        return 0.5 * (a + b)

    intervals, start = [], (0.0 if inside[0] else None)
    for i in range(1, len(grid)):
        if inside[i] != inside[i - 1]:
            edge = switch(float(grid[i - 1]), float(grid[i]), inside[i - 1])
            if inside[i]:
                start = edge
            else:
                intervals.append((start, edge))
                start = None
    if start is not None:
        intervals.append((start, 2.0 * math.pi))
    return intervals


# -- the limit of the controlled 1/1 orbit (§5-§7) ----------------------------------------

@functools.lru_cache(maxsize=64, typed=True)
def _reduced(model: NdofModel, delay: float = 0.0):
    """(N~, iv, a1, q): N restricted to W = ker w^T (rows and columns other than i_w,
    the same for every mu), the index of e_v in it, a1 = e_v^T (N~ - I)^-1 e_v and
    q = r + (1 + r) a1 = e_v^T (N~ - I)^-1 (r N~ + I) e_v (§5); formed once a model
    and delay, N~ read-only (as :func:`_vectors`)."""
    n_mat = smooth_map(model, gain_family(model, 0.0, delay), delay)
    keep = [j for j in range(2 * model.n) if j != model.i_w]
    nt = n_mat[np.ix_(keep, keep)]
    iv = keep.index(model.n + model.i_w)
    eye = np.eye(len(keep))
    try:
        a1 = float(np.linalg.solve(nt - eye, eye[iv])[iv])
    except np.linalg.LinAlgError:
        a1 = math.inf
    if not math.isfinite(a1):
        raise ParameterError("model is invalid for the design: 1 is a transmission zero "
                             "(N - I singular on ker w^T), the 1/1 branch born at grazing is "
                             "not a graph over psi")
    return _read_only(nt)[0], iv, a1, model.r + (1.0 + model.r) * a1


def limit_monodromy(model: NdofModel, mu: float, delay: float = 0.0) -> np.ndarray:
    """J0(mu): the monodromy of the controlled 1/1 orbit at its impact, in the limit
    Delta d -> 0-, up to similarity (the wall coordinate's row scaled by 1/psi) (§6, Eq. (N6)).

    With N~ = N on W = ker w^T, e_v the wall velocity in it, R = I - (1 + r) e_v e_v^T,
    gamma = -(1 + r) omega q::

        J0[w, w] = -r mu + gamma (N~_vv - mu) / omega,
        J0[w, W] = (e_v^T N~ - mu e_v^T) R / omega,
        J0[W, w] = gamma N~ e_v,        J0[W, W] = N~ R;

    det J0 = r^2 det N. For n = 1 its trace and determinant are (D8). With an actuation
    delay N is N(k; delay) (§14).
    """
    mu = _mu(mu)
    nt, iv, _a1, q = _reduced(model, delay)
    r, om = model.r, model.omega
    d = 2 * model.n
    gam = -(1.0 + r) * om * q
    ev = np.eye(d - 1)[iv]
    rw = np.eye(d - 1) - (1.0 + r) * np.outer(ev, ev)
    keep = [j for j in range(d) if j != model.i_w]
    j0 = np.zeros((d, d))
    j0[model.i_w, model.i_w] = -r * mu + gam * (nt[iv, iv] - mu) / om
    j0[model.i_w, keep] = (nt[iv] - mu * ev) @ rw / om
    j0[np.ix_(keep, [model.i_w])] = (gam * nt[:, iv])[:, None]
    j0[np.ix_(keep, keep)] = nt @ rw
    return j0


def limit_multipliers(model: NdofModel, mu: float, delay: float = 0.0) -> np.ndarray:
    """The predicted limit spectrum of the controlled 1/1 orbit as Delta d -> 0- on the
    family (§6): the 2n eigenvalues of :func:`limit_monodromy`, by decreasing modulus.

    It is not {mu(1 + w^T q)} U zeros (docs/theory_ndof.md §6 says why); for n = 1 it is
    the study's lambda0 (Eq. 23).
    """
    lam = np.linalg.eigvals(limit_monodromy(model, mu, delay)).astype(complex)
    return lam[np.argsort(-np.abs(lam), kind="stable")]


def existence_coefficient(model: NdofModel, mu: float, delay: float = 0.0) -> float:
    """gamma1(mu): Delta d = -gamma1 psi^2 + O(psi^3) on the 1/1 branch born at grazing
    (§7, Eq. (N7); psi the impact phase after tau*). The controlled 1/1 orbit exists for
    d < d* iff gamma1 > 0 (the n-DOF Eq. 36)::

        gamma1 = d*/2 + (1 + r) d* (1 + a1 - mu a1) / (q (mu - 1)).

    For n = 1 (a1 = 1/(N22 - 1)) this is (D9). inf/nan at its poles mu = 1, q = 0.
    """
    mu = _mu(mu)
    _nt, _iv, a1, q = _reduced(model, delay)
    dstar, r = _flow(model).d_star, model.r
    num, den = (1.0 + r) * dstar * (1.0 + a1 - mu * a1), q * (mu - 1.0)
    if den == 0.0:
        return 0.5 * dstar if num == 0.0 else math.copysign(math.inf, num)
    return 0.5 * dstar + num / den


def _existence_value(mu: float, a1: float, q: float, r: float) -> float:
    """Division-free sign of gamma1: (mu - 1) q (q (mu - 1)/2 + (1 + r)(1 + a1 - mu a1))."""
    e = q * (mu - 1.0)
    return e * (0.5 * e + (1.0 + r) * (1.0 + a1 - mu * a1))


def free_multipliers(model: NdofModel, mu: float, delay: float = 0.0) -> np.ndarray:
    """Eigenvalues of N(k(mu)): the non-impacting controlled motion (Delta d > 0), which
    on the family are {mu} U transmission zeros (§4)."""
    lam = np.concatenate([[complex(_mu(mu))], transmission_zeros(model, delay)])
    return lam[np.argsort(-np.abs(lam), kind="stable")]


@dataclass(frozen=True)
class FamilyDesign:
    """The design quantities for one mu (gains from the family, §3).

    mu : the eigenvalue of N(k) along w (w^T N = mu w^T).
    gains : k(mu), the 2n gains of the kick Delta v_{i_a} = k^T z on Pi2.
    zeros : the 2n - 1 transmission zeros (the other eigenvalues of N, any mu).
    limit_multipliers : the 2n multipliers of the controlled 1/1 orbit as Delta d -> 0-.
    gamma1 : existence coefficient, > 0: the 1/1 orbit exists for d < d*.
    delay : the actuation delay the gains are designed for (§14; 0: the kick on Pi2).
    """

    mu: float
    gains: np.ndarray
    zeros: np.ndarray
    limit_multipliers: np.ndarray
    gamma1: float
    delay: float = 0.0

    @property
    def lambda0(self) -> np.ndarray:
        """The study's name (Eq. 23) for :attr:`limit_multipliers`."""
        return self.limit_multipliers

    @property
    def zeros_radius(self) -> float:
        """max |zero|: < 1 is needed for the non-impacting side (§4)."""
        return float(np.max(np.abs(self.zeros)))

    @property
    def limit_radius(self) -> float:
        """max |lambda| of the limit spectrum."""
        return float(np.max(np.abs(self.limit_multipliers)))

    @property
    def stable(self) -> bool:
        """The near-grazing controlled 1/1 orbit is stable (limit radius < 1)."""
        return self.limit_radius < 1.0

    @property
    def exists(self) -> bool:
        return self.gamma1 > 0.0

    @property
    def free_stable(self) -> bool:
        """rho(N) = max(|mu|, zeros radius) < 1: the non-impacting motion is stable."""
        return abs(self.mu) < 1.0 and self.zeros_radius < 1.0

    @property
    def admissible_impacting(self) -> bool:
        return self.stable and self.exists

    @property
    def admissible(self) -> bool:
        """All of §8: stable, exists, and the non-impacting motion stable."""
        return self.admissible_impacting and self.free_stable


def evaluate_design(model: NdofModel, mu: float, delay: float = 0.0) -> FamilyDesign:
    """gains, zeros, limit multipliers and gamma1 at mu (for a kick acting ``delay`` after
    the sample, §14)."""
    k = gain_family(model, mu, delay)
    return FamilyDesign(float(mu), k, transmission_zeros(model, delay),
                      limit_multipliers(model, mu, delay),
                      existence_coefficient(model, mu, delay),
                      delay if isinstance(delay, Actuation) else float(delay))


# -- the admissible set (§8) ------------------------------------------------------------

def _char_affine(model: NdofModel, delay: float = 0.0):
    """(p0, p1): det(lambda I - J0(mu)) = p0(lambda) + mu p1(lambda), coefficient arrays
    of length 2n + 1 (J0 is affine in mu through one row, §8)."""
    j_0 = limit_monodromy(model, 0.0, delay)
    j_1 = limit_monodromy(model, 1.0, delay)
    p0 = np.real(np.poly(j_0))
    p1 = np.real(np.poly(j_1)) - p0
    return p0, p1


def _limit_breakpoints(model: NdofModel, delay: float = 0.0) -> list:
    """mu where a root of p0 + mu p1 may lie on the unit circle: lambda = e^{i theta}
    with p0(z) conj(p1(z)) real, i.e. roots on |z| = 1 of
    p0(z) z^{2n} p1(1/z) - p1(z) z^{2n} p0(1/z) (§8)."""
    p0, p1 = _char_affine(model, delay)
    qz = np.polysub(np.polymul(p0, p1[::-1]), np.polymul(p0[::-1], p1))
    scale = float(np.abs(qz).max()) or 1.0
    qz = np.trim_zeros(np.where(np.abs(qz) <= 1e-14 * scale, 0.0, qz), "f")
    out = []
    roots = np.roots(qz) if qz.size > 1 else np.array([])
    for z in list(roots) + [1.0, -1.0]:
        if abs(abs(z) - 1.0) > 1e-4:
            continue
        z = z / abs(z)
        den = np.polyval(p1, z)
        if den == 0:
            continue
        mu = -np.polyval(p0, z) / den
        if abs(mu.imag) <= 1e-6 * max(1.0, abs(mu.real)) and abs(mu.real) < MU_LIMIT:
            out.append(float(mu.real))
    return out


def admissible_mu(model: NdofModel, conditions: str = "combined", delay: float = 0.0):
    """Intervals of mu where the design conditions hold (§8), as [(lo, hi), ...].

    ``conditions``: 'impacting' (limit spectrum inside the unit circle and gamma1 > 0),
    'non-impacting' (|mu| < 1 and the transmission zeros inside) or 'combined' (both,
    the default). Every mu where a condition can switch is a root: of the unit-circle
    polynomial of the limit spectrum (:func:`_limit_breakpoints`), mu = 1 and the zero
    of gamma1 (linear), mu = +-1; each interval's ends are bisected to adjacent floats
    (:func:`grazing_control.dynamics.design.gains.admissible_intervals`).
    """
    if conditions not in CONDITIONS:
        raise ValueError(f"conditions={conditions!r} is invalid: valid values are "
                         f"{', '.join(CONDITIONS)}")
    zeros_in = bool(np.max(np.abs(transmission_zeros(model, delay))) < 1.0)
    _nt, _iv, a1, q = _reduced(model, delay)
    r = model.r
    impact = conditions in ("combined", "impacting")
    free = conditions in ("combined", "non-impacting")
    if free and not zeros_in:
        return []
    cands = [1.0, -1.0]
    if impact:
        cands += _limit_breakpoints(model, delay)
        den = 0.5 * q - (1.0 + r) * a1
        if den != 0.0:
            cands.append((0.5 * q - (1.0 + r) * (1.0 + a1)) / den)

    def ok(mu):
        if free and not abs(mu) < 1.0:
            return False
        if impact:
            if not _existence_value(mu, a1, q, r) > 0.0:
                return False
            lam = np.linalg.eigvals(limit_monodromy(model, mu, delay))
            if not np.max(np.abs(lam)) < 1.0:
                return False
        return True

    return admissible_intervals(ok, [c for c in cands if math.isfinite(c)], MU_LIMIT)


def default_mu(intervals) -> tuple:
    """(mu, why) where no mu is given (grazing design --model/--rig, a rig's controller):
    the middle of the widest admissible interval of ``intervals`` ((lo, hi) pairs, e.g.
    :func:`admissible_mu`'s combined set); an unbounded one: 1 inside its finite end;
    none: mu = 0."""
    if not intervals:
        return 0.0, "mu = 0 (no admissible mu; no --mu given)"
    lo, hi = max(intervals, key=lambda iv: iv[1] - iv[0])
    mu = 0.5 * (lo + hi) if math.isfinite(lo) and math.isfinite(hi) else \
        (hi - 1.0 if math.isfinite(hi) else lo + 1.0)
    return mu, "the middle of the widest admissible interval (no --mu given)"


# -- the bad gain (§9) --------------------------------------------------------------------

def cancel_first_markov(model: NdofModel, mu: float, offset: float, *,
                        smooth_branch: bool = True, delay: float = 0.0) -> np.ndarray:
    """A gain that kills the first Markov parameter w^T N e_v but not the others (§9):
    k = k(mu) + offset d, d a unit vector off the family.

    With ``smooth_branch`` the step also keeps G(1) = 0, i.e. w^T (I - N)^-1 e_v = 0 (an affine
    condition on k, §9): the 1/1 branch stays smooth (Delta d ~ psi^2) and the largest
    multiplier grows like |Delta d|^-1/4; d is then the direction of that set orthogonal
    to the family along which w^T N^2 e_v grows fastest. Without it d breaks G(1) (the
    direction of its gradient within w^T N e_v = 0, orthogonal to the family): the branch
    is linear in psi and the largest multiplier grows like |Delta d|^-1/2. offset = 0
    is the design k(mu). Whether the 1/1 orbit exists for d < d* depends on the sign of
    offset (modal_branch.branch_coefficients).
    """
    k0 = gain_family(model, mu, delay)
    offset = float(offset)
    if not math.isfinite(offset):
        raise ParameterError(f"offset={offset!r} is invalid: valid range is a finite real number")
    c = _reach(model, delay)
    p, q, pinv = _sections(model)
    w, ev, b = _vectors(model, delay)
    m, g = q @ p, q @ b
    try:
        res = np.linalg.inv(np.eye(2 * model.n) - m)
    except np.linalg.LinAlgError:
        raise ParameterError("model is invalid for cancel_first_markov: Phi(T) has the "
                             "eigenvalue 1") from None
    markov1 = p @ ev                                    # w^T N e_v = w^T M e_v + c k^T P e_v
    te, tg = w @ res @ ev, w @ res @ g
    g1_row = p @ (tg * (res @ ev) - te * (res @ g))     # G(1) = 0 <=> g1_row . k = -te
    family = pinv.T @ w                                 # dk/dmu (times c)
    n_k = smooth_map(model, k0, delay)
    if smooth_branch:
        fixed, target = [markov1, g1_row, family], p @ n_k @ ev   # d(w^T N^2 e_v) = c d.P N e_v
    else:
        fixed, target = [markov1, family], g1_row
    basis = scipy.linalg.null_space(np.array(fixed))
    d = basis @ (basis.T @ target)
    size = float(np.linalg.norm(d))
    if not size > 1e-12 * float(np.linalg.norm(target)):
        raise ParameterError("model is invalid for cancel_first_markov: no direction off the "
                             "family changes the higher Markov parameters")
    return k0 + offset * d / size * (1.0 if c > 0 else -1.0)


# -- the controller's parameter file ------------------------------------------------------

def controller_parameters(model: NdofModel, design: FamilyDesign, model_file) -> dict:
    """The n-DOF controller's parameters: the gain vector, the model file it is for, and
    the section data the node checks it against (n, i_a, omega, pi2_offset)."""
    k = gain_vector(design.gains, model.n)
    return {
        "model_file": os.fspath(model_file),
        "gains": [float(x) for x in k],
        "n": int(model.n),
        "i_a": int(model.i_a),
        "omega": float(model.omega),
        "pi2_offset": float(model.pi2_offset),
        "mu": float(design.mu),
        **actuation_parameters(design.delay),
    }


def actuation_parameters(delay) -> dict:
    """The gain file's actuation entries: ``actuation_delay`` (when not 0), and for a
    pulse ``pulse_width``, ``actuator_bandwidth`` (1 / tau_a, 0 for the ideal pulse) and
    ``actuator_latency`` (§15): the nodes' own parameter names, so that controller_node
    reads them from the file and the launcher gives them to the simulator (the file once
    said ``actuator_time_constant``, which no node declares: the scene ran the ideal
    pulse with the actuator's gains, 203 impacts in 400 periods)."""
    if isinstance(delay, Actuation):
        tau = delay.time_constant
        return {"actuation_delay": delay.delay, "pulse_width": delay.width,
                "actuator_bandwidth": 1.0 / tau if tau > 0.0 else 0.0,
                "actuator_latency": delay.latency}
    return {"actuation_delay": float(delay)} if delay != 0.0 else {}


def design_actuation(delay: float = 0.0, pulse_width: float = 0.0,
                     actuator_bandwidth: float = 0.0, actuator_latency: float = 0.0):
    """The ``delay`` argument of this module for `grazing design --model M --delay D
    --pulse-width W [--actuator-bandwidth B] [--actuator-latency L]`: D itself without a
    pulse (the delayed kick, §14), else the :class:`Actuation` with tau_a = 1 / B (B = 0:
    the ideal pulse) (§15). ParameterError naming an option that is negative or not
    finite, or an actuator option given without a pulse width."""
    for name, value in (("pulse_width", pulse_width), ("actuator_bandwidth", actuator_bandwidth),
                        ("actuator_latency", actuator_latency)):
        if not (math.isfinite(value) and value >= 0.0):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite "
                                 f"{name} >= 0")
    if pulse_width == 0.0:
        if actuator_bandwidth or actuator_latency:
            raise ParameterError("pulse_width=0.0 is invalid with an actuator: valid range is "
                                 "pulse_width > 0 (the design is for the pulse's force "
                                 "profile)")
        return delay
    tau_a = 1.0 / actuator_bandwidth if actuator_bandwidth > 0.0 else 0.0
    return Actuation(delay, pulse_width, tau_a, actuator_latency)


def pulse_design(model: NdofModel, mu: float, delay: float = 0.0, width: float = 0.0,
                 time_constant: float = 0.0, latency: float = 0.0) -> FamilyDesign:
    """The design for a correction acting as a force pulse of ``width`` centred ``delay``
    after the sample, through a first-order actuator (``time_constant``, ``latency``)
    (§15; the `grazing design --model M --pulse-width W` route). Width 0 without an
    actuator: the delayed kick's design (§14), the same floats."""
    if width == 0.0 and time_constant == 0.0 and latency == 0.0:
        return evaluate_design(model, mu, delay)
    return evaluate_design(model, mu, Actuation(delay, width, time_constant, latency))


def write_gain_yaml(path, model: NdofModel, design: FamilyDesign, model_file,
                    node_name: str = "**") -> None:
    """Write the n-DOF controller's ROS 2 parameter file.

    Shape ``/**: ros__parameters: {model_file, gains: [k0 .. k_{2n-1}], n, i_a, omega,
    pi2_offset, mu}``, keyed ``/**`` as
    :func:`grazing_control.dynamics.design.gains.write_controller_yaml` so that it applies under a namespace or a renamed node. Refuses a design that is not
    on this model's family (w^T N(k) != mu w^T). Written to a temporary file and renamed.
    """
    from grazing_control.support.files import write_yaml_atomic

    k = gain_vector(design.gains, model.n)
    w, _ev, _b = _vectors(model)
    row = w @ smooth_map(model, k, design.delay)
    if not np.allclose(row, design.mu * w, atol=1e-9 * (1.0 + np.abs(row).max())):
        raise ParameterError(f"design is invalid for this model: its gains are not on the "
                             f"family w^T N = mu w^T (row {row.tolist()}, mu {design.mu!r})")
    doc = {f"/{node_name}": {"ros__parameters": controller_parameters(model, design, model_file)}}
    write_yaml_atomic(path, doc, ["n-DOF controller gains from the design "
                                  "(docs/theory_ndof.md, w^T N = mu w^T)"])

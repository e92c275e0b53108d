"""The Pi2 state from a sampled, noisy sensor stream: nearest sample, arc fit, model fit.

A rig does not sample its motion on Pi2; it streams position (and maybe velocity)
samples x~_j = x(t_j) + sigma e_j at a fixed rate. The controller needs the state
z_k = (x, v)(t_k) - y_p(tau2) on Pi2 (deviation coordinates,
:mod:`grazing_control.oscillator.flow`) at the section times t_k = k T, before the
correction of period k. docs/theory_estimation.md derives the three estimators:

``nearest``
    The last sample at or before t_k; where velocity is not measured, the backward
    difference of the last two samples (never across a known impact). Error
    covariance sigma^2 diag(1, 2 / h^2) (position only), sigma^2 I with velocity,
    plus the bias of the time offset (docs/theory_estimation.md, (E1)).
``arc``
    Linear least squares of the exact free flow over the samples since the last
    impact: between impacts y_j = e1^T Phi(t_j - t_k) z_k + sigma e_j (E2), so
    z^ = (H^T H)^-1 H^T y with covariance sigma^2 (H^T H)^-1.
``model``
    An iterated extended Kalman filter without process noise beyond a small floor,
    over whole periods, with the exact flow, the impact law and the known correction
    (E3-E5): the prior N(z^_{k-1}, P_{k-1}) and the samples of (t_{k-1}, t_k] give
    the posterior of z_{k-1} by Gauss-Newton on the exact trajectory (Jacobians: Phi,
    the saltation matrix S at each impact), which the exact map carries to t_k with
    P_k = M P+ M^T + Q. The information of every earlier period is kept through the
    map; a residual test (chi^2) falls back to the arc fit when the prior and the data
    disagree (an unexpected or missed impact).

The model filter is one algorithm over any model (docs/theory_estimation.md, (E11)), on
the exact motion of :mod:`.motion` (:func:`.motion.trajectory`: the 1-DOF closed form, or
for a model file of any n, an :class:`~grazing_control.oscillator.ndof.model.NdofModel`
in place of the parameters, the modal flow, the impact law, the saltation matrices); the state
has 2n coordinates and the sensor reads the position (and maybe the velocity) of any
one coordinate (``coordinate``); the 1-DOF closed form is the special case n = 1,
coordinate 0, bit for bit.

Every estimate comes with its covariance per the noise model (tests/test_estimation.py
checks it against seeded Monte Carlo). Impacts are detected from the stream where the
rig has no impact sensor by a split test on the arc fit (:func:`detect_impact`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from grazing_control.dynamics.estimation.motion import phi_rows, trajectory

__all__ = ["ESTIMATORS", "Estimate", "FilterState", "deviation_samples", "unkick",
           "nearest_estimate", "arc_fit", "detect_impact", "split_rss", "split_rss_by_fits",
           "model_update", "gauss_newton_fit", "estimate_covariance", "CHI2_SIGMAS"]
#: The estimators by name (``estimator`` parameter of the controller).
ESTIMATORS = ("nearest", "arc", "model")
#: The residual test of the model fit: reset when the sum of squared normalised
#: residuals of a period exceeds n + CHI2_SIGMAS sqrt(2 n) (chi^2_n's mean + 8 std).
CHI2_SIGMAS = 8.0


@dataclass(frozen=True)
class Estimate:
    """The Pi2 deviation estimate ``z`` = (dx, dv) and its covariance ``cov`` (2x2) at
    the section time; ``source`` names what produced it."""

    z: tuple
    cov: np.ndarray
    source: str


@dataclass(frozen=True)
class FilterState:
    """The model filter's state at a section time: the estimate ``z`` (before the
    correction) and its covariance ``cov``; ``periods`` counts the periods fitted
    since the last reset."""

    z: tuple
    cov: np.ndarray
    periods: int = 0


def _check_sigma(sigma: float) -> float:
    sigma = float(sigma)
    if not (math.isfinite(sigma) and sigma > 0.0):
        raise ParameterError(f"sensor_noise={sigma!r} is invalid: valid range is a finite "
                             "sensor_noise > 0 for the fitted estimators")
    return sigma


def deviation_samples(p: OscillatorParams, s, x, v=None, tau_start: float | None = None):
    """Measured deviations y_j = x~_j - x_p(tau_j), w_j = v~_j - v_p(tau_j) at times s
    after a section (phase tau2, or ``tau_start``): tau_j = tau + omega s_j (spec
    section 1). ``w`` is NaN where v is not measured."""
    tau = p.tau2 if tau_start is None else tau_start
    s = np.asarray(s, dtype=float)
    psi = tau + p.omega * s - p.lag
    y = np.asarray(x, dtype=float) - p.amplitude * np.cos(psi)
    if v is None:
        w = np.full_like(y, math.nan)
    else:
        w = np.asarray(v, dtype=float) + p.amplitude * p.omega * np.sin(psi)
    return y, w


def nearest_estimate(s, y, w, sigma: float) -> Estimate:
    """The last sample (times ``s`` <= 0 relative to the section, sorted) as the Pi2
    state; without velocity the backward difference (y_n - y_{n-1}) / h (E1).

    The covariance is that of the noise alone: sigma^2 I with velocity, else
    sigma^2 [[1, 1/h], [1/h, 2/h^2]] (the difference shares the last sample's noise).
    The time offset of the sample is not corrected: it is a bias, not in the covariance.
    """
    s, y, w = (np.asarray(a, dtype=float) for a in (s, y, w))
    if s.size == 0:
        raise ValueError("no sample before the section: the nearest estimator needs one")
    var = sigma * sigma
    if math.isfinite(w[-1]):
        return Estimate((float(y[-1]), float(w[-1])), var * np.eye(2), "nearest")
    if s.size < 2:
        return Estimate((float(y[-1]), 0.0), np.diag([var, math.inf]), "nearest")
    h = float(s[-1] - s[-2])
    dv = (y[-1] - y[-2]) / h
    cov = var * np.array([[1.0, 1.0 / h], [1.0 / h, 2.0 / (h * h)]])
    return Estimate((float(y[-1]), float(dv)), cov, "nearest")


def unkick(p: OscillatorParams, s, y, w, kicks=()):
    """Samples with the known corrections taken out: a sample before a kick dv at time
    s_c is moved to the free flow through the kick's end state,
    y_j + dv Phi12(s_j - s_c), w_j + dv Phi22(s_j - s_c) (E2'), so that an arc through
    corrections is one free flow."""
    s = np.asarray(s, dtype=float)
    y = np.array(y, dtype=float)
    w = np.array(w, dtype=float)
    for at, dv in kicks:
        if dv == 0.0:
            continue
        before = s <= at
        phi = phi_rows(p.zeta, s[before] - at)
        y[before] += dv * phi[:, 0, 1]
        w[before] += dv * phi[:, 1, 1]
    return y, w


def arc_fit(p: OscillatorParams, s, y, w, sigma: float, at: float = 0.0,
            kicks=()) -> Estimate:
    """Least squares of the free flow over one arc (no impact among the samples):
    the deviation z at time ``at`` from y_j = e1^T Phi(s_j - at) z + noise and, where
    measured, w_j = e2^T Phi(s_j - at) z + noise (E2), through the known corrections
    ``kicks`` ((time, dv) pairs, :func:`unkick`). Covariance sigma^2 (H^T H)^-1.
    Fewer than two measured components: ValueError."""
    sigma = _check_sigma(sigma)
    s = np.asarray(s, dtype=float)
    y, w = unkick(p, s, y, w, kicks)
    phi = phi_rows(p.zeta, s - at)
    rows = [phi[:, 0, :]]
    obs = [y]
    has_v = np.isfinite(w)
    if has_v.any():
        rows.append(phi[has_v, 1, :])
        obs.append(w[has_v])
    h = np.vstack(rows)
    b = np.concatenate(obs)
    if b.size < 2:
        raise ValueError(f"{b.size} measurement(s) since the last impact: the arc fit needs 2")
    info = h.T @ h
    z = np.linalg.solve(info, h.T @ b)
    return Estimate((float(z[0]), float(z[1])), sigma * sigma * np.linalg.inv(info), "arc")


def _residuals(phi_x, y):
    """Residuals of the LS fit y ~ phi_x z (2 unknowns)."""
    z, *_ = np.linalg.lstsq(phi_x, y, rcond=None)
    return y - phi_x @ z


def _explained(a, b):
    """b^T a^-1 b of stacked 2 x 2 normal matrices ``a`` (m, 2, 2) and right-hand sides
    ``b`` (m, 2), in closed form: what a two-unknown least-squares fit removes from the
    sum of squares. Where ``a`` has rank 1 (one row, or parallel rows) the
    pseudo-inverse a / tr(a)^2, as a minimum-norm least-squares fit does; 0 for no rows."""
    p, q, s = a[:, 0, 0], a[:, 0, 1], a[:, 1, 1]
    u, v = b[:, 0], b[:, 1]
    det = p * s - q * q
    trace = p + s
    with np.errstate(divide="ignore", invalid="ignore"):
        full = (s * u * u - 2.0 * q * u * v + p * v * v) / det
        rank1 = (p * u * u + 2.0 * q * u * v + s * v * v) / (trace * trace)
    return np.where(det > 1e-12 * (p * s), full, np.where(trace > 0.0, rank1, 0.0))


def split_rss(phi_x, r, splits):
    """Residual sums of squares of the two-arc fits r[:m] ~ phi_x[:m] z and r[m:] ~
    phi_x[m:] z' for each split m of ``splits`` (E6), all at once: each arc's normal
    equations are prefix (and suffix) sums of the rows' outer products, and a
    two-unknown fit removes b^T A^-1 b from the sum of squares (:func:`_explained`).
    ``r`` are the residuals of the one-arc fit over every sample: the same sums as for
    the samples themselves (the one-arc fit is in each arc's span), without the
    cancellation of subtracting two large sums."""
    outer = phi_x[:, :, None] * phi_x[:, None, :]
    rhs = phi_x * r[:, None]
    sq = r * r
    m = np.asarray(splits, dtype=np.int64)
    # rows [0, m): prefix sums; rows [m, n): suffix sums (no differences of large sums)
    a0, b0, c0 = (np.cumsum(x, axis=0)[m - 1] for x in (outer, rhs, sq))
    a1, b1, c1 = (np.cumsum(x[::-1], axis=0)[::-1][m] for x in (outer, rhs, sq))
    left = np.maximum(c0 - _explained(a0, b0), 0.0)
    right = np.maximum(c1 - _explained(a1, b1), 0.0)
    return left + right


def split_rss_by_fits(phi_x, y, splits):
    """:func:`split_rss`'s definition, one pair of least-squares fits (np.linalg.lstsq) per
    split m of ``splits``: the residual sums of y[:m] ~ phi_x[:m] z and y[m:] ~ phi_x[m:]
    z'. The reference it is checked and timed against (tests/test_estimation.py,
    benchmarks/bench_split_test.py); what the split test ran before (issue 30)."""
    def rss(a, b):
        r = _residuals(a, b)
        return float(r @ r)
    return np.array([rss(phi_x[:m], y[:m]) + rss(phi_x[m:], y[m:]) for m in splits])


def detect_impact(p: OscillatorParams, s, y, sigma: float, *, min_side: int = 3,
                  threshold: float = 25.0):
    """The time of an impact among position samples (times ``s`` after a section), or None.

    A split test on the free flow (E6): one arc through all samples against two arcs
    split between samples m-1 and m; the split with the smallest residual sum wins if
    it lowers the sum by more than ``threshold`` sigma^2 (a kink of the velocity that
    noise alone explains with probability ~ e^{-threshold/2}). Impacts can only be where
    the mass is at the wall, so only splits next to samples within 6 sigma + one sample
    step of motion of the wall are tried. The impact time is where the arc before the
    split reaches the wall (x = d), else the midpoint of the split.
    """
    s, y = np.asarray(s, dtype=float), np.asarray(y, dtype=float)
    n = s.size
    if n < 2 * min_side + 1:
        return None
    # the gap of each sample: g = x - d = y - Delta d - 2 a sin^2(psi / 2)
    psi = p.tau2 + p.omega * s - p.lag
    gap = y - p.delta_d - 2.0 * p.amplitude * np.sin(0.5 * psi) ** 2
    hstep = float(np.max(np.diff(s))) if n > 1 else 0.0
    near = gap > -(6.0 * sigma + 2.0 * hstep + hstep * hstep)
    # a split m is tried where one of the samples m - 2 .. m + 1 is near the wall
    padded = np.concatenate([[False, False], near, [False]])
    window = padded[:-3] | padded[1:-2] | padded[2:-1] | padded[3:]
    cands = np.arange(min_side, n - min_side + 1)
    cands = cands[window[cands]]
    if cands.size == 0:
        return None
    phi_x = phi_rows(p.zeta, s)[:, 0, :]
    r = _residuals(phi_x, y)
    whole = float(r @ r)
    rss = split_rss(phi_x, r, cands)
    i = int(np.argmin(rss))          # the first of equal sums, as a scan in m would keep
    if not rss[i] < whole or whole - rss[i] <= threshold * sigma * sigma:
        return None
    # refine: the pre-impact arc meets the wall between s[m-1] and s[m + 1)
    m = int(cands[i])
    fit = arc_fit(p, s[:m], y[:m], np.full(m, math.nan), sigma, at=float(s[m - 1]))
    lo, hi = float(s[m - 1]), float(s[m])
    tt = np.linspace(lo, hi, 65)
    ph = phi_rows(p.zeta, tt - lo)[:, 0, :] @ np.array(fit.z)
    g = ph - p.delta_d - 2.0 * p.amplitude * np.sin(0.5 * (p.tau2 + p.omega * tt - p.lag)) ** 2
    above = np.nonzero(g >= 0.0)[0]
    return float(tt[above[0]]) if above.size else 0.5 * (lo + hi)


def model_update(p: OscillatorParams, prior: FilterState, s, y, w, sigma: float,
                 correction: float, delay: float = 0.0, *, floor: float = 1e-2,
                 iterations: int = 8, width: float = 0.0, force_limit: float = math.inf,
                 actuator=None, force0: float = 0.0, coordinate: int = 0,
                 kernel: bool = False):
    """One period of the model filter: from the prior of z_{k-1} and the samples at times
    ``s`` in (0, T] after t_{k-1} to the estimate of z_k (E4, E5).

    ``p`` is the 1-DOF parameters or an n-DOF model (module docstring): the samples
    ``y`` (and ``w``, NaN where not measured) are the deviations of the position (and
    velocity) of coordinate ``coordinate`` (0 <= coordinate < n; 0 for 1-DOF), the
    correction a kick on v_{i_a}, the state and its covariance 2n-dimensional.

    Gauss-Newton on the exact trajectory (:func:`trajectory`) minimises
    (z - z^)^T P^-1 (z - z^) + |y - h(z)|^2 / sigma^2; the posterior covariance
    P+ = (P^-1 + H^T H / sigma^2)^-1 is carried by the exact map's monodromy M:
    P_k = M P+ M^T + (floor sigma)^2 I (the floor keeps the filter from trusting a
    direction that the map contracts to zero; it stands for what the model omits).

    The correction acts as a kick, or as a force pulse of ``width`` (clipped to
    ``force_limit``) where the plant's actuator pushes for a finite time, through the
    first-order ``actuator`` from the force ``force0`` at the section where it has a lag
    (:func:`trajectory`), compiled with ``kernel`` (:func:`trajectory`).

    Returns (FilterState at t_k, chi2 of the period's residuals, number of
    measurements); raises ValueError when the fit fails (no convergence, a sticking
    motion), for the caller to reset.
    """
    sigma = _check_sigma(sigma)
    s, y, w = (np.asarray(a, dtype=float) for a in (s, y, w))
    has_v = np.isfinite(w)
    z_prior = np.array(prior.z, dtype=float)
    dof = p.n if isinstance(p, NdofModel) else 1
    if isinstance(coordinate, bool) or not isinstance(coordinate, int) \
            or not 0 <= coordinate < dof:
        raise ParameterError(f"coordinate={coordinate!r} is invalid: valid range is "
                             f"0 <= coordinate < n = {dof}")
    ix, iv = coordinate, dof + coordinate          # the measured position and velocity
    info_prior = np.linalg.inv(prior.cov)
    z = z_prior.copy()
    inv_var = 1.0 / (sigma * sigma)

    def linearised(z):
        """(H, r, end, monodromy): the measurement rows and residuals of the samples at z."""
        pred, jac, end, mono, _imps = trajectory(p, z, s, correction, delay, width=width,
                                                 force_limit=force_limit, actuator=actuator,
                                                 force0=force0, kernel=kernel)
        h = np.vstack([jac[:, ix, :], jac[has_v, iv, :]])
        r = np.concatenate([y - pred[:, ix], w[has_v] - pred[has_v, iv]])
        return h, r, end, mono

    z, (h, r, end, mono) = gauss_newton_fit(linearised, z_prior, info_prior, inv_var, z,
                                            iterations)
    info = info_prior + inv_var * (h.T @ h)
    post = np.linalg.inv(info)
    cov = mono @ post @ mono.T + (floor * sigma) ** 2 * np.eye(len(z))
    chi2 = float(r @ r) * inv_var
    return FilterState(tuple(float(x) for x in end), 0.5 * (cov + cov.T),
                       prior.periods + 1), chi2, r.size


#: (E4)'s Gauss-Newton stops once a step is below this fraction of the posterior
#: standard deviation along it (its norm under P^-1 + H^T H / sigma^2): the estimate is
#: then that close to the minimiser, far inside its own uncertainty
#: (docs/theory_estimation.md, "When the fit stops").
STEP_TOLERANCE = 1e-3


def _gauss_newton_step(info_prior, inv_var, z_prior, z, h, r):
    """(step, its squared norm under the posterior information): the Gauss-Newton step of
    (E4) at z, (P^-1 + H^T H / sigma^2)^-1 (P^-1 (z^ - z) + H^T r / sigma^2)."""
    info = info_prior + inv_var * (h.T @ h)
    grad = info_prior @ (z_prior - z) + inv_var * (h.T @ r)
    step = np.linalg.solve(info, grad)
    return step, float(step @ info @ step)


def _small(step, norm2, z) -> bool:
    """Whether a step ends the fit: below STEP_TOLERANCE of the posterior standard
    deviation, or at the rounding of z."""
    return norm2 <= STEP_TOLERANCE * STEP_TOLERANCE \
        or bool(np.all(np.abs(step) <= 1e-12 + 1e-9 * np.abs(z)))


def gauss_newton_fit(linearised, z_prior, info_prior, inv_var, z, iterations: int = 8, *,
                     at_start=None):
    """The minimiser of (E4) from ``z`` and the linearisation at it: (z, (H, r, end,
    d end / dz, ...)), ``linearised(z)`` giving that tuple at z (H and r of the samples,
    the state at the section and its Jacobian, anything else the caller needs there).

    Gauss-Newton; a full step that raises the cost (z - z^)^T P^-1 (z - z^) + |r|^2 /
    sigma^2 is halved until it lowers it (:func:`_line_search`: the direction descends
    the cost. A large-residual fit on a trajectory strongly curved by a low-velocity
    impact, or a minimum at the kink where an impact appears, has full steps that circle
    for ever), and the next step starts from twice the last fraction taken
    (docs/theory_estimation.md, (E11) and "Where the fit stops"). It stops at a step
    below STEP_TOLERANCE of the posterior standard deviation (:func:`_small`), at a
    decrease of the cost below STEP_TOLERANCE^2 (or 1e-12 of it), or where no fraction
    down to 1e-6 lowers it (the minimum, to rounding or at a kink). A full step that ends
    the fit is not evaluated again: r and the end at z + step are those at z carried to
    first order (r - H step, end + (d end / dz) step; the step is below the tolerance,
    the error of the order of its square; the rest of the tuple is the one at z). At
    most 5 ``iterations`` steps; beyond, ValueError. model_update and the augmented
    filter (:mod:`.augmented`) fit with it; ``at_start``: ``linearised(z)`` where the
    caller has it already."""
    lin = linearised(z) if at_start is None else at_start
    cost = _cost(z, lin[1], z_prior, info_prior, inv_var)
    t = 1.0
    for _ in range(5 * iterations):
        h, r, end, d_end = lin[:4]
        step, norm2 = _gauss_newton_step(info_prior, inv_var, z_prior, z, h, r)
        if _small(step, norm2, z):
            return z + step, (h, r - h @ step, np.asarray(end) + d_end @ step) + lin[3:]
        t, zt, lin_t, cost_t = _line_search(linearised, z, step, t, cost, z_prior,
                                            info_prior, inv_var)
        if not cost_t < cost:
            return z, lin
        decrease = cost - cost_t
        z, lin, cost = zt, lin_t, cost_t
        if _small(t * step, t * t * norm2, z) \
                or decrease <= max(STEP_TOLERANCE * STEP_TOLERANCE, 1e-12 * cost):
            return z, lin
        t = min(1.0, 2.0 * t)
    raise ValueError("the model fit did not converge")


def _cost(z, r, z_prior, info_prior, inv_var) -> float:
    """(E4)'s cost (z - z^)^T P^-1 (z - z^) + |r|^2 / sigma^2."""
    d = z - z_prior
    return float(d @ info_prior @ d) + inv_var * float(r @ r)


def _line_search(linearised, z, step, t, cost, z_prior, info_prior, inv_var):
    """(t, z + t step, linearised(z + t step), its cost): the first of t, t/2, t/4, ...
    whose point lowers ``cost``, or the last tried once t < 1e-6."""
    while True:
        zt = z + t * step
        lin = linearised(zt)
        cost_t = _cost(zt, lin[1], z_prior, info_prior, inv_var)
        if cost_t < cost or t < 1e-6:
            return t, zt, lin, cost_t
        t *= 0.5


def estimate_covariance(p: OscillatorParams, gains, rate: int, *, estimator: str = "model",
                        velocity: bool = False, floor: float = 1e-2, target=None,
                        periods: int = 400, lead: float = 0.0, width: float = 0.0,
                        force_limit: float = math.inf, exact_plant: bool = False) -> np.ndarray:
    """The Pi2 estimate's error covariance per unit sigma^2 on the controlled 1/1 orbit
    (2x2), for a sensor at ``rate`` samples per period (position only unless
    ``velocity``): the design's measurement covariance R for
    :func:`grazing_control.dynamics.design.noise.noise_covariance` (E7).

    ``nearest``: diag(1, 1) with velocity, [[1, 1/h], [1/h, 2/h^2]] without (E1).
    ``arc``: (H^T H)^-1 over the orbit's samples after its impact (E2).
    ``model``: the fixed point of P = M (P^-1 + H^T H)^-1 M^T + floor^2 I along the
    orbit (E5), iterated from the arc fit's covariance for ``periods`` periods at most.
    ``target``: the orbit's Pi2 deviation (default ``orbit_11``).

    ``lead``: the estimate is made ``lead`` before the section's last sample (the stream
    estimator's ``lead``, a rig controller's answer_lead): the samples after the one
    that makes the section due are never used (model, arc). ``width``: the corrections
    act as force pulses of that width (:func:`trajectory`).

    ``exact_plant`` (model): the covariance of the errors the same filter, tuned with
    the floor, makes on a plant its model describes exactly (no process noise), in place
    of the one it reports: with the fixed point's gain K = (P^-1 + H^T H)^-1 H^T, the
    fixed point of S = M ((I - K H) S (I - K H)^T + K K^T) M^T (E7'). Where the floor is
    carried through an impact no sample sees (an answer lead past it, (E2'')) the
    reported covariance is several times this one.
    """
    if estimator not in ESTIMATORS:
        raise ParameterError(f"estimator={estimator!r} is invalid: valid values are "
                             f"{', '.join(ESTIMATORS)}")
    if int(rate) != rate or rate < 2:
        raise ParameterError(f"rate={rate!r} is invalid: valid range is an integer >= 2 "
                             "samples per period")
    T = p.period
    h = T / rate
    if estimator == "nearest":
        if velocity:
            return np.eye(2)
        return np.array([[1.0, 1.0 / h], [1.0 / h, 2.0 / (h * h)]])
    if target is None:
        from grazing_control.dynamics.orbits.orbits import orbit_11

        target = orbit_11(p, gains).pi2_deviation
    dv = gains.c1 * target[0] + gains.c2 * target[1]
    s = np.arange(1, int(rate)) * h        # the samples strictly between the sections
    if lead > 0.0:      # up to the first sample s with s + h + lead >= T (StreamEstimator)
        due = np.nonzero(s + h + lead >= T - 1e-3 * h)[0]
        s = s[:due[0] + 1] if due.size else s
    _pred, jac, _end, mono, imps = trajectory(p, target, s, dv, gains.delay, width=width,
                                              force_limit=force_limit)
    if estimator == "arc":
        after = s > (imps[-1][0] if imps else -math.inf)
        phi = phi_rows(p.zeta, s[after] - T)
        h_arc = phi[:, 0, :] if not velocity else np.vstack([phi[:, 0, :], phi[:, 1, :]])
        return np.linalg.inv(h_arc.T @ h_arc)
    hm = jac[:, 0, :] if not velocity else np.vstack([jac[:, 0, :], jac[:, 1, :]])
    info_data = hm.T @ hm
    cov = _fixed_point(lambda c: mono @ np.linalg.inv(np.linalg.inv(c) + info_data) @ mono.T
                       + floor * floor * np.eye(2), np.linalg.inv(info_data), periods)
    if not exact_plant:
        return cov
    gain = np.linalg.inv(np.linalg.inv(cov) + info_data) @ hm.T
    keep = np.eye(2) - gain @ hm
    return _fixed_point(lambda e: mono @ (keep @ e @ keep.T + gain @ gain.T) @ mono.T, cov,
                        periods)


def _fixed_point(step, start, periods: int):
    """S <- step(S), symmetrised, from ``start`` until a step changes it by no more than
    1e-10 of itself (at most ``periods`` steps): estimate_covariance's Riccati and
    error recursions (E7, E7')."""
    s = start
    for _ in range(periods):
        new = step(s)
        done = np.allclose(new, s, rtol=1e-10, atol=0.0)
        s = 0.5 * (new + new.T)
        if done:
            break
    return s

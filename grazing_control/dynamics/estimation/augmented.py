"""The model filter with a sensor bias and a drifting wall in its state (issue 29 section 1).

The model filter of :mod:`grazing_control.dynamics.estimation.section_state` trusts its model: a
constant position bias b of the sensor reads as a displaced orbit (the loop then holds
the *measured* orbit on X**, i.e. the true one b away and worse, issue 29: 3.4 b), and a
clearance Delta d that drifts away from the identified one moves the impacts the filter
predicts. Here both are states of the filter, estimated from the same stream
(docs/theory_estimation.md, E8-E10):

    theta_k = (z_k, b, Delta d_k),    b_{k+1} = b,    Delta d_{k+1} = Delta d_k + eta_k,

with eta_k ~ N(0, q_d) per period (a random walk of documented tuning ``wall_noise``).
The samples of period k are y_j = x_p-deviation of the exact trajectory from z_{k-1}
through the wall at Delta d_{k-1}, plus b:

    y_j = e1^T z(s_j; z_{k-1}, Delta d) + b + sigma e_j,

with the Jacobians d z(s_j) / d z_{k-1} (Phi and the saltation matrices, (E3)),
d y_j / d b = 1 and d z(s_j) / d Delta d (the wall's sensitivity through the impacts,
(E8): :func:`grazing_control.dynamics.estimation.motion.trajectory` with ``wall=True``).
One period is the iterated EKF of (E4, E5) over the augmented state
(:func:`augmented_update`), and its minimised cost is the period's normalised
innovation squared, chi^2 with one degree of freedom per measurement under the right
model (E9): what :mod:`grazing_control.dynamics.estimation.consistency` watches.

:class:`AugmentedStreamEstimator` is :class:`grazing_control.dynamics.estimation.stream.StreamEstimator`
with that filter: the same bookkeeping, arc fit and impact detection, run on the samples
less the current bias estimate and with the model's wall at the current Delta d
estimate, so that its estimates (``Estimate.z``, the Pi2 deviation) are what the
controller's Eq. 28 needs. With both augmentations off it is the plain model filter
(the same estimates to rounding: tests/test_augmented.py).

The same filter runs over a model file of any n
(:class:`~grazing_control.oscillator.ndof.model.NdofModel`, issue 32;
docs/theory_estimation.md, (E12)): theta = (z (2n), b, Delta d), the samples
those of the sensed coordinate ``coordinate`` (b on its position), the wall's
sensitivity through the n-DOF impacts; the estimator then runs through
:class:`StreamEstimator`'s n-DOF bookkeeping (its ``_ndof_fit``), restarting from the
wide prior about its state with b and Delta d kept (tests/test_augmented_ndof.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.estimation.section_state import (
    CHI2_SIGMAS, Estimate, FilterState, arc_fit, deviation_samples, gauss_newton_fit)
from grazing_control.dynamics.estimation.motion import trajectory
from grazing_control.dynamics.estimation.stream import _TOL, StreamEstimator

__all__ = ["AugmentedState", "augmented_update", "AugmentedStreamEstimator", "augmented_covariance",
           "WALL_NOISE", "BIAS_STD", "WALL_STD"]

#: The random walk of Delta d per period (variance q_d = WALL_NOISE^2): a ramp of
#: 5e-10 per period (20 % of 5e-6 over 2000 periods) is followed with a lag of 2.3e-8
#: (1.2e-7 with 2e-9); docs/theory_estimation.md E8, "Tuning".
WALL_NOISE = 1e-8
#: The prior std of the sensor bias when nothing is known (dimensionless position;
#: 10 sigma of the issue's sensor).
BIAS_STD = 1e-3
#: Sections whose innovation :attr:`AugmentedStreamEstimator.innovations` keeps.
RECENT_INNOVATIONS = 8
#: The prior std of Delta d about the identified value.
WALL_STD = 1e-6


@dataclass(frozen=True)
class AugmentedState:
    """The augmented filter's state at a section time: the Pi2 deviation ``z`` (before
    the correction; 2n values, (dx, dv) for 1-DOF), the bias ``bias``, the clearance
    ``delta_d`` and the covariance ``cov`` (2n + 2 square over (z, b, Delta d));
    ``periods`` counts the fitted periods."""

    z: tuple
    bias: float
    delta_d: float
    cov: np.ndarray
    periods: int = 0

    @property
    def theta(self) -> np.ndarray:
        return np.array([*self.z, self.bias, self.delta_d], dtype=float)


def with_wall(p, delta_d: float):
    """The model ``p`` (1-DOF parameters or a model file) with its clearance Delta d."""
    if isinstance(p, NdofModel):
        return p if delta_d == p.delta_d else p.with_clearance(delta_d)
    return p.with_(delta_d=delta_d)


def _whiten(nu, h, cov, sigma: float) -> np.ndarray:
    """S^{-1/2} nu for S = sigma^2 I + H P H^T, the symmetric square root, in O(n m^2):
    with U = H L / sigma (P = L L^T) = Q diag(s) V^T (thin SVD),
    S^{-1/2} = (I + Q ((1 + s^2)^{-1/2} - 1) Q^T) / sigma (E10). |result|^2 = nu^T S^-1 nu."""
    u = h @ np.linalg.cholesky(cov) / sigma
    q, sv, _vt = np.linalg.svd(u, full_matrices=False)
    return (nu + q @ ((1.0 / np.sqrt(1.0 + sv * sv) - 1.0) * (q.T @ nu))) / sigma


def augmented_update(p: OscillatorParams, prior: AugmentedState, s, y, w, sigma: float,
                     correction: float, delay: float = 0.0, *, bias: bool = True,
                     wall: bool = True, wall_noise: float = WALL_NOISE,
                     floor: float = 1e-2, iterations: int = 8, innovation: bool = False,
                     width: float = 0.0, force_limit: float = math.inf, actuator=None,
                     force0: float = 0.0, coordinate: int = 0, kernel: bool = False):
    """One period of the augmented filter, from the prior at t_{k-1} and the samples at
    times ``s`` in (0, T] after it to the state at t_k (module docstring; (E8, E9)).

    Gauss-Newton on the exact trajectory through the wall at the estimated Delta d
    minimises J(theta) = |theta - theta^|^2_{P^-1} + |y - h(theta)|^2 / sigma^2 over
    the active states (z, and b where ``bias``, Delta d where ``wall``; an
    inactive one keeps its prior value and variance). The posterior is carried by the
    exact map F = [[M, 0, d end / d Delta d], [0, 1, 0], [0, 0, 1]]:
    P_k = F P+ F^T + diag((floor sigma)^2 I, 0, wall_noise^2).

    ``p`` a model file (n > 1): z has 2n entries, the samples are coordinate
    ``coordinate``'s (b on its position), the wall's sensitivity (E12); ``kernel``: the
    compiled motion where the wall is not estimated (:func:`trajectory`).

    Returns (AugmentedState at t_k, J at the minimum: the period's normalised
    innovation squared, the number of measurements); raises ValueError when the fit
    fails (no convergence, a sticking motion). ``width``, ``force_limit``,
    ``actuator``, ``force0``: how the correction acts (:func:`trajectory`).
    """
    s, y, w = (np.asarray(a, dtype=float) for a in (s, y, w))
    has_v = np.isfinite(w)
    nz = len(prior.z)                   # 2n
    ib, iw = nz, nz + 1                 # b and Delta d in theta
    ix, iv = coordinate, nz // 2 + coordinate      # the sensed position and velocity
    act = list(range(nz)) + ([ib] if bias else []) + ([iw] if wall else [])
    theta_prior = prior.theta
    info_prior = np.linalg.inv(prior.cov[np.ix_(act, act)])
    theta = theta_prior.copy()
    inv_var = 1.0 / (sigma * sigma)

    def linearise(z):
        """(H, r, end, d end / dz, M, d end / d Delta d) at the active states z."""
        t = theta_prior.copy()
        t[act] = z
        pm = with_wall(p, float(t[iw]))
        pred, jac, end, mono, _imps, *g = trajectory(
            pm, t[:nz], s, correction, delay, wall=wall, width=width,
            force_limit=force_limit, actuator=actuator, force0=force0, kernel=kernel)
        gw, gend = g if wall else (np.zeros((s.size, nz)), np.zeros(nz))
        hx = np.column_stack([jac[:, ix, :], np.ones(s.size), gw[:, ix]])
        hv = np.column_stack([jac[has_v, iv, :], np.zeros(has_v.sum()), gw[has_v, iv]])
        h = np.vstack([hx, hv])[:, act]
        r = np.concatenate([y - pred[:, ix] - t[ib], w[has_v] - pred[has_v, iv]])
        d_end = np.column_stack([mono, np.zeros(nz), gend])[:, act]
        return h, r, end, d_end, mono, gend

    first = linearise(theta[act])
    whitened = _whiten(first[1], first[0], prior.cov[np.ix_(act, act)], sigma)
    theta[act], (h, r, end, _d_end, mono, gend) = gauss_newton_fit(
        linearise, theta_prior[act], info_prior, inv_var, theta[act], iterations,
        at_start=first)
    info = info_prior + inv_var * (h.T @ h)
    post = prior.cov.copy()
    post[np.ix_(act, act)] = np.linalg.inv(info)
    # an inactive state is not updated: its cross terms with the active ones stay 0
    for i in (ib, iw):
        if i not in act:
            post[i, :] = post[:, i] = 0.0
            post[i, i] = prior.cov[i, i]
    f = np.eye(nz + 2)
    f[:nz, :nz] = mono
    f[:nz, iw] = gend if wall else 0.0
    q = np.diag([(floor * sigma) ** 2] * nz + [0.0, wall_noise ** 2 if wall else 0.0])
    cov = f @ post @ f.T + q
    d = (theta - theta_prior)[act]
    cost = float(d @ info_prior @ d) + float(r @ r) * inv_var
    state = AugmentedState(tuple(float(x) for x in end), float(theta[ib]), float(theta[iw]),
                           0.5 * (cov + cov.T), prior.periods + 1)
    if innovation:
        return state, cost, r.size, whitened
    return state, cost, r.size


class AugmentedStreamEstimator(StreamEstimator):
    """:class:`grazing_control.dynamics.estimation.stream.StreamEstimator` (``model``) with the sensor
    bias and the wall's drift in the filter's state (module docstring).

    Parameters (beyond those of StreamEstimator, whose ``estimator`` is ``model``)
    ----------
    bias, wall : bool
        Estimate the bias b, and Delta d as a random walk.
    bias0, bias_std : float
        The prior of b (default 0 and :data:`BIAS_STD`).
    wall_std : float
        The prior std of Delta d about ``p.delta_d`` (default :data:`WALL_STD`).
    wall_noise : float
        The random walk's std per period, sqrt(q_d) (default :data:`WALL_NOISE`).
    coordinate : int
        With a model file (n > 1): the sensed coordinate (StreamEstimator's); the
        estimates and their covariance then have 2n + 2 entries (E12).

    After each section: :attr:`state` (the :class:`AugmentedState`), and
    :attr:`innovation` = (k, J, n, eps): the period's normalised innovation squared, its
    degrees of freedom and the whitened innovation (E9, E10), for
    :class:`grazing_control.dynamics.estimation.consistency.ConsistencyMonitor`
    (``monitor.add(*innovation)``); (k, None, 0, None) for a fit that failed (no
    convergence, or reset by the chi^2 test); None for a section the model filter did
    not fit, and for the first fit after a (re)start that passed (its prior is the arc
    fit's: a bad one there is the arc fit's failure, not the model's). The same tuples
    of the last RECENT_INNOVATIONS sections are in :attr:`innovations` by k (a sample
    after a lost one makes two sections due at once: ``monitor.add(*innovations.pop(k))``
    for each).

    Per section, a controller does what :func:`grazing_control.dynamics.estimation.stream.simulate_stream`
    does with it: ``add_sample`` for each sample (the due sections come back), then
    ``monitor.add(*est.innovation)`` when it is not None, Eq. 28 on ``Estimate.z``
    times ``switch(k, estimate)`` (:mod:`grazing_control.dynamics.design.capture`), and
    ``set_correction``.
    """

    def __init__(self, p: OscillatorParams, sigma: float = 1e-4, impact_source: str = "stream",
                 sample_period: float = 0.0, floor: float = 1e-2, after_section: bool = False,
                 lead: float = 0.0, *, bias: bool = True, wall: bool = True, bias0: float = 0.0,
                 bias_std: float = BIAS_STD, wall_std: float = WALL_STD,
                 wall_noise: float = WALL_NOISE, pulse_width: float = 0.0,
                 force_limit: float = math.inf, actuator=None, coordinate: int = 0):
        for name, value, ok, valid in (
                ("bias0", bias0, True, "finite"),
                ("bias_std", bias_std, bias_std > 0.0, "finite and > 0"),
                ("wall_std", wall_std, wall_std > 0.0, "finite and > 0"),
                ("wall_noise", wall_noise, wall_noise >= 0.0, "finite and >= 0")):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and ok):
                raise ParameterError(f"{name}={value!r} is invalid: valid range is {valid}")
        self.use_bias, self.use_wall = bool(bias), bool(wall)
        self.wall_noise = float(wall_noise)
        self.identified = p
        # the parameters' estimate and covariance, kept across resets of the filter
        self.params = (float(bias0), float(p.delta_d))
        self.params_cov = np.diag([bias_std ** 2 if bias else 0.0,
                                   wall_std ** 2 if wall else 0.0])
        super().__init__(p, "model", sigma, impact_source, sample_period, floor, after_section,
                         lead, pulse_width=pulse_width, force_limit=force_limit,
                         actuator=actuator, coordinate=coordinate)

    def reset(self) -> None:
        """Forget the stream (the filter restarts from the arc fit); the bias and Delta d
        estimates are kept: they belong to the rig, not to the run."""
        super().reset()
        self.state = None
        self.innovation = None
        self.innovations = {}       # k -> innovation of the last few sections

    @property
    def bias(self) -> float:
        return self.params[0]

    @property
    def delta_d(self) -> float:
        return self.params[1]

    def _window(self, k: int, since: float):
        """The base class's samples, less the current bias estimate (so the arc fit,
        the impact detection and the nearest sample see bias-corrected positions)."""
        s, x, v = super()._window(k, since)
        return s, x - self.params[0], v

    def estimate(self, k: int) -> Estimate:
        self.innovation = None
        est = super().estimate(k)
        if est.source == "arc":
            self.state = self._from_arc(k, est)
        if self.innovation is not None:     # kept by section: one sample may make two due
            self.innovations[k] = self.innovation
            while len(self.innovations) > RECENT_INNOVATIONS:
                self.innovations.pop(next(iter(self.innovations)))
        return est

    def _from_arc(self, k: int, est: Estimate) -> AugmentedState:
        """The augmented prior after a (re)start from the arc fit: the arc's z was fitted
        to samples less b^, so its error is -c (b^ - b) + noise with c the arc fit of a
        unit offset (docs/theory_estimation.md E8): P_zz = P_arc + c P_bb c^T,
        P_zb = -c P_bb."""
        cov = np.zeros((4, 4))
        cov[2:, 2:] = self.params_cov
        cov[:2, :2] = est.cov
        if self.use_bias:
            tk = k * self.p.period
            s, _x, _v = self._window(k, tk - 2.0 * self.p.period)
            last = max((i for i in self.impacts if i <= tk), default=-math.inf) - tk
            keep = s > last
            ones = np.ones(keep.sum())
            c = np.array(arc_fit(self.p, s[keep], ones, np.full(ones.size, math.nan),
                                 self.sigma).z)
            pbb = self.params_cov[0, 0]
            cov[:2, :2] += pbb * np.outer(c, c)
            cov[:2, 2] = cov[2, :2] = -c * pbb
            cov[:2, 3] = cov[3, :2] = -c * self.params_cov[0, 1]
        return AugmentedState(est.z, *self.params, cov, 0)

    def _model(self, k: int):
        """One period of the augmented filter from section k - 1 (None: start or reset)."""
        p, T = self.p, self.p.period
        if self.filter is None or self.filter_k != k - 1 or self.state is None:
            return None
        s, x, v = self._window(k, (k - 1) * T + _TOL * T)
        if s.size == 0:
            return None
        s = s + T
        # the raw positions: the bias is a state of the fit here
        y, w = deviation_samples(p, s, x + self.params[0], v, tau_start=p.tau2)
        at, dv = self.kicks.get(k - 1, ((k - 1) * T, 0.0))
        try:
            new, cost, n, white = augmented_update(
                p, self.state, s, y, w, self.sigma, dv, at - (k - 1) * T, bias=self.use_bias,
                wall=self.use_wall, wall_noise=self.wall_noise, floor=self.floor,
                innovation=True, **self.correction_shape(k - 1))
        except (ValueError, np.linalg.LinAlgError, ArithmeticError):
            self.filter = self.state = None
            self.resets += 1
            self.innovation = (k, None, 0, None)
            return None
        failed = cost > n + CHI2_SIGMAS * math.sqrt(2.0 * n)
        # the first fit after a (re)start tests the arc fit's prior, not the model: it is
        # reported only as a failure (docs/theory_estimation.md E10)
        if self.state.periods >= 1:
            self.innovation = (k, cost, n, white)
        elif failed:
            self.innovation = (k, None, 0, None)
        if failed:
            self.filter = self.state = None
            self.resets += 1
            return None
        self.state = new
        self.params = (new.bias, new.delta_d)
        self.params_cov = new.cov[2:, 2:].copy()
        self.p = self.identified.with_(delta_d=new.delta_d)
        self.filter, self.filter_k = FilterState(new.z, new.cov[:2, :2], new.periods), k
        return Estimate(new.z, new.cov[:2, :2], "model")

    def _ndof_fit(self, k: int, prior: FilterState, s, y, w, dv: float, delay: float):
        """One period of the augmented filter over a model file (E12), for
        :meth:`StreamEstimator._ndof_model`: from :attr:`state` where ``prior`` is the
        filter held from section k - 1, else (a restart) from ``prior`` (the wide prior
        about the filter's state) with the kept b and Delta d and their covariance. The
        innovation as :meth:`_model`'s (the first of the section's tries is kept: a held
        fit that failed is reported though the restart after it passes)."""
        nz = len(prior.z)
        state = self.state if prior is self.filter else None
        if state is None:
            cov = np.zeros((nz + 2, nz + 2))
            cov[:nz, :nz] = prior.cov
            cov[nz:, nz:] = self.params_cov
            state = AugmentedState(tuple(prior.z), *self.params, cov, 0)
        self.state = None
        try:     # the raw positions: the bias is a state of the fit (_window took it off)
            new, cost, n, white = augmented_update(
                self.p, state, s, y + self.params[0], w, self.sigma, dv, delay,
                bias=self.use_bias, wall=self.use_wall, wall_noise=self.wall_noise,
                floor=self.floor, innovation=True, coordinate=self.coordinate,
                kernel=self.kernel, **self.correction_shape(k - 1))
        except (ValueError, np.linalg.LinAlgError, ArithmeticError):
            if self.innovation is None:
                self.innovation = (k, None, 0, None)
            raise
        failed = cost > n + CHI2_SIGMAS * math.sqrt(2.0 * n)
        if self.innovation is None and (state.periods >= 1 or failed):
            self.innovation = (k, cost, n, white) if state.periods >= 1 else (k, None, 0, None)
        if not failed:
            self.state = new
            self.params = (new.bias, new.delta_d)
            self.params_cov = new.cov[nz:, nz:].copy()
            self.p = with_wall(self.identified, new.delta_d)
        return FilterState(new.z, new.cov[:nz, :nz], new.periods), cost, n


def augmented_covariance(p: OscillatorParams, gains, rate: int, *, bias: bool = True,
                         wall: bool = True, wall_noise: float = WALL_NOISE,
                         sigma: float = 1e-4, floor: float = 1e-2, target=None,
                         periods: int = 5000, coordinate: int = 0, delay: float = 0.0,
                         width: float = 0.0, actuator=None, force0: float = 0.0,
                         section_sample: bool = False) -> np.ndarray:
    """The augmented filter's stationary covariance on the controlled 1/1 orbit (4x4 over
    (dx, dv, b, Delta d), absolute units for the noise ``sigma``), position only at
    ``rate`` samples per period: the fixed point of
    P = F (P^-1 + H^T H / sigma^2)^-1 F^T + Q along the orbit (E5 with the augmented H
    and F of :func:`augmented_update`), iterated from the bias and wall priors.

    Its (dx, dv) block over sigma^2 is the design's measurement covariance R with the
    augmentation (:func:`grazing_control.dynamics.design.noise.noise_covariance`): the bias
    has no process noise, so its variance goes to 0 and leaves R as without it; the
    wall's random walk keeps a share (docs/theory_estimation.md, "Measured (issue 29)"). Unlike the
    plain filter's (E7) this needs sigma: the walk's std is absolute.

    ``p`` a model file (any n; issue 32, docs/theory_estimation.md E13): the same fixed
    point over theta = (z (2n), b, Delta d), (2n + 2) x (2n + 2), ``gains`` the gain
    vector k, the samples coordinate ``coordinate``'s position, the correction k^T z*
    ``delay`` after the section (a pulse of ``width``, through ``actuator`` from the force
    ``force0``: :func:`trajectory`), ``target`` z* (default: the kick's controlled orbit,
    :func:`grazing_control.dynamics.design.noise.controlled_orbit`); ``section_sample``
    fits the sample at t_k too (the 1-DOF form never does: a lockstep stream estimator
    does not wait for it). With bias and wall off its z block is
    :func:`grazing_control.dynamics.design.noise.filter_covariance` times sigma^2; for the
    n = 1 model file it is the 1-DOF result (tests/test_augmented_covariance.py). The
    other arguments are the 1-DOF ones' (``coordinate`` onwards are the model file's only).
    """
    if isinstance(p, NdofModel):
        return _model_file_covariance(
            p, gains, rate, bias=bias, wall=wall, wall_noise=wall_noise, sigma=sigma,
            floor=floor, target=target, periods=periods, coordinate=coordinate, delay=delay,
            width=width, actuator=actuator, force0=force0, section_sample=section_sample)
    from grazing_control.dynamics.orbits.orbits import orbit_11

    if target is None:
        target = orbit_11(p, gains).pi2_deviation
    dv = gains.c1 * target[0] + gains.c2 * target[1]
    h = p.period / rate
    s = np.arange(1, int(rate)) * h
    _pred, jac, _end, mono, _imps, gw, gend = trajectory(p, target, s, dv, gains.delay,
                                                         wall=True)
    act = [0, 1] + ([2] if bias else []) + ([3] if wall else [])
    hm = np.column_stack([jac[:, 0, :], np.ones(s.size), gw[:, 0]])[:, act]
    info_data = hm.T @ hm / sigma ** 2
    f = np.eye(4)
    f[:2, :2] = mono
    f[:2, 3] = gend
    f = f[np.ix_(act, act)]
    q = np.diag([(floor * sigma) ** 2, (floor * sigma) ** 2, 0.0, wall_noise ** 2])
    q = q[np.ix_(act, act)]
    cov = np.diag([sigma ** 2, sigma ** 2, BIAS_STD ** 2, WALL_STD ** 2])[np.ix_(act, act)]
    cov = _riccati_fixed_point(f, q, cov, info_data, periods)
    out = np.zeros((4, 4))
    out[np.ix_(act, act)] = cov
    return out


def _model_file_covariance(model: NdofModel, gains, rate: int, *, bias, wall, wall_noise, sigma,
                           floor, target, periods, coordinate, delay, width, actuator, force0,
                           section_sample) -> np.ndarray:
    """:func:`augmented_covariance` over a model file (E13): the 1-DOF form's fixed point
    with z in R^{2n}, H = [e_c^T dz(s_j)/dz0, 1, e_c^T g(s_j)] and
    F = [[M, 0, g(T)], [0, 1, 0], [0, 0, 1]] at the controlled orbit (E12)."""
    k = np.asarray(gains, dtype=float)
    nz = 2 * model.n
    if k.shape != (nz,) or not np.all(np.isfinite(k)):
        raise ParameterError(f"gains are invalid: expected {nz} finite gains for a model file "
                             f"of n = {model.n}")
    if not (isinstance(coordinate, (int, np.integer)) and 0 <= coordinate < model.n):
        raise ParameterError(f"coordinate={coordinate!r} is invalid: valid range is "
                             f"0 .. {model.n - 1}")
    if target is None:
        if width != 0.0 or actuator is not None:
            raise ParameterError("target is missing: with a pulse or an actuator give the "
                                 "controlled orbit's Pi2 deviation")
        from grazing_control.dynamics.design.noise import controlled_orbit

        target = controlled_orbit(model, k, delay)
    z = np.asarray(target, dtype=float)[:nz]
    last = int(rate) + (1 if section_sample else 0)
    s = model.period * np.arange(1, last) / rate
    _pred, jac, _end, mono, _imps, gw, gend = trajectory(
        model, z, s, float(k @ z), delay, wall=True, width=width, actuator=actuator,
        force0=force0)
    ib, iw = nz, nz + 1
    act = list(range(nz)) + ([ib] if bias else []) + ([iw] if wall else [])
    hm = np.column_stack([jac[:, coordinate, :], np.ones(s.size), gw[:, coordinate]])[:, act]
    info_data = hm.T @ hm / sigma ** 2
    f = np.eye(nz + 2)
    f[:nz, :nz] = mono
    f[:nz, iw] = gend
    f = f[np.ix_(act, act)]
    q = np.diag([(floor * sigma) ** 2] * nz + [0.0, wall_noise ** 2])[np.ix_(act, act)]
    cov = np.diag([sigma ** 2] * nz + [BIAS_STD ** 2, WALL_STD ** 2])[np.ix_(act, act)]
    cov = _riccati_fixed_point(f, q, cov, info_data, periods)
    out = np.zeros((nz + 2, nz + 2))
    out[np.ix_(act, act)] = cov
    return out


def _riccati_fixed_point(f, q, cov, info_data, periods: int) -> np.ndarray:
    """P <- F (P^-1 + H^T H / sigma^2)^-1 F^T + Q (E5; ``info_data`` = H^T H / sigma^2
    summed over the period) from ``cov`` until it moves less than 1e-10 relative, at most
    ``periods`` times; kept symmetric."""
    for _ in range(periods):
        new = f @ np.linalg.inv(np.linalg.inv(cov) + info_data) @ f.T + q
        done = np.allclose(new, cov, rtol=1e-10, atol=0.0)
        cov = 0.5 * (new + new.T)
        if done:
            break
    return cov

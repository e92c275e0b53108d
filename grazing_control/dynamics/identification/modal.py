"""The n-DOF model as the wall coordinate's sensor sees it: modal parameters
(docs/theory_identification.md, section 11).

A sensor of the wall coordinate x_w alone sees the n-DOF oscillator of
docs/ndof_model.md through three linear responses, each a sum over its n modes
lambda_k = -zeta_k Omega_k +- i Omega_k sqrt(1 - zeta_k^2) (sigma_k = zeta_k Omega_k,
w_k = Omega_k sqrt(1 - zeta_k^2)):

* free flight from the arc's start: x_w - x_p,w = sum_k e^{-sigma_k h}(alpha_k cos w_k h +
  beta_k sin w_k h), (alpha_k, beta_k) the arc's modal state (2n numbers);
* a velocity kick Delta v on the wall coordinate (the impact, Delta v = -(1 + r) v-) adds
  Delta v (c_k, s_k) to the modal state: x_w's response to a unit kick is
  sum_k e^{-sigma_k t}(c_k cos w_k t + s_k sin w_k t) = e_w^T e^{A t} e_{n+w}, so
  sum_k c_k = 0 (x_w continuous) and sum_k (w_k s_k - sigma_k c_k) = 1 (v_w jumps by
  Delta v): 2n - 2 free numbers;
* a kick on the actuated coordinate i_a != i_w: its own (c^a_k, s^a_k) with
  sum c^a = 0 and sum (w s^a - sigma c^a) = 0 (x_w and v_w continuous);
* the forcing's periodic response of x_w: x_p,w = P_c cos tau + P_s sin tau (tau the
  reference's phase); d* = sqrt(P_c^2 + P_s^2), Delta d = d - d*.

These are what the data determine (the eigenvalues and the residues of the
transfer functions from the two kicks and the forcing to x_w); M, C and K are not (a
change of the hidden coordinates leaves every response of x_w the same). For n = 1 the
vector is (Omega, zeta, P_c, P_s, d, r), the 1-DOF fit's (zeta, Omega, A, theta, d, r)
in other coordinates (c = 0, s = 1/w).

Every function here is analytic in the parameters (no abs, no branch on them): the fit's
complex-step Jacobian is exact to rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.params import ParameterError

__all__ = ["ModalLayout", "ModalModel", "modal_of", "kick_coefficients",
           "modal_flow",
           "propagate", "particular"]


@dataclass(frozen=True)
class ModalLayout:
    """Where each parameter sits in the fit's global vector g.

    g = (Omega_1..n, zeta_1..n, (c_k, s_k) k < n, P_c, P_s, d, r[, (c^a_k, s^a_k) k < n]),
    the actuator's block only when ``actuator`` (a kick on i_a != i_w with recorded
    size: its response is fitted)."""

    n: int
    actuator: bool = False

    @property
    def size(self) -> int:
        return 4 * self.n + 2 + (2 * self.n - 2 if self.actuator else 0)

    @property
    def names(self) -> tuple:
        n = self.n
        out = [f"natural_frequency_{k}" for k in range(n)]
        out += [f"damping_ratio_{k}" for k in range(n)]
        for k in range(n - 1):
            out += [f"impact_response_c_{k}", f"impact_response_s_{k}"]
        out += ["response_cos", "response_sin", "d", "r"]
        if self.actuator:
            for k in range(n - 1):
                out += [f"kick_response_c_{k}", f"kick_response_s_{k}"]
        return tuple(out)

    def split(self, g):
        """(Omega, zeta, free impact coefficients (n-1, 2), P_c, P_s, d, r, free kick
        coefficients (n-1, 2) or None) of g (real or complex), or of each row of a
        batch (B, size): each with the batch's leading axis."""
        n = self.n
        lead = g.shape[:-1]
        Om, ze = g[..., :n], g[..., n:2 * n]
        o = 2 * n
        ci = g[..., o:o + 2 * (n - 1)].reshape(lead + (n - 1, 2))
        o += 2 * (n - 1)
        Pc, Ps, d, r = g[..., o], g[..., o + 1], g[..., o + 2], g[..., o + 3]
        ka = g[..., o + 4:o + 4 + 2 * (n - 1)].reshape(lead + (n - 1, 2)) \
            if self.actuator else None
        return Om, ze, ci, Pc, Ps, d, r, ka

    @property
    def index_d(self) -> int:
        return 4 * self.n


def rates(Om, zeta):
    """(sigma, w): decay rates zeta Omega and damped frequencies Omega sqrt(1 - zeta^2)."""
    return zeta * Om, Om * np.sqrt(1.0 - zeta * zeta)


def kick_coefficients(Om, zeta, free, slope):
    """(c, s) of all n modes from the first n - 1 (``free``, (n-1, 2)): the last mode's
    from sum c = 0 and sum (w s - sigma c) = ``slope`` (1 for the wall's own kick, 0 for
    another coordinate's; module docstring). A batch: Om, zeta (B, n), free (B, n-1, 2)."""
    sig, w = rates(Om, zeta)
    cf, sf = free[..., 0], free[..., 1]
    c_last = -np.sum(cf, axis=-1)
    s_last = (slope - np.sum(w[..., :-1] * sf - sig[..., :-1] * cf, axis=-1)
              + sig[..., -1] * c_last) / w[..., -1]
    return (np.concatenate([cf, c_last[..., None]], axis=-1),
            np.concatenate([sf, s_last[..., None]], axis=-1))


def modal_flow(sig, w, alpha, beta, h):
    """Deviation of x_w and v_w after time h from modal state (alpha, beta); arrays
    broadcast as (m, n) with h (m, 1)."""
    E = np.exp(-sig * h)
    C, S = np.cos(w * h), np.sin(w * h)
    y = np.sum(E * (alpha * C + beta * S), axis=-1)
    dy = np.sum(E * ((w * beta - sig * alpha) * C - (sig * beta + w * alpha) * S), axis=-1)
    return y, dy


def propagate(sig, w, alpha, beta, h):
    """The modal state after time h: e^{-sigma h} R(w h) (alpha, beta)."""
    E = np.exp(-sig * h)
    C, S = np.cos(w * h), np.sin(w * h)
    return E * (alpha * C + beta * S), E * (beta * C - alpha * S)


def particular(Pc, Ps, omega, psi):
    """x_p,w and v_p,w at reference phase psi."""
    c, s = np.cos(psi), np.sin(psi)
    return Pc * c + Ps * s, omega * (Ps * c - Pc * s)


@dataclass(frozen=True)
class ModalModel:
    """The identified quantities (module docstring), real arrays of n modes sorted by
    natural frequency; ``omega``, ``tau0`` the reference's tau = omega t + tau0.
    ``kick_c``, ``kick_s``: the actuated coordinate's response (None: not identified)."""

    natural_frequency: np.ndarray
    damping_ratio: np.ndarray
    impact_c: np.ndarray
    impact_s: np.ndarray
    response_cos: float
    response_sin: float
    d: float
    r: float
    omega: float
    kick_c: np.ndarray | None = None
    kick_s: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.natural_frequency.size)

    @property
    def d_star(self) -> float:
        """Grazing clearance of x_w: the amplitude of its periodic response."""
        return math.hypot(self.response_cos, self.response_sin)

    @property
    def delta_d(self) -> float:
        return self.d - self.d_star

    def vector(self, layout: ModalLayout) -> np.ndarray:
        """The global vector g of ``layout``."""
        n = self.n
        g = [self.natural_frequency, self.damping_ratio,
             np.column_stack([self.impact_c, self.impact_s])[:n - 1].ravel(),
             [self.response_cos, self.response_sin, self.d, self.r]]
        if layout.actuator:
            g.append(np.column_stack([self.kick_c, self.kick_s])[:n - 1].ravel())
        return np.concatenate([np.asarray(a, float).ravel() for a in g])

    @classmethod
    def from_vector(cls, g, layout: ModalLayout, omega: float) -> "ModalModel":
        Om, ze, ci, Pc, Ps, d, r, ka = layout.split(np.asarray(g, float))
        c, s = kick_coefficients(Om, ze, ci, 1.0)
        kc = ks = None
        if ka is not None:
            kc, ks = kick_coefficients(Om, ze, ka, 0.0)
        return cls(Om.copy(), ze.copy(), c, s, float(Pc), float(Ps), float(d), float(r),
                   float(omega), kc, ks)


def _response(flow, j: int):
    """(c, s) per kept mode of x_w's response to a unit kick on velocity j."""
    m = flow.model
    q = flow.modes[m.i_w, :] * flow.inverse[:, m.n + j]
    return q.real, -q.imag


def modal_of(model) -> ModalModel:
    """The modal parameters of an :class:`~grazing_control.oscillator.ndof.NdofModel`
    as x_w sees them (its tau the model's omega t + phase), sorted by natural frequency;
    ParameterError for a model with an overdamped (real) mode, which this fit does not
    take."""
    from grazing_control.oscillator.ndof.flow import NdofFlow

    flow = NdofFlow.of(model)
    lam = flow.eigenvalues
    if lam.size != model.n or np.any(lam.imag <= 0.0):
        raise ParameterError("C is invalid for identification: every mode must be "
                             "underdamped (0 < zeta < 1); the model has a real eigenvalue")
    order = np.argsort(np.abs(lam), kind="stable")
    Om = np.abs(lam)[order]
    zeta = (-lam.real / np.abs(lam))[order]
    c, s = (a[order] for a in _response(flow, model.i_w))
    kc = ks = None
    if model.i_a != model.i_w:
        kc, ks = (a[order] for a in _response(flow, model.i_a))
    X = flow.amplitudes[model.i_w]
    return ModalModel(Om, zeta, c, s, float(X.real), float(-X.imag),
                      flow.d_star + model.delta_d, model.r, model.omega, kc, ks)


def realise(fitted: ModalModel, nominal, scale, tau0: float = 0.0,
            amplitude_only: bool = False):
    """A model file's model (symmetric M, C, K, real f) whose wall coordinate shows the
    ``fitted`` modal parameters: least squares over M, C, K (upper triangles; M's wall
    entry held: the common scale) and f from ``nominal`` (the model the recording was
    made with: its n, i_w, i_a, pi2_offset),
    each residual the modal parameter's misfit over ``scale`` (its standard error), plus
    1e-6 x the departure from ``nominal`` relative to its size (the data leave M, C, K, f
    determined only up to a change of the hidden coordinates and a common scale; this
    picks the realisation nearest the nominal one). r, omega, the phase tau0 and
    delta_d = d - d* (d* of the realised model) are the fitted ones.

    ``amplitude_only``: of the periodic response only d* = |(P_c, P_s)| is fitted (its
    misfit over P_c's scale), not its phase: a stream whose sections are the plant's own
    Pi2 (t_k = k T) shows no phase of x_w against the forcing (the re-identification in
    the loop, docs/theory_reidentification.md section 6); the phase then follows from
    the realised model nearest ``nominal``.

    Returns (model, misfit): the largest |realised - fitted| / scale over the modal
    parameters (module docstring: the data need not lie exactly on a symmetric model;
    a good realisation misfits by less than a few standard errors).
    """
    import dataclasses

    from scipy.optimize import least_squares

    from grazing_control.oscillator.ndof.model import NdofModel

    n = nominal.n
    if n != fitted.n:
        raise ParameterError(f"model: n={n} of the nominal model, the fit has {fitted.n} modes")
    layout = ModalLayout(n, actuator=nominal.i_a != nominal.i_w)
    if layout.actuator and fitted.kick_c is None:
        raise ParameterError(
            f"i_a={nominal.i_a}: the kick's response on the wall coordinate i_w="
            f"{nominal.i_w} is not identified (the recording has no corrections): no model "
            "for a design can be written; record a controlled scene")
    ip = layout.index_d - 2                 # P_c, P_s (before d and r)

    def shaped(v):
        if amplitude_only:
            v = v.copy()
            v[ip], v[ip + 1] = math.hypot(v[ip], v[ip + 1]), 0.0
        return np.delete(v, [layout.index_d, layout.index_d + 1])

    target = shaped(fitted.vector(layout))
    scale = np.delete(np.asarray(scale, float), [layout.index_d, layout.index_d + 1])
    iu = np.triu_indices(n)
    base = dataclasses.replace(nominal, omega=fitted.omega, r=fitted.r)

    # the wall coordinate's mass is held at the nominal one: it fixes the common scale of
    # M, C, K and f, which no motion shows
    pin = int(np.flatnonzero((iu[0] == nominal.i_w) & (iu[1] == nominal.i_w))[0])
    m_ww = float(nominal.M[nominal.i_w, nominal.i_w])

    def build(theta):
        k = iu[0].size
        theta = np.insert(theta, pin, m_ww)
        mats = []
        for j in range(3):
            a = np.zeros((n, n))
            a[iu] = theta[j * k:(j + 1) * k]
            mats.append(a + np.triu(a, 1).T)
        return dataclasses.replace(base, M=mats[0], C=mats[1], K=mats[2], f=theta[3 * k:])

    theta0 = np.delete(np.concatenate([nominal.M[iu], nominal.C[iu], nominal.K[iu],
                                       nominal.f]), pin)
    size = np.maximum(np.abs(theta0), 1e-3 * np.max(np.abs(theta0)))

    def residual(theta):
        try:
            got = shaped(modal_of(build(theta)).vector(layout))
        except (ParameterError, np.linalg.LinAlgError):
            return np.full(target.size + theta.size, 1e6)
        return np.concatenate([(got - target) / scale, 1e-6 * (theta - theta0) / size])

    sol = least_squares(residual, theta0, x_scale=size, xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=2000)
    model = build(sol.x)
    real = modal_of(model)
    misfit = float(np.max(np.abs(residual(sol.x)[:target.size])))
    model = NdofModel(model.M, model.C, model.K, model.f, fitted.omega, nominal.i_w,
                      delta_d=fitted.d - real.d_star, r=fitted.r, i_a=nominal.i_a,
                      phase=tau0, pi2_offset=nominal.pi2_offset)
    return model, misfit

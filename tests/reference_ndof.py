"""Independent high-precision reference of the n-DOF impact oscillator (mpmath, physical
coordinates).

The yardstick of tests/test_ndof_impact.py and tests/test_modal_map.py; it shares no code
with :mod:`grazing_control`: every formula is written again from the model
(docs/ndof_model.md)::

    M x'' + C x' + K x = f cos(omega t + phase)    while x[i_w] < d,  d = d* + delta_d
    v[i_w]+ = -r v[i_w]-                           at x[i_w] = d, v[i_w]- > 0

at ``DPS`` = 50 digits (the precision tests/reference.py sets too). The periodic response is x_p = Re(X e^{i tau}) with
(K - omega^2 M + i omega C) X = f solved by mpmath's LU; d* = |X_w|, tau* = -arg X_w.
Free flight is X(h) = X_p(tau + omega h) + e^{A h} (X(0) - X_p(tau)) with
A = [[0, I], [-M^-1 K, -M^-1 C]]; e^{A h} comes from mpmath's eigendecomposition of A at
50 digits (:meth:`NdofRef.transition`), checked against mpmath's own ``expm``
(:meth:`NdofRef.transition_expm`) by the tests.

Impacts: the first h > 0 with x_w(h) = d, v_w >= 0. Each forcing period is cut into
``SAMPLES`` cells; a cell whose acceleration changes sign is split at its zero, so v_w
is monotone on each piece; a piece with g < 0 <= g at its ends brackets a root, and a
piece where v_w goes from + to - holds a maximum of g (the zero of v_w) that is tested,
so a grazing hump negative at every grid point is still found (the search is
tests/reference.py's ``first_root``). Every zero is refined by a bracketed Newton
iteration (the next component as derivative) to the precision the arc's evaluation
allows, the bracket closed to a few units of the last place (``_root``). Assumption
(true for the example models: cells of T/128 against the fastest mode's period): no
cell holds two zeros of the acceleration. Sticking is not modelled (more than
``MAX_IMPACTS_PER_PERIOD`` impacts raise RuntimeError).

A force pulse (:meth:`NdofRef.pulse_map`): under a constant force F on x[i_a] the flight
is X_p + S + e^{A h}(X - X_p - S) with S = (K^-1 e_a F ; 0), and the gap has x_w = the
harmonic + S_w + the modes; F = m_a dv / w, m_a = 1 / (M^-1)_aa. Through a first-order
actuator (:meth:`NdofRef.actuated_map`) the force is F + c e^{-h / tau_a} on a piece,
and Q e^{-h / tau_a} with (A + I / tau_a) Q = -B c joins the particular solution (one
more exponential in the arc).

The controller: on Pi2 (phase tau* + pi2_offset) the velocity of coordinate i_a gets
k^T (X - X**), X** = X_p(tau2) the grazing orbit's point.
"""

from __future__ import annotations

from mpmath import mp, mpc, mpf

from reference import first_root, newton_bracket

__all__ = ["DPS", "NdofRef", "load_reference"]

DPS = 50
mp.dps = DPS
SAMPLES = 128
ROOT_TOL = mpf(10) ** -36
MAX_IMPACTS_PER_PERIOD = 60


def _f(value):
    """A float (exact dyadic) or an mpf, as an mpf."""
    return value if isinstance(value, (mpf, mpc)) else mpf(float(value))


def load_reference(path, **changes) -> "NdofRef":
    """The reference of a model YAML file (schema docs/ndof_model.md), fields changed."""
    import yaml

    with open(path, encoding="utf-8") as fh:
        data = dict(yaml.safe_load(fh))
    data.update(changes)
    return NdofRef(**data)


class NdofRef:
    """The model at ``DPS`` digits; parameters taken exactly from their float values."""

    def __init__(self, M, C, K, f, omega, i_w, delta_d=0.0, r=0.68, i_a=0, phase=0.0,
                 pi2_offset=None):
        n = len(M)
        self.n, self.i_w, self.i_a = n, int(i_w), int(i_a)
        self.M = mp.matrix([[_f(x) for x in row] for row in M])
        self.C = mp.matrix([[_f(x) for x in row] for row in C])
        self.K = mp.matrix([[_f(x) for x in row] for row in K])
        self.f = mp.matrix([_f(x) for x in f])
        self.omega = _f(omega)
        self.delta_d = _f(delta_d)
        self.r = _f(r)
        self.phase = _f(phase)
        self.pi2_offset = mp.pi / 2 if pi2_offset is None else _f(pi2_offset)
        w = self.omega
        D = self.K - w * w * self.M + mpc(0, 1) * w * self.C
        self.X = mp.lu_solve(D, self.f)
        Xw = self.X[self.i_w]
        self.d_star = abs(Xw)
        self.tau_star = (-mp.arg(Xw)) % (2 * mp.pi)
        self.tau2 = (self.tau_star + self.pi2_offset) % (2 * mp.pi)
        self.d = self.d_star + self.delta_d
        self.period = 2 * mp.pi / w
        Minv = mp.inverse(self.M)
        MK, MC = Minv * self.K, Minv * self.C
        A = mp.zeros(2 * n, 2 * n)
        for i in range(n):
            A[i, n + i] = 1
            for j in range(n):
                A[n + i, j] = -MK[i, j]
                A[n + i, n + j] = -MC[i, j]
        self.A = A
        self.lam, self.ER = mp.eig(A)
        self.ERinv = mp.inverse(self.ER)
        self.pairs = _conjugate_pairs(self.lam)

    # ------------------------------------------------------------------ flow
    def transition(self, h):
        """e^{A h} = V diag(e^{lambda h}) V^-1 (real part), 2n x 2n mp.matrix."""
        h = _f(h)
        m = 2 * self.n
        out = mp.zeros(m, m)
        e = [mp.exp(l * h) for l in self.lam]
        for i in range(m):
            for j in range(m):
                out[i, j] = mp.re(mp.fsum(self.ER[i, k] * e[k] * self.ERinv[k, j] for k in range(m)))
        return out

    def transition_expm(self, h):
        """e^{A h} by mpmath's expm (Pade / Taylor with scaling), for the cross-check."""
        return mp.expm(self.A * _f(h))

    def particular(self, tau):
        """X_p(tau) = (Re(X e^{i tau}), Re(i omega X e^{i tau})) as a list of 2n mpf."""
        e = mp.expj(_f(tau))
        xs = [mp.re(x * e) for x in self.X]
        vs = [mp.re(mpc(0, 1) * self.omega * x * e) for x in self.X]
        return xs + vs

    def static(self, force):
        """(K^-1 e_a F ; 0): the state at rest under the constant force F on x[i_a]."""
        if force == 0:
            return [mpf(0)] * (2 * self.n)
        e = mp.matrix([1 if i == self.i_a else 0 for i in range(self.n)])
        xs = mp.lu_solve(self.K, e)
        return [xs[i] * _f(force) for i in range(self.n)] + [mpf(0)] * self.n

    def actuated_mass(self):
        """m_a = 1 / (M^-1)_aa (the impulse m_a dv moves v[i_a] by dv)."""
        return 1 / mp.inverse(self.M)[self.i_a, self.i_a]

    def lag_state(self, c, tau_a):
        """Q with (A + I / tau_a) Q = -B c, B = (0 ; M^-1 e_a): the particular solution
        Q e^{-h / tau_a} under the force transient c e^{-h / tau_a} (an actuator's lag)."""
        m = 2 * self.n
        if c == 0:
            return [mpf(0)] * m
        minv_e = mp.inverse(self.M)[:, self.i_a]
        rhs = mp.matrix([0] * self.n + [-_f(c) * minv_e[i] for i in range(self.n)])
        return list(mp.lu_solve(self.A + mp.eye(m) / _f(tau_a), rhs))

    def state(self, tau, X, h, force=0, lag=None):
        """Physical state after flight h from X at phase tau under the force F +
        c e^{-h / tau_a} on x[i_a] (``lag`` = (c, tau_a), default none; a list of 2n mpf):
        X_p + S + Q e^{-h / tau_a} + e^{A h}(X - X_p - S - Q), S the static state, Q
        :meth:`lag_state`."""
        p0 = self.particular(tau)
        S = self.static(force)
        Q, e = (self.lag_state(*lag), mp.exp(-_f(h) / _f(lag[1]))) if lag else \
            ([mpf(0)] * (2 * self.n), mpf(0))
        dev = mp.matrix([_f(X[i]) - p0[i] - S[i] - Q[i] for i in range(2 * self.n)])
        z = self.transition(h) * dev
        p1 = self.particular(_f(tau) + self.omega * _f(h))
        return [p1[i] + S[i] + Q[i] * e + z[i] for i in range(2 * self.n)]

    def arc(self, tau, X, force=0, lag=None):
        return _Arc(self, _f(tau), [_f(x) for x in X], self.static(force),
                    (self.lag_state(*lag), _f(lag[1])) if lag else None)

    # --------------------------------------------------------------- impacts
    def next_impact(self, tau, X, horizon, samples=SAMPLES, force=0, lag=None):
        """First impact time in (0, horizon] from physical X at phase tau (under the
        force F + c e^{-h / tau_a} on x[i_a], ``lag`` = (c, tau_a)), or None."""
        arc = self.arc(tau, X, force, lag)
        horizon = _f(horizon)
        cells = max(4, int(mp.ceil(samples * horizon / self.period)))
        hs = [horizon * k / cells for k in range(cells + 1)]
        return first_root(arc, hs, ROOT_TOL,
                          lambda arc, a, b, which, up: _root(arc, which, a, b, up))

    # -------------------------------------------------------------- the map
    def pi2_map(self, z, gains=None):
        """One period of the Pi2 map from deviation z (from X** = X_p(tau2), before the
        kick); returns (z_next as a list of mpf, impacts [(t, phase mod 2 pi, v-, v+)])."""
        n = self.n
        p2 = self.particular(self.tau2)
        X = [p2[i] + _f(z[i]) for i in range(2 * n)]
        if gains is not None:
            X[n + self.i_a] += mp.fsum(_f(k) * _f(zi) for k, zi in zip(gains, z))
        impacts = []
        X, tau = self._fly(self.tau2, X, mpf(0), self.period, 0, impacts)
        pe = self.particular(tau)
        return [X[i] - pe[i] for i in range(2 * n)], impacts

    def _fly(self, tau, X, t_in, t1, force, impacts, lag=None):
        """Flight with impacts from time t_in to t1 (phase tau there) under the force
        F + c e^{-(t - t_in) / tau_a} on x[i_a] (``lag`` = (c, tau_a), default none), the
        impacts appended (time, phase mod 2 pi, v-, v+); returns (X, tau) at t1 (and the
        transient c there, with ``lag``)."""
        n = self.n
        while t1 > t_in:
            h = self.next_impact(tau, X, t1 - t_in, force=force, lag=lag)
            if h is None:
                X = self.state(tau, X, t1 - t_in, force, lag)
                tau = tau + self.omega * (t1 - t_in)
                if lag:
                    lag = (lag[0] * mp.exp(-(t1 - t_in) / _f(lag[1])), lag[1])
                break
            if len(impacts) >= MAX_IMPACTS_PER_PERIOD:
                raise RuntimeError("reference: chattering/sticking is not modelled")
            X = self.state(tau, X, h, force, lag)
            if lag:
                lag = (lag[0] * mp.exp(-h / _f(lag[1])), lag[1])
            t_in += h
            tau = tau + self.omega * h
            vm = X[n + self.i_w]
            X[self.i_w] = self.d
            X[n + self.i_w] = -self.r * vm
            impacts.append((t_in, tau % (2 * mp.pi), vm, -self.r * vm))
        return (X, tau, lag[0]) if lag else (X, tau)

    def actuated_map(self, z, force, correction, start, width, tau_a, latency):
        """One period through a first-order actuator tau_a F' = u(t - L) - F, u = m_a dv /
        width on the commanded pulse [start, start + width], from deviation z and the
        force ``force`` at the sample; returns (z_next, force at the next sample,
        impacts)."""
        n = self.n
        p2 = self.particular(self.tau2)
        X = [p2[i] + _f(z[i]) for i in range(2 * n)]
        on = _f(start) + _f(latency)
        off = on + _f(width)
        u_on = self.actuated_mass() * _f(correction) / _f(width)
        tau, t, f, impacts = self.tau2, mpf(0), _f(force), []
        for end, u in ((on, 0), (off, u_on), (self.period, 0)):
            if end > t:
                X, tau, c = self._fly(tau, X, t, end, u, impacts, lag=(f - u, tau_a))
                f = u + c
            t = end
        pe = self.particular(tau)
        return [X[i] - pe[i] for i in range(2 * n)], f, impacts

    def pulse_map(self, z, correction, start, width):
        """One period of the Pi2 map from deviation z with the correction dv as a force
        pulse F = m_a dv / width on x[i_a] over [start, start + width] after the sample
        (width 0: the kick at start); returns (z_next, impacts) as :meth:`pi2_map`."""
        n = self.n
        p2 = self.particular(self.tau2)
        X = [p2[i] + _f(z[i]) for i in range(2 * n)]
        start, width = _f(start), _f(width)
        force = self.actuated_mass() * _f(correction) / width if width > 0 else mpf(0)
        legs = [(mpf(0), start, 0), (start, start + width, force),
                (start + width, self.period, 0)]
        tau, impacts = self.tau2, []
        for j, (t0, t1, F) in enumerate(legs):
            if width == 0 and j == 1:
                X[n + self.i_a] += _f(correction)
            X, tau = self._fly(tau, X, t0, t1, F, impacts)
        pe = self.particular(tau)
        return [X[i] - pe[i] for i in range(2 * n)], impacts

    def jacobian(self, z, gains=None, step=mpf("1e-20")):
        """D(pi2_map) at z by central differences: truncation ~ step^2 |D^3 P|, and near
        grazing |D^3 P| ~ v-^-5 (1e28 at v- = 1e-6), rounding ~ 1e-50 / step: both far
        below 1e-12 of |DP| for v- >= 1e-7."""
        m = 2 * self.n
        J = mp.zeros(m, m)
        z = [_f(x) for x in z]
        for j in range(m):
            zp, zm = list(z), list(z)
            zp[j] += step
            zm[j] -= step
            fp, ip = self.pi2_map(zp, gains)
            fm, im = self.pi2_map(zm, gains)
            if len(ip) != len(im):
                raise RuntimeError("reference: the impact count changes inside the difference")
            for i in range(m):
                J[i, j] = (fp[i] - fm[i]) / (2 * step)
        return J

    def fixed_point(self, z, gains=None, tol=mpf("1e-30"), max_iter=20):
        """A fixed point of the Pi2 map near z by Newton with the differenced Jacobian;
        returns (z*, J at z*, impacts)."""
        m = 2 * self.n
        z = mp.matrix([_f(x) for x in z])
        for _ in range(max_iter):
            fz, _imp = self.pi2_map(list(z), gains)
            J = self.jacobian(list(z), gains)
            res = mp.matrix([fz[i] - z[i] for i in range(m)])
            dz = mp.lu_solve(J - mp.eye(m), -res)
            z = z + dz
            if mp.norm(dz) < tol * (1 + mp.norm(z)):
                break
        else:
            raise RuntimeError("reference Newton did not converge")
        zs = list(z)
        fz, imp = self.pi2_map(zs, gains)
        return zs, self.jacobian(zs, gains), imp

    # ------------------------------------------------------------- sticking
    def _stuck_generator(self):
        """Augmented generator G of (y, y', cos tau, sin tau, 1) while x_w = d, v_w = 0:
        y'' = M_yy^-1 (f_y cos tau - K_yw d - C_yy y' - K_yy y)."""
        n, w = self.n, self.i_w
        o = [i for i in range(n) if i != w]
        p = len(o)
        Myy = mp.matrix([[self.M[i, j] for j in o] for i in o]) if p else None
        G = mp.zeros(2 * p + 3, 2 * p + 3)
        if p:
            Minv = mp.inverse(Myy)
            for a in range(p):
                G[a, p + a] = 1
            for a in range(p):
                for b in range(p):
                    G[p + a, b] = -mp.fsum(Minv[a, c] * self.K[o[c], o[b]] for c in range(p))
                    G[p + a, p + b] = -mp.fsum(Minv[a, c] * self.C[o[c], o[b]] for c in range(p))
                G[p + a, 2 * p] = mp.fsum(Minv[a, c] * self.f[o[c]] for c in range(p))
                G[p + a, 2 * p + 2] = -mp.fsum(Minv[a, c] * self.K[o[c], w] * self.d for c in range(p))
        G[2 * p, 2 * p + 1] = -self.omega      # (cos tau)' = -omega sin tau
        G[2 * p + 1, 2 * p] = self.omega       # (sin tau)' = omega cos tau
        return o, G

    def contact_force(self, tau, X):
        """lambda at physical X (x_w = d, v_w = 0): the n x n solve of M (x'') + lambda e_w
        = f cos tau - C x' - K x for the unknowns (y'', lambda) with x_w'' = 0."""
        n, w = self.n, self.i_w
        rhs = mp.matrix([self.f[i] * mp.cos(tau)
                         - mp.fsum(self.C[i, j] * X[n + j] + self.K[i, j] * X[j] for j in range(n))
                         for i in range(n)])
        Bm = mp.zeros(n, n)
        for i in range(n):
            for j in range(n):
                Bm[i, j] = (1 if i == w else 0) if j == w else self.M[i, j]
        sol = mp.lu_solve(Bm, rhs)
        return sol[w]

    def stuck_state(self, tau, X, h):
        """Physical state after time h stuck on the wall from X at phase tau."""
        n, w = self.n, self.i_w
        o, G = self._stuck_generator()
        p = len(o)
        s = [X[i] for i in o] + [X[n + i] for i in o] + [mp.cos(tau), mp.sin(tau), mpf(1)]
        E = mp.expm(G * _f(h))
        u = E * mp.matrix(s)
        out = [mpf(0)] * (2 * n)
        for a, i in enumerate(o):
            out[i], out[n + i] = u[a], u[p + a]
        out[w], out[n + w] = self.d, mpf(0)
        return out

    def run(self, tau, X, duration, samples=SAMPLES):
        """Physical state after ``duration`` from X at phase tau, with impacts and sticking
        (a start at rest on the wall pushed into it sticks); returns (X, events), events
        ('impact', t, v-) and ('stick', t, release or None)."""
        n, w = self.n, self.i_w
        X = [_f(x) for x in X]
        tau, t, T = _f(tau), mpf(0), _f(duration)
        events = []
        while t < T:
            # at rest on the wall to the rounding of a float start state (1e-13)
            rest = abs(X[w] - self.d) < mpf(10) ** -13 and abs(X[n + w]) < mpf(10) ** -13
            if rest and self.contact_force(tau, X) > 0:
                X[w], X[n + w] = self.d, mpf(0)
                X0, tau0 = list(X), tau

                def lam(h):
                    return self.contact_force(tau0 + self.omega * h, self.stuck_state(tau0, X0, h))

                cells = max(4, int(mp.ceil(samples * (T - t) / self.period)))
                hs = [(T - t) * k / cells for k in range(cells + 1)]
                hr = None
                for a, b in zip(hs, hs[1:]):
                    if lam(b) <= 0:
                        hr = mp.findroot(lam, (a, b), solver="anderson", tol=ROOT_TOL ** 2,
                                         verify=False)
                        break
                h = (T - t) if hr is None else hr
                events.append(("stick", t, None if hr is None else t + hr))
                X = self.stuck_state(tau0, X0, h)
                t, tau = t + h, tau0 + self.omega * h
                if hr is None:
                    break
                # leave the wall: a first step without search (g ~ lambda' h^3 / 6 < 0)
                eps = self.period * mpf(10) ** -18
                X, t, tau = self.state(tau, X, eps), t + eps, tau + self.omega * eps
                continue
            h = self.next_impact(tau, X, T - t, samples)
            if h is None:
                X = self.state(tau, X, T - t)
                break
            X = self.state(tau, X, h)
            t, tau = t + h, tau + self.omega * h
            vm = X[n + w]
            if len(events) >= MAX_IMPACTS_PER_PERIOD:
                raise RuntimeError("reference: chattering is not modelled")
            X[w], X[n + w] = self.d, -self.r * vm
            events.append(("impact", t, vm))
        return X, events

    def multipliers(self, J):
        """Eigenvalues of J at DPS digits, by decreasing modulus."""
        ev, _ = mp.eig(J)
        return sorted(ev, key=lambda x: -abs(x))


class _Arc:
    """Gap g = x_w - d, velocity and acceleration of the wall coordinate along one free
    flight: the harmonic of X_w plus the modes of the homogeneous part."""

    def __init__(self, ref: NdofRef, tau, X, static=None, lag=None):
        self.ref = ref
        p0 = ref.particular(tau)
        m = 2 * ref.n
        static = static or [mpf(0)] * m
        self.xs = static[ref.i_w]
        q, self.tau_a = lag if lag else ([mpf(0)] * m, None)
        self.qw = q[ref.i_w]
        dev = [X[i] - p0[i] - static[i] - q[i] for i in range(m)]
        w = ref.i_w
        c = [ref.ER[w, k] * mp.fsum(ref.ERinv[k, j] * dev[j] for j in range(m))
             for k in range(m)]
        # only real parts are used: a conjugate pair's two terms are one,
        # Re(c_k e^{l h} + c_j e^{conj(l) h}) = Re((c_k + conj(c_j)) e^{l h}); each term
        # is kept as real numbers: Re l, Im l, Re and Im of c and of l^2, l^3
        self.terms = []
        for k, j in ref.pairs:
            lk = mpc(ref.lam[k])
            ck = mpc(c[k] if j is None else c[k] + mp.conj(c[j]))
            l2, l3 = lk * lk, lk * lk * lk
            self.terms.append((lk.real, lk.imag, ck.real, ck.imag,
                               l2.real, l2.imag, l3.real, l3.imag))
        # the harmonic Re(X_w e^{i (tau + omega h)}) = |X_w| cos(arg X_w + tau + omega h)
        self.amplitude = abs(ref.X[w])
        self.phase = mp.arg(ref.X[w]) + tau

    def __call__(self, h, jerk=False):
        """(g, v_w, a_w[, jerk]) at time h since the start of the flight."""
        ref = self.ref
        om = ref.omega
        cp, sp = mp.cos_sin(self.phase + om * h)
        ah = self.amplitude * cp
        g = ah + self.xs - ref.d
        v = -om * self.amplitude * sp
        a = -om * om * ah
        j = -om * v * om if jerk else 0
        for re, im, cr, ci, re2, im2, re3, im3 in self.terms:
            # e = c e^{l h} = u + i w
            ex = mp.exp(re * h)
            if im:
                c, s = mp.cos_sin(im * h)
                u, w = ex * (cr * c - ci * s), ex * (cr * s + ci * c)
            else:
                u, w = ex * cr, ex * ci
            g += u
            v += re * u - im * w
            a += re2 * u - im2 * w
            if jerk:
                j += re3 * u - im3 * w
        if self.tau_a is not None:     # the lag's transient q_w e^{-h / tau_a}
            e = self.qw * mp.exp(-h / self.tau_a)
            g, v, a = g + e, v - e / self.tau_a, a + e / self.tau_a ** 2
            j -= e / self.tau_a ** 3
        return (g, v, a, j) if jerk else (g, v, a)


def _conjugate_pairs(lam):
    """[(k, j)]: each eigenvalue k with positive imaginary part and j its conjugate
    (nearest conj(lam[k]), to 1e-30 relative), or (k, None) for one without a partner
    (real). The eigenvalues of the real A come in such pairs."""
    left, out = set(range(len(lam))), []
    for k in sorted(left, key=lambda k: -mp.im(lam[k])):
        if k not in left:
            continue
        left.discard(k)
        j = min(left, key=lambda j: abs(lam[j] - mp.conj(lam[k])), default=None)
        if (j is not None and mp.im(lam[k]) > 0
                and abs(lam[j] - mp.conj(lam[k])) <= abs(lam[k]) * mpf(10) ** -30):
            left.discard(j)
            out.append((k, j))
        else:
            out.append((k, None))
    return out


def _root(arc, which, lo, hi, increasing):
    """Root of component ``which`` (0 gap, 1 velocity, 2 acceleration) of the arc in the
    bracket [lo, hi], where it goes from < 0 at lo to >= 0 at hi (``increasing``; else the
    reverse), to the precision the arc's evaluation allows; the bracket's upper end is
    returned (as a bisection would). Newton with the next component as derivative, kept
    inside the bracket (bisection where a step leaves it); once its steps are below 16
    units of the last place, or its value below 32 units of the last place of 1 (the
    components' terms are of order 1: their rounding), the bracket is closed around its
    limit at widths growing 16-fold from the step w0 that rounding allows, each
    evaluation moving one end of the bracket, and bisected to 2 w0. (mp.findroot's Anderson
    method took 34 evaluations a split and, near grazing, failed on the gap to a 200-step
    bisection: 235 evaluations a root.)"""
    sign = 1 if increasing else -1

    def f(h):
        return sign * arc(h)[which]

    ulp = mp.ldexp(max(abs(lo), abs(hi)), 4 - mp.prec)     # 16 units of the last place
    noise = mp.ldexp(1, 5 - mp.prec)    # the components' terms are of order 1
    x = (lo + hi) / 2
    for _ in range(600):
        fx, dfx, lo, hi = newton_bracket(arc, x, lo, hi, which, sign)
        if fx == 0:
            return x
        if hi - lo <= ulp:
            return hi
        xn = x - fx / dfx if dfx != 0 else (lo + hi) / 2
        # converged: the step rounds to nothing, or the value is at its rounding's level
        if abs(xn - x) <= ulp or abs(fx) <= noise:
            xn = min(max(xn, lo), hi)
            break
        x = xn if lo < xn < hi else (lo + hi) / 2
    else:
        return hi
    # close the bracket around Newton's limit xn, then bisect it to the width rounding
    # allows: the root is within 2 w0 above a point where the component is < 0
    w0 = width = max(ulp, 2 * noise / abs(dfx)) if dfx != 0 else ulp
    while hi - lo > 2 * width:
        for y in (xn - width, xn + width):
            if lo < y < hi:
                if f(y) < 0:
                    lo = y
                else:
                    hi = y
        width *= 16
    while hi - lo > 2 * w0:
        mid = (lo + hi) / 2
        if f(mid) < 0:
            lo = mid
        else:
            hi = mid
    return hi

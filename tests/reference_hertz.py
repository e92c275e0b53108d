"""20-digit mpmath reference for one Hertz / Hunt-Crossley contact (docs/theory_contact.md,
"Hertz accuracy").

delta^{3/2} is not analytic at the entry, so mpmath's Taylor-series odefun starts at
h0 = 1e-5 after it, from the free flight's closed form (in mpmath) plus the leading
correction of the contact force: with K = k_c (1 + 1.5 alpha v0),

    delta(h0) = delta_free(h0) - (4/35) K v0^{3/2} h0^{7/2},
    delta'(h0) = delta_free'(h0) - (2/5) K v0^{3/2} h0^{5/2},

whose neglected terms are O(K v0^{1/2} |delta''| h0^{9/2}) (about 1e-20 here). The exit
(the first of 1 + 1.5 alpha delta' = 0 and delta = 0) is bracketed on a grid of the
solution and refined by mpmath's findroot.
"""

from __future__ import annotations

import mpmath as mp

H0 = mp.mpf("1e-5")


def reference_contact(p, law, tau_e, v0, dps=20):
    """(exit time after the entry, delta at the exit, delta' at the exit), at ``dps``
    digits (mpmath's working precision is restored on return: the other references of the
    suite set theirs at import)."""
    with mp.workdps(dps):
        return _reference_contact(p, law, tau_e, v0)


def _reference_contact(p, law, tau_e, v0):
    zeta, w, d = mp.mpf(p.zeta), mp.mpf(p.omega), mp.mpf(p.d)
    k, a = mp.mpf(law.stiffness), mp.mpf(law.alpha)
    tau_e, v0 = mp.mpf(tau_e), mp.mpf(v0)
    # free flight from (delta, delta') = (0, v0) at phase tau_e, closed form in mpmath
    amp = 1 / mp.sqrt((1 - w ** 2) ** 2 + (2 * zeta * w) ** 2)
    lag = mp.atan2(2 * zeta * w, 1 - w ** 2)
    wd = mp.sqrt(1 - zeta ** 2)
    c1 = 0 - (amp * mp.cos(tau_e - lag) - d)
    c2 = (v0 + amp * w * mp.sin(tau_e - lag) + zeta * c1) / wd

    def free(h):
        e = mp.exp(-zeta * h)
        x = amp * mp.cos(tau_e + w * h - lag) - d + e * (c1 * mp.cos(wd * h) + c2 * mp.sin(wd * h))
        v = (-amp * w * mp.sin(tau_e + w * h - lag)
             + e * ((wd * c2 - zeta * c1) * mp.cos(wd * h) - (wd * c1 + zeta * c2) * mp.sin(wd * h)))
        return x, v

    big_k = k * (1 + mp.mpf(3) / 2 * a * v0)
    x0, y0 = free(H0)
    x0 -= mp.mpf(4) / 35 * big_k * v0 ** 1.5 * H0 ** 3.5
    y0 -= mp.mpf(2) / 5 * big_k * v0 ** 1.5 * H0 ** 2.5

    def rhs(h, u):
        delta, vel = u
        force = k * (delta if delta > 0 else 0) ** 1.5 * (1 + mp.mpf(3) / 2 * a * vel)
        return [vel, mp.cos(tau_e + w * h) - 2 * zeta * vel - (delta + d) - force]

    sol = mp.odefun(rhs, H0, [x0, y0])

    def ends(h):
        delta, vel = sol(h)
        return delta, 1 + mp.mpf(3) / 2 * a * vel

    step = mp.pi / mp.sqrt(k * mp.sqrt(v0)) / 40  # a fraction of the contact time scale
    lo = H0
    while True:
        hi = lo + step
        gap, factor = ends(hi)
        if gap <= 0 or factor <= 0:
            break
        lo = hi
    which = 0 if gap <= 0 else 1  # the force's first zero: the gap's or the factor's
    te = mp.findroot(lambda h: ends(h)[which], (lo, hi), solver="anderson")
    delta, vel = sol(te)
    return te, delta, vel

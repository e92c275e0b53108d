"""The 2/2 orbit born at the period doubling, by Newton shooting: drawn in Fig. 1(b).

An independent check of the brute-force diagram past the doubling: the 2/2 orbit
is found by Newton shooting on the twice-iterated Pi2 map
(:func:`grazing_control.dynamics.orbits.shoot`, exact flow, monodromy from Phi and S),
started from a brute-force period-2 sample and continued in Delta d with the
previous orbit as the guess. Its own period doubling (the start of the period-4
window) is located by Brent's method on the test function 1 + tr J + det J of its
monodromy, as for the 1/1 branch (docs/theory.md §7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from grazing_control.dynamics.maps import pi2_map
from grazing_control.dynamics.orbits import OrbitNotFound, shoot
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["TwoCycle", "two_cycle"]


@dataclass(frozen=True)
class TwoCycle:
    """The 2/2 branch: delta_d (n,), x (n, 2) its two Pi2 samples, multipliers (n, 2),
    stable (n,), and the Delta d of its period doubling (None if not in range)."""

    delta_d: np.ndarray
    x: np.ndarray
    multipliers: np.ndarray
    stable: np.ndarray
    period_doubling: float | None


def _orbit(p, delta_d, guess):
    o = shoot(p.with_(delta_d=float(delta_d)), deviation=guess, periods=2)
    if o.label != "2/2":
        raise OrbitNotFound(f"shooting at delta_d={delta_d!r} found a {o.label} orbit, not 2/2")
    return o


def _test(o) -> float:
    """1 + tr J + det J: zero when a multiplier of the 2/2 orbit is -1."""
    lam = o.multipliers
    return float(1.0 + (lam[0] + lam[1]).real + (lam[0] * lam[1]).real)


def two_cycle(p: OscillatorParams, delta_d, guess) -> TwoCycle:
    """Continue the 2/2 orbit along the values ``delta_d`` (in order) from ``guess``, a
    Pi2 deviation near it at the first value; stops early where shooting fails."""
    rows, g = [], np.asarray(guess, dtype=float)
    for d in np.asarray(delta_d, dtype=float):
        try:
            o = _orbit(p, d, g)
        except (OrbitNotFound, ValueError, ArithmeticError):
            break
        g = np.array(o.pi2_deviation)
        q = p.with_(delta_d=float(d))
        nxt = pi2_map(q, *o.pi2_deviation)
        rows.append((float(d), o.pi2[0], q.x_ref + nxt.dx, o.multipliers, o))
    pd = None
    for a, b in zip(rows[:-1], rows[1:]):
        fa, fb = _test(a[4]), _test(b[4])
        if fa * fb < 0.0:
            last = {"guess": np.array(a[4].pi2_deviation)}

            def f(d):
                o = _orbit(p, d, last["guess"])
                last["guess"] = np.array(o.pi2_deviation)
                return _test(o)

            pd = float(brentq(f, a[0], b[0], xtol=1e-16, rtol=1e-13))
            break
    lam = np.array([r[3] for r in rows]).reshape(-1, 2)
    return TwoCycle(
        delta_d=np.array([r[0] for r in rows]),
        x=np.array([(r[1], r[2]) for r in rows]).reshape(-1, 2),
        multipliers=lam,
        stable=np.max(np.abs(lam), axis=1) < 1.0 if rows else np.zeros(0, bool),
        period_doubling=pd,
    )

"""The 2/2 orbit born at the period doubling, by Newton shooting: drawn in Fig. 1(b).

An independent check of the brute-force diagram past the doubling: the 2/2 orbit
is found by Newton shooting on the twice-iterated Pi2 map (exact flow, monodromy from
Phi and S), started from a brute-force period-2 sample and continued in Delta d by the
generic continuation over the model protocol
(:func:`grazing_control.dynamics.orbits.continuation.continue_orbit`). Its own period
doubling (the start of the period-4 window) is located by Brent's method on the test
function det(J + I) of its monodromy, as for the 1/1 branch (docs/theory.md §7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from grazing_control.dynamics.orbits.continuation import continue_orbit
from grazing_control.dynamics.maps.maps import pi2_map
from grazing_control.dynamics.maps.model import OneDOF
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


def two_cycle(p: OscillatorParams, delta_d, guess) -> TwoCycle:
    """Continue the 2/2 orbit along the values ``delta_d`` (in order) from ``guess``, a
    Pi2 deviation near it at the first value; stops early where shooting fails or the
    orbit is no longer 2/2 (:func:`grazing_control.dynamics.orbits.continuation.continue_orbit`
    on the 1-DOF model)."""
    values = np.asarray(delta_d, dtype=float)
    rows = []
    if values.size >= 2:
        branch = continue_orbit(OneDOF(p), "delta_d", values, guess, periods=2, tol=1e-14)
        rows = [pt for pt in branch.points if pt.impacts == 2 and pt.value in values]
        pd = next((b.value for b in branch.bifurcations if b.type == "period-doubling"),
                  None)
    else:
        pd = None
    x = []
    for pt in rows:
        q = p.with_(delta_d=pt.value)
        nxt = pi2_map(q, *pt.state)
        x.append((q.x_ref + pt.state[0], q.x_ref + nxt.dx))
    lam = np.array([pt.multipliers for pt in rows]).reshape(-1, 2)
    return TwoCycle(
        delta_d=np.array([pt.value for pt in rows]),
        x=np.array(x).reshape(-1, 2),
        multipliers=lam,
        stable=np.max(np.abs(lam), axis=1) < 1.0 if rows else np.zeros(0, bool),
        period_doubling=pd,
    )

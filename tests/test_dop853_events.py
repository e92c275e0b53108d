"""The contact references' integrator (tests/dop853_events.py): Hairer's Fortran DOP853
with solve_ivp's events gives the closed form's roots and states, and the references
built on it agree with the same references on solve_ivp."""

from __future__ import annotations

import math
import random

import pytest
from scipy.integrate import solve_ivp

import reference_contact
from dop853_events import solve
from test_contact import _case


def _oscillator(t, y):
    return [y[1], -y[0]]


def test_roots_and_states_are_the_closed_forms():
    """x'' = -x from (1, 0): x = cos t. Every zero of x (non-terminal, either direction)
    at pi/2 + k pi, a terminal maximum of x (x' = 0 falling) at 2 pi, the state there and
    inside any step to 1e-13."""
    def zero(t, y):
        return y[0]

    def top(t, y):
        return y[1]
    top.terminal, top.direction = True, -1.0
    sol = solve(_oscillator, 0.1, [math.cos(0.1), -math.sin(0.1)], 20.0, [zero, top],
                rtol=2.3e-14, atol=1e-15, max_step=0.05, first_step=1e-9)
    assert sol.status == 1
    assert sol.t_events[0] == pytest.approx([math.pi / 2, 3 * math.pi / 2], abs=1e-13)
    assert sol.t_events[1] == pytest.approx([2 * math.pi], abs=1e-13)
    assert sol.t[-1] == sol.t_events[1][0]
    assert sol.y[:, -1] == pytest.approx([1.0, 0.0], abs=1e-13)
    rng = random.Random(5)
    for s in (rng.uniform(0.1, 2 * math.pi) for _ in range(200)):
        assert sol.sol(s) == pytest.approx([math.cos(s), -math.sin(s)], abs=1e-13)


def test_an_event_on_one_side_only_and_the_end_without_one():
    """A rising zero is not a falling one; with no terminal event the solution runs to
    t1, whose state is the closed form's."""
    def rising(t, y):
        return y[0]
    rising.direction = 1.0
    sol = solve(_oscillator, 0.0, [1.0, 0.0], 7.0, [rising], rtol=2.3e-14, atol=1e-15,
                max_step=0.05, first_step=1e-9)
    assert sol.status == 0 and sol.t[-1] == 7.0
    assert sol.t_events[0] == pytest.approx([3 * math.pi / 2], abs=1e-13)
    assert sol.y[:, -1] == pytest.approx([math.cos(7.0), -math.sin(7.0)], abs=1e-13)


def test_the_kelvin_voigt_reference_is_the_one_on_solve_ivp(monkeypatch):
    """tests/test_contact.py's seeded cases (seed 1000, 24 cases: random states, grazing
    flights and held contacts), the reference on each integrator: end states to 1e-12
    (1 + |x| + |v|), the same contacts, their times to 1e-10."""
    def on_solve_ivp(rhs, t0, y0, t1, events):
        return solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol=reference_contact.RTOL,
                         atol=reference_contact.ATOL, events=events, dense_output=True,
                         max_step=reference_contact.MAX_STEP[0], first_step=1e-9)

    rng = random.Random(1000)
    cases = [_case(rng) for _ in range(24)]
    ours = [reference_contact.reference_advance(p, law, tau0, x, v, p.period)
            for _, p, law, tau0, x, v in cases]
    monkeypatch.setattr(reference_contact, "_solve", on_solve_ivp)
    kinds, contacts = set(), 0
    for (kind, p, law, tau0, x, v), (xa, va, ca) in zip(cases, ours):
        xb, vb, cb = reference_contact.reference_advance(p, law, tau0, x, v, p.period)
        tol = 1e-12 * (1.0 + abs(xb) + abs(vb))
        assert abs(xa - xb) <= tol and abs(va - vb) <= tol, (kind, xa - xb, va - vb)
        assert len(ca) == len(cb), (kind, ca, cb)
        for (ia, oa), (ib, ob) in zip(ca, cb):
            assert ia == pytest.approx(ib, abs=1e-10)
            if math.isinf(ob):
                assert math.isinf(oa)
            else:
                assert oa == pytest.approx(ob, abs=1e-10)
        kinds.add(kind)
        contacts += len(cb)
    assert kinds == {"random", "graze", "stick"} and contacts > 10, (kinds, contacts)

"""The Kelvin-Voigt stop's exact flow (oscillator/contact.py) gives the same floats, bit
for bit, as before its hot path was made cheaper (issue 30, the suite's CPU): a digest of
seeded random cases (states, stops, frictions, external forces, monodromy and dense
output) against the one the unchanged code gave (commit c0ece06, the digest printed by
``python tests/test_compliant_flow_bits.py``), and the stop's fit residuals likewise.

A digest rather than the old code kept as a copy: the reference is the code as it was,
not a second implementation to keep in step; a case that differs in any bit of any
output (end state, contacts, sticks, monodromy, dense states, the error raised) changes
the digest. ``benchmarks/bench_compliant_flow.py`` runs the old code (from git) and the
new side by side on the same cases and names the first that differs.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

from grazing_control.oscillator import contact, kernel
from grazing_control.oscillator.contact import (Coulomb, KelvinVoigt, LagForce,
                                                advance_compliant, compliant_period_step)
from grazing_control.oscillator.impact import ImpactCapError
from grazing_control.oscillator.params import OscillatorParams

CASES = 600
#: sha256 of the canonical outputs of :func:`flow_cases` (CASES, seed 30) from c0ece06
FLOW_DIGEST = "44a6138e02c48b4300507cb252ff920be4e767d3458962bc8ae46aa5de7db3bc"
#: sha256 of :func:`period_cases` from c0ece06
PERIOD_DIGEST = "3caa1de96cbe0120f2e82f064278d1c8ff4125dccd971774730e8de4893eca57"


def _canonical(value) -> str:
    """Every float as its exact hex, recursively: equal strings iff equal bits."""
    if isinstance(value, float):
        return value.hex()
    if isinstance(value, (tuple, list)):
        return "(" + ",".join(_canonical(v) for v in value) + ")"
    return repr(value)


def _digest(outputs) -> str:
    h = hashlib.sha256()
    for out in outputs:
        h.update(_canonical(out).encode())
        h.update(b";")
    return h.hexdigest()


def flow_cases(n: int = CASES, seed: int = 30) -> list:
    """``n`` seeded calls of advance_compliant as (args, kwargs): oscillators around the
    study's, stops from k_c = 3 to 1e7 and r = 0.3 ... 0.95, states near the stop (every
    region to start in), Coulomb friction (kinetic only or with a larger static level)
    (F_f = 1e-3 ... 0.6, sticks too)
    in two thirds, an actuator's force in a quarter, monodromy where it is defined, dense
    output in a third."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n):
        base = OscillatorParams()
        p = OscillatorParams(zeta=float(rng.uniform(0.01, 0.1)),
                             omega=float(base.omega * rng.uniform(0.97, 1.03)),
                             delta_d=float(rng.uniform(-0.1, 0.02)))
        law = KelvinVoigt.from_restitution(float(10.0 ** rng.uniform(0.5, 7.0)),
                                           float(rng.uniform(0.3, 0.95)))
        kind = rng.integers(3)
        f = float(10.0 ** rng.uniform(-3.0, -0.2))
        friction = (None, Coulomb(f), Coulomb(f, f * float(rng.uniform(1.0, 2.0))))[kind]
        force = None
        if rng.uniform() < 0.25:
            force = LagForce(float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.2, 0.2)),
                             float(rng.uniform(0.5, 5.0)))
        x = p.d + float(rng.uniform(-0.5, 0.02))
        v = float(rng.uniform(-1.0, 1.0))
        duration = float(p.period * rng.uniform(0.3, 2.5))
        kwargs = {"friction": friction, "force": force, "max_contacts": 100}
        if friction is None and force is None and rng.uniform() < 0.5:
            kwargs["monodromy"] = True
        if rng.uniform() < 0.33:
            kwargs["times"] = sorted(float(u) for u in rng.uniform(0.0, duration, 6))
        cases.append(((p, law, float(rng.uniform(0.0, 2.0 * math.pi)), x, v, duration),
                      kwargs))
    return cases


def run_flow(advance, cases) -> list:
    """The outputs of ``advance`` on ``cases`` (the error's type where one is raised)."""
    out = []
    for args, kwargs in cases:
        try:
            out.append(tuple(advance(*args, **kwargs)))
        except (ValueError, ArithmeticError, ImpactCapError) as e:
            out.append(type(e).__name__)
    return out


def period_cases(n: int = 200, seed: int = 31) -> list:
    """``n`` seeded calls of compliant_period_step: Pi2 deviations of the study's
    oscillator at Delta d = -0.05 ... 0, the stops of :func:`flow_cases`, with and
    without friction and a correction."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n):
        p = OscillatorParams(delta_d=float(rng.uniform(-0.05, 0.0)))
        law = KelvinVoigt.from_restitution(float(10.0 ** rng.uniform(0.5, 7.0)),
                                           float(rng.uniform(0.3, 0.95)))
        friction = Coulomb(float(rng.uniform(0.0, 0.03))) if rng.uniform() < 0.5 else None
        cases.append(((p, law, float(rng.uniform(-0.3, 0.3)), float(rng.uniform(-0.3, 0.3)),
                       float(rng.uniform(-0.01, 0.01))), {"friction": friction}))
    return cases


def test_the_flow_gives_the_same_bits():
    outputs = run_flow(advance_compliant, flow_cases())
    # the cases reach the branches: contacts (463 of 600), sticks (30), the cap (5)
    assert sum(isinstance(o, tuple) and len(o[2]) > 0 for o in outputs) > CASES // 4
    assert sum(isinstance(o, tuple) and len(o[3]) > 0 for o in outputs) >= 20
    assert sum(isinstance(o, str) for o in outputs) > 0      # the cap, raised
    assert _digest(outputs) == FLOW_DIGEST


def test_the_period_map_gives_the_same_bits():
    assert _digest(run_flow(compliant_period_step, period_cases())) == PERIOD_DIGEST


def test_the_compiled_bracketing_gives_the_same_bits(monkeypatch):
    """contact.load_compiled's path (kernel/compiled_contact.py) against the same digests;
    the Python path above runs in this process before (and, GRAZING_KERNEL=python, after)."""
    if not kernel.available():
        pytest.skip("numba is not installed")
    monkeypatch.delenv(kernel.ENV, raising=False)
    monkeypatch.setattr(contact, "_compiled", None)
    assert contact.load_compiled()
    assert _digest(run_flow(advance_compliant, flow_cases())) == FLOW_DIGEST
    assert _digest(run_flow(compliant_period_step, period_cases())) == PERIOD_DIGEST
    monkeypatch.setattr(contact, "_compiled", None)
    monkeypatch.setenv(kernel.ENV, "python")
    assert not contact.load_compiled()      # the choice of the core's kernel is followed


if __name__ == "__main__":
    print(_digest(run_flow(advance_compliant, flow_cases())))
    print(_digest(run_flow(compliant_period_step, period_cases())))

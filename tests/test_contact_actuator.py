"""The compliant stops under the first-order actuator's force (issue 31 with issue 29's
actuator; docs/theory_contact.md §21): the Kelvin-Voigt stop's closed form with the
exponential particular solution, its certified switches and the stick released by the
decaying force, and the Hertz stop with the force in DOP853's right-hand side, against
the independent DOP853 references with the force written into the equation
(tests/reference_contact.py, tests/reference_hertz.py)."""

from __future__ import annotations

import math
import os
import random

import pytest

from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, LagForce, advance_compliant
from grazing_control.oscillator.hertz import HuntCrossley, advance_hertz
from grazing_control.oscillator.params import OscillatorParams

from reference_contact import refined, reference_advance, seeded_start
from reference_hertz import reference_advance_hertz

#: seeded cases per test (each law, with and without friction)
CASES = int(os.environ.get("CONTACT_LAG_CASES", "100"))
TWO_PI = 2.0 * math.pi
#: the Hertz flow's documented tolerance (tests/test_hertz.py, docs/theory_contact.md)
TOL_HERTZ = 1e-10


def _lag(rng):
    """The actuator's force on a piece: F_inf + C e^{-t / tau_a}, tau_a 0.05..2 (the
    bandwidths of the scenes, 0.5..20 omega), a rising (C < 0 < F_inf) or decaying
    transient, or a constant force (C = 0, the latency alone)."""
    f_inf = rng.uniform(-0.5, 0.5)
    c = 0.0 if rng.random() < 0.1 else rng.uniform(-1.0, 1.0)
    return LagForce(f_inf, c, 1.0 / rng.uniform(0.05, 2.0))


def _case(rng, law_kind, friction):
    p = OscillatorParams(delta_d=-10 ** rng.uniform(-6, -0.5), zeta=rng.uniform(0.005, 0.2))
    if law_kind == "kv":
        law = KelvinVoigt.from_restitution(10 ** rng.uniform(0.5, 4), rng.uniform(0.2, 1.0))
    else:
        law = HuntCrossley(10 ** rng.uniform(1, 4),
                           rng.choice([0.0, 10 ** rng.uniform(-2, 1)]))
    kind, p, tau0, x, v = seeded_start(rng, p)
    fr = None
    if friction:
        f_kin = 10 ** rng.uniform(-2, -0.3)
        fr = Coulomb(f_kin, f_kin * rng.uniform(1.0, 1.5))
    return kind, p, law, fr, tau0, x, v, _lag(rng)


def _compare(law_kind, seed, friction, tol, time_tol):
    rng = random.Random(31000 + 10 * seed + (5 if friction else 0) + (0 if law_kind == "kv" else 2))
    contacts = transient_contacts = sticks = released = 0
    for _ in range(CASES):
        kind, p, law, fr, tau0, x, v, lag = _case(rng, law_kind, friction)
        advance = advance_compliant if law_kind == "kv" else advance_hertz
        reference = reference_advance if law_kind == "kv" else reference_advance_hertz
        seg = advance(p, law, tau0, x, v, p.period, friction=fr, force=lag)
        args = (p, law, tau0, x, v, p.period)
        kw = dict(friction=fr, force=lambda t, lag=lag: lag.at(t))
        out = reference(*args, **kw)
        xr, vr, ref = out[:3]
        tol_x = tol * (1.0 + abs(xr) + abs(vr))
        if not (abs(seg.x - xr) <= tol_x and abs(seg.v - vr) <= tol_x):
            out = refined(reference, *args, **kw)
            xr, vr, ref = out[:3]
        label = (kind, p, law, fr, tau0, x, v, lag)
        assert abs(seg.x - xr) <= tol_x and abs(seg.v - vr) <= tol_x, (label, seg, xr, vr)
        assert len(seg.contacts) == len(ref), (label, seg.contacts, ref)
        for c, (t_in, t_out) in zip(seg.contacts, ref):
            assert abs(c.dt - t_in) <= time_tol, (label, c, t_in)
            assert (math.isinf(c.duration) if math.isinf(t_out)
                    else abs(c.dt + c.duration - t_out) <= time_tol), (label, c, t_out)
            # a contact entered while the transient is at least 10 % of its start
            transient_contacts += abs(lag.transient(c.dt)) > 0.1 * abs(lag.c) > 0.0
        if friction:
            ref_sticks = out[3]
            assert len(seg.sticks) == len(ref_sticks), (label, seg.sticks, ref_sticks)
            for (a, b), (ar, br) in zip(seg.sticks, ref_sticks):
                assert abs(a - ar) <= time_tol, (label, seg.sticks, ref_sticks)
                assert (abs(b - br) <= time_tol if math.isfinite(br) else math.isinf(b)), (
                    label, seg.sticks, ref_sticks)
                # released while the transient is a fifth of the static level: its share
                # of G at the release moves the release time
                released += math.isfinite(b) and abs(lag.transient(b)) > 0.2 * fr.static
            sticks += len(seg.sticks)
        contacts += len(seg.contacts)
    return contacts, transient_contacts, sticks, released


@pytest.mark.timeout(1800)  # a hang guard
@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("friction", [False, True])
def test_kelvin_voigt_under_the_actuator_matches_the_reference(seed, friction):
    """States to 1e-10 (times 1 + |x| + |v|; a case beyond it compared again with the
    reference at a step of 0.005), contacts and sticks counted exactly, switching times
    to 1e-9; contacts entered while the transient is above a tenth of its start and (with
    friction) sticks released while it is above a fifth of F_s both occur."""
    contacts, inside, sticks, released = _compare("kv", seed, friction, 1e-10, 1e-9)
    assert contacts > 20 and inside > 5, (contacts, inside)
    if friction:
        assert sticks > 10 and released >= 3, (sticks, released)


@pytest.mark.timeout(1800)  # a hang guard
@pytest.mark.parametrize("friction", [False, True])
def test_hertz_under_the_actuator_matches_the_reference(friction):
    """As above for the Hertz stop at its documented tolerance (TOL_HERTZ, times 1 + |x| +
    |v|), switching times to 1e-8."""
    contacts, inside, sticks, released = _compare("hertz", 0, friction, TOL_HERTZ, 1e-8)
    assert contacts > 20 and inside > 5, (contacts, inside)
    if friction:
        assert sticks > 10 and released >= 3, (sticks, released)

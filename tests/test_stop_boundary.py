"""Where the rigid design stops working on a compliant stop: the library function
(grazing_control/dynamics/orbits/stop_boundary.py) and ``grazing stop --boundary``
(docs/theory_contact.md section 22).

* the failing set of section 15 again (log10 k_c = 1.292396, k_c = 19.61), against an
  independent bisection on max |lambda| = 1 with the model built and its orbits shot
  here (not through the new function);
* a differential test over seeded random parameter sets (Delta d, c2 in the admissible
  set, r, friction): an independent grid of max |lambda| over 1e8 .. 1e1 (4 points a
  decade, orbits shot here from the previous one) agrees with the function: no crossing
  reported -> the grid stays on one side of 1 (below where the function says it holds);
  a crossing reported -> max |lambda| - 1 changes sign across it, and every sign change of
  the grid has a crossing between its points. ``STOP_BOUNDARY_SETS=N`` runs N sets
  (default 24);
* the command: its lines, --json, --rig, and each bad input one line naming the option,
  status 2.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from grazing_control.cli.commands import main
from grazing_control.dynamics.design.gains import admissible_c2, degenerate_c1
from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11
from grazing_control.dynamics.orbits.shooting import ShootingFailed, find_periodic
from grazing_control.dynamics.orbits.stop_boundary import stop_boundary
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError

SETS = int(os.environ.get("STOP_BOUNDARY_SETS", "24"))


def _model(dd, c2, r, friction, log10_k):
    """The rigid design on a Kelvin-Voigt stop with friction F_s = 1.2 F_f, built here."""
    p = OscillatorParams(delta_d=dd, r=r)
    gains = Gains(degenerate_c1(p, c2), c2)
    fr = Coulomb(friction, 1.2 * friction) if friction > 0.0 else None
    return CompliantOneDOF(p, gains, law=KelvinVoigt.from_restitution(10.0 ** log10_k, r),
                           friction=fr), OneDOF(p, gains)


def _grid(dd, c2, r, friction, values):
    """[(log10 k_c, max |lambda|, contacts, state)] from the stiff end, each orbit shot from the
    previous one's state (the first from the rigid orbit, else from X**), up to where shooting fails or
    the contact count changes (the orbit ends)."""
    _, rigid = _model(dd, c2, r, friction, 8.0)
    state = find_periodic(rigid, np.asarray(orbit_11(rigid.params, rigid.gains).pi2_deviation)).state
    out = []
    for lk in values:
        model, _ = _model(dd, c2, r, friction, lk)
        try:
            o = find_periodic(model, state)
        except (ShootingFailed, ValueError, ArithmeticError):
            if out:
                break
            try:    # friction near grazing: the orbit may be far from the rigid one's
                o = find_periodic(model, np.zeros(2))
            except (ShootingFailed, ValueError, ArithmeticError):
                break
        if out and len(o.impacts) != out[-1][2]:
            break
        state = o.state
        out.append((lk, float(np.max(np.abs(np.linalg.eigvals(o.monodromy)))), len(o.impacts),
                    o.state))
    return out


def test_the_failing_set_gives_the_documented_boundary_and_a_bisection_agrees():
    """Section 15: Delta d = -0.05, c2 = -1.5, r = 0.68, F_f = 0.01: one period doubling,
    the rigid design fails above it; log10 k_c = 1.292396 (k_c = 19.61); a bisection on
    max |lambda| - 1 (orbits shot here, 60 halvings) puts it at the same place to 1e-6."""
    sb = stop_boundary(OscillatorParams(delta_d=-0.05, r=0.68), -1.5, friction=0.01)
    assert [(c.type, c.fails) for c in sb.crossings] == [("period-doubling", "above")]
    found = sb.crossings[0].log10_stiffness
    assert found == pytest.approx(1.292396, abs=1e-6)
    assert sb.crossings[0].stiffness == pytest.approx(19.61, abs=5e-3)
    assert sb.lines(1e8, 1e1) == ["the rigid design fails for k_c > 19.61 (log10 k_c = "
                                  "1.292396): a multiplier crosses -1 (period doubling)"]
    assert sb.rho_max == pytest.approx(1.833, abs=1e-3) and sb.rho_max_at == 8.0
    # a stiffness placed on the branch takes the point on its own side of the crossing
    assert np.abs(sb.at(19.0).multipliers).max() < 1.0 < np.abs(sb.at(19.7).multipliers).max()
    assert sb.at(5.0) is None
    # the independent bisection: march the orbit down to 10^1.5, then halve [1, 2], each
    # orbit shot from the last one
    grid = _grid(-0.05, -1.5, 0.68, 0.01, [8.0, 6.0, 4.0, 3.0, 2.0, 1.5])
    assert len(grid) == 6 and grid[0][1] > 1.5
    state = grid[-1][3]

    def excess(lk):
        nonlocal state
        o = find_periodic(_model(-0.05, -1.5, 0.68, 0.01, lk)[0], state)
        state = o.state
        return float(np.max(np.abs(np.linalg.eigvals(o.monodromy)))) - 1.0

    lo, hi = 1.0, 2.0
    assert excess(lo) < 0.0 < excess(hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if excess(mid) > 0.0:
            hi = mid
        else:
            lo = mid
    assert 0.5 * (lo + hi) == pytest.approx(found, abs=1e-6)


def _random_set(rng):
    """Delta d log-uniform in [-5e-2, -1e-5], r in [0.5, 0.95], c2 uniform in an
    admissible interval (ends clipped to [-3, 1]), friction 0 or uniform in [0, 0.01]."""
    dd = -10.0 ** rng.uniform(-5.0, math.log10(5e-2))
    r = rng.uniform(0.5, 0.95)
    p = OscillatorParams(delta_d=dd, r=r)
    intervals = [(max(a, -3.0), min(b, 1.0)) for a, b in admissible_c2(p)]
    intervals = [(a, b) for a, b in intervals if b - a > 1e-3]
    a, b = intervals[rng.integers(len(intervals))]
    c2 = rng.uniform(a + 1e-4 * (b - a), b - 1e-4 * (b - a))
    friction = 0.0 if rng.random() < 0.4 else rng.uniform(0.0, 0.01)
    return dd, float(c2), r, friction


@pytest.mark.parametrize("seed", range(SETS))
def test_the_boundary_agrees_with_a_grid_of_the_largest_multiplier(seed):
    rng = np.random.default_rng(3100 + seed)
    dd, c2, r, friction = _random_set(rng)
    p = OscillatorParams(delta_d=dd, r=r)
    try:
        sb = stop_boundary(p, c2, friction=friction)
    except ParameterError as exc:    # c2 admissible at grazing, no rigid 1/1 orbit here
        assert str(exc).startswith(f"c2={c2!r}: the rigid design has no controlled 1/1 orbit")
        with pytest.raises(OrbitNotFound):
            orbit_11(p, Gains(degenerate_c1(p, c2), c2))
        return
    grid = _grid(dd, c2, r, friction, np.linspace(8.0, 1.0, 29))
    # compare where both have the orbit: down to the higher of the two ends
    end = max(sb.end, grid[-1][0]) if grid else 8.0
    grid = [g for g in grid if g[0] >= end]
    inside = [c for c in sb.crossings if c.log10_stiffness > end]
    where = (dd, c2, r, friction, [c.type for c in sb.crossings],
             [(g[0], round(g[1], 4)) for g in grid])
    sign = [g[1] > 1.0 for g in grid]
    changes = [(grid[i + 1][0], grid[i][0]) for i in range(len(grid) - 1)
               if sign[i] != sign[i + 1]]
    for soft, stiff in changes:      # every sign change of the grid is a reported crossing
        assert any(soft < c.log10_stiffness < stiff and c.fails is not None
                   for c in inside), where
    for c in inside:
        if c.fails is None:
            continue                 # another multiplier decides: no change of max |lambda|
        stiffer = min((g for g in grid if g[0] > c.log10_stiffness), key=lambda g: g[0])
        softer = max((g for g in grid if g[0] < c.log10_stiffness), key=lambda g: g[0],
                     default=None)
        if softer is None:
            continue                 # the grid's orbit ended before the crossing
        assert (stiffer[1] > 1.0) == (c.fails == "above") != (softer[1] > 1.0), where
    if not sb.branch.points:
        assert not grid, where       # neither finds the orbit at the stiff end
        return
    if not inside:
        rhos = [g[1] for g in grid]
        assert all(v < 1.0 for v in rhos) or all(v > 1.0 for v in rhos), where
        line = sb.lines(1e8, 1e1)[0]
        assert line.startswith("none" if max(rhos) < 1.0 else "no crossing"), (line, where)


# ---------------------------------------------------------------------- the command
def _cli(capsys, *argv):
    code = main(["stop", "--boundary", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_the_command_prints_the_boundary_and_its_json(capsys):
    code, out, _ = _cli(capsys, "--delta-d", "-0.05", "--c2", "-1.5", "--restitution",
                        "0.68", "--friction", "0.01")
    assert code == 0 and out == ("the rigid design fails for k_c > 19.61 (log10 k_c = "
                                 "1.292396): a multiplier crosses -1 (period doubling)\n")
    code, out, _ = _cli(capsys, "--delta-d", "-0.05", "--c2", "-1.5", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["crossings"] == [] and doc["branch"]["complete"]
    assert doc["rho_max"] == pytest.approx(0.824, abs=5e-4)      # section 15's table, 1e8
    assert doc["lines"][0].startswith("none in [1e1, 1e8]: the largest multiplier stays "
                                      "<= 0.824")


def test_the_command_takes_a_rig_with_a_stop(capsys):
    """The soft Kelvin-Voigt rig of the acceptance scenes: its stop read from the rig's
    stop section, its own k_c placed on the branch."""
    code, out, _ = _cli(capsys, "--rig", "config/rigs/acceptance_stop_soft.yaml", "--c2",
                        "-1", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["law"]["type"] == "kelvin_voigt"
    assert doc["rig_stiffness"]["stiffness"] == pytest.approx(1e3)
    assert "holds there" in doc["rig_stiffness"]["side"]


@pytest.mark.parametrize("argv, names", [
    (["--restitution", "0.1"], "--restitution=0.1"),
    (["--delta-d", "0.01"], "--delta-d=0.01"),
    (["--zeta", "-1"], "--zeta=-1"),
    (["--friction", "-0.1"], "--friction=-0.1"),
    (["--friction", "0.01", "--friction-static", "0.001"], "--friction-static=0.001"),
    (["--law", "kelvin_voigt", "--alpha", "1"], "--alpha"),
    (["--stiffness-range", "10", "10"], "--stiffness-range"),
    (["--periods", "5"], "--periods"),
    (["--rig", "config/rigs/acceptance_stop_soft.yaml", "--delta-d", "-0.01"], "--delta-d"),
    (["--rig", "config/rigs/no_such_rig.yaml"], "--rig"),
    (["--delta-d", "-0.022481557169788523", "--c2", "0.10189314866706134", "--restitution",
      "0.918"], "--c2=0.10189314866706134: the rigid design has no controlled 1/1 orbit"),
])
def test_bad_input_is_one_line_naming_the_option(capsys, argv, names):
    code, out, err = _cli(capsys, *argv)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert names in err, err

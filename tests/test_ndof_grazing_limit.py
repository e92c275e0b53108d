"""The n-DOF 1/1 orbit down to |Delta d| = 1e-10 against the 50-digit reference (issue 32).

The three measured defects of issue 32, each reproduced here:

* ``grazing orbit --model M --delta-d -1e-8`` failed ("Newton shooting did not converge")
  on a 2-mass chain with masses 1.5 / 0.8, wall and kick on the outer mass, for every
  |Delta d| <= 1.28e-8 (here: for every |Delta d| <= 2e-8), and on a 3-mass chain whose
  uncontrolled orbit lies on Delta d > 0, ``--delta-d 1e-10`` converged to the
  non-impacting orbit ("0 impacts per period");
* ``grazing continue --from -1e-3 --to -1e-9 --points 8`` returned 37 points on the 2-mass
  chain, 10 of them off by 1.2e-2 .. 4.4e-2 in v- (shooting accepted where the event
  search cannot resolve an impact), without a warning;
* the multiplier that goes to 0 like v- came out 2.25x off at Delta d = 2.8e-8 on the
  3-mass chain (LAPACK on a monodromy with an entry ~1/v-).

The yardstick is tests/reference_ndof.py (mpmath, physical coordinates, no code shared):
its Pi2 map, a fixed point of it by Newton's method from our orbit (the chord method with
the reference's own central-difference Jacobian), and its multipliers (mp.eig of that
Jacobian). The multipliers need the Jacobian to ~1e-30 where v- ~ 3e-8 (an error dJ moves
the smallest multiplier by ~dJ / v-^2), so that test runs the reference at 80 digits with a
1e-40 difference step; orbits and continuation points at its 50.
"""

import contextlib
import io
import json

import numpy as np
import pytest
from mpmath import mp, mpf

from grazing_control.cli.commands import main
from reference_ndof import DPS, load_reference
from test_cli_model_file import THREE_MASS

#: 2-mass chain of issue 32: wall - outer mass 1.5 (x0) - spring - inner mass 0.8 (x1) -
#: spring - ground; forced on the inner mass, wall and kick on the outer one. Its
#: uncontrolled orbit born at grazing lies on Delta d < 0, v- ~ 0.19 |Delta d|.
TWO = """\
M: [[1.5, 0.0], [0.0, 0.8]]
C: [[0.04, -0.02], [-0.02, 0.04]]
K: [[1.0, -1.0], [-1.0, 2.0]]
f: [0.0, 1.0]
omega: 0.5
i_w: 0
r: 0.68
i_a: 0
pi2_offset: 0.3
"""
#: The 3-mass chain of tests/test_cli_model_file.py: its uncontrolled orbit lies on Delta d > 0
#: (at omega 0.7 instead of 0.85 on Delta d < 0: the fixture's "three07").
THREE = THREE_MASS


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    out = {}
    for name, text in (("two", TWO), ("three", THREE),
                       ("three07", THREE.replace("omega: 0.85", "omega: 0.7"))):
        (folder / f"{name}.yaml").write_text(text, encoding="utf-8")
        out[name] = str(folder / f"{name}.yaml")
    return out


def grazing(*argv):
    """``grazing ARGV --json`` in-process: (status, JSON or None, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([*argv, "--json"])
        except SystemExit as exc:
            code = exc.code
    return code, (json.loads(out.getvalue()) if code == 0 else None), err.getvalue()


def reference_orbit(path, delta_d, z0, gains=None, step=None, jacobian=False):
    """(ref, z*, impacts, J at z* or None) of the reference's Pi2 map: the chord method
    from z0 with the reference's central-difference Jacobian at z0 (step 1e-35 at 50
    digits: the default 1e-20 would move the state by more than the penetration
    ~v-^2 ~ 1e-21 at Delta d = 1e-10), to 1e-30 relative."""
    ref = load_reference(path, delta_d=delta_d)
    z = [mpf(float(x)) for x in z0]
    m = len(z)
    diff = {"step": mpf(10) ** -35 if step is None else step}
    J = ref.jacobian(z, gains, **diff)
    for _ in range(8):
        fz, _imp = ref.pi2_map(z, gains)
        dz = mp.lu_solve(J - mp.eye(m), mp.matrix([z[i] - fz[i] for i in range(m)]))
        z = [z[i] + dz[i] for i in range(m)]
        if mp.norm(dz) <= mpf("1e-30") * mp.norm(mp.matrix(z)):
            break
    else:
        raise AssertionError("the reference's chord iteration did not converge")
    _fz, impacts = ref.pi2_map(z, gains)
    return ref, z, impacts, (ref.jacobian(z, gains, **diff) if jacobian else None)


def relative(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


# ------------------------------------------------------------------ orbit down to 1e-10
@pytest.mark.parametrize("name, delta_d", [("two", -1e-8), ("two", -1e-10), ("three", 1e-10),
                                           ("three07", -1e-8)])
def test_orbit_near_grazing_is_the_reference_orbit(files, name, delta_d):
    """Failed before (shooting: no convergence; +1e-10: the non-impacting orbit); now the
    orbit born at grazing, its Pi2 state and v- to 1e-12 of the reference's. three07:
    the 3-mass chain at omega 0.7, whose orbit lies on Delta d < 0 (shooting failed
    there from -1e-6 on)."""
    code, got, err = grazing("orbit", "--model", files[name], "--delta-d", repr(delta_d))
    assert code == 0, err
    assert got["branch"] == "grazing" and got["grazing_side"] == np.sign(delta_d)
    _ref, z, impacts, _ = reference_orbit(files[name], delta_d, got["section_pi2_deviation"])
    assert len(impacts) == 1                       # one impact per period, v- > 0
    v_ref = float(impacts[0][2])
    assert 0.0 < v_ref < 1e-8
    assert got["v_minus"] == pytest.approx(v_ref, rel=1e-12, abs=0)
    assert relative(got["section_pi2_deviation"], [float(x) for x in z]) < 1e-12


# ------------------------------------------------------------------ continue, few points
def test_continue_with_few_points_returns_converged_orbits(files):
    """8 values from -1e-3 to -1e-9: 8 points (not 37), those with |Delta d| <= 3.7e-7
    the reference's orbit to 1e-12 in state and v- (10 of the 37 were 1.2e-2 .. 4.4e-2
    off in v-, the first at -8.1e-7)."""
    code, got, err = grazing("continue", "--model", files["two"], "--from", "-1e-3",
                             "--to", "-1e-9", "--points", "8")
    assert code == 0, err
    pts = got["branch"]
    assert got["stopped"] == "end" and len(pts) == 8 and got["route"] == "impact phase"
    np.testing.assert_allclose([p["delta_d"] for p in pts],
                               -np.geomspace(1e-3, 1e-9, 8), rtol=1e-15)
    for p in pts[4:]:      # |Delta d| <= 3.7e-7, where shooting's points went wrong
        _ref, z, impacts, _ = reference_orbit(files["two"], p["delta_d"],
                                              p["section_pi2_deviation"])
        assert len(impacts) == 1 and p["impacts"] == 1, p["delta_d"]
        assert p["v_minus"] == pytest.approx(float(impacts[0][2]), rel=1e-12), p["delta_d"]
        assert relative(p["section_pi2_deviation"], [float(x) for x in z]) < 1e-12


# ------------------------------------------------------------------ multipliers
@pytest.mark.parametrize("delta_d, controlled", [(2.8e-8, False), (-1e-6, True)])
def test_multipliers_near_grazing_keep_their_digits(files, delta_d, controlled):
    """All six multipliers of the 3-mass chain to 11 digits of the reference's (the
    smallest, 1.5435e-8 at 2.8e-8, was 6.86e-9; controlled at -1e-6: design's mu)."""
    extra = ()
    gains = None
    if controlled:
        code, design, err = grazing("design", "--model", files["three"])
        assert code == 0, err
        gains = design["gains"]
        extra = ("--gains=" + ",".join(repr(g) for g in gains),)
    code, got, err = grazing("orbit", "--model", files["three"], "--delta-d", repr(delta_d),
                             *extra)
    assert code == 0, err
    with mp.workdps(80):
        ref, _z, impacts, J = reference_orbit(files["three"], delta_d,
                                              got["section_pi2_deviation"], gains,
                                              step=mpf(10) ** -40, jacobian=True)
        want = [complex(x) for x in ref.multipliers(J)]
    assert len(impacts) == 1
    lam = np.array([complex(a, b) for a, b in got["multipliers"]])
    for w in want:
        nearest = lam[np.argmin(np.abs(lam - w))]
        assert abs(nearest - w) <= 1e-11 * abs(w), (w, nearest)
    assert mp.dps == DPS


def test_continue_by_shooting_names_its_unresolved_points(files, monkeypatch):
    """Where the branch in the impact phase is not taken (here: switched off), shooting
    continues as before, and the points whose v- its event search cannot resolve are
    named in a warning instead of passing silently."""
    import grazing_control.dynamics.orbits.near_grazing as branch

    monkeypatch.setattr(branch, "_on_branch", lambda *args: (None, "switched off"))
    code, got, err = grazing("continue", "--model", files["two"], "--from", "-1e-3",
                             "--to", "-1e-9", "--points", "8")
    assert code == 0, err
    assert got["route"] == "shooting"
    assert got["warning"] and "shooting resolves the impact to a few digits only" in got["warning"]
    weak = [p for p in got["branch"] if p["v_minus"] < 1e-5 * 0.5 * got["d_star"]]
    assert weak and got["warning"].startswith(f"{len(weak)} of {len(got['branch'])} points")

"""Model-error bands for n > 1 (issue 32; docs/theory_mismatch.md section 5,
dynamics/design/mismatch.py): the band of Delta d next to grazing where the controlled
1/1 orbit of a mismatched n-DOF plant fails, with the nominal design's gains.

Yardsticks: the 1-DOF bands (the study's shooting route, dynamics/orbits/orbits.py) for
n = 1; for n = 2 brute force: the plant perturbed, its orbit's multipliers recomputed
from the fourth-order finite-difference Jacobian of the exact map (ModalMap, the certified
event-driven core), over seeded random parameters, errors and Delta d, and on both sides
of a band's end.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design import family as nd
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.design.mismatch import (instability_band, mismatched_model,
                                                      model_largest_multiplier)
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.dynamics.orbits import modal_branch
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.params import OscillatorParams, ParameterError

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
#: A short scan (the CLI's is -1e-2 .. -1e-14 at 4 per decade).
SCAN = dict(floor=1e-10, ceiling=1e-3, per_decade=2)


def _fd_multiplier(plant, k, dd, delay=0.0):
    """max |lambda| of the fourth-order finite-difference Jacobian of the exact map (the
    kick ``delay`` after Pi2) at the plant's 1/1 orbit, and the orbit's impacts per
    period. The step starts at 1e-2 v-^2 and shrinks tenfold until two successive
    estimates agree to 1e-7, else the most consistent pair is taken (a multiplier ~1e6
    needs ~1e-5 v-^2: the map's curvature grows with it; below, rounding takes over)."""
    bp = modal_branch.orbit_at(plant, k, dd, delay=delay)
    P = ModalMap(plant, k, delay)
    z = bp.pi2_state

    def estimate(h):
        jac = np.zeros((z.size, z.size))
        for j in range(z.size):
            e = np.zeros(z.size)
            e[j] = h

            def f(t):
                return P.step(z + t * e).state

            jac[:, j] = (8.0 * (f(1) - f(-1)) - (f(2) - f(-2))) / (12.0 * h)
        return float(np.max(np.abs(np.linalg.eigvals(jac))))

    values = [estimate(1e-2 * bp.v_minus ** 2)]
    for c in (1e-3, 1e-4, 1e-5, 1e-6):
        values.append(estimate(c * bp.v_minus ** 2))
        if abs(values[-1] - values[-2]) <= 1e-7 * values[-1]:
            break
    # the most consistent pair of successive steps (too large: curvature; too small: rounding)
    gaps = [abs(a - b) / b for a, b in zip(values, values[1:])]
    return values[1 + int(np.argmin(gaps))], len(P.step(z).impacts)


def _brute_force_error(m0, k, name, e, dd):
    """|brute force - band's multiplier| / multiplier for the plant ``name`` off by ``e``
    at ``dd``; None where that plant is invalid (e.g. r pushed above 1) or has no 1/1
    orbit."""
    try:
        plant = dataclasses.replace(mismatched_model(m0, name, e), delta_d=dd)
    except ParameterError:
        return None
    rho = model_largest_multiplier(plant, k)
    if not math.isfinite(rho):
        return None
    fd, impacts = _fd_multiplier(plant, k, dd)
    assert impacts == 1
    return abs(fd - rho) / rho


@pytest.mark.parametrize("one, many, error", [("zeta", "C", 0.05), ("omega", "omega", 1e-4),
                                              ("r", "r", 0.1), ("zeta", "C", -0.05)])
def test_n1_bands_are_the_1dof_bands(one, many, error):
    """n = 1 (the study as a model file, the study's design c2 = -1): an error in C is
    one in zeta. The band end is the 1-DOF one to 1e-10 (measured: equal floats,
    -7.444e-8 for zeta +5 %, -4.711e-7 for omega +1e-4, none for r and zeta -5 %) and
    the scan's multipliers agree to 1e-9 relative (measured <= 5.4e-10: shooting against
    the explicit branch)."""
    m = load_model(MODELS / "study_1dof.yaml")
    base = OscillatorParams(zeta=0.5 * m.C[0, 0], r=m.r, omega=m.omega, pi2_offset=m.pi2_offset)
    g = Gains(degenerate_c1(base, -1.0), -1.0)
    b1 = instability_band(base, g, one, error, **SCAN)
    bn = instability_band(m, [g.c1, g.c2], many, error, **SCAN)
    assert abs(bn.end - b1.end) <= 1e-10 * abs(b1.end)
    assert (b1.end < 0.0) == (error > 0.0 and one != "r")
    for (d1, r1), (dn, rn) in zip(b1.multipliers, bn.multipliers):
        assert d1 == dn
        assert math.isinf(r1) == math.isinf(rn)
        if math.isfinite(r1):
            assert abs(rn - r1) <= 1e-9 * r1


def test_chain_multipliers_against_brute_force():
    """Chain (config/models/two_mass_chain.yaml), design mu = 0.2, 12 seeded random
    (parameter, error in +-1e-3 .. 3e-2, Delta d in -1e-7 .. -1e-4): the largest
    multiplier of the mismatched plant's orbit equals that of the finite-difference
    Jacobian of the exact map to 1e-5 relative (measured <= 1.9e-6), the orbit is a
    fixed point of the map with one impact."""
    m0 = load_model(MODELS / "two_mass_chain.yaml")
    k = nd.gain_family(m0, 0.2)
    rng = np.random.default_rng(3203)
    names = ["M", "C", "K", "M[0,0]", "M[1,1]", "C[0,1]", "K[0,0]", "K[0,1]", "K[1,1]", "r",
             "omega"]
    checked, worst = 0, 0.0
    for _ in range(12):
        name = names[rng.integers(len(names))]
        e = float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-3.0, -1.5))
        dd = -10 ** rng.uniform(-7.0, -4.0)
        err = _brute_force_error(m0, k, name, e, dd)
        if err is not None:
            worst, checked = max(worst, err), checked + 1
    assert checked >= 8
    assert worst < 1e-5


def test_random_3dof_multipliers_against_brute_force():
    """Seeded random 3-DOF models (full M, C, K; tests/test_family.py's generator),
    their family gain k(mu = 0), a random parameter (a whole matrix, an entry pair, r,
    omega) off by +-1e-3 .. 1e-2 at Delta d in -1e-6 .. -1e-4: the band's multiplier
    equals the finite-difference Jacobian of the exact map to 1e-5 (measured <= 6.2e-8
    over the 9 cases with an orbit)."""
    from test_family import _random_model

    rng = np.random.default_rng(3204)
    checked, worst = 0, 0.0
    for seed in range(40, 52):
        m0 = _random_model(seed, 3)
        try:
            k = nd.gain_family(m0, 0.0)
        except ParameterError:
            continue
        name = str(rng.choice(["M", "C", "K", "M[1,1]", "K[0,2]", "C[2,1]", "r", "omega"]))
        e = float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-3.0, -2.0))
        dd = -10 ** rng.uniform(-6.0, -4.0)
        err = _brute_force_error(m0, k, name, e, dd)
        if err is not None:
            worst, checked = max(worst, err), checked + 1
    assert checked >= 5
    assert worst < 1e-5


def test_delayed_design_multipliers_against_brute_force():
    """The delay-aware design k(mu = 0; delay 4) (docs/theory_ndof.md section 14) on the
    chain, plant with M[0,0] +0.5 % and K -0.3 % at Delta d = -1e-5: the band's multiplier
    equals the finite-difference Jacobian of the exact delayed map to 1e-5 (measured
    3.9e-9: 5.828 and 1.147; the same gains taken as undelayed give 4.3e5)."""
    m0 = load_model(MODELS / "two_mass_chain.yaml")
    k = nd.gain_family(m0, 0.0, 4.0)
    for name, e in (("M[0,0]", 0.005), ("K", -0.003)):
        plant = dataclasses.replace(mismatched_model(m0, name, e), delta_d=-1e-5)
        rho = model_largest_multiplier(plant, k, 4.0)
        fd, impacts = _fd_multiplier(plant, k, -1e-5, 4.0)
        assert impacts == 1 and math.isfinite(rho)
        assert abs(fd - rho) < 1e-5 * rho
        assert model_largest_multiplier(plant, k) != pytest.approx(rho, rel=1e-3)


def test_chain_band_end_against_brute_force_and_the_square_law():
    """Chain, mu = 0.2, C off by -1 %: a band opens (end -6.22e-6); the brute-force
    multiplier is >= 1 just inside it (0.97 end) and < 1 just outside (1.03 end); halving
    the error divides the end by ~4 (e^2 law, docs/theory_mismatch.md (M1); measured
    4.034, and 4.018 for the next halving: K = end/e^2 = -0.0622, -0.0617, -0.0614), and
    C +1 % opens none."""
    m0 = load_model(MODELS / "two_mass_chain.yaml")
    k = nd.gain_family(m0, 0.2)
    band = instability_band(m0, k, "C", -0.01, **SCAN)
    assert -1e-5 < band.end < -1e-6
    plant = mismatched_model(m0, "C", -0.01)
    inside = _fd_multiplier(dataclasses.replace(plant, delta_d=0.97 * band.end), k, 0.97 * band.end)[0]
    outside = _fd_multiplier(dataclasses.replace(plant, delta_d=1.03 * band.end), k, 1.03 * band.end)[0]
    assert inside >= 1.0 > outside
    half = instability_band(m0, k, "C", -0.005, **SCAN)
    assert 3.8 < band.end / half.end < 4.2
    assert instability_band(m0, k, "C", 0.01, **SCAN).end == 0.0


def test_mismatched_model_changes_one_parameter_and_refuses_bad_names():
    m0 = load_model(MODELS / "two_mass_chain.yaml")
    p = mismatched_model(m0, "K[0,1]", 0.1)
    assert p.K[0, 1] == p.K[1, 0] == m0.K[0, 1] * 1.1 and p.K[0, 0] == m0.K[0, 0]
    assert np.array_equal(mismatched_model(m0, "M", -0.5).M, 0.5 * m0.M)
    assert mismatched_model(m0, "r", 0.1).r == m0.r * 1.1
    with pytest.raises(ParameterError, match=r"name='K\[2,0\]' is invalid: valid values"):
        mismatched_model(m0, "K[2,0]", 0.1)
    with pytest.raises(ParameterError, match="name='zeta' is invalid"):
        mismatched_model(m0, "zeta", 0.1)
    with pytest.raises(ParameterError, match="error=-1.0 is invalid"):
        mismatched_model(m0, "M", -1.0)
    with pytest.raises(ParameterError, match="gains=.* is invalid"):
        instability_band(m0, [1.0, 2.0], "M", 0.01)     # not every point a failure
    with pytest.raises(ParameterError, match="delay=.* is invalid"):
        instability_band(m0, np.zeros(4), "M", 0.01, delay=-1.0)


def test_grazing_robustness_model_of_a_model_file(tmp_path, capsys, monkeypatch):
    """`grazing robustness model --model FILE --mu MU --parameter ...`: the bands equal the
    core's (instability_band over the exact n-DOF branch), with k = end/e^2 and the error
    tolerated at the file's delta_d by the e^2 law; chart and JSON written. Reduced error
    sizes; bad input: one line, exit status 2."""
    import json

    import yaml

    from grazing_control.cli import main
    from grazing_control.studies.robustness import model as study

    monkeypatch.setattr(study, "NDOF_ERRORS", {"C": (0.01,), "r": (0.1,), "M": (1e-3,)})
    data = yaml.safe_load((MODELS / "two_mass_chain.yaml").read_text())
    data["delta_d"] = -1e-6
    path = tmp_path / "chain.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "m"
    assert main(["robustness", "model", "--model", str(path), "--mu", "0.2", "--parameter", "C",
                 "--parameter", "r", "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert (out / "model_error_bands.png").stat().st_size > 0
    (design,) = d["designs"]
    rows = {(r["parameter"], r["error"]): r for r in design["bands"]}
    assert set(rows) == {("C", 0.01), ("C", -0.01), ("r", 0.1), ("r", -0.1)}
    m0 = load_model(path)
    k = nd.gain_family(m0, 0.2)
    end = instability_band(m0, k, "C", -0.01).end
    assert design["gains"] == pytest.approx(list(k), rel=1e-15)
    assert rows[("C", -0.01)]["end"] == end < 0.0
    assert rows[("C", 0.01)]["end"] == 0.0 and rows[("r", 0.1)]["end"] == rows[("r", -0.1)]["end"] == 0.0
    assert rows[("C", -0.01)]["tolerated"] == pytest.approx(0.01 * math.sqrt(1e-6 / -end))
    assert rows[("C", 0.01)]["tolerated"] is None
    for argv, message in [(["--mu", "0.2", "--parameter", "K[3,0]"], "name='K[3,0]' is invalid"),
                          ([], "--model needs --mu MU"),
                          (["--mu", "0.2", "--c2", "-1"], "--c2 is a 1-DOF design")]:
        assert main(["robustness", "model", "--model", str(path), "--out", str(out)] + argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0]

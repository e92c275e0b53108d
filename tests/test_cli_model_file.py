"""`grazing design|orbit|continue|simulate|sweep|figures --model FILE`: the model commands on
a model file (cli/model_file.py, cli/design.py, cli/orbits.py, cli/diagrams.py).

Contract (docs/ndof_commands.md):

* the n = 1 model file (config/models/study_1dof.yaml) reproduces the 1-DOF commands'
  numbers to 1e-12 (issue 32's acceptance): design (c1 for a given c2 is the family's x0
  gain for the same v0 gain, the limit multipliers), orbit (multipliers, v-, impact
  phase, Pi2 point), continue (each point's multipliers and v- against the 1-DOF orbit
  at its Delta d) and simulate (the Pi2 samples and impacts), uncontrolled and
  controlled;
* on the 2-mass example and on a 3-mass chain written here, each command runs and its
  numbers hold up against independent checks: the design's gains put the wall row of
  N = Phi_a K Phi_b at mu w^T, the orbit is a fixed point of the period map with
  one impact, its multipliers are those of a finite-difference Jacobian, the controlled
  simulation converges to the controlled orbit;
* user errors are one line ``grazing: error: ...`` on stderr, status 2, nothing on
  stdout: a 1-DOF option with --model, an n-DOF option without it, a missing or
  malformed model file, gains of the wrong length, an unknown coordinate name.

Commands run in-process (``main(argv)``) so that the numpy/scipy import is paid once.
"""

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from grazing_control.cli.commands import main
from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.oscillator.ndof import load_model
from grazing_control.dynamics.design.family import gain_family
from grazing_control.dynamics.orbits.near_grazing import grazing_side, pi1_factors, with_delta_d

ROOT = Path(__file__).resolve().parents[1]
ONE = str(ROOT / "config" / "models" / "study_1dof.yaml")
TWO = str(ROOT / "config" / "models" / "two_mass_chain.yaml")

#: A 3-mass chain of our own (wall - m0 - m1 - m2 - ground), forced and kicked on m2.
THREE_MASS = """\
# 3-mass chain for the tests: wall -- x0 -- x1 -- x2 -- ground, unit masses and springs,
# damping C = 0.02 K + 0.01 I, forcing and kick on the inner mass x2.
M: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
C: [[0.05, -0.02, 0.0], [-0.02, 0.05, -0.02], [0.0, -0.02, 0.05]]
K: [[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 2.0]]
f: [0.0, 0.0, 1.0]
omega: 0.85
i_w: 0
r: 0.7
i_a: 2
"""


def run(_capsys, *argv):
    """(status, stdout, stderr) of ``grazing ARGV`` (argparse's errors exit: caught)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as exc:
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def run_json(_capsys, *argv):
    code, out, err = run(None, *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def lam(pairs):
    return np.array([complex(a, b) for a, b in pairs])


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    path = tmp_path_factory.mktemp("models") / "three_mass_chain.yaml"
    path.write_text(THREE_MASS, encoding="utf-8")
    return str(path)


@pytest.fixture(scope="module")
def design3(three):
    """``design --model THREE --json`` (run once: the admissible set costs seconds)."""
    return run_json(None, "design", "--model", three)


# ------------------------------------------------------------------ n = 1 is the 1-DOF
def test_design_of_the_n1_file_is_the_1dof_design(capsys):
    ref = run_json(capsys, "design", "--c2", "-0.5")
    got = run_json(capsys, "design", "--model", ONE, "--free-gain", "v0=-0.5")
    assert got["n"] == 1 and got["coordinates"] == ["x0", "v0"]
    assert got["gains"][1] == pytest.approx(-0.5, abs=1e-15)
    assert got["gains"][0] == pytest.approx(ref["c1"], rel=1e-12, abs=1e-12)
    a = sorted(lam(ref["multipliers_limit"]), key=lambda z: (-abs(z), z.imag))
    b = sorted(lam(got["multipliers_limit"]), key=lambda z: (-abs(z), z.imag))
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
    assert got["gamma1"] == pytest.approx(ref["gamma1"], rel=1e-12)
    assert got["admissible"] == ref["admissible"]


@pytest.mark.parametrize("controlled", [False, True])
def test_orbit_of_the_n1_file_is_the_1dof_orbit(capsys, controlled):
    """The same gains on both routes (the design's c1 is checked above): the orbit."""
    gains, ndof = (), ()
    if controlled:
        c1 = run_json(capsys, "design", "--c2", "-1")["c1"]
        gains, ndof = ("--c1", repr(c1), "--c2", "-1"), (f"--gains={c1!r},-1",)
    ref = run_json(capsys, "orbit", "--delta-d", "-1e-6", *gains)
    got = run_json(capsys, "orbit", "--model", ONE, "--delta-d", "-1e-6", *ndof)
    np.testing.assert_allclose(lam(got["multipliers"]), lam(ref["multipliers"]),
                               rtol=1e-12, atol=1e-12)
    assert got["v_minus"] == pytest.approx(ref["v_minus"], rel=1e-10)
    assert got["impact_phase"] == pytest.approx(ref["impact_phase"], abs=1e-12)
    np.testing.assert_allclose(got["section_pi2"], ref["section_pi2"], rtol=0, atol=1e-12)
    assert got["stable"] == ref["stable"] and got["branch"] == ref["branch"] == "grazing"


@pytest.mark.parametrize("c2, to", [(None, "-1e-7"), (-0.5, "-1e-6")])
def test_continue_of_the_n1_file_is_the_1dof_branch(capsys, c2, to):
    """Each point of ``continue --model ONE`` against the 1-DOF orbit at its Delta d.
    Measured: uncontrolled to -1e-7 (the largest multiplier grows to 255), multipliers
    1.6e-12 absolute at most (at -1.02), v- 3.3e-13 relative; with the design's gains
    (c2 = -0.5) to -1e-6, multipliers 2.5e-13, v- 3.3e-13. There the deviation from the
    grazing orbit is ~ sqrt|Delta d| and both routes carry a few eps of the physical
    state (docs/ndof_commands.md, "Near grazing"): at -1e-7, 1.9e-12 and 5.3e-12."""
    gains, vector = (), ()
    if c2 is not None:
        c1 = run_json(capsys, "design", "--c2", repr(c2))["c1"]
        gains, vector = ("--c1", repr(c1), "--c2", repr(c2)), (f"--gains={c1!r},{c2!r}",)
    got = run_json(capsys, "continue", "--model", ONE, "--from", "-1e-3", "--to", to,
                   "--points", "5", *vector)
    assert got["route"] == "impact phase" and len(got["branch"]) == 5
    for point in got["branch"]:
        ref = run_json(capsys, "orbit", "--delta-d", repr(point["delta_d"]), *gains)
        a = sorted(lam(point["multipliers"]), key=lambda z: (-abs(z), z.imag))
        b = sorted(lam(ref["multipliers"]), key=lambda z: (-abs(z), z.imag))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)    # as the orbit's, above
        assert point["v_minus"] == pytest.approx(ref["v_minus"], rel=1e-12)
        assert point["stable"] == ref["stable"]


@pytest.mark.parametrize("controlled", [False, True])
def test_simulate_of_the_n1_file_is_the_1dof_simulation(capsys, controlled):
    """The Pi2 samples of ``simulate --model ONE`` against the 1-DOF simulation: to 1e-12
    over 30 periods with control (measured 2e-15), over the first 10 of the uncontrolled
    irregular motion (2e-14 there; it then separates as the motion does, 4e-11 at 30)."""
    gains, vector = (), ()
    if controlled:
        c1 = run_json(capsys, "design", "--c2", "-1")["c1"]
        gains, vector = ("--c1", repr(c1), "--c2", "-1"), (f"--gains={c1!r},-1",)
    ref = run_json(capsys, "simulate", "--delta-d", "-5e-6", "--periods", "30", *gains)
    got = run_json(capsys, "simulate", "--model", ONE, "--delta-d", "-5e-6", "--periods", "30",
                   *vector)
    kept = 30 if controlled else 10
    np.testing.assert_allclose(got["pi2"][:kept], ref["pi2"][:kept], rtol=0, atol=1e-12)
    assert got["impacts_per_period"] == ref["impacts_per_period"]
    assert sum(ref["impacts_per_period"]) > 0


# ------------------------------------------------------------------ the 2-mass example
def test_design_gains_are_on_the_family(capsys):
    got = run_json(capsys, "design", "--model", TWO, "--mu", "0.2")
    model = load_model(TWO)
    N = pi1_factors(model, got["gains"])[0]          # independent: Phi_a (I + b k^T) Phi_b
    w = np.eye(4)[model.i_w]
    np.testing.assert_allclose(w @ N, 0.2 * w, atol=1e-10)
    k0, dk = np.array(got["family"]["k_at_mu_0"]), np.array(got["family"]["dk_dmu"])
    np.testing.assert_allclose(k0 + 0.2 * dk, got["gains"], rtol=1e-10, atol=1e-12)
    # the other eigenvalues of N are the transmission zeros, whatever mu
    eig = np.linalg.eigvals(N)
    zeros = lam(got["transmission_zeros"])
    for z in zeros:
        assert np.min(np.abs(eig - z)) < 1e-8
    assert got["transmission_zeros_max_modulus"] == pytest.approx(np.max(np.abs(zeros)))


def test_design_chooses_an_admissible_mu_on_three_masses(design3):
    d = design3
    assert d["n"] == 3 and len(d["gains"]) == 6 and len(d["transmission_zeros"]) == 5
    assert d["admissible"] and d["admissible_mu"]
    assert any(lo < d["mu"] < hi for lo, hi in d["admissible_mu"])
    assert d["conditions"] == {"limit_stable": True, "exists_impacting": True,
                               "free_stable": True}


def test_design_out_names_its_model_file_from_anywhere(capsys, tmp_path, monkeypatch):
    """A relative --model is written as the absolute path of the file it names: the gain
    file is read by `grazing run --controller-params` from any folder (written as given,
    a scene run elsewhere failed with "model_file='<there>/two_mass_chain.yaml' is
    invalid: ... no such file")."""
    import yaml

    monkeypatch.chdir(Path(TWO).parent)
    out = tmp_path / "gains.yaml"
    code, _text, err = run(capsys, "design", "--model", Path(TWO).name, "--mu", "-0.22",
                           "--out", str(out))
    assert code == 0, err
    params = next(iter(yaml.safe_load(out.read_text()).values()))["ros__parameters"]
    assert params["model_file"] == TWO


def test_design_report_and_out_file(capsys, tmp_path):
    """The human report names every design quantity; --out writes the family's gains
    (and only for an admissible mu: nothing is written for mu = 5)."""
    import yaml

    out = tmp_path / "gains.yaml"
    code, text, err = run(capsys, "design", "--model", ONE, "--mu", "0.1", "--out", str(out))
    assert code == 0, err
    for word in ("transmission zeros", "admissible mu", "gains k", "lambda0", "gamma1",
                 "this mu            : admissible", f"gains written to {out}"):
        assert word in text
    params = next(iter(yaml.safe_load(out.read_text()).values()))["ros__parameters"]
    np.testing.assert_allclose(params["gains"], gain_family(load_model(ONE), 0.1), rtol=1e-15)
    code, o, err = run(capsys, "design", "--model", ONE, "--mu", "5", "--out",
                       str(tmp_path / "bad.yaml"))
    assert code == 2 and o == "" and "not admissible" in err and err.count("\n") == 1
    assert not (tmp_path / "bad.yaml").exists()


def test_orbit_report(capsys, three):
    code, out, err = run(capsys, "orbit", "--model", three, "--delta-d", "1e-5")
    assert code == 0, err
    assert "1/1 orbit" in out and "multipliers" in out and "born at grazing" in out


# ------------------------------------------------------------------ a 3-DOF model
def test_orbit_on_three_masses_is_a_fixed_point_with_fd_multipliers(capsys, three, design3):
    """Uncontrolled at |Delta d| = 1e-3 (G(1) > 0 here: the orbit born at grazing is on
    Delta d > 0, and its multiplier ~ 1/Delta d makes a finite difference meaningless
    much closer), controlled at -1e-5 (bounded multipliers)."""
    model3 = load_model(three)
    mu = design3["mu"]
    for size, extra in ((1e-3, ()), (1e-5, ("--mu", str(mu)))):
        k = None if not extra else gain_family(model3, mu)
        side = grazing_side(model3, k)
        dd = f"{side * size:g}"
        got = run_json(capsys, "orbit", "--model", three, "--delta-d", dd, *extra)
        assert got["branch"] == "grazing" and got["grazing_side"] == side
        model = with_delta_d(model3, float(dd))
        pmap = ModalMap(model, k)
        z = np.array(got["section_pi2_deviation"])
        step = pmap.step(z)
        assert len(step.impacts) == 1
        np.testing.assert_allclose(step.state, z, rtol=0, atol=1e-11)
        # multipliers against a central-difference Jacobian of the period map
        h = 1e-6 * float(np.max(np.abs(z)))
        J = np.column_stack([(pmap.step(z + h * e).state - pmap.step(z - h * e).state) / (2 * h)
                             for e in np.eye(6)])
        fd = np.sort_complex(np.linalg.eigvals(J))
        mult = np.sort_complex(lam(got["multipliers"]))
        np.testing.assert_allclose(mult, fd, atol=1e-5 * max(1.0, np.max(np.abs(fd))))


def test_continue_on_three_masses_reaches_towards_grazing(capsys, three, design3):
    mu = design3["mu"]
    got = run_json(capsys, "continue", "--model", three, "--from", "-1e-4", "--to", "-1e-9",
                   "--points", "6", "--mu", str(mu))
    assert got["start_branch"] == "grazing"
    dd = [p["delta_d"] for p in got["branch"]]
    assert len(dd) >= 2 and dd[0] == pytest.approx(-1e-4)
    assert all(p["impacts"] == 1 for p in got["branch"])
    v = [p["v_minus"] for p in got["branch"]]
    assert v[-1] < v[0]                    # impact velocity falls towards grazing
    biggest = max(np.max(np.abs(lam(p["multipliers"]))) for p in got["branch"])
    limit = np.max(np.abs(lam(got["multipliers_limit"])))
    assert biggest < 10 * max(1.0, limit)  # on the family: bounded


def test_simulate_with_control_converges_on_three_masses(capsys, three, design3):
    """From the grazing point with the controller on: the controlled 1/1 orbit. Without
    it the motion leaves grazing for a large 1/1 orbit (v- ~ 3.8) within tens of
    periods, an attractor the local controller does not reach back from."""
    d = design3
    assert d["transmission_zeros_max_modulus"] < 1
    got = run_json(capsys, "simulate", "--model", three, "--delta-d", "-1e-5",
                   "--periods", "150", "--control-after", "0", "--mu", str(d["mu"]))
    assert len(got["pi2"]) == 150 and len(got["impacts_per_period"]) == 150
    assert got["impacts_per_period"][-20:] == [1] * 20
    assert got["distance_to_orbit"] < 1e-10
    free = run_json(capsys, "simulate", "--model", three, "--delta-d", "-1e-5",
                    "--periods", "60")
    assert np.max(np.abs(free["final_deviation"])) > 1.0
    assert "distance_to_orbit" not in free


def test_sweep_with_model_writes_npz_and_png(capsys, tmp_path, three):
    got = run_json(capsys, "sweep", "--model", three, "--grid", "delta_d=-1e-4:0:3",
                   "--periods", "20", "--workers", "1", "--out", str(tmp_path / "s.npz"))
    data = np.load(got["npz"])
    assert data["samples"].shape == (3, 10, 6)
    assert Path(got["png"]).stat().st_size > 1000
    assert got["points"] == 3 and got["failed"] == 0


def test_design_with_delay_is_the_delayed_family_and_the_1dof_delayed_c1(capsys, tmp_path):
    """`design --model M --delay D` prints the delayed design (docs/theory_ndof.md §14):
    n = 1, --free-gain v0=0.5 at delay 2 gives the 1-DOF `design --c2 0.5 --delay 2`'s c1
    to 1e-12; the chain's gains are family.gain_family(m, mu, 4) and the written
    file carries actuation_delay."""
    one = run_json(capsys, "design", "--model", ONE, "--delay", "2", "--free-gain", "v0=0.5")
    m1 = load_model(ONE)
    ref = run_json(capsys, "design", "--c2", "0.5", "--delay", "2", "--omega", repr(m1.omega),
                   "--r", repr(m1.r), "--zeta", "0.01", "--delta-d", repr(m1.delta_d))
    assert one["delay"] == 2.0
    assert abs(one["gains"][0] - ref["c1"]) <= 1e-12 * abs(ref["c1"])
    out = tmp_path / "k.yaml"
    two = run_json(capsys, "design", "--model", TWO, "--delay", "4", "--mu", "0", "--out", str(out))
    assert two["gains"] == gain_family(load_model(TWO), 0.0, 4.0).tolist()
    assert two["admissible"] and max(abs(complex(*z)) for z in two["multipliers_limit"]) < 1
    assert "actuation_delay: 4.0" in out.read_text()
    code, text, _err = run(capsys, "design", "--model", TWO, "--delay", "4", "--mu", "0")
    assert code in (0, None) and "actuation delay    = 4" in text


def test_design_with_a_pulse_is_the_pulse_family_and_the_1dof_p1_c1(capsys, tmp_path):
    """`design --model M --delay D --pulse-width W [--actuator-bandwidth B
    --actuator-latency L]` (docs/theory_ndof.md §15): n = 1 gives the 1-DOF `design
    --c2 0.5 --delay 2 --pulse-width 1`'s c1 (P1) to 1e-12; the chain's gains are
    family.gain_family with the Actuation, written with the pulse's entries; an
    actuator without a pulse width is refused naming pulse_width."""
    from grazing_control.dynamics.design.family import Actuation

    one = run_json(capsys, "design", "--model", ONE, "--delay", "2", "--pulse-width", "1",
                   "--free-gain", "v0=0.5")
    m1 = load_model(ONE)
    ref = run_json(capsys, "design", "--c2", "0.5", "--delay", "2", "--pulse-width", "1",
                   "--omega", repr(m1.omega), "--r", repr(m1.r), "--zeta", "0.01",
                   "--delta-d", repr(m1.delta_d))
    assert one["delay"] == 2.0 and one["pulse"]["pulse_width"] == 1.0
    assert abs(one["gains"][0] - ref["c1"]) <= 1e-12 * abs(ref["c1"])
    out = tmp_path / "k.yaml"
    two = run_json(capsys, "design", "--model", TWO, "--delay", "4", "--mu", "0",
                   "--pulse-width", "1", "--actuator-bandwidth", "5", "--actuator-latency",
                   "0.1", "--out", str(out))
    assert two["gains"] == gain_family(load_model(TWO), 0.0,
                                       Actuation(4.0, 1.0, 0.2, 0.1)).tolist()
    assert "pulse_width: 1.0" in out.read_text()
    code, _text, err = run(capsys, "design", "--model", TWO, "--delay", "4",
                           "--actuator-bandwidth", "5")
    assert code == 2 and "pulse_width=0.0 is invalid with an actuator" in err


# ------------------------------------------------------------------ the delayed kick
def _delayed(which, three):
    """(model file, delay, mu) of an admissible delayed design: the chain at delay 0.5
    (admissible mu (-0.408, 0.420)), the 3-mass chain at delay 2 ((-0.746, 0.497); none
    at 0.2 .. 1)."""
    return (TWO, "0.5", "0.2") if which == "two" else (three, "2", "-0.12")


@pytest.mark.parametrize("which", ["two", "three"])
def test_orbit_with_delay_down_to_1e_10_is_the_delayed_map_s_orbit(capsys, three, which):
    """``orbit --model M --delay D --mu MU`` (refused before, issue 32) on a 2- and a 3-mass
    chain down to Delta d = -1e-10: the delayed family's gains (design --delay's), the
    branch in the impact phase, the Pi2 state a fixed point of the exact delayed map
    (ModalMap(model, k, D): flow D, kick, flow T - D) with its one impact at the same v-;
    the multipliers tend to design --delay's limit (within 20 sqrt|Delta d|)."""
    path, delay, mu = _delayed(which, three)
    model0 = load_model(path)
    k = gain_family(model0, float(mu), float(delay))
    limit = lam(run_json(capsys, "design", "--model", path, "--delay", delay, "--mu",
                         mu)["multipliers_limit"])
    for dd in ("-1e-6", "-1e-8", "-1e-10"):
        got = run_json(capsys, "orbit", "--model", path, "--delta-d", dd, "--mu", mu,
                       "--delay", delay)
        assert got["actuation_delay"] == float(delay) and got["gains"] == k.tolist()
        assert got["guess"].startswith("impact phase") and got["branch"] == "grazing"
        z = np.array(got["section_pi2_deviation"])
        step = ModalMap(with_delta_d(model0, float(dd)), k, float(delay)).step(z)
        assert len(step.impacts) == 1 and step.impacts[0].dt > float(delay)
        assert abs(step.impacts[0].v_minus - got["v_minus"]) <= 1e-6 * got["v_minus"]
        np.testing.assert_allclose(step.state, z, rtol=0, atol=1e-13)
        mult = lam(got["multipliers"])
        cost = np.abs(np.subtract.outer(mult, limit))
        assert max(cost[i].min() for i in range(len(mult))) <= 20 * abs(float(dd)) ** 0.5


def test_continue_with_delay_and_few_points_gives_the_points_of_many(capsys):
    """``continue --delay 0.5 --points 8`` from -1e-3 to -1e-10 on the chain: 8 converged
    points (one impact each, stopped at the end), the same v- (1e-12) and multipliers
    (1e-12) as ``--points 190`` at the common values (every 27th: 7 decades); the
    issue's defect was shooting with few points 1e-2 off near grazing."""
    span = ("continue", "--model", TWO, "--from", "-1e-3", "--to", "-1e-10", "--mu", "0.2",
            "--delay", "0.5")
    few = run_json(capsys, *span, "--points", "8")
    many = run_json(capsys, *span, "--points", "190")
    assert few["route"] == "impact phase" and few["stopped"] == "end"
    assert len(few["branch"]) == 8 and len(many["branch"]) == 190
    assert all(p["impacts"] == 1 for p in few["branch"])
    for j, p in enumerate(few["branch"]):
        q = many["branch"][27 * j]
        assert q["delta_d"] == pytest.approx(p["delta_d"], rel=1e-14)
        assert q["v_minus"] == pytest.approx(p["v_minus"], rel=1e-12)
        np.testing.assert_allclose(lam(q["multipliers"]), lam(p["multipliers"]), rtol=0,
                                   atol=1e-12)
    assert few["actuation_delay"] == 0.5 and few["multipliers_limit"] is not None


def test_simulate_with_delay_steps_the_delayed_map_to_the_delayed_orbit(capsys):
    """``simulate --delay 0.5 --mu 0.2`` on the chain: each sample is the exact delayed
    map of the one before (1e-13), one impact per period, and the end is on the delayed
    orbit (1e-12)."""
    got = run_json(capsys, "simulate", "--model", TWO, "--delta-d", "-1e-5", "--periods",
                   "200", "--mu", "0.2", "--delay", "0.5")
    model = with_delta_d(load_model(TWO), -1e-5)
    pmap = ModalMap(model, np.array(got["gains"]), 0.5)
    z = np.array(got["pi2_deviation"])
    for j in (0, 1, 100):
        np.testing.assert_allclose(pmap.step(z[j]).state, z[j + 1], rtol=0, atol=1e-13)
    assert got["impacts_per_period"][-20:] == [1] * 20
    assert got["distance_to_orbit"] < 1e-12 and got["actuation_delay"] == 0.5


def test_a_gain_file_of_design_out_gives_its_gains_and_its_delay(capsys, tmp_path, three):
    """``--gains FILE`` (issue 32: refused as "expected comma-separated finite numbers"):
    the file of ``design --model M --delay 0.5 --mu 0.2 --out FILE`` gives orbit the
    same numbers as ``--mu 0.2 --delay 0.5`` (bit for bit), and sweep its delayed kick
    (refused there before; issue 32); a file of another model, a different --delay are
    one line naming the entry. A gain file written under another name (``--out k.json``)
    is read too (it was refused as "expected comma-separated finite numbers")."""
    out = tmp_path / "k.yaml"
    run_json(capsys, "design", "--model", TWO, "--delay", "0.5", "--mu", "0.2", "--out",
             str(out))
    ref = run_json(capsys, "orbit", "--model", TWO, "--delta-d", "-1e-8", "--mu", "0.2",
                   "--delay", "0.5")
    got = run_json(capsys, "orbit", "--model", TWO, "--delta-d", "-1e-8", "--gains", str(out))
    for key in ("gains", "actuation_delay", "section_pi2_deviation", "multipliers", "v_minus"):
        assert got[key] == ref[key], key
    for argv, needle in (
            (("orbit", "--model", TWO, "--delta-d", "-1e-8", "--gains", str(out), "--delay",
              "0.3"), "--delay 0.3 is invalid with --gains"),
            (("orbit", "--model", three, "--delta-d", "-1e-8", "--gains", str(out)),
             "n=2 is invalid for this model: the model file gives n = 3"),
            (("orbit", "--model", TWO, "--delta-d", "-1e-8", "--gains", TWO),
             "not a gain file of design --model --out")):
        code, text, err = run(capsys, *argv)
        assert code == 2 and text == "" and err.count("\n") == 1 and needle in err, err
    named = tmp_path / "k.json"       # design --out writes YAML under any name it is given
    run_json(capsys, "design", "--model", TWO, "--delay", "0.5", "--mu", "0.2", "--out",
             str(named))
    assert run_json(capsys, "orbit", "--model", TWO, "--delta-d", "-1e-8", "--gains",
                    str(named))["gains"] == ref["gains"]
    swept = run_json(capsys, "sweep", "--model", TWO, "--grid", "delta_d=-1e-4:-1e-5:2",
                     "--periods", "3", "--workers", "1", "--no-png", "--gains", str(out),
                     "--out", str(tmp_path / "sweep"))
    assert swept["actuation_delay"] == 0.5 and swept["gains"] == ref["gains"]
    assert float(np.load(swept["npz"])["delay"]) == 0.5


# ------------------------------------------------------------------ the pulse
#: The issue's 3-mass chain (docs/theory_ndof.md §18): its design with the pulse of width
#: 0.5 centred 0.5 after the sample is admissible (mu in (0.647, 0.810)).
PULSE_THREE = """\
M: [[1.0, 0.0, 0.0], [0.0, 1.2, 0.0], [0.0, 0.0, 0.9]]
C: [[0.05, -0.02, 0.0], [-0.02, 0.05, -0.02], [0.0, -0.02, 0.05]]
K: [[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 2.2]]
f: [0.0, 0.0, 1.0]
omega: 0.45
i_w: 0
r: 0.7
i_a: 2
phase: 0.0
pi2_offset: 1.5
delta_d: 0.0
"""


@pytest.fixture(scope="module")
def pulse_files(tmp_path_factory):
    """{name: (model file, gain file of design --delay D --pulse-width W --mu MU --out,
    (D, W, MU))}: the chain (pulse 1 at 1, mu -0.17) and the issue's 3-mass chain (0.5 at
    0.5, mu 0.73)."""
    base = tmp_path_factory.mktemp("pulse")
    three = base / "three_pulse.yaml"
    three.write_text(PULSE_THREE, encoding="utf-8")
    out = {}
    for name, path, case in (("two", TWO, ("1", "1", "-0.17")),
                             ("three", str(three), ("0.5", "0.5", "0.73"))):
        gains = base / f"gains_{name}.yaml"
        got = run_json(None, "design", "--model", path, "--delay", case[0], "--pulse-width",
                       case[1], "--mu", case[2], "--out", str(gains))
        assert got["admissible"] and got["pulse"]["pulse_width"] == float(case[1])
        out[name] = (path, str(gains), case)
    return out


@pytest.mark.parametrize("which", ["two", "three"])
def test_orbit_of_a_pulse_design_s_gain_file_down_to_1e_10(capsys, pulse_files, which):
    """``orbit --gains FILE`` of ``design --delay D --pulse-width W --out FILE`` (issue 32:
    refused as "pulse_width=1.0 is invalid here"): the same numbers as ``--mu MU --delay
    D --pulse-width W``, bit for bit, on the branch in the impact phase down to -1e-10;
    the Pi2 state a fixed point of the exact pulsed map ModalMap(model, k, D, W) with one
    impact after the pulse at the same v- (1e-13 absolute; 1e-6 in v-, the map's event
    search at v- ~ 1e-5)."""
    path, gains, (delay, width, mu) = pulse_files[which]
    model0 = load_model(path)
    for dd in ("-1e-3", "-1e-10"):
        got = run_json(capsys, "orbit", "--model", path, "--delta-d", dd, "--gains", gains)
        ref = run_json(capsys, "orbit", "--model", path, "--delta-d", dd, "--mu", mu,
                       "--delay", delay, "--pulse-width", width)
        for key in ("gains", "actuation_delay", "pulse_width", "section_pi2_deviation",
                    "multipliers", "v_minus", "guess"):
            assert got[key] == ref[key], key
        assert got["pulse_width"] == float(width) and got["guess"].startswith("impact phase")
        z = np.array(got["section_pi2_deviation"])
        step = ModalMap(with_delta_d(model0, float(dd)), np.array(got["gains"]),
                        float(delay), float(width)).step(z)
        assert len(step.impacts) == 1 and step.impacts[0].dt > float(delay) + float(width) / 2
        assert abs(step.impacts[0].v_minus - got["v_minus"]) <= 1e-6 * got["v_minus"]
        np.testing.assert_allclose(step.state, z, rtol=0, atol=1e-13)


def test_continue_and_simulate_of_a_pulse_design(capsys, pulse_files):
    """``continue --gains FILE --points 8`` from -1e-3 to -1e-9 on the chain's pulse
    design: 8 points in the impact phase, each the ``orbit`` at its Delta d (state and v-
    1e-12 relative, multipliers 1e-12); ``simulate --gains FILE``: every sample is the
    exact pulsed map ModalMap(model, k, 1, 1) of the one before, bit for bit (the same
    map), one impact per period, and it ends on the pulse's orbit (1e-12)."""
    path, gains, _case = pulse_files["two"]
    branch = run_json(capsys, "continue", "--model", path, "--from", "-1e-3", "--to", "-1e-9",
                      "--points", "8", "--gains", gains)
    assert branch["route"] == "impact phase" and branch["stopped"] == "end"
    assert len(branch["branch"]) == 8 and branch["pulse_width"] == 1.0
    for p in branch["branch"]:
        o = run_json(capsys, "orbit", "--model", path, "--delta-d", repr(p["delta_d"]),
                     "--gains", gains)
        z, zo = np.array(p["section_pi2_deviation"]), np.array(o["section_pi2_deviation"])
        assert np.max(np.abs(z - zo)) <= 1e-12 * np.max(np.abs(zo))
        assert p["v_minus"] == pytest.approx(o["v_minus"], rel=1e-12)
        np.testing.assert_allclose(lam(p["multipliers"]), lam(o["multipliers"]), rtol=0,
                                   atol=1e-12)
    got = run_json(capsys, "simulate", "--model", path, "--delta-d", "-1e-5", "--periods",
                   "150", "--gains", gains)
    pmap = ModalMap(with_delta_d(load_model(path), -1e-5), np.array(got["gains"]), 1.0, 1.0)
    z = np.array(got["pi2_deviation"] + [got["final_deviation"]])
    for j in range(150):
        assert np.array_equal(pmap.step(z[j]).state, z[j + 1]), j
    assert got["impacts_per_period"][-20:] == [1] * 20 and got["pulse_width"] == 1.0
    assert got["distance_to_orbit"] < 1e-12


def test_a_pulse_s_gain_file_is_refused_where_it_does_not_fit(capsys, pulse_files, three,
                                                             tmp_path):
    """One line naming the option or the entry: a different --pulse-width (0 too), a
    file of another model (n; omega with the same n), sweep (which runs the kick), a
    file of a pulse through an actuator (actuator_bandwidth)."""
    path, gains, _case = pulse_files["two"]
    three_path, three_gains, _ = pulse_files["three"]
    actuated = tmp_path / "actuated.yaml"
    run_json(capsys, "design", "--model", TWO, "--delay", "4", "--pulse-width", "1",
             "--actuator-bandwidth", "5", "--mu", "0", "--out", str(actuated))
    for argv, needle in (
            (("orbit", "--model", path, "--delta-d", "-1e-8", "--gains", gains,
              "--pulse-width", "0.5"), "--pulse-width 0.5 is invalid with --gains"),
            (("continue", "--model", path, "--from", "-1e-3", "--to", "-1e-6", "--gains",
              gains, "--pulse-width", "0"), "the file's pulse_width is 1.0 (give the same"),
            (("orbit", "--model", three_path, "--delta-d", "-1e-8", "--gains", gains),
             "n=2 is invalid for this model: the model file gives n = 3"),
            (("simulate", "--model", three, "--delta-d", "-1e-8", "--periods", "2",
              "--gains", three_gains), "omega=0.45 is invalid for this model"),
            (("sweep", "--model", path, "--grid", "delta_d=-1e-4:-1e-5:2", "--periods", "3",
              "--gains", gains), "pulse_width=1.0 is invalid here: sweep runs the kick"),
            (("orbit", "--model", TWO, "--delta-d", "-1e-8", "--gains", str(actuated)),
             "actuator_bandwidth=5.0 is invalid here")):
        code, text, err = run(capsys, *argv)
        assert code == 2 and text == "" and err.count("\n") == 1 and needle in err, err


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize("argv, needle", [
    (["orbit", "--model", ONE, "--delta-d", "-1e-6", "--c2", "-1"], "--c2 is a 1-DOF option"),
    (["design", "--model", ONE, "--zeta", "0.02"], "--zeta is a 1-DOF option"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--mu", "0", "--delay", "12"],
     "--delay 12.0 is invalid: valid range is 0 <= delay < T - pi2_offset/omega = 11.96637061"),
    (["continue", "--model", TWO, "--from", "-1e-3", "--to", "-1e-6", "--mu", "0",
      "--delay", "-0.5"], "--delay -0.5 is invalid: valid range is 0 <= delay"),
    (["simulate", "--model", TWO, "--delta-d", "-1e-6", "--periods", "3", "--delay", "1"],
     "--delay needs the gains: give --gains, --mu or --free-gain"),
    (["design", "--model", TWO, "--delay", "12"], "delay=12.0 is invalid: valid range is 0 <= delay"),
    (["sweep", "--model", TWO, "--grid", "delta_d=-1e-4:0:3", "--periods", "3", "--mu", "0",
      "--delay", "12"], "--delay 12.0 is invalid: valid range is 0 <= delay"),
    (["sweep", "--model", TWO, "--grid", "delta_d=-1e-4:0:3", "--periods", "3", "--delay",
      "1"], "--delay needs the gains: give --gains, --mu or --free-gain"),
    (["sweep", "--grid", "delta_d=-1e-4:0:3", "--periods", "3", "--delay", "1"],
     "--delay needs the gains: give --c2"),
    (["figures", "--model", TWO, "--delay", "12", "--quick"], "--delay 12.0 is invalid"),
    (["figures", "--delay", "0.5", "--quick"], "--delay needs --model"),
    (["orbit", "--delta-d", "-1e-6", "--mu", "0"], "--mu needs --model"),
    (["orbit", "--model", "/nonexistent/m.yaml", "--delta-d", "-1e-6"], "no such file"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--gains", "1,2,3"], "give 2n = 4"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--mu", "0", "--gains", "1,2,3,4"],
     "give one of"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--free-gain", "q3=1"],
     "valid names are x0, x1, v0, v1"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--gains", "1,x"], "comma-separated"),
    (["simulate", "--model", TWO, "--delta-d", "-1e-6", "--periods", "3", "--z0", "1,2"],
     "give 2n = 4"),
    (["sweep", "--model", TWO, "--grid", "zeta=0.1:0.2:2", "--periods", "3"],
     "valid names are delta_d"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--mu", "0", "--pulse-width", "30"],
     "--pulse-width 30.0 is invalid: valid range is 0 <= pulse_width < 11.96637061 with "
     "--delay 0"),
    (["continue", "--model", TWO, "--from", "-1e-3", "--to", "-1e-6", "--mu", "0",
      "--delay", "11", "--pulse-width", "2"],
     "--pulse-width 2.0 is invalid: valid range is 0 <= pulse_width < 1.932741229 with "
     "--delay 11"),
    (["orbit", "--model", TWO, "--delta-d", "-1e-6", "--mu", "0", "--pulse-width", "-1"],
     "--pulse-width -1.0 is invalid: valid range is 0 <= pulse_width"),
    (["simulate", "--model", TWO, "--delta-d", "-1e-6", "--periods", "3", "--pulse-width",
      "1"], "--pulse-width needs the gains: give --gains, --mu or --free-gain"),
    (["orbit", "--delta-d", "-1e-6", "--c2", "-1", "--pulse-width", "1"],
     "--pulse-width needs --model FILE: the 1-DOF orbit, continue and simulate run the kick"),
    (["continue", "--from", "-1e-3", "--to", "-1e-6", "--c2", "-1", "--pulse-width", "1"],
     "--pulse-width needs --model FILE"),
    (["simulate", "--delta-d", "-1e-6", "--periods", "3", "--c2", "-1", "--pulse-width=1"],
     "--pulse-width needs --model FILE"),
])
def test_errors_are_one_line_status_2(capsys, argv, needle):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert out == ""
    assert err.startswith("grazing: error: ") and err.count("\n") == 1, err
    assert needle in err


def test_malformed_model_file_is_one_line(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("M: [[1.0]]\nC: [[-1.0]]\nK: [[1.0]]\nf: [1.0]\nomega: 0.5\ni_w: 0\n")
    code, out, err = run(capsys, "design", "--model", str(bad))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"--model {bad}: C is invalid" in err
    bad.write_text("M: [[1.0]\n")
    code, out, err = run(capsys, "design", "--model", str(bad))
    assert code == 2 and "is not valid YAML (line 2)" in err and err.count("\n") == 1



@pytest.mark.parametrize("args,message", [
    (["--mu", "1e308"], "mu=1e+308 is invalid: valid range is |mu| <= 1e+06"),
    (["--free-gain", "v1=1e308"], "--free-gain v1=1e+308 is invalid: it is the member"),
])
def test_design_refuses_a_family_member_beyond_the_search_range_in_one_line(args, message,
                                                                          capsys):
    """An absurd member of the family is refused naming the option and its valid range
    (it gave numpy's "Array must not contain infs or NaNs")."""
    from grazing_control import cli

    model = str(Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_chain.yaml")
    assert cli.main(["design", "--model", model, *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err

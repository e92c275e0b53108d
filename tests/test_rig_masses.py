"""A rig of n masses in SI (plant/rig_structure.py, docs/rig.md "A rig with n masses";
issue 32): its n-DOF model, the inverse, the file's round trip and its refusals.

* The n = 1 rig gives exactly today's 1-DOF model: the masses form of the issue's lab rig
  is the same Rig as config/rigs/lab_20hz.yaml read today, and Rig.model() is
  M = K = f = 1, C = 2 zeta with params()' omega and Delta d (d* to 1e-15).
* Seeded random rigs of 2 and 3 masses: file -> Rig -> file is exact, and
  SI -> model -> SI (rig_with_model(rig, rig.model())) is the identity to 1e-12.
* The derivation checked independently in SI: the periodic response of
  (K - Omega^2 M + i Omega C) X = f solved in SI is the model's times l, so d* l is the
  impacting mass's largest excursion; the SI state matrix's eigenvalues have |lambda| =
  omega_i and Re lambda = -zeta_i omega_i (the modal ratios of the file).
* The correction's impulse: J = Delta v_a / (M^-1)_aa, checked by applying J to the
  momentum M v (Delta v = M^-1 e_a J changes v_a by Delta v_a).
* Each bad field refused by one line naming it.
"""

import copy
import json
import math

import numpy as np
import pytest
import yaml

from grazing_control.oscillator.ndof.flow import grazing_clearance
from grazing_control.plant.rig import (RigError, load_rig, rig_from_dict, rig_to_dict,
                                       rig_with_model)
from grazing_control.plant.rig_structure import chain_stiffness, modal_damping

from rig_files import LAB

TWO_MASS = "config/rigs/two_mass_beam.yaml"


def _two_mass() -> dict:
    with open(TWO_MASS) as fh:
        return yaml.safe_load(fh)


def random_masses_rig(rng, n: int) -> dict:
    """A valid n-mass rig file's mapping: random masses, a chain or a full stiffness
    matrix, modal ratios, the stop at Delta d = -1e-6 d* ... -0.1 d*."""
    def U(a, b):
        return float(rng.uniform(a, b))

    masses = [10 ** U(-1, 1) for _ in range(n)]
    springs = [10 ** U(2, 4) for _ in range(n)]
    K = chain_stiffness(springs)
    w = int(rng.integers(n))
    wn = math.sqrt(K[w][w] / masses[w])
    f = U(0.2, 0.5) * wn / (2 * math.pi)      # below the reference's frequency
    doc = {"masses": [f"{m!r} kg" for m in masses],
           "damping_ratios": sorted(U(0.005, 0.1) for _ in range(n)),
           "impacting": w, "restitution": U(0.2, 0.9), "gap": "1 m",
           "forcing": {"type": "force", "amplitude": f"{10 ** U(-1, 2)!r} N",
                       "frequency": f"{f!r} Hz", "phase": f"{U(-3, 3)!r} rad",
                       "mass": int(rng.integers(n))},
           "sensor": {"rate": f"{100 * f!r} Hz", "noise": "1e-06 m", "latency": "0 s",
                      "masses": [int(i) for i in rng.permutation(n)[:int(rng.integers(1, n + 1))]]},
           "actuator": {"pulse_width": f"{0.01 / f!r} s", "mass": int(rng.integers(n))},
           "controller": {"budget": f"{0.05 / f!r} s", "pi2_offset": f"{U(0.2, 1.0)!r} rad"}}
    if rng.random() < 0.5:
        doc["springs"] = [f"{k!r} N/m" for k in springs]
    else:
        doc["stiffness"] = [[f"{k!r} N/m" for k in row] for row in K]
    if rng.random() < 0.3:
        doc["forcing"] = {"type": "base", "amplitude": f"{10 ** U(-5, -3)!r} m",
                          "frequency": doc["forcing"]["frequency"], "stop": "frame"}
    rig = rig_from_dict(doc)
    model = rig.model()
    d_star = grazing_clearance(model)
    doc["gap"] = f"{d_star * (1.0 - 10 ** U(-6, -1)) * rig.scales.length!r} m"
    return doc


def test_the_one_mass_rig_gives_exactly_todays_model():
    today = rig_from_dict(LAB)
    doc = copy.deepcopy(LAB)
    for key in ("mass", "natural_frequency", "damping_ratio"):
        del doc[key]
    k = today.stiffness
    doc.update(masses=["0.5 kg"], springs=[f"{k!r} N/m"], damping_ratios=[0.01])
    masses = rig_from_dict(doc)
    assert masses.structure is None and masses.n == 1
    assert masses.params() == today.params()      # omega_n = sqrt(k / m) to the last bit
    p, m = today.params(), today.model()
    assert m.M.tolist() == [[1.0]] and m.K.tolist() == [[1.0]] and m.f.tolist() == [1.0]
    assert m.C.tolist() == [[2.0 * p.zeta]]
    assert (m.omega, m.delta_d, m.r, m.pi2_offset) == (p.omega, p.delta_d, p.r, p.pi2_offset)
    assert grazing_clearance(m) == pytest.approx(p.d_star, rel=1e-15)
    assert today.effective_mass == today.mass
    assert today.state_gains_si([0.3, -0.2]) == {
        "position_gains_per_s": [today.gains_si(0.3, -0.2)["c1_per_s"]],
        "velocity_gains": [-0.2],
        "force_gains_position_N_per_m": [today.gains_si(0.3, -0.2)["force_gain_position_N_per_m"]],
        "force_gains_velocity_N_s_per_m": [today.gains_si(0.3, -0.2)["force_gain_velocity_N_s_per_m"]]}


@pytest.mark.parametrize("n", [2, 3])
def test_round_trips_over_random_rigs_of_n_masses(n):
    rng = np.random.default_rng(32 + n)
    for _ in range(100):
        rig = rig_from_dict(random_masses_rig(rng, n))
        assert rig.n == n
        again = rig_from_dict(yaml.safe_load(yaml.safe_dump(rig_to_dict(rig))))
        assert again == rig
        back = rig_with_model(rig, rig.model())
        st, bs = rig.structure, back.structure
        for a, b in ((st.masses, bs.masses), (st.damping_ratios, bs.damping_ratios),
                     (np.ravel(st.stiffness), np.ravel(bs.stiffness)),
                     ((rig.omega_n, rig.mass, rig.zeta, rig.gap, rig.restitution),
                      (back.omega_n, back.mass, back.zeta, back.gap, back.restitution))):
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=0.0)
        assert (bs.impacting, bs.actuated, bs.measured, bs.forced) == \
            (st.impacting, st.actuated, st.measured, st.forced)


def test_the_model_is_the_si_equation_scaled():
    rng = np.random.default_rng(3232)
    for n in (2, 3):
        for _ in range(20):
            rig = rig_from_dict(random_masses_rig(rng, n))
            st, s, model = rig.structure, rig.scales, rig.model()
            M, K, C = st.M, st.K, st.C
            Om = 2 * math.pi * rig.frequency
            if rig.forcing == "force":
                f = np.zeros(n)
                f[st.forced] = rig.amplitude
            else:
                f = Om ** 2 * rig.amplitude * np.diag(M)
            X = np.linalg.solve(K - Om ** 2 * M + 1j * Om * C, f)
            assert abs(X[st.impacting]) == pytest.approx(grazing_clearance(model) * s.length,
                                                         rel=1e-10)
            assert rig.gap / s.length - grazing_clearance(model) == \
                pytest.approx(model.delta_d, rel=1e-9, abs=1e-15)
            A = np.block([[np.zeros((n, n)), np.eye(n)],
                          [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
            lam = np.linalg.eigvals(A)
            lam = lam[lam.imag > 0]
            lam = lam[np.argsort(abs(lam))]
            np.testing.assert_allclose(-lam.real / abs(lam), st.damping_ratios, rtol=1e-8)


def test_the_impulse_is_the_velocity_change_over_the_inverse_mass_entry():
    rig = load_rig(TWO_MASS)
    st = rig.structure
    dv = 0.01                               # model units
    out = rig.correction_si(dv)
    # J e_a added to the momentum M v: the velocities change by M^-1 e_a J
    dvel = np.linalg.solve(st.M, np.eye(st.n)[st.actuated] * out["impulse_N_s"])
    assert dvel[st.actuated] == pytest.approx(dv * rig.scales.velocity, rel=1e-15)
    assert out["impulse_N_s"] == pytest.approx(st.masses[st.actuated] * out["velocity_m_per_s"],
                                               rel=1e-15)
    assert out["force_N"] == pytest.approx(out["impulse_N_s"] / rig.actuator.pulse_width)
    # a full mass matrix (not a rig file's, the formula's): m_a = 1 / (M^-1)_aa
    M = modal_damping(np.eye(2), np.array([[2.0, -1.0], [-1.0, 1.0]]), [0.5, 0.5]) + np.eye(2)
    ma = 1.0 / np.linalg.inv(M)[0, 0]
    assert np.linalg.solve(M, np.array([ma * 0.3, 0.0]))[0] == pytest.approx(0.3, rel=1e-14)


def _mutate(doc, path, value):
    d = doc
    for key in path[:-1]:
        d = d[key]
    if value is KeyError:
        del d[path[-1]]
    else:
        d[path[-1]] = value


BAD = [
    (("masses",), [], "masses"),
    (("masses",), ["0.8 kg", "-1 kg"], "masses[1]"),
    (("masses",), ["0.8", "0.5 kg"], "masses[0]"),
    (("masses",), ["1 kg"] * 13, "masses"),
    (("springs",), ["3200 N/m"], "springs"),
    (("springs",), ["3200 N/m", "0 N/m"], "springs[1]"),
    (("springs",), KeyError, "springs / stiffness"),
    (("stiffness",), [["1 N/m", "2 N/m"], ["0 N/m", "1 N/m"]], "springs / stiffness"),
    (("damping_ratios",), [0.01], "damping_ratios"),
    (("damping_ratios",), [0.01, 1.5], "damping_ratios[1]"),
    (("impacting",), 2, "impacting"),
    (("impacting",), KeyError, "impacting"),
    (("mass",), "1 kg", "mass"),
    (("forcing", "mass"), 5, "forcing.mass"),
    (("actuator", "mass"), -1, "actuator.mass"),
    (("sensor", "masses"), [0, 0], "sensor.masses"),
    (("sensor", "masses"), [3], "sensor.masses[0]"),
    (("stop",), {"type": "kelvin_voigt", "stiffness": "1e6 N/m"}, "stop.type"),
]


@pytest.mark.parametrize("path, value, field", BAD)
def test_each_bad_field_is_one_line_naming_it(path, value, field):
    doc = _two_mass()
    _mutate(doc, path, value)
    with pytest.raises(RigError) as info:
        rig_from_dict(doc)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(field), msg


def test_a_full_stiffness_matrix_must_be_symmetric_positive_definite():
    doc = _two_mass()
    del doc["springs"]
    doc["stiffness"] = [["1000 N/m", "-2000 N/m"], ["-2000 N/m", "1000 N/m"]]
    with pytest.raises(RigError, match="^stiffness is invalid: .*positive definite"):
        rig_from_dict(doc)
    doc["stiffness"] = [["1000 N/m", "-20 N/m"], ["-10 N/m", "1000 N/m"]]
    with pytest.raises(RigError, match="^stiffness is invalid: .*symmetric"):
        rig_from_dict(doc)


# ---------------------------------------------------------------------- the commands
@pytest.fixture
def cli(capsys):
    """main(argv) -> (status, stdout, stderr)."""
    from grazing_control.cli import commands

    def run(*argv):
        code = commands.main([str(a) for a in argv])
        out = capsys.readouterr()
        return code, out.out, out.err
    return run


def test_design_with_a_rig_of_two_masses_is_the_model_files_design_with_its_pulse(cli, tmp_path):
    model_file = tmp_path / "model.yaml"
    code, out, err = cli("rig", TWO_MASS, "--model-out", model_file, "--json")
    assert code == 0, err
    report = json.loads(out)
    rig = load_rig(TWO_MASS)
    from grazing_control.oscillator.ndof.model import load_model

    written = load_model(model_file)
    for name in ("M", "C", "K", "f"):
        assert np.array_equal(getattr(written, name), getattr(rig.model(), name)), name
    assert written.delta_d == rig.model().delta_d and written.omega == rig.model().omega
    # the rig's pulse in model time: budget and width times omega_n
    w, delay = rig.actuator.pulse_width, rig.budget
    code, out, err = cli("design", "--model", model_file, "--delay", repr(delay * rig.omega_n),
                         "--pulse-width", repr(w * rig.omega_n), "--mu", "0.1", "--json")
    assert code == 0, err
    by_model = json.loads(out)
    code, out, err = cli("design", "--rig", TWO_MASS, "--mu", "0.1", "--json")
    assert code == 0, err
    by_rig = json.loads(out)
    assert by_rig["gains"] == by_model["gains"] and by_rig["pulse"] == by_model["pulse"]
    k, si = by_rig["gains"], by_rig["si"]
    m_a = rig.structure.masses[rig.structure.actuated]     # lumped: 1 / (M^-1)_aa = M_aa
    assert si["effective_mass_kg"] == m_a
    # Delta v_a [m/s] = omega_n l k^T (x / l, v / (omega_n l)), force = m_a Delta v_a / w
    x, v = np.array([1e-6, -2e-6]), np.array([3e-3, 1e-3])
    dv_model = np.dot(k, np.r_[x / rig.scales.length, v / rig.scales.velocity])
    dv_si = np.dot(si["position_gains_per_s"], x) + np.dot(si["velocity_gains"], v)
    assert dv_si == pytest.approx(dv_model * rig.scales.velocity, rel=1e-12)
    force = np.dot(si["force_gains_position_N_per_m"], x) + \
        np.dot(si["force_gains_velocity_N_s_per_m"], v)
    assert force == pytest.approx(m_a * dv_si / w, rel=1e-12)
    assert report["design"]["admissible"] and report["model"]["delta_d"] == written.delta_d
    # the correction at the controlled orbit (issue 32: the 1-DOF rig's, through the one
    # entry of every model): z is the fixed point of the exact n-DOF period map with the
    # report's gains kicking at its delay, and the pulse is k^T z in SI
    from grazing_control.dynamics.maps.modal_map import ModalMap

    k, delay = np.array(report["design"]["gains"]), report["design"]["delay"]
    at = report["corrections"]["at_controlled_orbit"]
    z = np.array(at["pi2_deviation"])
    step = ModalMap(written, k, delay).step(z)
    assert len(step.impacts) == 1
    assert np.max(np.abs(step.state - z)) < 1e-12 * np.max(np.abs(z)), step.state - z
    assert at["pi2_deviation_m_and_m_per_s"] == pytest.approx(
        np.r_[z[:2] * rig.scales.length, z[2:] * rig.scales.velocity], rel=1e-15)
    assert at == {**at, **rig.correction_si(float(k @ z)), "within_force_limit": True}
    assert at["velocity_m_per_s"] == pytest.approx(float(k @ z) * rig.scales.velocity, rel=1e-12)


@pytest.mark.parametrize("argv, first", [
    (("orbit", "--rig", TWO_MASS), "--rig"),
    (("design", "--rig", TWO_MASS, "--c2", "0.1"), "--c2"),
    (("design", "--rig", TWO_MASS, "--delay", "0.1"), "--rig FILE and --delay"),
    (("design", "--rig", TWO_MASS, "--out", "/tmp/never_written.yaml"), "--out"),
    (("design", "--rig", "config/rigs/lab_20hz.yaml", "--mu", "0.1"), "--mu"),
    (("rig", TWO_MASS, "--c2", "0.1"), "--c2"),
])
def test_the_commands_refuse_what_a_rig_of_two_masses_cannot_take(cli, argv, first):
    code, out, err = cli(*argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"grazing: error: {first}"), err


# ---------------------------------------------------------------------- the driver contract
def test_the_force_pulse_carries_the_effective_mass_and_the_sensor_the_length_scale():
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.ros.rig_boundary import (correction_of, force_of, joint_names,
                                                  model_positions, sensor_positions,
                                                  sim_values)

    rig = load_rig(TWO_MASS)
    st, s, w = rig.structure, rig.scales, rig.actuator.pulse_width
    dv = -0.0123
    force = force_of(rig, dv)
    # the impulse F w on the actuated mass changes its velocity by (M^-1)_aa F w
    dvel = np.linalg.solve(st.M, np.eye(st.n)[st.actuated] * force * w)
    assert dvel[st.actuated] == pytest.approx(dv * s.velocity, rel=1e-14)
    assert correction_of(rig, force, w) == pytest.approx(dv, rel=1e-15)
    one = rig_from_dict(LAB)          # one mass: today's m omega_n l dv / w, bit for bit
    assert force_of(one, dv) == one.mass * one.scales.velocity * dv / one.actuator.pulse_width
    assert joint_names(one) == ["mass"] and sensor_positions(one, [0.5]) == [0.5 * one.scales.length]
    # rig/sensor: the measured masses (sensor.masses [1, 0]) in metres, and back
    x = np.array([0.25, -1.5])
    assert joint_names(rig) == ["mass1", "mass0"]
    assert sensor_positions(rig, x) == [x[1] * s.length, x[0] * s.length]
    back = model_positions(rig, joint_names(rig), sensor_positions(rig, x))
    assert back == {1: pytest.approx(x[1], rel=1e-15), 0: pytest.approx(x[0], rel=1e-15)}
    with pytest.raises(ValueError, match="^rig/sensor names"):
        model_positions(rig, ["mass"], [0.0])
    # the simulated rig of two masses is the n-DOF scene of its model (the model gives
    # zeta, r, omega, pi2_offset); a compliant stop is refused naming stop.type
    values = sim_values(rig)
    assert values["delta_d"] == rig.model().delta_d and "zeta" not in values
    assert values["state_period"] == rig.omega_n / rig.sensor.rate
    import dataclasses

    from grazing_control.plant.rig import Stop

    soft = dataclasses.replace(rig, stop=Stop("kelvin_voigt", 1e5, 1.0))
    with pytest.raises(ParameterError, match="^stop.type='kelvin_voigt' is not simulated "
                                             "for a rig of 2 masses: valid there is rigid"):
        sim_values(soft)


def test_the_controller_of_a_rig_of_two_masses_is_grazing_design_rigs(cli):
    """controller_node's values of a rig of two masses (rig_boundary.controller_values):
    the n-DOF law with the gains `grazing design --rig FILE` prints (its default mu, or
    rig_mu), the stream estimator on the first measured mass; rig_c2 refused."""
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.ros.rig_boundary import MASSES_CONTROLLER_KEYS, controller_values

    rig = load_rig(TWO_MASS)
    values = controller_values(rig, math.nan)
    assert set(values) == set(MASSES_CONTROLLER_KEYS)
    design = json.loads(cli("design", "--rig", TWO_MASS, "--json")[1])
    assert values["mu"] == design["mu"] and values["gains"] == design["gains"]
    assert values["sensor_coordinate"] == rig.structure.measured[0] == 1
    assert (values["n"], values["i_a"]) == (2, rig.structure.actuated)
    given = controller_values(rig, math.nan, 0.1)
    mine = json.loads(cli("design", "--rig", TWO_MASS, "--mu", "0.1", "--json")[1])
    assert given["gains"] == pytest.approx(mine["gains"], rel=1e-15, abs=0.0)
    with pytest.raises(ParameterError, match="^rig_c2=0.03 is invalid for a rig of 2 masses"):
        controller_values(rig, 0.03)
    with pytest.raises(ParameterError, match="^rig_mu=0.1 is invalid for a rig of one mass"):
        controller_values(rig_from_dict(LAB), math.nan, 0.1)


def test_the_rig_controller_reads_the_first_measured_mass_and_never_fails_on_a_message():
    """RigSide's rig/sensor of a rig of two masses (ros/rig_control.py): the position of
    the mass the estimator reads (sensor_coordinate = sensor.masses[0] = 1, the first
    entry of the message); a message with other names, another count, or bytes that are
    no JointState is counted as malformed and dropped (None), never raised."""
    from types import SimpleNamespace

    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from grazing_control.ros.rig_control import RigSide

    bad = []
    node = SimpleNamespace(malformed=bad.append, stream=SimpleNamespace(coordinate=1))
    side = RigSide(node, load_rig(TWO_MASS), 200)

    def data(names, positions, velocities=()):
        msg = JointState(name=names, position=positions, velocity=list(velocities))
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1000, 5
        return serialize_message(msg)

    assert side._masses_sample(data(["mass1", "mass0"], [2.5e-3, 2.1e-3])) == (
        1000, 5, 2.5e-3, pytest.approx(math.nan, nan_ok=True), ())
    assert side._masses_sample(data(["mass1", "mass0"], [2.5e-3, 2.1e-3], [0.1, 0.2]))[3] == 0.1
    for wrong in (data(["mass0", "mass1"], [2.1e-3, 2.5e-3]), data(["mass"], [2.5e-3]),
                  data(["mass1", "mass0"], [2.5e-3]), b"\x00\x01\x00\x00garbage"):
        assert side._masses_sample(wrong) is None
    assert len(bad) == 4 and bad[0].startswith("rig/sensor at (1000, 5): rig/sensor names")

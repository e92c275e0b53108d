"""``grazing identify BAG...``: bags in, parameters with standard errors out, exit status.

Specification (issue 16 §1, "Names"): ``grazing identify BAG... [--json] [--out FILE]``,
JSON ``{"parameters": {"zeta": {"value", "stderr"}, "r", "omega", "delta_d", ...}, ...}``;
exit 0 good fit, 1 poor fit (wrong model), 2 bad input with one line on stderr; ``--out``
writes the parameter file that ``--params`` of the model's commands reads. The bags are
written with the package's BagWriter from the exact simulation (state stream, impacts,
corrections, the parameter record), and two bags recorded from the real nodes
(bags/scene_5e-6, scene_9e-6) are fitted against their own parameter record.
"""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from grazing_control.cli.commands import build_parser, main
from grazing_control.cli.parameter_file import apply_to_args, read_parameter_file
from grazing_control.oscillator.control import Gains
from grazing_control.recordings import reader
from grazing_control.ros.recording import BagWriter
from grazing_control.ros.recording.record import encode

from bagtools_helpers import BAGS, TYPESTORE
from identification_scenes import SCENE, exact_motion, soft_wall_recording

_NS = 1_000_000_000
TRUTH = {"zeta": SCENE.zeta, "r": SCENE.r, "omega": SCENE.omega, "delta_d": SCENE.delta_d}


def _stamp(t_ns):
    T = TYPESTORE.types
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
        sec=int(t_ns // _NS), nanosec=int(t_ns % _NS)), frame_id="")


def _joint_state(t_ns, x, v, effort, names=("mass",)):
    JS = TYPESTORE.types["sensor_msgs/msg/JointState"]
    msg = JS(header=_stamp(t_ns), name=list(names), position=np.array([x], float),
             velocity=np.array([] if v is None else [v], float), effort=np.array(effort, float))
    return TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/JointState")


def _vector3(t_ns, a, b, c):
    T = TYPESTORE.types
    msg = T["geometry_msgs/msg/Vector3Stamped"](
        header=_stamp(t_ns), vector=T["geometry_msgs/msg/Vector3"](x=a, y=b, z=c))
    return TYPESTORE.serialize_cdr(msg, "geometry_msgs/msg/Vector3Stamped")


def _twist(t_ns, dv):
    T = TYPESTORE.types
    V3 = T["geometry_msgs/msg/Vector3"]
    msg = T["geometry_msgs/msg/TwistStamped"](
        header=_stamp(t_ns), twist=T["geometry_msgs/msg/Twist"](linear=V3(x=dv, y=0.0, z=0.0),
                                                                 angular=V3(x=0.0, y=0.0, z=0.0)))
    return TYPESTORE.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped")


def _string(text):
    msg = TYPESTORE.types["std_msgs/msg/String"](data=text)
    return TYPESTORE.serialize_cdr(msg, "std_msgs/msg/String")


def write_bag(path, t, x, v, tau, impacts=None, corrections=None, *, sin=False,
              velocity=True, record=True, p=SCENE, extra=None):
    """A bag as sim_node and the recorder write it: state (x, v or empty, effort [cos tau]
    or [cos tau, sin tau]), impacts, corrections, the parameter record (with ``extra``
    of sim_node's parameters)."""
    with BagWriter(path) as bag:
        bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
        if record:
            bag.add_topic("/grazing/parameters", "std_msgs/msg/String")
            bag.write("/grazing/parameters", _string(encode("/sim_node", {
                "zeta": p.zeta, "r": p.r, "omega": p.omega, "delta_d": p.delta_d,
                "actuation_delay": 0.0, **(extra or {})})), 0)
        stamps = np.round(np.asarray(t) * 1e9).astype(np.int64)
        for j, s in enumerate(stamps):
            eff = [np.cos(tau[j]), np.sin(tau[j])] if sin else [np.cos(tau[j])]
            bag.write("/oscillator/state",
                      _joint_state(s, x[j], v[j] if velocity else None, eff), int(s))
        if impacts is not None and len(impacts):
            bag.add_topic("/oscillator/impact", "geometry_msgs/msg/Vector3Stamped")
            for ti, vm, vp, ph in impacts:
                s = int(round(ti * 1e9))
                bag.write("/oscillator/impact", _vector3(s, vm, vp, ph), s)
        if corrections is not None and len(corrections):
            bag.add_topic("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped")
            for tc, dv in corrections:
                s = int(round(tc * 1e9))
                bag.write("/controller/velocity_correction", _twist(s, dv), s)
    return Path(path)


def scene_bag(path, periods=24, **kwargs):
    gains = kwargs.pop("gains", None)
    t, x, v, tau, imp, corr = exact_motion(SCENE, periods, ns=True, gains=gains,
                                           control_after=8)
    with_impacts = kwargs.pop("impacts", True)
    return write_bag(path, t, x, v, tau, imp if with_impacts else None, corr, **kwargs)


def run(capsys, *argv):
    code = main(["identify", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def _close(params, rel=1e-8):
    errs = {k: abs(params[k]["value"] - v) / abs(v) for k, v in TRUTH.items()}
    assert max(errs.values()) <= rel, errs


# ---------------------------------------------------------------------------- the reader
def test_decode_joint_stream_reads_what_rosbags_wrote(tmp_path):
    rows = [(1_000, 0.5, 0.25, [0.1, 0.2]), (2_000, -0.5, None, [0.3]),
            (3_000, 1.5, 2.0, []), (4_000, 2.5, None, [0.7, -0.7])]
    with BagWriter(tmp_path / "b") as bag:
        bag.add_topic("/s", "sensor_msgs/msg/JointState")
        for t, x, v, e in rows:
            bag.write("/s", _joint_state(t, x, v, e, names=("a", "bb", "ccc")), t)
    c = reader.decode_joint_stream(reader.read_raw(tmp_path / "b"), "/s")
    assert c["ok"].all()
    assert c["stamp"].tolist() == [r[0] for r in rows]
    assert c["x"].tolist() == [r[1] for r in rows]
    np.testing.assert_array_equal(c["v"], [0.25, np.nan, 2.0, np.nan])
    np.testing.assert_array_equal(c["e0"], [0.1, 0.3, np.nan, 0.7])
    np.testing.assert_array_equal(c["e1"], [0.2, np.nan, np.nan, -0.7])


# ---------------------------------------------------------------------------- good fits
def test_identify_json_out_and_design_params(tmp_path, capsys):
    bag = scene_bag(tmp_path / "bag")
    out = tmp_path / "model.yaml"
    code, text, err = run(capsys, bag, "--json", "--out", out)
    assert code == 0, err
    result = json.loads(text)
    assert result["fit"] == "good"
    assert set(result["parameters"]) >= {"zeta", "r", "omega", "delta_d", "d",
                                         "natural_frequency", "forcing_amplitude",
                                         "forcing_phase"}
    assert all(set(v) == {"value", "stderr"} for v in result["parameters"].values())
    _close(result["parameters"])
    assert result["parameter_record"]["delta_d"] == SCENE.delta_d
    # the file: a /** ROS 2 parameter file with the identified model
    doc = yaml.safe_load(out.read_text())
    assert set(doc["/**"]["ros__parameters"]) == {"zeta", "r", "omega", "delta_d"}
    model = read_parameter_file(out)
    assert model == {k: result["parameters"][k]["value"] for k in model}
    # grazing design --params FILE == grazing design with the same values given
    assert main(["design", "--c2", "-1", "--json", "--params", str(out)]) == 0
    from_file = json.loads(capsys.readouterr().out)
    assert main(["design", "--c2", "-1", "--json", "--zeta", repr(model["zeta"]), "--r",
                 repr(model["r"]), "--omega", repr(model["omega"])]) == 0
    given = json.loads(capsys.readouterr().out)
    assert from_file["c1"] == given["c1"]


def test_position_only_sensor_with_sin_reference_and_no_impact_topic(tmp_path, capsys):
    bag = scene_bag(tmp_path / "bag", velocity=False, sin=True, impacts=False)
    code, text, err = run(capsys, bag, "--json")
    assert code == 0, err
    result = json.loads(text)
    assert result["impacts_from"] == "motion" and result["velocity"] is False
    assert result["phase_reference"]["sin"] is True
    _close(result["parameters"])


def test_options_no_impacts_and_position_only(tmp_path, capsys):
    bag = scene_bag(tmp_path / "bag")
    code, text, err = run(capsys, bag, "--json", "--no-impacts", "--position-only")
    assert code == 0, err
    result = json.loads(text)
    assert result["impacts_from"] == "motion" and result["velocity"] is False
    _close(result["parameters"])


def test_corrections_cut_the_arcs(tmp_path, capsys):
    bag = scene_bag(tmp_path / "bag", gains=Gains(-0.9, -0.5))
    code, text, err = run(capsys, bag, "--json")
    assert code == 0, err
    result = json.loads(text)
    assert result["arcs"] > result["impacts"] + 10        # 16 corrections, 24 impacts
    _close(result["parameters"])


def test_two_bags_are_combined(tmp_path, capsys):
    a = scene_bag(tmp_path / "a", periods=16)
    b = scene_bag(tmp_path / "b", periods=20, velocity=False)
    code, text, err = run(capsys, a, b, "--json")
    assert code == 0, err
    result = json.loads(text)
    assert result["bags"] == [str(a), str(b)] and len(result["per_bag"]) == 2
    _close(result["parameters"])


@pytest.mark.parametrize("name", ["scene_5e-6", "scene_9e-6"])
def test_bags_recorded_from_the_nodes_match_their_parameter_record(name, capsys):
    code, text, err = run(capsys, BAGS / name, "--json", "--max-arcs", "40")
    assert code == 0, err
    result = json.loads(text)
    record = result["parameter_record"]
    for k in ("zeta", "r", "omega", "delta_d"):
        assert abs(result["parameters"][k]["value"] - record[k]) <= 1e-8 * abs(record[k]), k


def test_text_report(tmp_path, capsys):
    code, text, _err = run(capsys, scene_bag(tmp_path / "bag"))
    assert code == 0
    assert "fit GOOD" in text and "delta_d" in text and "+-" in text


# ---------------------------------------------------------------------------- poor fit
def test_a_soft_wall_bag_is_a_poor_fit_and_nothing_is_written(tmp_path, capsys):
    rec = soft_wall_recording(stiffness=1e5, noise=1e-4)
    imps = np.column_stack([rec.impact_t, rec.impact_v_minus, rec.impact_v_plus,
                            np.zeros(rec.impact_t.size)])
    bag = write_bag(tmp_path / "bag", rec.t, rec.x, rec.v, SCENE.tau2 + SCENE.omega * rec.t,
                    imps)
    out = tmp_path / "model.yaml"
    code, text, _err = run(capsys, bag, "--out", out)
    assert code == 1
    assert "fit POOR" in text and "not white" in text and "nothing written" in text
    assert not out.exists()


# ---------------------------------------------------------------------------- bad input
def _one_error_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("grazing: error: "), err
    return lines[0]


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    code, _out, err = run(capsys, tmp_path / "missing")
    assert code == 2 and "no such bag" in _one_error_line(err)
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    code, _out, err = run(capsys, tmp_path / "junk.mcap")
    assert code == 2 and "not an MCAP file" in _one_error_line(err)
    with BagWriter(tmp_path / "empty") as bag:
        bag.add_topic("/grazing/parameters", "std_msgs/msg/String")
    code, _out, err = run(capsys, tmp_path / "empty")
    assert code == 2 and "no messages on /oscillator/state" in _one_error_line(err)
    t, x, v, tau, imp, _c = exact_motion(SCENE, 1)
    write_bag(tmp_path / "short", t[:12], x, v, tau, imp)
    code, _out, err = run(capsys, tmp_path / "short")
    assert code == 2 and "need at least 20" in _one_error_line(err)
    free = SCENE.with_(delta_d=5.0)
    t, x, v, tau, imp, _c = exact_motion(free, 8, ns=True)
    write_bag(tmp_path / "free", t, x, v, tau, imp, p=free)
    code, _out, err = run(capsys, tmp_path / "free")
    assert code == 2 and "no impact" in _one_error_line(err)


def test_a_state_stream_without_phase_reference_is_bad_input(tmp_path, capsys):
    with BagWriter(tmp_path / "b") as bag:
        bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
        for j in range(40):
            bag.write("/oscillator/state", _joint_state(j * 10**8, 0.1 * j, 0.1, []), j)
    code, _out, err = run(capsys, tmp_path / "b")
    assert code == 2 and "no phase reference" in _one_error_line(err)


# ---------------------------------------------------------------------------- --params
def test_params_fill_what_the_command_line_leaves(tmp_path):
    f = tmp_path / "m.yaml"
    f.write_text("/**:\n  ros__parameters:\n    zeta: 0.02\n    r: 0.5\n    omega: 0.7\n"
                 "    delta_d: -1.0e-05\n")
    argv = ["orbit", "--params", str(f), "--r", "0.6", "--delta-d=-2e-5"]
    args = build_parser().parse_args(argv)
    apply_to_args(args, argv)
    assert (args.zeta, args.r, args.omega, args.delta_d) == (0.02, 0.6, 0.7, -2e-5)
    assert not hasattr(args, "params")
    argv = ["run", "--params", str(f), "--sim-param", "zeta:=0.03"]
    args = build_parser().parse_args(argv)
    apply_to_args(args, argv)
    assert args.sim_overrides == {"zeta": "0.03", "r": 0.5, "omega": 0.7, "delta_d": -1e-5}


def test_a_bad_params_file_is_one_error_line(tmp_path, capsys):
    f = tmp_path / "m.yaml"
    f.write_text("/**:\n  ros__parameters:\n    zeta: fast\n")
    assert main(["design", "--c2", "-1", "--params", str(f)]) == 2
    assert "zeta='fast' is invalid" in _one_error_line(capsys.readouterr().err)
    f.write_text("/**:\n  ros__parameters:\n    mode: lockstep\n")
    assert main(["design", "--c2", "-1", "--params", str(f)]) == 2
    assert "no model parameter" in _one_error_line(capsys.readouterr().err)


def test_design_on_the_pole_of_the_existence_coefficient(capsys):
    """The parameters identified from bags/scene_5e-6 once put the c2 root search exactly on
    the pole of gamma1 (D9): a ZeroDivisionError, status 2."""
    assert main(["design", "--c2", "-1", "--json", "--zeta", "0.009999999999931803", "--r",
                 "0.6799999999999659", "--omega", "0.6671333324999374"]) == 0
    assert json.loads(capsys.readouterr().out)["admissible"] is True

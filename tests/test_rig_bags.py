"""Bags of a rig scene (grazing/rig on the bag): ``grazing analyze`` and ``grazing identify``
in SI as well (recordings/rig_record.py, docs/rig.md "Recordings").

The bags are written here: the recorded scene bags/scene_5e-6 copied message by message
(rosbags' reader and writer) with a grazing/rig record added, and the identification
scene of tests/identification_scenes.py (the exact motion) through the package's
BagWriter with one. No ROS scene is started. The SI numbers are checked against the
dimensionless ones times the rig's scales computed here by hand, and the identified SI
model against the rig the motion was made on, its standard errors against the delta
method done by finite differences of rig_with_model.
"""

import json
import math

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from grazing_control.cli.commands import main
from grazing_control.oscillator.params import OscillatorParams, study_omega
from grazing_control.plant.rig import load_rig, rig_from_dict, rig_to_dict, rig_with_model
from grazing_control.recordings.rig_record import read_rig
from grazing_control.ros.recording import BagWriter

from bagtools_helpers import BAGS, TYPESTORE, string
from identification_scenes import SCENE, exact_motion
from rig_files import LAB, dump

_NS = 1_000_000_000
#: The lab rig made to match bags/scene_5e-6's model (r 0.68, the study's set).
SCENE_RIG = rig_with_model(rig_from_dict(LAB), OscillatorParams(r=0.68, omega=study_omega(),
                                                                delta_d=-5e-6))


def _rig_cdr(text):
    return TYPESTORE.serialize_cdr(string(text), "std_msgs/msg/String")


def copy_with_rig(dst, text, topic="/grazing/rig", src=BAGS / "scene_5e-6"):
    """bags/scene_5e-6 with ``text`` on ``topic`` (None: none)."""
    with Reader(src) as r, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=TYPESTORE)
                 for c in r.connections}
        first = None
        for c, t, raw in r.messages():
            first = t if first is None else first
            w.write(conns[c.id], t, raw)
        if text is not None:
            w.write(w.add_connection(topic, "std_msgs/msg/String", typestore=TYPESTORE),
                    first, _rig_cdr(text))
    return dst


def _analyze(capsys, bag, out):
    assert main(["analyze", str(bag), "--json", "--no-figures", "--out", str(out)]) == 0
    return json.loads(capsys.readouterr().out)["bags"][0]


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    """(report of the bag with the rig, report of the same bag without one)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("rigbags")
    out = []
    for name, text in (("with", dump(rig_to_dict(SCENE_RIG))), ("without", None)):
        bag = copy_with_rig(tmp / name, text)
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main(["analyze", str(bag), "--json", "--no-figures", "--out",
                         str(tmp / f"out_{name}")]) == 0
        out.append(json.loads(buf.getvalue())["bags"][0])
        out.append((tmp / f"out_{name}" / "report.md").read_text())
    return out


def test_analyze_reports_the_main_numbers_in_si(analysed):
    entry, markdown, plain, plain_md = analysed
    rig = SCENE_RIG
    L = 0.5 * 0 + 50.0 / (0.5 * (2 * math.pi * 20) ** 2)   # F0 / k, by hand
    V = 2 * math.pi * 20 * L
    T = 1.0 / rig.frequency
    assert rig.natural_frequency == pytest.approx(20.0, rel=1e-14)
    assert rig.scales.length == pytest.approx(L, rel=1e-14)
    n, si = entry["scenes"][0], entry["scenes"][0]["si"]
    assert entry["rig"]["length_scale_m"] == pytest.approx(L, rel=1e-14)
    assert si["duration_s"] == pytest.approx(n["samples"] * T, rel=1e-14)
    assert si["control_on_after_s"] == pytest.approx(n["control_on_sample"] * T, rel=1e-14)
    assert si["converged_after_s"] == pytest.approx(n["samples_to_converge"] * T, rel=1e-14)
    x, v = n["final_pi2"]
    assert si["final_pi2_m_and_m_per_s"] == pytest.approx([x * L, v * V], rel=1e-14)
    ox, ov = n["predicted"]["orbit_pi2"]
    assert si["orbit_pi2_m_and_m_per_s"] == pytest.approx([ox * L, ov * V], rel=1e-14)
    c = si["largest_correction"]
    dv = n["corrections"]["max_abs"] * V
    assert c["velocity_m_per_s"] == pytest.approx(dv, rel=1e-14)
    assert c["impulse_N_s"] == pytest.approx(0.5 * dv, rel=1e-14)
    assert c["force_N"] == pytest.approx(0.5 * dv / 2e-3, rel=1e-14)
    # the spread about the exact controlled orbit: the lockstep scene sits on it
    assert max(si["pi2_spread_m_and_m_per_s"]) < 1e-12
    assert not any("rig mismatch" in s for s in entry["notes"])
    assert "* rig (grazing/rig): m = 0.5 kg, f_n = 20 Hz" in markdown
    assert "* in SI: largest correction Δv" in markdown
    assert "/grazing/rig" not in "".join(s for s in entry["notes"] if "other topics" in s)
    # without the rig: the same numbers, none in SI
    assert plain["rig"] is None and "si" not in plain["scenes"][0]
    assert "in SI" not in plain_md
    same = dict(n)
    same.pop("si")
    assert json.dumps(same, sort_keys=True) == json.dumps(plain["scenes"][0], sort_keys=True)


def test_a_rig_that_disagrees_with_the_run_is_noted(tmp_path, capsys):
    bag = copy_with_rig(tmp_path / "b", dump(LAB))          # r 0.7, the run's 0.68
    entry = _analyze(capsys, bag, tmp_path / "out")
    assert any("rig mismatch: the rig gives r = 0.7, the run's parameters 0.68" in s
               for s in entry["notes"])
    assert "si" in entry["scenes"][0]


@pytest.mark.parametrize("text,why", [("mass: 1\n", "cannot be used"),
                                      ("a: [b\n", "cannot be used"),
                                      (dump(dict(LAB, gap="-1 mm")), "gap=")])
def test_a_broken_rig_is_a_note_and_the_analysis_goes_on(tmp_path, capsys, text, why):
    bag = copy_with_rig(tmp_path / "b", text)
    entry = _analyze(capsys, bag, tmp_path / "out")
    assert entry["rig"] is None and "si" not in entry["scenes"][0]
    assert any(why in s and "/grazing/rig" in s for s in entry["notes"]), entry["notes"]


def test_a_rig_under_a_namespace_is_found(tmp_path):
    bag = copy_with_rig(tmp_path / "b", dump(LAB), topic="/lab/grazing/rig")
    rig, notes = read_rig(bag)
    assert rig == rig_from_dict(LAB) and "/lab/grazing/rig" in notes[0]


# ------------------------------------------------------------------ identify
def _string_cdr(text):
    return TYPESTORE.serialize_cdr(string(text), "std_msgs/msg/String")


def _joint_state(t_ns, x, v, effort):
    T = TYPESTORE.types
    msg = T["sensor_msgs/msg/JointState"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=int(t_ns // _NS), nanosec=int(t_ns % _NS)), frame_id=""),
        name=["mass"], position=np.array([x]), velocity=np.array([v]),
        effort=np.array(effort, float))
    return TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/JointState")


def _vector3(t_ns, a, b, c):
    T = TYPESTORE.types
    msg = T["geometry_msgs/msg/Vector3Stamped"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=int(t_ns // _NS), nanosec=int(t_ns % _NS)), frame_id=""),
        vector=T["geometry_msgs/msg/Vector3"](x=a, y=b, z=c))
    return TYPESTORE.serialize_cdr(msg, "geometry_msgs/msg/Vector3Stamped")


#: A rig whose model is the identification scene's (Delta d = -0.05: impacts of every size).
ID_RIG = rig_with_model(rig_from_dict(LAB), SCENE)


def identification_bag(path, rig_text=None, periods=24):
    """The exact motion of SCENE (tests/identification_scenes.py) as sim_node records it,
    with ``rig_text`` on grazing/rig."""
    t, x, v, tau, imp, _corr = exact_motion(SCENE, periods, ns=True)
    with BagWriter(path) as bag:
        if rig_text is not None:
            bag.add_topic("/grazing/rig", "std_msgs/msg/String")
            bag.write("/grazing/rig", _string_cdr(rig_text), 0)
        bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
        for j, s in enumerate(np.round(t * 1e9).astype(np.int64)):
            bag.write("/oscillator/state", _joint_state(s, x[j], v[j], [math.cos(tau[j]),
                                                                        math.sin(tau[j])]), int(s))
        bag.add_topic("/oscillator/impact", "geometry_msgs/msg/Vector3Stamped")
        for ti, vm, vp, ph in imp:
            s = int(round(ti * 1e9))
            bag.write("/oscillator/impact", _vector3(s, vm, vp, ph), s)
    return path


def _identify(capsys, *argv):
    code = main(["identify", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def id_bags(tmp_path_factory):
    """(bag with the rig, bag without, identify --json --out-rig of the first, the file)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("idbags")
    with_rig = identification_bag(tmp / "with", dump(rig_to_dict(ID_RIG)))
    out = tmp / "fitted.yaml"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["identify", str(with_rig), "--json", "--out-rig", str(out)]) == 0
    return with_rig, identification_bag(tmp / "without"), json.loads(buf.getvalue()), out


def test_identify_reports_the_model_in_si_and_writes_a_rig_file(id_bags):
    _with, _without, r, out = id_bags
    si = r["si"]
    assert r["rig_from"].endswith("(grazing/rig)") and r["out_rig"] == str(out)
    # the exact motion: the SI model is the rig the motion was made on
    assert si["natural_frequency_Hz"]["value"] == pytest.approx(ID_RIG.natural_frequency, rel=1e-8)
    assert si["damping_ratio"]["value"] == pytest.approx(ID_RIG.zeta, rel=1e-8)
    assert si["restitution"]["value"] == pytest.approx(ID_RIG.restitution, rel=1e-8)
    assert si["gap_m"]["value"] == pytest.approx(ID_RIG.gap, rel=1e-8)
    # standard errors: f_n = f / omega by hand; the gap by finite differences of
    # rig_with_model over the fit's covariance (the delta method, independently)
    par = r["parameters"]
    assert si["natural_frequency_Hz"]["stderr"] == pytest.approx(
        ID_RIG.frequency * par["omega"]["stderr"] / par["omega"]["value"] ** 2, rel=1e-9)
    assert si["damping_ratio"]["stderr"] == par["zeta"]["stderr"]
    names, cov = r["covariance"]["names"], np.array(r["covariance"]["matrix"])
    assert names == ["zeta", "r", "omega", "d"]
    base = {k: par[k]["value"] for k in names}

    def gap(vals):
        p = OscillatorParams(zeta=vals["zeta"], r=vals["r"], omega=vals["omega"])
        return rig_with_model(ID_RIG, p.with_(delta_d=vals["d"] - p.d_star)).gap

    grad = []
    for k in names:
        h = 1e-6 * abs(base[k])
        up, down = dict(base), dict(base)
        up[k] += h
        down[k] -= h
        grad.append((gap(up) - gap(down)) / (2 * h))
    grad = np.array(grad)
    assert si["gap_m"]["stderr"] == pytest.approx(math.sqrt(grad @ cov @ grad), rel=1e-5)
    assert si["gap_m"]["stderr"] > 0
    # the rig file: the bag's rig with the fitted model
    fitted = load_rig(out)
    assert fitted.natural_frequency == pytest.approx(si["natural_frequency_Hz"]["value"], rel=1e-14)
    assert fitted.gap == pytest.approx(si["gap_m"]["value"], rel=1e-12)
    for same in ("mass", "frequency", "amplitude", "phase", "sensor", "actuator", "budget"):
        assert getattr(fitted, same) == getattr(ID_RIG, same)
    assert "rig identified by `grazing identify`" in out.read_text()


def test_identify_takes_rig_when_the_bag_has_none(id_bags, capsys, tmp_path):
    _with, without, from_bag, _ = id_bags
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(dump(rig_to_dict(ID_RIG)))
    code, text, err = _identify(capsys, without, "--json", "--rig", rig_file)
    assert code == 0, err
    r = json.loads(text)
    assert r["rig_from"] == "--rig"
    assert r["si"] == from_bag["si"]
    # the text report has the SI lines too
    code, text, _ = _identify(capsys, without, "--rig", rig_file)
    assert "in SI, with the rig of --rig" in text and "gap_m" in text


def test_identify_without_any_rig_has_no_si_and_refuses_out_rig(id_bags, capsys, tmp_path):
    _with, without, _r, _out = id_bags
    code, text, _ = _identify(capsys, without, "--json")
    assert code == 0 and "si" not in json.loads(text)
    code, text, err = _identify(capsys, without, "--out-rig", tmp_path / "x.yaml")
    assert code == 2 and text == "" and err.count("\n") == 1
    assert "--out-rig" in err and "give --rig FILE" in err
    assert not (tmp_path / "x.yaml").exists()
    code, _, err = _identify(capsys, without, "--rig", tmp_path / "missing.yaml")
    assert code == 2 and err.startswith("grazing: error: --rig ") and "no such file" in err

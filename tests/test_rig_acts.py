"""recordings/rig_acts.py: a rig scene's bag analysed by what acted (rig/applied).

Bags written in-process from the simulator's engine (:class:`grazing_control.plant.
engine.Engine`) as the simulated rig runs a wrong model's timed commands
(docs/driver_contract.md, "Off the rig's section"; sim_node/rig_io.py, plant/realtime.py):
the acceptance rig (config/rigs/acceptance.yaml), the controller's section 14.3 us
before the rig's and its count of sections one behind (as measured with zeta 5 % low),
each command's apply time its section + budget - w/2, its pulse starting there (the
start the rig computes from the nanosecond stamp), a few commands late (the previous
command's prediction acting at the carried start). The bag holds what a rig scene
records: Pi2, the controller's dimensionless answers, rig/force_pulse, rig/applied,
grazing/rig and the parameter record. The numbers expected are exact: the model check
at rounding with the recorded starts, the late answers the rig's, the offsets those
written. The same scene on the rig's grid analyses as without rig/applied.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from bagtools_helpers import TYPESTORE, string, twist_stamped, write_rosbags
from grazing_control.plant.engine import Engine
from grazing_control.plant.rig import load_rig, rig_to_dict
from grazing_control.plant.settings import settings_from_values
from grazing_control.recordings.analyze import analyze
from grazing_control.ros.rig_boundary import correction_of, first_section, force_of, sim_values
from grazing_control.ros.recording.record import encode

ROOT = Path(__file__).resolve().parents[1]
RIG = load_rig(ROOT / "config" / "rigs" / "acceptance.yaml")
WALL0 = 1_700_000_000_000_000_000
CLOCK_START = 1000.0
OFF_S = -14.3e-6                  # the controller's section less the rig's (s)
PERIODS, ON = 60, 5
LATE = (17, 18, 33)               # commands that come after their apply time
C1, C2 = -0.03233850167169667, 0.03257133014405418     # the scene's recorded gains


def _stamp(ns):
    t = TYPESTORE.types
    return t["builtin_interfaces/msg/Time"](sec=int(ns // 10**9), nanosec=int(ns % 10**9))


def _wrench(stamp_ns, fx, fy, fz, width, t_k):
    t = TYPESTORE.types
    v3 = t["geometry_msgs/msg/Vector3"]
    return t["geometry_msgs/msg/WrenchStamped"](
        header=t["std_msgs/msg/Header"](stamp=_stamp(stamp_ns), frame_id=""),
        wrench=t["geometry_msgs/msg/Wrench"](force=v3(x=fx, y=fy, z=fz),
                                             torque=v3(x=width, y=t_k, z=0.0)))


def _pi2(stamp_ns, x, v):
    t = TYPESTORE.types
    return t["sensor_msgs/msg/JointState"](
        header=t["std_msgs/msg/Header"](stamp=_stamp(stamp_ns), frame_id=""), name=["mass"],
        position=np.array([x]), velocity=np.array([v]), effort=np.zeros(0))


def _ns(seconds: float) -> int:
    return int(round(seconds * 1e9))


def _sec(ns: int) -> float:
    return ns // 10**9 + (ns % 10**9) * 1e-9          # as the nodes read a stamp


def rig_bag(path, off_s: float):
    """The scene (module docstring); ``off_s`` 0: the controller's model is the rig's.
    Returns the starts after their sections (model time) at which the pulses acted, and
    the rig's own instant."""
    vals = sim_values(RIG)
    vals.update({"sensor_noise": 0.0, "sensor_quantum": 0.0, "delta_d": RIG.params().delta_d})
    eng = Engine(settings_from_values(vals))
    p, wn = eng.p, RIG.omega_n
    delay, w_s = vals["actuation_delay"], RIG.actuator.pulse_width
    own = eng.actuation_start(delay)
    start0 = first_section(RIG, CLOCK_START)
    rig_time = lambda t: start0 + t / wn                          # noqa: E731
    shift = 1 if off_s < 0 else 0          # the controller's first section: one behind
    msgs, starts, carried, prediction = [], [], None, 0.0
    for k in range(PERIODS):
        ev = eng.sample()
        pub = WALL0 + _ns(ev.t / vals["time_scale"])
        dv = C1 * (ev.x - p.x_ref) + C2 * (ev.v - p.v_ref) if k >= ON else 0.0
        force = force_of(RIG, dv)
        t_c = rig_time(ev.t) + off_s                       # the controller's section (s)
        apply_ns = _ns(t_c + RIG.budget - w_s / 2.0)
        late = k in LATE and off_s != 0.0       # (the right model's all in time)
        if off_s == 0.0:
            rel, start_ns = None, _ns(rig_time(ev.t + own))
        elif late:                          # the prediction, at the carried start
            rel = carried
            start_ns = _ns(rig_time(ev.t + rel))
        else:
            rel = (_sec(apply_ns) - start0) * wn - ev.t     # sim_node/rig_io.py's start
            start_ns, carried = apply_ns, rel
        acted = correction_of(RIG, prediction if late else force, w_s)
        eng.begin_head(delay, rel)
        eng.actuate(acted, delay, rel)
        eng.end_period()
        starts.append(own if rel is None else rel)
        prediction = force
        stamp = _ns(ev.t)
        ctl_stamp = _ns((k - shift) * p.period)            # the controller's count
        cmd_pub = pub + (10_000_000 if late else 500_000)
        msgs += [("/oscillator/pi2", "sensor_msgs/msg/JointState", pub, _pi2(stamp, ev.x, ev.v)),
                 ("/rig/force_pulse", "geometry_msgs/msg/WrenchStamped", cmd_pub,
                  _wrench(apply_ns, force, force, 0.0, w_s, t_c)),
                 ("/rig/applied", "geometry_msgs/msg/WrenchStamped", pub + 4_000_000,
                  _wrench(start_ns, force_of(RIG, acted), float("nan"), 1.0 if late else 0.0,
                          w_s, rig_time(ev.t)))]
        if k >= shift:
            msgs.append(("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped",
                         cmd_pub + 1, twist_stamped(ctl_stamp, dv)))
    sim = {**vals, "mode": "realtime", "actuation": "auto", "jitter": 0.0,
           "clock_start": CLOCK_START, **{k: getattr(p, k) for k in
                                          ("zeta", "r", "omega", "delta_d", "pi2_offset")}}
    head = [("/grazing/parameters", "std_msgs/msg/String", WALL0 - 3,
             string(encode("/sim_node", sim))),
            ("/grazing/parameters", "std_msgs/msg/String", WALL0 - 2,
             string(encode("/controller_node", {"enable_after": ON, "c1": C1, "c2": C2,
                                                "actuation_delay": delay}))),
            ("/grazing/rig", "std_msgs/msg/String", WALL0 - 1,
             string(yaml.safe_dump(rig_to_dict(RIG), sort_keys=False)))]
    write_rosbags(path, head + sorted(msgs, key=lambda m: m[2]))
    return np.array(starts), own


def _analysed(bag, out):
    report = analyze([bag], out, figures=False)
    return report["bags"][0], (Path(out) / "report.md").read_text()


def _without_acts(src, dst):
    """The bag less rig/applied and rig/force_pulse: read as before rig_acts.py."""
    from rosbags.rosbag2 import Reader
    msgs = []
    with Reader(src) as r:
        for c, t, raw in r.messages():
            if c.topic not in ("/rig/applied", "/rig/force_pulse"):
                msgs.append((c.topic, c.msgtype, t, TYPESTORE.deserialize_cdr(raw, c.msgtype)))
    return write_rosbags(dst, msgs)


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("rig_acts")
    starts, own = rig_bag(d / "wrong", OFF_S)
    rig_bag(d / "right", 0.0)
    _without_acts(d / "wrong", d / "wrong_stamps")
    _without_acts(d / "right", d / "right_stamps")
    return d, (starts, own)


def test_the_wrong_models_pulses_are_re_integrated_at_their_recorded_starts(bags):
    d, (starts, own) = bags
    assert np.all(np.abs(starts - own - OFF_S * RIG.omega_n) < 1e-6)   # off its instant
    entry, _ = _analysed(d / "wrong", d / "out_wrong")
    n = entry["scenes"][0]
    mc = n["model_check"]
    assert mc["max_departure"] < 1e-12, mc
    assert mc["pulses_at_recorded_starts"] == PERIODS
    # matched by the controller's stamps, with the pulses at the rig's instant: departs
    before, _ = _analysed(d / "wrong_stamps", d / "out_wrong_stamps")
    assert before["scenes"][0]["model_check"]["max_departure"] > 1e-4


def test_late_answers_are_the_rigs_count_and_answer_times_are_the_commands(bags):
    d, _ = bags
    entry, text = _analysed(d / "wrong", d / "out_wrong")
    rt = entry["scenes"][0]["realtime"]
    assert rt["late_answers"] == len(LATE)
    assert rt["rig_applied"] == {"in_time": PERIODS - len(LATE), "predicted": len(LATE),
                                 "nothing": 0, "safe": 0}
    assert rt["answer_time_ms"]["p50"] == pytest.approx(0.5, abs=1e-6)
    assert rt["answer_time_ms"]["max"] == pytest.approx(10.0, abs=1e-6)
    c = entry["scenes"][0]["corrections"]
    assert c["answered"] == PERIODS and c["answers_matching_no_sample"] == 0
    before, _ = _analysed(d / "wrong_stamps", d / "out_wrong_stamps")
    assert before["scenes"][0]["realtime"]["answer_time_ms"]["p50"] > 70.0   # a period


def test_the_report_says_how_far_the_controllers_sections_are_off(bags):
    d, _ = bags
    entry, text = _analysed(d / "wrong", d / "out_wrong")
    off = entry["rig_commands_off_grid"]
    assert off["commands"] == PERIODS
    assert off["median_offset_s"] == pytest.approx(OFF_S, abs=1e-12)
    assert off["max_abs_offset_s"] == pytest.approx(-OFF_S, abs=1e-12)
    assert "the controller's sections are 14.3 us off the rig's (median -14.3 us" in text
    assert "its model is not the rig's" in text


def test_a_right_model_rig_bag_analyses_as_without_rig_applied(bags):
    d, _ = bags
    entry, text = _analysed(d / "right", d / "out_right")
    same, _ = _analysed(d / "right_stamps", d / "out_right_stamps")
    assert "rig_commands_off_grid" not in entry and "off the rig's" not in text
    a, b = (json.dumps(e["scenes"], sort_keys=True, default=str) for e in (entry, same))
    assert a == b
    assert entry["scenes"][0]["model_check"]["max_departure"] < 1e-12

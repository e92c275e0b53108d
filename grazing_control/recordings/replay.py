"""``grazing replay BAG --bag OUT``: a recording replayed through the real nodes.

Controller replay (the regression test of a controller change)
    The recorded Pi2 samples, with their stamps, are published to a real
    ``controller_node`` process started with the given gains (``--controller-params``;
    default: the controller's parameters from the bag's parameter record; a bag without
    one uses config/controller.yaml if its gains match the gains inferred from the
    recording, else the inferred gains). As fast as the controller answers (the default:
    each sample waits for its answer) or at the recorded timing scaled by ``--rate``. The
    answers are recorded to OUT (with the samples as recorded and the controller's
    parameter record) and compared with the bag's own corrections: with the same gains
    they must be bit-identical; with others, a table of the differences and what the new
    gains would have commanded (open loop: the samples stay those of the recording).
    An n-DOF scene's bag (issues 17, 32) is replayed the same way: its recorded Pi2
    messages (every coordinate) are published as recorded to a controller_node with the
    record's ``model_file`` and ``gains`` (or ``--controller-params``), the one law
    k^T (X - X**) of every n. A stream scene's controller (``pi2_source`` stream) reads
    no Pi2 samples: its recorded sensor stream is replayed instead
    (:mod:`.stream_replay`; ``--controller-params`` then goes over the recorded
    parameters, which keep its estimator and sensor).

Simulator replay (open loop)
    ``sim_node`` runs in lockstep with the bag's model parameters and initial state; this
    process answers each of its samples with the correction recorded for the same stamp.
    A lockstep bag is reproduced sample for sample (<= 1e-12; bit-identical when the
    parameters are the recorded ones); a realtime run, whose corrections acted at their
    arrival and not on Pi2, departs, and the report says from which sample and how fast.
    Recorded to ``OUT_sim``. An n-DOF scene's bag (issue 32) the same way: sim_node with
    the record's ``model_file``, ``delta_d``, noise, seeds and actuation, started at the
    bag's first recorded Pi2 state (``state0``, the 2n coordinates; the record's own
    ``state0`` where the first sample is it to rounding, so that the start is the
    recorded scene's bit for bit), answered with the recorded corrections; a lockstep
    bag's Pi2 samples are reproduced bit for bit (tests/test_ndof_nodes.py). A bag
    without the simulator's record (its model file) is refused in one line before
    anything starts.

Both need rclpy (the PyPI wheels or a sourced ROS 2); the nodes are started as processes
by :mod:`grazing_control.ros.launcher`, on a ROS domain of their own (``--domain-id``, default
random) so that no other scene can cross-talk.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from .analysis import fmt as _fmt
from .analyze import _jsonable, add_model_options, options_from_args
from .numbers import resolve_setup
from grazing_control.support.files import YamlFileError, read_yaml_file

from .reader import read_raw
from .replay_nodes import (ControllerRun, Session, bag_writer, claim, close, params_file, qos,
                           stamp_of, start_process)
from .scenes import load, parse_topic_option

__all__ = ["replay_controller", "replay_simulator", "add_arguments", "main"]

_NS = 1_000_000_000
#: Parameters of the record that are not the controller's or sim's own settings.
_NOT_SETTINGS = ("use_sim_time", "start_type_description_service")
#: The simulator's parameters of the record that its replay takes: the model, the start,
#: the noise, and how a correction acts (a pulse, its force limit, the actuator's lag and
#: latency) and the wall's drift: without the pulse a pulse scene's replay departed by
#: 1.6e-3 at its first correction.
SIM_KEYS = ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset", "x0", "v0", "noise", "seed",
            "fidelity", "actuation_delay", "actuation", "pulse_width", "force_limit",
            "actuator_bandwidth", "actuator_latency", "delta_d_drift", "contact",
            "contact_stiffness", "contact_damping", "friction", "friction_static")


# ---------------------------------------------------------------------- parameters
def _controller_values(data, setup, controller_params, notes):
    """(parameter file path or dict, description) for the replay's controller."""
    from grazing_control.ros.launcher import CONFIG_DIR

    if controller_params is not None:
        path = Path(controller_params)
        try:
            doc = read_yaml_file(path)
        except YamlFileError as exc:
            raise ValueError(f"--controller-params {exc}") from None
        try:
            values = dict(next(iter(doc.values()))["ros__parameters"])
        except (AttributeError, KeyError, StopIteration, TypeError):
            raise ValueError(f"--controller-params {path}: not a ROS parameter file "
                             "('/controller_node: ros__parameters: ...')") from None
        rec = (data.parameters.get("nodes", {}).get("controller_node") or [{}])[0]
        if rec.get("pi2_source") == "stream":   # its estimator, sensor and stream kept
            values = {**{k: v for k, v in rec.items() if k not in _NOT_SETTINGS}, **values}
            notes.append(f"{path}'s values over the recorded stream controller's parameters")
        if "enable_after" not in values:
            values["enable_after"] = _bag_enable_after(data)
            notes.append(f"{path} has no enable_after: the bag's, {values['enable_after']}")
        return values, f"{path}"
    rec = (data.parameters.get("nodes", {}).get("controller_node") or [None])[0]
    if rec is not None:
        values = {k: v for k, v in rec.items() if k not in _NOT_SETTINGS}
        return values, "the bag's parameter record (controller_node)"
    if setup is None:       # an n-DOF scene: its model file and gains are not inferred
        raise ValueError(f"{data.path}: an n-DOF scene without the controller's parameter "
                         "record: give --controller-params (its model_file and gains)")
    # no record: the package default if it is what the recording shows, else inferred
    default = CONFIG_DIR / "controller.yaml"
    doc = yaml.safe_load(default.read_text())
    values = dict(next(iter(doc.values()))["ros__parameters"])
    values["enable_after"] = _bag_enable_after(data)
    notes.append(f"no parameter record: enable_after = {values['enable_after']} from the first "
                 "non-zero correction")
    p = setup.params
    if p is not None:       # the model of this run (options, else inferred): its X**
        model = dict(zeta=p.zeta, r=p.r, omega=p.omega, pi2_offset=p.pi2_offset,
                     x_ref=p.x_ref, v_ref=p.v_ref)
        changed = sorted(k for k, v in model.items() if values.get(k) != v)
        values.update(model)
        if changed:
            notes.append(f"no parameter record: the controller's {', '.join(changed)} from this "
                         "run's model (the options, else inferred), not config/controller.yaml's")
    g = setup.gains
    if g is not None and math.isclose(g.c1, values["c1"], rel_tol=1e-9) and \
            math.isclose(g.c2, values["c2"], rel_tol=1e-9):
        notes.append(f"gains of {default} (c1 = {values['c1']!r}, c2 = {values['c2']!r}) match "
                     f"the gains inferred from the recording ({g.c1!r}, {g.c2!r}) to 1e-9: used")
        return values, f"{default} (matches the recording)"
    if g is None:
        raise ValueError(f"{data.path}: no parameter record and no corrections to infer the "
                         "gains from: give --controller-params")
    values.update(c1=float(g.c1), c2=float(g.c2))
    notes.append("gains inferred from the recording (not those of config/controller.yaml): "
                 "bit-identical answers are not expected")
    return values, "inferred from the recording"


def _bag_enable_after(data) -> int:
    """The controller's enable_after in the bag: its record, else the first non-zero answer."""
    rec = (data.parameters.get("nodes", {}).get("controller_node") or [{}])[0]
    if "enable_after" in rec:
        return int(rec["enable_after"])
    on = data.scenes[0].scene.correction.nonzero()[0]
    return int(on[0]) if on.size else -1


def _pi2_samples(data):
    """Every usable Pi2 sample of the bag in order: (stamp_ns, x, v)."""
    out = []
    for sd in data.scenes:
        out += list(zip(sd.stamp_ns.tolist(), sd.scene.pi2[:, 0].tolist(),
                        sd.scene.pi2[:, 1].tolist()))
    return out


def _is_ndof(data) -> bool:
    """Whether a loaded bag is an n-DOF scene's (recordings/analysis.is_ndof)."""
    from .analysis import is_ndof

    return is_ndof(data)


def _ndof_sim_record(bag, data) -> dict | None:
    """An n-DOF bag's simulator record (its ``model_file``), None for a 1-DOF bag;
    ValueError, one line, where the record or its model file is missing (the simulator
    replay cannot know the model)."""
    if not _is_ndof(data):
        return None
    rec = (data.parameters.get("nodes", {}).get("sim_node") or [None])[0]
    if rec is None or not rec.get("model_file"):
        raise ValueError(f"{bag}: an n-DOF scene ({data.joints} joints per Pi2 sample) "
                         "without the simulator's parameter record: its model_file is "
                         "unknown, so the simulator cannot be replayed; give --no-sim to "
                         "replay the controller")
    return rec


def _ndof_sim_values(rec: dict, sd, notes: list) -> dict:
    """sim_node's parameters for the replay of an n-DOF bag (module docstring): the
    record's model file and :data:`SIM_KEYS` that an n-DOF scene takes (those it refuses,
    plant.settings.NOT_WITH_MODEL_FILE, are at their defaults there), the injected
    measurement noise (it is in the published samples compared), and the start
    ``state0``: the first recorded Pi2 state X_0 (2n values), or the record's
    ``state0`` where X_0 is it to within 1e-12 (X_0 = X_p + (state0 - X_p) is state0 to
    rounding only; the record's is the recorded scene's start bit for bit). With
    velocity or measurement noise the first sample is not the state: the record's."""
    from grazing_control.plant.settings import NOT_WITH_MODEL_FILE

    values = {k: rec[k] for k in SIM_KEYS + ("measurement_noise",)
              if k in rec and k not in NOT_WITH_MODEL_FILE}
    values["model_file"] = str(rec["model_file"])
    first = [float(v) for v in sd.scene.pi2[0]]
    start = [float(v) for v in (rec.get("state0") or ())]
    noisy = float(rec.get("noise", 0.0) or 0.0) > 0.0 or float(
        rec.get("measurement_noise", 0.0) or 0.0) > 0.0
    if noisy:
        values["state0"] = start
        notes.append("velocity or measurement noise in the recorded scene: started at the "
                     "record's state0 (its first sample is not the state)")
    elif len(start) == len(first) and np.allclose(start, first, rtol=1e-12, atol=1e-12):
        values["state0"] = start
    else:
        values["state0"] = first
    return values


def replay_controller(bag, out, *, controller_params=None, rate=None, domain_id=None,
                      answer_timeout=2.0, topics=None, options=None, log_dir=None) -> dict:
    """Replay a bag's Pi2 samples through a real controller_node; compare (module doc).

    A bag whose controller estimated the sections from the sensor stream (``pi2_source``
    stream) replays its stream instead (:func:`.stream_replay.replay_stream`).
    Returns a dict: where the gains came from, counts, the comparison and the new
    controller's parameters. Raises ValueError for bad input, RuntimeError if the
    controller does not start.
    """
    from sensor_msgs.msg import JointState

    from builtin_interfaces.msg import Time

    data = load(bag, topics)
    ndof = _is_ndof(data)         # its model and gains: the record's (or the file's)
    setup = None if ndof else resolve_setup(data, options or {})
    notes = []
    values, source = _controller_values(data, setup, controller_params, notes)
    if values.get("pi2_source") == "stream":
        from .stream_replay import replay_stream

        return replay_stream(data, values, source, notes, out, setup=setup, rate=rate,
                             domain_id=domain_id, answer_timeout=answer_timeout,
                             log_dir=log_dir)
    samples = _pi2_samples(data)
    raw = read_raw(data.path, [data.present["pi2"]])
    with ControllerRun(out, domain_id=domain_id, log_dir=log_dir) as run:
        pub = run.publisher(JointState, "oscillator/pi2")
        run.start(values, [pub])
        run.writer.add_topic("/oscillator/pi2", "sensor_msgs/msg/JointState",
                             run.offered("/oscillator/pi2"))
        order = _pi2_raw_order(raw, data.present["pi2"])
        msg = JointState(name=["mass"])
        t0 = time.monotonic()
        logs = [sd.pi2_log_ns for sd in data.scenes]
        log_all = np.concatenate(logs) if logs else np.zeros(0)
        for i, (stamp, x, v) in enumerate(samples):
            if rate is not None:
                run.session.until(t0 + (log_all[i] - log_all[0]) / 1e9 / rate)
            sec, nsec = divmod(int(stamp), _NS)
            if ndof:          # every coordinate, as recorded
                pub.publish(order[i])
            else:
                msg.header.stamp = Time(sec=sec, nanosec=nsec)
                msg.position, msg.velocity = [x], [v]
                pub.publish(msg)
            run.writer.write("/oscillator/pi2", order[i], time.time_ns())
            if rate is None:
                run.wait_answer(stamp, answer_timeout)
        # the late answers: at a rate, or of a controller stalled past a sample's wait
        # (a fresh clone's suite: the last answer missing, 2026-11-29)
        run.collect_late([s[0] for s in samples], answer_timeout)
        run.finish({"source_bag": str(bag),
                    "rate": "as fast as possible" if rate is None else rate,
                    "gains_source": source})
    return {"gains_source": source, "notes": notes, "domain_id": run.domain_id,
            "samples_published": len(samples), "answers": len(run.answers),
            "comparison": compare_corrections(data, load(out), setup)}


def _pi2_raw_order(raw, topic):
    """The recorded CDR bytes of the usable Pi2 samples, in the order of :func:`load`."""
    from .reader import decode_joint_state, serialized

    cols = decode_joint_state(raw, topic)
    order = np.argsort(cols["log_time"], kind="stable")
    data = serialized(raw, topic)["data"]
    return [data[i] for i in order[cols["ok"][order]].tolist()]


def compare_corrections(orig, new, setup) -> dict:
    """Per-sample comparison of two bags' corrections, matched by sample stamp."""
    def table(d):
        st, dv, ans = [], [], []
        for sd in d.scenes:
            st.append(sd.stamp_ns)
            dv.append(sd.scene.correction)
            ans.append(sd.answered)
        return np.concatenate(st), np.concatenate(dv), np.concatenate(ans)

    s0, d0, a0 = table(orig)
    s1, d1, a1 = table(new)
    n = min(len(s0), len(s1))
    if n == 0 or not np.array_equal(s0[:n], s1[:n]):
        return {"error": "the replayed samples do not match the recording's stamps"}
    d0, d1, a0, a1 = d0[:n], d1[:n], a0[:n], a1[:n]
    both = a0 & a1
    same_bits = d0.view(np.int64) == d1.view(np.int64)
    diff = np.abs(d1 - d0)
    differ = both & ~same_bits
    on = np.flatnonzero(d0 != 0)
    on = int(on[0]) if on.size else n
    rec = (new.parameters.get("nodes", {}).get("controller_node") or [{}])[0]
    sat = rec.get("saturation", math.inf)
    sat = float(sat) if isinstance(sat, (int, float, str)) else math.inf
    out = {"samples": int(n), "answered_in_both": int(np.count_nonzero(both)),
           "missing_in_replay": int(np.count_nonzero(a0 & ~a1)),
           "bit_identical": int(np.count_nonzero(both & same_bits)),
           "differing": int(np.count_nonzero(differ)),
           "all_bit_identical": bool(np.count_nonzero(differ) == 0 and np.all(a1[a0])),
           "max_abs_difference": float(diff[both].max()) if np.any(both) else None,
           "rms_difference": float(np.sqrt(np.mean(diff[both] ** 2))) if np.any(both) else None,
           "first_differing_sample": int(np.flatnonzero(differ)[0]) if np.any(differ) else None,
           "original_control_on": on if on < n else None,
           "new_control_on": (int(np.flatnonzero(d1 != 0)[0]) if np.any(d1 != 0) else None),
           "new_gains": ({"gains": rec.get("gains")} if rec.get("model_file") else
                         {"c1": rec.get("c1"), "c2": rec.get("c2")}) if rec else None}
    phases = []
    for name, sl in (("before the original switch-on", slice(0, on)),
                     ("after the original switch-on", slice(on, n))):
        o, w = d0[sl], d1[sl]
        if o.size == 0:
            continue
        phases.append({"phase": name, "samples": int(o.size),
                       "original_max_abs": float(np.max(np.abs(o))),
                       "replay_max_abs": float(np.max(np.abs(w))),
                       "max_abs_difference": float(np.max(np.abs(w - o))),
                       "replay_saturation_hits": (int(np.count_nonzero(np.abs(w) >= sat))
                                                  if math.isfinite(sat) else 0)})
    out["phases"] = phases
    # what the new gains would do in closed loop, from the core
    g = rec.get("c1"), rec.get("c2")
    if setup is not None and setup.params is not None and None not in g:
        from grazing_control.oscillator.control import Gains
        from grazing_control.dynamics.orbits.orbits import orbit_11
        try:
            delay = float(rec.get("actuation_delay") or setup.actuation_delay or 0.0)
            orb = orbit_11(setup.params, Gains(float(g[0]), float(g[1]), delay),
                           branch="grazing")
            out["new_gains_controlled_orbit"] = {
                "multipliers": [complex(z) for z in orb.multipliers],
                "rho": float(np.max(np.abs(orb.multipliers))),
                "stable": bool(orb.stable), "pi2": list(orb.pi2)}
        except Exception as exc:
            out["new_gains_controlled_orbit"] = {"error": f"{type(exc).__name__}: {exc}"}
    return out


def replay_simulator(bag, out, *, domain_id=None, answer_timeout=2.0, topics=None,
                     options=None, log_dir=None) -> dict:
    """Replay a bag's corrections through sim_node in lockstep, open loop; compare."""
    from geometry_msgs.msg import TwistStamped
    from sensor_msgs.msg import JointState

    from grazing_control.ros.launcher import SIM_MODULE

    data = load(bag, topics)
    ndof = _ndof_sim_record(bag, data)
    sd = data.scenes[0]
    notes = []
    if len(data.scenes) > 1:
        notes.append(f"only scene 0 of {len(data.scenes)} is replayed through the simulator")
    if ndof is not None:          # an n-DOF scene: the record's model file, its start
        values = _ndof_sim_values(ndof, sd, notes)
        mode = str(ndof.get("mode", "lockstep"))
        delay = float(ndof.get("actuation_delay", 0.0) or 0.0)
        time_scale = float(ndof.get("time_scale", 1.0) or 1.0)
    else:
        setup = resolve_setup(data, options or {})
        if setup.params is None:
            raise ValueError(f"{bag}: Delta d unknown: give --delta-d for the simulator "
                             "replay")
        rec = (data.parameters.get("nodes", {}).get("sim_node") or [None])[0]
        values = {}
        if rec is not None:
            values = {k: rec[k] for k in SIM_KEYS if k in rec}
        for k in ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset"):
            values[k] = float(getattr(setup.params, k))
        if float(values.get("noise", 0.0) or 0.0) == 0.0:
            values["x0"], values["v0"] = float(sd.scene.pi2[0, 0]), float(sd.scene.pi2[0, 1])
        mode, delay, time_scale = setup.mode, setup.actuation_delay, setup.time_scale
    n = len(sd.stamp_ns)
    values.update(mode="lockstep", max_periods=n, state_period=0.0, exit_when_done=True,
                  wait_for_controller=True, wait_for_subscribers=0,
                  answer_timeout=float(answer_timeout))
    dv_of = dict(zip(sd.stamp_ns.tolist(), sd.scene.correction.tolist()))
    # a correction the simulator dropped at a deadline miss did not act: replay what did,
    # the prediction it substituted (on_miss predict) or 0 (on_miss drop)
    from .numbers import applied_corrections
    dropped = set(sd.missed_stamp_ns.tolist())
    applied = applied_corrections(sd)
    dv_of = dict(zip(sd.stamp_ns.tolist(), applied.tolist()))
    if dropped or sd.substituted:
        notes.append(f"{len(dropped)} samples had a deadline miss: their recorded answers did "
                     f"not act; replayed are the {len(sd.substituted)} predictions the "
                     "simulator substituted (oscillator/substituted) and 0 for the rest")
    out = Path(out)
    writer = bag_writer(out)
    domain_id, lock = claim(domain_id)
    log_dir = Path(log_dir) if log_dir else out
    proc = session = None
    unknown = [0]
    with tempfile.TemporaryDirectory(prefix="grazing_replay_sim_") as tmp:
        try:
            session = Session(domain_id, "grazing_replay_sim")
            node = session.node
            pub = node.create_publisher(TwistStamped, "controller/velocity_correction", qos())
            answer = TwistStamped()
            from grazing_control.ros.common import PUBLISHER_QOS
            from grazing_control.ros.recording.topics import qos_to_dict

            # offered_qos_profiles as the recorder stores them: the simulator's data
            # publisher (PUBLISHER_QOS) and this replay's correction publisher
            writer.add_topic("/oscillator/pi2", "sensor_msgs/msg/JointState",
                             [qos_to_dict(PUBLISHER_QOS)])
            writer.add_topic("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped",
                             [qos_to_dict(qos())])
            from rclpy.serialization import serialize_message

            def on_sample(msg_raw, info=None):
                key = stamp_of(msg_raw)
                writer.write("/oscillator/pi2", msg_raw, time.time_ns())
                dv = dv_of.get(key)
                if dv is None:
                    unknown[0] += 1
                    dv = 0.0
                answer.header.stamp.sec, answer.header.stamp.nanosec = divmod(key, _NS)
                answer.twist.linear.x = dv
                pub.publish(answer)
                writer.write("/controller/velocity_correction", _cdr(serialize_message(answer)),
                             time.time_ns())

            node.create_subscription(JointState, "oscillator/pi2", on_sample, qos(), raw=True)
            proc = start_process(SIM_MODULE, params_file(values, "sim_node", Path(tmp)), {},
                          domain_id, log_dir.parent / f"{out.name}_sim.log")
            timeout = 60.0 + n * answer_timeout
            end = time.monotonic() + timeout
            while proc.poll() is None and time.monotonic() < end:
                session.spin(0.05)
            session.wait_for(lambda: False, 0.3)
            if proc.poll() is None:
                raise RuntimeError(f"sim_node did not finish within {timeout:.0f} s")
            if proc.returncode != 0:
                raise RuntimeError(f"sim_node exited with status {proc.returncode}; see "
                                   f"{log_dir.parent / (out.name + '_sim.log')}")
        finally:
            close(proc, session, writer, lock)
    new = load(out).scenes[0]
    m = min(len(new.stamp_ns), n)
    dep = np.max(np.abs(new.scene.pi2[:m] - sd.scene.pi2[:m]), axis=1) if m else np.zeros(0)
    above = np.flatnonzero(dep > 1e-12)
    res = {"samples_recorded": n, "samples_replayed": int(len(new.stamp_ns)),
           "stamps_equal": bool(np.array_equal(new.stamp_ns[:m], sd.stamp_ns[:m])),
           "max_departure": float(dep.max()) if m else None,
           "bit_identical_samples": int(np.count_nonzero(
               np.all(new.scene.pi2[:m].view(np.int64) == sd.scene.pi2[:m].view(np.int64), axis=1))),
           "first_sample_above_1e-12": int(above[0]) if above.size else None,
           "samples_without_recorded_correction": unknown[0], "notes": notes,
           "mode": mode, "sim_parameters": values}
    if above.size:
        k0 = int(above[0])
        res["departure_at"] = {str(k): float(dep[k]) for k in
                               sorted({k0, min(k0 + 10, m - 1), min(k0 + 50, m - 1), m - 1})}
        if mode == "realtime" and (delay or 0.0) > 0.0:
            why = ("scheduled actuation: the simulator applied each correction "
                   f"{delay:g} after its sample, as this replay does, and the "
                   f"{len(dropped)} missed answers are replayed as what acted; a departure "
                   "here is not explained by the timing of the corrections: check the model "
                   "parameters and the simulator's fidelity")
        elif mode == "realtime":
            lat = sd.latency_s
            nz = np.flatnonzero(sd.scene.correction != 0)
            first_on = int(nz[0]) if nz.size else None
            why = ("in realtime the corrections acted at their arrival (latency "
                   + (f"p50 {np.median(lat) * 1e3:.3g} ms wall = {np.median(lat) * (time_scale or 1):.3g}"
                      " simulation time after Π2" if lat.size else "not recorded")
                   + "), the lockstep replay applies them on Π2 itself")
            if first_on is None or k0 < first_on:
                why += (f"; the departure starts at sample {k0}, before any non-zero correction "
                        f"(first at {first_on}): the realtime simulator splits each period at the "
                        "arrival of even a zero correction (the flow evaluated in two pieces), "
                        "which rounds differently, and the chaotic motion before control "
                        "amplifies that rounding")
            why += ("; once apart, the open-loop replay follows its own trajectory with "
                    "corrections computed for the recorded one")
        else:
            why = ("a lockstep bag should be reproduced: check the model parameters (the bag's "
                   "record or --delta-d ...) and the simulator's fidelity")
        res["why"] = why
    return res


def _cdr(buf) -> bytes:
    return bytes(buf)


# -------------------------------------------------------------------------- command
def add_arguments(parser) -> None:
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    parser.add_argument("--bag", dest="out", required=True, metavar="OUT",
                        help="record the replayed controller's answers here (the simulator "
                             "replay goes to OUT_sim)")
    parser.add_argument("--controller-params", default=None, metavar="FILE",
                        help="controller parameter file (`grazing design --out`); default: "
                             "the gains recorded in the bag (a stream scene's: FILE over its "
                             "recorded parameters)")
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=float, default=None, metavar="R",
                      help="publish at the recorded timing scaled by R (2: twice as fast)")
    pace.add_argument("--as-fast-as-possible", action="store_true",
                      help="each sample waits for its answer (the default)")
    parser.add_argument("--no-sim", action="store_true", help="skip the simulator replay "
                        "(required for an n-DOF bag without the simulator's parameter "
                        "record: its model file is unknown)")
    parser.add_argument("--no-controller", action="store_true",
                        help="skip the controller replay (OUT is then unused)")
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID of the replay (default: random in 110..230)")
    parser.add_argument("--answer-timeout", type=float, default=2.0,
                        help="wall seconds to wait for each answer (default 2)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_model_options(parser)


def main(args):
    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        raise ValueError(f"--rate={args.rate!r} is invalid: valid range is R > 0")
    if not (math.isfinite(args.answer_timeout) and args.answer_timeout > 0):
        raise ValueError(f"--answer-timeout={args.answer_timeout!r} is invalid: valid range "
                         "is > 0")
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise ValueError(f"--domain-id={args.domain_id} is invalid: valid range is 0..232")
    topics = parse_topic_option(args.topic)
    options = options_from_args(args)
    data = load(args.bag, topics)   # refuse a bad bag or output before starting anything
    if not args.no_sim:
        _ndof_sim_record(args.bag, data)      # an n-DOF bag needs its model file
    out = Path(args.out)
    for path, used in ((out, not args.no_controller),
                       (out.with_name(out.name + "_sim"), not args.no_sim)):
        if used and path.exists() and (not path.is_dir() or any(path.iterdir())):
            raise ValueError(f"--bag: {path} exists and is not an empty directory")
    result = {"bag": args.bag}
    if not args.no_controller:
        result["controller"] = replay_controller(
            args.bag, out, controller_params=args.controller_params, rate=args.rate,
            domain_id=args.domain_id, answer_timeout=args.answer_timeout, topics=topics,
            options=options)
    if not args.no_sim:
        result["simulator"] = replay_simulator(
            args.bag, out.with_name(out.name + "_sim"), domain_id=args.domain_id,
            answer_timeout=args.answer_timeout, topics=topics, options=options)
    if args.json:
        return _jsonable(result)
    print(format_result(result))
    return 0


def format_result(result) -> str:
    lines = []
    c = result.get("controller")
    if c:
        cmp_ = c["comparison"]
        what = "stream messages" if "stream" in c else "samples"
        lines.append(f"controller replay: gains from {c['gains_source']}; "
                     f"{c['samples_published']} {what} published, {c['answers']} answers")
        lines += [f"  note: {n}" for n in c["notes"]]
        if "stream" in c:           # a stream scene's replay (stream_replay.py)
            st, ans, est = c["stream"], c["answers_bytes"], c["estimates"]
            sent = ", ".join(f"{n} on /oscillator/{r}" for r, n in st["published"].items())
            lines.append(f"  the sensor stream replayed ({sent}): {st['answers_awaited']} "
                         "answers awaited, "
                         f"{st['answers_not_in_time']} not in time; answers by stamp "
                         f"{ans['bit_identical']} of {ans['recorded']} bit-identical, estimates "
                         f"{est['bit_identical']} of {est['recorded']} ({est['differing']} "
                         f"differ, {est['missing_in_replay']} missing)")
            if "why" in c:
                lines.append(f"  why: {c['why']}")
        if "error" in cmp_:
            lines.append(f"  {cmp_['error']}")
        else:
            verdict = ("BIT-IDENTICAL to the recorded corrections" if cmp_["all_bit_identical"]
                       else f"{cmp_['differing']} of {cmp_['answered_in_both']} answers differ")
            lines.append(f"  {verdict}; max |difference| {_fmt(cmp_['max_abs_difference'], '.3e')}, "
                         f"rms {_fmt(cmp_['rms_difference'], '.3e')}, first differing sample "
                         f"{_fmt(cmp_['first_differing_sample'])}, missing in the replay "
                         f"{cmp_['missing_in_replay']}")
            if not cmp_["all_bit_identical"]:
                lines.append("  | phase | samples | original max |Δv| | replay max |Δv| | "
                             "max |difference| | replay saturation hits |")
                lines.append("  |---|---|---|---|---|---|")
                for ph in cmp_["phases"]:
                    lines.append(f"  | {ph['phase']} | {ph['samples']} | "
                                 f"{ph['original_max_abs']:.4g} | {ph['replay_max_abs']:.4g} | "
                                 f"{ph['max_abs_difference']:.4g} | {ph['replay_saturation_hits']} |")
                o = cmp_.get("new_gains_controlled_orbit") or {}
                if "rho" in o:
                    lines.append(f"  new gains {cmp_['new_gains']}: controlled 1/1 orbit "
                                 f"|λ|max = {o['rho']:.5f} ({'stable' if o['stable'] else 'UNSTABLE'}) "
                                 "(core prediction, closed loop); switch-on at sample "
                                 f"{_fmt(cmp_['new_control_on'])}")
                elif o:
                    lines.append(f"  new gains: {o.get('error')}")
    s = result.get("simulator")
    if s:
        lines.append(f"simulator replay (lockstep, open loop, recorded corrections): "
                     f"{s['samples_replayed']} of {s['samples_recorded']} samples, max departure "
                     f"{_fmt(s['max_departure'], '.3e')}, {s['bit_identical_samples']} "
                     f"bit-identical, first above 1e-12: {_fmt(s['first_sample_above_1e-12'])}")
        lines += [f"  note: {n}" for n in s["notes"]]
        if "why" in s:
            lines.append(f"  departure {s.get('departure_at')}: {s['why']}")
    return "\n".join(lines)

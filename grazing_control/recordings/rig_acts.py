"""What acted at each section of a rig scene: ``rig/applied`` read back onto the Pi2 samples.

A rig scene (``grazing run --rig``, docs/rig_scene.md) records the rig's own account of
what acted (``rig/applied``, docs/driver_contract.md: one per section, ``header.stamp``
the pulse's start in the rig clock, ``wrench.force.x`` the force in N, ``force.z`` the
status 0 in time / 1 predicted / 2 nothing / 3 safe, ``torque.x`` the width,
``torque.y`` the rig's own section time) and the controller's commands
(``rig/force_pulse``, ``torque.y`` the section time of the controller's model,
``header.stamp`` its apply time). A controller whose model is not the rig's names
section times off the rig's Pi2 grid (docs/driver_contract.md, "Off the rig's
section"): its dimensionless answers on ``controller/velocity_correction`` are stamped
by its own count of sections, which need not be the rig's (the acceptance rig with
zeta 5 % low: 14 us early, and one section behind), and the rig acts each command at
its apply time, not at its own instant.

:func:`read_acts` reads both; :func:`apply_acts` then makes the scene's corrections
what acted at each rig section (the rig's section k is Pi2 sample k: the simulated rig
clock runs at rig time ``start`` + t / omega_n, ``start`` the first section at or after
``clock_start``, :class:`grazing_control.ros.rig_boundary.SimulatedClock`), each
sample's answer the command of its slot (for its publish time), the late answers the
rig's count (a command recorded for a section where a prediction or nothing acted), and
each pulse's start, model time after its section, the one the rig reports (the same
conversion of the same nanosecond stamp as the simulated rig's, so the model check
re-integrates each period as the rig did). A scene whose commands are all on the rig's
grid is left as it is (right-model bags analyse exactly as before).

The same for a rig of any number of masses: the rig's sections, slots and pulse starts
are its model's (:meth:`grazing_control.plant.rig.Rig.model`, its forcing period; for
one mass the 1-DOF study's, the same number), the correction of a force its actuated
mass's (:func:`grazing_control.ros.rig_boundary.correction_of`, the effective mass m_a);
the 1-DOF analysis and the n-DOF one (:func:`.analysis.ndof_scene_numbers`) read the
scene it leaves alike (its ``pulse_starts``, ``rig_late``, ``rig_status``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import reader

__all__ = ["APPLIED_TOPIC", "COMMAND_TOPIC", "read_acts", "apply_acts", "offgrid_line",
           "summary"]

APPLIED_TOPIC = "/rig/applied"
COMMAND_TOPIC = "/rig/force_pulse"
_NS = 1_000_000_000
WRENCH = "geometry_msgs/msg/WrenchStamped"
#: A command within this fraction of a forcing period of the rig's own section and
#: instant is the rig's own (sim_node/rig_io.py: the same tolerance).
ON_GRID = 1e-6


def _topic(raw, name: str) -> str | None:
    if name in raw.channels:
        return name
    found = sorted(t for t in raw.channels if t.endswith(name))
    return found[0] if len(found) == 1 else None


def _wrenches(raw, topic) -> dict:
    """WrenchStamped columns: stamp (ns), fx, fy, fz, tx, ty, publish_time, ok."""
    b, stamp, pos = reader.decode_stamped(raw, topic)
    p = reader._align(pos, 8)
    cols = {"stamp": stamp, "fx": b.f64(p), "fy": b.f64(p + 8), "fz": b.f64(p + 16),
            "tx": b.f64(p + 24), "ty": b.f64(p + 32), "publish_time": b.publish_time}
    ok = b.ok & np.isfinite(cols["fx"]) & np.isfinite(cols["ty"]) & (cols["tx"] > 0)
    return {k: v[ok] for k, v in cols.items()}


def _seconds(stamp_ns) -> np.ndarray:
    """Seconds of stamps as the nodes compute them (sec + nanosec * 1e-9)."""
    s = np.asarray(stamp_ns, np.int64)
    return (s // _NS).astype(float) + (s % _NS).astype(float) * 1e-9


def _carry(k, status, s, on, resolution) -> None:
    """A prediction acts at the expected start, the last answer's start after its section
    carried (plant/realtime.py), reported rounded to the stamp's nanosecond: where the
    reported start is that within ``resolution`` (model time), the carried one, in place."""
    carried = None
    for i in np.argsort(k, kind="stable"):
        if status[i] == 0:
            carried = None if on[i] else s[i]
        elif (status[i] == 1 and not on[i] and carried is not None
              and abs(s[i] - carried) <= resolution):
            s[i] = carried


def read_acts(bag, rig, sim: dict) -> dict | None:
    """What acted and what was commanded, per rig section (module docstring), or None
    (no ``rig/applied`` in the bag, or no rig).

    ``sim``: the simulator's parameter record (its ``clock_start``, default 1000 s, and
    ``actuation_delay``, the budget in model time). Returns a dict: ``period``, for
    ``rig/applied`` the arrays ``k`` (the rig's section), ``dv`` (the correction that
    acted, dimensionless), ``status``, ``start`` (model time after the section; NaN: the
    rig's own instant), and for the commands ``cmd_k`` (the section whose slot holds the
    apply time, -1: none), ``cmd_pub`` (publish time, ns), ``offset_s`` (the command's
    section time less the rig's nearest section, s), ``timed`` (any command or act off
    the grid).
    """
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.plant.schedule import slot
    from grazing_control.ros.rig_boundary import correction_of, first_section

    if rig is None:
        return None
    raw = reader.read_raw(Path(bag), topics=[APPLIED_TOPIC, COMMAND_TOPIC])
    at, ct = _topic(raw, APPLIED_TOPIC), _topic(raw, COMMAND_TOPIC)
    if at is None:
        return None
    if at != APPLIED_TOPIC:                 # under a namespace
        raw = reader.read_raw(Path(bag), topics=[t for t in (at, ct) if t])
    if ct is not None and raw.channels[ct].type != WRENCH:
        ct = None
    if raw.channels[at].type != WRENCH:
        return None
    try:
        clock_start = float(sim.get("clock_start", 1000.0))
        delay = float(sim.get("actuation_delay"))
    except (TypeError, ValueError):
        return None
    period, wn = rig.model().period, rig.omega_n
    start0 = first_section(rig, clock_start)
    width = rig.actuator.pulse_width * wn
    own = pulse_start(period, delay, width)
    room = period - width - rig.actuator.latency * wn
    tol = ON_GRID * period

    a = _wrenches(raw, at)
    t = (a["ty"] - start0) * wn
    k = np.rint(t / period).astype(np.int64)
    s = (_seconds(a["stamp"]) - start0) * wn - k * period
    on = np.abs(s - own) <= tol
    _carry(k, np.rint(a["fz"]), s, on, 1e-9 * wn)
    out = {"period": period, "k": k, "status": np.rint(a["fz"]).astype(np.int64),
           "dv": np.array([correction_of(rig, f, w) for f, w in zip(a["fx"], a["tx"])]),
           "start": np.where(on, np.nan, s)}
    c = _wrenches(raw, ct) if ct is not None else {key: v[:0] for key, v in a.items()}
    tc = (c["ty"] - start0) * wn
    sc = (_seconds(c["stamp"]) - start0) * wn
    near = np.rint(tc / period)
    out["offset_s"] = c["ty"] - (start0 + near * period / wn)
    out["cmd_k"] = np.array([-1 if (j := slot(x, period, room)) is None else j for x in sc],
                            np.int64)
    out["cmd_pub"] = c["publish_time"]
    off_cmd = (np.abs(tc - near * period) > tol) | (np.abs(sc - near * period - own) > tol)
    out["timed"] = bool(np.any(off_cmd) or np.any(~on))
    return out


def apply_acts(sd, acts: dict) -> None:
    """Make scene ``sd``'s corrections, answers and pulse starts what acted at each rig
    section (module docstring), in place; nothing when ``acts`` is on the rig's grid."""
    if acts is None or not acts["timed"]:
        return
    period = acts["period"]
    n = sd.stamp_ns.size
    ks = np.rint(sd.scene.t / period).astype(np.int64)
    index = {int(kk): i for i, kk in enumerate(ks.tolist())}
    dv = np.zeros(n)
    starts = np.full(n, np.nan)
    status = np.full(n, -1, np.int64)
    for kk, v, st, s in zip(acts["k"].tolist(), acts["dv"].tolist(),
                            acts["status"].tolist(), acts["start"].tolist()):
        i = index.get(kk)
        if i is None:
            continue
        status[i] = st
        starts[i] = s
        dv[i] = v if st in (0, 1) else 0.0
    answered = np.zeros(n, bool)
    pub = np.full(n, -1, np.int64)
    unmatched = dup = 0
    for kk, tp in zip(acts["cmd_k"].tolist(), acts["cmd_pub"].tolist()):
        i = index.get(kk) if kk >= 0 else None
        if i is None:
            unmatched += 1
        elif answered[i]:
            dup += 1
        else:
            answered[i], pub[i] = True, tp
    sd.scene.correction = dv
    sd.answered, sd.corr_pub_ns = answered, pub
    sd.unmatched_answers, sd.duplicate_answers, sd.conflicting_answers = unmatched, dup, 0
    sd.pulse_starts = starts
    sd.rig_late = int(np.count_nonzero(answered & (status >= 1)))
    sd.rig_status = {name: int(np.count_nonzero(status == code)) for code, name in
                     enumerate(("in_time", "predicted", "nothing", "safe"))}


def offgrid_line(acts: dict | None) -> str | None:
    """The report's line when the controller's commands are off the rig's grid: how far
    (median and largest), and that its model is not the rig's; None otherwise."""
    if acts is None or not acts["timed"] or acts["offset_s"].size == 0:
        return None
    off = acts["offset_s"] * 1e6
    med, big = float(np.median(off)), float(off[np.argmax(np.abs(off))])
    return (f"* the controller's sections are {abs(med):.3g} us off the rig's (median "
            f"{med:+.3g} us, largest {big:+.3g} us over {off.size} commands): its model is "
            "not the rig's; the corrections are read from rig/applied (what acted at each "
            "rig section) and each pulse re-integrated at its recorded start")


def summary(acts: dict | None) -> dict | None:
    """The off-grid numbers for report.json (None when on the grid)."""
    if acts is None or not acts["timed"]:
        return None
    off = acts["offset_s"]
    return {"commands": int(off.size),
            "median_offset_s": float(np.median(off)) if off.size else None,
            "max_abs_offset_s": float(np.max(np.abs(off))) if off.size else None,
            "timed_acts": int(np.count_nonzero(np.isfinite(acts["start"])))}

"""``grazing identify BAG...``: the model's parameters from recordings (issue 16 §1).

bag -> data -> fit -> report. :func:`load_recording` reads a bag's state stream
(``oscillator/state``: position [x], velocity [v] or empty, effort [cos tau] or
[cos tau, sin tau]; stamp = time; or the same samples in blocks on
``oscillator/state_block``, of one mass or n, expanded by
:func:`reader.decode_state_blocks`), its impacts (``oscillator/impact``: x = v-, y = v+,
z = phase) where recorded, its corrections (``controller/velocity_correction``, acting
at the sample's stamp + the simulator's ``actuation_delay`` from the parameter record)
into a :class:`grazing_control.dynamics.identification.Recording`;
:func:`identify_bags` fits each bag (:func:`grazing_control.dynamics.identification.identify`),
checks the fit (:mod:`grazing_control.dynamics.identification.checks`) and combines the
bags' estimates (inverse-variance weighted means). A bag of an n-DOF scene (its
parameter record's ``model_file`` of n > 1, or ``model``) is fitted by
:func:`identify_ndof`: the wall coordinate's modal parameters
(:mod:`grazing_control.dynamics.identification.modal_fit`), the corrections' sizes as the
kicks. The method is in docs/theory_identification.md (section 11 for n > 1).
"""

from __future__ import annotations

import math
import numpy as np

from grazing_control.dynamics.identification import IdentificationError, identify
from grazing_control.dynamics.identification.checks import verdict
from grazing_control.dynamics.identification.data import Recording, RecordingError
from grazing_control.ros.recording.record import run_parameters

from . import reader

__all__ = ["TOPICS", "load_recording", "identify_bag", "identify_bags", "combine",
           "format_report", "si_report", "PARAMETER_ORDER"]

#: Role -> default topic (the simulator's names in the root namespace).
TOPICS = {
    "state": "/oscillator/state",
    "state_block": "/oscillator/state_block",     # the stream in blocks (issue 30)
    "impact": "/oscillator/impact",
    "correction": "/controller/velocity_correction",
    "parameters": "/grazing/parameters",
    "latency": "/oscillator/latency",
}

#: The reported parameters: the study's (nondimensional), then the rig's.
PARAMETER_ORDER = ("zeta", "r", "omega", "delta_d", "d", "natural_frequency",
                   "forcing_amplitude", "forcing_phase")

_NS = 1_000_000_000


def _sim_parameters(raw, topic) -> dict:
    """The simulator's parameters at start from the bag's parameter record (docs/analysis.md,
    "Parameter record"); {} without one."""
    if raw.count(topic) == 0:
        return {}
    nodes = run_parameters(reader.decode_strings(raw, topic))["nodes"]
    for name, seq in nodes.items():
        if "sim" in name and seq:
            return dict(seq[0])
    return {}


def _on_arrival(sim) -> bool:
    """Whether the simulator applied corrections on arrival (realtime, docs/nodes.md)."""
    act = str(sim.get("actuation", ""))
    return sim.get("mode") == "realtime" and (
        act == "on_arrival" or (act == "auto" and not sim.get("actuation_delay", 0.0)))


def _arrival_instants(raw, topics, corrections, when, time_scale, notes):
    """On arrival a correction acts at its sample's stamp + the latency (wall seconds,
    ``oscillator/latency``, one per applied correction in sample order) x time_scale: the
    fit's start for each instant (the fit refines it between the samples around it)."""
    topic = topics.get("latency", "/oscillator/latency")
    lat = reader.decode_float64(raw, topic) if raw.count(topic) else None
    if lat is None or np.count_nonzero(lat["ok"]) != when.size:
        notes.append("corrections applied on arrival (realtime): their instants are fitted "
                     "from the Pi2 stamps (no latency per correction recorded)")
        return when
    notes.append(f"corrections applied on arrival (realtime): their instants are fitted from "
                 f"stamp + latency x time_scale ({time_scale:g})")
    order = np.argsort(corrections["stamp"], kind="stable")
    out = when.copy()
    out[order] = when[order] + lat["data"][lat["ok"]] * time_scale
    return out


def load_recording(bag, *, topics: dict | None = None, position_only: bool = False,
                   impacts: bool = True):
    """(Recording, notes, the simulator's parameter record) of one bag (module docstring).

    Raises RecordingError (or reader.BagReadError) when the bag has no usable state stream.
    """
    return _load(bag, topics, position_only, impacts)[:3]


def _load(bag, topics, position_only, impacts, coordinate=None):
    """:func:`load_recording`'s (Recording, notes, record) and the size of each of the
    recording's corrections (the kicks, for the n-DOF fit). The stream's position is
    coordinate ``coordinate(record)`` (an n-DOF bag's wall coordinate i_w), 0 when None."""
    topics = dict(TOPICS, **(topics or {}))
    raw = reader.read_raw(bag, topics=list(topics.values()))
    notes = list(raw.problems)
    stream = topics["state"]
    sim = _sim_parameters(raw, topics["parameters"])
    c = 0 if coordinate is None else coordinate(sim)
    if raw.count(stream) == 0 and raw.count(topics["state_block"]):
        stream = topics["state_block"]           # sim_node's stream_message block
        s = reader.decode_state_blocks(raw, stream, c)
        _streamed(bag, stream, int(s["masses"].max(initial=0)), c)
    elif raw.count(stream) == 0:
        raise RecordingError(f"{bag}: no messages on {topics['state']} nor "
                             f"{topics['state_block']} (the state stream; sim_node "
                             "publishes it every state_period > 0)")
    else:
        _streamed(bag, stream, reader.joint_count(raw, stream), c)
        s = reader.decode_joint_stream(raw, stream, c)
    ok = s["ok"]
    if not np.any(ok):
        raise RecordingError(f"{bag}: no decodable stream sample with a position on "
                             f"{stream}")
    if np.count_nonzero(~ok):
        notes.append(f"{np.count_nonzero(~ok)} state messages not decodable: skipped")
    stamp = s["stamp"][ok]
    order = np.argsort(stamp, kind="stable")
    stamp = stamp[order]
    if stamp.size > 1 and np.any(np.diff(stamp) <= 0):
        # a reset (time back to 0) or repeated stamps: keep the first increasing stretch
        cut = int(np.flatnonzero(np.diff(s["stamp"][ok]) <= 0)[0]) + 1
        notes.append(f"the state stream's stamps stop increasing after {cut} samples "
                     "(a simulator reset?): the first stretch is fitted")
        stamp = s["stamp"][ok][:cut]
        order = np.arange(cut)
    t0 = int(stamp[0])
    t = (stamp - t0) / _NS
    x = s["x"][ok][order]
    v = np.full(t.size, np.nan) if position_only else s["v"][ok][order]
    e0, e1 = s["e0"][ok][order], s["e1"][ok][order]
    if not np.all(np.isfinite(e0)):
        raise RecordingError(f"{bag}: the state stream carries no phase reference in "
                             "effort ([cos tau] or [cos tau, sin tau]) on every sample")
    it = vm = vp = np.zeros(0)
    if impacts and raw.count(topics["impact"]):
        im = reader.decode_vector3_stamped(raw, topics["impact"])
        k = im["ok"]
        it = (im["stamp"][k] - t0) / _NS
        vm, vp = im["vx"][k], im["vy"][k]
        o = np.argsort(it, kind="stable")
        it, vm, vp = it[o], vm[o], vp[o]
        keep = np.concatenate([[True], np.diff(it) > 0]) if it.size else np.zeros(0, bool)
        if np.count_nonzero(~keep):
            notes.append(f"{np.count_nonzero(~keep)} impacts with repeated stamps dropped")
        it, vm, vp = it[keep], vm[keep], vp[keep]
    elif impacts:
        notes.append(f"no impacts recorded on {topics['impact']}: found in the motion")
    corr = corr_dv = np.zeros(0)
    if raw.count(topics["correction"]):
        c = reader.decode_twist_stamped(raw, topics["correction"])
        delay = float(sim.get("actuation_delay", 0.0) or 0.0)
        when = (c["stamp"] - t0) / _NS + delay
        if _on_arrival(sim):
            when = _arrival_instants(raw, topics, c, when, float(sim.get("time_scale", 1.0)),
                                     notes)
        k = c["ok"] & (c["dv"] != 0.0)
        corr, first = np.unique(when[k], return_index=True)
        corr_dv = c["dv"][k][first]
    rec = Recording(t, x, v, e0, e1, it, vm, vp, corr)
    return rec, notes, sim, corr_dv


def _streamed(bag, stream, count: int, coordinate: int) -> None:
    """Raise RecordingError (one line naming the coordinates) when the stream's messages
    carry ``count`` positions, too few for coordinate ``coordinate`` (a sensor of other
    coordinates than the fitted one: an n-DOF model's wall coordinate i_w)."""
    if coordinate >= max(count, 1):
        carried = "coordinate 0" if count <= 1 else f"coordinates 0..{count - 1}"
        raise RecordingError(f"{bag}: the state stream {stream} carries the position of "
                             f"{carried} only; the model's wall coordinate i_w={coordinate} "
                             "is fitted (identification reads the wall coordinate's position)")


def _parameters(ident) -> dict:
    """The reported parameters: name -> {value, stderr} (:data:`PARAMETER_ORDER`)."""
    m = ident.model
    nd = ident.nondimensional
    out = {name: {"value": nd[name][0], "stderr": nd[name][1]}
           for name in ("zeta", "r", "omega", "delta_d", "d")}
    for name in ("natural_frequency", "forcing_amplitude", "forcing_phase"):
        out[name] = {"value": getattr(m, name), "stderr": ident.stderr[name]}
    out["forcing_phase"]["value"] = math.remainder(m.forcing_phase, 2.0 * math.pi)
    return {k: out[k] for k in PARAMETER_ORDER}


def _bag_model(sim, model):
    """(NdofModel, path) of an n-DOF bag: ``model`` (--model) or the parameter record's
    model_file; (None, None) for a 1-DOF bag."""
    path = str(model or sim.get("model_file", "") or "")
    if not path:
        return None, None
    from grazing_control.oscillator.ndof.model import load_model

    try:
        return load_model(path), path
    except (OSError, ValueError) as exc:
        raise RecordingError(f"model_file {path}: {exc} (the n-DOF bag's model: give "
                             "--model FILE, the model file it was recorded with)") from None


def identify_ndof(bag, rec, notes, sim, kicks, model, path, *, impacts=True,
                  max_arcs: int | None = 100, shrink: bool = False) -> dict:
    """The report of an n-DOF bag (n > 1): the wall coordinate's modal parameters
    (:func:`grazing_control.dynamics.identification.modal_fit.identify_modal`) with
    standard errors, the verdict, residuals, counts; ``_ident``, ``_model`` (the fit and
    the bag's model file, for ``--out-model``) are removed before printing."""
    from grazing_control.dynamics.identification.modal_fit import identify_modal, modal_verdict

    if not impacts or rec.impact_t.size == 0:
        raise IdentificationError(
            f"impacts: {bag} has no recorded impacts on oscillator/impact"
            + ("" if impacts else " (--no-impacts)") + ": the n-DOF fit starts from them "
            "(finding them in the motion is built for n = 1 only)")
    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.oscillator.ndof.forced import actuated_mass

    act = actuation(sim, model.period, notes)
    if act["width"] > 0.0 and act["force_limit"] > 0.0:     # the plant clips m_a dv / w
        ma = actuated_mass(NdofFlow.of(model))
        kicks = clipped(kicks, act, ma)
    ident = identify_modal(rec, model.n, correction_dv=kicks,
                           kick_on_wall=model.i_a == model.i_w, max_arcs=max_arcs,
                           shrink=shrink, width=act["width"],
                           time_constant=act["time_constant"], latency=act["latency"],
                           pulse_offset=act["pulse_offset"])
    check = modal_verdict(ident)
    names = ident.names + ("delta_d", "d_star")
    params = {k: {"value": ident.value(k), "stderr": ident.stderr[k]} for k in names}
    report = {
        "bag": str(bag), "n": model.n, "model_file": path, "parameters": params,
        "fit": check["fit"], "reasons": check["reasons"],
        "residuals": {"sigma": ident.sigma, "rms_x": ident.rms_x, "rms_v": None,
                      "constraint_rms": ident.constraint_rms, "dof": ident.dof,
                      **check["whiteness"]},
        "phase_reference": {"omega": ident.phase.omega, "omega_stderr": ident.phase.omega_stderr,
                            "tau0": ident.phase.tau0, "rms": ident.phase.rms},
        "samples": ident.samples_used, "samples_in_bag": int(rec.t.size),
        "arcs": ident.arcs_used, "impacts": ident.impacts_used, "impacts_from": "recording",
        "velocity": bool(rec.has_velocity), "converged": ident.converged,
        "kick_response": "fitted" if ident.problem.layout.actuator else (
            "the impact's (i_a = i_w)" if model.i_a == model.i_w else "not identified "
            "(no corrections)"),
        "notes": notes, "_ident": ident, "_model": model,
    }
    record = model_file_record(sim, model)
    if record:
        report["parameter_record"] = record
    return report


def actuation(sim: dict, period: float, notes: list) -> dict:
    """How the bag's corrections reached the mass, from its parameter record (docs/nodes.md):
    the force pulse's ``width`` (pulse_width), its start ``pulse_offset`` relative to the
    correction's time (stamp + actuation_delay; the engine's pulse_start: centred there,
    kept within [0, T - w)), the first-order actuator's ``time_constant`` (1 /
    actuator_bandwidth) and ``latency``, the ``force_limit``; a note when the record
    lacks them (the corrections are then fitted as kicks)."""
    from grazing_control.dynamics.simulation.actuation import pulse_start

    from .numbers import _actuator, _num

    if not sim:
        notes.append("no parameter record: the corrections are fitted as kicks at their "
                     "stamps (a force pulse or actuator the scene had is not modelled)")
    width = _num(sim.get("pulse_width"), 0.0) or 0.0
    width = width if math.isfinite(width) and width > 0.0 else 0.0
    limit = _num(sim.get("force_limit"), 0.0) or 0.0
    delay = _num(sim.get("actuation_delay"), 0.0) or 0.0
    act = _actuator(sim, notes)
    if width > 0.0 or act is not None and act.time_constant > 0.0:
        notes.append(f"the corrections' force modelled as the parameter record gives it: "
                     f"pulse width {width:g}, actuator time constant "
                     f"{act.time_constant if act else 0.0:g}, latency "
                     f"{act.latency if act else 0.0:g} (docs/theory_identification.md "
                     "section 12)")
    return {"width": width, "time_constant": act.time_constant if act else 0.0,
            "latency": act.latency if act else 0.0,
            "pulse_offset": pulse_start(period, delay, width) - delay,
            "force_limit": limit if math.isfinite(limit) and limit > 0.0 else 0.0}


def _num_or(value, default: float) -> float:
    """A positive finite number of the record, else ``default``."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        return default
    return value if math.isfinite(value) and value > 0.0 else default


def clipped(kicks, act: dict, mass: float = 1.0):
    """The impulses the plant delivered for the commanded ``kicks``: the pulse's force
    mass dv / w clipped to +-force_limit (dynamics/simulation/actuation.pulse_force)."""
    w, limit = act["width"], act["force_limit"]
    return np.clip(mass * np.asarray(kicks, float) / w, -limit, limit) * w / mass


def model_file_record(sim: dict, model) -> dict:
    """What an n-DOF bag's scene ran with, to set beside the fit: r of its model file (the
    simulator's own ``r`` parameter is the 1-DOF one, left at its default and unused in a
    model file's scene: plant/settings.NOT_WITH_MODEL_FILE) and the recorded delta_d."""
    record = {"r": float(model.r)} if model is not None else {}
    if "delta_d" in sim:
        record["delta_d"] = sim["delta_d"]
    return record


def identify_bag(bag, *, topics=None, position_only=False, impacts=True,
                 max_arcs: int | None = 100, shrink: bool = False, model=None) -> dict:
    """The report of one bag: parameters (value, stderr), fit verdict, residuals,
    re-simulation, counts, the parameter record (when the bag has one). A bag recorded
    with a model file of n > 1 (its parameter record's model_file, or ``model``) gets the
    n-DOF fit (:func:`identify_ndof`); n = 1 the 1-DOF fit.

    Raises IdentificationError / RecordingError / reader.BagReadError (bad input).
    """
    found = {}

    def wall(sim):                 # an n-DOF bag's stream is read at its wall coordinate
        found["model"] = _bag_model(sim, model)
        nominal = found["model"][0]
        return nominal.i_w if nominal is not None and nominal.n > 1 else 0

    rec, notes, sim, kicks = _load(bag, topics, position_only, impacts, wall)
    nominal, path = found["model"]
    if nominal is not None and nominal.n > 1:
        return identify_ndof(bag, rec, notes, sim, kicks, nominal, path, impacts=impacts,
                             max_arcs=max_arcs, shrink=shrink)
    from grazing_control.oscillator.params import OscillatorParams

    omega = _num_or(sim.get("omega"), OscillatorParams().omega)
    act = actuation(sim, 2.0 * math.pi / omega, notes)
    if act["width"] > 0.0 and act["force_limit"] > 0.0:
        kicks = clipped(kicks, act)
    ident = identify(rec, impacts="recorded" if impacts and rec.impact_t.size else "motion",
                     max_arcs=max_arcs, shrink=shrink, correction_dv=kicks,
                     width=act["width"], time_constant=act["time_constant"],
                     latency=act["latency"], pulse_offset=act["pulse_offset"])
    check = verdict(ident)
    report = {
        "bag": str(bag),
        "parameters": _parameters(ident),
        "fit": check["fit"],
        "reasons": check["reasons"],
        "residuals": {"sigma": ident.sigma, "rms_x": ident.rms_x,
                      "rms_v": ident.rms_v if math.isfinite(ident.rms_v) else None,
                      "constraint_rms": ident.constraint_rms, "dof": ident.dof,
                      **check["whiteness"]},
        "resimulation": check["resimulation"],
        "phase_reference": {"omega": ident.phase.omega, "omega_stderr": ident.phase.omega_stderr,
                            "tau0": ident.phase.tau0, "rms": ident.phase.rms,
                            "sin": bool(np.any(np.isfinite(rec.sin_tau)))},
        "samples": ident.samples_used, "samples_in_bag": int(rec.t.size),
        "arcs": ident.arcs_used, "impacts": ident.impacts_used,
        "impacts_from": "recording" if impacts and rec.impact_t.size else "motion",
        "velocity": bool(rec.has_velocity), "converged": ident.converged,
        "notes": notes,
    }
    record = {k: sim[k] for k in ("zeta", "r", "omega", "delta_d") if k in sim}
    if record:
        report["parameter_record"] = record
    cov = ident.nondimensional_covariance
    report["covariance"] = {"names": list(_SI_FROM),
                            "matrix": None if cov is None else cov[:4, :4].tolist()}
    return report


#: The nondimensional parameters the SI model is made of (their covariance is reported).
_SI_FROM = ("zeta", "r", "omega", "d")


def _bag_rig(bags, rig, notes):
    """(Rig, where from): the first bag's rig on grazing/rig, else ``rig`` (--rig)."""
    from .rig_record import read_rig

    found = []
    for b in bags:
        r, why = read_rig(b)
        notes += [f"{b}: {w}" for w in why if "cannot be used" in w or "type" in w]
        if r is not None:
            found.append((b, r))
    if found:
        if any(r != found[0][1] for _, r in found[1:]):
            notes.append("the bags carry different rigs: the first one's is used")
        return found[0][1], f"{found[0][0]} (grazing/rig)"
    if rig is not None:
        return rig, "--rig"
    return None, None


def si_report(result: dict, bags, rig=None) -> None:
    """Add the identified model in SI to ``result`` (``si``: natural frequency, damping
    ratio, restitution, gap with standard errors; ``rig_from``; ``_rig``: the rig file's
    Rig for --out-rig) where a bag carries its rig, or ``rig`` is given (docs/rig.md)."""
    from .rig_record import model_in_si

    notes = []
    found, where = _bag_rig(bags, rig, notes)
    if notes:
        result.setdefault("notes", [])
        result["notes"] = list(result["notes"]) + notes
    if found is None:
        return
    par = result["parameters"]
    values = {k: par[k]["value"] for k in _SI_FROM}
    cov = result.get("covariance", {}).get("matrix")
    if cov is None or "per_bag" in result:     # combined bags: their combined errors
        cov = np.diag([par[k]["stderr"] ** 2 for k in _SI_FROM])
    si = model_in_si(found, values, cov)
    result["si"] = si["parameters"]
    result["rig_from"] = where
    result["_rig"] = si["rig"]


def combine(reports) -> dict:
    """Inverse-variance weighted means of the bags' parameters (each parameter on its
    own; bags whose fit is poor are left out unless all are)."""
    use = [r for r in reports if r["fit"] == "good"] or list(reports)
    out = {}
    for name in PARAMETER_ORDER:
        vals = np.array([r["parameters"][name]["value"] for r in use])
        se = np.array([r["parameters"][name]["stderr"] for r in use])
        w = np.where((se > 0) & np.isfinite(se), 1.0 / np.where(se > 0, se, 1.0) ** 2, 0.0)
        if len(use) == 1 or not np.any(w > 0):
            out[name] = dict(use[0]["parameters"][name])
        else:
            out[name] = {"value": float(w @ vals / w.sum()), "stderr": float(w.sum() ** -0.5)}
    return out


def identify_bags(bags, **kwargs) -> dict:
    """Every bag's report, their combination and the overall verdict (the JSON of
    ``grazing identify``)."""
    reports = [identify_bag(b, **kwargs) for b in bags]
    if len(reports) > 1 and any(r.get("n", 1) > 1 for r in reports):
        raise IdentificationError("bags: several n-DOF bags are not combined: identify "
                                  "them one at a time")
    fit = "good" if all(r["fit"] == "good" for r in reports) else "poor"
    if len(reports) == 1:
        return dict(reports[0], bags=[reports[0]["bag"]])
    return {"parameters": combine(reports), "fit": fit,
            "reasons": [f"{r['bag']}: {why}" for r in reports for why in r["reasons"]],
            "bags": [r["bag"] for r in reports], "per_bag": reports}


def _fmt(name, entry):
    """One line of the text report: value and standard error."""
    v, s = entry["value"], entry["stderr"]
    s_text = "not identified" if not math.isfinite(s) else f"+- {s:.2g}"
    return f"  {name:18s} = {v:.12g}  {s_text}"


def _format_ndof(result: dict) -> str:
    """The text report of an n-DOF bag (:func:`identify_ndof`)."""
    lines = [f"identification of {result['bag']} (n = {result['n']}, model file "
             f"{result['model_file']}): fit {result['fit'].upper()}"]
    lines += [_fmt(n, e) for n, e in result["parameters"].items()]
    lines.append("  (the wall coordinate's modal parameters in the recording's units: "
                 "natural frequencies, damping ratios, its response (c, s) to a unit kick "
                 "on its own velocity (impacts) and on the actuated one (corrections), its "
                 "periodic response P_c cos tau + P_s sin tau; docs/theory_identification.md "
                 "section 11)")
    res = result["residuals"]
    lines.append(f"  {result['samples']} samples, {result['arcs']} arcs, {result['impacts']} "
                 f"impacts; noise sigma {res['sigma']:.3g}, residual lag-1 autocorrelation "
                 f"{res['lag1_autocorrelation']:.3f} ({res['z']:.1f} sigma); kick response "
                 f"{result['kick_response']}")
    if "parameter_record" in result:
        lines.append("    its parameter record: " + ", ".join(
            f"{k} = {v:.12g}" for k, v in result["parameter_record"].items()))
    lines += [f"    note: {n}" for n in result["notes"]]
    lines += [f"  poor fit: {why}" for why in result["reasons"]]
    return "\n".join(lines)


def format_report(result: dict) -> str:
    """The human-readable report."""
    if result.get("n", 1) > 1:
        return _format_ndof(result)
    lines = [f"identification of {', '.join(result['bags'])}: fit {result['fit'].upper()}"]
    lines += [_fmt(n, result["parameters"][n]) for n in PARAMETER_ORDER]
    lines.append("  (zeta, r, omega, delta_d, d: the study's nondimensional model; "
                 "natural_frequency, forcing_amplitude, forcing_phase: the recording's units)")
    if "si" in result:
        lines.append(f"  in SI, with the rig of {result['rig_from']} (its forcing, amplitude "
                     "and mass held):")
        lines += ["  " + _fmt(n, e) for n, e in result["si"].items()]
    for rep in result.get("per_bag", [result]):
        res, sim = rep["residuals"], rep["resimulation"]
        lines.append(f"  {rep['bag']}: {rep['samples']} samples, {rep['arcs']} arcs, "
                     f"{rep['impacts']} impacts ({rep['impacts_from']}); noise sigma "
                     f"{res['sigma']:.3g}, residual lag-1 autocorrelation "
                     f"{res['lag1_autocorrelation']:.3f} ({res['z']:.1f} sigma); one-period "
                     f"re-simulation RMS {sim['rms']:.3g} ({sim['ratio_to_noise']:.3g} x noise)")
        if "parameter_record" in rep:
            rec = rep["parameter_record"]
            lines.append("    its parameter record: " + ", ".join(f"{k} = {v:.12g}"
                                                             for k, v in rec.items()))
        lines += [f"    note: {n}" for n in rep["notes"]]
    lines += [f"  poor fit: {why}" for why in result["reasons"]]
    return "\n".join(lines)


def bad_input_types():
    """The exceptions that mean bad input (exit status 2)."""
    return (IdentificationError, RecordingError, reader.BagReadError, FileNotFoundError)

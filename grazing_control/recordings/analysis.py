"""Offline analysis of a control scene: numbers and figures from a recording alone.

A scene is what the nodes publish: the Pi2 samples (before correction), the
corrections that answered them, and the impacts. :class:`Scene` holds those arrays;
:func:`scene_from_bag` reads them from a recording (topics ``/oscillator/pi2``,
``/controller/velocity_correction``, ``/oscillator/impact``), and
:func:`scene_from_simulation` from a :class:`grazing_control.dynamics.simulation.simulate.SimulationResult`,
so the same numbers can be compared between the node run and the core.

Numbers (:func:`summarize`):

* ``control_on``: the first sample answered with a non-zero correction;
* ``uncontrolled_period``: the smallest p <= 64 with the last ``window`` samples before
  control p-periodic to a tolerance, or None (not periodic: chaotic or transient);
* ``samples_to_converge``: samples after ``control_on`` until every later sample stays
  within ``tol`` of the final one;
* ``final_pi2`` and ``final_impacts_per_period`` (1 for a 1/1 motion).

A model file's scene (any n; :func:`is_ndof`, :func:`ndof_scene_numbers`, issue 17), per
coordinate, from the bag alone. An n-DOF scene (sim_node with ``model_file``; docs/nodes.md,
"n-DOF scenes") records its Pi2 samples as JointState with n joints: :func:`grazing_control.recordings.scenes.load`
reads them as (N, 2n) arrays X_k = (x_0 .. x_{n-1}, v_0 .. v_{n-1}). The model and the
gains come from the bag's parameter record (the simulator's ``model_file`` and
``delta_d``, the controller's ``gains``, ``enable_after``, ``saturation``,
``actuation_delay``); the model file must still be readable at its recorded path (else
only the measured numbers are given, and the report says why). A rig scene names no
model file; read by what acted (its commands off the rig's grid, :mod:`.rig_acts`) its
model is the simulated rig's own (:func:`ndof_setup` with the rig).

Per scene (:func:`summarize` over the whole state, then):

* per coordinate: the range of each x_i, v_i over the uncontrolled samples before the
  switch-on (the attractor's extent) and the final sample;
* the measured contraction per sample after the switch-on
  (:func:`~grazing_control.recordings.numbers.measured_contraction`) against the largest
  Floquet multiplier |lambda|max of the controlled 1/1 orbit, found by Newton shooting
  (:func:`grazing_control.dynamics.orbits.shooting.find_periodic`) on
  :class:`grazing_control.dynamics.maps.modal_map.ModalMap` with the recorded gains and delay from the
  last sample; the final sample's distance to that orbit, per coordinate;
* the model check: every recorded period re-integrated by the core from the recorded
  sample with the recorded correction (at ``actuation_delay``; the simulator's calls,
  :mod:`grazing_control.plant.engine`), the largest departure from the next
  recorded sample (rounding level for a lockstep run; a deadline miss re-integrated
  with what acted, the prediction substituted or 0);
* realtime (:func:`ndof_realtime`): the numbers of :mod:`.timing` (latency, answers,
  misses, substitutions, sample lag) and, with actuation on arrival, its delay check by
  this model's period with each kick at its measured arrival.

The correction acts as the plant acted it (:func:`ndof_period`, from the simulator's
record: ``pulse_width``, ``force_limit``, ``actuator_bandwidth``, ``actuator_latency``;
issue 32): the kick, the force pulse, or the pulse through the first-order actuator with
the force carried from period to period; the controlled orbit is that map's fixed point
(through a lag on (z, F), :func:`_actuated_orbit`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Scene", "scene_from_bag", "scene_from_simulation", "summarize", "plot_scene",
           "fmt", "complex_text", "control_lines", "NdofSetup", "is_ndof", "ndof_setup",
           "ndof_scene_numbers", "ndof_realtime", "ndof_lines", "plot_ndof_scene",
           "coordinate_names"]

TOPIC_PI2 = "/oscillator/pi2"
TOPIC_CORRECTION = "/controller/velocity_correction"
TOPIC_IMPACT = "/oscillator/impact"


@dataclass
class Scene:
    """Arrays of one run: sample times, Pi2 states, corrections, impacts.

    Attributes
    ----------
    t : (N,) sample times; pi2 : (N, 2) states (x, v) before correction;
    correction : (N,) correction answering each sample (0 when none arrived);
    impacts : (M, 4) [time, v-, v+, phase].
    """

    t: np.ndarray
    pi2: np.ndarray
    correction: np.ndarray
    impacts: np.ndarray

    @property
    def impacts_per_period(self) -> np.ndarray:
        """Impacts between consecutive samples (the last period is open-ended)."""
        edges = np.append(self.t, np.inf)
        counts, _ = np.histogram(self.impacts[:, 0], bins=edges) if len(self.t) else (np.zeros(0), None)
        return counts.astype(int)


def _key(header):
    return header.stamp.sec, header.stamp.nanosec


def scene_from_bag(bag_dir) -> Scene:
    """Read a scene from a recording (see :mod:`grazing_control.ros.recording`).

    Corrections are matched to samples by their header stamp (the stamp of the
    sample they answer, spec ros.md); a sample without an answer gets 0.
    """
    from grazing_control.ros.recording import read_messages

    samples, corrections, impacts = [], {}, []
    try:
        for m in read_messages(bag_dir, topics=[TOPIC_PI2, TOPIC_CORRECTION, TOPIC_IMPACT]):
            msg = m.message
            if m.topic == TOPIC_PI2:
                if len(msg.position) and len(msg.velocity):     # else: not a sample, skipped
                    samples.append((_key(msg.header), msg.position[0], msg.velocity[0]))
            elif m.topic == TOPIC_CORRECTION:
                corrections[_key(msg.header)] = msg.twist.linear.x
            else:
                sec, nsec = _key(msg.header)
                impacts.append((sec + 1e-9 * nsec, msg.vector.x, msg.vector.y, msg.vector.z))
    except (OSError, ValueError):
        raise
    except Exception as exc:        # mcap's own errors, a schema that does not decode, ...
        raise ValueError(f"{bag_dir}: not a readable recording ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    if not samples:
        raise ValueError(f"{bag_dir}: no Pi2 samples on {TOPIC_PI2}: not a scene recording")
    samples.sort()
    impacts.sort()
    t = np.array([sec + 1e-9 * nsec for (sec, nsec), _x, _v in samples])
    corr = np.array([corrections.get(key, 0.0) for key, _x, _v in samples])
    return Scene(t, np.array([[x, v] for _k, x, v in samples]).reshape(-1, 2), corr,
                 np.array(impacts, dtype=float).reshape(-1, 4))


def scene_from_simulation(res) -> Scene:
    """The same arrays from a core simulation result."""
    n = len(res.pi2)
    t = np.arange(n) * res.params.period
    imp = res.impacts
    return Scene(t, res.pi2.copy(), res.corrections.copy(),
                 np.column_stack([imp[:, 1], imp[:, 3], imp[:, 4], imp[:, 2]]) if len(imp) else
                 np.zeros((0, 4)))


def _periodicity(x: np.ndarray, tol: float, max_period: int = 64):
    for p in range(1, max_period + 1):
        if len(x) <= p:
            return None
        if np.max(np.abs(x[p:] - x[:-p])) <= tol:
            return p
    return None


def summarize(scene: Scene, tol: float = 1e-8, window: int = 200) -> dict:
    """The scene's numbers (see the module docstring); JSON-serialisable."""
    n = len(scene.t)
    nonzero = np.flatnonzero(scene.correction != 0.0)
    on = int(nonzero[0]) if nonzero.size else None
    counts = scene.impacts_per_period
    before = scene.pi2[:on] if on is not None else scene.pi2
    period = _periodicity(before[-window:], tol) if len(before) >= 2 else None
    out = {
        "samples": n,
        "impacts": int(len(scene.impacts)),
        "control_on": on,
        "uncontrolled_period": period,
        "uncontrolled_impacts_per_period": _histogram(counts if on is None else counts[:on]),
        "samples_to_converge": None,
        "converge_tol": float(tol),
        "final_pi2": scene.pi2[-1].tolist() if n else None,
        "final_impacts_per_period": (int(counts[-2]) if n >= 2 else None),
        "final_v_minus": float(scene.impacts[-1, 1]) if len(scene.impacts) else None,
        "max_abs_correction": float(np.max(np.abs(scene.correction))) if n else 0.0,
    }
    if on is not None and n > on + 1:
        dist = np.max(np.abs(scene.pi2[on:] - scene.pi2[-1]), axis=1)
        outside = np.flatnonzero(dist > tol)
        conv = int(outside[-1] + 1) if outside.size else 0
        if conv < n - on - 1:
            out["samples_to_converge"] = conv
            tail = counts[on + conv:n - 1]
            out["final_impacts_per_period"] = int(np.round(np.mean(tail))) if tail.size else None
            out["one_impact_per_period_after_convergence"] = bool(tail.size and np.all(tail == 1))
    return out


def plot_scene(scene: Scene, title: str, path) -> None:
    """Four panels: Pi2 before/after control, Pi2 x per sample, impact velocities, corrections."""
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()

    summary = summarize(scene)
    on = summary["control_on"] if summary["control_on"] is not None else len(scene.t)
    k = np.arange(len(scene.t))
    fig, ax = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    a = ax[0, 0]
    a.plot(scene.pi2[:on, 0], scene.pi2[:on, 1], ".", ms=2, color="tab:red", label="before control")
    a.plot(scene.pi2[on:, 0], scene.pi2[on:, 1], ".", ms=3, color="tab:blue", label="after control")
    a.plot(*scene.pi2[-1], "k*", ms=10, label="final sample")
    a.set(xlabel="x on Π2", ylabel="v on Π2", title="Π2 samples")
    a.legend(fontsize=8)
    a = ax[0, 1]
    a.plot(k, scene.pi2[:, 0], ".", ms=2)
    a.axvline(on, color="k", lw=0.8, ls="--", label="control on")
    a.set(xlabel="sample k", ylabel="x on Π2", title="Π2 position per forcing period")
    a.legend(fontsize=8)
    a = ax[1, 0]
    if len(scene.impacts):
        period = np.median(np.diff(scene.t)) if len(scene.t) > 1 else 1.0
        a.semilogy((scene.impacts[:, 0] - scene.t[0]) / period, scene.impacts[:, 1], ".", ms=2)
    a.axvline(on, color="k", lw=0.8, ls="--")
    a.set(xlabel="time / T", ylabel="impact velocity v⁻", title="impact velocities")
    a = ax[1, 1]
    a.plot(k, scene.correction, ".-", ms=2, lw=0.5)
    a.set(xlabel="sample k", ylabel="Δv", title="velocity corrections")
    fig.suptitle(title)
    save_png(fig, path, dpi=110)


def _histogram(counts):
    """Impacts per period 0, 1, 2, ... as counts of periods (None for no period)."""
    counts = np.asarray(counts, dtype=np.int64)
    return np.bincount(counts).tolist() if counts.size else None


# ------------------------------------------------- report lines of every model (any n)
def convergence(samples, tol) -> str:
    """``samples_to_converge`` in words, with the tolerance it was measured to (the
    analysis's ``--tol``; None: the default 1e-8 of bags' numbers from before it was
    kept): "converged to 1e-08 after 15 samples", or, where a sample after the switch-on
    lies farther than ``tol`` from the last one to the end (a loop with noise, whose
    spread is above ``tol``), "not converged to 1e-08 by the end"."""
    tol = 1e-8 if tol is None else tol
    if samples is None:
        return f"not converged to {tol:g} by the end"
    return f"converged to {tol:g} after {samples} samples"


def fmt(v, spec=".4g") -> str:
    """A number of a report: "—" for None, ``spec`` for a float, str otherwise."""
    if v is None:
        return "—"
    if isinstance(v, float):
        return format(v, spec)
    return str(v)


def complex_text(z) -> str:
    """A multiplier, (re, im) or complex, as "re" or "re+imi" (6 digits)."""
    z = complex(*z) if isinstance(z, (list, tuple)) else complex(z)
    return f"{z.real:.6g}" if z.imag == 0 else f"{z.real:.6g}{z.imag:+.6g}i"


def control_lines(numbers: dict) -> list:
    """The report's lines on the control of a scene, the same for the 1-DOF and the n-DOF
    scenes: the switch-on (sample, time) and the samples to converge; the contraction per
    sample after it, measured
    (:func:`grazing_control.recordings.numbers.measured_contraction`) against the
    predicted orbit's |lambda|max and multipliers; the prediction's notes. ``numbers``:
    the scene's numbers (keys ``control_on_sample``, ``control_on_time_s``,
    ``samples_to_converge``, ``measured_contraction``, ``predicted``,
    ``contraction_relative_error``)."""
    n = numbers
    if n["control_on_sample"] is None:
        lines = ["* control never switched on (no non-zero correction)"]
    else:
        lines = [f"* control on at sample {n['control_on_sample']} (t = "
                 f"{n['control_on_time_s']:.6g} s); "
                 f"{convergence(n['samples_to_converge'], n.get('converge_tol'))}"]
    meas, pred, relative_error = (n["measured_contraction"], n["predicted"],
                                  n.get("contraction_relative_error"))
    if meas and meas.get("rho"):
        lines.append(f"* contraction per sample: measured ρ = {meas['rho']:.6f} (median ratio "
                     f"{meas['median_ratio']:.6f}, samples {meas['first']}–{meas['last']}); "
                     f"predicted |λ|max = {fmt(pred.get('rho'), '.6f')} "
                     f"(multipliers {', '.join(complex_text(z) for z in pred.get('multipliers', []))}); "
                     f"relative difference {fmt(relative_error, '.1e')}")
    elif meas:
        lines.append(f"* contraction: not measured ({meas.get('reason')})")
    for key in ("controlled_orbit_error", "uncontrolled_orbit_error", "note", "error"):
        if key in pred:
            lines.append(f"* prediction: {pred[key]}")
    return lines


# ------------------------------------------------- a model file's scene (any n)
@dataclass
class NdofSetup:
    """What an n-DOF run was: the model file and its model (None if unreadable), the
    gains, the controller's switches, the mode, and notes."""

    model_file: str
    model: object | None
    n: int
    gains: np.ndarray | None
    enable_after: int | None
    saturation: float
    actuation_delay: float
    mode: str
    notes: list = field(default_factory=list)
    pulse_width: float = 0.0      # the simulator's force pulse (0: the kick)
    force_limit: float = 0.0      # 0: none
    actuator: object | None = None  # the simulator's first-order actuator (None: ideal)
    time_scale: float | None = None  # realtime: the simulator's (None: estimated)
    on_arrival: bool = False      # realtime: each correction acted on its arrival
    drift: float = 0.0            # the simulator's delta_d_drift (per period; 0: none)


def is_ndof(data) -> bool:
    """Whether a loaded bag is an n-DOF scene: a simulator record with ``model_file``, or
    Pi2 samples with more than one joint."""
    sim = (data.parameters.get("nodes", {}).get("sim_node") or [{}])[0]
    return bool(sim.get("model_file")) or getattr(data, "joints", 1) > 1


def coordinate_names(n: int) -> list:
    """x0 .. x{n-1}, v0 .. v{n-1}: the columns of an n-DOF scene's Pi2 array."""
    return [f"x{i}" for i in range(n)] + [f"v{i}" for i in range(n)]


def _number(value, default):
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        else default


def ndof_setup(data, rig=None) -> NdofSetup:
    """The run's model and controller from the bag's parameter record (module docstring).
    ``rig``: the simulated rig whose scene the bag holds (a rig scene read by what acted,
    :mod:`.rig_acts`): without a model file its model is the rig's own
    (:meth:`grazing_control.plant.rig.Rig.model`, the simulator's)."""
    from grazing_control.oscillator.ndof.model import load_model

    from .numbers import drift_notes, recorded_drift

    nodes = data.parameters.get("nodes", {})
    sim = (nodes.get("sim_node") or [{}])[0]
    ctl = (nodes.get("controller_node") or [{}])[0]
    notes = drift_notes(sim)
    path = str(sim.get("model_file") or ctl.get("model_file") or "")
    model = None
    if not path and rig is not None:
        model = rig.model()
        notes.append(f"the model: the simulated rig's (grazing/rig, n = {model.n}), the "
                     "plant that acted")
    elif not path:
        notes.append("no model_file in the parameter record: measured numbers only")
    else:
        try:
            model = load_model(path)
        except (OSError, ValueError) as exc:
            notes.append(f"the model file {path!r} cannot be read now ({exc}): measured "
                         "numbers only")
    if model is not None and _number(sim.get("delta_d"), None) is not None:
        model = dataclasses.replace(model, delta_d=float(sim["delta_d"]))
    n = model.n if model is not None else max(getattr(data, "joints", 1), 1)
    gains = ctl.get("gains")
    gains = np.asarray(gains, float) if isinstance(gains, list) and len(gains) == 2 * n \
        else None
    if gains is None and ctl:
        notes.append("no gains of length 2n in the controller's record: no predicted orbit")
    enable_after = ctl.get("enable_after")
    enable_after = int(enable_after) if isinstance(enable_after, int) else None
    for name, seq in nodes.items():
        if len(seq) > 1:
            notes.append(f"{name} parameters changed during the run; the analysis uses the "
                         "values at start")
    from .numbers import _actuator
    from .timing import acts_on_arrival

    width = _number(sim.get("pulse_width"), 0.0)
    limit = _number(sim.get("force_limit"), 0.0)
    return NdofSetup(path, model, n, gains, enable_after,
                     _number(ctl.get("saturation"), math.inf),
                     _number(ctl.get("actuation_delay"), 0.0),
                     str(sim.get("mode") or "lockstep"), notes,
                     width if math.isfinite(width) and width > 0.0 else 0.0,
                     limit if math.isfinite(limit) and limit > 0.0 else 0.0,
                     _actuator(sim, notes) if width > 0.0 else None,
                     _number(sim.get("time_scale"), None),
                     sim.get("mode") == "realtime" and acts_on_arrival(sim),
                     recorded_drift(sim))


def ndof_period(setup: NdofSetup):
    """The plant's period as the simulator ran it (:mod:`grazing_control.plant.engine`):
    ``step(z, force, correction) -> (z', force', impacts)`` on Pi2 deviations, the
    correction the kick ``actuation_delay`` after the sample, or with ``pulse_width`` > 0
    the force pulse centred there
    (:func:`~grazing_control.dynamics.maps.modal_map.pulse_step`), through the simulator's
    first-order actuator when it had one
    (:func:`~grazing_control.dynamics.maps.modal_map.actuated_step`, the force on the
    actuated coordinate at the section carried from period to period; docs/theory_ndof.md
    section 15). ``force`` is 0 except through an actuator with a lag; the step takes, as
    a fourth argument, another time after the sample for the correction: the kick's
    delay (the realtime delay check, the correction at its arrival), or the pulse's start
    (a rig scene off the rig's grid, each pulse at its recorded start: :mod:`.rig_acts`),
    and as a keyword ``flow`` the flow of that period (:func:`ndof_flow_at`: a drifting
    wall's; default the model's).
    """
    from grazing_control.dynamics.maps.modal_map import actuated_step, pulse_step
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.oscillator.ndof.flow import NdofFlow
    from grazing_control.oscillator.ndof.impact import advance

    m = setup.model
    flow = NdofFlow.of(m)
    n, T, delay, w = m.n, m.period, setup.actuation_delay, setup.pulse_width
    limit = setup.force_limit or math.inf
    start = pulse_start(T, delay, w)
    act = setup.actuator
    if w > 0.0 and act is not None:
        def step(z, force, dv, start=start, flow=flow):
            return actuated_step(flow, z, force, dv, start=start, width=w,
                                 time_constant=act.time_constant, latency=act.latency,
                                 force_limit=limit)
    elif w > 0.0:
        def step(z, force, dv, start=start, flow=flow):
            out = pulse_step(flow, z, dv, start=start, width=w, force_limit=limit)
            return out.state, 0.0, list(out.impacts)
    else:
        def step(z, force, dv, delay=delay, flow=flow):
            tau, impacts = flow.tau2, []
            if delay > 0.0:
                head = advance(flow, tau, z, delay)
                z, impacts = head.z, list(head.impacts)
                tau = (tau + m.omega * delay) % (2.0 * math.pi)
            z = np.array(z, dtype=float)
            z[n + m.i_a] += dv
            tail = advance(flow, tau, z, T - delay)
            return tail.z, 0.0, impacts + list(tail.impacts)
    return flow, step


def ndof_flow_at(flow, drift: float, t: float):
    """The flow of the plant's period of the sample stamped ``t``: the model's wall at
    Delta d + drift k (k = :func:`~grazing_control.recordings.numbers.sample_index`),
    as the simulator moves it (plant.engine.Engine._drift_wall, k0 = 0:
    :meth:`~grazing_control.oscillator.ndof.section.NdofSection.with_delta_d`, the
    same expression, so bit for bit its wall); ``flow`` itself without a drift."""
    from .numbers import sample_index

    if not drift:
        return flow
    m = flow.model
    model = dataclasses.replace(m, delta_d=float(m.delta_d + drift * sample_index(
        t, m.period)))
    return dataclasses.replace(flow, model=model)


def ndof_model_check(setup: NdofSetup, scene, limit: int = 20000,
                     corrections=None, starts=None) -> dict | None:
    """Each recorded period re-integrated from its recorded sample and correction by the
    plant's period (:func:`ndof_period`): the largest departure from the next recorded
    sample (module docstring). Through an actuator with a lag the force at the section is
    not recorded: it is carried from 0 at the first sample (exact for a scene recorded
    from its start: the force follows the commands alone), and after a gap in the
    recording the later periods are not checked (``unchecked``). ``corrections``: what
    acted (default the recorded answers; :func:`~grazing_control.recordings.numbers.
    applied_corrections`: at a deadline miss the prediction substituted, or 0).
    ``starts``: per sample, the pulse's recorded start after it (a rig scene off the
    rig's grid, :func:`.rig_acts.apply_acts`; NaN: the simulator's rule), as
    :func:`~grazing_control.recordings.numbers.model_check` takes them. A drifting wall
    (``setup.drift``): each period at the plant's Delta d of that period
    (:func:`ndof_flow_at`)."""
    m = setup.model
    dvs = scene.correction if corrections is None else corrections
    if m is None or len(scene.t) < 2:
        return None
    flow, step = ndof_period(setup)
    T = m.period
    periods = min(len(scene.t) - 1, limit)
    worst, above, failed, unchecked, force = 0.0, 0, 0, 0, 0.0
    dep = np.full(periods, np.nan)         # per period (NaN: not checked, inf: failed)
    for k in range(periods):
        if force is None:
            unchecked += 1
            continue
        if not math.isclose(scene.t[k + 1] - scene.t[k], T, rel_tol=0.0, abs_tol=1e-6):
            # a gap in the recording: no next sample of this period, the force lost
            force = 0.0 if setup.actuator is None else None
            continue
        z = flow.to_deviation(flow.tau2, scene.pi2[k])
        at = ndof_flow_at(flow, setup.drift, scene.t[k])
        try:
            if starts is not None and math.isfinite(starts[k]):
                z, force, _ = step(z, force, float(dvs[k]), float(starts[k]), flow=at)
            else:
                z, force, _ = step(z, force, float(dvs[k]), flow=at)
        except (ValueError, ArithmeticError, RuntimeError):
            failed += 1
            dep[k] = np.inf
            force = 0.0 if setup.actuator is None else None
            continue
        d = dep[k] = float(np.max(np.abs(flow.to_physical(flow.tau2, z) - scene.pi2[k + 1])))
        worst = max(worst, d)
        above += d > 1e-12
    out = {"max_departure": worst, "periods": periods, "periods_above_1e-12": int(above),
           "periods_in_scene": len(scene.t) - 1, "failed": failed,
           "correction": _actuation_text(setup), "_departures": dep}
    if setup.drift:
        out["delta_d_drift"] = setup.drift
    if setup.actuator is not None:
        out["unchecked"] = unchecked
        out["final_force"] = force
    if starts is not None:
        out["pulses_at_recorded_starts"] = int(np.count_nonzero(np.isfinite(starts)))
    return out


def _actuation_text(setup: NdofSetup) -> str:
    """How the correction acted (for the report): the kick, the pulse, the actuator."""
    d, w, a = setup.actuation_delay, setup.pulse_width, setup.actuator
    if w <= 0.0:
        return f"the kick {d:g} after the sample"
    text = f"a force pulse of width {w:g} centred {d:g} after the sample"
    if setup.force_limit:
        text += f", clipped to ±{setup.force_limit:g}"
    if a is not None:
        text += (f", through the first-order actuator (tau_a {a.time_constant:.6g}, latency "
                 f"{a.latency:g}; the force carried from period to period)")
    return text


def _actuated_orbit(setup: NdofSetup, z0, force0: float | None, tol: float = 1e-13,
                    max_iter: int = 40):
    """The fixed point of the closed loop z -> step(z, k^T z) of :func:`ndof_period`,
    through an actuator with a lag on (z, F) (the force at the section a state of the
    loop, dimension 2n + 1; ``force0`` its guess, None without a lag), by Newton with a
    central-difference Jacobian (actuated_step, and pulse_step with a force limit, have
    none). Returns (y, that Jacobian at y, impacts)."""
    _, step = ndof_period(setup)
    g, n2 = setup.gains, len(z0)
    carry = force0 is not None
    dim = n2 + carry

    def loop(y):
        z, f, imps = step(y[:n2], float(y[n2]) if carry else 0.0, float(g @ y[:n2]))
        z = np.asarray(z, float)
        return (np.append(z, f) if carry else z), imps

    def jac(y):
        J = np.empty((dim, dim))
        for j in range(dim):
            h = 1e-7 * max(1.0, abs(y[j]))
            e = np.zeros(dim)
            e[j] = h
            J[:, j] = (loop(y + e)[0] - loop(y - e)[0]) / (2.0 * h)
        return J

    y = np.asarray(z0, float) if not carry else np.append(np.asarray(z0, float),
                                                           float(force0))
    for _ in range(max_iter):
        fy, _ = loop(y)
        J = jac(y)
        dy = np.linalg.solve(J - np.eye(dim), -(fy - y))
        y = y + dy
        if np.max(np.abs(dy)) <= tol * max(1.0, float(np.max(np.abs(y)))):
            fy, imps = loop(y)
            if np.max(np.abs(fy - y)) > 1e-10:
                break
            return y, jac(y), imps
    raise RuntimeError(f"Newton on the actuated loop did not converge in {max_iter} steps")


def ndof_controlled_orbit(setup: NdofSetup, final, force: float | None = None) -> dict:
    """The exact controlled 1/1 orbit near the final sample, its multipliers and impacts:
    the fixed point of the plant's period (:func:`ndof_period`) with the recorded gains,
    the kick or the pulse by Newton shooting on
    :class:`~grazing_control.dynamics.maps.modal_map.ModalMap` (``width``), through an
    actuator with a lag on (z, F) (:func:`_actuated_orbit`, ``force`` the guess of F)."""
    from grazing_control.dynamics.maps.modal_map import ModalMap
    from grazing_control.dynamics.orbits.shooting import ShootingFailed, find_periodic

    if setup.model is None or setup.gains is None:
        return {"note": "no model or gains: no predicted orbit"}
    a = setup.actuator
    lag = a is not None and a.time_constant > 0.0
    # ModalMap has neither a force limit nor a latency: those loops through ndof_period
    newton = lag or (setup.pulse_width > 0.0 and (setup.force_limit or a is not None))
    P = ModalMap(setup.model, setup.gains, setup.actuation_delay)   # its section
    xref = P.flow.particular(P.flow.tau2)
    z0 = np.asarray(final, float) - xref
    try:
        if newton:
            y, J, imps = _actuated_orbit(setup, z0, (force or 0.0) if lag else None)
            state, mult = y[:len(z0)], np.linalg.eigvals(J)
        else:
            P = ModalMap(setup.model, setup.gains, setup.actuation_delay, setup.pulse_width)
            orbit = find_periodic(P, z0)
            state, imps, mult = orbit.state, orbit.impacts, np.linalg.eigvals(orbit.monodromy)
    except (ShootingFailed, ValueError, ArithmeticError, RuntimeError,
            np.linalg.LinAlgError) as exc:
        return {"error": f"no controlled 1/1 orbit found from the final sample ({exc})"}
    mult = mult[np.argsort(-np.abs(mult))]
    out = {"orbit_pi2": (xref + state).tolist(), "rho": float(np.abs(mult).max()),
           "multipliers": [[float(z.real), float(z.imag)] for z in mult],
           "orbit_impacts": len(imps),
           "orbit_v_minus": [float(i.v_minus) for i in imps],
           "correction": _actuation_text(setup)}
    if lag:
        out["orbit_force"] = float(y[-1])
    return out


def ndof_scene_numbers(sd, setup: NdofSetup, tol: float = 1e-8) -> dict:
    """The numbers of one n-DOF scene (the section "A model file's scene" of the module
    docstring); JSON-serialisable."""
    from .numbers import applied_corrections, measured_contraction

    scene = sd.scene
    base = summarize(scene, tol)
    on = base["control_on"]
    if setup.enable_after is not None and 0 <= setup.enable_after < len(scene.t):
        on = setup.enable_after if on is None or on > setup.enable_after else on
    names = coordinate_names(setup.n)
    before = scene.pi2[:on] if on is not None else scene.pi2
    tail = before[-200:]
    out = {"samples": base["samples"], "duration_s": float(scene.t[-1] - scene.t[0])
           if len(scene.t) else 0.0, "n": setup.n, "coordinates": names,
           "impacts": base["impacts"], "control_on_sample": on,
           "control_on_time_s": float(scene.t[on]) if on is not None else None,
           "uncontrolled": {"period": base["uncontrolled_period"],
                            "impacts_per_period_histogram":
                                base["uncontrolled_impacts_per_period"],
                            "range": {c: [float(tail[:, j].min()), float(tail[:, j].max())]
                                      for j, c in enumerate(names)} if len(tail) else {}},
           "samples_to_converge": base["samples_to_converge"],
           "converge_tol": base["converge_tol"],
           "final_pi2": dict(zip(names, base["final_pi2"] or [])),
           "final_impacts_per_period": base["final_impacts_per_period"],
           "corrections": {"answered": int(np.count_nonzero(sd.answered)),
                           "missing": int(np.count_nonzero(~sd.answered)),
                           "max_abs": base["max_abs_correction"],
                           "saturation": setup.saturation,
                           "saturation_hits": int(np.count_nonzero(
                               np.abs(scene.correction) >= setup.saturation))}}
    out["measured_contraction"] = measured_contraction(scene.pi2, on)
    check = ndof_model_check(setup, scene, corrections=applied_corrections(sd),
                             starts=sd.pulse_starts)
    pred = ndof_controlled_orbit(setup, scene.pi2[-1], (check or {}).get("final_force")) \
        if on is not None and len(scene.t) else {}
    out["predicted"] = pred
    if "orbit_pi2" in pred:
        d = np.abs(scene.pi2[-1] - np.asarray(pred["orbit_pi2"]))
        out["final_vs_exact_orbit"] = float(d.max())
        out["final_vs_exact_orbit_per_coordinate"] = dict(zip(names, d.tolist()))
        rho = (out["measured_contraction"] or {}).get("rho")
        if rho:
            out["contraction_relative_error"] = abs(rho - pred["rho"]) / pred["rho"]
    if check:
        check.update(dropped_at_deadline_misses=int(sd.missed_stamp_ns.size),
                     predictions_substituted=len(sd.substituted))
    out["model_check"] = check
    if setup.mode == "realtime":
        out["realtime"] = ndof_realtime(sd, setup, check)
    return out


def ndof_realtime(sd, setup: NdofSetup, check: dict | None) -> dict:
    """The realtime numbers of an n-DOF scene (:func:`.timing.realtime_numbers`) and, when
    each correction acted on its arrival (the kick: the simulator refuses a pulse or an
    actuator on arrival), the delay check (:func:`.timing.delay_check`) by the plant's
    period (:func:`ndof_period`) with the kick at the measured arrival."""
    from .timing import delay_check, kicks_on_the_sample, realtime_numbers

    rt = realtime_numbers(sd, setup.time_scale)
    rt["delay_check"] = None
    m = setup.model
    if m is None or not setup.on_arrival or setup.pulse_width > 0.0 \
            or setup.actuator is not None:
        return rt
    flow, step = ndof_period(setup)
    pi2, dv = sd.scene.pi2, sd.scene.correction

    def predict(k, delay):
        z, _, _ = step(flow.to_deviation(flow.tau2, pi2[k]), 0.0, float(dv[k]), delay,
                       flow=ndof_flow_at(flow, setup.drift, sd.scene.t[k]))
        return flow.to_physical(flow.tau2, z)

    rt["delay_check"] = delay_check(sd, rt, predict, m.period)
    if check:
        kicks_on_the_sample(rt["delay_check"], check["_departures"], dv)
    return rt


def ndof_lines(label: str, setup: NdofSetup, n: dict, fig_name: str | None) -> list:
    """The markdown lines of one n-DOF scene."""
    u, pred = n["uncontrolled"], n["predicted"]
    lines = [f"### {label}", ""] + ([f"![{label}]({fig_name})", ""] if fig_name else [])
    m = setup.model
    lines += [f"* n-DOF scene: model file `{setup.model_file}`"
              + (f" (n = {m.n}, wall coordinate x{m.i_w}, kick on v{m.i_a}, Δd = "
                 f"{m.delta_d:.6g}, T = {m.period:.6g})" if m is not None else ""),
              f"* gains k = {setup.gains.tolist() if setup.gains is not None else '—'}",
              f"* samples: {n['samples']} over {n['duration_s']:.6g} s of simulation time; "
              f"impacts: {n['impacts']}",
              f"* uncontrolled: {'period ' + str(u['period']) if u['period'] else 'not periodic to 1e-8 (chaotic, quasi-periodic or transient)'}"
              f"; impacts per period (histogram 0, 1, 2, …): "
              f"{u['impacts_per_period_histogram']}"]
    if u["range"]:
        lines.append("* uncontrolled range per coordinate (last 200 samples before the "
                     "switch-on): " + "; ".join(f"{c} ∈ [{a:.6g}, {b:.6g}]"
                                                for c, (a, b) in u["range"].items()))
    lines += control_lines(n)
    if n["control_on_sample"] is not None:
        lines.append(f"* impacts per period at the end: {fmt(n['final_impacts_per_period'])}")
    if "final_vs_exact_orbit" in n:
        lines.append("* final Π2 sample vs the exact controlled 1/1 orbit (the correction "
                     f"as {pred.get('correction', 'the kick')}"
                     + (f"; the actuator's force there {pred['orbit_force']:.6g}"
                        if "orbit_force" in pred else "") + "): max "
                     f"{n['final_vs_exact_orbit']:.2e}; per coordinate " + "; ".join(
                         f"{c} {n['final_pi2'][c]:.12g} (orbit {o:.12g}, |Δ| {d:.1e})"
                         for (c, d), o in zip(n["final_vs_exact_orbit_per_coordinate"].items(),
                                              pred["orbit_pi2"])))
    c = n["corrections"]
    lines.append(f"* corrections: {c['answered']} answers, {c['missing']} samples without one, "
                 f"max |Δv| = {c['max_abs']:.3g}, saturation {fmt(c['saturation'])} hit "
                 f"{c['saturation_hits']} times")
    mc = n.get("model_check")
    if mc:
        lines.append(f"* model check: each recorded period re-integrated by the n-DOF core "
                     f"from the recorded sample and correction (as "
                     f"{mc.get('correction', 'the kick')}) departs from the next "
                     f"recorded sample by at most {mc['max_departure']:.2e} "
                     f"({mc['periods_above_1e-12']} of {mc['periods']} periods above 1e-12"
                     + (f"; each period at the plant's Δd of that period, the wall "
                        f"drifting by {mc['delta_d_drift']:g} per period"
                        if mc.get("delta_d_drift") else "")
                     + (f", {mc['failed']} could not be re-integrated" if mc["failed"] else "")
                     + (f", {mc['unchecked']} not checked after a gap (the actuator's force "
                        "unknown)" if mc.get("unchecked") else "")
                     + (f"; the {mc['dropped_at_deadline_misses']} answers missed at deadline "
                        "misses re-integrated as what acted instead ("
                        f"{mc['predictions_substituted']} predictions, 0 otherwise)"
                        if mc.get("dropped_at_deadline_misses") else "")
                     + ")")
    from .numbers import MODEL_CHECK_BOUND
    from .timing import realtime_lines

    lines += realtime_lines(n, MODEL_CHECK_BOUND)
    lines.append("")
    return lines


def plot_ndof_scene(sd, numbers: dict, title: str, path) -> None:
    """Panels: each coordinate's Pi2 samples, the distance to the final sample (log), the
    corrections."""
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()
    scene = sd.scene
    names = numbers["coordinates"]
    k = np.arange(len(scene.t))
    on = numbers["control_on_sample"]
    fig, ax = plt.subplots(1, 3, figsize=(15, 4), constrained_layout=True)
    for j, c in enumerate(names):
        ax[0].plot(k, scene.pi2[:, j], ".", ms=2, label=c)
    ax[0].set(xlabel="sample k", ylabel="Π2 sample", title="every coordinate on Π2")
    ax[0].legend(fontsize=8)
    dist = np.max(np.abs(scene.pi2 - scene.pi2[-1]), axis=1)
    ax[1].semilogy(k[:-1], np.maximum(dist[:-1], 1e-17), ".", ms=2)
    ax[1].set(xlabel="sample k", ylabel="max |X_k − X_final|", title="convergence")
    ax[2].plot(k, scene.correction, ".", ms=2)
    ax[2].set(xlabel="sample k", ylabel="Δv", title="corrections")
    for a in ax:
        if on is not None:
            a.axvline(on, color="k", lw=0.5)
    fig.suptitle(title)
    save_png(fig, Path(path))
    plt.close(fig)

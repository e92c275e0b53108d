"""The numbers of a recorded scene, measured from the bag and predicted by the core.

:func:`resolve_setup` finds the model, gains and mode of a run: from the bag's
parameter record (:mod:`.record`) if it has one, else from options, else inferred from
the recording itself (docs/analysis.md, "Where the parameters come from"):

* Delta d from the impacts: at an impact the gap is zero (docs/theory.md, gap function),
  so with the deviation z(h) = Phi(h) (z_k + (0, dv_k)) carried by the free flow from the
  preceding sample over the recorded time h to the first impact,
  Delta d = z_x(h) - 2 a sin^2((tau - phi)/2). Stamps are rounded to 1 ns, so this is
  exact to |v-| * 0.5 ns; secant steps on one recorded period then refine it, and the
  shortest decimal within 1e-12 relative is taken (a value typed by a person, -5e-06, is
  recovered exactly; the model check below shows whether it reproduces every period).
* the gains (c1, c2) by least squares on Eq. 28, Delta v = c1 (x - x**) + c2 (v - v**),
  over the corrected, unsaturated samples.

:func:`scene_numbers` then gives, per scene, what :func:`grazing_control.recordings.analysis.summarize`
gives (uncontrolled attractor, switch-on, convergence, final point) and:

* the measured contraction per sample after the switch-on, exp of the least-squares slope
  of log |X_k - X_final| over the samples above the rounding floor, against the modulus of
  the largest Floquet multiplier of the controlled 1/1 orbit that the core predicts
  (:func:`grazing_control.dynamics.orbits.orbits.orbit_11`) for the same parameters and gains, or,
  when the simulator acted with a force pulse, of the pulse's orbit
  (:func:`controlled_orbit`);
* the final sample against the exact controlled orbit (the kick's, or the pulse's);
* the model check: every recorded period re-integrated with the core
  (:func:`grazing_control.dynamics.simulation.simulate.period_step`) from the recorded sample and correction,
  the largest departure from the next recorded sample (rounding level for a lockstep run;
  for a realtime run the corrections act at their arrival, not on Pi2, and it departs);
* corrections: largest |Delta v|, saturation hits;
* realtime: latency distribution, late and missing answers, deadline misses, sample lag,
  and the delay check with this period (:mod:`.timing`, the same for every model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .analysis import summarize
from .timing import delay_check, kicks_on_the_sample, realtime_numbers as realtime_measured
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.flow import propagate
from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["Setup", "resolve_setup", "infer_delta_d", "shortest_decimal", "infer_gains", "scene_numbers",
           "model_check", "measured_contraction", "controlled_orbit", "scene_problems",
           "MODEL_CHECK_BOUND"]

MODEL_KEYS = ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset")
_NS = 1_000_000_000


@dataclass
class Setup:
    """What a run was: model, gains, mode, and where each came from (``sources``)."""

    params: OscillatorParams | None
    gains: Gains | None
    mode: str
    time_scale: float | None
    saturation: float
    enable_after: int | None
    actuation_delay: float
    sources: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    pulse_width: float = 0.0      # the simulator's force pulse (0: the kick of Eq. 28)
    force_limit: float = 0.0      # 0: none
    actuator: object = None       # the simulator's first-order actuator (None: ideal)
    drift: float = 0.0            # the simulator's delta_d_drift (per period; 0: none)


def infer_delta_d(base: OscillatorParams, scene):
    """Delta d from the first impact after each sample (module docstring); (value, n, spread).

    Returns (None, 0, None) without impacts.
    """
    t, pi2, dv, imp = scene.t, scene.pi2, scene.correction, scene.impacts
    if len(imp) == 0 or len(t) < 2:
        return None, 0, None
    k = np.searchsorted(t, imp[:, 0], side="right") - 1
    first = np.ones(len(imp), bool)
    first[1:] = k[1:] != k[:-1]
    sel = np.flatnonzero(first & (k >= 0))[:50]
    p = base
    out = []
    for j in sel:
        kk = int(k[j])
        h = imp[j, 0] - t[kk]
        if not 0.0 < h <= p.period * 1.0000001:
            continue
        dx, dvv = pi2[kk, 0] - p.x_ref, pi2[kk, 1] - p.v_ref + dv[kk]
        zx, _ = propagate(p.zeta, dx, dvv, h)
        tau = p.tau2 + p.omega * h
        s = math.sin(0.5 * (tau - p.lag))
        out.append(zx - 2.0 * p.amplitude * s * s)
    if not out:
        return None, 0, None
    out = np.array(out)
    return _refine_delta_d(base, scene, float(np.median(out))), int(out.size), \
        float(np.max(out) - np.min(out))


def _refine_delta_d(base, scene, dd):
    """Secant steps on the recorded one-period step with the first impact (stamp rounding
    limits the impact estimate; the Pi2 map is ~1/v- sensitive to Delta d near grazing)."""
    from grazing_control.dynamics.simulation.simulate import period_step

    t, pi2, dv, imp = scene.t, scene.pi2, scene.correction, scene.impacts
    k = int(np.searchsorted(t, imp[0, 0], side="right") - 1)
    if k + 1 >= len(t):
        return dd

    def f(d):
        p = base.with_(delta_d=d)
        seg = period_step(p, pi2[k, 0] - p.x_ref, pi2[k, 1] - p.v_ref, float(dv[k]))
        return p.x_ref + seg.dx - pi2[k + 1, 0]

    try:
        a, b = dd, dd * (1.0 + 1e-7)
        fa, fb = f(a), f(b)
        for _ in range(8):
            if fb == fa or fb == 0.0:
                break
            a, b, fa = b, b - fb * (b - a) / (fb - fa), fb
            fb = f(b)
        best = b if abs(fb) <= abs(f(dd)) else dd
    except Exception:
        return dd
    return shortest_decimal(best, 1e-12)


def shortest_decimal(value: float, rel: float) -> float:
    """The float with the fewest significant decimal digits within ``rel`` of ``value``.

    A parameter typed by a person (-5e-06) is recovered exactly from an estimate good to
    ``rel``; the model check then shows whether it reproduces every recorded period.
    """
    for digits in range(1, 18):
        cand = float(f"{value:.{digits}g}")
        if abs(cand - value) <= rel * abs(value):
            return cand
    return value


def infer_gains(scene, x_ref, v_ref, saturation=math.inf):
    """(c1, c2, rms residual, n) by least squares on Eq. 28; None if < 3 usable samples."""
    dv = scene.correction
    use = (dv != 0.0) & (np.abs(dv) < saturation)
    if np.count_nonzero(use) < 3:
        return None
    a = np.column_stack([scene.pi2[use, 0] - x_ref, scene.pi2[use, 1] - v_ref])
    (c1, c2), *_ = np.linalg.lstsq(a, dv[use], rcond=None)
    res = a @ np.array([c1, c2]) - dv[use]
    return float(c1), float(c2), float(np.sqrt(np.mean(res * res))), int(np.count_nonzero(use))


def _num(value, default=None):
    try:
        value = float(value)
    except (TypeError, ValueError):
        return default
    return value


def recorded_drift(sim: dict) -> float:
    """The simulator's ``delta_d_drift`` (per period) of its parameter record; 0 where
    absent or not a finite number."""
    drift = _num(sim.get("delta_d_drift"), 0.0)
    return drift if drift is not None and math.isfinite(drift) else 0.0


def sample_index(t: float, period: float) -> int:
    """The simulator's index k of the Pi2 sample stamped ``t``: t_k = k T from the
    scene's start (plant.engine.Engine.t; a reset starts a scene at t = 0)."""
    return int(round(t / period))


def drift_notes(sim: dict) -> list:
    """The note of a scene whose wall drifted (the simulator's ``delta_d_drift``, a
    wearing stop): the model check re-integrates period k at the plant's Delta d of that
    period, the recorded Delta d + delta_d_drift k (k0 = 0: the scene's start), as the
    simulator ran it (plant.engine.Engine._drift_wall)."""
    drift = recorded_drift(sim)
    if drift == 0.0:
        return []
    return [f"the plant's wall drifted (delta_d_drift={drift:g} per period): the model "
            "check re-integrates period k at the plant's Delta d of that period, the "
            "recorded Delta d + delta_d_drift k (k counted from the scene's start, t_k = "
            "k T), so a departure is the model's, not the drift's"]


def resolve_setup(bag, options: dict) -> Setup:
    """Model, gains and mode of a bag: record, else options, else inferred (module doc).

    ``options``: zeta, r, omega, pi2_offset, delta_d, c1, c2, mode, time_scale (None when
    not given). An option given explicitly overrides the record (said in the notes).
    """
    nodes = bag.parameters.get("nodes", {})
    sim = (nodes.get("sim_node") or [{}])[0]
    ctl = (nodes.get("controller_node") or [{}])[0]
    sources, notes = {}, drift_notes(sim)
    for name, seq in nodes.items():
        if len(seq) > 1:
            changed = sorted({k for a in seq[1:] for k in a if a.get(k) != seq[0].get(k)})
            notes.append(f"{name} parameters changed during the run ({', '.join(changed)}); "
                         "the analysis uses the values at start")
    model = {}
    for key in MODEL_KEYS:
        opt = options.get(key)
        rec = _num(sim.get(key), _num(ctl.get(key)) if key != "delta_d" else None)
        if opt is not None:
            model[key] = float(opt)
            sources[key] = "option" + (" (overrides the record)" if rec is not None else "")
        elif rec is not None:
            model[key] = rec
            sources[key] = "parameter record"
    scene0 = bag.scenes[0].scene
    base_keys = {k: v for k, v in model.items() if k != "delta_d"}
    try:
        base = OscillatorParams(**base_keys)
    except ParameterError as exc:
        raise ParameterError(f"{bag.path}: {exc}") from None
    for key in MODEL_KEYS:
        if key != "delta_d" and key not in sources:
            sources[key] = "default (the study's set)"
    if "delta_d" not in model:
        dd, n, spread = infer_delta_d(base, scene0)
        if dd is not None:
            model["delta_d"] = dd
            sources["delta_d"] = (f"inferred from {n} impacts (spread {spread:.1e}); give "
                                  "--delta-d to set it")
        else:
            notes.append("Delta d unknown (no parameter record, no --delta-d, no impacts): "
                         "no prediction")
    params = None
    if "delta_d" in model:
        params = OscillatorParams(**model)
    # the controller's reference point and gains
    x_ref = _num(ctl.get("x_ref"), math.nan)
    v_ref = _num(ctl.get("v_ref"), math.nan)
    ref = params or base
    x_ref = ref.x_ref if math.isnan(x_ref) else x_ref
    v_ref = ref.v_ref if math.isnan(v_ref) else v_ref
    saturation = _num(ctl.get("saturation"), math.inf)
    gains = None
    c1o, c2o = options.get("c1"), options.get("c2")
    if c2o is not None:
        from grazing_control.dynamics.design.gains import degenerate_c1
        c1 = c1o if c1o is not None else degenerate_c1(params or base, c2o)
        gains = Gains(c1, c2o)
        sources["gains"] = "option" + (" (c1 from the degenerate condition, Eq. 38)"
                                       if c1o is None else "")
    elif "c1" in ctl and "c2" in ctl and None not in (_num(ctl["c1"]), _num(ctl["c2"])):
        gains = Gains(_num(ctl["c1"]), _num(ctl["c2"]))
        sources["gains"] = "parameter record"
    else:
        if "c1" in ctl or "c2" in ctl:
            notes.append("the controller's c1 or c2 in the parameter record is not a number: "
                         "ignored")
        fit = infer_gains(scene0, x_ref, v_ref, saturation)
        if fit is not None:
            c1, c2, rms, n = fit
            gains = Gains(c1, c2)
            sources["gains"] = (f"inferred by least squares on Eq. 28 from {n} corrections "
                                f"(rms residual {rms:.1e}); give --c2 (and --c1) to set them")
        else:
            sources["gains"] = "unknown (no record, no option, fewer than 3 corrections)"
    mode = options.get("mode") or (sim.get("mode") if isinstance(sim.get("mode"), str)
                                   else None)
    if options.get("mode"):
        sources["mode"] = "option"
    elif mode:
        sources["mode"] = "parameter record"
    elif "latency" in bag.present:
        mode = "realtime"
        sources["mode"] = f"inferred: the bag has {bag.present['latency']}"
    else:
        mode = "lockstep"
        sources["mode"] = "assumed (no parameter record, no latency topic); give --mode"
    ts = options.get("time_scale")
    if ts is not None:
        sources["time_scale"] = "option"
    elif "time_scale" in sim:
        ts = _num(sim["time_scale"])
        sources["time_scale"] = "parameter record"
    delay = _num(sim.get("actuation_delay"), _num(ctl.get("actuation_delay"), 0.0))
    ea = _num(ctl.get("enable_after"))
    ea = int(ea) if ea is not None and math.isfinite(ea) else None
    width = _num(sim.get("pulse_width"), 0.0)
    limit = _num(sim.get("force_limit"), 0.0)
    return Setup(params, gains, str(mode), ts, saturation, ea, delay, sources, notes,
                 width if width is not None and math.isfinite(width) and width > 0 else 0.0,
                 limit if limit is not None and math.isfinite(limit) and limit > 0 else 0.0,
                 _actuator(sim, notes), recorded_drift(sim))


def _actuator(sim: dict, notes: list):
    """The simulator's first-order actuator of its parameter record (actuator_bandwidth,
    actuator_latency; docs/nodes.md), or None (ideal, or a record without them)."""
    from grazing_control.dynamics.simulation.actuator import Actuator

    bw = _num(sim.get("actuator_bandwidth"), 0.0)
    lat = _num(sim.get("actuator_latency"), 0.0)
    if bw is None or lat is None or not (bw > 0.0 or lat > 0.0):
        return None
    try:
        return Actuator(1.0 / bw if bw > 0.0 else 0.0, lat)
    except ValueError as exc:
        notes.append(f"the simulator's actuator is not used: {exc}")
        return None


#: Largest |omega t mod 2 pi| of a Pi2 stamp accepted as "on the section" (rad): stamps are
#: whole nanoseconds, so a genuine sample is within omega * 1e-9 of the section's phase.
SECTION_PHASE_TOL = 1e-4


def section_phase_problems(bag, setup: Setup) -> list:
    """Problems if the Pi2 samples are not stamped at the section's phase.

    The simulator's clock starts at the first Pi2 sample and sample k is stamped t_k = k T
    (docs/nodes.md), so omega t_k = 0 mod 2 pi; a Pi1 sample is stamped at
    omega t = -pi2_offset mod 2 pi. Samples away from the section's phase (swapped pi1/pi2
    topics, another section, a foreign clock) would be analysed as Pi2 samples: say so.
    """
    p = setup.params
    if p is None:
        return []
    out = []
    for sd in bag.scenes:
        t = sd.scene.t
        if t.size < 2:
            continue
        phase = np.angle(np.exp(1j * p.omega * t))
        worst = float(np.median(np.abs(phase)))
        if worst > SECTION_PHASE_TOL:
            pi1 = float(np.angle(np.exp(-1j * p.pi2_offset)))
            swapped = abs(float(np.median(phase)) - pi1) < 1e-3
            out.append(f"scene {sd.index}: the Pi2 samples are not at the section's phase "
                       f"(median |omega t mod 2 pi| = {worst:.3g} rad, not 0"
                       + ("; they are at Pi1's phase: are the pi1 and pi2 topics swapped?"
                          if swapped else "") + "): the numbers below are not Pi2 numbers")
    return out


def measured_contraction(pi2: np.ndarray, on: int | None, floor_factor: float = 1e4):
    """Contraction per sample after ``on``, measured: dict or None (see module docstring).

    The distance to the final sample e_k = max |X_k - X_final| is fitted by
    log e_k = a + k log rho over k = on+1 ... up to the first sample within
    ``floor_factor`` ulps of the final point (below that, rounding decides).
    """
    if on is None or len(pi2) - on < 5:
        return None
    final = pi2[-1]
    e = np.max(np.abs(pi2[on:] - final), axis=1)
    floor = floor_factor * np.finfo(float).eps * max(1.0, float(np.max(np.abs(final))))
    below = np.flatnonzero(e[1:] <= floor)
    stop = int(below[0]) + 1 if below.size else len(e) - 1
    k = np.arange(1, stop)
    if k.size < 3:
        return {"rho": None, "samples": int(k.size), "reason": "fewer than 3 samples between "
                "the switch-on and the rounding floor"}
    # the capture is nonlinear (impacts near grazing): fit where e_k has dropped two
    # decades below its first value, the linear regime, if that leaves 3 samples
    lin = k[e[k] <= 1e-2 * e[k[0]]]
    if lin.size >= 3:
        k = lin
    slope, icpt = np.polyfit(k, np.log(e[k]), 1)
    ratios = e[k[1:]] / e[k[:-1]]
    out = {"rho": float(math.exp(slope)), "samples": int(k.size), "first": on + 1,
           "last": on + int(k[-1]), "median_ratio": float(np.median(ratios)),
           "floor": float(floor), "distances": e[: stop + 3].tolist(),
           "intercept": float(icpt), "method": "slope of log distance"}
    fitted = _fitted_map(pi2[on:] - final, k)
    if fitted is not None:
        out["rho_distance_slope"] = out["rho"]
        out.update(fitted)
    return out


def _fitted_map(dev: np.ndarray, k: np.ndarray):
    """The linearised Pi2 map fitted to the deviations: D_{j+1} = A D_j (least squares).

    The slope of log |D_k| measures the largest multiplier only when it is real and
    dominates; with complex multipliers |D_k| oscillates about the decay and the slope is
    biased by a few per cent. The 2x2 map fitted to the same samples has the multipliers
    as its eigenvalues (linear regime, deviations from the final sample, which is on the
    orbit to rounding). None with fewer than 3 pairs or an ill-conditioned fit.
    """
    j = k[:-1]
    if j.size < 3:
        return None
    a, b = dev[j], dev[j + 1]
    scale = np.max(np.abs(a), axis=1)
    w = 1.0 / scale                                   # each pair counts alike
    x, _res, rank, sv = np.linalg.lstsq(a * w[:, None], b * w[:, None], rcond=None)
    if rank < 2 or sv[-1] < 1e-9 * sv[0]:
        return None
    mult = np.linalg.eigvals(x.T)
    order = np.argsort(-np.abs(mult))
    mult = mult[order]
    return {"rho": float(np.abs(mult[0])), "method": "eigenvalues of the fitted 2x2 map",
            "fitted_multipliers": [[float(m.real), float(m.imag)] for m in mult]}


def applied_corrections(sd) -> np.ndarray:
    """The corrections that acted: the recorded answers, except where the simulator
    reported a deadline miss for the sample (the answer came too late): there the
    prediction it applied instead (``oscillator/substituted``, on_miss predict), else 0
    (on_miss drop). A prediction recorded for a lost answer acts too."""
    dv = np.array(sd.scene.correction, dtype=float)
    if sd.missed_stamp_ns.size:
        dv[np.isin(sd.stamp_ns, sd.missed_stamp_ns)] = 0.0
    if sd.substituted:
        index = {s: k for k, s in enumerate(sd.stamp_ns.tolist())}
        for stamp, value in sd.substituted.items():
            if stamp in index:
                dv[index[stamp]] = value
    return dv


def model_check(p: OscillatorParams, scene, delay: float = 0.0, limit: int = 20000,
                corrections=None, pulse_width: float = 0.0, force_limit: float = 0.0,
                actuator=None, starts=None, drift: float = 0.0):
    """Re-integrate each recorded period with the core; largest departure, per sample.

    Returns (max departure, array of departures |P(X_k, dv_k) - X_{k+1}|) over at most
    ``limit`` periods; the correction of sample k (``corrections``, default the recorded
    ones) is applied on Pi2 (``delay`` after it when the run had an actuation delay), as
    a force pulse of ``pulse_width`` centred there when the simulator had one
    (:func:`grazing_control.dynamics.simulation.actuation.pulse_step`, docs/theory_pulse.md), through
    the simulator's first-order ``actuator`` when it had one
    (:func:`grazing_control.dynamics.simulation.actuator.actuated_step`; the force on the mass is
    not recorded: it is carried from 0 at the first recorded sample, exact for a scene
    recorded from its start, since the force follows the commands alone). ``starts``: per
    sample, the pulse's recorded start after the sample (a rig scene off the rig's grid,
    :func:`.rig_acts.apply_acts`; NaN: the rule above). ``drift``: the simulator's
    ``delta_d_drift``: the period of sample k (t_k = k T, :func:`sample_index`) at
    Delta d + drift k, as the simulator ran it (plant.engine.Engine._drift_wall).
    """
    from grazing_control.dynamics.simulation.actuation import pulse_start, pulse_step
    from grazing_control.dynamics.simulation.simulate import period_step

    dvs = scene.correction if corrections is None else corrections
    n = min(len(scene.t) - 1, limit)
    dep = np.zeros(max(n, 0))
    force = [0.0]
    if actuator is not None:    # the force carried from period to period
        from grazing_control.dynamics.simulation.actuator import actuated_step

        start = pulse_start(p.period, delay, pulse_width)

        def step(p, dx, dv, dvc, start=start):
            x, v, f, imps = actuated_step(p, dx, dv, force[0], dvc, start=start,
                                          width=pulse_width, actuator=actuator,
                                          force_limit=force_limit or math.inf)
            force[0] = f
            return _Step(x, v, imps)
    elif pulse_width > 0.0:     # the engine's rule: centred at the delay, within [0, T - w)
        start = pulse_start(p.period, delay, pulse_width)

        def step(p, dx, dv, dvc, start=start):
            return pulse_step(p, dx, dv, dvc, start=start, width=pulse_width,
                              force_limit=force_limit or math.inf)
    else:
        kw = {"delay": delay} if delay else {}

        def step(p, dx, dv, dvc, start=None):
            return period_step(p, dx, dv, dvc, **kw)
    base = p
    for k in range(n):
        x, v = scene.pi2[k]
        p = params_at(base, drift, scene.t[k])
        try:
            if starts is not None and math.isfinite(starts[k]):
                seg = step(p, x - p.x_ref, v - p.v_ref, float(dvs[k]), float(starts[k]))
            else:
                seg = step(p, x - p.x_ref, v - p.v_ref, float(dvs[k]))
        except Exception:            # the core refuses (impact cap): count as departed
            dep[k] = np.inf
            continue
        dep[k] = max(abs(p.x_ref + seg.dx - scene.pi2[k + 1, 0]),
                     abs(p.v_ref + seg.dv - scene.pi2[k + 1, 1]))
    return (float(np.max(dep)) if n > 0 else None), dep


def params_at(p: OscillatorParams, drift: float, t: float) -> OscillatorParams:
    """The plant's model in the period of the sample stamped ``t``: ``p`` with Delta d +
    drift k (k = :func:`sample_index`), the expression the simulator evaluates
    (plant.engine.Engine._drift_wall, k0 = 0), so bit for bit its wall; ``p`` itself
    without a drift."""
    if not drift:
        return p
    return p.with_(delta_d=p.delta_d + drift * sample_index(t, p.period))


#: Largest model-check departure of a lockstep scene that is not a problem: the simulator
#: runs the core's own step, so a lockstep bag is reproduced to rounding (reference
#: bags: below 1e-12); a departure beyond means the bag lacks what acted (issue 27: 7.6e-3
#: with 88 corrections lost) or the model is not the run's.
MODEL_CHECK_BOUND = 1e-9


def _ranges(indices) -> str:
    """"3, 7–9, 12" for the sorted integers ``indices``."""
    out, idx = [], [int(i) for i in indices]
    start = prev = idx[0]
    for i in idx[1:] + [None]:
        if i is not None and i == prev + 1:
            prev = i
            continue
        out.append(str(start) if start == prev else f"{start}–{prev}")
        if i is not None:
            start = prev = i
    return ", ".join(out)


def scene_problems(sd, setup: Setup, numbers: dict) -> list:
    """What a lockstep scene's numbers show was lost (issue 27), as problems.

    In lockstep the simulator waits for the answer to each sample and the controller
    answers every one (with 0 before its switch-on), so a sample without a recorded
    correction is a message lost in the recording (or an answer that timed out); and the
    model check reproduces every period to rounding, so a departure beyond
    :data:`MODEL_CHECK_BOUND` means the bag does not hold what acted. Realtime scenes
    miss answers by design (their numbers say how many); a scene without any correction
    (no controller) is not checked for them.
    """
    if setup.mode != "lockstep":
        return []
    out = []
    label = f"scene {sd.index}: "
    c = numbers["corrections"]
    if c["answered"] and c["missing"]:
        missing = np.flatnonzero(~sd.answered)
        out.append(f"{label}{c['missing']} of {numbers['samples']} samples have no recorded "
                   f"correction (samples {_ranges(missing)}): in lockstep the controller "
                   "answers every sample, so these were lost in the recording (or the "
                   "answer timed out); the numbers below treat them as uncorrected")
    mc = numbers.get("model_check")
    dep = numbers.get("_departures")
    if mc and mc["max_departure"] is not None and not mc["max_departure"] <= MODEL_CHECK_BOUND:
        bad = np.flatnonzero(~(np.asarray(dep) <= MODEL_CHECK_BOUND))
        out.append(f"{label}the model check departs by up to {mc['max_departure']:.2e} "
                   f"(bound {MODEL_CHECK_BOUND:g}: a lockstep run is reproduced to rounding) "
                   f"in {bad.size} of {mc['periods']} periods, first at sample {int(bad[0])}: "
                   "the recorded samples and corrections do not follow the model (a lost "
                   "correction, or not the run's parameters)")
    return out


class _Step(NamedTuple):
    """A period's end (dx, dv) and impacts, as the core's segments give them."""

    dx: float
    dv: float
    impacts: tuple


def controlled_orbit(setup: Setup):
    """The controlled 1/1 orbit the scene should settle on, and what it is.

    The kick of Eq. 28 (acting the actuation delay after Pi2, docs/theory_delay.md):
    :func:`grazing_control.dynamics.orbits.orbits.orbit_11`; a simulator with a force pulse
    (``pulse_width`` > 0) closes the loop with the pulse centred the delay after Pi2, whose
    orbit is O(w^2) away (docs/theory_pulse.md): :func:`grazing_control.dynamics.simulation.actuation.
    pulse_orbit`, with the force limit and the controller's saturation. Returns
    ``(orbit, description)``; the orbit has ``pi2``, ``pi2_deviation``, ``multipliers``
    and ``v_minus``. Raises what the orbit search raises.
    """
    from grazing_control.dynamics.simulation.actuation import pulse_orbit
    from grazing_control.dynamics.orbits.orbits import orbit_11

    p, g = setup.params, setup.gains
    if setup.actuation_delay:
        g = Gains(g.c1, g.c2, setup.actuation_delay)
    if setup.actuator is not None:
        from grazing_control.dynamics.simulation.actuator import actuated_orbit_for

        a = setup.actuator
        orbit = actuated_orbit_for(p, g, setup.pulse_width, a)
        return orbit, (f"force pulse of width {setup.pulse_width:g} centred "
                       f"{setup.actuation_delay:g} after Pi2 through a first-order actuator "
                       f"(tau_a {a.time_constant:.6g}, latency {a.latency:g}; fixed point of "
                       "the exact 3-state map (x, v, force))")
    if setup.pulse_width > 0.0:
        orbit = pulse_orbit(p, g, setup.pulse_width,
                            force_limit=setup.force_limit or math.inf,
                            saturation=setup.saturation)
        return orbit, (f"force pulse of width {setup.pulse_width:g} centred "
                       f"{setup.actuation_delay:g} after Pi2 (fixed point of the exact pulse "
                       "map, Jacobian by central differences)")
    orbit = orbit_11(p, g, branch="grazing")
    return orbit, ("kick on Pi2" if not setup.actuation_delay else
                   f"kick {setup.actuation_delay:g} after Pi2")


def _predicted(setup: Setup):
    """Multipliers of the controlled 1/1 orbit (and the uncontrolled one) from the core
    (:func:`controlled_orbit`: the kick's, or the pulse's for a pulse scene)."""
    from grazing_control.dynamics.orbits.orbits import orbit_11

    out = {}
    p, g = setup.params, setup.gains
    if p is None:
        return {"error": "Delta d unknown"}
    try:
        unc = orbit_11(p, None)
        out["uncontrolled_orbit_multipliers"] = [complex(z) for z in unc.multipliers]
    except Exception as exc:
        out["uncontrolled_orbit_error"] = f"{type(exc).__name__}: {exc}"
    if g is None:
        return out
    try:
        orb, actuation = controlled_orbit(setup)
    except Exception as exc:
        out["controlled_orbit_error"] = f"{type(exc).__name__}: {exc}"
        return out
    mult = orb.multipliers
    out.update({"multipliers": [complex(z) for z in mult],
                "rho": float(np.max(np.abs(mult))),
                "orbit_pi2": [float(orb.pi2[0]), float(orb.pi2[1])],
                "orbit_v_minus": float(orb.v_minus),
                "actuation": actuation})
    return out


def scene_numbers(sd, setup: Setup, tol: float = 1e-8) -> dict:
    """All numbers of one scene (JSON-serialisable except complex multipliers)."""
    scene = sd.scene
    base = summarize(scene, tol=tol)
    on = base["control_on"]
    out = {"samples": base["samples"], "duration_s": float(scene.t[-1] - scene.t[0]),
           "summary": base}
    per = base["uncontrolled_period"]
    hist = base["uncontrolled_impacts_per_period"]
    out["uncontrolled"] = {
        "period": per,
        "kind": ("periodic" if per else "not periodic over the last 200 samples (chaotic)")
                if on is None or on >= 2 else "too short to tell",
        "impacts_per_period_histogram": hist,
        "mean_impacts_per_period": (float(np.dot(np.arange(len(hist)), hist) / max(sum(hist), 1))
                                    if hist else None),
    }
    out["control_on_sample"] = on
    out["control_on_time_s"] = float(scene.t[on]) if on is not None else None
    out["samples_to_converge"] = base["samples_to_converge"]
    out["converge_tol"] = base["converge_tol"]
    pred = _predicted(setup)
    if on is None:       # the controller never acted: nothing controlled to compare with
        pred = {"note": "the controller never acted in this scene: no controlled orbit or "
                        "contraction to compare with"}
    out["predicted"] = pred
    meas = measured_contraction(scene.pi2, on) if on is not None else None
    if meas is not None and base["samples_to_converge"] is None:
        meas = {"rho": None, "samples": 0, "reason": f"the scene did not converge to {tol:g} "
                "by its end, so there is no fixed point to measure the contraction against"}
    out["measured_contraction"] = meas
    if meas and meas.get("rho") and pred.get("rho") is not None:
        out["contraction_relative_error"] = abs(meas["rho"] - pred["rho"]) / max(pred["rho"], 1e-300)
    if "orbit_pi2" in pred:
        out["final_vs_exact_orbit"] = float(np.max(np.abs(scene.pi2[-1] - np.array(pred["orbit_pi2"]))))
        out["final_v_minus"] = base["final_v_minus"]
        out["exact_v_minus"] = pred["orbit_v_minus"]
    out["final_pi2"] = base["final_pi2"]
    out["final_impacts_per_period"] = base["final_impacts_per_period"]
    out["one_impact_per_period_after_convergence"] = base.get(
        "one_impact_per_period_after_convergence")
    dv = scene.correction
    sat = setup.saturation
    out["corrections"] = {
        "answered": int(np.count_nonzero(sd.answered)),
        "missing": int(np.count_nonzero(~sd.answered)),
        "nonzero": int(np.count_nonzero(dv)),
        "max_abs": float(np.max(np.abs(dv))) if dv.size else 0.0,
        "saturation": None if math.isinf(sat) else sat,
        "saturation_hits": int(np.count_nonzero(np.abs(dv) >= sat)) if math.isfinite(sat) else 0,
        "duplicate_answers": sd.duplicate_answers,
        "conflicting_answers": sd.conflicting_answers,
        "answers_matching_no_sample": sd.unmatched_answers,
    }
    if setup.params is not None:
        worst, dep = model_check(setup.params, scene, setup.actuation_delay,
                                 corrections=applied_corrections(sd),
                                 pulse_width=setup.pulse_width, force_limit=setup.force_limit,
                                 actuator=setup.actuator, starts=sd.pulse_starts,
                                 drift=setup.drift)
        out["model_check"] = {"max_departure": worst,
                              "periods": int(dep.size),
                              "periods_in_scene": max(len(scene.t) - 1, 0),
                              "periods_above_1e-12": int(np.count_nonzero(dep > 1e-12)),
                              "dropped_at_deadline_misses": int(sd.missed_stamp_ns.size),
                              "predictions_substituted": len(sd.substituted)}
        if setup.drift:
            out["model_check"]["delta_d_drift"] = setup.drift
        if sd.pulse_starts is not None:
            out["model_check"]["pulses_at_recorded_starts"] = int(
                np.count_nonzero(np.isfinite(sd.pulse_starts)))
        out["_departures"] = dep
    out["realtime"] = realtime_numbers(sd, setup) if setup.mode == "realtime" else None
    if "_departures" in out:       # the model check's periods (at most its limit)
        kicks_on_the_sample((out["realtime"] or {}).get("delay_check"), out["_departures"],
                            scene.correction)
    return out


def realtime_numbers(sd, setup: Setup) -> dict:
    """Latency, late and missing answers, deadline misses, sample lag (wall clock), and
    the delay check (:mod:`.timing`) with the core's period."""
    out = realtime_measured(sd, setup.time_scale)
    out["delay_check"] = _delay_check(sd, setup, out)
    return out


def _delay_check(sd, setup: Setup, rt: dict):
    """:func:`.timing.delay_check` with the 1-DOF period
    (:func:`grazing_control.dynamics.simulation.simulate.period_step`, the kick ``delay``
    after the sample); None with scheduled actuation (a correction acts at t_k + delay, not
    on arrival) or without the model."""
    from grazing_control.dynamics.simulation.simulate import period_step

    p = setup.params
    if (setup.actuation_delay or 0.0) > 0.0 or p is None:
        return None
    pi2, dv = sd.scene.pi2, sd.scene.correction

    def predict(k, delay):
        q = params_at(p, setup.drift, sd.scene.t[k])
        seg = period_step(q, pi2[k, 0] - q.x_ref, pi2[k, 1] - q.v_ref, float(dv[k]),
                          delay=delay)
        return (q.x_ref + seg.dx, q.v_ref + seg.dv)

    return delay_check(sd, rt, predict, p.period)

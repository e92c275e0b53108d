"""The realtime numbers of a recorded scene, for any model: latency, answers, misses, lag,
and the delay check that says whether the corrections' arrival explains the run.

:func:`realtime_numbers` measures, from the recorded topics alone (docs/analysis.md,
"Realtime numbers"): the simulator's latency messages (sample published -> answer
received), the controller's answer time (publish times), late and missing answers, the
deadline misses and the predictions substituted at them, and each sample's lag against
the time scale (recorded, or estimated from the publish times) on the plant's clock: less
the pauses of that clock before the sample (the simulator's ``paused`` event records,
plant.realtime.Realtime.resume; docs/nodes.md, "A stall of the simulator"), which are
reported apart (count, total, longest).

:func:`delay_check` is the model check with each correction applied at its measured
arrival instead of on the sample. In realtime with actuation on arrival (``actuation``
auto with ``actuation_delay`` 0, or on_arrival; docs/nodes.md, "Modes") the simulator
applies the correction of sample k when it arrives,

    d_k = (lag_k + latency_k) x time_scale

of simulation time after the sample (plant/realtime.py: the arrival's simulation time
less t_k), less the plant's pauses between the two (:func:`paused_before`). The latency
is the simulator's own message (one per applied correction, in order); the lag comes
from the recorded publish times relative to sample 0, whose own lag (the time the
simulator took between its clock's start and publishing sample 0) is not recorded: it is
fitted as one constant offset minimising the median departure (a grid over the window,
then Brent: :func:`grazing_control.recordings.lag_fit.window_minimum`), no smaller than
the largest lead of a sample over sample 0 (every lag is >= 0), to a tenth of the
stamps' resolution (1 ns). The model is the caller's: ``predict(k, delay)``, the
next sample from sample k with its correction ``delay`` after it (0: on the sample), by
the core's own period (the 1-DOF closed form, :func:`grazing_control.recordings.numbers.
realtime_numbers`; the n-DOF model's, :func:`grazing_control.recordings.analysis.
ndof_scene_numbers`). What is left is what the recorded wall-clock timestamps cannot
resolve (their resolution, times the time scale).

:func:`realtime_lines` are the report's lines of both, the same for every model, with the
line that says why a realtime run departs from the undelayed design when the arrival
explains it (issue 32: nothing lost, nothing silent).
"""

from __future__ import annotations

import numpy as np

__all__ = ["distribution", "realtime_numbers", "delay_check", "kicks_on_the_sample",
           "acts_on_arrival", "realtime_lines", "EXPLAINED_FRACTION"]

#: The delay check explains a run when its median departure is below this fraction of
#: the median departure with the kicks on the sample (a tenth: the realtime scenes
#: recorded here leave 1-3 %, docs/benchmarks.md).
EXPLAINED_FRACTION = 0.1
#: Periods of the delay check's grid over sample 0's lag (recordings/lag_fit.py; its
#: refinement uses up to ``fit_samples``).
COARSE_SAMPLES = 40


def distribution(a_ms) -> dict | None:
    """n, p50, p90, p99, max, mean of ``a_ms`` (None when empty)."""
    a = np.asarray(a_ms, float)
    if a.size == 0:
        return None
    return {"n": int(a.size), "p50": float(np.percentile(a, 50)),
            "p90": float(np.percentile(a, 90)), "p99": float(np.percentile(a, 99)),
            "max": float(a.max()), "mean": float(a.mean())}


def acts_on_arrival(sim: dict) -> bool:
    """Whether a realtime simulator of this parameter record applied each correction on
    its arrival (docs/nodes.md, "Modes": ``actuation`` on_arrival, or auto with neither
    ``actuation_delay`` nor ``jitter``)."""
    how = sim.get("actuation", "auto")
    if how == "on_arrival":
        return True
    if how != "auto":
        return False
    return not any(isinstance(sim.get(k), (int, float)) and sim.get(k) > 0.0
                   for k in ("actuation_delay", "jitter"))


#: Simulation seconds a stamp (whole ns) may lie off the time it rounds.
STAMP_ROUNDING = 1e-9


def paused_before(pauses: np.ndarray, t) -> np.ndarray:
    """Wall seconds the plant's clock had paused before what is due at simulation time(s)
    ``t`` went out: the sum of the pauses (rows: the simulation time up to which
    everything had gone out before the pause, seconds) with that time before t (a sample
    at that very time had gone out before; within STAMP_ROUNDING, as its stamp rounds)."""
    t = np.asarray(t, dtype=float)
    if pauses.size == 0:
        return np.zeros_like(t)
    total = np.concatenate([[0.0], np.cumsum(pauses[:, 1])])
    return total[np.searchsorted(pauses[:, 0] + STAMP_ROUNDING, t, side="left")]


def realtime_numbers(sd, time_scale) -> dict:
    """Latency, answer time, late and missing answers, deadline misses, substitutions,
    sample lag (wall clock) of one scene (module docstring); ``time_scale`` None: estimated
    from the publish times. A rig scene read by what acted (:func:`.rig_acts.apply_acts`,
    any number of masses): its answers are the commands of the rig's sections, and the
    late answers the rig's own count (``rig/applied``), with its count per status."""
    out = {}
    if sd.latency_s.size:
        out["latency_ms"] = distribution(sd.latency_s * 1e3)
        out["latency_source"] = "the simulator's latency messages (sample published -> answer received)"
    ans = sd.answered & (sd.corr_pub_ns >= 0) & (sd.pi2_pub_ns > 0)
    rt = (sd.corr_pub_ns[ans] - sd.pi2_pub_ns[ans]) / 1e6
    out["answer_time_ms"] = distribution(rt)
    out["answer_time_source"] = ("correction publish time - sample publish time (source "
                                 "timestamps, wall clock)")
    nxt = np.append(sd.pi2_pub_ns[1:], np.iinfo(np.int64).max)
    late = ans & (sd.corr_pub_ns > nxt)
    out["late_answers"] = int(np.count_nonzero(late))
    out["missing_answers"] = int(np.count_nonzero(~sd.answered))
    out["deadline_misses"] = sd.deadline_misses
    out["substituted"] = len(sd.substituted)
    ts = time_scale
    t = sd.scene.t
    # on the plant's clock: the pauses before each sample taken out of its wall time
    wall = (sd.pi2_pub_ns - sd.pi2_pub_ns[0]) / 1e9 - paused_before(sd.pauses, t)
    if sd.pauses.size:
        out["plant_pauses"] = {"count": int(len(sd.pauses)),
                               "total_ms": float(sd.pauses[:, 1].sum() * 1e3),
                               "longest_ms": float(sd.pauses[:, 1].max() * 1e3)}
    if ts is None and len(t) > 2 and np.all(sd.pi2_pub_ns > 0):
        slope = np.polyfit(t - t[0], wall, 1)[0]
        ts = 1.0 / slope if slope > 0 else None
        out["time_scale_source"] = "estimated from the publish times"
    out["time_scale"] = ts
    if ts:
        lag = (wall - (t - t[0]) / ts) * 1e3
        out["sample_lag_ms"] = distribution(lag)
        out["_lag_ms"] = lag
    out["_answer_ms"] = rt
    if sd.rig_late is not None:      # a rig scene off the rig's grid: the rig's own count
        out["late_answers"] = sd.rig_late
        out["late_source"] = ("the rig's count (rig/applied): a command recorded for a "
                              "section where a prediction or nothing acted")
        out["rig_applied"] = sd.rig_status
    return out


def delay_check(sd, rt: dict, predict, period: float, corrections=None,
                fit_samples: int = 300) -> dict | None:
    """Model check with each correction applied at its measured arrival (module
    docstring): ``predict(k, delay)`` gives the next sample (an array like the scene's
    Pi2 rows) from sample k with its correction ``delay`` after it (0: on the sample; a
    delay outside (0, period) is given as 0), or raises (counted as departed).

    Returns the fitted lag of sample 0 (ms), the largest and median departures over the
    periods with a non-zero correction, the median and largest delays (simulation time)
    and their wall-clock median (ms); None when the data do not allow it (a sample
    without answer, latencies missing, no time scale, no correction).
    """
    from .lag_fit import window_minimum

    ts, lat, lag = rt.get("time_scale"), sd.latency_s, rt.get("_lag_ms")
    pi2 = sd.scene.pi2
    dv = sd.scene.correction if corrections is None else corrections
    n = len(sd.scene.t)
    if not ts or lag is None or lat.size != n or not sd.answered.all() or n < 3:
        return None
    base = lat + lag / 1e3                 # the delays less sample 0's lag, the offset
    if sd.pauses.size:                     # less a pause between a sample and its answer
        t = sd.scene.t
        base = base - (paused_before(sd.pauses, t + base * ts) - paused_before(sd.pauses, t))
    least = max(0.0, -float(np.min(lag)) / 1e3)

    def departures(offset, ks):
        out = np.empty(len(ks))
        for j, k in enumerate(ks):
            d = float((base[k] + offset) * ts)
            try:
                nxt = predict(k, d if 0.0 < d < period else 0.0)
            except Exception:
                out[j] = np.inf
                continue
            out[j] = float(np.max(np.abs(np.asarray(nxt) - pi2[k + 1])))
        return out

    active = np.flatnonzero(dv[:-1] != 0.0)
    if active.size == 0:
        return None
    fit = active[:: max(1, active.size // fit_samples)]
    probe = fit[:: max(1, fit.size // COARSE_SAMPLES)]    # the grid's cheaper misfit
    offset = window_minimum(lambda c: float(np.median(departures(c, fit))), least,
                            least + 5e-3, xatol=1e-10,
                            coarse=lambda c: float(np.median(departures(c, probe))))
    dep = departures(offset, active)
    delays = (base[active] + offset) * ts
    return {"fitted_first_sample_lag_ms": offset * 1e3,
            "max_departure": float(dep.max()), "median_departure": float(np.median(dep)),
            "median_delay": float(np.median(delays)), "max_delay": float(delays.max()),
            "median_delay_ms": float(np.median(delays)) / ts * 1e3,
            "period": float(period), "periods": int(active.size)}


def kicks_on_the_sample(dc: dict | None, departures, corrections) -> None:
    """Add to the delay check ``dc`` the median departure of the model check with the
    kicks on the sample (``departures``, per period; NaN: not checked) over the same
    periods (a non-zero correction), and whether the arrival explains the run (its median
    departure below :data:`EXPLAINED_FRACTION` of that)."""
    if not dc:
        return
    dep = np.asarray(departures, float)
    active = np.flatnonzero(np.asarray(corrections)[:dep.size] != 0.0)
    on_sample = dep[active][~np.isnan(dep[active])] if active.size else dep[:0]
    dc["median_departure_kicks_on_pi2"] = (float(np.median(on_sample)) if on_sample.size
                                           else None)
    ref = dc["median_departure_kicks_on_pi2"]
    dc["explains_model_check"] = bool(ref is not None and ref > 0.0 and
                                      dc["median_departure"] < EXPLAINED_FRACTION * ref)


def _d(x) -> str:
    return ("—" if not x else f"p50 {x['p50']:.3g}, p90 {x['p90']:.3g}, p99 {x['p99']:.3g}, "
            f"max {x['max']:.3g} ms (n = {x['n']})")


def realtime_lines(n: dict, bound: float = 1e-9) -> list:
    """The report's realtime lines of a scene's numbers ``n`` (keys ``realtime``,
    ``model_check``): latency, answer time, late and missing answers, misses, sample lag,
    the delay check, and where the model check departs beyond ``bound`` and the arrival
    explains it, the line that says so and what to do (docs/nodes.md, "Scheduled
    actuation")."""
    from .analysis import fmt

    rt = n.get("realtime")
    if not rt:
        return []
    misses = rt["deadline_misses"]
    lines = [f"* realtime latency (sim, sample published → answer received): {_d(rt.get('latency_ms'))}",
             f"* answer time (controller, source timestamps): {_d(rt.get('answer_time_ms'))}",
             f"* late answers ({rt.get('late_source', 'sent after the next sample')}): "
             f"{rt['late_answers']}; samples "
             f"without an answer: {rt['missing_answers']}; deadline misses: "
             f"{fmt(misses) if misses is not None else 'topic not recorded'}"
             + (f" ({rt['substituted']} predictions substituted)" if rt.get("substituted")
                else ""),
             f"* sample lag (published vs due, time scale {fmt(rt.get('time_scale'))}"
             f"{', ' + rt['time_scale_source'] if 'time_scale_source' in rt else ''}): "
             f"{_d(rt.get('sample_lag_ms'))}"]
    pp = rt.get("plant_pauses")
    if pp:
        lines.append(f"* the plant's clock paused {pp['count']} times for stalls of the "
                     f"simulator, {pp['total_ms']:.3g} ms in all, the longest "
                     f"{pp['longest_ms']:.3g} ms (stall_pause: not charged to the deadlines; "
                     "the sample lag above is on the paused clock)")
    dc = rt.get("delay_check")
    mc = n.get("model_check") or {}
    if not dc:
        return lines
    lines.append(
        f"* why a realtime run departs from the model with kicks on Π2: applying each "
        f"non-zero correction at its measured arrival ((sample lag + latency) × time "
        f"scale after Π2, median {dc['median_delay']:.3g}; the first sample's own lag, "
        f"not recorded, fitted: {dc['fitted_first_sample_lag_ms']:.3g} ms) leaves a "
        f"departure of median {dc['median_departure']:.2e}, max "
        f"{dc['max_departure']:.2e} over {dc['periods']} periods, against median "
        f"{fmt(dc.get('median_departure_kicks_on_pi2'), '.2e')}, max "
        f"{fmt(mc.get('max_departure'), '.2e')} with the kicks on Π2; the rest is the "
        "microsecond resolution of the recorded wall-clock timestamps, times the time scale")
    worst = mc.get("max_departure")
    if worst is not None and not worst <= bound:
        head = (f"* **the corrections acted on arrival**, median {dc['median_delay_ms']:.3g} ms "
                f"({dc['median_delay']:.3g} in simulation time, "
                f"{100 * dc['median_delay'] / dc['period']:.2g} % of the period; largest "
                f"{dc['max_delay']:.3g}) after their samples, not on the sample as the "
                "undelayed design (gains, predicted orbit and contraction above) assumes")
        if dc.get("explains_model_check"):
            lines.append(head + f": re-integrated at their arrival the periods depart by "
                         f"{dc['median_departure']:.1e} (median) against "
                         f"{dc['median_departure_kicks_on_pi2']:.1e} on the sample, so the "
                         "arrival explains the model check's departure; for a realtime run "
                         "that behaves as designed, design for a delay above the largest "
                         "arrival (grazing design --delay D) and run with actuation "
                         "scheduled (docs/nodes.md, \"Scheduled actuation\")")
        else:
            lines.append(head + f"; re-integrated at their arrival the periods still depart "
                         f"by {dc['median_departure']:.1e} (median; "
                         f"{fmt(dc.get('median_departure_kicks_on_pi2'), '.1e')} on the "
                         "sample): the arrival does not explain the model check's departure "
                         "(a lost message, or not the run's model)")
    return lines

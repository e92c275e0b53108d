"""``grazing analyze BAG...``: a report (markdown, JSON, PNG panels) from recordings alone.

For each bag (:func:`.scenes.load`) and each scene in it, the numbers of
:func:`.numbers.scene_numbers`; with several scenes a comparison table. The report says
where each parameter came from (the bag's parameter record, an option, the study's
defaults, or inferred from the data) and what the bag lacked or held that could not be
used. Documented in docs/analysis.md.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from grazing_control.support.arguments import finite, non_empty_path, positive
from . import reader
from .analysis import (control_lines, convergence, fmt, is_ndof, ndof_lines,
                       ndof_scene_numbers, ndof_setup, plot_ndof_scene)
from .estimates import estimate_lines, estimate_numbers, read_estimates
from .numbers import (MODEL_CHECK_BOUND, resolve_setup, scene_numbers, scene_problems,
                      section_phase_problems)
from .rig_acts import apply_acts, offgrid_line, read_acts, summary as rig_acts_summary
from .rig_record import check_against_model, read_rig, si_numbers
from .scenes import load, parse_topic_options
from .timing import realtime_lines

#: The controller's model watch (issue 29: bias, Delta d, consistency verdicts).
WATCH_TOPIC = "/controller/model_watch"
#: The controller's re-identification decisions (issue 29 section 3: switches, refusals).
SWITCH_TOPIC = "/controller/model_switch"

__all__ = ["analyze", "add_arguments", "main"]


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    return obj


def _setup_value(setup, key):
    if key == "gains":
        g = setup.gains
        return "unknown" if g is None else f"c1 {g.c1!r}, c2 {g.c2!r}"
    if setup.params is not None and hasattr(setup.params, key):
        return repr(getattr(setup.params, key))
    return fmt(getattr(setup, key, None))


def _label(path: Path, used: set) -> str:
    name = path.name[:-5] if path.name.endswith(".mcap") else path.name
    label, i = name, 2
    while label in used:
        label, i = f"{name}_{i}", i + 1
    used.add(label)
    return label


def plot_scene(sd, numbers: dict, setup, title: str, path) -> None:
    """Panels: Pi2 samples, x per sample, impact velocities, corrections, contraction,
    and for realtime runs the latency, answer-time and sample-lag histograms."""
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()

    scene = sd.scene
    on = numbers["control_on_sample"]
    on_ = on if on is not None else len(scene.t)
    rt = numbers.get("realtime")
    rows = 3 if rt else 2
    fig, ax = plt.subplots(rows, 3, figsize=(15, 4 * rows), constrained_layout=True)
    k = np.arange(len(scene.t))
    a = ax[0, 0]
    a.plot(scene.pi2[:on_, 0], scene.pi2[:on_, 1], ".", ms=2, color="tab:red", label="before control")
    a.plot(scene.pi2[on_:, 0], scene.pi2[on_:, 1], ".", ms=3, color="tab:blue", label="after control")
    pred = numbers.get("predicted", {})
    if "orbit_pi2" in pred:
        a.plot(*pred["orbit_pi2"], "k+", ms=14, label="exact controlled 1/1 orbit")
    a.set(xlabel="x on Π2", ylabel="v on Π2", title="Π2 samples")
    a.legend(fontsize=8)
    a = ax[0, 1]
    a.plot(k, scene.pi2[:, 0], ".", ms=2)
    if on is not None:
        a.axvline(on, color="k", lw=0.8, ls="--", label="control on")
        a.legend(fontsize=8)
    a.set(xlabel="sample k", ylabel="x on Π2", title="Π2 position per forcing period")
    a = ax[0, 2]
    if len(scene.impacts):
        period = np.median(np.diff(scene.t)) if len(scene.t) > 1 else 1.0
        a.semilogy((scene.impacts[:, 0] - scene.t[0]) / period, np.abs(scene.impacts[:, 1]),
                   ".", ms=2)
    else:
        a.text(0.5, 0.5, "no impacts recorded", ha="center", transform=a.transAxes)
    if on is not None:
        a.axvline(on, color="k", lw=0.8, ls="--")
    a.set(xlabel="time / T", ylabel="impact velocity v⁻", title="impact velocities")
    a = ax[1, 0]
    a.plot(k, scene.correction, ".-", ms=2, lw=0.5)
    if numbers["corrections"]["saturation"] is not None:
        for s in (-1, 1):
            a.axhline(s * numbers["corrections"]["saturation"], color="tab:red", lw=0.8, ls=":")
    a.set(xlabel="sample k", ylabel="Δv", title="velocity corrections")
    a = ax[1, 1]
    meas = numbers.get("measured_contraction")
    if meas and meas.get("distances"):
        e = np.array(meas["distances"])
        kk = np.arange(len(e)) + on
        a.semilogy(kk, np.maximum(e, 1e-18), "o-", ms=3, label="|X_k − X_final| (recorded)")
        if meas.get("rho"):
            for rho, style, lab in ((meas["rho"], "-", f"measured ρ = {meas['rho']:.5f}"),
                                    (pred.get("rho"), "--", f"predicted |λ|max = "
                                     f"{fmt(pred.get('rho'), '.5f')}")):
                if rho:
                    ks = np.arange(meas["first"], meas["last"] + 1)
                    a.semilogy(ks, np.exp(meas["intercept"]) * rho ** (ks - on), style, lw=1,
                               label=lab)
        a.axhline(meas["floor"], color="gray", lw=0.6, ls=":", label="rounding floor")
        a.legend(fontsize=8)
    else:
        a.text(0.5, 0.5, "no convergence to measure", ha="center", transform=a.transAxes)
    a.set(xlabel="sample k", ylabel="distance", title="contraction per sample after control")
    a = ax[1, 2]
    dep = numbers.get("_departures")
    if dep is not None and len(dep):
        a.semilogy(np.arange(len(dep)), np.maximum(dep, 1e-18), ".", ms=2)
    a.set(xlabel="sample k", ylabel="|core step − recorded next sample|",
          title="model check: core step vs recorded")
    if rt:
        for a, key, lab in ((ax[2, 0], None, "latency (sim: sample published → answer received) [ms]"),
                            (ax[2, 1], "_answer_ms", "answer time (controller) [ms]"),
                            (ax[2, 2], "_lag_ms", "sample lag [ms]")):
            data = sd.latency_s * 1e3 if key is None else rt.get(key)
            if data is not None and len(data):
                a.hist(data, bins=60)
                a.set_yscale("log")
            else:
                a.text(0.5, 0.5, "not recorded", ha="center", transform=a.transAxes)
            a.set(xlabel=lab, ylabel="count")
    from matplotlib.ticker import MaxNLocator

    for a in ax.flat:           # sample numbers are integers, whatever the scene's length
        if a.get_xlabel() == "sample k":
            a.xaxis.set_major_locator(MaxNLocator(integer=True))
        a.title.set_fontsize(10)
    fig.suptitle(title)
    save_png(fig, path, dpi=90)


def read_watch(path, topic: str = WATCH_TOPIC) -> dict | None:
    """The model watch's rows ({field: column} of :data:`WATCH_FIELDS` and ``stamp``, in
    stamp order), or None when the bag has no such topic or no row."""
    from grazing_control.ros.model_watch import WATCH_FIELDS

    raw = reader.read_raw(Path(path), topics=[topic])
    if topic not in raw.channels:
        return None
    cols = reader.decode_values(raw, topic, len(WATCH_FIELDS))
    ok = cols["ok"]
    if not np.any(ok):
        return None
    order = np.argsort(cols["stamp"][ok], kind="stable")
    rows = {name: cols["values"][ok][order, i] for i, name in enumerate(WATCH_FIELDS)}
    rows["stamp"] = cols["stamp"][ok][order]
    return rows


def watch_numbers(rows, period_s: float | None = None) -> dict | None:
    """What the model watch said (issue 29): the last bias and Delta d estimates with
    their standard errors, the sections with a mismatch verdict, the first one (its
    section index when the period is known) and how often each test failed, and the
    last verdict's statistics against their bounds."""
    if rows is None:
        return None
    last = {k: float(v[-1]) for k, v in rows.items() if k != "stamp"}
    mismatch = rows["mismatch"] == 1.0
    out = {"sections": int(rows["stamp"].size), "mismatch_sections": int(mismatch.sum()),
           "failing": {t: int(np.sum(rows[f"fail_{t}"] == 1.0))
                       for t in ("nis", "mean", "resets")},
           "last": last}
    for name in ("bias", "delta_d"):
        if math.isfinite(last[name]):
            out[name] = [last[name], last[f"{name}_se"]]
    if np.any(mismatch):
        first = int(rows["stamp"][np.flatnonzero(mismatch)[0]])
        out["first_mismatch_stamp_ns"] = first
        if period_s:
            out["first_mismatch_section"] = int(round(first * 1e-9 / period_s))
    return out


def read_switches(path, topic: str = SWITCH_TOPIC, period_s: float | None = None) -> list:
    """The re-identification's decisions in stamp order: one dict per row of
    :data:`grazing_control.ros.reidentify.SWITCH_FIELDS` (NaN as None), ``switched`` a
    bool, ``reason`` its name (None: switched), ``stamp_ns`` and, with the period, the
    ``section``; [] when the bag has none."""
    from grazing_control.dynamics.estimation.reidentification import REASONS
    from grazing_control.ros.reidentify import SWITCH_FIELDS

    raw = reader.read_raw(Path(path), topics=[topic])
    if topic not in raw.channels:
        return []
    cols = reader.decode_values(raw, topic, len(SWITCH_FIELDS))
    ok = cols["ok"]
    out = []
    for i in np.flatnonzero(ok)[np.argsort(cols["stamp"][ok], kind="stable")]:
        row = {n: (float(v) if math.isfinite(v) else None)
               for n, v in zip(SWITCH_FIELDS, cols["values"][i])}
        row["switched"] = row["switched"] == 1.0
        code = row["reason"]
        row["reason"] = None if not code else (REASONS[int(code) - 1]
                                               if 1 <= code <= len(REASONS) else str(code))
        row["stamp_ns"] = int(cols["stamp"][i])
        if period_s:
            row["section"] = int(round(row["stamp_ns"] * 1e-9 / period_s))
        out.append(row)
    return out


def _switch_lines(rows) -> list:
    """The report's lines on the re-identification (:func:`read_switches`)."""
    lines = []
    for r in rows:
        at = r.get("section", f"{r['stamp_ns']} ns")
        req = "" if r["requested_at"] is None else f", requested at section {r['requested_at']:.0f}"
        fit = ("" if r["zeta"] is None else
               f"refit zeta {r['zeta']:.6g} ± {r['zeta_se']:.2g}, r {r['r']:.6g} ± "
               f"{r['r_se']:.2g}, Δd {r['delta_d']:.6g} ± {r['delta_d_se']:.2g} "
               f"({r['periods']:.0f} periods, {r['impacts']:.0f} impacts)")
        if r["switched"]:
            lines.append(f"* model switched at section {at}{req}: {fit}; gains c1 "
                         f"{r['c1']:.6g}, c2 {r['c2']:.6g}; X** ({r['x_ref']:.6g}, "
                         f"{r['v_ref']:.6g})")
        else:
            lines.append(f"* re-identification refused at section {at}{req} "
                         f"({r['reason']}){': ' + fit if fit else ''}; model and gains kept")
    return lines


def _watch(bag, period_s: float | None) -> dict | None:
    """The model watch's numbers of ``bag`` (:func:`watch_numbers` of :func:`read_watch`,
    None without the topic), for a bag of any model; its stamps are simulation time, the
    period ``period_s`` gives the first mismatch's section."""
    return watch_numbers(read_watch(bag), period_s)


def _watch_lines(n) -> list:
    """The report's lines on the model watch (:func:`watch_numbers`)."""
    if not n:
        return []
    lines = []
    for name, label in (("bias", "sensor bias"), ("delta_d", "Δd")):
        if name in n:
            lines.append(f"* {label} estimate (last section): {n[name][0]:.6g} ± "
                         f"{n[name][1]:.3g} (standard error)")
    last = n["last"]
    if math.isfinite(last["nis"]) or n["mismatch_sections"]:
        first = n.get("first_mismatch_section", n.get("first_mismatch_stamp_ns"))
        lines.append(
            f"* consistency test: {n['mismatch_sections']} of {n['sections']} sections with "
            f"a model mismatch verdict" + ("" if first is None else f" (first: section {first}"
                                          + ("" if "first_mismatch_section" in n else " ns")
                                          + ")")
            + "; failing: " + ", ".join(f"{t} {c}" for t, c in n["failing"].items())
            + f"; last window: nis {last['nis']:.4g} (bound {last['nis_bound']:.4g}, "
              f"{last['nis_dof']:.0f} dof), mean {last['mean']:.4g} (bound "
              f"{last['mean_bound']:.4g}, {last['mean_dof']:.0f} dof)")
    return lines


def _scene_lines(label, numbers, fig_name):
    n = numbers
    u = n["uncontrolled"]
    pred = n["predicted"]
    c = n["corrections"]
    lines = [f"### {label}", "", f"![{label}]({fig_name})", "",
             f"* samples: {n['samples']} over {n['duration_s']:.6g} s of simulation time",
             f"* uncontrolled attractor: {('period ' + str(u['period'])) if u['period'] else u['kind']}; "
             f"impacts per period before control (histogram 0, 1, 2, …): "
             f"{u['impacts_per_period_histogram']}"]
    lines += control_lines(n)
    if "final_vs_exact_orbit" in n:
        lines.append(f"* final Π2 sample ({n['final_pi2'][0]:.12g}, {n['final_pi2'][1]:.12g}) vs "
                     f"the exact controlled 1/1 orbit ({pred['orbit_pi2'][0]:.12g}, "
                     f"{pred['orbit_pi2'][1]:.12g}): {n['final_vs_exact_orbit']:.2e}; impacts "
                     f"per period at the end: {fmt(n['final_impacts_per_period'])}; v⁻ "
                     f"{fmt(n['final_v_minus'], '.8g')} (exact {pred['orbit_v_minus']:.8g})")
    lines.append(f"* corrections: {c['answered']} answers, {c['missing']} samples without one, "
                 f"{c['nonzero']} non-zero, max |Δv| = {c['max_abs']:.3g}, saturation "
                 f"{fmt(c['saturation'])} hit {c['saturation_hits']} times"
                 + (f"; {c['duplicate_answers']} duplicate answers ({c['conflicting_answers']} "
                    "with different values: two controllers?)" if c["duplicate_answers"] else "")
                 + (f"; {c['answers_matching_no_sample']} answers match no sample"
                    if c["answers_matching_no_sample"] else ""))
    mc = n.get("model_check")
    lines += estimate_lines(n.get("estimate"))
    if mc:
        lines.append(f"* model check: each recorded period re-integrated by the core from the "
                     f"recorded sample and correction departs from the next recorded sample by "
                     f"at most {fmt(mc['max_departure'], '.2e')} ({mc['periods_above_1e-12']} "
                     f"of {mc['periods']} periods above 1e-12"
                     + (f"; each period at the plant's Δd of that period, the wall "
                        f"drifting by {mc['delta_d_drift']:g} per period"
                        if mc.get("delta_d_drift") else "")
                     + (f"; the {mc['dropped_at_deadline_misses']} answers missed at "
                        "deadline misses re-integrated as what acted instead ("
                        f"{mc.get('predictions_substituted', 0)} predictions, 0 otherwise)"
                        if mc.get("dropped_at_deadline_misses") else "")
                     + (f"; checked only the first {mc['periods']} of "
                        f"{mc['periods_in_scene']} periods" if mc.get("periods_in_scene", 0)
                        > mc["periods"] else "") + ")")
    lines += realtime_lines(n, MODEL_CHECK_BOUND)
    lines.append("")
    return lines


_COLUMNS = [("bag / scene", None), ("mode", None), ("Δd", ".3g"), ("c2", ".4g"),
            ("on at", None), ("converged", None), ("ρ measured", ".5f"),
            ("\\|λ\\|max predicted", ".5f"), ("\\|final − exact\\|", ".1e"),
            ("max \\|Δv\\|", ".2e"),
            ("sat. hits", None), ("missing", None), ("model check", ".1e"),
            ("latency p50/p99 ms", None), ("late", None), ("deadline misses", None)]


def _row(label, setup, n):
    rt = n.get("realtime") or {}
    lat = rt.get("latency_ms") or rt.get("answer_time_ms")
    meas = n.get("measured_contraction") or {}
    vals = [label, setup.mode, setup.params.delta_d if setup.params else None,
            setup.gains.c2 if setup.gains else None, n["control_on_sample"],
            n["samples_to_converge"], meas.get("rho"), n["predicted"].get("rho"),
            n.get("final_vs_exact_orbit"), n["corrections"]["max_abs"],
            n["corrections"]["saturation_hits"], n["corrections"]["missing"],
            (n.get("model_check") or {}).get("max_departure"),
            f"{lat['p50']:.3g}/{lat['p99']:.3g}" if lat else None,
            rt.get("late_answers"), rt.get("deadline_misses")]
    return "| " + " | ".join(fmt(v, spec) if spec else fmt(v)
                             for v, (_, spec) in zip(vals, _COLUMNS)) + " |"


def analyze(bags, out=None, *, topics=None, options=None, tol=1e-8, figures=True) -> dict:
    """Analyse bags; write report.md, report.json and one PNG per scene under ``out``.

    Returns the report as a JSON-serialisable dict. Raises ValueError (BagReadError,
    DuplicateStampsError, ParameterError) for a bag that cannot be analysed.
    """
    options = dict(options or {})
    out = Path(out) if out is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    report = {"bags": [], "comparison": []}
    lines = ["# Bag analysis", ""]
    rows = []
    used = set()
    per_bag = topics if isinstance(topics, list) else [topics] * len(bags)
    for bag, bag_topics in zip(bags, per_bag):
        data = load(bag, bag_topics)
        if is_ndof(data):            # an n-DOF scene (issue 17): per-coordinate numbers
            rig = read_rig(bag)[0]
            entry, bag_lines = _ndof_bag(bag, data, _label(Path(bag), used), out, tol,
                                         figures, rig, _acts(bag, data, rig))
            lines += bag_lines
            report["bags"].append(_jsonable(entry))
            continue
        setup = resolve_setup(data, options)
        data.problems.extend(section_phase_problems(data, setup))
        estimates = read_estimates(bag)
        rig, rig_notes = read_rig(bag)
        acts = _acts(bag, data, rig)
        numbers = []
        for sd in data.scenes:
            n = scene_numbers(sd, setup, tol)
            if estimates is not None:
                n["estimate"] = estimate_numbers(estimates, sd, setup)
            data.problems.extend(scene_problems(sd, setup, n))
            numbers.append(n)
        period_s = None if setup.params is None else setup.params.period
        watch = _watch(bag, period_s)
        switches = read_switches(bag, period_s=period_s)
        rig_notes += model_differences(data.parameters)
        if rig is not None:
            rig_notes += [f"rig mismatch: {m} (the SI numbers use the rig's scales)"
                          for m in check_against_model(rig, setup.params)]
            for sd, n in zip(data.scenes, numbers):
                n["si"] = si_numbers(rig, n, sd.scene)
        label = _label(Path(bag), used)
        entry = {**_bag_entry(bag, data, label, setup.notes + rig_notes),
                 "rig": None if rig is None else _rig_entry(rig),
                 **({"rig_commands_off_grid": rig_acts_summary(acts)} if acts and acts["timed"]
                    else {}),
                 "model_watch": watch,
                 "model_switches": switches,
                 "setup": {"params": ({k: getattr(setup.params, k) for k in
                                       ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset")}
                                      if setup.params else None),
                           "gains": ({"c1": setup.gains.c1, "c2": setup.gains.c2}
                                     if setup.gains else None),
                           "mode": setup.mode, "time_scale": setup.time_scale,
                           "saturation": setup.saturation, "enable_after": setup.enable_after,
                           "actuation_delay": setup.actuation_delay,
                           "sources": setup.sources},
                 "scenes": []}
        lines += [f"## {label}", "", _file_line(data),
                  "* parameter record: " + ("yes" if entry["parameter_record"] else
                                            "none in this bag (it predates the record, or the "
                                            "nodes did not publish one): options, defaults and "
                                            "inference are used"),
                  "* parameters: " + "; ".join(
                      f"{k} = {_setup_value(setup, k)} ({v})" for k, v in setup.sources.items()),
                  "* topics used: " + ", ".join(f"{r} = {t}" for r, t in data.present.items())]
        if rig is not None:
            lines.append(_rig_line(entry["rig"]))
            lines += [x for x in [offgrid_line(acts)] if x]
        lines += [f"* note: {s}" for s in entry["notes"]]
        lines += [f"* **cannot use**: {s}" for s in data.problems]
        lines += _watch_lines(watch)
        lines += _switch_lines(switches)
        lines.append("")
        for sd, n in zip(data.scenes, numbers):
            slabel, fig_name = _scene_label(label, data, sd)
            if out is not None and figures:
                title = (f"{slabel}: {setup.mode}, Δd = {fmt(setup.params.delta_d if setup.params else None, '.3g')}")
                plot_scene(sd, n, setup, title, out / fig_name)
                n["figure"] = fig_name
            lines += _scene_lines(slabel, n, fig_name)
            if "si" in n:
                lines[-1:-1] = _si_lines(n["si"])
            rows.append(_row(slabel, setup, n))
            entry["scenes"].append(_jsonable(n))
        report["bags"].append(_jsonable(entry))
    if len(rows) > 1:
        lines += ["## Comparison", "",
                  "| " + " | ".join(c for c, _ in _COLUMNS) + " |",
                  "|" + "---|" * len(_COLUMNS)] + rows + [""]
    report["comparison"] = rows
    report["markdown"] = "\n".join(lines) + "\n"
    if out is not None:
        (out / "report.md").write_text(report["markdown"], encoding="utf-8")
        (out / "report.json").write_text(json.dumps({k: v for k, v in report.items()
                                                     if k != "markdown"}, indent=1) + "\n",
                                         encoding="utf-8")
    return report


_finite = finite


#: The model parameters a controller and a simulator both hold (1-DOF).
MODEL_KEYS = ("zeta", "r", "omega", "delta_d", "pi2_offset")


def model_differences(parameters) -> list:
    """Notes where the controller's model (its parameter record) is not the simulator's:
    a model-error scene says so (issue 28: a controller designed on another rig file ran
    against the plant and the analysis did not mention it)."""
    nodes = (parameters or {}).get("nodes") or {}
    ctl = (nodes.get("controller_node") or [{}])[0]
    sim = (nodes.get("sim_node") or [{}])[0]
    out = []
    for key in MODEL_KEYS:
        a, b = ctl.get(key), sim.get(key)
        if (isinstance(a, float) and isinstance(b, float) and math.isfinite(a)
                and math.isfinite(b) and a != b):
            out.append(f"the controller's model differs from the simulator's: {key} = {a!r} "
                       f"(controller) against {b!r} (simulator)")
    return out


def _rig_entry(rig) -> dict:
    """The report's summary of the bag's rig (grazing/rig)."""
    s = rig.scales
    return {"mass_kg": rig.mass, "natural_frequency_Hz": rig.natural_frequency,
            "forcing_frequency_Hz": rig.frequency, "force_amplitude_N": rig.force_amplitude,
            "pulse_width_s": rig.actuator.pulse_width, "sensor_noise_m": rig.sensor.noise,
            "length_scale_m": s.length, "velocity_scale_m_per_s": s.velocity,
            "time_scale_s": s.time}


def _rig_line(r) -> str:
    return (f"* rig (grazing/rig): m = {r['mass_kg']:.6g} kg, f_n = "
            f"{r['natural_frequency_Hz']:.6g} Hz, f = {r['forcing_frequency_Hz']:.9g} Hz, "
            f"F0 = {r['force_amplitude_N']:.6g} N; scales l = {r['length_scale_m']:.6g} m, "
            f"omega_n l = {r['velocity_scale_m_per_s']:.6g} m/s, 1/omega_n = "
            f"{r['time_scale_s']:.6g} s (docs/rig.md)")


def _si_lines(si) -> list:
    """The scene's main numbers in the rig's SI units (:func:`.rig_record.si_numbers`)."""
    def pair(key):
        x, v = si[key]
        return f"{x:.4g} m, {v:.4g} m/s"

    parts = [f"{si['duration_s']:.6g} s"]
    if "control_on_after_s" in si:
        parts.append(f"control on after {si['control_on_after_s']:.6g} s")
    if "converged_after_s" in si:
        parts.append(f"converged after {si['converged_after_s']:.6g} s")
    lines = ["* in SI (the rig's units): " + ", ".join(parts)]
    if "orbit_pi2_m_and_m_per_s" in si:
        lines.append(f"* in SI: controlled orbit on Π2 ({pair('orbit_pi2_m_and_m_per_s')}), "
                     f"impact velocity {si['orbit_v_minus_m_per_s']:.4g} m/s; final Π2 "
                     f"{pair('final_pi2_m_and_m_per_s')}, "
                     f"{pair('final_vs_exact_orbit_m_and_m_per_s')} from the orbit")
    if "pi2_spread_m_and_m_per_s" in si:
        lines.append(f"* in SI: Π2 spread about the controlled orbit (rms, last "
                     f"{si['pi2_spread_window']} samples): {pair('pi2_spread_m_and_m_per_s')}")
    c = si["largest_correction"]
    force = (f", force {c['force_N']:.4g} N over {c['pulse_width_s'] * 1e3:.4g} ms"
             if "force_N" in c else "")
    lines.append(f"* in SI: largest correction Δv {c['velocity_m_per_s']:.4g} m/s, impulse "
                 f"{c['impulse_N_s']:.4g} N s{force}")
    if "estimate_measured_spread_m" in si:
        predicted = (f", predicted from the reported covariance "
                     f"{si['estimate_predicted_spread_m']:.4g} m"
                     if "estimate_predicted_spread_m" in si else "")
        lines.append(f"* in SI: estimate error std {pair('estimate_error_std_m_and_m_per_s')}; "
                     f"Π2 spread measured {si['estimate_measured_spread_m']:.4g} m{predicted}")
    return lines


def _acts(bag, data, rig) -> dict | None:
    """What acted in a rig scene of any number of masses (:mod:`.rig_acts`), applied to
    the bag's scene when the controller's commands are off the rig's grid (then the dict
    of :func:`.rig_acts.read_acts`, else None or that dict untimed: nothing changed)."""
    if rig is None:
        return None
    acts = read_acts(bag, rig, (data.parameters["nodes"].get("sim_node") or [{}])[0])
    if acts and acts["timed"] and len(data.scenes) > 1:
        data.problems.append("the controller's commands are off the rig's grid, but the "
                             "bag holds several scenes: not read by what acted")
        return None
    for sd in data.scenes:      # a rig scene off the rig's grid: what acted (rig_acts)
        apply_acts(sd, acts)
    return acts


def _bag_entry(bag, data, label, notes) -> dict:
    """The report entry's head of a bag of any model: the file, its messages, the topics,
    the notes (the bag's, then ``notes``), the problems, whether it has a parameter record."""
    return {"bag": str(bag), "file": str(data.file), "label": label,
            "closed_cleanly": data.complete, "messages": data.message_count,
            "messages_read": data.messages_read, "topics_used": data.present,
            "notes": data.notes + notes, "problems": data.problems,
            "parameter_record": bool(data.parameters.get("nodes"))}


def _file_line(data) -> str:
    """The report's line on the bag's file: messages, those analysed, a clean close."""
    return (f"* file: `{data.file}` ({data.message_count} messages, {data.messages_read} of "
            f"them on the topics analysed{'' if data.complete else ', not closed cleanly'})")


def _scene_label(label, data, sd):
    """(the scene's label, its figure's file name): the bag's label, with the scene's
    index when the bag holds more than one."""
    slabel = label if len(data.scenes) == 1 else f"{label} scene {sd.index}"
    return slabel, f"{slabel.replace(' ', '_')}.png"


def _ndof_bag(bag, data, label, out, tol, figures, rig=None, acts=None):
    """The report entry and markdown lines of an n-DOF bag (.analysis, a model file's scene): the model
    and gains from its parameter record; options for the 1-DOF model do not apply. A rig
    scene of ``rig``: the model the simulated rig's (its model file names none); off its
    grid (``acts`` timed, :func:`_acts`) read by what acted."""
    timed = bool(acts and acts["timed"])
    setup = ndof_setup(data, rig)
    entry = {**_bag_entry(bag, data, label, setup.notes),
             **({"rig_commands_off_grid": rig_acts_summary(acts)} if timed else {}),
             "setup": {"model_file": setup.model_file, "n": setup.n,
                       "delta_d": setup.model.delta_d if setup.model is not None else None,
                       "gains": setup.gains.tolist() if setup.gains is not None else None,
                       "mode": setup.mode, "enable_after": setup.enable_after,
                       "saturation": setup.saturation,
                       "actuation_delay": setup.actuation_delay},
             "scenes": []}
    lines = [f"## {label}", "", _file_line(data),
             "* topics used: " + ", ".join(f"{r} = {t}" for r, t in data.present.items())]
    lines += [x for x in [offgrid_line(acts)] if x]
    lines += [f"* note: {s}" for s in entry["notes"]]
    lines += [f"* **cannot use**: {s}" for s in data.problems]
    watch = _watch(bag, None if setup.model is None else setup.model.period)
    if watch is not None:       # a controller with a model watch (issue 32)
        entry["model_watch"] = watch
        lines += _watch_lines(watch)
    lines.append("")
    for sd in data.scenes:
        n = ndof_scene_numbers(sd, setup, tol)
        slabel, fig_name = _scene_label(label, data, sd)
        if out is not None and figures:
            dd = setup.model.delta_d if setup.model is not None else None
            plot_ndof_scene(sd, n, f"{slabel}: {setup.mode}, n = {setup.n}, Δd = "
                                   f"{fmt(dd, '.3g')}", out / fig_name)
            n["figure"] = fig_name
        else:
            fig_name = None
        lines += ndof_lines(slabel, setup, n, fig_name)
        entry["scenes"].append(_jsonable(n))
    return entry, lines


def add_model_options(parser) -> None:
    """Options that stand in for a missing parameter record (or override it)."""
    g = parser.add_argument_group("run parameters (default: the bag's parameter record; "
                                  "without one the study's set, Δd and gains inferred)")
    for name, help_ in (("zeta", "damping ratio"), ("r", "restitution"),
                        ("omega", "forcing frequency"), ("pi2-offset", "phase of Π2 after Π1"),
                        ("delta-d", "Δd = d − d*"), ("c1", "gain c1 (default with --c2: Eq. 38)"),
                        ("c2", "gain c2"), ("time-scale", "realtime time scale")):
        g.add_argument(f"--{name}", type=positive if name == "time-scale" else _finite,
                       default=None, help=help_)
    g.add_argument("--mode", choices=("lockstep", "realtime"), default=None,
                   help="simulator mode of the run")
    parser.add_argument("--topic", action="append", default=[], metavar="[N:]ROLE=TOPIC",
                        help="remap a topic (repeatable); roles: pi2, correction, impact, pi1, "
                             "state, latency, deadline_miss, parameters; N: only in the N-th "
                             "bag given (e.g. 2:pi2=/rig/pi2)")


def options_from_args(args) -> dict:
    return {"zeta": args.zeta, "r": args.r, "omega": args.omega, "pi2_offset": args.pi2_offset,
            "delta_d": args.delta_d, "c1": args.c1, "c2": args.c2, "mode": args.mode,
            "time_scale": args.time_scale}


def add_arguments(parser) -> None:
    """The options of ``grazing analyze``."""
    parser.add_argument("bags", nargs="+", metavar="BAG",
                        help="rosbag2 directory or .mcap file (several: a comparison table)")
    parser.add_argument("--out", default="out/analyze", type=non_empty_path,
                        help="report folder (default out/analyze)")
    parser.add_argument("--json", action="store_true",
                        help="print the report as one JSON object (files are written too)")
    parser.add_argument("--tol", type=_finite, default=1e-8,
                        help="convergence tolerance on Π2 (default 1e-8)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG panels")
    add_model_options(parser)


def main(args):
    """``grazing analyze``: returns the report dict (--json) or 0 after printing a summary."""
    if not args.tol > 0:
        raise ValueError(f"--tol={args.tol!r} is invalid: valid range is tol > 0")
    if args.c1 is not None and args.c2 is None:
        raise ValueError("--c1 given without --c2: give both, or --c2 alone (c1 from Eq. 38)")
    topics = parse_topic_options(args.topic, len(args.bags))
    report = analyze(args.bags, args.out, topics=topics, options=options_from_args(args),
                     tol=args.tol, figures=not args.no_figures)
    if args.json:
        return {k: v for k, v in report.items() if k != "markdown"}
    for b in report["bags"]:
        for i, s in enumerate(b["scenes"]):
            m = s.get("measured_contraction") or {}
            where = f"{b['label']}{'' if len(b['scenes']) == 1 else f' scene {i}'}"
            if s["control_on_sample"] is None:
                u = s.get("uncontrolled") or {}
                kind = u.get("kind") or (f"period {u['period']}" if u.get("period") else
                                         "not periodic to 1e-8")   # n-DOF scenes: a period
                print(f"{where}: {b['setup']['mode']}, uncontrolled (the controller never "
                      f"acted), {s['samples']} samples, {kind}")
                continue
            spread = (s.get("si") or {}).get("pi2_spread_m_and_m_per_s")
            print(f"{where}: "
                  f"{b['setup']['mode']}, control on at {s['control_on_sample']}, "
                  f"{convergence(s['samples_to_converge'], s.get('converge_tol'))}, "
                  f"contraction measured {fmt(m.get('rho'), '.5f')} vs "
                  f"predicted {fmt(s['predicted'].get('rho'), '.5f')}, |final - exact| "
                  f"{fmt(s.get('final_vs_exact_orbit'), '.1e')}"
                  + (f", Π2 spread {spread[0]:.3g} m (rig units)" if spread else ""))
        for p_ in b["problems"]:
            print(f"  cannot use: {p_}")
    print(f"report: {Path(args.out) / 'report.md'} (numbers: {Path(args.out) / 'report.json'})")
    return 0

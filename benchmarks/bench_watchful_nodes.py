"""Issue 29's acceptance through the real nodes: the model watch of controller_node
(estimate_bias, track_delta_d, consistency_window; docs/nodes.md, "The model watch").

Lockstep scenes of sim_node, controller_node and the recorder (`launcher.run`), as the
issue measured them: position-only sensor at 200 samples per period (state_period
T/200), sigma 1e-4, pulse width 0.1, actuation delay 3, Delta d = -5e-6, gains from
`grazing design --optimize noise --delay 3`, control on after ``--control-after``
periods. Each scene's bag is read back (`grazing analyze`'s loaders): the simulator's
exact Pi2 samples are the truth. Parts (``--part``, repeatable):

``bias``      sim_node's sensor_bias 1e-4; the controller with and without
              estimate_bias (consistency window 10): the orbit offset (the mean Pi2 x of
              the last ``--window`` periods less the exact orbit of the loop with the
              pulse, the one `grazing analyze` measures spreads about), the spread about
              it, the bias estimate and its standard error at the end (controller/
              model_watch), impacts per period, the filter's resets (exit summary).
``mismatch``  the controller's model with zeta +5 % and Delta d +10 % (the plant's
              exact), consistency window 10, alpha 1e-3, with and without the
              augmentation: the first mismatch section (the detection time, counted
              from the first fitted section), the sections with a mismatch verdict, the
              failing tests, the orbit offset and impacts per period.
``right``     the right model, consistency window 10: the mismatch verdicts per
              evaluated window (false alarms; the design rate is 1e-3).
``gross``     a grossly wrong controller model (zeta +20 %, Delta d +50 %), monitor: which
              tests name it, and whether the loop holds one impact per period.
``drift``     sim_node's delta_d_drift = 20 % of Delta d over 2000 periods (-5e-10 per
              period, |Delta d| growing, as benchmarks/watchful_core.py --part drift),
              against no drift, with the plain model filter and with track_delta_d: the
              spread (RMS) and mean of the Pi2 x about the moving orbit of the pulse loop
              (dynamics.simulation.actuation.pulse_orbit at 21 walls, interpolated) over the
              controlled periods from ``--control-after`` + 100 on, one impact per period,
              the Delta d estimate's error at the end. Use ``--periods 2000``.
``reidentify`` the mismatch scene with re-identification in the loop (reidentify,
              reidentify_periods 20, track_delta_d, consistency window 10): the first
              mismatch section, each decision on controller/model_switch (the section,
              the refitted zeta, r, Delta d with standard errors, the new gains), the
              orbit offset after the last switch (the mean Pi2 x from SETTLE periods
              after it, and after control on, to the end, less the pulse loop's orbit
              of the plant with its gains), mismatch sections after it, impacts per
              period from control on. Use ``--periods 3000``.
``reidentify-right`` the same with the right model: what the test's false alarms
              start (refits of the right model, switches to them or refusals).
``actuator``  sim_node's first-order actuator (actuator_bandwidth 10x and 3x the
              forcing frequency omega, latency 0), the gains of `grazing design
              --optimize noise --delay 3 --pulse-width 0.1 --actuator-bandwidth B` (c1 of
              the exact condition (P1) for the force profile), against the ideal
              actuator's gains in the same plant: one impact per period, the offset and
              spread (RMS) of the Pi2 x about the loop's orbit through the actuator
              (dynamics.simulation.actuator.actuated_design) over the last ``--window`` periods,
              against the design's predicted spread (position only, model filter, 200
              samples per period, times sigma). ``--pi2-source sample``: the
              controller on the exact Pi2 samples (no noise reaches the loop: the
              orbit's offset alone). ``--controller-actuator``: the controller is told
              the pulse and the actuator (its pulse_width, actuator_bandwidth: the
              stream estimator and the prediction integrate the lag exactly); without
              it the estimator models each correction as a kick.
``capture``   the controller's capture rule (capture, default radius 5 sqrt(|Delta d|)
              = 1.1e-2) against switching on at once, from the uncontrolled motion at
              ``--control-after``: the section the rule switched on (exit summary), the
              capture time (dynamics.design.capture.capture_time: one impact per period and
              within 1e-3 of the orbit to the end), the largest |Delta v|.

    .venv/bin/python benchmarks/bench_watchful_nodes.py --part bias --part mismatch \
        --periods 600 --control-after 100
    .venv/bin/python benchmarks/bench_watchful_nodes.py --part actuator --periods 600 \
        --control-after 100 --window 300 --measured benchmarks/out/actuator/nodes.json
    .venv/bin/python benchmarks/bench_watchful_nodes.py --part actuator --periods 600 \
        --control-after 100 --window 300 --controller-actuator
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml as _yaml

from grazing_control.dynamics.design.capture import capture_time
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.recordings.analyze import analyze, read_switches, read_watch
from grazing_control.recordings.scenes import load
from grazing_control.ros import launcher

GRAZING = str(Path(sys.executable).with_name("grazing"))
#: Periods after a model switch before its orbit offset is measured.
SETTLE = 100
DD, SIGMA, RATE, DELAY, WIDTH = -5e-6, 1e-4, 200, 3.0, 0.1


def design(out: Path):
    """The least-noise gains for the delay (the controller's parameter file)."""
    yaml = out / "controller.yaml"
    subprocess.run([GRAZING, "design", "--optimize", "noise", f"--delta-d={DD}", "--delay",
                    str(DELAY), "--out", str(yaml)], check=True, capture_output=True)
    values = _yaml.safe_load(yaml.read_text())["/**"]["ros__parameters"]
    return yaml, Gains(values["c1"], values["c2"], DELAY)


def moving_orbit(g, periods: int, drift: float):
    """The Pi2 x of the pulse loop's orbit per period under the drift (interpolated)."""
    from grazing_control.dynamics.simulation.actuation import pulse_orbit

    ks = np.linspace(0, periods, 21)
    xs = [pulse_orbit(OscillatorParams(delta_d=DD + drift * k), g, WIDTH).pi2[0] for k in ks]
    return np.interp(np.arange(periods + 1), ks, xs)


def scene(yaml, out: Path, periods: int, control_after: int, window: int, *,
          sensor_bias=0.0, controller=None, seed=7, drift=0.0, gains=None, sim=None,
          orbit_x=None) -> dict:
    """One lockstep scene; its numbers (module docstring)."""
    p = OscillatorParams(delta_d=DD)
    over = {"pi2_source": "stream", "estimator": "model"}
    over.update(controller or {})
    t0 = time.time()
    res = launcher.run(None, str(yaml), str(out / "bag"), periods, delta_d=DD,
                       enable_after=control_after, mode="lockstep", timeout=590,
                       sim_overrides={"state_period": p.period / RATE, "sensor_noise": SIGMA,
                                      "sensor_velocity": False, "pulse_width": WIDTH,
                                      "sensor_seed": seed, "sensor_bias": sensor_bias,
                                      "delta_d_drift": drift, **(sim or {})},
                       controller_overrides=over, log_dir=str(out / "logs"))
    wall = time.time() - t0
    if not res.ok:
        return {"failed": str(res)}
    sd = load(out / "bag").scenes[0]
    rep = analyze([out / "bag"], out / "report", figures=False)
    est = rep["bags"][0]["scenes"][0]["estimate"] or {}
    orbit_x = est["spread_about"][0] if orbit_x is None else orbit_x
    t, x = sd.scene.t, sd.scene.pi2[:, 0]
    last = slice(-window, None)
    edges = np.append(t, t[-1] + p.period)
    counts = np.histogram(sd.scene.impacts[:, 0], edges)[0]
    summary = (out / "logs" / "controller_node.log").read_text(errors="replace")
    resets = re.search(r"model_resets=(\d+)", summary)
    captured = re.search(r"captured_at=(\w+)", summary)
    ct = None
    if "spread_about" in est:           # the stream estimator's scenes
        ct = capture_time(sd.scene.pi2[control_after:], counts[control_after:],
                          np.array(est["spread_about"]), 1e-3)
    rows = read_watch(out / "bag")
    watch = rep["bags"][0]["model_watch"]
    num = {"wall_s": wall, "offset": float(np.mean(x[last]) - orbit_x),
           "spread": float(np.sqrt(np.mean((x[last] - orbit_x) ** 2))),
           "std": float(np.std(x[last])),
           "one_impact_after_control": float(np.mean(counts[control_after:] == 1)),
           "not_one_impact": np.flatnonzero(counts != 1).tolist()[-5:],
           "impacts_per_period_after_control": np.bincount(counts[control_after:]).tolist(),
           "resets": int(resets.group(1)) if resets else None, "watch": watch,
           "captured_at": captured.group(1) if captured else None,
           "capture_time": ct, "max_dv": float(np.max(np.abs(sd.scene.correction)))}
    if gains is not None:               # the drift part: about the moving orbit
        ox = moving_orbit(gains, periods, drift)[:x.size]
        held = slice(control_after + 100, None)
        err = x[held] - ox[held]
        num["moving_rms"], num["moving_mean"] = (float(np.sqrt(np.mean(err ** 2))),
                                                 float(np.mean(err)))
        if rows is not None and np.isfinite(rows["delta_d"][-1]):
            k_last = int(round(rows["stamp"][-1] * 1e-9 / p.period))
            num["delta_d_error_end"] = float(rows["delta_d"][-1] - (DD + drift * k_last))
    switches = read_switches(out / "bag", period_s=p.period)
    if switches:
        num["switches"] = switches
        done = [s for s in switches if s["switched"]]
        if done:
            from grazing_control.dynamics.simulation.actuation import pulse_orbit

            last = done[-1]
            g2 = Gains(last["c1"], last["c2"], DELAY)
            ox = pulse_orbit(p, g2, WIDTH).pi2[0]
            held = x[max(last["section"], control_after) + SETTLE:]   # switched, controlled
            num["offset_after_switch"] = float(np.mean(held) - ox) if held.size else None
            num["held_periods"] = int(held.size)
            after = counts[max(last["section"], control_after):]
            num["one_impact_after_switch"] = float(np.mean(after == 1))
            if rows is not None:
                k_rows = np.round(rows["stamp"] * 1e-9 / p.period).astype(int)
                num["mismatch_after_switch"] = int(np.sum((rows["mismatch"] == 1.0)
                                                          & (k_rows > last["section"])))
    if rows is not None:
        fitted = np.isfinite(rows["nis"])
        num["first_verdict_section"] = (int(round(rows["stamp"][fitted][0] * 1e-9 / p.period))
                                        if np.any(fitted) else None)
        num["verdicts"] = int(fitted.sum())
    return num


def _line(name, n) -> str:
    if "failed" in n:
        return f"{name}: FAILED {n['failed']}"
    w = n["watch"] or {}
    parts = [f"{name}: offset {n['offset']:.3g}, spread {n['spread']:.3g}, one impact in "
             f"{100 * n['one_impact_after_control']:.1f} % of the controlled periods "
             f"(histogram {n['impacts_per_period_after_control']}; the last periods without "
             f"one: {n['not_one_impact']}), model_resets {n['resets']}, "
             + ("" if "moving_rms" in n else
                f"capture time {n['capture_time']} periods after control on (rule on at "
                f"section {n['captured_at']}), ")
             + f"max |dv| {n['max_dv']:.3g}, {n['wall_s']:.0f} s"]
    if "moving_rms" in n:
        parts.append(f"about the moving orbit: rms {n['moving_rms']:.3g}, mean "
                     f"{n['moving_mean']:.3g}")
    if "delta_d_error_end" in n:
        parts.append(f"Delta d^ - Delta d at the end {n['delta_d_error_end']:.3g}")
    if "bias" in w:
        parts.append(f"bias^ {w['bias'][0]:.6g} +- {w['bias'][1]:.3g}, (bias^ - 1e-4) / se "
                     f"{(w['bias'][0] - 1e-4) / w['bias'][1]:.2f}")
    if "delta_d" in w:
        parts.append(f"Delta d^ {w['delta_d'][0]:.5g} +- {w['delta_d'][1]:.3g}")
    for sw in n.get("switches", []):
        fit = ("" if sw["zeta"] is None else
               f"zeta {sw['zeta']:.6g} +- {sw['zeta_se']:.2g}, r {sw['r']:.4g} +- "
               f"{sw['r_se']:.2g}, Delta d {sw['delta_d']:.4g} +- {sw['delta_d_se']:.2g}, "
               f"fit {sw['cpu_s']:.0f} s CPU")
        parts.append((f"switched at section {sw['section']}" if sw["switched"] else
                      f"refused at section {sw['section']} ({sw['reason']})")
                     + f" (requested at {sw['requested_at']}): {fit}"
                     + (f", c1 {sw['c1']:.6g} c2 {sw['c2']:.6g}" if sw["switched"] else ""))
    if "offset_after_switch" in n:
        parts.append(f"after the last switch: orbit offset (mean Pi2 x of the last "
                     f"{n['held_periods']} periods, from {SETTLE} after it and after control "
                     f"on, about the pulse orbit of its gains) "
                     f"{n['offset_after_switch']:.3g}, one impact in "
                     f"{100 * n['one_impact_after_switch']:.1f} % of the controlled periods, "
                     f"{n.get('mismatch_after_switch')} mismatch sections after it")
    if w:
        parts.append(f"mismatch sections {w['mismatch_sections']} of {w['sections']} "
                     f"(first {w.get('first_mismatch_section')}, first verdict "
                     f"{n.get('first_verdict_section')}; failing {w['failing']})")
    return "; ".join(parts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", action="append",
                    choices=("bias", "mismatch", "right", "capture", "drift", "gross",
                             "actuator", "reidentify", "reidentify-right"))
    ap.add_argument("--periods", type=int, default=600)
    ap.add_argument("--control-after", type=int, default=100)
    ap.add_argument("--window", type=int, default=300)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--model-zeta", type=float, default=1.05,
                    help="reidentify: the controller's zeta over the plant's (1.05)")
    ap.add_argument("--model-delta-d", type=float, default=1.1,
                    help="reidentify: the controller's Delta d over the plant's (1.1)")
    ap.add_argument("--pi2-source", choices=("stream", "sample"), default="stream",
                    help="the actuator part's controller: the stream's model filter, or the "
                         "simulator's exact Pi2 sample (no estimator: the orbit alone)")
    ap.add_argument("--controller-actuator", action="store_true",
                    help="the actuator part: give the controller pulse_width and "
                         "actuator_bandwidth (its estimator models the actuator)")
    ap.add_argument("--ratio", type=float, action="append",
                    help="the actuator part: bandwidth / omega (repeatable; default 10, 3)")
    ap.add_argument("--measured", type=Path, help="the actuator part: write its numbers "
                    "here (JSON) for benchmarks/chart_actuator.py --measured")
    a = ap.parse_args(argv)
    root = Path(tempfile.mkdtemp())
    yaml, g = design(root)
    print(f"gains c1 {g.c1:.6g} c2 {g.c2:.6g} delay {DELAY}; {a.periods} periods, control "
          f"after {a.control_after}, numbers over the last {a.window}", flush=True)
    p = OscillatorParams(delta_d=DD)
    watch = {"consistency_window": 10}
    cases = []
    for part in a.part or ["bias"]:
        if part == "actuator":
            rows = [_actuator_case(root, a, ratio, designed, g)
                    for ratio in (a.ratio or (10.0, 3.0)) for designed in (True, False)]
            if a.measured:
                import json
                a.measured.write_text(json.dumps(rows, indent=1))
            continue
        if part == "bias":
            cases += [("bias 1e-4, plain model filter", 1e-4, {}),
                      ("bias 1e-4, estimate_bias", 1e-4, {"estimate_bias": True, **watch})]
        elif part == "mismatch":
            wrong = {"zeta": 1.05 * p.zeta, "delta_d": 1.1 * DD, **watch}
            cases += [("zeta +5 %, Delta d +10 %, monitor", 0.0, wrong),
                      ("zeta +5 %, Delta d +10 %, track_delta_d", 0.0,
                       {**wrong, "track_delta_d": True})]
        elif part == "reidentify":
            wrong = {"zeta": a.model_zeta * p.zeta, "delta_d": a.model_delta_d * DD, **watch}
            cases += [(f"zeta x {a.model_zeta:g}, Delta d x {a.model_delta_d:g}, reidentify", 0.0,
                       {**wrong, "track_delta_d": True, "reidentify": True,
                        "reidentify_periods": 20})]
        elif part == "reidentify-right":
            cases += [("right model, reidentify", 0.0,
                       {**watch, "track_delta_d": True, "reidentify": True,
                        "reidentify_periods": 20})]
        elif part == "gross":
            cases += [("zeta +20 %, Delta d +50 %, monitor", 0.0,
                       {"zeta": 1.2 * p.zeta, "delta_d": 1.5 * DD, **watch})]
        elif part == "drift":
            ramp = DD * 0.2 / 2000
            cases += [("no drift, plain", 0.0, {}, 0.0),
                      ("drift 20 %/2000, plain", 0.0, {}, ramp),
                      ("drift 20 %/2000, track_delta_d", 0.0,
                       {"track_delta_d": True, **watch}, ramp)]
        elif part == "capture":
            cases += [("switch on at once", 0.0, {}),
                      ("capture rule", 0.0, {"capture": True})]
        else:
            cases += [("right model, monitor", 0.0, watch)]
    for i, (name, bias, over, *drift) in enumerate(cases):
        out = root / f"case{i}"
        out.mkdir()
        n = scene(yaml, out, a.periods, a.control_after, a.window, sensor_bias=bias,
                  controller=over, seed=a.seed, drift=drift[0] if drift else 0.0,
                  gains=g if drift else None)
        print(_line(name, n), flush=True)


def _actuator_case(root: Path, a, ratio: float, designed: bool, g) -> dict:
    """The ``actuator`` part: one scene through the actuator (module docstring); its
    numbers for the chart (std and offset per sigma)."""
    import json

    from grazing_control.dynamics.simulation.actuator import actuated_design, bandwidth_actuator
    from grazing_control.dynamics.estimation.section_state import estimate_covariance

    p = OscillatorParams(delta_d=DD)
    act = bandwidth_actuator(p, ratio)
    bw = 1.0 / act.time_constant
    out = root / f"actuator{ratio:g}{'d' if designed else 'n'}"
    out.mkdir()
    yaml = out / "controller.yaml"
    cmd = [GRAZING, "design", "--optimize", "noise", f"--delta-d={DD}", "--delay", str(DELAY),
           "--out", str(yaml), "--json"]
    if designed:
        cmd += ["--pulse-width", str(WIDTH), "--actuator-bandwidth", repr(bw)]
    res = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    gains = Gains(res["c1"], res["c2"], DELAY)
    r = estimate_covariance(p, g, RATE)
    _gains, orbit, spread = actuated_design(p, gains.c2, DELAY, WIDTH, act, r)
    if not designed:               # the ideal design's gains through the same actuator
        from grazing_control.dynamics.simulation.actuator import actuated_orbit_for
        orbit = actuated_orbit_for(p, gains, WIDTH, act)
        spread = np.sqrt(np.diag(orbit.noise_covariance(gains, r)))
    told = ({"pulse_width": WIDTH, "actuator_bandwidth": bw} if a.controller_actuator
            else {})
    n = scene(yaml, out, a.periods, a.control_after, a.window, seed=a.seed,
              sim={"actuator_bandwidth": bw}, orbit_x=p.x_ref + orbit.state[0],
              controller={"pi2_source": a.pi2_source, **told})
    name = (f"bandwidth {ratio:g}x omega ({bw:.6g}), "
            + ("design through the actuator" if designed else "ideal actuator's design"))
    print(_line(name, n) + f"; std about the mean {n.get('std', math.nan):.3g}; c1 "
          f"{gains.c1:.6g}; predicted: spectral radius "
          f"{orbit.spectral_radius:.6f}, spread {spread[0] * SIGMA:.3g}, orbit x - x** "
          f"{orbit.state[0]:.3g}", flush=True)
    return {"ratio": ratio, "design": "exact N_g" if designed else "naive",
            "std_per_sigma": n.get("std", math.nan) / SIGMA,
            "offset": n.get("offset", math.nan), "predicted_per_sigma": float(spread[0]),
            "one_impact_after_control": n.get("one_impact_after_control"),
            "pi2_source": a.pi2_source, "controller_actuator": a.controller_actuator,
            "resets": n.get("resets")}


if __name__ == "__main__":
    main()

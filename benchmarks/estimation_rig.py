"""Issue 15's rig scene through the real nodes: sim_node with a position-only sensor
stream and pulse actuation, controller_node estimating Pi2 from the stream.

Lockstep, sensor at 200 samples per period, sigma = 1e-4, position only, pulse width
0.1 centred at the actuation delay 1.0, gains from `grazing design --optimize noise
--delay 1.0 --delta-d DD`, control on after 1000 periods, 1500 periods; over the last
500: the share of periods with one impact, the Pi2 spread (RMS about the exact
controlled orbit with the kick at the delay, and the std), and `grazing analyze`'s
estimate lines. Each scene with the model estimator and, for contrast, the nearest.

    .venv/bin/python benchmarks/estimation_rig.py [--periods 1500] [--delta-d=-5e-6 ...]
    .venv/bin/python benchmarks/estimation_rig.py --mode realtime --delay 5.0
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from grazing_control.dynamics.orbits import one_one
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.recordings.analyze import analyze
from grazing_control.recordings.scenes import load
from grazing_control.ros import launcher

GRAZING = str(Path(sys.executable).with_name("grazing"))


def scene(dd, estimator, periods, sigma, rate, delay, width, out, control_after=1000,
          mode="lockstep", time_scale=1000.0):
    p = OscillatorParams(delta_d=dd)
    yaml = out / "controller.yaml"
    subprocess.run([GRAZING, "design", "--optimize", "noise", f"--delta-d={dd}",
                    "--delay", str(delay), "--out", str(yaml)], check=True,
                   capture_output=True)
    import yaml as _yaml
    values = _yaml.safe_load(yaml.read_text())["/**"]["ros__parameters"]
    g = Gains(values["c1"], values["c2"], delay)
    t0 = time.time()
    res = launcher.run(None, str(yaml), str(out / "bag"), periods, delta_d=dd,
                       enable_after=control_after, mode=mode, timeout=590,
                       sim_overrides={"state_period": p.period / rate, "sensor_noise": sigma,
                                      "time_scale": time_scale,
                                      "sensor_velocity": False, "pulse_width": width,
                                      "sensor_seed": 7},
                       controller_overrides={"pi2_source": "stream", "estimator": estimator},
                       log_dir=str(out / "logs"))
    wall = time.time() - t0
    if not res.ok:
        return f"Delta d {dd:g}, {estimator}: {res}"
    sd = load(out / "bag").scenes[0]
    t, x = sd.scene.t, sd.scene.pi2[:, 0]
    n = min(500, len(t) - control_after)
    last = slice(-n, None)
    edges = np.append(t, t[-1] + p.period)
    counts = np.histogram(sd.scene.impacts[:, 0], edges)[0]
    z = one_one.orbit(p, g).state
    rms = float(np.sqrt(np.mean((x[last] - p.x_ref - z[0]) ** 2)))
    rep = analyze([out / "bag"], out / "report", figures=False)
    lines = [ln for ln in rep["markdown"].splitlines() if "estimate vs" in ln]
    misses = sd.deadline_misses
    return (f"Delta d {dd:g}, {estimator}, {mode}: c2 = {g.c2:.4g}, {res}; deadline misses "
            f"{misses}; one impact in "
            f"{100 * np.mean(counts[last] == 1):.1f} % of the last {n} periods, spread RMS "
            f"{rms:.3g} (std {np.std(x[last]):.3g}); {wall:.0f} s\n  " + "\n  ".join(lines))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=1500)
    ap.add_argument("--delta-d", type=float, action="append", default=None)
    ap.add_argument("--estimator", action="append", default=None)
    ap.add_argument("--sigma", type=float, default=1e-4)
    ap.add_argument("--rate", type=int, default=200)
    ap.add_argument("--delay", type=float, default=1.0)
    ap.add_argument("--pulse-width", type=float, default=0.1)
    ap.add_argument("--control-after", type=int, default=1000)
    ap.add_argument("--mode", default="lockstep", choices=("lockstep", "realtime"))
    ap.add_argument("--time-scale", type=float, default=1000.0)
    a = ap.parse_args(argv)
    for dd in a.delta_d or [-5e-6, -9e-6]:
        for est in a.estimator or ["model", "nearest"]:
            out = Path(tempfile.mkdtemp())
            print(scene(dd, est, a.periods, a.sigma, a.rate, a.delay, a.pulse_width, out,
                        a.control_after, a.mode, a.time_scale), flush=True)


if __name__ == "__main__":
    main()

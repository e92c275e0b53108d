"""The study's two control scenes in realtime through ``grazing run`` (issue 8 §2 acceptance).

For Delta d = -5e-6 and -9e-6 (1300 periods, control from sample 1000, recorder on,
state every 1.0, time_scale 1000: a period is 9.4 ms of wall time) three runs:

* ``lockstep``: delay-aware gains, correction at t_k + delay (the reference);
* ``scheduled``: realtime, the same gains and delay, the correction applied at exactly
  t_k + delay if it has arrived by then (a deadline miss otherwise);
* ``on arrival``: realtime, today's loop: the undelayed gains (config/controller.yaml)
  and each correction applied when it arrives.

From the bags alone: the spread of the Pi2 position over the last 200 samples (the chaos
spans about -2.4 .. +1.8; the controlled 1/1 orbit is one point), the first sample where
the realtime run differs from lockstep, the deadline misses (oscillator/deadline_miss),
and the largest difference to lockstep before the first miss of a non-zero correction;
"on orbit": the share of the last 200 samples within 1e-9 of the lockstep 1/1 orbit.

The delay-aware gains are those of ``grazing design --c2 -1 --delay D`` (c1 from
N_g,12(delay) = 0, docs/theory_delay.md). Each ``grazing run`` gets its own ROS domain.
Run: ``.venv/bin/python benchmarks/realtime_scenes.py [--delay 6]``;
the bags and YAMLs go to benchmarks/out/realtime_scenes/.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1, write_controller_yaml  # noqa: E402
from grazing_control.ros.common import stamp_key  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.ros.recording import read_messages  # noqa: E402

OUT = ROOT / "benchmarks" / "out" / "realtime_scenes"


def controller_yaml(path: Path, p: OscillatorParams, delay: float) -> Path:
    """The controller YAML of ``grazing design --c2 -1 --delay D --out path``."""
    write_controller_yaml(path, p, Gains(degenerate_c1(p, -1.0, delay), -1.0, delay))
    return path


def grazing_run(name, delta_d, mode, controller, extra=()):
    bag, logs = OUT / f"{name}_bag", OUT / f"{name}_logs"
    shutil.rmtree(bag, ignore_errors=True)
    cmd = [sys.executable, "-m", "grazing_control.cli", "run", "--mode", mode,
           "--periods", "1300", "--delta-d", repr(delta_d), "--controller-params",
           str(controller), "--bag", str(bag), "--log-dir", str(logs), "--timeout", "300", *extra]
    print("$ grazing " + " ".join(cmd[3:]), flush=True)
    subprocess.run(cmd, check=True, cwd=ROOT)
    text = (logs / "sim_node.log").read_text()
    summary = re.search(r"summary: (.*)", text).group(1)
    pi2, dv, misses = [], {}, []
    for m in read_messages(bag):
        if m.topic == "/oscillator/pi2":
            pi2.append((m.message.position[0], m.message.velocity[0]))
        elif m.topic == "/controller/velocity_correction":
            dv[stamp_key(m.message.header.stamp)] = m.message.twist.linear.x
        elif m.topic == "/oscillator/deadline_miss":
            misses.append((int(m.message.vector.x), stamp_key(m.message.header.stamp)))
    misses = [(k, dv.get(key)) for k, key in misses]     # the answer each miss lost
    return np.array(pi2), misses, summary, dv


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--delay", type=float, default=6.0, help="actuation delay (simulation time)")
    ap.add_argument("--scale", type=float, default=1000.0, help="realtime time_scale")
    args = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    for dd in (-5e-6, -9e-6):
        p = OscillatorParams(delta_d=dd)
        aware = controller_yaml(OUT / f"controller_delay{args.delay:g}.yaml", p, args.delay)
        scale = ["--sim-param", f"time_scale:={args.scale!r}"]
        lock = grazing_run(f"lockstep_{dd:g}", dd, "lockstep", aware)
        sched = grazing_run(f"scheduled_{dd:g}", dd, "realtime", aware, scale)
        arrive = grazing_run(f"on_arrival_{dd:g}", dd, "realtime", ROOT / "config" /
                             "controller.yaml", scale + ["--sim-param", "actuation:=on_arrival"])
        for name, (pi2, misses, summary, _) in (("lockstep", lock), ("scheduled", sched),
                                                 ("on arrival", arrive)):
            x = pi2[-200:, 0]
            on_orbit = np.mean(np.abs(x - lock[0][-1, 0]) < 1e-9)
            diff = np.abs(pi2 - lock[0]).max(axis=1) if len(pi2) == len(lock[0]) else None
            first_diff = (int(np.argmax(diff > 0)) if diff is not None and (diff > 0).any()
                          else None)
            effective = [k for k, dv in misses if dv != 0.0]
            upto = len(pi2) if not effective else effective[0] + 1
            eq = float(diff[:upto].max()) if diff is not None else float("nan")
            lat = re.search(r"latency_ms p50=(\S+) p99=(\S+) max=(\S+)", summary)
            rows.append((dd, name, x.min(), x.max(), on_orbit, len(misses),
                         effective[0] if effective else None, first_diff, eq,
                         lat.groups() if lat else ("-", "-", "-")))
            print(f"  {name}: {summary}")
    print(f"\nrealtime scenes, time_scale {args.scale:g}, actuation delay {args.delay:g} "
          f"(= {args.delay / args.scale * 1e3:.2f} ms of wall time), 1300 periods, control "
          "from sample 1000")
    print(f"{'Delta d':>8s} {'run':11s} {'x min (last 200)':>17s} {'x max':>10s} {'on orbit':>9s} "
          f"{'misses':>6s} {'1st eff.':>8s} {'1st diff':>8s} {'max |diff| before':>17s} "
          f"{'lat p50/p99/max ms':>20s}")
    for dd, name, lo, hi, sd, nm, eff, fd, eq, lat in rows:
        print(f"{dd:8.0e} {name:11s} {lo:17.6g} {hi:10.6g} {sd:9.0%} {nm:6d} "
              f"{str(eff):>8s} {str(fd):>8s} {eq:17.2e} {'/'.join(lat):>20s}")


if __name__ == "__main__":
    main()

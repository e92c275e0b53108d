"""Deadline misses in realtime through the real nodes: on_miss predict against drop (issue 16 §3).

sim_node + controller_node (the controller sends its prediction of the next correction,
twist.linear.y, with the plant's delta_d), realtime at time_scale 1000 (a period is
9.4 ms of wall time), Delta d = -5e-6, delay-aware gains (c2 = -1, c1 from
design.degenerate_c1 with the delay), control from sample 200. Reported from the
messages a collector node receives: the misses (oscillator/deadline_miss) and the
summary's predicted count, and the spread (std) and largest distance of the Pi2
position from its median over the samples from 500 on (the controlled 1/1 orbit is
one point). Each run gets its own ROS domain.

Run: ``.venv/bin/python benchmarks/realtime_misses.py predict 3000 5.0`` (on_miss,
periods, delay); one JSON line. Results: docs/nodes.md, "Scheduled actuation".
"""

from __future__ import annotations

import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from geometry_msgs.msg import Vector3Stamped  # noqa: E402

from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.ros import launcher  # noqa: E402
from test_closed_loop import STUDY, TOPICS, Collector, new_domain, xv  # noqa: E402

ON = 200


def main(on_miss: str, n: int, delay: float) -> dict:
    p = OscillatorParams(delta_d=-5e-6)
    ctl = {"c1": float(degenerate_c1(p, -1.0, delay)), "c2": -1.0, "actuation_delay": delay,
           "zeta": p.zeta, "r": p.r, "omega": p.omega, "pi2_offset": p.pi2_offset}
    domain = new_domain()
    col = Collector(domain, {**TOPICS, "oscillator/deadline_miss": Vector3Stamped},
                    ready=True)
    try:
        with tempfile.TemporaryDirectory() as logs:
            res = launcher.run(STUDY, ctl, None, n, mode="realtime", enable_after=ON,
                               domain_id=domain, timeout=600, log_dir=logs,
                               sim_overrides={"state_period": 0.0, "wait_for_subscribers": 1,
                                              "wait_for_recorder": True, "time_scale": 1000.0,
                                              "delta_d": p.delta_d, "on_miss": on_miss})
            log = Path(res.logs["sim_node"]).read_text()
        s = dict(re.findall(r"(\w+)=(\S+)", re.search(r"summary: (.*)", log).group(1)))
        col.wait_for(lambda: len(col.get("oscillator/pi2")) == n, 5.0)
        tail = xv(col.get("oscillator/pi2"))[ON + 300:, 0]
        off = tail - np.median(tail)
        return {"on_miss": on_miss, "periods": n, "delay": delay, "ok": res.ok,
                "missed": int(s["missed"]), "predicted": int(s["predicted"]),
                "spread": float(np.std(off)), "max_off": float(np.abs(off).max()),
                "latency_ms_p99_max": [s.get("p99"), s.get("max")]}
    finally:
        col.close()


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))))

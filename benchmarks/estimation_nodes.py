"""A few points of the estimation chart confirmed through the real controller_node.

This process plays a position-only rig over Fast DDS in lockstep: the exact flow (the
core's trajectory), the SensorModel's draws (the same as the core's for the seed), the
samples published on oscillator/state at ``rate`` per period (the sample at t_k itself
is not published, as sim_node does not), each period waiting for the controller's answer
and applying it at Pi2. The controller_node runs in stream mode with the estimator
asked for. The Pi2 spread about the exact orbit (last 2/3 of the periods) is compared
with the core's simulate_stream on the same draws (docs/theory_estimation.md).

    .venv/bin/python benchmarks/estimation_nodes.py --estimator model --periods 300
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from sensor_msgs.msg import JointState  # noqa: E402

from grazing_control.dynamics.design.gains import degenerate_c1, write_controller_yaml  # noqa: E402
from grazing_control.dynamics.estimation.motion import trajectory  # noqa: E402
from grazing_control.dynamics.orbits import one_one  # noqa: E402
from grazing_control.dynamics.estimation.stream import simulate_stream  # noqa: E402
from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.plant.sensor import SensorModel  # noqa: E402
from grazing_control.ros import launcher  # noqa: E402
from grazing_control.ros.common import DATA_QOS, stamp_from_seconds  # noqa: E402
from test_closed_loop import Collector, new_domain  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--estimator", default="model")
    ap.add_argument("--periods", type=int, default=300)
    ap.add_argument("--rate", type=int, default=200)
    ap.add_argument("--sigma", type=float, default=1e-4)
    ap.add_argument("--c2", type=float, default=-0.3)
    ap.add_argument("--delta-d", type=float, default=-5e-6)
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args(argv)
    p = OscillatorParams(delta_d=a.delta_d)
    g = Gains(degenerate_c1(p, a.c2), a.c2)
    z0 = one_one.orbit(p, g).state
    sensor = SensorModel(noise=a.sigma, velocity=False, seed=a.seed)
    tmp = Path(tempfile.mkdtemp())
    yaml = tmp / "controller.yaml"
    write_controller_yaml(yaml, p, g)
    domain = new_domain()
    col = Collector(domain, {"controller/velocity_correction": __import__(
        "geometry_msgs.msg", fromlist=["TwistStamped"]).TwistStamped})
    proc = launcher.start_node(launcher.CONTROLLER_MODULE, [str(yaml)], {
        "pi2_source": "stream", "estimator": a.estimator, "delta_d": p.delta_d,
        "sensor_noise": a.sigma, "enable_after": 0}, domain_id=domain, log=tmp / "c.log")
    try:
        pub = col.node.create_publisher(JointState, "oscillator/state", DATA_QOS)
        answers = col.subs["controller/velocity_correction"]
        assert col.wait_for(lambda: pub.get_subscription_count() > 0
                            and answers.get_publisher_count() > 0, 30.0)
        col.wait_for(lambda: False, 0.3)
        T, h = p.period, p.period / a.rate

        def send(j0, x):
            xm, _ = sensor.measure(j0, x, x)
            for j, xj in enumerate(xm):
                t = (j0 + j) * h
                tau = p.tau2 + p.omega * t
                m = JointState(name=["mass"], position=[float(xj)], velocity=[],
                               effort=[math.cos(tau), math.sin(tau)])
                m.header.stamp = stamp_from_seconds(t)
                pub.publish(m)

        z = z0
        truth = []
        send(0, np.array([p.x_ref + z[0]]))
        t0 = time.time()
        for k in range(a.periods):
            truth.append(z)
            assert col.wait_for(lambda: len(col.get("controller/velocity_correction")) > k,
                                30.0), f"no answer to section {k}"
            dv = col.get("controller/velocity_correction")[k].twist.linear.x
            s = np.arange(k * a.rate + 1, (k + 1) * a.rate) * h - k * T
            dev, _j, z, _m, _i = trajectory(p, z, s, dv)
            psi = p.tau2 + p.omega * s - p.lag
            send(k * a.rate + 1, p.amplitude * np.cos(psi) + dev[:, 0])
        wall = time.time() - t0
    finally:
        launcher.stop_nodes([proc])
        col.close()
    truth = np.array(truth)
    last = slice(a.periods // 3, None)
    nodes = float(np.sqrt(np.mean((truth[last, 0] - z0[0]) ** 2)))
    core = simulate_stream(p, g, sensor.measure, a.periods, a.rate, estimator=a.estimator,
                           sigma=a.sigma, deviation=z0)
    core_spread = float(np.sqrt(np.mean((core.truth[last, 0] - z0[0]) ** 2)))
    print(f"{a.estimator}, c2 = {a.c2}, sigma = {a.sigma:g}, {a.rate}/T, {a.periods} periods: "
          f"spread through the nodes {nodes:.3g}, core {core_spread:.3g}, max |truth "
          f"difference| {np.max(np.abs(truth - core.truth)):.2e}; {wall:.1f} s wall")


if __name__ == "__main__":
    main()

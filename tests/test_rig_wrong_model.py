"""A rig scene whose controller's model is wrong (docs/driver_contract.md, "Off the rig's
section"), through the real nodes: the acceptance rig (config/rigs/acceptance.yaml)
simulated, its controller given the same rig with a damping ratio 5 % low (0.0095; 5 %
high gives its own Delta d > 0, which its design refuses). The controller's Pi2 section,
from its own model, lies 14 us before the rig's: every command is off the rig's section
grid, and the simulated rig applies each at its apply time, as a driver executes timed
output (sim_node/rig_io.py, plant/realtime.py's timed answers)."""

import numpy as np
import pytest

from test_rig_scene import RIG, _seconds, _summary, run_rig_scene

pytestmark = pytest.mark.timeout(240)

PERIODS, ON = 40, 3
#: At half physical speed: each command has 10 ms of wall time to its apply time (the
#: budget of 5 ms rig time; the answers take 2-3 ms), and the 40 periods 6 s (28 s for
#: the scene at the rig scene's 1/8 speed, alone in the realtime group).
SLOW = 2.0


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig_wrong_model")
    wrong = out / "wrong.yaml"
    text = RIG.read_text()
    assert "\ndamping_ratio: 0.01\n" in text
    wrong.write_text(text.replace("\ndamping_ratio: 0.01\n", "\ndamping_ratio: 0.0095\n"))
    topics = ("/rig/phase", "/rig/force_pulse", "/rig/applied", "/oscillator/pi2",
              "/oscillator/impact")
    return run_rig_scene(out, RIG, PERIODS, ON, topics, {"rig_file": str(wrong)}, slow=SLOW)


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_off_grid_commands_act_at_their_apply_times_exactly(scene):
    rig, res, m = scene
    T = rig.forcing_period
    phases = [_seconds(msg.header.stamp) for _, msg in m["/rig/phase"]]
    pulses = [msg for _, msg in m["/rig/force_pulse"]]
    # every command is off the rig's own section (beyond the 1e-6 T of one of its own)
    off = [msg.wrench.torque.y - phases[0] - round((msg.wrench.torque.y - phases[0]) / T) * T
           for msg in pulses]
    assert all(abs(o) > 1e-6 * T for o in off), off
    by_start = {(p.header.stamp.sec, p.header.stamp.nanosec): p for p in pulses}
    in_time = acting = 0
    for _, a in m["/rig/applied"]:
        if a.wrench.force.z != 0.0:
            continue
        in_time += 1
        # what acted is a command, from its own apply time (the stamp, exactly) ...
        cmd = by_start[(a.header.stamp.sec, a.header.stamp.nanosec)]
        # ... in the slot of the rig's section it reports (torque.y, the rig's grid)
        assert 0.0 <= _seconds(cmd.header.stamp) - a.wrench.torque.y < T
        assert a.wrench.force.x == pytest.approx(cmd.wrench.force.x, rel=1e-12, abs=1e-15)
        acting += a.wrench.force.x != 0.0
    sim = _summary(res.logs["sim_node"], r"\b(in_time|malformed|safe|ignored)=(\d+)")
    assert sim["malformed"] == 0 and sim["safe"] == 0 and sim["ignored"] == 0
    assert sim["in_time"] == in_time >= 0.75 * (PERIODS - 1), (in_time, sim)
    assert acting >= 0.75 * (PERIODS - ON - 1)        # the corrections act


@pytest.mark.realtime      # one scene, its answers in time: with the other worker idle
def test_the_wrong_model_holds_the_orbit_near_the_exact_one(scene):
    """The controlled 1/1 orbit of the rig's own model (X** on Pi2, one impact a
    period): the wrong model's corrections hold the motion there, farther off than the
    right model does. Measured: within 0.008 of X** (dimensionless) over the last 10 of
    40 periods, one impact in 8 of them (none in 2: the held motion sits nearer grazing,
    impact velocity 0.0049 against the orbit's 0.0144); at 200 periods (grazing analyze) 3.6e-5 m from the
    orbit at the end and a spread of 4.1e-5 m, against 1.4e-7 m and 4.9e-7 m with the
    right model: its estimator's fit fails every period (model_resets), as the χ² test
    of its own model says."""
    rig, res, m = scene
    p = rig.params()
    pi2 = [(_seconds(msg.header.stamp), msg.position[0], msg.velocity[0])
           for _, msg in m["/oscillator/pi2"]]
    t, x, v = np.array(pi2).T
    dep = np.hypot(x - p.x_ref, v - p.v_ref)
    assert dep[ON + 10:].max() < 0.03, dep
    hits = np.array([_seconds(msg.header.stamp) for _, msg in m["/oscillator/impact"]])
    per = [int(((hits > a) & (hits <= b)).sum()) for a, b in zip(t[-11:-1], t[-10:])]
    print("departure", dep[-10:].max(), "impacts", per)
    assert set(per) <= {0, 1} and sum(per) >= 5, per      # no chatter, mostly 1/1
    ctl = _summary(res.logs["controller_node"], r"\b(model_resets|answered)=(\d+)")
    assert ctl["model_resets"] >= PERIODS - ON - 2       # the wrong model's fit fails

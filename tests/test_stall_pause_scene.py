"""The simulator held by a SIGSTOP, through the nodes: with ``stall_pause`` (the default)
its plant's clock pauses and no deadline is missed; pinned to the wall clock
(``stall_pause:=0``) the deadlines in the stall are missed (plant.realtime,
``Realtime.resume``; tests/test_plant_stall_pause.py drives the loop itself).

Two realtime scenes at once, each in its own domain: the simulator and a controller
(answering 0, control never on: a miss counts all the same) at time_scale 100, where a
period is 94 ms of wall time and the 5.0 of actuation delay 50 ms. Once each scene runs,
its simulator is stopped for 0.3 s (SIGSTOP, SIGCONT: three periods and more) while its
controller runs on. The verdict file gives the simulator's summary line, the deadlines
it missed (sample, actuation time) and its longest pause (simulation time, seconds).

The paused scene is judged on the deadlines the hold could reach: a miss elsewhere is
the host's, not the hold's (in the suite a controller once answered 129 ms after its sample
against the 50 ms budget, 1.5 s after the hold, on a loaded host).
"""

from __future__ import annotations

import json
import os
import re
import signal
import time

import math

import pytest
import yaml

from grazing_control.ros import launcher

from test_closed_loop import CONTROLLER, STUDY, new_domain

pytestmark = pytest.mark.realtime

PERIODS, HELD, TIME_SCALE, DELAY = 45, 0.3, 100.0, 5.0
#: the forcing period, simulation time
PERIOD = 2 * math.pi / yaml.safe_load(STUDY.read_text())["/**"]["ros__parameters"]["omega"]


def scene(tmp, name: str, pause: float | None):
    """Start one scene: (simulator, controller, verdict path, simulator log)."""
    domain = new_domain()
    verdict, log = tmp / f"{name}.json", tmp / f"{name}_sim.log"
    # the default watchdog (lag 1 s): a sample's lag counts the plant's pauses since the
    # previous sample, not all of the run's (in the suite the paused scene's small pauses
    # once summed to 0.73 s beside the 0.3 s hold, 258 pauses, 1.03 s, and tripped the
    # lag at sample 40 of 45 when all of them counted)
    sim = {"mode": "realtime", "time_scale": TIME_SCALE, "actuation_delay": DELAY,
           "max_periods": PERIODS, "state_period": 0.0, "exit_when_done": True,
           "verdict_file": str(verdict)}
    if pause is not None:
        sim["stall_pause"] = pause
    procs = (launcher.start_node(launcher.SIM_MODULE, (str(STUDY),), sim, domain_id=domain,
                                 log=log),
             launcher.start_node(launcher.CONTROLLER_MODULE, (str(CONTROLLER),),
                                 {"actuation_delay": DELAY, "enable_after": 100_000},
                                 domain_id=domain, log=tmp / f"{name}_controller.log"))
    return procs, verdict, log


def hold_once_running(proc, log, seconds: float) -> None:
    """SIGSTOP the simulator 1 s after its scene started (its log says so), for
    ``seconds``, then SIGCONT."""
    end = time.monotonic() + 60.0
    while "start conditions met" not in log.read_text(errors="replace"):
        assert proc.poll() is None and time.monotonic() < end, log.read_text()[-3000:]
        time.sleep(0.05)
    time.sleep(1.0)
    os.kill(proc.pid, signal.SIGSTOP)
    time.sleep(seconds)
    os.kill(proc.pid, signal.SIGCONT)


@pytest.fixture(scope="module")
def verdicts(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("stall")
    scenes = {"paused": scene(tmp, "paused", None), "wall": scene(tmp, "wall", 0.0)}
    try:
        for (sim, _), _, log in scenes.values():
            hold_once_running(sim, log, HELD)
        for (sim, _), _, log in scenes.values():
            assert sim.wait(60) == 0, log.read_text()[-3000:]
    finally:
        launcher.stop_nodes([p for procs, _, _ in scenes.values() for p in procs])
    return {name: json.loads(verdict.read_text()) for name, (_, verdict, _) in scenes.items()}


def count(summary: str, name: str) -> float:
    m = re.search(rf"\b{name}=([0-9.]+)", summary)
    return float(m.group(1)) if m else 0.0


def in_reach(miss: dict, t_hold: float) -> bool:
    """Whether the hold, begun at simulation time ``t_hold``, could have made ``miss``: its
    actuation due from the hold's start to the end of the span the hold covers on the wall
    clock, one period and the delay more (on the wall clock those deadlines pass in it)."""
    return t_hold <= miss["t"] <= t_hold + HELD * TIME_SCALE + PERIOD + DELAY


def test_held_on_the_wall_clock_the_deadlines_in_the_stall_are_missed(verdicts):
    v = verdicts["wall"]
    s = v["summary"]
    assert f"periods={PERIODS} " in s, s
    assert count(s, "missed") >= 2 and "paused=" not in s and v["longest_pause"] is None, v
    # every miss is listed, and the hold's are consecutive samples
    assert len(v["misses"]) == count(s, "missed"), v
    ks = [m["k"] for m in v["misses"]]
    assert any(b == a + 1 for a, b in zip(ks, ks[1:])), v


def test_held_with_the_plant_paused_no_deadline_it_reaches_is_missed_and_the_pause_is_told(
        verdicts):
    v = verdicts["paused"]
    s = v["summary"]
    assert f"periods={PERIODS} " in s, s
    assert count(s, "paused") >= 1, s
    # the stop of 0.3 s, less the wake-up that was not yet due when it began
    assert HELD - 0.01 <= count(s, "longest_pause_ms") / 1e3 <= HELD + 0.2, s
    hold = v["longest_pause"]
    assert hold["seconds"] == pytest.approx(count(s, "longest_pause_ms") / 1e3, abs=1e-5), v
    assert len(v["misses"]) == count(s, "missed"), v
    assert [m for m in v["misses"] if in_reach(m, hold["t"])] == [], v

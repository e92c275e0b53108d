"""The realtime numbers and the delay check of recordings/timing.py, for every n (issue 32).

Bags written in-process with known arrivals: the simulator's engine
(:class:`grazing_control.plant.engine.Engine`) run as the realtime loop runs it with
actuation on arrival (plant/realtime.py: the period integrated uncorrected when its sample
goes out, then split at the correction's arrival), each sample published ``lag_k`` after
it is due and answered ``latency_k`` after that, so the correction acts
(lag_k + latency_k) x time_scale after its sample. The bag holds what the nodes record:
the samples with those publish times, the corrections, the simulator's latency messages
and the parameter record; sample 0's lag is in no message. ``grazing analyze`` must fit
it, explain the departures from the undelayed model check by the arrivals, and say so;
an n = 1 model file's bag and the 1-DOF bag of the same scene give the same numbers.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bagtools_helpers import (TYPESTORE, masses_joint_state, string, twist_stamped,
                              write_rosbags)
from grazing_control.dynamics.design.family import evaluate_design
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.oscillator.control import Gains, correction
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import load_model
from grazing_control.oscillator.params import OscillatorParams
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values
from grazing_control.recordings.analyze import analyze
from grazing_control.ros.recording.record import encode, encode_event

ROOT = Path(__file__).resolve().parents[1]
CHAIN = str(ROOT / "config" / "models" / "two_mass_chain.yaml")
ONE = str(ROOT / "config" / "models" / "study_1dof.yaml")
WALL0 = 1_700_000_000_000_000_000      # the simulator's clock start, ns (wall0)
LAG0_NS = 1_500_000                      # sample 0 published 1.5 ms after it: in no message
TIME_SCALE = 50.0


def on_arrival_bag(path, model_file: str, delta_d: float, answer, periods: int, on: int,
                   *, sim: dict, ctl: dict, seed: int = 3, scheduled: float = 0.0,
                   misses: dict | None = None, pauses: dict | None = None,
                   record_pauses: bool = True):
    """A realtime scene with actuation on arrival, written as recorded (module docstring):
    ``answer(x, v)`` the controller's correction from sample k's positions and
    velocities (from ``on`` on; 0 before). Returns the delays (simulation time) at which
    the corrections acted. ``scheduled`` > 0: actuation scheduled that long after each
    sample instead, and at the samples k of ``misses`` a deadline miss, the prediction
    ``misses[k]`` acting in place of the answer (oscillator/substituted). ``pauses``:
    {k: (before, between)}, wall seconds the plant's clock paused (plant.realtime.
    Realtime.resume) just before sample k went out and between sample k and its answer's
    arrival: every later publish time moves on by them, the simulator's latency of sample
    k includes ``between``, and each is a ``paused`` event record (unless not
    ``record_pauses``)."""
    misses, pauses = misses or {}, pauses or {}
    held = 0                                          # ns the plant's clock has paused
    eng = Engine(settings_from_values({"delta_d": delta_d, "actuation_delay": scheduled,
                                       "delta_d_drift": sim.get("delta_d_drift", 0.0)},
                                      model_file))
    vec = TYPESTORE.types["geometry_msgs/msg/Vector3Stamped"]
    rng = np.random.default_rng(seed)
    msgs, delays = [], []
    for k in range(periods):
        ev = eng.sample()
        x, v = np.atleast_1d(ev.x), np.atleast_1d(ev.v)
        stamp = round(ev.t * 1e9)
        before, between = pauses.get(k, (0.0, 0.0))
        held += round(before * 1e9)
        pub = WALL0 + held + (LAG0_NS if k == 0 else round((ev.t / TIME_SCALE) * 1e9
                                                            + rng.uniform(0.2e6, 3e6)))
        latency = float(rng.uniform(2e-3, 8e-3))
        lag = (pub - WALL0 - held) / 1e9 - ev.t / TIME_SCALE
        delay = (lag + latency) * TIME_SCALE            # plant/realtime.py, on arrival
        # (seconds, the simulation time up to which everything had gone out, log time)
        paused = [(before, ev.t - 1e-6, pub - 1),
                  (between, ev.t + delay / 2, pub + round(latency * 1e9))]
        held += round(between * 1e9)
        latency += between                               # the simulator's wall latency
        if record_pauses:
            msgs += [("/grazing/parameters", "std_msgs/msg/String", log,
                      string(encode_event("/sim_node", "paused", t=t, seconds=s)))
                     for s, t, log in paused if s]
        dv = float(answer(x, v)) if k >= on else 0.0
        if scheduled:
            eng.begin_period(misses.get(k, dv), scheduled)
            delay = scheduled
        else:
            eng.begin_period(0.0)
            eng.split(ev.t + delay, dv)
        eng.end_period()
        if k in misses:
            t = TYPESTORE.types
            stamped = twist_stamped(stamp, 0.0).header
            msgs += [("/oscillator/deadline_miss", "geometry_msgs/msg/Vector3Stamped",
                      pub + 300_000, vec(header=stamped, vector=t["geometry_msgs/msg/Vector3"](
                          x=float(k), y=scheduled, z=0.0))),
                     ("/oscillator/substituted", "geometry_msgs/msg/TwistStamped",
                      pub + 300_001, twist_stamped(stamp, misses[k]))]
        delays.append(delay)
        msgs += [("/oscillator/pi2", "sensor_msgs/msg/JointState", pub,
                  masses_joint_state(stamp, x, v)),
                 ("/controller/velocity_correction", "geometry_msgs/msg/TwistStamped",
                  pub + 400_000, twist_stamped(stamp, dv)),
                 ("/oscillator/latency", "std_msgs/msg/Float64", pub + round(latency * 1e9),
                  TYPESTORE.types["std_msgs/msg/Float64"](data=latency))]
    record = {"mode": "realtime", "time_scale": TIME_SCALE, "actuation": "auto",
              "actuation_delay": scheduled, "jitter": 0.0, "delta_d": delta_d,
              "model_file": model_file, **sim}
    head = [("/grazing/parameters", "std_msgs/msg/String", WALL0 - 2,
             string(encode("/sim_node", record))),
            ("/grazing/parameters", "std_msgs/msg/String", WALL0 - 1,
             string(encode("/controller_node", {"enable_after": on, "actuation_delay": scheduled,
                                                "model_file": model_file, **ctl})))]
    write_rosbags(path, head + sorted(msgs, key=lambda m: m[2]))
    return np.array(delays)


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    """The two-mass chain at Delta d = -1e-3 with the design's gains (mu = -0.22),
    switched on at sample 10, 40 periods: docs/analysis.md's realtime scene."""
    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    gains = np.asarray(evaluate_design(model, -0.22).gains, float)
    flow = NdofFlow.of(model)
    path = tmp_path_factory.mktemp("chain") / "bag"

    def answer(x, v):
        return float(gains @ flow.to_deviation(flow.tau2, np.concatenate([x, v])))

    delays = on_arrival_bag(path, CHAIN, -1e-3, answer, 40, 10, sim={},
                            ctl={"gains": gains.tolist()})
    report = analyze([path], path.parent / "report", figures=False)
    return report, delays


def test_the_fitted_lag_of_sample_0_is_the_known_one(chain):
    report, delays = chain
    rt = report["bags"][0]["scenes"][0]["realtime"]
    dc = rt["delay_check"]
    assert rt["latency_ms"]["n"] == 40 and rt["time_scale"] == TIME_SCALE
    assert rt["deadline_misses"] is None and rt["missing_answers"] == 0
    assert abs(dc["fitted_first_sample_lag_ms"] - LAG0_NS / 1e6) < 1e-6, dc
    assert dc["median_delay"] == pytest.approx(np.median(delays[10:-1]), abs=1e-8)
    assert dc["max_delay"] == pytest.approx(delays[10:-1].max(), abs=1e-8)
    print(f"chain: fitted lag {dc['fitted_first_sample_lag_ms']!r} ms (known 1.5)")


def test_the_arrivals_explain_the_departures_and_the_report_says_so(chain):
    """Undelayed, the model check departs by more than 1e-3; with each correction at its
    fitted arrival by ~1e-9 (what the fit's 1e-10 s on the lag leaves, times the time
    scale); the report's line says the corrections acted on arrival and what to do."""
    report, _ = chain
    s = report["bags"][0]["scenes"][0]
    dc = s["realtime"]["delay_check"]
    assert s["model_check"]["max_departure"] > 1e-3
    assert dc["max_departure"] < 1e-8 and dc["explains_model_check"], dc
    assert dc["median_departure_kicks_on_pi2"] > 1e-3
    print(f"chain: model check {s['model_check']['max_departure']:.2e}, at the arrivals "
          f"max {dc['max_departure']:.2e}, median {dc['median_departure']:.2e}")
    text = report["markdown"]
    assert "* **the corrections acted on arrival**" in text
    assert "grazing design --delay" in text and "actuation scheduled" in text
    assert "realtime latency (sim, sample published → answer received): p50" in text


#: The plant's clock paused (stall_pause): 4 ms before sample 15 went out, 6 ms between
#: sample 22 and its answer, 10 ms before sample 30 and 3 ms after it.
PAUSES = {15: (4e-3, 0.0), 22: (0.0, 6e-3), 30: (10e-3, 3e-3)}


@pytest.mark.parametrize("recorded", [True, False], ids=["recorded", "not recorded"])
def test_the_plants_pauses_are_taken_out_of_the_lag_and_the_delays(tmp_path, recorded):
    """The same chain scene with the plant's clock paused four times (plant.realtime.
    Realtime.resume): read with its ``paused`` records, the sample lag stays that of the
    plant's clock (under 3 ms, as drawn), the fitted lag of sample 0 and the delays are
    the known ones, the arrivals explain the departures, and the report counts the pauses;
    without the records the pauses read as lag (23 ms) and the arrivals no longer explain
    the run."""
    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    gains = np.asarray(evaluate_design(model, -0.22).gains, float)
    flow = NdofFlow.of(model)

    def answer(x, v):
        return float(gains @ flow.to_deviation(flow.tau2, np.concatenate([x, v])))

    delays = on_arrival_bag(tmp_path / "bag", CHAIN, -1e-3, answer, 40, 10, sim={},
                            ctl={"gains": gains.tolist()}, pauses=PAUSES,
                            record_pauses=recorded)
    report = analyze([tmp_path / "bag"], tmp_path / "report", figures=False)
    rt = report["bags"][0]["scenes"][0]["realtime"]
    dc = rt["delay_check"]
    total = sum(sum(p) for p in PAUSES.values())
    if not recorded:
        assert "plant_pauses" not in rt
        assert rt["sample_lag_ms"]["max"] > total * 1e3
        assert not dc["explains_model_check"] or dc["max_departure"] > 1e-6, dc
        return
    assert rt["plant_pauses"] == {"count": 4, "total_ms": pytest.approx(total * 1e3),
                                  "longest_ms": pytest.approx(10.0)}
    assert rt["sample_lag_ms"]["max"] < 3.0 - LAG0_NS / 1e6 + 1e-6
    assert abs(dc["fitted_first_sample_lag_ms"] - LAG0_NS / 1e6) < 1e-6, dc
    assert dc["median_delay"] == pytest.approx(np.median(delays[10:-1]), abs=1e-8)
    assert dc["max_delay"] == pytest.approx(delays[10:-1].max(), abs=1e-8)
    assert dc["max_departure"] < 1e-8 and dc["explains_model_check"], dc
    assert "the plant's clock paused 4 times for stalls of the simulator" in report["markdown"]


def test_an_n1_model_file_bag_and_the_1dof_bag_of_the_scene_agree(tmp_path):
    """The study's oscillator through config/models/study_1dof.yaml (n = 1) and through
    the 1-DOF closed form, the same arrivals: the same latency, the same fitted lag and
    delays, both explained."""
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(degenerate_c1(p, -0.5), -0.5)
    one = on_arrival_bag(tmp_path / "one", "", -5e-6,
                         lambda x, v: correction(g, x[0], v[0], p.x_ref, p.v_ref), 60, 20,
                         sim={k: getattr(p, k) for k in ("zeta", "r", "omega", "pi2_offset")},
                         ctl={"c1": g.c1, "c2": g.c2})
    n1 = on_arrival_bag(tmp_path / "n1", ONE, -5e-6,
                        lambda x, v: correction(g, x[0], v[0], p.x_ref, p.v_ref), 60, 20,
                        sim={}, ctl={"gains": [g.c1, g.c2]})
    assert np.allclose(one, n1, rtol=0, atol=1e-12)
    a, b = (analyze([tmp_path / name], tmp_path / f"r_{name}", figures=False)["bags"][0]
            for name in ("one", "n1"))
    assert "n" not in a["setup"] and b["setup"]["n"] == 1
    ra, rb = a["scenes"][0]["realtime"], b["scenes"][0]["realtime"]
    assert ra["latency_ms"] == rb["latency_ms"] and ra["sample_lag_ms"] == rb["sample_lag_ms"]
    da, db = ra["delay_check"], rb["delay_check"]
    assert da["periods"] == db["periods"] == 39
    for key in ("fitted_first_sample_lag_ms", "median_delay", "max_delay"):
        assert da[key] == pytest.approx(db[key], rel=1e-9), key
    assert abs(da["fitted_first_sample_lag_ms"] - LAG0_NS / 1e6) < 1e-6
    assert da["max_departure"] < 1e-8 and db["max_departure"] < 1e-8, (da, db)
    assert da["explains_model_check"] and db["explains_model_check"]
    assert da["median_departure_kicks_on_pi2"] == pytest.approx(
        db["median_departure_kicks_on_pi2"], rel=1e-6)


@pytest.mark.parametrize("model_file", ["", CHAIN], ids=["1-DOF", "chain"])
def test_on_a_drifting_wall_the_arrivals_still_explain_the_departures(tmp_path, model_file):
    """The plant's wall drifting by 2e-5 per period (sim_node's delta_d_drift, issue 32):
    the delay check re-integrates each period at its arrival and at the plant's Delta d
    of that period, as the model check does, so the arrivals explain the departures to
    the fit's ~1e-9 as on a fixed wall (measured 2.5e-11 1-DOF, 1.2e-9 chain; the model
    check 5.5e-3, 0.40). At the recorded constant Delta d both failed the bound."""
    model = dataclasses.replace(load_model(model_file or ONE), delta_d=-1e-3)
    gains = np.asarray(evaluate_design(model, -0.22).gains, float)
    flow = NdofFlow.of(model)

    def answer(x, v):
        return float(gains @ flow.to_deviation(flow.tau2, np.concatenate([x, v])))

    ctl = {"gains": gains.tolist()} if model_file else {"c1": gains[0], "c2": gains[1]}
    on_arrival_bag(tmp_path / "bag", model_file, -1e-3, answer, 40, 10,
                   sim={"delta_d_drift": 2e-5}, ctl=ctl)
    s = analyze([tmp_path / "bag"], tmp_path / "report", figures=False)["bags"][0]["scenes"][0]
    dc = s["realtime"]["delay_check"]
    assert s["model_check"]["delta_d_drift"] == 2e-5
    assert s["model_check"]["max_departure"] > 1e-3
    assert dc["max_departure"] < 1e-8 and dc["explains_model_check"], dc
    print(f"drifting {model_file or '1-DOF'}: model check "
          f"{s['model_check']['max_departure']:.2e}, at the arrivals {dc['max_departure']:.2e}")


def test_a_scheduled_n_dof_bag_gets_its_misses_and_substitutions_but_no_delay_check(
        tmp_path):
    """Actuation scheduled 3.0 after each sample (grazing design --delay): the realtime
    numbers (latency, the deadline misses, the predictions substituted) without a delay
    check (a correction acts at t_k + delay, not on arrival: as 1-DOF); the model check
    re-integrates a miss with the prediction that acted (it took the late answer, and
    departed)."""
    model = dataclasses.replace(load_model(CHAIN), delta_d=-1e-3)
    design = evaluate_design(model, -0.22, delay=3.0)
    gains = np.asarray(design.gains, float)
    flow = NdofFlow.of(model)

    def answer(x, v):
        return float(gains @ flow.to_deviation(flow.tau2, np.concatenate([x, v])))

    on_arrival_bag(tmp_path / "bag", CHAIN, -1e-3, answer, 30, 10, sim={},
                   ctl={"gains": gains.tolist()}, scheduled=3.0, misses={15: 0.05, 21: 0.0})
    report = analyze([tmp_path / "bag"], tmp_path / "report", figures=False)
    s = report["bags"][0]["scenes"][0]
    rt, mc = s["realtime"], s["model_check"]
    assert rt["latency_ms"]["n"] == 30 and rt["delay_check"] is None
    assert rt["deadline_misses"] == 2 and rt["substituted"] == 2
    assert mc["max_departure"] < 1e-12, mc
    text = report["markdown"]
    assert "deadline misses: 2 (2 predictions substituted)" in text
    assert "acted on arrival" not in text and "why a realtime run departs" not in text

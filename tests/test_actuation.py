"""Scheduled actuation and injected faults in sim_node (issue 8 sections 2 and 3).

The engine is checked without middleware against ``simulate.period_step(..., delay=)``
(bit for bit); the nodes over Fast DDS against a reference loop of the core written here:
lockstep with a delay and injected faults (loss, measurement noise, jitter) must equal the
core's fault simulation sample for sample, and a realtime scene at time_scale 1000 with
actuation at t_k + delay must equal the lockstep scene until its first deadline miss that
mattered, suppress the chaos, and count and publish every miss.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import Vector3Stamped

from grazing_control.ros import launcher
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.plant.faults import FaultModel
from grazing_control.oscillator.flow import transition_matrix
from grazing_control.ros.common import seconds_from_stamp, stamp_key
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.simulation.simulate import period_step
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values
from test_closed_loop import TOPICS as CLOSED_LOOP_TOPICS
from test_closed_loop import NO_WATCHDOG, STUDY, Collector, new_domain, xv

BASE = dict(zeta=0.01, r=0.68, omega=OscillatorParams().omega, delta_d=-5e-6, tau0=0.0,
            pi2_offset=math.pi / 2, x0=math.nan, v0=math.nan, mode="lockstep",
            time_scale=1.0, state_period=1.0, answer_timeout=1.0, max_periods=0,
            fidelity="exact", noise=0.0, seed=0)

#: What the collector keeps: the recorder's topics (the simulator, wait_for_subscribers 1,
#: starts when each has a subscriber) and the deadline misses.
TOPICS = {**CLOSED_LOOP_TOPICS, "oscillator/deadline_miss": Vector3Stamped}


def settings(**kw):
    return settings_from_values({**BASE, **kw})


def delayed_c1(p: OscillatorParams, c2: float, delay: float) -> float:
    """c1 making the grazing bifurcation degenerate with the kick delayed by ``delay``.

    Test-only restatement of issue 8 section 1, independent of the library's
    design.degenerate_c1(p, c2, delay):
    N_g(delay) = Phi(T - s) (I + b k^T) Phi(s), b = Phi(-delay) (0, 1)^T, k = (c1, c2),
    s = pi2_offset / omega; N_g[0, 1] = 0 is linear in c1.
    """
    s = p.pi2_offset / p.omega
    a = np.reshape(transition_matrix(p.zeta, p.period - s), (2, 2))
    m = np.reshape(transition_matrix(p.zeta, s), (2, 2))
    b = np.reshape(transition_matrix(p.zeta, -delay), (2, 2)) @ (0.0, 1.0)
    u = a @ b
    return -((a @ m)[0, 1] + u[0] * c2 * m[1, 1]) / (u[0] * m[0, 1])


def core_fault_run(p, n, c1, c2, on, delay, faults: FaultModel):
    """The core's fault simulation, one period_step per sample (reference for the nodes).

    The controller sees the sample plus the measurement noise of draw(k); its correction
    is lost when draw(k) says so; it acts at actuation_delay(delay, k, T) after the sample.
    Returns the measured samples (what sim_node publishes on oscillator/pi2) and the
    true deviations.
    """
    dx = dv = 0.0
    measured, true = [], []
    for k in range(n):
        f = faults.draw(k)
        mx, mv = p.x_ref + dx + f.noise_x, p.v_ref + dv + f.noise_v
        measured.append((mx, mv))
        true.append((dx, dv))
        dvc = c1 * (mx - p.x_ref) + c2 * (mv - p.v_ref) if k >= on else 0.0
        if f.dropped:
            dvc = 0.0
        seg = period_step(p, dx, dv, dvc, delay=faults.actuation_delay(delay, k, p.period))
        dx, dv = seg.dx, seg.dv
    return np.array(measured), np.array(true)


# ============================================================ engine, no middleware
def test_library_delayed_design_equals_the_restatement():
    """design.degenerate_c1(p, c2, delay) (docs/theory_delay.md, Eq. D5) equals the
    matrix restatement above at the delays the node tests use."""
    p = OscillatorParams(delta_d=-5e-6)
    for c2 in (-1.0, -0.5, 0.5):
        for delay in (0.3, 2.0, 6.0):
            assert degenerate_c1(p, c2, delay) == pytest.approx(delayed_c1(p, c2, delay),
                                                                rel=1e-12)


def test_delayed_c1_at_zero_delay_is_the_study_design():
    p = OscillatorParams(delta_d=-5e-6)
    for c2 in (-1.0, -0.5, 0.3):
        assert delayed_c1(p, c2, 0.0) == pytest.approx(degenerate_c1(p, c2), rel=1e-12)


def test_new_parameters_refused_with_a_reason():
    T = OscillatorParams().period
    for kw, text in [({"actuation_delay": -0.1}, "actuation_delay=-0.1 is invalid"),
                     ({"actuation_delay": T}, "actuation_delay="),
                     ({"actuation_delay": math.nan}, "actuation_delay=nan"),
                     ({"actuation": "soon"}, "actuation='soon' is invalid"),
                     ({"loss": 1.5}, "loss=1.5 is invalid: valid range is 0 <= loss <= 1"),
                     ({"measurement_noise": -1.0}, "measurement_noise=-1.0"),
                     ({"jitter": math.inf}, "jitter=inf"),
                     ({"actuation_delay": 2.0, "fidelity": "zdm2"}, "fidelity='zdm2'"),
                     ({"mode": "realtime", "actuation": "scheduled"}, "actuation_delay=0.0"),
                     ({"mode": "realtime", "actuation": "on_arrival", "jitter": 0.1},
                      "jitter=0.1 is invalid with actuation=on_arrival")]:
        with pytest.raises(ParameterError, match=re.escape(text)):
            settings(**kw)
    assert not settings().scheduled and settings(actuation_delay=1.0).scheduled
    assert not settings(actuation_delay=1.0, actuation="on_arrival").scheduled


def test_controller_validates_the_design_delay_and_the_launcher_passes_it_on(tmp_path):
    from grazing_control.ros.launcher import design_delay as _design_delay
    from grazing_control.ros.controller_values import actuation_delay_from_values

    omega = OscillatorParams().omega
    assert actuation_delay_from_values({"actuation_delay": 6.0, "omega": omega}) == 6.0
    for bad in (-1.0, 2 * math.pi / omega, math.inf):
        with pytest.raises(ParameterError, match="actuation_delay=.* is invalid: valid range"):
            actuation_delay_from_values({"actuation_delay": bad, "omega": omega})
    yaml_file = tmp_path / "c.yaml"
    yaml_file.write_text("/controller_node:\n  ros__parameters:\n    c1: -1.0\n"
                         "    c2: -1.0\n    actuation_delay: 6.0\n")
    assert _design_delay(yaml_file) == 6.0
    assert _design_delay({"c1": -1.0, "actuation_delay": 2.5}) == 2.5
    assert _design_delay(launcher.CONFIG_DIR / "controller.yaml") == 0.0   # undelayed design
    assert _design_delay(tmp_path / "missing.yaml") is None   # the node reports it


def test_delayed_period_equals_period_step_bitwise_on_both_paths():
    """Lockstep (begin_period with a delay) and realtime (begin_period(0), then actuate at
    the deadline) give the same state as simulate.period_step(delay=) bit for bit."""
    rng = np.random.default_rng(8)
    for _ in range(60):
        dd = -10 ** rng.uniform(-6, -2)
        s = settings(delta_d=dd, state_period=0.7)
        T = s.params.period
        a, b = Engine(s), Engine(s)
        dx, dv = a.dx, a.dv
        for _ in range(5):
            delay, dvc = rng.uniform(0, T), rng.normal(0, 0.05)
            ref = period_step(s.params, dx, dv, dvc, delay=delay)
            ev_a = a.begin_period(dvc, delay)
            ev_b0 = b.begin_period(0.0)
            ev_b = [e for e in ev_b0 if e.t < b.t + delay] + b.actuate(dvc, delay)
            assert (a.seg.dx_end, a.seg.dv_end) == (ref.dx, ref.dv)
            assert (b.seg.dx_end, b.seg.dv_end) == (ref.dx, ref.dv)
            assert [e.t for e in ev_a] == sorted(e.t for e in ev_a)
            assert sum(e.kind == "impact" for e in ev_a) == len(ref.impacts)
            assert [e.kind for e in ev_a] == [e.kind for e in ev_b]
            np.testing.assert_allclose([(e.t, e.x, e.v) for e in ev_a],
                                       [(e.t, e.x, e.v) for e in ev_b], rtol=0, atol=1e-9)
            a.end_period()
            b.end_period()
            dx, dv = ref.dx, ref.dv


def test_engine_faults_are_the_fault_models_per_sample():
    s = settings(loss=0.3, measurement_noise=1e-3, jitter=0.5, seed=11, actuation_delay=3.0)
    fm = FaultModel(0.3, 1e-3, 0.5, 11)
    eng = Engine(s)
    for k in range(200):
        f = fm.draw(k)
        ev = eng.sample()
        m = eng.measured(ev)
        assert (m.x, m.v) == (ev.x + f.noise_x, ev.v + f.noise_v)
        assert eng.correction_lost() == f.dropped
        assert eng.actuation_delay() == fm.actuation_delay(3.0, k, s.params.period)
        eng.begin_period(0.0, eng.actuation_delay())
        eng.end_period()
    # without faults the sample is the true one and the delay the designed one
    eng = Engine(settings(actuation_delay=2.0))
    ev = eng.sample()
    assert eng.measured(ev) == ev and eng.actuation_delay() == 2.0 and not eng.correction_lost()


# ======================================================================= nodes
def _scene(tmp_path, domain, n, on, c1, delay, mode="lockstep", sim=None, ex="events",
           controller=None):
    p = OscillatorParams(delta_d=BASE["delta_d"] if sim is None else
                         sim.get("delta_d", BASE["delta_d"]))
    ctl = {"c1": float(c1), "c2": -1.0, "actuation_delay": float(delay), "zeta": p.zeta,
           "r": p.r, "omega": p.omega, "pi2_offset": p.pi2_offset, "executor": ex}
    over = {"state_period": 0.0, "wait_for_subscribers": 1, "wait_for_recorder": True,
            "executor": ex, "on_miss": "drop",   # these scenes specify the drop
            # and replay what the loop did however many answers missed (40 % under a
            # load measured here; the pace tripped once with the pure tests beside)
            **NO_WATCHDOG}
    over.update(sim or {})
    res = launcher.run(STUDY, ctl, None, n, mode=mode, enable_after=on, domain_id=domain,
                       timeout=120, sim_overrides=over, controller_overrides=controller,
                       log_dir=tmp_path)
    log = Path(res.logs["sim_node"]).read_text()
    assert res.ok, (res, log)
    summary = dict(re.findall(r"(\w+)=(\S+)", re.search(r"summary: (.*)", log).group(1)))
    return summary


FAULTS = {"loss": dict(loss=0.3, measurement_noise=0.0, jitter=0.0),
          "noise": dict(loss=0.0, measurement_noise=2e-4, jitter=0.0),
          "jitter": dict(loss=0.0, measurement_noise=0.0, jitter=0.3),
          "realtime, all three": dict(loss=0.3, measurement_noise=2e-4, jitter=0.3)}


def _fault_scene(tmp_path, name, n, on, delay, seed):
    """One scene with the faults FAULTS[name]: (published samples, answers, misses, summary)."""
    domain = new_domain()
    col = Collector(domain, TOPICS, ready=True)
    try:
        p = OscillatorParams(delta_d=-5e-6)
        mode = "realtime" if name.startswith("realtime") else "lockstep"
        # no assertion needs a deadline met (each miss is replayed): not under
        # SCHED_FIFO, beside the FIFO group's scenes (tests/conftest.py)
        summary = _scene(tmp_path / name.split(",")[0], domain, n, on,
                         delayed_c1(p, -1.0, delay), delay, mode,
                         sim={"seed": seed, "time_scale": 1000.0, **FAULTS[name]},
                         controller={"thread_priority": 0})
        assert col.wait_for(lambda: len(col.get("oscillator/pi2")) == n, 5.0)
        answers = col.get("controller/velocity_correction")
        assert col.wait_for(lambda: len(col.get("controller/velocity_correction")) == n,
                            5.0), (name, len(answers), n, summary, [
            stamp_key(m.header.stamp) for m in col.get("controller/velocity_correction")][:3])
        assert col.wait_for(lambda: len(col.get("oscillator/deadline_miss"))
                            == int(summary["missed"]), 5.0), summary
        pi2 = col.get("oscillator/pi2")
        dv = {stamp_key(m.header.stamp): m.twist.linear.x
              for m in col.get("controller/velocity_correction")}
        missed = {int(m.vector.x) for m in col.get("oscillator/deadline_miss")}
        return xv(pi2), [dv.get(stamp_key(m.header.stamp)) for m in pi2], missed, summary
    finally:
        col.close()


N_FAULTS, ON_FAULTS, DELAY_FAULTS, SEED_FAULTS = 250, 120, 5.0, 3


def _fault_scenes(tmp_path, names):
    """The fault scenes ``names`` (keys of FAULTS) at once, each in its own domain."""
    import concurrent.futures

    with concurrent.futures.ThreadPoolExecutor(len(names)) as pool:
        jobs = {name: pool.submit(_fault_scene, tmp_path, name, N_FAULTS, ON_FAULTS,
                                  DELAY_FAULTS, SEED_FAULTS) for name in names}
        return {name: job.result() for name, job in jobs.items()}


def test_faults_through_the_nodes_in_lockstep_reproduce_the_core_fault_run(tmp_path):
    """Issue 8 section 3 through the nodes: delay 5 with the delay-aware gains and one
    fault at a time (loss 0.3; measurement noise 2e-4; jitter 0.3) in lockstep, the
    three scenes at once (own domains): each equals the core's fault simulation (the
    reference loop above, written from the FaultModel alone) sample for sample: bitwise
    before control, to rounding after (the controller computes from the published
    physical state). (Lockstep meets no deadline: beside the other tests, not in the
    realtime group; the realtime scene with all three is the next test.)"""
    n, on, delay, seed = N_FAULTS, ON_FAULTS, DELAY_FAULTS, SEED_FAULTS
    p = OscillatorParams(delta_d=-5e-6)
    c1 = delayed_c1(p, -1.0, delay)
    results = _fault_scenes(tmp_path, [name for name in FAULTS if not name.startswith("realtime")])
    assert len(results) == 3
    for name, (got, answers, missed, summary) in results.items():
        f = FAULTS[name]
        fm = FaultModel(f["loss"], f["measurement_noise"], f["jitter"], seed)
        lost = {k for k in range(n) if fm.draw(k).dropped}
        print(f"\n{name}: {summary}")
        ref, _ = core_fault_run(p, n, c1, -1.0, on, delay, fm)
        np.testing.assert_array_equal(got[:on], ref[:on])  # uncontrolled: the same calls
        rel = np.abs(got[on:] - ref[on:]).max() / np.abs(ref[on:]).max()
        assert rel < 1e-9, (name, rel)  # controller from the physical state: rounding
        assert int(summary["lost"]) == len(lost) and int(summary["applied"]) == n - len(lost)
        assert int(summary["missed"]) == 0 and not missed


def test_faults_through_the_nodes_in_realtime_reproduce_the_core_replay(tmp_path):
    """All three faults of the previous test (loss 0.3, measurement noise 2e-4, jitter
    0.3) in realtime at time_scale 1000, delay 5, the delay-aware gains: the samples
    equal the core's replay of the scene's own corrections with the same faults, bit for
    bit, a deadline miss counting as a lost correction.

    Not in the realtime group: no assertion needs a deadline met (each miss is replayed
    as a lost correction and counted; the watchdog is off, on_miss drop), so it runs in
    the module's scene group beside the other tests (3.3-3.6 s less of the suite's
    serial tail). Beside two busy-looping processes 9-29 of the 250 answers missed (4
    runs; 156-168 corrections applied) and the replay held bit for bit
    (docs/benchmarks.md, "The suite's tail and CPU")."""
    n, delay, seed = N_FAULTS, DELAY_FAULTS, SEED_FAULTS
    p = OscillatorParams(delta_d=-5e-6)
    ((name, (got, answers, missed, summary)),) = _fault_scenes(
        tmp_path, ["realtime, all three"]).items()
    f = FAULTS[name]
    fm = FaultModel(f["loss"], f["measurement_noise"], f["jitter"], seed)
    lost = {k for k in range(n) if fm.draw(k).dropped}
    print(f"\n{name}: {summary}")
    assert lost and fm.jitter > 0 and fm.noise > 0
    dx = dv = 0.0
    for k in range(n):
        noise = fm.draw(k)
        assert (got[k, 0], got[k, 1]) == (p.x_ref + dx + noise.noise_x,
                                          p.v_ref + dv + noise.noise_v), k
        dvc = 0.0 if (k in missed or k in lost) else answers[k]
        seg = period_step(p, dx, dv, dvc, delay=fm.actuation_delay(delay, k, p.period))
        dx, dv = seg.dx, seg.dv
    assert int(summary["lost"]) == len(lost - missed)
    assert int(summary["applied"]) == n - len(lost | missed)


#: The realtime-vs-lockstep scenes: 100 uncontrolled periods, 140 controlled: the core's
#: closed loop of each Delta d is captured (every later sample within 1e-9 of the orbit)
#: 14-19 periods after the switch-on, from k = 60, 100 or 150 alike; the last 100 samples
#: begin 40 after it. (420 and 200 before: 1.7 s more of each realtime scene, in the
#: realtime group.) time_scale 1000, delay 6.
N_CHAOS, ON_CHAOS, DELAY_CHAOS, SCALE_CHAOS, DD_CHAOS = 240, 100, 6.0, 1000.0, (-5e-6, -9e-6)


def _chaos_scene(tmp_path, delta_d, mode):
    """(Pi2 samples, summary, answers by sample, {k: deadline miss}) of one scene of
    test_realtime_scheduled_matches_lockstep_and_suppresses_the_chaos."""
    n, on, delay = N_CHAOS, ON_CHAOS, DELAY_CHAOS
    c1 = delayed_c1(OscillatorParams(delta_d=delta_d), -1.0, delay)
    domain = new_domain()
    col = Collector(domain, TOPICS, ready=True)
    try:
        summary = _scene(tmp_path / mode, domain, n, on, c1, delay, mode,
                         sim={"delta_d": delta_d, "time_scale": SCALE_CHAOS})
        assert col.wait_for(lambda: len(col.get("oscillator/pi2")) == n, 5.0)
        assert col.wait_for(
            lambda: len(col.get("controller/velocity_correction")) == n, 5.0)
        assert col.wait_for(lambda: len(col.get("oscillator/deadline_miss"))
                            == int(summary["missed"]), 5.0), summary
        dv = {stamp_key(m.header.stamp): m.twist.linear.x
              for m in col.get("controller/velocity_correction")}
        pi2 = col.get("oscillator/pi2")
        missed = {int(m.vector.x): m for m in col.get("oscillator/deadline_miss")}
        return xv(pi2), summary, [dv[stamp_key(m.header.stamp)] for m in pi2], missed
    finally:
        col.close()


@pytest.fixture(scope="module")
def lockstep_chaos(tmp_path_factory):
    """The lockstep scenes of both Delta d of the next test, at once (own domains; a
    lockstep scene meets no deadline): in the realtime group they ran one after the
    other, each before its realtime scene (1.0-2.4 s each of the suite's serial tail)."""
    import concurrent.futures

    tmp = tmp_path_factory.mktemp("lockstep_chaos")
    with concurrent.futures.ThreadPoolExecutor(len(DD_CHAOS)) as pool:
        jobs = {dd: pool.submit(_chaos_scene, tmp / repr(dd), dd, "lockstep")
                for dd in DD_CHAOS}
        return {dd: job.result() for dd, job in jobs.items()}


@pytest.mark.realtime
@pytest.mark.parametrize("delta_d", DD_CHAOS)
def test_realtime_scheduled_matches_lockstep_and_suppresses_the_chaos(tmp_path, delta_d,
                                                                      lockstep_chaos):
    """time_scale 1000 (a period is 9.4 ms of wall time), delay 6 (6 ms of wall time,
    several times the idle p99 latency), delay-aware gains.

    * Every realtime sample is the core's replay of the run: period_step with the
      delay and the controller's published corrections, 0 for each sample whose deadline
      was missed, bit for bit: nothing acts at another phase.
    * Until the first miss that mattered the realtime samples are the lockstep run's
      (<= 1e-12); on a loaded machine that may be before control starts.
    * Every miss is counted once and published with its sample's stamp.
    * The 1/1 orbit is captured (lockstep exactly; realtime on most of the last 100
      samples, each miss costing one uncorrected period) while at most 10 % of the
      controlled samples miss their deadline (beyond that, on an overloaded machine,
      a warning reports it: the replay has already shown what the run did).
    """
    n, on, delay = N_CHAOS, ON_CHAOS, DELAY_CHAOS
    p = OscillatorParams(delta_d=delta_d)
    runs = {"lockstep": lockstep_chaos[delta_d],
            "realtime": _chaos_scene(tmp_path, delta_d, "realtime")}
    lock, rt = runs["lockstep"][0], runs["realtime"][0]
    summary, answers, missed = runs["realtime"][1], runs["realtime"][2], runs["realtime"][3]
    assert int(runs["lockstep"][1]["missed"]) == 0
    # every miss counted once, published with its sample's stamp, its correction not applied
    assert len(missed) == int(summary["missed"])
    assert int(summary["applied"]) + len(missed) == n
    for k, m in missed.items():
        assert seconds_from_stamp(m.header.stamp) == pytest.approx(k * p.period, abs=1e-9)
        assert m.vector.y == pytest.approx(k * p.period + delay, abs=1e-9)
    # the realtime run is the core's period_step with the delay and the applied corrections
    dx, dv = 0.0, 0.0
    for k in range(n):
        assert (rt[k, 0], rt[k, 1]) == (p.x_ref + dx, p.v_ref + dv), k
        seg = period_step(p, dx, dv, 0.0 if k in missed else answers[k], delay=delay)
        dx, dv = seg.dx, seg.dv
    # equal to the lockstep run until the first miss that mattered
    effective = [k for k in sorted(missed) if answers[k] != 0.0]
    upto = n if not effective else effective[0] + 1     # sample `first` itself still equal
    np.testing.assert_allclose(rt[:upto], lock[:upto], rtol=0, atol=1e-12)
    tail = lock[-50:, 0]
    assert tail.max() - tail.min() < 1e-9                  # lockstep: on the 1/1 orbit
    off = np.abs(rt[-100:, 0] - lock[-1, 0])
    print(f"\nrealtime Delta d={delta_d}: {summary}\n  equal to lockstep for samples "
          f"0..{upto - 1}; misses at {sorted(missed)}; last 100 samples |x - x_orbit| "
          f"median {np.median(off):.2e} max {off.max():.2e}")
    # capture needs most corrections on time: a miss is a lost correction, and how much
    # loss control tolerates is the core's question (issue 8 section 3), answered for
    # this very run by the replay above; on an overloaded machine it is reported
    late_share = sum(k >= on for k in missed) / (n - on)
    if late_share <= 0.1:
        assert np.median(off) < 1e-9 and off.max() < 0.05, off
    else:
        warnings.warn(f"realtime Delta d={delta_d}: {late_share:.0%} of the controlled "
                      "samples missed their deadline (machine overloaded): capture not "
                      f"asserted; |x - x_orbit| median {np.median(off):.2e}")

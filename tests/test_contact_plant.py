"""The simulator's compliant stop (plant/contact_plant.py, sim_node's contact parameters):
the engine runs the core's compliant period map, its stream states are that flow, and a
bad contact parameter is one clear line naming it (issue 31, docs/nodes.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.orbits.shooting import iterate
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt, advance_compliant
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.hertz import HuntCrossley
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

from test_closed_loop import CONTROLLER, STUDY, collector, domain, xv  # noqa: F401 (fixtures)

#: the failing set of docs/theory_contact.md section 15 at a stiffness above the boundary
SCENE = dict(delta_d=-0.05, contact="kelvin_voigt", friction=0.01, friction_static=0.012)


def _settings(k, **kw):
    p = OscillatorParams(delta_d=-0.05)
    law = KelvinVoigt.from_restitution(k, p.r)
    return settings_from_values({**SCENE, "contact_stiffness": law.stiffness,
                                 "contact_damping": law.damping, "state_period": 0.5, **kw})


def test_engine_runs_the_compliant_period_map_with_its_corrections():
    """Ten periods of the engine under the rigid design's corrections (c2 = -1.5) equal
    CompliantOneDOF's map (the model the chart's multipliers are of) period by period, to
    rounding, and the contacts are published as impacts."""
    s = _settings(1e4)
    p = s.params
    gains = Gains(degenerate_c1(p, -1.5), -1.5)
    model = CompliantOneDOF(p, gains, law=s.contact.law, friction=s.contact.friction)
    eng = Engine(s)
    z = np.array([eng.dx, eng.dv])
    impacts = 0
    for _ in range(10):
        dvc = gains.c1 * eng.dx + gains.c2 * eng.dv
        events = eng.begin_period(dvc)
        impacts += sum(e.kind == "impact" for e in events)
        eng.end_period()
        z, _, _ = iterate(model, z)
        assert (eng.dx, eng.dv) == pytest.approx(tuple(z), abs=1e-12)
    assert impacts >= 5


def test_stream_states_are_the_compliant_flow():
    """The oscillator/state samples of a period are advance_compliant from its start."""
    s = _settings(1e2, state_period=0.25)
    eng = Engine(s)
    p = s.params
    x0, v0 = p.x_ref + eng.dx, p.v_ref + eng.dv
    events = eng.begin_period(0.0)
    for e in [e for e in events if e.kind == "state"][:8]:
        ref = advance_compliant(p, s.contact.law, p.tau2, x0, v0, e.t,
                                friction=s.contact.friction)
        assert (e.x, e.v) == pytest.approx((ref.x, ref.v), abs=1e-11)


def test_hertz_and_rigid_values():
    s = settings_from_values({"delta_d": -0.01, "contact": "hertz", "contact_stiffness": 1e4,
                              "contact_damping": 0.5})
    assert s.contact.law == HuntCrossley(1e4, 0.5) and s.contact.friction is None
    assert settings_from_values({"delta_d": -0.01}).contact is None
    kv = _settings(1e3, friction_static=0.0)
    assert kv.contact.friction == Coulomb(0.01, 0.01)
    hertz = settings_from_values({"delta_d": -0.01, "contact": "hertz", "friction": 0.01,
                                  "contact_stiffness": 1e4, "friction_static": 0.012})
    assert hertz.contact.friction == Coulomb(0.01, 0.012)


@pytest.mark.parametrize("bad, name", [
    (dict(contact="rubber"), "contact="),
    (dict(contact_stiffness=0.0), "contact_stiffness="),
    (dict(contact_stiffness=math.inf), "contact_stiffness="),
    (dict(contact_damping=-1.0), "contact_damping="),
    (dict(contact_damping=1e3), "contact_damping="),
    (dict(friction=-0.1), "friction="),
    (dict(friction_static=0.005), "friction_static="),
    (dict(contact="rigid"), "friction="),
    (dict(fidelity="zdm2"), "fidelity="),
    (dict(actuator_bandwidth=2.0), "actuator_bandwidth="),
    (dict(actuator_latency=0.1), "actuator_latency="),
])
def test_bad_contact_parameters_name_the_parameter(bad, name):
    with pytest.raises(ParameterError, match=name):
        _settings(1e3, **bad)


# ============================================= every scene the wall runs in (issue 31)
def _stop(kind: str, k: float) -> dict:
    """sim_node's stop parameters: Kelvin-Voigt at the study's r (C3), with the friction of
    SCENE or without, or Hertz with alpha = (1 - r) / 0.3 (C5 at v- = 0.3)."""
    p = OscillatorParams(delta_d=-0.05)
    if kind == "hertz":
        return dict(contact="hertz", contact_stiffness=k, contact_damping=(1.0 - p.r) / 0.3)
    law = KelvinVoigt.from_restitution(k, p.r)
    out = dict(contact="kelvin_voigt", contact_stiffness=law.stiffness,
               contact_damping=law.damping)
    return {**out, **({"friction": 0.01, "friction_static": 0.012} if kind == "friction"
                      else {})}


def _core_pulse_loop(s, n, gains, on, delay, skip):
    """The core, one period per sample (as test_plant_loops.reference for the wall):
    ContactPlant.pulse_step with the pulse at pulse_start (the delay of sample k drawn by
    the fault model where there is jitter); the Pi2 samples, physical."""
    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.plant.settings import initial_deviation

    p, w = s.params, s.pulse_width
    dx, dv = initial_deviation(p, s.x0, s.v0)
    out = []
    for k in range(n):
        out.append((p.x_ref + dx, p.v_ref + dv))
        dvc = gains.c1 * dx + gains.c2 * dv if k >= on and k not in skip else 0.0
        delay_k = s.faults.actuation_delay(delay, k, p.period) if s.jitter else delay
        dx, dv, _ = s.contact.pulse_step(p, dx, dv, dvc, pulse_start(p.period, delay_k, w), w,
                                         s.force_limit or math.inf)
    return np.array(out)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kind, n, w, jitter", [("friction", 40, 0.6, 0.0),
                                                ("plain", 30, 0.0, 0.5),
                                                ("hertz", 12, 0.6, 0.0)])
def test_a_realtime_pulse_scene_is_the_core_loop_sample_for_sample(kind, n, w, jitter):
    """Realtime with the correction as a force pulse (or the kick, w = 0, with jitter on
    its delay) after a scheduled delay, two deadline misses: the Pi2 samples equal the
    core's loop bit for bit (the engine's pieces are the stop's flow, the pulse the same
    shift of the stop as of the wall), and the stop's contacts are published as
    impacts."""
    from test_plant_loops import Clock, Recorder, key, run_realtime

    delay, on, c2 = 3.0, 5, -1.0
    p = OscillatorParams(delta_d=-0.05)
    gains = Gains(degenerate_c1(p, c2), c2)
    s = settings_from_values({"delta_d": -0.05, "mode": "realtime", "time_scale": 1000.0,
                              "actuation_delay": delay, "pulse_width": w, "max_periods": n,
                              "jitter": jitter,
                              "state_period": 0.5, "x0": p.x_ref + 0.05, **_stop(kind, 1e3)})
    skip = {8, 9}
    clock, sink = Clock(), Recorder()

    def answer(loop, ev):
        k = round(ev.t / p.period)
        if k in skip:
            return
        clock.now += 1e-4
        dvc = gains.c1 * (ev.x - p.x_ref) + gains.c2 * (ev.v - p.v_ref)
        loop.answer(key(ev), dvc if k >= on else 0.0)

    run_realtime(s, n, answer, clock, sink)
    got = np.array([(e.x, e.v) for e in sink.samples()])
    np.testing.assert_array_equal(got, _core_pulse_loop(s, n, gains, on, delay, skip))
    assert [m[0] for m in sink.misses] == sorted(skip)
    assert sum(e.kind == "impact" for e in sink.events) >= n // 2
    assert sum(e.kind == "state" for e in sink.events) >= n * 15


@pytest.mark.parametrize("kind", ["friction", "hertz"])
def test_a_pulse_into_the_stop_matches_the_reference_with_the_force_written_in(kind):
    """A pulse that pushes the mass into the stop (delays 6 and 7: a contact inside the
    pulse): the engine's period and the stream's states during the pulse equal the
    DOP853 reference with the constant force in its equation of motion (not the shifted
    stop of the plant), to 1e-11."""
    from grazing_control.dynamics.simulation.actuation import pulse_force, pulse_start
    from reference_contact import reference_advance
    from reference_hertz import reference_advance_hertz

    p, w, dvc = OscillatorParams(delta_d=-0.05), 1.5, 0.3
    inside = 0
    for delay in (6.0, 7.0):
        s = settings_from_values({"delta_d": -0.05, "pulse_width": w, "actuation_delay": delay,
                                  "state_period": 0.25, "x0": p.x_ref + 0.02,
                                  **_stop(kind, 1e2)})
        law, friction = s.contact.law, s.contact.friction

        def ref(tau, x, v, h, force=0.0):
            if kind == "hertz":
                return reference_advance_hertz(p, law, tau, x, v, h, force=force)
            return reference_advance(p, law, tau, x, v, h, friction=friction, force=force)

        eng = Engine(s)
        x0, v0 = p.x_ref + eng.dx, p.v_ref + eng.dv
        eng.begin_period(0.0)
        events = eng.actuate(dvc, delay)
        start = pulse_start(p.period, delay, w)
        force = pulse_force(dvc, w, math.inf)
        a = ref(p.tau2, x0, v0, start)
        for e in [e for e in events if e.kind == "state" and e.t < start + w]:
            b = ref(p.tau2 + p.omega * start, a[0], a[1], e.t - start, force)
            assert (e.x, e.v) == pytest.approx((b[0], b[1]), abs=1e-11)
        b = ref(p.tau2 + p.omega * start, a[0], a[1], w, force)
        inside += len(b[2])
        c = ref(p.tau2 + p.omega * (start + w), b[0], b[1], p.period - start - w)
        assert (p.x_ref + eng.seg.dx_end, p.v_ref + eng.seg.dv_end) == pytest.approx(
            (c[0], c[1]), abs=1e-11)
    assert inside >= 2


def test_a_drifting_wall_and_a_split_period_on_the_compliant_stop():
    """delta_d_drift: period k runs the stop's period map with Delta d + drift k (as for the
    wall, test_plant_engine); a correction on arrival (split) is the stop's flow to its
    time, the jump, the flow on."""
    drift = 1e-4
    s = _settings(1e3, delta_d_drift=drift, x0=OscillatorParams(delta_d=-0.05).x_ref + 0.02)
    eng, p = Engine(s), s.params
    z = (eng.dx, eng.dv)
    for k in range(6):
        assert eng.p == p.with_(delta_d=p.delta_d + drift * k)
        eng.begin_period(1e-3 * k)
        eng.end_period()
        z = s.contact.period_step(p.with_(delta_d=p.delta_d + drift * k), *z, 1e-3 * k)[:2]
        assert (eng.dx, eng.dv) == z
    eng.begin_period(0.0)
    q, seg = eng.p, eng.seg
    tc = seg.ts + 4.0
    eng.split(tc, 0.05)
    head = s.contact.advance(q, q.tau2, seg.dx, seg.dv, tc - seg.ts)
    tail = s.contact.advance(q, (q.tau2 + (tc - seg.ts) * q.omega) % (2.0 * math.pi),
                             head.dx, head.dv + 0.05, seg.te - tc)
    assert (eng.seg.dx_end, eng.seg.dv_end) == (tail.dx, tail.dv)


# ======================================================================= nodes
def _node_scene(tmp_path, domain, collector, log10_k, periods=40, offset=(1e-4, 0.0),
                enable_after=0):
    """The failing set through sim_node and controller_node in lockstep: the rigid design
    (c2 = -1.5) from the first sample, the plant started 1e-4 off its controlled orbit
    (found by continuation from the rigid one on CompliantOneDOF). Returns the Pi2
    samples' deviations from X**, the orbit and the model."""
    from grazing_control.dynamics.orbits.continuation import continue_orbit
    from grazing_control.dynamics.maps.model import OneDOF
    from grazing_control.dynamics.orbits.shooting import find_periodic
    from grazing_control.ros import launcher

    s = _settings(10.0 ** log10_k)
    p = s.params
    gains = Gains(degenerate_c1(p, -1.5), -1.5)
    rigid = find_periodic(OneDOF(p, gains), np.zeros(2))
    model = CompliantOneDOF(p, gains, law=KelvinVoigt.from_restitution(1e8, p.r),
                            friction=s.contact.friction)
    branch = continue_orbit(model, "log10_stiffness", np.linspace(8.0, log10_k, 12),
                            rigid.state)
    orbit = branch.points[-1]
    assert orbit.value == pytest.approx(log10_k)
    start = orbit.state + np.array(offset)
    sim = {"delta_d": p.delta_d, "x0": float(p.x_ref + start[0]),
           "v0": float(p.v_ref + start[1]), "state_period": 0.0, "wait_for_subscribers": 1,
           "wait_for_recorder": True, **SCENE, "contact_stiffness": s.contact.law.stiffness,
           "contact_damping": s.contact.law.damping}
    res = launcher.run(STUDY, CONTROLLER, None, periods, domain_id=domain, timeout=120,
                       sim_overrides=sim, controller_overrides={
                           "enable_after": enable_after, "c1": gains.c1, "c2": gains.c2},
                       log_dir=tmp_path)
    assert res.ok, (res, (tmp_path / "sim_node.log").read_text()
                    if (tmp_path / "sim_node.log").exists() else "")
    assert collector.wait_for(lambda: len(collector.get("oscillator/pi2")) == periods, 20.0)
    got = xv(collector.get("oscillator/pi2")) - np.array([p.x_ref, p.v_ref])
    contacts = len(collector.get("oscillator/impact"))
    return got, orbit, model.with_parameter("log10_stiffness", log10_k), contacts


@pytest.mark.timeout(300)
@pytest.mark.parametrize("log10_k, holds", [(3.0, False), (0.5, True)])
def test_a_node_scene_on_each_side_of_the_boundary(tmp_path, domain, collector, log10_k,
                                                   holds):
    """docs/theory_contact.md section 15: with friction F_f = 0.01 the rigid design
    (c2 = -1.5) fails above k_c = 19.6 and holds below. Through the nodes, 40 controlled
    periods from 1e-4 off the controlled orbit: at k_c = 1e3 (max |lambda| 1.51) the
    motion leaves the orbit (> 0.1 away at the end), at k_c = 10^0.5 (0.918) it returns
    (< 2e-5); sample for sample the scene is the core's map (CompliantOneDOF) with the
    controller's corrections, to 1e-6 (the controller computes from the published
    physical state: rounding, grown by at most 1.51^40 on the unstable side)."""
    got, orbit, model, contacts = _node_scene(tmp_path, domain, collector, log10_k)
    z, expected = got[0], 0
    for k in range(1, len(got)):
        z, _, impacts = iterate(model, z)
        expected += len(impacts)
        assert got[k] == pytest.approx(z, abs=1e-6 * max(1.0, np.abs(z).max())), k
    away = np.linalg.norm(got[-1] - orbit.state)
    assert (away < 2e-5) if holds else (away > 0.1), away
    expected += len(iterate(model, z)[2])   # the 40th period runs after the last sample
    assert contacts == expected   # every contact published as an impact


@pytest.mark.timeout(300)
def test_capture_through_the_nodes_below_the_boundary(tmp_path, domain, collector):
    """docs/theory_contact.md section 15, "Capture": the control switched on far from the
    orbit. At k_c = 10^0.5 (below the boundary 19.61) the plant runs uncontrolled for 10
    periods from 0.3 off the controlled orbit (friction's own attractor, 19 contacts in 20
    periods), then the rigid design (c2 = -1.5) captures it: each sample is the core's
    map, free then controlled, to 1e-6, and the motion comes from 0.054 off the orbit at
    the switch-on to 0.0051 in 30 controlled periods (the multiplier 0.918: 0.918^30 =
    0.077; measured 0.094)."""
    got, orbit, model, _ = _node_scene(tmp_path, domain, collector, 0.5, periods=40,
                                       offset=(0.3, -0.2), enable_after=10)
    free = CompliantOneDOF(model.params, Gains(0.0, 0.0), law=model.law, friction=model.friction)
    z = got[0]
    for k in range(1, len(got)):
        z = iterate(free if k <= 10 else model, z)[0]
        assert got[k] == pytest.approx(z, abs=1e-6), k
    switch_on = np.linalg.norm(got[10] - orbit.state)
    away = np.linalg.norm(got[-1] - orbit.state)
    assert switch_on > 0.03 and away < 0.01 and away < switch_on / 5, (switch_on, away)

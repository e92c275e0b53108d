"""Switching the correction on (grazing_control.dynamics.design.capture): the rules as pure
callables, the capture time on arrays with a known answer, and the closed loop from a
distance of 4.5e-2 (issue 29) with the study's gains (c2 = -1, delay 0): at once, the
first correction is 4.3e-2; with the capture rule it never exceeds 1e-3, and both
capture.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from grazing_control.dynamics.design.capture import (CaptureRule, GainRamp, capture_time,
                                                      free_approach)
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.estimation.section_state import estimate_covariance
from grazing_control.dynamics.design.noise import noise_covariance
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.estimation.stream import simulate_stream
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.sensor import SensorModel

P = OscillatorParams(delta_d=-5e-6)


def _est(z, cov=np.eye(2)):
    return SimpleNamespace(z=tuple(z), cov=cov)


def test_the_rule_switches_on_within_its_radius_and_stays_on():
    rule = CaptureRule((0.0, 0.0), 1e-2)
    assert rule(0, _est((2e-2, 0.0))) == 0.0
    assert rule(1, _est((math.nan, 0.0))) == 0.0
    # 8.5e-3 away, but the covariance says the estimate is unknown (a nearest sample)
    assert rule(2, _est((6e-3, 6e-3), np.full((2, 2), math.inf))) == 0.0
    assert rule(3, _est((6e-3, 6e-3))) == 1.0 and rule.on_at == 3
    assert rule(4, _est((1.0, 0.0))) == 1.0              # latched
    assert CaptureRule.for_wall((0, 0), -4e-6, 5.0).radius == pytest.approx(1e-2)


def test_the_rule_keeps_its_closest_approach_and_says_once_when_it_has_waited_too_long():
    """While it holds back the rule keeps the least distance of an estimate it judged
    (not a NaN one, nor one with an unknown covariance) and counts the sections held;
    ``news`` warns once, at the ``patience``-th section held, naming the closest approach
    and the radius; on switching on it says so at that section; ``summary`` is the
    controller's summary field."""
    rule = CaptureRule((0.0, 0.0), 1e-2)
    assert rule.summary() == "captured_at=None capture_closest=inf capture_radius=0.01"
    news = []
    for k, dz in enumerate([(0.3, 0.0), (0.0, 0.2), (math.nan, 0.0), (0.25, 0.0)]):
        assert rule(k, _est(dz)) == 0.0
        news.append(rule.news(k, patience=3))
    assert rule(4, _est((1e-3, 1e-3), np.full((2, 2), math.inf))) == 0.0
    assert news[:2] == [None, None] and news[3] is None
    level, line = news[2]
    assert level == "warning" and "in 3 sections" in line and "no closer than 0.2 " in line \
        and "radius 0.01)" in line
    assert (rule.held, rule.closest) == (5, 0.2)
    assert rule.summary() == "captured_at=None capture_closest=0.2 capture_radius=0.01"
    assert rule(5, _est((0.0, 5e-3))) == 1.0 and rule.held == 5
    assert rule.news(5, patience=3)[0] == "info" and "section 5" in rule.news(5)[1]
    assert rule(6, _est((1.0, 0.0))) == 1.0 and rule.news(6) is None
    assert rule.summary() == "captured_at=5"


def test_the_forecast_warns_only_where_the_free_motion_leaves_and_stays_away():
    """free_approach: ``left`` the first period beyond the radius, ``closest`` the least
    distance over periods late..periods; a warning only where it left and stayed beyond
    (a motion doubling away from z** from 0.01, radius 0.05: left at period 3); none
    where it comes back (halving from 0.3), nor where it never leaves."""
    fa = free_approach(lambda z: 2.0 * z, (0.0, 0.0), 0.05, start=(0.01, 0.0), late=5,
                       periods=8)
    assert (fa.left, fa.closest) == (3, 0.32)
    assert "leaves the radius 0.05 of the controlled orbit at period 3 and comes no closer " \
        "than 0.32 in periods 5-8" in fa.warning()
    back = free_approach(lambda z: 0.5 * z, (0.0, 0.0), 0.05, start=(0.3, 0.0), late=5,
                         periods=8)
    assert back.left == 0 and back.closest < 0.05 and back.warning() is None
    still = free_approach(lambda z: z, (0.0, 0.01), 0.05, late=5, periods=8)
    assert still.left is None and still.warning() is None


def test_the_ramp_rises_linearly_to_one():
    ramp = GainRamp(4, start=2)
    assert [ramp(k) for k in range(8)] == [0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0]
    assert GainRamp(1)(0) == 1.0


@pytest.mark.parametrize("make, match", [
    (lambda: CaptureRule((0, 0), 0.0), "capture_radius=0.0"),
    (lambda: CaptureRule((0, 0), math.inf), "capture_radius=inf"),
    (lambda: GainRamp(0), "ramp_sections=0"), (lambda: GainRamp(2.5), "ramp_sections=2.5")])
def test_bad_settings_are_refused_naming_the_parameter(make, match):
    with pytest.raises(ParameterError, match=match):
        make()


def test_the_capture_time_is_where_the_run_enters_for_good():
    truth = np.array([[1.0, 0], [0.0, 0], [0.5, 0], [0.0, 0], [0.01, 0], [0.0, 0.0]])
    ones = np.ones(6, int)
    assert capture_time(truth, ones, (0.0, 0.0), 0.1) == 3
    ones[4] = 2                                         # two impacts in period 4
    assert capture_time(truth, ones, (0.0, 0.0), 0.1) == 5
    assert capture_time(truth[:3], ones[:3], (0.0, 0.0), 0.1) is None


def test_the_rule_captures_from_afar_with_small_corrections():
    """Study gains (c2 = -1, delay 0), start 4.5e-2 off in x, 200 periods: both capture
    (within 5 predicted standard deviations for good; measured 9 periods at once, 15
    with the rule), the rule's largest correction is below 1e-3 (measured 3.2e-4)
    against 4.3e-2 at once."""
    g = Gains(degenerate_c1(P, -1.0, 0.0), -1.0, 0.0)
    z = np.array(orbit_11(P, g).pi2_deviation)
    band = 5.0 * math.sqrt(np.trace(noise_covariance(P, g, estimate_covariance(P, g, 200))) * 1e-8)
    out = {}
    for mode, switch in (("now", None), ("rule", CaptureRule.for_wall(z, P.delta_d))):
        run = simulate_stream(P, g, SensorModel(noise=1e-4, velocity=False, seed=2).measure,
                              200, 200, sigma=1e-4, deviation=z + np.array([4.5e-2, 0.0]),
                              switch=switch)
        out[mode] = (capture_time(run.truth, run.impacts_per_period, z, band),
                     float(np.max(np.abs(run.corrections))))
    assert out["now"][0] is not None and out["rule"][0] is not None
    assert out["now"][1] > 4e-2 and out["rule"][1] < 1e-3


def test_the_rule_of_2n_coordinates_switches_at_its_radius_and_stays_on():
    """n = 2 (issue 32): the Euclidean norm of the 2n-vector z^ - z** against the radius
    (just outside, on, inside), latched; a NaN coordinate or an unknown covariance never
    switches; n = 1 is np.hypot bit for bit."""
    target = np.array([0.1, -0.2, 0.3, 0.05])
    step = np.full(4, 0.5e-2)
    rule = CaptureRule(target, float(np.linalg.norm(target + step - target)))   # ~1e-2
    cov = np.eye(4)
    assert rule(0, _est(target + 1.001 * step, cov)) == 0.0
    assert rule(1, _est(target + np.array([math.nan, 0, 0, 0]), cov)) == 0.0
    assert rule(2, _est(target, np.full((4, 4), math.nan))) == 0.0
    assert rule(3, _est(target + step, cov)) == 1.0 and rule.on_at == 3
    assert rule(4, _est(target + 100.0 * step, cov)) == 1.0        # latched
    assert rule(5, _est(target + np.array([math.nan] * 4), cov)) == 1.0 and rule.on_at == 3
    # n = 1: the same hypot as before (its rounding, not the norm's, at the boundary)
    for dz in [(3e-3, 4e-3), (1e-300, 1e-300), (0.1, 0.7)]:
        r = float(np.hypot(*dz))
        assert CaptureRule((0.0, 0.0), r)(0, _est(dz)) == 1.0
        assert CaptureRule((0.0, 0.0), math.nextafter(r, 0.0))(0, _est(dz)) == 0.0


def _chain_pulse():
    import dataclasses

    from grazing_control.dynamics.design.family import Actuation, evaluate_design
    from grazing_control.oscillator.ndof.model import load_model
    from grazing_control.ros import launcher

    path = launcher.CONFIG_DIR / "models" / "two_mass_chain.yaml"
    model = dataclasses.replace(load_model(path), delta_d=-1e-3)
    return path, model, evaluate_design(model, -0.22, Actuation(1.0, 1.0)).gains


def test_the_rule_captures_the_chain_the_law_at_once_does_not():
    """Two-mass chain at Delta d = -1e-3, the pulse design (mu -0.22, delay 1, width 1;
    z** 0.073 from X**, its correction 0.128), the force clipped at 0.6 (m_a = 1, w = 1:
    Delta v <= 0.6), exact state on the n-DOF map, switched on after 100 uncontrolled
    periods (0.61 from z**): the law at once saturates and settles 0.35 away on a
    clipped orbit; the rule (radius 5 sqrt(|Delta d|) = 0.158) waits 1 period and then
    captures (within 1e-5 of z** by period 60, the multipliers 0.81). docs/theory_capture.md, n DOF."""
    from grazing_control.dynamics.maps.modal_map import ModalMap, pulse_step
    from grazing_control.dynamics.orbits.one_one import orbit

    _path, model, k = _chain_pulse()
    target = orbit(model, k, delay=1.0, width=1.0).state
    free, cm = ModalMap(model), ModalMap(model, k, 1.0, 1.0)
    z0 = target.copy()
    for _ in range(100):
        z0 = free.step(z0).state
    ends = {}
    for name, rule in (("at once", None), ("rule", CaptureRule.for_wall(target, -1e-3))):
        z = z0.copy()
        for j in range(60):
            factor = 1.0 if rule is None else rule(j, _est(z, np.eye(4)))
            z = pulse_step(cm.flow, z, factor * float(k @ z), start=cm.pulse_start,
                           width=1.0, force_limit=0.6).state
        ends[name] = (float(np.linalg.norm(z - target)), None if rule is None else rule.on_at)
    assert np.linalg.norm(z0 - target) > 0.6
    assert ends["at once"][0] > 0.3
    assert ends["rule"][0] < 1e-5 and ends["rule"][1] == 1


def test_the_n_dof_controllers_rule_targets_the_designs_orbit():
    """controller_values.model_capture_from_values: z** of the design's pulse (delay,
    width) in the law's coordinates X - X**, radius 5 sqrt(|Delta d|) at 0; off without
    capture; in sample mode, or with a bad radius, one line naming the parameter."""
    from grazing_control.dynamics.orbits.one_one import orbit
    from grazing_control.ros.controller_values import (model_capture_from_values,
                                                       model_controller_from_values)

    path, model, k = _chain_pulse()
    c = model_controller_from_values({"delta_d": -1e-3}, str(path), k.tolist())
    on = {"capture": True, "capture_radius": 0.0, "pi2_source": "stream"}
    rule = model_capture_from_values(on, c, 1.0, (1.0, math.inf, None))
    o = orbit(model, k, delay=1.0, width=1.0)
    np.testing.assert_array_equal(rule.target, o.state)
    np.testing.assert_allclose(o.physical - o.state, np.append(c.x_ref, c.v_ref), atol=1e-12)
    assert rule.radius == pytest.approx(5.0 * math.sqrt(1e-3))
    assert rule.forecast is None            # the chain's free motion comes back near z**
    assert model_capture_from_values({**on, "capture_radius": 0.2}, c, 1.0,
                                     (1.0, math.inf)).radius == 0.2
    assert model_capture_from_values({**on, "capture": False}, c, 1.0) is None
    with pytest.raises(ParameterError, match="capture=True is invalid with pi2_source=sample"):
        model_capture_from_values({**on, "pi2_source": "sample"}, c, 1.0)
    with pytest.raises(ParameterError, match="capture_radius=-1.0 is invalid: valid range"):
        model_capture_from_values({**on, "capture_radius": -1.0}, c, 1.0)


def test_an_n_dof_controller_holds_back_until_its_estimate_is_near_the_orbit():
    """Issue 32, in-process (the pattern of test_stream_block's n-DOF controller): a
    2-DOF controller_node with capture (radius 0: 5 sqrt(|Delta d|)) in stream mode, the
    chain's kick design at delay 1, fed the engine's stream from 10 uncontrolled periods
    off z** (0.25 away), the loop closed on its answers: from the switch-on it answers 0
    while its estimate X^ - X** is farther than the radius from z**, latches at the first
    section within it (capture.on_at) and answers k^T z^ from there on."""
    import dataclasses

    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from grazing_control.dynamics.design.family import pulse_design
    from grazing_control.dynamics.maps.modal_map import ModalMap
    from grazing_control.dynamics.orbits.one_one import orbit
    from grazing_control.oscillator.ndof.model import load_model
    from grazing_control.plant.engine import Engine
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros import cdr, launcher
    from grazing_control.ros.controller_node import ControllerNode
    from sim_node.messages import joint_names, ndof_joint_state
    from test_closed_loop import new_domain

    chain, delay, rate, periods, on = (launcher.CONFIG_DIR / "models" / "two_mass_chain.yaml",
                                       1.0, 50, 30, 2)
    model = dataclasses.replace(load_model(chain), delta_d=-1e-3)
    gains = pulse_design(model, -0.22, delay, 0.0).gains
    target = orbit(model, gains, delay=delay).state
    sim = {"delta_d": -1e-3, "actuation_delay": delay, "sensor_noise": 1e-4,
           "sensor_velocity": True, "sensor_seed": 7, "state_period": model.period / rate}
    eng = Engine(settings_from_values(sim, str(chain)))
    z = target.copy()
    for _ in range(10):
        z = ModalMap(model).step(z).state
    eng.z = z
    ctx = Context()
    rclpy.init(context=ctx, domain_id=new_domain())
    answers, estimates = {}, {}
    try:
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in (
                ("model_file", str(chain)), ("gains", gains.tolist()), ("delta_d", -1e-3),
                ("enable_after", on), ("actuation_delay", delay), ("pi2_source", "stream"),
                ("estimator", "model"), ("sensor_coordinate", 1), ("sensor_noise", 1e-4),
                ("state_period", model.period / rate), ("capture", True))])
        node.pub.publish = lambda data: answers.setdefault(
            *(lambda a: (a[:2], a[2]))(cdr.read_twist_stamped(data)))
        node.pub_estimate.publish = lambda m: estimates.setdefault(
            (m.header.stamp.sec, m.header.stamp.nanosec), np.append(m.position, m.velocity))
        names, states = joint_names(2), eng.initial_states()
        for k in range(periods):
            for ev in states:
                node._on_state(bytes(serialize_message(ndof_joint_state(ev, names))))
            key = cdr.stamp_parts(eng.sample().t)
            states = [ev for ev in eng.begin_period(answers.get(key, 0.0), delay)
                      if ev.kind == "state"]
            eng.end_period()
        on_at, radius = node.capture.on_at, node.capture.radius
        ref = np.append(node.ndof.x_ref, node.ndof.v_ref)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    keys = sorted(answers)
    assert len(keys) >= periods - 1 and on_at is not None and on_at > on, on_at
    far = [float(np.linalg.norm(estimates[key] - ref - target)) > radius for key in keys]
    first = far.index(False, on)                 # the first section within the radius
    assert first == on_at
    assert all(answers[key] == 0.0 for key in keys[:on_at])
    assert all(answers[key] != 0.0 for key in keys[on_at:])


def test_the_two_mass_beam_is_captured_only_if_switched_on_before_its_free_motion_leaves():
    """Issue 32, the rig config/rigs/two_mass_beam.yaml in the core (its dimensionless model,
    the controller's design and pulse, the 20 N limit: |Delta v| <= 0.316; Delta d = -1e-4,
    radius 5 sqrt(|Delta d|) = 0.05, |z**| = 0.019): from the scene's start X** the free
    motion leaves the radius at period 2 and, after period 10, stays at least 0.8 (16
    radii) from z** (a period-16 motion with one or two impacts per period). Switched on
    at period 1 the law captures; at period 100 (the scene's late switch-on) the law at once
    ends far from z**, and the rule never switches on and says so after 100 sections; the
    forecast (free_approach, what the controller logs at its start) says it beforehand.
    docs/theory_capture.md, "The two-mass beam after a late switch-on"."""
    from grazing_control.dynamics.maps.modal_map import ModalMap, pulse_step
    from grazing_control.dynamics.orbits.one_one import orbit
    from grazing_control.plant.rig import load_rig
    from grazing_control.ros import launcher
    from grazing_control.ros.rig_boundary import masses_controller_values

    rig = load_rig(launcher.CONFIG_DIR / "rigs" / "two_mass_beam.yaml")
    model, v = rig.model(), masses_controller_values(rig, math.nan)
    k, delay, width = np.array(v["gains"]), v["actuation_delay"], v["pulse_width"]
    target = orbit(model, k, delay=delay, width=width).state
    rule = CaptureRule.for_wall(target, model.delta_d)
    assert rule.radius == pytest.approx(0.05)
    free, cm = ModalMap(model), ModalMap(model, k, delay, width)
    trail = [np.zeros(4)]
    for _ in range(400):
        trail.append(free.step(trail[-1]).state)
    dist = [float(np.linalg.norm(z - target)) for z in trail]
    assert dist[1] < rule.radius < dist[2]
    assert min(dist[10:]) > 0.8
    forecast = free_approach(lambda z: free.step(z).state, target, rule.radius)
    assert forecast.left == 2 and forecast.closest > 0.8 and "at period 2" in forecast.warning()

    def closed(z, periods, switch=None):
        for j in range(periods):
            factor = 1.0 if switch is None else switch(j, _est(z, np.eye(4)))
            z = pulse_step(cm.flow, z, factor * float(k @ z), start=cm.pulse_start,
                           width=width, force_limit=v["force_limit"]).state
        return float(np.linalg.norm(z - target))

    assert closed(trail[1], 60) < 1e-9
    assert closed(trail[100], 100) > 0.5
    assert closed(trail[100], 100, rule) > 0.5 and rule.on_at is None
    assert rule.held == 100 and rule.closest > 0.8
    assert rule.news(99)[0] == "warning"

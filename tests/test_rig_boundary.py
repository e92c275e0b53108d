"""The nodes' rig boundary (grazing_control/ros/rig_boundary.py): SI and the rig clock
against the model's units and time, checked against plant.rig's own conversions."""

import math
from pathlib import Path

import pytest

from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.rig import load_rig, rig_from_dict, rig_to_dict
from grazing_control.ros.rig_boundary import (SIM_KEYS, DelayLine, Pacer, Sections,
                                              SimulatedClock, check_rig_values,
                                              controller_values, correction_of,
                                              first_section, force_of, sim_values)

RIG = Path(__file__).resolve().parents[1] / "config" / "rigs" / "acceptance.yaml"
TWO_PI = 2.0 * math.pi


@pytest.fixture(scope="module")
def rig():
    return load_rig(RIG)


def test_the_simulator_gets_the_rigs_dimensionless_model_and_physical_speed(rig):
    values = sim_values(rig)
    d, p = rig.dimensionless(), rig.params()
    assert set(values) == set(SIM_KEYS)
    assert values["time_scale"] == rig.omega_n == d["time_scale"]
    assert (values["delta_d"], values["omega"]) == (p.delta_d, p.omega)
    assert values["actuation_delay"] == rig.budget * rig.omega_n
    assert values["sensor_velocity"] is False
    # a drift of the rig clock is a slower (or faster) pace of the simulation
    assert sim_values(rig, 1e-4)["time_scale"] == rig.omega_n / (1.0 + 1e-4)


def test_what_the_simulator_does_not_model_is_refused_naming_the_field(rig):
    doc = rig_to_dict(rig)
    doc["actuator"]["latency"] = "1 ms"
    with pytest.raises(ParameterError, match=r"^actuator\.latency=0\.001 s is not simulated"):
        sim_values(rig_from_dict(doc))
    doc = rig_to_dict(rig)
    doc["sensor"].update(measures="position_velocity", velocity_noise="1 mm/s")
    with pytest.raises(ParameterError, match=r"^sensor\.velocity_noise="):
        sim_values(rig_from_dict(doc))


def test_a_force_pulse_carries_the_correction_as_its_impulse(rig):
    # F w = m Delta v = m omega_n l Delta v~ (plant.rig.Rig.correction_si)
    dv = 3.7e-4
    f = force_of(rig, dv)
    assert f == pytest.approx(rig.correction_si(dv)["force_N"], rel=1e-15)
    assert correction_of(rig, f, rig.actuator.pulse_width) == pytest.approx(dv, rel=1e-15)
    # the same impulse over twice the width is half the force
    assert correction_of(rig, f / 2.0, 2.0 * rig.actuator.pulse_width) == pytest.approx(dv)


def test_the_simulated_clock_starts_on_a_section_and_keeps_the_forcing_phase(rig):
    p = rig.params()
    clock = SimulatedClock(rig, 1000.0, rig.omega_n / (1.0 + 5e-5))
    assert 1000.0 <= clock.start < 1000.0 + rig.forcing_period
    assert clock.drift == pytest.approx(5e-5, rel=1e-9)
    for k in (0, 1, 17):           # every section's phase is tau2
        s = clock.rig_time(k * p.period)
        assert math.remainder(clock.phase(s) - p.tau2, TWO_PI) == pytest.approx(0.0, abs=1e-9)
        assert clock.model_time(s) == pytest.approx(k * p.period, abs=1e-9)
    # with the clock at 0 the sections are plant.rig's own (Rig.rig_time)
    assert first_section(rig, 0.0) == pytest.approx(rig.rig_time(0.0), abs=1e-12)
    clock.started(ros_now=5000.0, model_now=2.0)
    assert clock.offset + (1.0 + clock.drift) * clock.rig_time(2.0) == pytest.approx(5000.0)


def test_the_controller_finds_the_sections_from_the_phase_reference(rig):
    p = rig.params()
    clock = SimulatedClock(rig, 1000.0, rig.omega_n)
    t_ref = clock.start + 0.3 * rig.forcing_period     # a reference between sections
    sections = Sections(rig)
    assert sections.reference(t_ref, rig.frequency, clock.phase(t_ref))
    # its first section is the simulated clock's next one after the reference
    assert sections.origin == pytest.approx(clock.start + rig.forcing_period, abs=1e-9)
    assert sections.model_time(sections.rig_time(3 * p.period)) == pytest.approx(3 * p.period)
    assert sections.apply_time(10.0) == 10.0 + rig.budget - rig.actuator.pulse_width / 2.0
    # a later reference on the same forcing agrees; another phase or frequency does not
    later = t_ref + 7.25 * rig.forcing_period
    assert sections.reference(later, rig.frequency, clock.phase(later))
    assert not sections.reference(later, rig.frequency, clock.phase(later) + 1e-4)
    assert not sections.reference(later, rig.frequency * 1.001, clock.phase(later))
    assert not sections.reference(math.nan, rig.frequency, 0.0)
    # a reference stamped on a section (its phase tau2 up to rounding) is that section
    on = Sections(rig)
    on.reference(clock.start, rig.frequency, math.nextafter(p.tau2 % TWO_PI, 0.0))
    assert on.origin == clock.start


def test_the_sensor_latency_holds_each_sample_until_its_time_plus_the_latency():
    line = DelayLine(0.5)
    for t in (0.0, 0.2, 0.4):
        line.push(t, t)
    assert line.due(0.49) == [] and line.next_time() == 0.5
    assert line.due(0.7) == [0.0, 0.2]
    assert line.due(10.0) == [0.4] and line.next_time() == math.inf


def test_a_one_mass_rigs_controller_design_imports_no_solver():
    """The controller's values of the shipped one-mass rig (c1 by Eq. 38 for a given c2)
    load neither scipy.optimize nor scipy.integrate: a node imports no solver it does not
    use (tests/test_node_common.py; the rig controller did, through the design's module
    of orbits)."""
    from loaded_modules import loaded

    code = ("from grazing_control.plant.rig import load_rig; "
            "from grazing_control.ros.rig_boundary import controller_values; "
            f"controller_values(load_rig({str(RIG)!r}), 0.03)")
    assert loaded(code, ("scipy.optimize", "scipy.integrate")) == []


def test_the_controller_designs_for_the_budget_and_refuses_other_values(rig):
    from grazing_control.dynamics.design.gains import degenerate_c1

    values = controller_values(rig, 0.03)
    p = rig.params()
    assert values["actuation_delay"] == rig.budget * rig.omega_n
    assert values["c1"] == degenerate_c1(p, 0.03, values["actuation_delay"])
    assert values["pi2_source"] == "stream" and values["answer_after_section"] is False
    check_rig_values("r.yaml", values, dict(values, x_ref=math.nan))
    with pytest.raises(ParameterError, match=r"^delta_d=0\.0 is invalid with rig_file=r\.yaml"):
        check_rig_values("r.yaml", values, dict(values, delta_d=0.0))
    check_rig_values("r.yaml", {"time_scale": 1.0}, {"time_scale": 2.0}, free=("time_scale",))


def test_the_pacer_keeps_the_rate_from_many_callers_without_bursts():
    """rig/clock pairs asked from a 20 Hz timer and a loop waking every 0.7-3 ms with
    stalls of up to 0.4 s (seeded): on average one pair per period over 60 s, never two
    within half a period, the first at once, and a pair not taken stays due."""
    import random

    rng = random.Random(27)
    pace = Pacer(0.05)
    assert pace.due(0.0)
    times, wall, stalled = [], 0.0, 0.0
    while wall < 60.0:
        step = rng.choice([rng.uniform(7e-4, 3e-3)] * 400 + [rng.uniform(0.05, 0.4)])
        stalled += step if step >= 0.05 else 0.0
        wall += step
        if pace.due(wall):
            times.append(wall)
            pace.done(wall)
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert min(gaps) >= 0.025
    # the time awake at the full rate (a stall of s costs at most s / period pairs)
    assert 0.97 * (wall - stalled) / 0.05 <= len(times) <= wall / 0.05 + 1
    late = Pacer(0.05)
    late.done(1.0)                       # a pair at 1.0 s
    assert not late.due(1.02) and late.due(1.025)
    assert late.due(1.03) and late.due(1.03)     # not taken (no done): still due

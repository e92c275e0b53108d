"""The simulator's plant through a first-order actuator (grazing_control.plant.engine,
``actuator_bandwidth`` / ``actuator_latency``; issue 29 section 4): each period against
an independent integration (DOP853 of (x, v, f), tests/reference_actuator.py) over
seeded cases, impacts while the force's transient decays among them; the period map of
dynamics.simulation.actuator bit for bit; the parameters' errors.
"""

import math

import numpy as np
import pytest

from grazing_control.dynamics.simulation.actuation import pulse_force, pulse_start
from grazing_control.dynamics.simulation.actuator import actuated_step
from grazing_control.oscillator.flow import to_physical
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

from reference_actuator import lag_reference, pulse_pieces

P = OscillatorParams(delta_d=-5e-6)
DELAY, W = 3.0, 0.1


def seeded_case(seed: int) -> dict:
    """A period from near X** with a correction through a random actuator: bandwidth
    0.5x..30x the forcing frequency, latency 0..0.5, a pulse of width 0..0.2 (0: an
    impulse) centred at 2.5..3.5, a force left from the period before."""
    rng = np.random.default_rng(seed)
    width = float(rng.choice([0.0, rng.uniform(0.02, 0.2)]))
    return {"bandwidth": P.omega * float(np.exp(rng.uniform(math.log(0.5), math.log(30)))),
            "latency": float(rng.choice([0.0, rng.uniform(0.0, 0.5)])),
            "width": width, "delay": float(rng.uniform(2.5, 3.5)),
            "dz": rng.normal(0.0, 2e-3, 2), "force": float(rng.normal(0.0, 2e-5)),
            "dv": float(rng.normal(0.0, 5e-3))}


def engine_for(case, state_period=0.0):
    s = settings_from_values({"delta_d": P.delta_d, "pulse_width": case["width"],
                              "actuation_delay": case["delay"],
                              "actuator_bandwidth": case["bandwidth"],
                              "actuator_latency": case["latency"],
                              "state_period": state_period})
    e = Engine(s)
    e.dx, e.dv = P.x_ref - P.x_ref + case["dz"][0], case["dz"][1]
    e.force = case["force"]
    return e


def run_case(case, state_period, max_step=0.05):
    """The engine's period and the reference's: (events, end deviation and force) and
    (end (x, v, f), impacts, dense states at the engine's state times)."""
    e = engine_for(case, state_period)
    dx, dv, f0 = e.dx, e.dv, e.force
    events = e.begin_period(case["dv"], case["delay"])
    e.end_period()
    s = e.settings
    on = pulse_start(P.period, case["delay"], case["width"]) + case["latency"]
    u = (pulse_force(case["dv"], case["width"], math.inf) if case["width"] > 0.0
         else case["dv"])
    states = [ev for ev in events if ev.kind == "state"]
    x0, v0 = to_physical(P, P.tau2, dx, dv)
    ref = lag_reference(P, x0, v0, f0, pulse_pieces(on, case["width"], u,
                                                    s.actuator.time_constant),
                        P.period, [ev.t for ev in states], max_step)
    return e, events, states, ref


def test_a_period_through_the_actuator_matches_an_ode_solver_over_seeded_cases():
    """60 seeded cases (benchmarks/bench_actuator_reference.py runs thousands): impact
    times and velocities, the state stream's samples (x, v) and the next sample's
    (x, v, f) agree with DOP853 at rtol 1e-13 to 1e-8; at least a tenth of the cases
    have an impact while the force's transient is above 1 % of its pulse."""
    transient = 0
    for seed in range(60):
        case = seeded_case(seed)
        e, events, states, (end, ref_imps, dense) = run_case(case, P.period / 40)
        imps = [ev for ev in events if ev.kind == "impact"]
        assert len(imps) == len(ref_imps), seed
        assert np.allclose([ev.t for ev in imps], [t for t, _ in ref_imps], rtol=0,
                           atol=1e-8), seed
        assert np.allclose([ev.x for ev in imps], [v for _, v in ref_imps], rtol=0,
                           atol=1e-8), seed
        assert np.allclose([(ev.x, ev.v) for ev in states], dense, rtol=0, atol=1e-8), seed
        x1, v1 = to_physical(P, P.tau2, e.dx, e.dv)
        assert np.allclose([x1, v1, e.force], end, rtol=0, atol=1e-8), seed
        tau_a = e.settings.actuator.time_constant
        off = (pulse_start(P.period, case["delay"], case["width"]) + case["latency"]
               + case["width"])
        transient += any(0.0 < ev.t - off < tau_a * math.log(100.0) for ev in imps)
    assert transient >= 6


def test_the_plant_runs_the_actuated_period_map_bit_for_bit():
    """Ten periods of the engine are ``dynamics.simulation.actuator.actuated_step``'s, state and
    force carried from period to period, exactly."""
    case = seeded_case(3) | {"width": W, "delay": DELAY, "latency": 0.2,
                             "bandwidth": 3.0 * P.omega, "force": 0.0}
    e = engine_for(case)
    z = (e.dx, e.dv, 0.0)
    for k in range(10):
        dv = -0.02 - 1e-3 * k
        e.begin_period(dv, DELAY)
        e.end_period()
        x, v, f, _ = actuated_step(P, *z, dv, start=pulse_start(P.period, DELAY, W), width=W,
                                   actuator=e.settings.actuator)
        z = (x, v, f)
        assert (e.dx, e.dv) == (x, v)
        assert e.force == pytest.approx(f, rel=1e-14, abs=1e-20)


def test_realtime_actuation_reintegrates_the_same_period():
    """Realtime: the uncorrected period (begin_period(0)), then the scheduled command
    (actuate) from its start: the events after it and the next sample are lockstep's."""
    case = seeded_case(5) | {"width": W, "delay": DELAY, "bandwidth": 10.0 * P.omega}
    a, b = engine_for(case, P.period / 50), engine_for(case, P.period / 50)
    lock = a.begin_period(-0.03, DELAY)
    a.end_period()
    b.begin_period(0.0)
    start = b.t + b.actuation_start(DELAY)
    real = b.actuate(-0.03, DELAY)
    b.end_period()
    assert real == [ev for ev in lock if ev.t >= start]
    assert (b.dx, b.dv, b.force) == (a.dx, a.dv, a.force)


def test_without_an_actuator_the_force_stays_zero():
    e = engine_for({"width": W, "delay": DELAY, "bandwidth": 0.0, "latency": 0.0,
                    "dz": (1e-3, 0.0), "force": 0.0})
    assert not e.lagged
    e.begin_period(-0.01, DELAY)
    e.end_period()
    assert e.force == 0.0


@pytest.mark.parametrize("values, match", [
    ({"actuator_bandwidth": -1.0}, r"^actuator_bandwidth=-1.0 is invalid: valid range is "
                                   r"0 <= actuator_bandwidth <= 1e12"),
    ({"actuator_bandwidth": 2e12}, "^actuator_bandwidth=2000000000000.0 is invalid"),
    ({"actuator_bandwidth": math.inf}, "^actuator_bandwidth=inf is invalid"),
    ({"actuator_bandwidth": 5e-324}, "^actuator_bandwidth=5e-324 is invalid: valid range "
                                     "is 0 or >= 1 / the largest double"),
    ({"actuator_latency": math.nan}, "^actuator_latency=nan is invalid"),
    ({"actuator_latency": 7.0, "actuation_delay": 3.0, "pulse_width": 0.1},
     r"^actuator_latency=7.0 is invalid with actuation_delay=3.0 and pulse_width=0.1: "
     r"valid range is actuation_delay \+ pulse_width / 2 \+ actuator_latency < T"),
    ({"actuator_bandwidth": 2.0, "fidelity": "zdm2"},
     "^actuator_bandwidth=2.0 is invalid with fidelity='zdm2': valid there is 0"),
    ({"actuator_latency": 0.1, "mode": "realtime", "actuation": "on_arrival"},
     "^actuator_latency=0.1 is invalid with actuation=on_arrival: valid there is 0"),
])
def test_a_bad_actuator_is_refused_in_one_line_naming_it(values, match):
    with pytest.raises(ParameterError, match=match) as err:
        settings_from_values(values)
    assert "\n" not in str(err.value)

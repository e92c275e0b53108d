"""plant.watchdog: the realtime watchdog's four checks, driven by hand (no clock, no ROS).

The misses in the sliding window are checked against a brute-force count over seeded
random miss patterns; pace, lag and excursion against the numbers they are defined by
(issue 27 §1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.settings import PARAMETERS, settings_from_values
from grazing_control.plant.watchdog import Watchdog, WatchdogLimits, excursion_scale

OFF = dict(misses=0, pace=0.0, lag=0.0, excursion=0.0)


def first_trip_brute_force(missed: np.ndarray, window: int, limit: int):
    """The first k with sum(missed[k - window + 1 .. k]) >= limit, else None."""
    for k in range(missed.size):
        if missed[max(0, k - window + 1):k + 1].sum() >= limit:
            return k
    return None


@pytest.mark.parametrize("seed", range(40))
def test_misses_in_the_window_trip_where_a_brute_force_count_does(seed):
    rng = np.random.default_rng(seed)
    window = int(rng.integers(1, 60))
    limit = int(rng.integers(1, window + 1))
    p = float(rng.uniform(0.05, 0.6))
    missed = rng.random(int(rng.integers(50, 400))) < p
    dog = Watchdog(WatchdogLimits(window=window, **{**OFF, "misses": limit}))
    trips = []
    for k, m in enumerate(missed):
        expected = int(missed[max(0, k - window + 1):k + 1].sum())
        trip = dog.outcome(k, bool(m), acting=True)
        if trip is not None:
            trips.append(trip)
        if not trips:
            assert dog.misses_in_window == expected, (k, window)
    want = first_trip_brute_force(missed, window, limit)
    if want is None:
        assert not trips and dog.tripped is None
    else:
        assert len(trips) == 1 and trips[0].k == want and trips[0].kind == "misses"
        assert f"{limit} of the last {window} samples" in trips[0].reason or \
            f"of the last {window} samples" in trips[0].reason


def test_a_trip_is_final_and_misses_off_never_trips():
    dog = Watchdog(WatchdogLimits(window=4, **{**OFF, "misses": 2}))
    assert dog.outcome(0, True) is None
    trip = dog.outcome(1, True)
    assert trip.kind == "misses" and trip.k == 1
    assert dog.outcome(2, True) is None and dog.tripped is trip
    dog.reset()
    assert dog.tripped is trip                            # a reset keeps the trip
    off = Watchdog(WatchdogLimits(window=4, **OFF))
    assert all(off.outcome(k, True) is None for k in range(100))


def run_samples(dog, n, period, time_scale, wall_per_period, lag=lambda k: 0.0):
    for k in range(n):
        trip = dog.sample(k, k * period, 100.0 + k * wall_per_period, lag(k), time_scale)
        if trip is not None:
            return trip
    return None


def test_pace_is_simulated_time_over_wall_time_and_time_scale():
    T, scale, w = 9.4, 1000.0, 10
    lim = WatchdogLimits(window=w, **{**OFF, "pace": 0.5})
    # exactly on pace, and at 0.51 of it: no trip
    assert run_samples(Watchdog(lim), 200, T, scale, T / scale) is None
    assert run_samples(Watchdog(lim), 200, T, scale, T / scale / 0.51) is None
    # at 0.4 of the pace: trips at the first full window (sample w), with the numbers
    trip = run_samples(Watchdog(lim), 200, T, scale, T / scale / 0.4)
    assert trip.kind == "pace" and trip.k == w and trip.t == w * T
    assert "pace 0.4 of time_scale 1000 over samples 0..10" in trip.reason
    assert "42.6 periods per wall second" in trip.reason      # 0.4 * 1000 / 9.4


def test_a_new_time_scale_starts_a_new_pace_window():
    T, w = 9.4, 10
    dog = Watchdog(WatchdogLimits(window=w, **{**OFF, "pace": 0.5}))
    wall = 100.0
    for k in range(25):          # 1000 for 15 samples, then 2000 at the 1000 pace
        scale = 1000.0 if k < 15 else 2000.0
        assert dog.sample(k, k * T, wall, 0.0, scale) is None or k >= 15 + w
        wall += T / 1000.0
    dog2 = Watchdog(WatchdogLimits(window=w, **{**OFF, "pace": 0.5}))
    wall = 100.0
    trips = []
    for k in range(40):
        scale = 1000.0 if k < 15 else 2000.0
        trips.append(dog2.sample(k, k * T, wall, 0.0, scale))
        wall += T / 1000.0 / (0.4 if k >= 15 else 1.0)   # the new scale at 0.2 of it
    first = next(t for t in trips if t is not None)
    assert first.k == 15 + w                                 # a full window at the new scale


def test_lag_trips_on_the_first_late_sample():
    dog = Watchdog(WatchdogLimits(window=5, **{**OFF, "lag": 0.25}))
    trip = run_samples(dog, 50, 9.4, 1000.0, 9.4e-3, lag=lambda k: 0.01 * k)
    assert trip.kind == "lag" and trip.k == 26                # 0.26 > 0.25
    assert "went out 0.26 s after its simulation time" in trip.reason


def test_excursion_only_while_corrections_act_past_the_window():
    w, scale = 5, 1e-3
    dog = Watchdog(WatchdogLimits(window=w, **{**OFF, "excursion": 10.0}), scale)
    far = (0.02, 0.0)                                         # 20 D11
    for k in range(3 * w):                                    # open loop: not checked
        assert dog.sample(k, k, 0.0, 0.0, 1.0, far) is None
        dog.outcome(k, False, acting=False)
    for k in range(3 * w, 4 * w):                             # capture transient
        assert dog.sample(k, k, 0.0, 0.0, 1.0, far) is None
        dog.outcome(k, False, acting=True)
    assert dog.sample(4 * w, 0.0, 0.0, 0.0, 1.0, (0.006, 0.008)) is None   # 10 D11 exactly
    dog.outcome(4 * w, False, acting=True)
    trip = dog.sample(4 * w + 1, 0.0, 0.0, 0.0, 1.0, (0.006, 0.0081))
    assert trip.kind == "excursion" and "beyond 10 sqrt(|Delta d|) = 0.01" in trip.reason
    # a miss disarms it for a window again
    dog2 = Watchdog(WatchdogLimits(window=w, **{**OFF, "excursion": 10.0}), scale)
    for k in range(w):
        dog2.outcome(k, False, acting=True)
    dog2.outcome(w, True)
    assert dog2.sample(w + 1, 0.0, 0.0, 0.0, 1.0, far) is None


def test_the_excursion_scale_is_the_square_root_of_the_clearance():
    assert excursion_scale(OscillatorParams(delta_d=-4e-6)) == pytest.approx(2e-3, rel=1e-15)
    assert excursion_scale(OscillatorParams(delta_d=1e-6)) is None
    assert excursion_scale(OscillatorParams(delta_d=0.0)) is None


def test_the_default_bound_holds_the_controlled_orbits_and_not_the_chaotic_motion():
    """The module docstring's numbers: the rig's least-noise design (delay 3) holds its
    orbit within the bound at Delta d = -5e-6 and -1e-7 once past the window; the
    uncontrolled motion at -5e-6 goes beyond it."""
    from grazing_control.dynamics.simulation.simulate import simulate
    from grazing_control.oscillator.control import Gains

    lim = WatchdogLimits()
    rig = Gains(0.006031909726621269, -0.0060746847760492625, 3.0)
    for dd in (-5e-6, -1e-7):
        p = OscillatorParams(delta_d=dd)
        r = simulate(p, 700, gains=rig, control_after=0)
        dist = np.hypot(*r.pi2_deviation[lim.window:].T) / excursion_scale(p)
        assert dist.max() < lim.excursion / 2, dd
    p = OscillatorParams(delta_d=-5e-6)
    free = np.hypot(*simulate(p, 1500).pi2_deviation[200:].T) / excursion_scale(p)
    assert free.max() > lim.excursion


def test_the_thresholds_are_parameters_with_their_ranges():
    names = {p.name: p for p in PARAMETERS}
    for name in ("watchdog_window", "watchdog_misses", "watchdog_pace", "watchdog_lag",
                 "watchdog_excursion", "feasibility"):
        assert names[name].read_only and names[name].doc
    s = settings_from_values({"watchdog_window": 20, "watchdog_misses": 5,
                              "watchdog_pace": 0.0, "watchdog_lag": 2.5,
                              "watchdog_excursion": 4.0})
    assert s.watchdog == WatchdogLimits(20, 5, 0.0, 2.5, 4.0)
    # each range end of the descriptor is accepted, one step beyond is refused
    for name in ("watchdog_window", "watchdog_misses", "watchdog_pace", "watchdog_lag",
                 "watchdog_excursion"):
        p = names[name]
        for end in (p.lo, p.hi):
            if end is not None:
                settings_from_values({name: type(p.default)(end)})
        beyond = (p.lo - 1 if p.kind == "integer" else math.nextafter(p.lo, -1.0))
        with pytest.raises(ParameterError, match=name):
            settings_from_values({name: beyond})
    with pytest.raises(ParameterError, match="watchdog_pace"):
        settings_from_values({"watchdog_pace": 1.5})
    with pytest.raises(ParameterError, match="feasibility"):
        settings_from_values({"feasibility": "maybe"})

"""Sampling Pi2 from a sensor stream (grazing_control.dynamics.estimation.stream).

The bookkeeping (which samples make which section, when an estimate is due, lost
samples, a reset), then the closed loop on a position-only stream at 200 samples per
period and sigma = 1e-4 (issue 15's measurement): the nearest sample does not suppress
the instability, the arc fit holds the orbit to ~1e-3, the model filter to ~1e-5; the
model's reported covariance is checked against the errors of seeded runs (normalised
errors and coverage) and the design helper's prediction against the simulated spread.
"""

import math

import numpy as np
import pytest

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.estimation.section_state import estimate_covariance
from grazing_control.dynamics.design.noise import noise_gain
from grazing_control.dynamics.orbits.orbits import orbit_11
from grazing_control.dynamics.estimation.stream import StreamEstimator, simulate_stream
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.sensor import SensorModel

P = OscillatorParams(delta_d=-5e-6)


def _gains(p, c2, delay=0.0):
    return Gains(degenerate_c1(p, c2, delay), c2, delay)


def _xv(p, t, z=(0.0, 0.0)):
    """A physical state of the free motion (no impact) with deviation z at t = 0."""
    from grazing_control.dynamics.estimation.motion import phi_rows
    dev = phi_rows(p.zeta, np.atleast_1d(t)) @ np.array(z)
    psi = p.tau2 + p.omega * np.atleast_1d(t) - p.lag
    return (p.amplitude * np.cos(psi) + dev[:, 0], -p.amplitude * p.omega * np.sin(psi)
            + dev[:, 1])


def test_a_section_is_due_with_its_last_sample_and_late_when_that_sample_is_lost():
    p = OscillatorParams(delta_d=0.1)        # far from the wall: no impacts
    est = StreamEstimator(p, "arc", 1e-6, "stream", p.period / 10)
    t = np.arange(0, 32) * p.period / 10
    x, v = _xv(p, t)
    due = [est.add_sample(ti, xi, math.nan) for ti, xi in zip(t[:21], x[:21])]
    # due with the sample before t_k: the sample at t_k itself is not waited for
    assert [len(d) for d in due] == [1] + [0] * 8 + [1] + [0] * 9 + [1, 0]
    assert [d[0][0] for d in due if d] == [0, 1, 2]
    # the samples before and at t_3 are lost: section 3 comes with the first one after it
    for ti, xi in zip(t[21:29], x[21:29]):
        assert est.add_sample(ti, xi) == []
    late = est.add_sample(t[31], x[31])
    assert [d[0] for d in late] == [3]
    # an estimate of a sampled free motion is the motion's deviation (0, 0)
    assert np.allclose(late[0][2].z, (0.0, 0.0), atol=1e-9)
    # back to t = 0: the simulator was reset, the count starts again
    assert [d[0] for d in est.add_sample(0.0, x[0])] == [0]


def test_the_sample_period_is_taken_from_the_stamps_when_not_given():
    p = OscillatorParams(delta_d=0.1)
    est = StreamEstimator(p, "nearest", 0.0, "stream", 0.0)
    t = np.arange(0, 12) * p.period / 5
    x, v = _xv(p, t)
    ks = [d[0] for ti, xi, vi in zip(t, x, v) for d in est.add_sample(ti, xi, vi)]
    assert ks == [0, 1, 2]


@pytest.mark.parametrize("kwargs, match", [
    ({"estimator": "kalman"}, "estimator='kalman'"),
    ({"impact_source": "radar"}, "impact_source='radar'"),
    ({"sigma": 0.0}, "sensor_noise=0.0"),
    ({"sigma": math.nan}, "sensor_noise=nan"),
    ({"sample_period": -1.0}, "state_period=-1.0"),
    ({"sample_period": 100.0}, "state_period=100.0"),
])
def test_bad_settings_are_refused_naming_the_parameter(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        StreamEstimator(P, **kwargs)


def _run(estimator, c2=-0.3, sigma=1e-4, periods=600, seed=3, impact_source="stream",
         delta_d=-5e-6, rate=200, velocity=False):
    p = OscillatorParams(delta_d=delta_d)
    g = _gains(p, c2)
    z = orbit_11(p, g).pi2_deviation
    sensor = SensorModel(noise=sigma, velocity=velocity, seed=seed)
    run = simulate_stream(p, g, sensor.measure, periods, rate, estimator=estimator,
                          sigma=sigma, impact_source=impact_source, deviation=z)
    last = slice(periods // 3, None)
    return (run, float(np.std(run.truth[last, 0] - z[0])),
            float(np.mean(run.impacts_per_period[last] == 1)), p, g)


def test_the_model_filter_beats_the_arc_fit_which_beats_the_nearest_sample():
    """Issue 15's measurement (c2 = -0.3, position only, 200 samples per period,
    sigma = 1e-4): nearest ~8e-3 (the issue's 2e-2 and impacts lost with other draws);
    arc fit ~1e-3; model ~1.4e-5, one impact in every period."""
    _r, nearest, _one, *_ = _run("nearest")
    _r, arc, a_one, *_ = _run("arc")
    _r, model, m_one, *_ = _run("model")
    assert nearest > 5e-3
    assert 3e-4 < arc < 3e-3 and a_one >= 0.99
    assert model < 2e-5 and m_one == 1.0


@pytest.mark.parametrize("impact_source", ["topic", "stream"])
def test_the_arc_fit_predicted_spread_matches_the_simulated_one(impact_source):
    """The arc fit's errors are independent from period to period: the noise gain with
    its covariance as the measurement covariance predicts the spread (within 20 %)."""
    run, spread, one, p, g = _run("arc", impact_source=impact_source, periods=900)
    predicted = noise_gain(p, g, estimate_covariance(p, g, 200, estimator="arc")) * 1e-4
    assert abs(spread / predicted - 1.0) < 0.2 and one >= 0.99


@pytest.mark.parametrize("c2, velocity", [(-0.3, False), (-1.0, False), (0.007, True)])
def test_the_model_covariance_is_that_of_its_errors(c2, velocity):
    """4 seeds x 250 periods. The model carries information across periods, so its
    errors lie along the direction its data leave least determined, P's major axis:
    the error along it, normalised by sqrt(lambda_max), has unit variance (within
    15 %). Across the minor axis P holds the floor (modelled process noise, absent in
    the exact plant), so P is conservative there: the 95 % ellipse covers >= 95 % of
    the errors. The design's stationary covariance is the reported one (10 %)."""
    along, chi2, covs = [], [], []
    for seed in range(4):
        run, _s, _o, p, g = _run("model", c2=c2, periods=300, seed=seed, velocity=velocity)
        e = (run.estimate - run.truth)[50:]
        cov = run.cov[50:]
        lam, vec = np.linalg.eigh(cov)
        along.append(np.einsum("ni,ni->n", e, vec[:, :, 1]) / np.sqrt(lam[:, 1]))
        chi2.append(np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e))
        covs.append(cov)
        assert run.resets == 0
    along, chi2 = np.concatenate(along), np.concatenate(chi2)
    assert abs(np.mean(along ** 2) - 1.0) < 0.15
    assert np.mean(chi2 < -2.0 * math.log(0.05)) >= 0.95
    design = estimate_covariance(p, g, 200, velocity=velocity) * 1e-8
    reported = np.concatenate(covs).mean(axis=0)
    assert np.allclose(np.diag(design), np.diag(reported), rtol=0.1)


def test_duplicates_older_samples_and_strays_are_not_used():
    """A repeated or older stamp is ignored (it must not make a section due early); a
    stamp far ahead is a stray unless the next sample follows it (a jump: restart
    there); a non-finite stamp is ignored."""
    p = OscillatorParams(delta_d=0.1)
    est = StreamEstimator(p, "arc", 1e-6, "stream", 0.0)
    t = np.arange(0, 25) * p.period / 10
    x, _v = _xv(p, t)
    ks = [d[0] for ti, xi in zip(t[:15], x[:15]) for d in est.add_sample(ti, xi)]
    assert ks == [0, 1]
    assert est.add_sample(t[14], x[14]) == [] and est.add_sample(t[12], x[12]) == []
    assert est.add_sample(math.nan, 0.0) == []
    assert est.add_sample(1e6, 0.0) == []              # a stray a million seconds ahead
    ks = [d[0] for ti, xi in zip(t[15:], x[15:]) for d in est.add_sample(ti, xi)]
    assert ks == [2] and est.ignored == 4
    far = 1000 * p.period + np.arange(0, 12) * p.period / 10
    xf, _ = _xv(p, far)
    ks = [d[0] for ti, xi in zip(far, xf) for d in est.add_sample(ti, xi)]
    assert ks == [1000, 1001]                          # confirmed by the next sample


def test_a_model_error_costs_the_model_filter_spread_but_not_the_orbit():
    """The estimator's model has zeta 1 % or 5 % below the plant's, or Delta d 10 % off:
    the model filter still keeps one impact in every period, with a spread that grows
    with the error (measured 5.1e-5, 2.4e-4, 4.2e-5) and stays below the arc fit's on the
    exact model (1.1e-3)."""
    model = OscillatorParams(delta_d=-5e-6)
    g = _gains(model, -0.3)
    for plant, bound in ((model.with_(zeta=0.0101), 1e-4), (model.with_(zeta=0.0105), 5e-4),
                         (model.with_(delta_d=-5.5e-6), 1e-4)):
        z = orbit_11(plant, g).pi2_deviation
        run = simulate_stream(plant, g, SensorModel(noise=1e-4, velocity=False, seed=3).measure,
                              600, 200, estimator="model", sigma=1e-4, deviation=z, model=model)
        spread = np.sqrt(np.mean((run.truth[200:, 0] - z[0]) ** 2))
        assert spread < bound and np.all(run.impacts_per_period[200:] == 1)


def test_after_section_makes_a_section_due_with_its_sample_at_t_k():
    """Realtime: section k is due with its last sample, the one at t_k (which the
    lockstep rule does not wait for); lost, with the first sample after t_k."""
    p = OscillatorParams(delta_d=0.1)
    t = np.arange(0, 22) * p.period / 10
    x, _v = _xv(p, t, (1e-3, -2e-3))
    before = StreamEstimator(p, "arc", 1e-6, "stream", p.period / 10)
    after = StreamEstimator(p, "arc", 1e-6, "stream", p.period / 10, after_section=True)
    b = [(j, d[0], d[2].z) for j, (ti, xi) in enumerate(zip(t, x)) for d in before.add_sample(ti, xi)]
    a = [(j, d[0], d[2].z) for j, (ti, xi) in enumerate(zip(t, x)) for d in after.add_sample(ti, xi)]
    assert [r[:2] for r in b] == [(0, 0), (9, 1), (19, 2)]
    assert [r[:2] for r in a] == [(0, 0), (10, 1), (20, 2)]
    assert np.allclose([r[2] for r in a[1:]], [r[2] for r in b[1:]], rtol=0, atol=1e-12)
    lost = StreamEstimator(p, "arc", 1e-6, "stream", p.period / 10, after_section=True)
    keep = [j for j in range(22) if j != 10]
    d = [(j, r[0]) for j in keep for r in lost.add_sample(t[j], x[j])]
    assert d == [(0, 0), (11, 1), (20, 2)]


def test_after_section_with_the_sample_at_t_k_estimates_as_with_the_sample_after_it():
    """Issue 30: answering with the sample at t_k instead of the first sample after it
    (which the estimate does not use; a simulator's wake-up later at T/200 x1000) gives
    the same estimates, covariances and filter resets bit for bit: the model filter over
    noisy samples at T/200 (stamps as the controller computes them), with corrections and
    a lost sample. The reference is the rule before (only a sample after t_k makes a
    section due: a negative sample period, which the constructor refuses, set here)."""
    p = OscillatorParams(delta_d=0.1)
    rng = np.random.default_rng(7)
    h = p.period / 200
    t = np.array([(lambda s: s[0] + s[1] * 1e-9)(divmod(round(j * h * 1e9), 10**9))
                  for j in range(200 * 12 + 1)])
    x, _v = _xv(p, t, (1e-3, -2e-3))
    x = x + rng.normal(0.0, 1e-4, x.size)
    new = StreamEstimator(p, "model", 1e-4, "stream", h, after_section=True,
                          pulse_width=0.1, kernel=False)
    old = StreamEstimator(p, "model", 1e-4, "stream", h, after_section=True,
                          pulse_width=0.1, kernel=False)
    old.sample_period = -1.0
    due = {"new": [], "old": []}
    for j in range(t.size):
        if j == 200 * 7:                     # lost: section 7 due with the next sample
            continue
        for name, est in (("new", new), ("old", old)):
            for k, tk, e in est.add_sample(t[j], x[j]):
                due[name].append((j, k, tk, tuple(e.z), e.cov.tobytes(), e.source))
                est.set_correction(k, 1e-5 * (k % 3), 3.0)
    assert [r[:2] for r in due["new"]] == [(200 * k + (k == 7), k) for k in range(13)]
    assert [r[0] for r in due["old"]] == [200 * k + 1 for k in range(12)]
    assert [r[1:] for r in due["new"][:12]] == [r[1:] for r in due["old"]]
    assert new.resets == old.resets and {r[-1] for r in due["new"][2:]} == {"model"}


def test_a_lead_makes_a_section_due_earlier_without_its_last_samples():
    """A realtime rig (issue 28): with lead 2.5 h section k is due with the sample at
    t_k - 3 h, and its estimate is the one of the samples up to there (the last ones are
    not used for it); a lead must lie in [0, T)."""
    p = OscillatorParams(delta_d=0.1)
    h = p.period / 10
    t = np.arange(0, 22) * h
    x, _v = _xv(p, t, (1e-3, -2e-3))
    early = StreamEstimator(p, "arc", 1e-6, "stream", h, lead=2.5 * h)
    cut = StreamEstimator(p, "arc", 1e-6, "stream", h)
    e = [(j, d[0], d[2].z) for j, (ti, xi) in enumerate(zip(t, x)) for d in early.add_sample(ti, xi)]
    assert [r[:2] for r in e] == [(0, 0), (7, 1), (17, 2)]
    # section 1 from samples 1..7 only: what an estimator that never got 8..10 says at t_1
    for ti, xi in zip(t[:8], x[:8]):
        cut.add_sample(ti, xi)
    (k, _tk, est), = cut.flush(1)[-1:]
    assert k == 1 and np.allclose(est.z, e[1][2], rtol=0, atol=1e-15)
    for lead in (-1e-9, p.period, math.nan):
        with pytest.raises(ParameterError, match="answer_lead"):
            StreamEstimator(p, "arc", 1e-6, "stream", h, lead=lead)
    # realtime (answer_after_section): lead 2.5 h before the sample at t_k, the sample
    # at t_k - 2 h (the lead was ignored there before issue 30)
    after = StreamEstimator(p, "arc", 1e-6, "stream", h, after_section=True, lead=2.5 * h)
    a = [(j, d[0]) for j, (ti, xi) in enumerate(zip(t, x)) for d in after.add_sample(ti, xi)]
    assert a == [(0, 0), (8, 1), (18, 2)]


def test_what_the_plant_reports_as_acted_replaces_the_answer():
    """A deadline miss (0) or a substituted prediction reported by the plant is the kick
    the filter integrates, before or after the controller's own late answer."""
    from grazing_control.dynamics.estimation.stream import StreamEstimator
    from grazing_control.oscillator.params import OscillatorParams

    s = StreamEstimator(OscillatorParams(delta_d=-5e-6), "model", 1e-4)
    s.set_correction(5, 1e-3, 2.0)
    s.acted(5, 0.0, 2.0)                   # the answer came too late: nothing acted
    assert s.kicks[5][1] == 0.0
    s.acted(6, 2e-4, 2.0)                  # the prediction acted, reported first ...
    s.set_correction(6, 3e-4, 2.0)         # ... then our late answer: ignored
    assert s.kicks[6] == (6 * s.p.period + 2.0, 2e-4)
    s.set_correction(7, 5e-4, 2.0)         # an answer in time stands
    assert s.kicks[7][1] == 5e-4


#: The time from the controlled orbit's impact to the next section at Delta d = -5e-6
#: (the exact flow: the impact falls 2.36 before t_k): an answer lead longer than it
#: leaves the impact after the last sample a section's estimate sees.
IMPACT_TO_SECTION = 2.358


@pytest.mark.parametrize("lead", [0.5, 2.95, 5.0])
def test_a_lead_past_the_impact_leaves_the_model_filter_running(lead):
    """An answer lead of 2.95 (a rig's budget - w/2 at delay 3) or 5 leaves the impact
    of every period between the last sample of a section's estimate and t_k. The arc
    fit that starts the model filter used to extrapolate the free flow through the
    wall there (errors ~2.5e-2, a reset at every section, every estimate an arc fit);
    carried through the impact by the exact flow it starts the filter, which then
    predicts through the impact itself: no reset, the errors those of the noise."""
    p = P
    g = _gains(p, -0.3, 3.0)
    z = orbit_11(p, g).pi2_deviation
    sensor = SensorModel(noise=1e-4, velocity=False, seed=5)
    est = StreamEstimator(p, "model", 1e-4, "stream", p.period / 200, lead=lead)
    run = simulate_stream(p, g, sensor.measure, 200, 200, deviation=z, stream_estimator=est)
    e = (run.estimate - run.truth)[20:]
    assert run.resets == 0
    assert np.sqrt(np.mean(e ** 2)) < 3e-5
    assert np.all(run.impacts_per_period[20:] == 1)
    # the arc that started the filter was carried through the impact (past it) or not
    assert (est.unseen_impacts > 0) == (lead > IMPACT_TO_SECTION)


def test_an_arc_carried_through_an_impact_no_sample_saw_is_the_exact_state():
    """Differential, 40 seeded random starts near the orbit: the samples of the exact
    motion (sigma 1e-9) up to 2.95 before t_1, the impact after the last of them; the
    arc estimator's state at t_1 is the exact flow's (trajectory's end) to 1e-7, where
    the arc's own free flow to t_1 is off by more than 1e-4 (through the wall)."""
    from grazing_control.dynamics.estimation.motion import trajectory
    from grazing_control.dynamics.estimation.section_state import arc_fit, deviation_samples

    p = P
    z_orbit = orbit_11(p, _gains(p, -0.3)).pi2_deviation
    rng = np.random.default_rng(11)
    h = p.period / 200
    lead = 2.95
    checked = 0
    for _ in range(40):
        z0 = np.array(z_orbit) + rng.normal(0.0, 2e-5, 2)
        s = np.arange(1, 201) * h                       # samples after t_0, up to t_1
        z, _jac, end, _m, imps = trajectory(p, z0, s)
        if not imps or not p.period - imps[-1][0] < lead:
            continue                                    # no impact in the lead's gap
        psi = p.tau2 + p.omega * s - p.lag
        x = p.amplitude * np.cos(psi) + z[:, 0]
        est = StreamEstimator(p, "arc", 1e-9, "stream", h, lead=lead)
        est.add_sample(0.0, p.amplitude * math.cos(p.tau2 - p.lag) + z0[0])
        due = [d for ti, xi in zip(s, x) for d in est.add_sample(ti, xi)]
        (k, _tk, e1), = [d for d in due if d[0] == 1]
        assert e1.source == "arc"
        assert np.allclose(e1.z, end, rtol=0.0, atol=1e-7)
        # the arc's free flow to t_1 from the same samples: through the wall
        seen = s + h + lead < p.period + 1e-9
        used = s[seen] - p.period
        y, w = deviation_samples(p, used, x[seen], np.full(used.size, np.nan),
                                 tau_start=p.tau2)
        after = used > imps[-2][0] - p.period if len(imps) > 1 else np.ones(used.size, bool)
        free = arc_fit(p, used[after], y[after], w[after], 1e-9)
        assert np.max(np.abs(np.array(free.z) - end)) > 1e-4
        checked += 1
    assert checked >= 20


def test_carry_is_the_trajectory_of_a_period():
    """:func:`carry` from the section over a period with the correction's kick at the
    delay is :func:`trajectory`'s end and monodromy (to rounding), over 30 seeded
    starts, impacting or not."""
    from grazing_control.dynamics.estimation.motion import carry, trajectory

    rng = np.random.default_rng(2)
    for _ in range(30):
        z0 = np.array(orbit_11(P, _gains(P, -0.3)).pi2_deviation) + rng.normal(0, 1e-3, 2)
        dv, delay = rng.normal(0, 1e-3), rng.uniform(0.1, 9.0)
        _z, _j, end, mono, imps = trajectory(P, z0, [], dv, delay)
        z, m, impacts = carry(P, z0, 0.0, P.period, [(delay, dv)])
        assert len(impacts) == len(imps)
        assert np.allclose(z, end, rtol=0.0, atol=1e-12)
        assert np.allclose(m, mono, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("lead", [0.0, 2.95])
def test_the_exact_plant_covariance_is_that_of_the_errors_on_an_exact_plant(lead):
    """E7': the floor-tuned filter's errors on a plant its model describes exactly, the
    least-noise gains at delay 3 with a 0.1 pulse, 3 seeds x 300 periods: their RMS per
    component within 15 % of the exact-plant covariance's. The reported covariance takes
    the floor as real process noise: close to it answering with the last sample (within
    10 %), several times it with a lead past the impact, where the floor is carried
    through an impact no sample sees ((E2''))."""
    p = P
    g = Gains(0.006031909726621269, -0.0060746847760492625, 3.0)
    z = orbit_11(p, g).pi2_deviation
    errors = []
    for seed in range(3):
        sensor = SensorModel(noise=1e-4, velocity=False, seed=seed)
        est = StreamEstimator(p, "model", 1e-4, "stream", p.period / 200, lead=lead,
                              pulse_width=0.1)
        run = simulate_stream(p, g, sensor.measure, 300, 200, deviation=z,
                              stream_estimator=est, pulse_width=0.1)
        assert run.resets == 0
        errors.append((run.estimate - run.truth)[50:])
    rms = np.sqrt(np.mean(np.concatenate(errors) ** 2, axis=0))
    exact = np.sqrt(np.diag(estimate_covariance(p, g, 200, lead=lead, width=0.1,
                                                exact_plant=True))) * 1e-4
    reported = np.sqrt(np.diag(estimate_covariance(p, g, 200, lead=lead, width=0.1))) * 1e-4
    assert np.allclose(rms, exact, rtol=0.15)
    if lead == 0.0:
        assert np.allclose(reported, exact, rtol=0.1)
    else:
        assert np.all(reported > 4.0 * exact)


def test_a_window_holds_exactly_the_kept_samples_in_its_interval():
    """The estimator's sample store against a plain list filtered by brute force: seeded
    random streams (irregular steps, drops of old samples, windows anywhere, the edges
    exact sample times)."""
    from grazing_control.dynamics.estimation.stream import _Samples

    rng = np.random.default_rng(5)
    for _ in range(100):
        store, kept, t = _Samples(), [], 0.0
        for _ in range(int(rng.integers(0, 1500))):
            t += float(rng.choice([1e-3, rng.exponential(0.05)]))
            x, v = float(rng.normal()), float(rng.choice([math.nan, rng.normal()]))
            store.append(t, x, v)
            kept.append((t, x, v))
            if rng.random() < 0.3:
                start = t - float(rng.exponential(2.0))
                store.drop_before(start)
                kept = [r for r in kept if not r[0] < start]
            if rng.random() < 0.05 and kept:
                edges = [r[0] for r in kept] + [t + 1.0, -1.0]
                since, until = sorted(float(rng.choice(edges)) for _ in range(2))
                want = [r for r in kept if since < r[0] <= until]
                got = store.between(since, until)
                np.testing.assert_array_equal(np.column_stack(got).reshape(-1, 3),
                                              np.array(want).reshape(-1, 3))
        assert bool(store) == bool(kept)
        assert store.t[store.first:] == [r[0] for r in kept]


def _hostile_stream(rng, p, rate, periods):
    """(t, x, v) of a seeded stream at T/rate with what a sensor and a network do to it:
    samples lost, repeated, swapped, NaN or infinite stamps, a stray far ahead, a jump
    ahead that the next sample confirms, a reset back to t = 0; noise on x, v sometimes
    NaN (position only)."""
    h = p.period / rate
    out = []
    j, n = 0, periods * rate
    while j <= n:
        t = j * h + float(rng.choice([0.0, 0.0, 0.0, rng.normal(0.0, 1e-3 * h)]))
        x, v = float(rng.normal(0.0, 1e-4)), float(rng.choice([math.nan, rng.normal()]))
        r = rng.random()
        if r < 0.04:
            pass                                             # lost
        elif r < 0.07:
            out += [(t, x, v), (t, x, v)]                    # repeated
        elif r < 0.09 and out:
            out.insert(len(out) - 1, (t, x, v))              # swapped with the one before
        elif r < 0.10:
            out.append((float(rng.choice([math.nan, math.inf, -math.inf])), x, v))
        elif r < 0.11:
            out.append((t + float(rng.uniform(5.0, 50.0)) * p.period, x, v))   # a stray
        elif r < 0.115:
            j += int(rng.integers(5, 12) * rate)              # a jump ahead
            continue
        elif r < 0.12 and j > rate:
            j = 0                                             # a reset back to the start
            n = int(rng.integers(1, periods + 1)) * rate
            continue
        else:
            out.append((t, x, v))
        j += 1
    return out


def _state(est):
    s = est.samples
    return (s.t[s.first:], s.x[s.first:], s.v[s.first:], est.last_t, est.next_k,
            est.ignored, est.resets, est._jump)


def test_a_block_taken_in_one_step_is_the_block_taken_sample_by_sample():
    """``add_samples`` (the leading ``plain_run`` kept at once, the rest one by one)
    against ``add_sample`` on each sample, over 1000 seeded hostile streams cut into
    blocks of 1 to 20 samples, with and without ``after_section``, a given or a measured
    sample period and a lead: the same sections due, in order, with the same estimates
    bit for bit, and the same samples kept, counts and state after every block."""
    rng = np.random.default_rng(3030)
    p = P
    taken_at_once = 0
    for case in range(1000):
        rate = int(rng.choice([8, 20, 50]))
        kw = dict(sample_period=float(rng.choice([0.0, p.period / rate])),
                  after_section=bool(rng.random() < 0.5),
                  lead=float(rng.choice([0.0, 0.0, rng.uniform(0.0, 0.3)]) * p.period))
        estimator = "model" if case % 50 == 0 else "nearest"
        one, many = (StreamEstimator(p, estimator, 1e-4, **kw) for _ in range(2))
        stream = _hostile_stream(rng, p, rate, int(rng.integers(1, 4)))
        i = 0
        while i < len(stream):
            block = stream[i:i + int(rng.integers(1, 21))]
            i += len(block)
            t, x, v = (list(c) for c in zip(*block))
            taken_at_once += many.plain_run(t)
            want = [d for s in block for d in one.add_sample(*s)]
            got = many.add_samples(t, x, v)
            assert [(k, tk, e.source) for k, tk, e in got] == \
                [(k, tk, e.source) for k, tk, e in want], case
            for (_, _, a), (_, _, b) in zip(got, want):
                np.testing.assert_array_equal(a.z, b.z)
                np.testing.assert_array_equal(a.cov, b.cov)
            assert _state(many) == _state(one) or repr(_state(many)) == repr(_state(one))
    assert taken_at_once > 10_000           # the one-step path was taken, and often


@pytest.mark.parametrize("estimator, impact_source, rate", [("model", "stream", 100),
                                                            ("arc", "topic", 50)])
def test_simulate_stream_in_blocks_is_the_run_sample_by_sample(estimator, impact_source,
                                                                rate):
    """simulate_stream hands each run of samples between two impacts over as a block
    (``add_samples``, most of it kept in one step); an estimator that takes every sample
    one at a time (``add_sample``) runs the same closed loop bit for bit: truth,
    estimates, covariances, corrections and impacts (160 periods, control from section
    40, impacts in most periods). Each impact reaches the estimator after the samples
    before it and before those at or after it."""
    class Blocks(StreamEstimator):
        def __init__(self, *args):
            super().__init__(*args)
            self.order, self.kept_at_once = [], 0

        def add_impact(self, t):
            self.order.append((t, 0))
            super().add_impact(t)

        def add_sample(self, t, x, v=math.nan):
            self.order.append((t, 1))
            return super().add_sample(t, x, v)

        def add_plain(self, t, x, v):
            self.order.extend((ti, 1) for ti in t)
            self.kept_at_once += len(t)
            super().add_plain(t, x, v)

    class OneByOne(StreamEstimator):
        def add_samples(self, t, x, v):
            return [d for s in zip(t, x, v) for d in self.add_sample(*s)]

    g = _gains(P, -0.3)
    estimators = [cls(P, estimator, 1e-4, impact_source, P.period / rate)
                  for cls in (Blocks, OneByOne)]
    runs = [simulate_stream(P, g, SensorModel(noise=1e-4, velocity=False, seed=4).measure,
                            160, rate, control_after=40, deviation=(1e-3, -1e-3),
                            stream_estimator=est) for est in estimators]
    for field in ("truth", "estimate", "cov", "corrections", "impacts_per_period"):
        np.testing.assert_array_equal(getattr(runs[0], field), getattr(runs[1], field))
    assert runs[0].resets == runs[1].resets
    blocks = estimators[0]
    assert blocks.order == sorted(blocks.order)
    impacts = sum(1 for _, kind in blocks.order if kind == 0)
    assert impacts == runs[0].impacts_per_period.sum() > 100
    assert blocks.kept_at_once > 0.8 * 160 * rate

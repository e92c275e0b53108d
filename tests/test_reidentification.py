"""grazing_control.dynamics.estimation.reidentification: the refit of the model from the stream, the
redesign with the admissibility re-checked, the switch of the estimator, and each named
failure (issue 29 section 3; docs/theory_reidentification.md).

The refit is checked against the truth of the package's exact simulation
(tests/identification_scenes.py), the redesign against the degenerate condition it
solves (N_g,12 = 0 of the new model, dynamics.maps.maps.period_matrix) and the design's
admissible set (dynamics.design.gains.admissible_c2), the switch against the absolute state
it must keep.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.design.gains import admissible_c2, degenerate_c1
from grazing_control.dynamics.estimation.section_state import FilterState
from grazing_control.dynamics.identification.model import RigModel
from grazing_control.dynamics.maps.maps import period_matrix
from grazing_control.dynamics.estimation.reidentification import (MIN_PERIODS, ReidentificationError,
                                                       Reidentifier, StreamRecord,
                                                       model_from_fit, plan_switch, redesign,
                                                       refit, switch_estimator)
from grazing_control.dynamics.estimation.stream import StreamEstimator
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError

from identification_scenes import SCENE, rig_recording

#: The issue's scene and gains (grazing design --optimize noise --delta-d -5e-6 --delay 3).
P = OscillatorParams(delta_d=-5e-6)
GAINS = Gains(0.006031909726621269, -0.0060746847760492625, 3.0)
#: The issue's wrong controller model: zeta +5 %, Delta d +10 %.
WRONG = P.with_(zeta=1.05 * P.zeta, delta_d=1.1 * P.delta_d)


def test_the_condition_sets_are_the_designs():
    from grazing_control.dynamics.design import gains as design
    from grazing_control.dynamics.estimation import reidentification
    assert reidentification.CONDITIONS == design.CONDITIONS


def test_redesign_solves_the_degenerate_condition_of_the_new_model():
    """c2 and the delay are kept; c1 makes N_g,12 of the NEW model vanish (Eq. 38/(D5)),
    and differs from the old model's c1."""
    new = redesign(P, Gains(degenerate_c1(WRONG, GAINS.c2, 3.0), GAINS.c2, 3.0))
    assert (new.c2, new.delay) == (GAINS.c2, 3.0)
    n = period_matrix(P, new)
    assert abs(n[1]) <= 1e-12 * max(abs(x) for x in n)
    assert abs(new.c1 - degenerate_c1(WRONG, GAINS.c2, 3.0)) > 1e-6 * abs(new.c1)
    assert new.c1 == pytest.approx(GAINS.c1, rel=1e-9)     # the design's own c1 for P


def test_a_model_without_an_admissible_design_is_refused_by_name():
    """A c2 outside the admissible set of the model (design.admissible_c2, the same
    conditions) is refused with reason no_admissible_design, whatever c1 was."""
    intervals = admissible_c2(P, delay=3.0)
    c2 = max(hi for _lo, hi in intervals if math.isfinite(hi)) + 0.5
    assert not any(lo < c2 < hi for lo, hi in intervals)
    with pytest.raises(ReidentificationError, match="no admissible design") as err:
        redesign(P, Gains(0.0, c2, 3.0))
    assert err.value.reason == "no_admissible_design"
    inside = 0.5 * sum(next(iv for iv in intervals if all(map(math.isfinite, iv))))
    assert redesign(P, Gains(0.0, inside, 3.0)).c2 == inside
    with pytest.raises(ParameterError, match="design_conditions='all' is invalid"):
        redesign(P, GAINS, "all")


def test_too_few_periods_are_refused_before_any_fit():
    rec = StreamRecord(P.period, 20)
    h = P.period / 50
    for j in range(50 * (MIN_PERIODS - 2)):
        rec.add_sample(j * h, 0.0, math.nan, 1.0, 0.0)
    with pytest.raises(ReidentificationError, match="too few periods") as err:
        rec.snapshot()
    assert err.value.reason == "too_few_periods"
    with pytest.raises(ParameterError, match="reidentify_periods=5 is invalid"):
        StreamRecord(P.period, 5)


def test_the_record_keeps_the_last_periods_and_restarts_at_a_reset():
    rec = StreamRecord(P.period, 12)
    h = P.period / 20
    for j in range(20 * 30):
        rec.add_sample(j * h, 0.1, math.nan, 1.0, 0.0)
    assert rec.covered == pytest.approx(12.0, abs=0.06)
    rec.add_sample(0.0, 0.1, math.nan, 1.0, 0.0)     # back to t = 0: a simulator reset
    assert len(rec.samples) == 1



def test_rows_added_in_one_step_are_the_rows_added_one_by_one():
    """``add_samples`` against ``add_sample`` on each row over 500 seeded runs of rows in
    increasing time, cut into blocks of 1-20, with impacts among them and now and then a
    block that starts with a repeat or goes back to the start: the same window kept."""
    rng = np.random.default_rng(1530)
    for _ in range(500):
        one, many = StreamRecord(P.period, 12), StreamRecord(P.period, 12)
        t = 0.0
        for _ in range(int(rng.integers(1, 60))):
            if rng.random() < 0.1:
                t = float(rng.choice([0.0, t, t - 0.5 * P.period]))
            rows = []
            for _ in range(int(rng.integers(1, 21))):
                t += float(rng.exponential(P.period / 20))
                rows.append((t, *rng.normal(size=4)))
            if rng.random() < 0.2:
                impact = t - float(rng.uniform(0.0, 30.0)) * P.period
                for rec in (one, many):
                    rec.add_impact(impact)
            for row in rows:
                one.add_sample(*row)
            many.add_samples(rows)
            assert list(many.samples) == list(one.samples)
            assert list(many.impacts) == list(one.impacts)

def test_the_window_starts_after_the_model_filters_last_restart():
    """Without an impact sensor the impacts are the model's predictions from the
    filter's estimates: the window starts after the last section the model filter did
    not estimate (an arc fit after a start or a reset), and is refused when too short."""
    rec = StreamRecord(P.period, 20)
    h = P.period / 20
    for j in range(20 * 25 + 1):
        rec.add_sample(j * h, 0.0, math.nan, 1.0, 0.0)
    for k in range(26):
        rec.add_section(k, (P.x_ref, P.v_ref), 0.0, k * P.period + 3.0, fitted=k not in (6, 8))
    w = rec.snapshot()
    assert w.samples[0, 0] == pytest.approx(9 * P.period) and min(w.sections) == 9
    rec.add_section(26, (P.x_ref, P.v_ref), 0.0, 26 * P.period + 3.0, fitted=False)
    rec.add_section(18, (P.x_ref, P.v_ref), 0.0, 18 * P.period + 3.0, fitted=False)
    with pytest.raises(ReidentificationError, match="since the model filter's last restart"):
        rec.snapshot()


def test_refit_recovers_the_model_from_a_noise_free_motion():
    """Differential: the refit of the exact motion (impacts of every size, recorded
    times) started from a model with zeta +5 % and Delta d +10 % gives the truth's zeta,
    r and Delta d to 1e-8, and the running model's time base."""
    record = rig_recording(SCENE, periods=24)
    running = SCENE.with_(zeta=1.05 * SCENE.zeta, delta_d=1.1 * SCENE.delta_d)
    fit = refit(record, running)
    m = fit.model
    assert m.zeta == pytest.approx(SCENE.zeta, rel=1e-8)
    assert m.r == pytest.approx(SCENE.r, rel=1e-8)
    assert m.delta_d == pytest.approx(SCENE.delta_d, rel=1e-8)
    assert (m.omega, m.pi2_offset) == (running.omega, running.pi2_offset)
    assert abs(fit.phase_error) < 1e-8
    assert fit.units == (1.0, 1.0) and fit.impacts > 10


def test_a_refit_beyond_its_time_budget_is_not_identified_and_ends():
    """A window that takes longer to fit than the budget (here a zero budget; through the
    nodes a controlled-only window had not ended after 124 s): the solver stops at the
    deadline, the plan is refused as not_identified, naming the budget."""
    record = rig_recording(SCENE, periods=24)
    running = SCENE.with_(zeta=1.05 * SCENE.zeta, delta_d=1.1 * SCENE.delta_d)
    with pytest.raises(ReidentificationError, match=r"did not end within 0 s") as err:
        refit(record, running, seconds=0.0)
    assert err.value.reason == "not_identified"
    assert refit(record, running).model.zeta == pytest.approx(SCENE.zeta, rel=1e-8)


def test_a_fit_that_does_not_explain_the_window_is_refused():
    """The fit's residual noise against the sensor's: a window noisier than the sensor
    says (1e-3 against 1e-4) is not explained by the refitted model: fit_failed; the
    same window against its own noise passes."""
    record = rig_recording(SCENE, periods=24, noise=1e-3, seed=3)
    with pytest.raises(ReidentificationError, match="does not explain the window") as err:
        refit(record, SCENE, sigma=1e-4)
    assert err.value.reason == "fit_failed"
    assert refit(record, SCENE, sigma=1e-3).sigma == pytest.approx(1e-3, rel=0.2)


def test_a_stretch_without_impacts_is_named_and_nothing_is_planned():
    """Free flight (the wall far away) identifies neither r nor the wall: reason
    no_impacts, no gains in the plan."""
    free = SCENE.with_(delta_d=0.5)
    record = rig_recording(free, periods=12, impacts=False, deviation=(0.01, 0.0))
    with pytest.raises(ReidentificationError, match="no impact") as err:
        refit(record, free)
    assert err.value.reason == "no_impacts"


def test_a_fit_outside_the_models_ranges_is_not_identified():
    """A fitted r beyond 1 (the fit's bound is 2: a wrong model) is not a model."""
    fitted = SimpleNamespace(model=RigModel(P.zeta, 1.0, 1.0, 0.0, P.d, 1.2, P.omega, 0.0))
    with pytest.raises(ReidentificationError, match="outside the model's ranges") as err:
        model_from_fit(fitted, P)
    assert err.value.reason == "not_identified"
    fitted = SimpleNamespace(model=RigModel(P.zeta, 1.0, 1.0, 0.0, P.d, P.r, P.omega, 0.0))
    assert model_from_fit(fitted, WRONG).delta_d == pytest.approx(P.delta_d, abs=1e-15)


def test_the_switch_keeps_the_absolute_state_of_the_filter():
    """Differential: the filter's deviation moves by X**_old - X**_new, so X** + z is the
    same state to rounding; the covariance is kept."""
    est = StreamEstimator(WRONG, "model", 1e-4)
    cov = np.array([[2e-8, 1e-9], [1e-9, 3e-8]])
    est.filter = FilterState((1e-4, -2e-4), cov, 7)
    switch_estimator(est, P)
    assert est.p is P
    assert P.x_ref + est.filter.z[0] == pytest.approx(WRONG.x_ref + 1e-4, abs=1e-16)
    assert P.v_ref + est.filter.z[1] == pytest.approx(WRONG.v_ref - 2e-4, abs=1e-15)
    assert est.filter.cov is cov and est.filter.periods == 7


def test_the_augmented_filter_takes_the_new_wall_with_the_refits_error():
    est = AugmentedStreamEstimator(WRONG, 1e-4, bias=True, wall=True)
    est.params = (3e-5, WRONG.delta_d)
    switch_estimator(est, P, wall_std=2e-6)
    assert est.identified is P and est.delta_d == P.delta_d and est.bias == 3e-5
    assert est.params_cov[1, 1] == pytest.approx(4e-12)
    assert est.params_cov[0, 1] == 0.0


def test_a_request_while_a_fit_runs_is_refused_and_the_first_goes_on():
    """The worker takes one request at a time: a second one, while the first runs or
    before its plan is taken, is refused (busy); the first's plan comes once."""
    record = StreamRecord(SCENE.period, MIN_PERIODS)
    data = rig_recording(SCENE, periods=MIN_PERIODS + 2)
    for t, x, c, s in zip(data.t, data.x, data.cos_tau, data.sin_tau):
        record.add_sample(t, x, math.nan, c, s)
    for t in data.impact_t:
        record.add_impact(t)
    worker = Reidentifier()
    gains = Gains(degenerate_c1(SCENE, -1.0), -1.0)
    worker.request(record, SCENE, gains, 12)
    with pytest.raises(ReidentificationError, match="already running") as err:
        worker.request(record, SCENE, gains, 13)
    assert err.value.reason == "busy"
    worker.join(300.0)
    plan = worker.take()
    assert plan is not None and plan.requested_at == 12
    assert worker.take() is None
    assert plan.error is None and plan.refit.model.zeta == pytest.approx(SCENE.zeta, rel=1e-6)


def test_a_plan_that_fails_carries_its_reason_and_no_gains():
    record = StreamRecord(P.period, MIN_PERIODS)
    h = P.period / 50
    for j in range(50 * (MIN_PERIODS + 1)):        # a motion without impacts
        t = j * h
        record.add_sample(t, P.amplitude * math.cos(P.tau2 + P.omega * t - P.lag) - 1.0,
                          math.nan, math.cos(P.omega * t), math.sin(P.omega * t))
    plan = plan_switch(record.snapshot(), P, GAINS)
    assert plan.gains is None and not plan.admissible
    assert plan.error.reason in ("no_impacts", "fit_failed")


def test_a_stretch_of_grazing_touches_is_a_singular_fit():
    """The grazing orbit itself (Delta d = 0: the motion touches the wall with v- = 0 once a
    period, the touches recorded): v+ = -r v- = 0 whatever r, so r has no column in the
    fit's Jacobian and the fit is singular: not_identified, nothing planned."""
    p = OscillatorParams(delta_d=0.0)
    t = np.arange(16 * 24) * (p.period / 16) + 0.013
    psi = p.tau2 + p.omega * t
    x = p.amplitude * np.cos(psi - p.lag)
    v = -p.amplitude * p.omega * np.sin(psi - p.lag)
    touch = (2.0 * math.pi * np.arange(30) + p.lag - p.tau2) / p.omega
    touch = touch[(touch > t[0]) & (touch < t[-1])]
    nan = np.full(touch.size, np.nan)
    from grazing_control.dynamics.identification import Recording

    record = Recording(t, x, v, np.cos(psi), np.sin(psi), touch, nan, nan)
    with pytest.raises(ReidentificationError, match="singular fit") as err:
        refit(record, p)
    assert err.value.reason == "not_identified"

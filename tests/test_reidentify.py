"""The controller's re-identification without ROS middleware (grazing_control/ros/reidentify.py,
issue 29 section 3): its parameters' validation, the decision rows, and the switch or the
refusal applied to the controller's state (a refusal keeps the loop's state)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from grazing_control.dynamics.estimation.consistency import ConsistencyMonitor
from grazing_control.dynamics.estimation.section_state import FilterState
from grazing_control.dynamics.estimation.reidentification import (REASONS, ReidentificationError,
                                                       Refit, SwitchPlan)
from grazing_control.dynamics.estimation.stream import StreamEstimator
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.ros.controller_values import ControlLaw
from grazing_control.ros.reidentify import (REID_DEFAULTS, SWITCH_FIELDS, ReidentifySide,
                                            reid_from_values, switch_row)

STREAM = {**REID_DEFAULTS, "pi2_source": "stream", "estimator": "model",
          "consistency_window": 10, "sensor_noise": 1e-4}
P = OscillatorParams(delta_d=-5e-6)
WRONG = P.with_(zeta=1.05 * P.zeta, delta_d=1.1 * P.delta_d)


def test_off_outside_the_model_filter_and_on_in_stream_mode():
    assert reid_from_values({**STREAM, "pi2_source": "sample"}, P.period) is None
    record, worker, auto = reid_from_values(STREAM, P.period)
    assert record.periods == REID_DEFAULTS["reidentify_periods"] and not auto
    assert worker.conditions == "combined"


@pytest.mark.parametrize("over, message", [
    ({"reidentify_periods": 5}, "reidentify_periods=5 is invalid: valid range is an integer >= 10"),
    ({"reidentify_periods": 12.5}, "reidentify_periods=12.5 is invalid"),
    ({"design_conditions": "all"}, "design_conditions='all' is invalid: valid values are "
                                   "combined, impacting, non-impacting"),
    ({"reidentify": True, "consistency_window": 0}, "reidentify=True is invalid with "
                                                    "consistency_window=0"),
    ({"reidentify": True, "estimator": "arc"}, "reidentify=True is invalid with "
                                               "pi2_source=stream estimator=arc"),
])
def test_bad_values_are_refused_in_one_line_naming_the_parameter(over, message):
    with pytest.raises(ParameterError, match=message.replace("(", r"\(")) as err:
        reid_from_values({**STREAM, **over}, P.period)
    assert "\n" not in str(err.value)


def _node():
    """The controller's state the side reads and writes: the stream estimator on the
    wrong model with a filter, the law, the monitor, a publisher that keeps rows."""
    stream = StreamEstimator(WRONG, "model", 1e-4)
    stream.filter = FilterState((1e-4, -1e-4), np.eye(2) * 1e-8, 5)
    stream.next_k = 40
    law = ControlLaw(Gains(0.006, -0.006), WRONG.x_ref, WRONG.v_ref, 0, math.inf)
    sent = []
    logger = SimpleNamespace(info=lambda m: None, warning=lambda m: None)
    node = SimpleNamespace(stream=stream, model=WRONG, law=law, actuation_delay=3.0,
                           monitor=ConsistencyMonitor(10), verdict=None,
                           pub_switch=SimpleNamespace(publish=sent.append),
                           get_logger=lambda: logger)
    side = ReidentifySide.from_node(node, STREAM)
    return node, side, sent


def _refit(model):
    return Refit(model, {"zeta": 1e-5, "r": 1e-2, "delta_d": 2e-6}, 1e-4, (1.0, 1.0), 0.0,
                 20.0, 20, 20, 3.0)


@pytest.mark.parametrize("reason", ["no_impacts", "not_identified", "no_admissible_design",
                                    "fit_failed"])
def test_a_refused_plan_keeps_the_loops_state(reason):
    node, side, sent = _node()
    before = (node.model, node.law.gains, node.law.x_ref, node.stream.p, node.stream.filter)
    plan = SwitchPlan(refit=_refit(P) if reason == "no_admissible_design" else None,
                      error=ReidentificationError(reason, "why"), requested_at=30)
    side._apply(plan, 41, (100, 0))
    assert (node.model, node.law.gains, node.law.x_ref, node.stream.p,
            node.stream.filter) == before
    row = dict(zip(SWITCH_FIELDS, sent[-1].position))
    assert row["switched"] == 0.0 and row["reason"] == 1 + REASONS.index(reason)
    assert row["requested_at"] == 30 and math.isnan(row["c1"])
    assert side.refused == {reason: 1} and side.switches == 0


def test_a_switch_moves_the_estimator_the_gains_and_x_ref_and_restarts_the_monitor():
    node, side, sent = _node()
    gains = Gains(0.0061, -0.006, 3.0)
    side._apply(SwitchPlan(refit=_refit(P), gains=gains, requested_at=30), 41, (100, 0))
    assert node.model is P and node.stream.p is P
    assert (node.law.gains.c1, node.law.gains.c2) == (0.0061, -0.006)
    assert (node.law.x_ref, node.law.v_ref) == (P.x_ref, P.v_ref)
    row = dict(zip(SWITCH_FIELDS, sent[-1].position))
    assert row["switched"] == 1.0 and row["reason"] == 0.0 and row["zeta"] == P.zeta
    assert row["c1"] == 0.0061 and row["x_ref"] == P.x_ref
    assert side.switches == 1 and node.verdict is None


def test_a_request_on_a_short_stream_is_refused_with_a_row():
    node, side, sent = _node()
    ok, message = side.request()
    assert not ok and "too_few_periods" in message
    row = dict(zip(SWITCH_FIELDS, sent[-1].position))
    assert row["reason"] == 1 + REASONS.index("too_few_periods")
    assert row["requested_at"] == 39


def test_rows_have_every_field():
    err = ReidentificationError("busy", "x")
    assert len(switch_row(error=err)) == len(SWITCH_FIELDS)
    plan = SwitchPlan(refit=_refit(P), gains=Gains(1.0, 2.0))
    assert len(switch_row(plan, law=SimpleNamespace(x_ref=0.0, v_ref=1.0))) == len(SWITCH_FIELDS)


def test_diagnostics_count_switches_and_warn_on_a_new_refusal():
    node, side, _sent = _node()
    stat = SimpleNamespace(values={}, summaries=[])
    stat.add = lambda k, v: stat.values.__setitem__(k, v)
    stat.merge_summary = lambda level, message: stat.summaries.append(message)
    side._apply(SwitchPlan(error=ReidentificationError("no_impacts", "why"),
                           requested_at=3), 30, (1, 0))
    side.diagnose(stat)
    assert stat.values["refits refused"] == "no_impacts 1"
    assert stat.values["model switches"] == 0 and stat.values["refit running"] == "false"
    assert "no_impacts" in stat.values["re-identification"]
    assert stat.summaries == ["1 re-identifications refused since the last message (model "
                              "and gains kept)"]
    stat.summaries.clear()
    side.diagnose(stat)                 # nothing new: no WARN
    assert stat.summaries == []


# ------------------------------------------------------------- a model-file controller
def _ndof_node(coordinate: int = 0):
    """An n-DOF controller's state (issue 32): the two-mass scene's model file with the
    damping 1 % high as the running model, its design k(mu = -0.22, delay 1.0), the
    stream estimator of x_`coordinate` with a filter, the law k^T (X - X**)."""
    import dataclasses
    from pathlib import Path

    from grazing_control.dynamics.design.family import evaluate_design
    from grazing_control.oscillator.ndof.model import load_model
    from grazing_control.ros.controller_values import model_controller_from_values

    path = Path(__file__).resolve().parents[1] / "config" / "models" / "two_mass_scene.yaml"
    true = dataclasses.replace(load_model(path), delta_d=-1e-3)
    wrong = dataclasses.replace(true, C=1.01 * true.C)
    ndof = model_controller_from_values({"delta_d": -1e-3}, str(path),
                                        evaluate_design(wrong, -0.22, 1.0).gains.tolist(),
                                        model=wrong)
    stream = StreamEstimator(ndof.model, "model", 1e-4, coordinate=coordinate)
    stream.filter = FilterState((1e-4, -1e-4, 2e-4, 0.0), np.eye(4) * 1e-8, 5)
    stream.next_k = 40
    law = ControlLaw(ndof.gains, ndof.x_ref, ndof.v_ref, 0, math.inf)
    sent = []
    logger = SimpleNamespace(info=lambda m: None, warning=lambda m: None)
    node = SimpleNamespace(stream=stream, model=ndof.model, ndof=ndof, law=law,
                           actuation_delay=1.0, pulse=(0.0, math.inf, None), monitor=None,
                           verdict=None, pub_switch=SimpleNamespace(publish=sent.append),
                           get_logger=lambda: logger)
    return node, ReidentifySide.from_node(node, STREAM), sent, true


def test_an_n_dof_switch_moves_the_model_the_gains_and_x_star_star():
    """A plan for a model file: the estimator, the controller's model (its prediction's
    section) and the law move to the new model's k and X** = X_p(tau2); the row has the
    lowest mode's zeta, c1 and c2 NaN, the wall coordinate's X**."""
    from grazing_control.dynamics.estimation.reidentification import VectorGains
    from grazing_control.dynamics.identification.modal import modal_of
    from grazing_control.oscillator.ndof.flow import NdofFlow

    node, side, sent, true = _ndof_node()
    old_X = np.concatenate([node.ndof.x_ref, node.ndof.v_ref]) + np.array(node.stream.filter.z)
    k = np.array([-1.3, 0.2, -1.6, -1.2])
    fit = Refit(true, {"zeta": 1e-5, "r": 1e-3, "delta_d": 5e-6}, 1e-4, (math.nan,) * 2,
                0.0, 20.0, 20, 20, 25.0, modal_of(true), {})
    side._apply(SwitchPlan(refit=fit, gains=VectorGains(k, 1.0, -0.22), requested_at=39),
                41, (100, 0))
    flow = NdofFlow.of(true)
    X = flow.particular(flow.tau2)
    assert node.model is true and node.stream.p is true and node.ndof.model is true
    assert node.ndof.section.model is true and node.ndof.gains is k and node.law.gains is k
    np.testing.assert_array_equal(node.law.x_ref, X[:2])
    np.testing.assert_array_equal(node.ndof.v_ref, X[2:])
    np.testing.assert_allclose(X + np.array(node.stream.filter.z), old_X, rtol=0, atol=1e-15)
    row = dict(zip(SWITCH_FIELDS, sent[-1].position))
    assert row["switched"] == 1.0 and row["reason"] == 0.0
    assert row["zeta"] == modal_of(true).damping_ratio[0] and row["r"] == true.r
    assert math.isnan(row["c1"]) and math.isnan(row["c2"]) and row["x_ref"] == X[0]
    assert side.switches == 1


def test_an_n_dof_request_names_its_refusals():
    """The stream of another coordinate than the wall's: not_identified at the request
    (the modal fit is x_w's); of the wall's, too short: too_few_periods; both a row."""
    node, side, sent, _true = _ndof_node(coordinate=1)
    ok, message = side.request()
    assert not ok and "(not_identified)" in message and "i_w=0" in message
    assert dict(zip(SWITCH_FIELDS, sent[-1].position))["reason"] == \
        1 + REASONS.index("not_identified")
    node, side, sent, _true = _ndof_node(coordinate=0)
    ok, message = side.request()
    assert not ok and "too_few_periods" in message

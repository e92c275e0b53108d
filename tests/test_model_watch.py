"""The controller's model watch without ROS (grazing_control/ros/model_watch.py, issue 29):
its parameters' validation, its rows and the /diagnostics level of a verdict."""

import math

import numpy as np
import pytest

from grazing_control.dynamics.estimation.augmented import AugmentedStreamEstimator
from grazing_control.dynamics.estimation.consistency import ConsistencyMonitor
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.ros.model_watch import (WATCH_DEFAULTS, WATCH_FIELDS, watch_from_values,
                                             watch_row, watch_status)

STREAM = {**WATCH_DEFAULTS, "pi2_source": "stream", "estimator": "model"}


def test_off_by_default_and_on_by_any_switch():
    assert watch_from_values(STREAM) is None
    kwargs, monitor = watch_from_values({**STREAM, "estimate_bias": True})
    assert kwargs["bias"] and not kwargs["wall"] and monitor is None
    kwargs, monitor = watch_from_values({**STREAM, "consistency_window": 7,
                                         "false_alarm": 0.01})
    assert not kwargs["bias"] and not kwargs["wall"]
    assert monitor.window == 7 and monitor.false_alarm == 0.01


@pytest.mark.parametrize("over, message", [
    ({"consistency_window": -1}, "consistency_window=-1 is invalid"),
    ({"consistency_window": 2.5}, "consistency_window=2.5 is invalid"),
    ({"bias_std": 0.0}, "bias_std=0.0 is invalid"),
    ({"wall_std": math.inf}, "wall_std=inf is invalid"),
    ({"wall_noise": -1e-9}, "wall_noise=-1e-09 is invalid"),
    ({"false_alarm": 0.5}, "false_alarm=0.5 is invalid"),
    ({"track_delta_d": True, "estimator": "arc"},
     "track_delta_d=True is invalid with pi2_source=stream estimator=arc"),
    ({"consistency_window": 3, "pi2_source": "sample"},
     "consistency_window=3 is invalid with pi2_source=sample")])
def test_bad_values_are_named(over, message):
    with pytest.raises(ParameterError, match=message.replace("(", r"\(").replace(".", r"\.")):
        watch_from_values({**STREAM, **over})


def test_a_row_names_its_values_and_a_mismatch_is_an_error():
    """A fresh estimator's row: the priors (b 0 with se bias_std; Delta d's NaN when not
    tracked); a monitor fed chi^2 far above its bound gives a mismatch verdict, an ERROR
    naming the nis test with its statistic and bound; a consistent one after it, a
    WARN that counts the mismatches since the last message."""
    p = OscillatorParams(delta_d=-5e-6)
    est = AugmentedStreamEstimator(p, 1e-4, "stream", p.period / 50, bias=True, wall=False,
                                   bias_std=2e-3)
    monitor = ConsistencyMonitor(4, 1e-3)
    bad = monitor.add(0, 500.0, 49)
    row = dict(zip(WATCH_FIELDS, watch_row(est, bad)))
    assert row["bias"] == 0.0 and row["bias_se"] == pytest.approx(2e-3)
    assert math.isnan(row["delta_d"]) and math.isnan(row["delta_d_se"])
    assert row["mismatch"] == 1.0 and row["fail_nis"] == 1.0 and row["fail_mean"] == 0.0
    assert row["nis"] == 500.0 and row["nis_dof"] == 49 and row["nis_bound"] == bad.bound
    level, message = watch_status(bad, 1)
    assert level == "error" and f"nis 500 > bound {bad.bound:.4g} (chi2, 49 dof)" in message
    assert "section 0" in message
    monitor = ConsistencyMonitor(4, 1e-3)
    good = monitor.add(5, 49.0, 49)
    assert watch_status(good, 3) == ("warn", "3 sections with a model mismatch verdict "
                                             "since the last message")
    assert watch_status(good, 0) == (None, "")
    assert watch_status(None, 0) == (None, "")
    assert np.all(np.isnan(watch_row(est, None)[4:12]))


def test_the_capture_rule_of_the_parameters():
    """capture: the rule's radius is 5 sqrt(|Delta d|) by default (docs/theory_capture.md)
    or capture_radius, its target the controlled orbit's Pi2 deviation; it holds the
    correction back (factor 0) until an estimate is within the radius, then latches;
    refused by name in sample mode and for a negative radius; off: None."""
    from types import SimpleNamespace

    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.orbits.orbits import orbit_11
    from grazing_control.oscillator.control import Gains
    from grazing_control.ros.controller_values import capture_from_values

    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(degenerate_c1(p, -1.0), -1.0)
    values = {"capture": True, "capture_radius": 0.0, "pi2_source": "stream",
              "c1": g.c1, "c2": g.c2}
    rule = capture_from_values(values, p, 0.0)
    z = np.array(orbit_11(p, g).pi2_deviation)
    assert rule.radius == pytest.approx(5.0 * math.sqrt(5e-6), rel=1e-12)
    assert np.allclose(rule.target, z, rtol=0, atol=1e-15)
    cov = np.eye(2) * 1e-8
    assert rule(0, SimpleNamespace(z=z + [0.02, 0.0], cov=cov)) == 0.0
    assert rule(1, SimpleNamespace(z=z + [0.01, 0.0], cov=cov)) == 1.0 and rule.on_at == 1
    assert rule(2, SimpleNamespace(z=z + [0.5, 0.0], cov=cov)) == 1.0
    assert capture_from_values({**values, "capture_radius": 3e-3}, p, 0.0).radius == 3e-3
    assert capture_from_values({**values, "capture": False}, p, 0.0) is None
    with pytest.raises(ParameterError, match="capture=True is invalid with pi2_source=sample"):
        capture_from_values({**values, "pi2_source": "sample"}, p, 0.0)
    with pytest.raises(ParameterError, match="capture_radius=-1.0 is invalid"):
        capture_from_values({**values, "capture_radius": -1.0}, p, 0.0)

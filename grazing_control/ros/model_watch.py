"""The controller's watch on its own model (issue 29 sections 1-2), without ROS.

In stream mode with ``estimator`` model, the controller may run the augmented filter
(:class:`grazing_control.dynamics.estimation.augmented.AugmentedStreamEstimator`: a sensor bias b
and a random-walk Delta d in the filter's state, docs/theory_estimation.md E8-E10) and
feed each fitted period's innovation to a
:class:`grazing_control.dynamics.estimation.consistency.ConsistencyMonitor` (the windowed nis and
mean tests, E9-E10). Parameters (all off by default: the plain model filter, the same
answers as before to the bit):

``estimate_bias``       estimate a constant position bias of the sensor;
``track_delta_d``       track Delta d as a random walk of std ``wall_noise`` per period;
``bias_std``            the bias's prior std (> 0, dimensionless position);
``wall_std``            Delta d's prior std about the given ``delta_d`` (> 0);
``wall_noise``          the random walk's std per period (>= 0);
``consistency_window``  the monitor's window in periods (0: no monitor; >= 1);
``false_alarm``         the monitor's false-alarm rate per window (0 < alpha < 0.5).

Any of ``estimate_bias``, ``track_delta_d`` or ``consistency_window`` >= 1 selects the
augmented filter (with both augmentations off it is the plain model filter to rounding,
tests/test_augmented.py, and gives the monitor its innovations).

Each section the controller publishes one row on ``controller/model_watch``
(sensor_msgs/JointState, stamp t_k, ``name`` = :data:`WATCH_FIELDS`, ``position`` = the
values): the estimates and standard errors of b and Delta d, and the monitor's verdict
(statistics, degrees of freedom, bounds; ``mismatch`` 1 or 0, and one flag per failing
test). NaN where there is none (no verdict yet, or an augmentation off).
"""

from __future__ import annotations

import math

from grazing_control.dynamics.estimation.augmented import BIAS_STD, WALL_NOISE, WALL_STD
from grazing_control.dynamics.estimation.consistency import FALSE_ALARM, ConsistencyMonitor
from grazing_control.oscillator.params import ParameterError

__all__ = ["WATCH_KEYS", "WATCH_DEFAULTS", "WATCH_FIELDS", "WATCH_TOPIC", "watch_from_values",
           "watch_row", "describe_verdict", "watch_status"]

#: The topic of the rows (recorded by default).
WATCH_TOPIC = "controller/model_watch"
#: The parameters, with their defaults (off).
WATCH_DEFAULTS = {"estimate_bias": False, "track_delta_d": False, "bias_std": BIAS_STD,
                  "wall_std": WALL_STD, "wall_noise": WALL_NOISE, "consistency_window": 0,
                  "false_alarm": FALSE_ALARM}
WATCH_KEYS = tuple(WATCH_DEFAULTS)
#: The names of a row's values, in order.
WATCH_FIELDS = ("bias", "bias_se", "delta_d", "delta_d_se", "nis", "nis_dof", "nis_bound",
                "mean", "mean_dof", "mean_bound", "periods", "failed", "mismatch",
                "fail_nis", "fail_mean", "fail_resets")


def watch_from_values(values: dict):
    """(keyword arguments of AugmentedStreamEstimator, ConsistencyMonitor or None), or
    None when the watch is off (every parameter at its off value); ParameterError naming
    the parameter and its valid range, or the estimator/pi2_source it needs."""
    bias, wall = bool(values["estimate_bias"]), bool(values["track_delta_d"])
    window = values["consistency_window"]
    if isinstance(window, bool) or int(window) != window or window < 0:
        raise ParameterError(f"consistency_window={window!r} is invalid: valid range is an "
                             "integer >= 0 periods (0: no consistency monitor)")
    for name, ok, valid in (("bias_std", lambda x: x > 0.0, "> 0"),
                            ("wall_std", lambda x: x > 0.0, "> 0"),
                            ("wall_noise", lambda x: x >= 0.0, ">= 0")):
        value = float(values[name])
        if not (math.isfinite(value) and ok(value)):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite "
                                 f"{name} {valid}")
    alarm = float(values["false_alarm"])
    if not 0.0 < alarm < 0.5:
        raise ParameterError(f"false_alarm={alarm!r} is invalid: valid range is "
                             "0 < false_alarm < 0.5 per window")
    if not (bias or wall or window):
        return None
    if values["pi2_source"] != "stream" or values["estimator"] != "model":
        on = [n for n, v in (("estimate_bias", bias), ("track_delta_d", wall),
                             ("consistency_window", window)) if v]
        raise ParameterError(f"{on[0]}={values[on[0]]!r} is invalid with pi2_source="
                             f"{values['pi2_source']} estimator={values['estimator']}: valid "
                             "only with pi2_source=stream and estimator=model (off: false, 0)")
    kwargs = {"bias": bias, "wall": wall, "bias_std": float(values["bias_std"]),
              "wall_std": float(values["wall_std"]), "wall_noise": float(values["wall_noise"])}
    monitor = ConsistencyMonitor(int(window), alarm) if window else None
    if monitor is not None:
        # its chi^2 bounds need scipy.stats: loaded now, at the node's start, not at the
        # first verdict (11 s on a loaded 2-core machine: an n-DOF lockstep scene's
        # simulator timed out on six sections and substituted its predictions, issue 32)
        monitor.bound(1)
    return kwargs, monitor


def watch_row(estimator, verdict) -> list:
    """The values of :data:`WATCH_FIELDS` after a section: ``estimator`` an
    AugmentedStreamEstimator, ``verdict`` the monitor's Verdict or None."""
    cov = estimator.params_cov
    nan = math.nan
    bias = (estimator.bias, math.sqrt(cov[0, 0])) if estimator.use_bias else (nan, nan)
    wall = (estimator.delta_d, math.sqrt(cov[1, 1])) if estimator.use_wall else (nan, nan)
    if verdict is None:
        tests = [nan] * 8 + [0.0, 0.0, 0.0, 0.0]
    else:
        fail = verdict.failing
        tests = [verdict.statistic, verdict.dof, verdict.bound, verdict.mean_statistic,
                 verdict.mean_dof, verdict.mean_bound, verdict.periods, verdict.failed,
                 float(verdict.status == "mismatch"), float("nis" in fail),
                 float("mean" in fail), float("resets" in fail)]
    return [float(x) for x in (*bias, *wall, *tests)]


def describe_verdict(verdict) -> str:
    """One line naming the failing tests with their statistic against the bound."""
    parts = []
    for test in verdict.failing:
        if test == "nis":
            parts.append(f"nis {verdict.statistic:.4g} > bound {verdict.bound:.4g} "
                         f"(chi2, {verdict.dof} dof)")
        elif test == "mean":
            parts.append(f"mean {verdict.mean_statistic:.4g} > bound "
                         f"{verdict.mean_bound:.4g} (chi2, {verdict.mean_dof} dof)")
        else:
            parts.append(f"resets: {verdict.failed} failed fits of "
                         f"{verdict.failed + verdict.periods} periods")
    return (f"model mismatch at section {verdict.k}: " + "; ".join(parts)
            if parts else f"model consistent at section {verdict.k}")


def watch_status(verdict, new_mismatches: int):
    """The /diagnostics level of the watch and its message: ("error", the failing tests)
    while the latest ``verdict`` is a mismatch; ("warn", how many) when
    ``new_mismatches`` sections had one since the last message but the latest is
    consistent; (None, "") otherwise."""
    if verdict is not None and verdict.status == "mismatch":
        return "error", describe_verdict(verdict)
    if new_mismatches:
        return "warn", (f"{new_mismatches} sections with a model mismatch verdict since the "
                        "last message")
    return None, ""

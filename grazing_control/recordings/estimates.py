"""The controller's estimates against the ground truth of a recording (``grazing analyze``):
the errors, their normalisation by the reported covariance, the Pi2 spread measured
against the one that covariance predicts, and the alarm when the loop is much noisier
than its model (docs/analysis.md)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import reader
from .numbers import controlled_orbit

#: The controller's Pi2 estimate in stream mode (ros/controller_node.py).
ESTIMATE_TOPIC = "/controller/estimate"
#: Samples at the end of a scene over which the spreads are measured.
SPREAD_WINDOW = 500
#: A measured Pi2 spread this many times the one predicted from the reported covariance
#: is named in the report: under the right model they agree to about 20 %
#: (tests/test_bagtools_analyze.py; 0.95-1.12 on the two-mass rig scenes of issue 32),
#: with the controller's zeta 5 % low on the acceptance rig the measured one was 62 times
#: the predicted (issue 30's hand check) and nothing said so.
SPREAD_ALARM = 3.0

__all__ = ["ESTIMATE_TOPIC", "SPREAD_WINDOW", "SPREAD_ALARM", "read_estimates", "estimate_numbers",
           "estimate_lines"]


def read_estimates(path, topic: str = ESTIMATE_TOPIC):
    """The estimate topic's columns (:func:`reader.decode_estimate`), or None when the bag
    has no such topic."""
    raw = reader.read_raw(Path(path), topics=[topic])
    if topic not in raw.channels:
        return None
    est = reader.decode_estimate(raw, topic)
    order = np.argsort(est["log_time"], kind="stable")
    order = order[est["ok"][order]]
    return {k: (v[order] if isinstance(v, np.ndarray) else v) for k, v in est.items()}


def estimate_numbers(est, sd, setup) -> dict | None:
    """The controller's estimates against the ground truth of one scene.

    Each estimate (stamped with its section) is matched to the recorded Pi2 sample of the
    same stamp in the scene's log-time span. Error e = estimate - truth; normalised
    errors e_x / sqrt(var x), e_v / sqrt(var v) (unit std if the covariance is right) and
    chi^2 = e^T P^-1 e (mean 2); coverage of the 95 % ellipse; all over the last
    :data:`SPREAD_WINDOW` samples (at most half of those since control is on): the
    measured Pi2 spread (rms of x about the exact controlled orbit of the scene's
    actuation, :func:`.numbers.controlled_orbit`: the pulse's for a pulse scene, O(w^2) away
    from the kick's) and the spread predicted from the reported covariance by the kick's
    loop linearised about its orbit (:func:`grazing_control.dynamics.design.noise.noise_covariance`
    with the mean reported covariance as the measurement covariance; a pulse changes the
    multipliers by O(w^2), docs/theory_pulse.md; errors correlated from period to period,
    as the model filter's are, break its white-noise premise).
    """
    if est is None:
        return None
    lo = sd.pi2_log_ns[0]
    span = (est["log_time"] >= lo)
    st = sd.stamp_ns
    pos = np.searchsorted(st, est["stamp"])
    hit = span & (pos < st.size) & (st[np.minimum(pos, st.size - 1)] == est["stamp"])
    if not np.any(hit):
        return {"estimates": 0, "note": "no estimate matches a Pi2 sample of this scene"}
    k = pos[hit]
    _, first = np.unique(k, return_index=True)
    k = k[first]
    sel = np.flatnonzero(hit)[first]
    e = np.column_stack([est["x"][sel], est["v"][sel]]) - sd.scene.pi2[k]
    cov = np.empty((sel.size, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = est["var_x"][sel], est["var_v"][sel]
    cov[:, 0, 1] = cov[:, 1, 0] = est["cov_xv"][sel]
    good = np.all(np.isfinite(cov.reshape(-1, 4)), axis=1) & (np.linalg.det(
        np.where(np.isfinite(cov), cov, 1.0)) > 0) & np.all(np.isfinite(e), axis=1)
    out = {"estimates": int(sel.size), "with_covariance": int(good.sum())}
    n_all = sd.scene.pi2.shape[0]
    on = np.flatnonzero(sd.scene.correction != 0.0)
    window = SPREAD_WINDOW if on.size == 0 else min(SPREAD_WINDOW, (n_all - on[0]) // 2)
    window = max(window, 1)
    last = k >= n_all - window
    use = good & last
    if not np.any(use):
        return out
    eu, cu = e[use], cov[use]
    chi2 = np.einsum("ni,nij,nj->n", eu, np.linalg.inv(cu), eu)
    out.update({
        "window": int(use.sum()),
        "error_std": eu.std(axis=0).tolist(),
        "error_mean": eu.mean(axis=0).tolist(),
        "reported_std": np.sqrt(np.mean(cu[:, [0, 1], [0, 1]], axis=0)).tolist(),
        "normalised_std": [float(np.std(eu[:, 0] / np.sqrt(cu[:, 0, 0]))),
                           float(np.std(eu[:, 1] / np.sqrt(cu[:, 1, 1])))],
        "chi2_mean": float(chi2.mean()),
        "coverage_95": float(np.mean(chi2 < -2.0 * math.log(0.05)))})
    p, g = setup.params, setup.gains
    if p is None or g is None:
        return out
    from grazing_control.dynamics.design.noise import noise_covariance
    from grazing_control.oscillator.control import Gains

    try:
        gains = Gains(g.c1, g.c2, setup.actuation_delay)
        orbit, _ = controlled_orbit(setup)       # the pulse's orbit for a pulse scene
        x = sd.scene.pi2[-window:, 0]
        out["measured_spread"] = float(np.sqrt(np.mean((x - orbit.pi2[0]) ** 2)))
        out["spread_about"] = [float(orbit.pi2[0]), float(orbit.pi2[1])]
        if setup.actuator is not None:       # the 3-state loop through the actuator
            pred = orbit.noise_covariance(gains, cu.mean(axis=0))
        else:
            pred = noise_covariance(p, gains, cu.mean(axis=0))    # the kick's linearised loop
        out["predicted_spread"] = float(math.sqrt(max(pred[0, 0], 0.0)))
        ratio = out["measured_spread"] / out["predicted_spread"] \
            if out["predicted_spread"] > 0.0 else math.inf
        if ratio > SPREAD_ALARM:
            out["spread_alarm"] = float(ratio)
    except (ValueError, RuntimeError, ArithmeticError) as exc:
        out["spread_note"] = f"no predicted spread: {exc}"
    return out


def estimate_lines(n) -> list:
    """The report's lines on the estimates (:func:`estimate_numbers`)."""
    if not n:
        return []
    if "chi2_mean" not in n:
        return [f"* estimates: {n.get('estimates', 0)} matched"
                + (f" ({n['note']})" if "note" in n else "")]
    lines = [f"* estimate vs ground truth (last {n['window']} sections): error std x "
             f"{n['error_std'][0]:.3g}, v {n['error_std'][1]:.3g} (reported "
             f"{n['reported_std'][0]:.3g}, {n['reported_std'][1]:.3g}); normalised error std "
             f"{n['normalised_std'][0]:.3f}, {n['normalised_std'][1]:.3f} (1 if the covariance "
             f"is right); χ² mean {n['chi2_mean']:.3f} (2), 95 % ellipse covers "
             f"{100 * n['coverage_95']:.1f} %"]
    if "measured_spread" in n:          # predicted: none where the loop has no stationary spread
        predicted = (f", predicted from the reported covariance {n['predicted_spread']:.3g}"
                     if "predicted_spread" in n else "")
        lines.append(f"* Π2 spread about the exact controlled orbit: measured "
                     f"{n['measured_spread']:.3g}{predicted}")
    if "spread_alarm" in n:
        lines.append(f"* **the loop is noisier than its model predicts**: the measured spread "
                     f"is {n['spread_alarm']:.3g} times the predicted (more than "
                     f"{SPREAD_ALARM:g}): a model error, noise the model lacks, or a reported "
                     "covariance that does not describe the errors (the model watch, "
                     "consistency_window, tests the model)")
    if "spread_note" in n:
        lines.append(f"* {n['spread_note']}")
    return lines

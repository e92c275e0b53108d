"""The rig a bag was recorded with, and the bag's numbers in its SI units (docs/rig.md).

A rig scene publishes its rig file on ``grazing/rig`` (std_msgs/String, transient local,
depth 1: the YAML text of :func:`grazing_control.plant.rig.rig_to_dict`), and the
recorder keeps it. :func:`read_rig` finds it (under a namespace too) and validates it as
a rig file; :func:`si_numbers` turns the analysis's numbers of a scene, which are in the
model's units (the ``oscillator/*`` topics: x~ = x / l, v~ = v / (omega_n l), one Pi2
sample per forcing period), into SI: positions and spreads in m, velocities in m/s, a
correction as a velocity change (m/s), an impulse (N s) and the force of the pulse
(N) over its width, times in s (sample counts x the forcing period); and
:func:`model_in_si` the identified model (natural frequency, damping ratio,
restitution, gap) with standard errors propagated from the fit's covariance.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from grazing_control.plant.rig import Rig, rig_from_dict
from . import reader

__all__ = ["RIG_TOPIC", "read_rig", "check_against_model", "si_numbers", "model_in_si"]

#: The topic of the rig file (relative name ``grazing/rig`` in the root namespace).
RIG_TOPIC = "/grazing/rig"


def _topic(raw) -> str | None:
    """``/grazing/rig``, or the one ``<ns>/grazing/rig`` of the bag."""
    if RIG_TOPIC in raw.channels:
        return RIG_TOPIC
    named = sorted(t for t in raw.channels if t.endswith(RIG_TOPIC))
    return named[0] if len(named) == 1 else None


def read_rig(bag) -> tuple:
    """(Rig or None, notes): the bag's rig from ``grazing/rig`` (its last message).

    No such topic: (None, []). A message that is not a valid rig file: (None, [one line
    saying why]), the analysis goes on in the model's units. Raises what
    :func:`reader.read_raw` raises for an unreadable bag.
    """
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.support.files import YamlFileError, parse_yaml_bytes

    raw = reader.read_raw(Path(bag), topics=[RIG_TOPIC])
    topic = _topic(raw)
    if topic is None:
        return None, []
    if topic != RIG_TOPIC:
        raw = reader.read_raw(Path(bag), topics=[topic])
    channel = raw.channels[topic]
    if channel.type != "std_msgs/msg/String":
        return None, [f"{topic} has type {channel.type or '?'}, expected std_msgs/msg/String: "
                      "no SI numbers"]
    texts = reader.decode_strings(raw, topic)
    if not texts:
        return None, [f"{topic} holds no readable message: no SI numbers"]
    _t, text = texts[-1]
    try:
        rig = rig_from_dict(parse_yaml_bytes(text.encode("utf-8"), topic))
    except (YamlFileError, ParameterError) as exc:
        return None, [f"the rig on {topic} cannot be used ({exc}): no SI numbers"]
    notes = [f"rig from {topic}: SI numbers use its scales"]
    if len(texts) > 1 and any(t != text for _, t in texts[:-1]):
        notes.append(f"{topic} holds {len(texts)} different rig files: the last one is used")
    return rig, notes


def check_against_model(rig: Rig, params) -> list:
    """Problems where the rig's model and the bag's parameter record disagree (beyond
    1e-9 relative; Delta d: 1e-9 of d)."""
    if params is None:
        return []
    p = rig.params()
    out = []
    for name in ("zeta", "r", "omega", "pi2_offset"):
        a, b = getattr(p, name), getattr(params, name)
        if not abs(a - b) <= 1e-9 * abs(b):
            out.append(f"the rig gives {name} = {a!r}, the run's parameters {b!r}")
    if not abs(p.delta_d - params.delta_d) <= 1e-9 * p.d:
        out.append(f"the rig gives delta_d = {p.delta_d!r}, the run's parameters "
                   f"{params.delta_d!r}")
    return out


def _pair(rig, xv):
    """A Pi2 state (x~, v~) in (m, m/s)."""
    s = rig.scales
    return [float(xv[0]) * s.length, float(xv[1]) * s.velocity]


def si_numbers(rig: Rig, numbers: dict, scene=None) -> dict:
    """The main numbers of one scene (``numbers``: :func:`.numbers.scene_numbers`, with
    ``estimate`` where the bag has the controller's estimates) in SI (module docstring).
    ``scene``: the scene's :class:`.analysis.Scene`, for the spread of the final Pi2
    samples about the controlled orbit."""
    s, T = rig.scales, rig.forcing_period
    n = numbers
    out = {"length_scale_m": s.length, "velocity_scale_m_per_s": s.velocity,
           "forcing_period_s": T, "duration_s": n["samples"] * T}
    if n.get("control_on_sample") is not None:
        out["control_on_after_s"] = n["control_on_sample"] * T
    if n.get("samples_to_converge") is not None:
        out["converged_after_s"] = n["samples_to_converge"] * T
    if n.get("final_pi2") is not None:
        out["final_pi2_m_and_m_per_s"] = _pair(rig, n["final_pi2"])
    pred = n.get("predicted") or {}
    if "orbit_pi2" in pred:
        out["orbit_pi2_m_and_m_per_s"] = _pair(rig, pred["orbit_pi2"])
        out["orbit_v_minus_m_per_s"] = pred["orbit_v_minus"] * s.velocity
        if n.get("final_pi2") is not None:
            d = np.abs(np.subtract(n["final_pi2"], pred["orbit_pi2"]))
            out["final_vs_exact_orbit_m_and_m_per_s"] = _pair(rig, d)
        if scene is not None and n.get("control_on_sample") is not None:
            from .estimates import SPREAD_WINDOW

            on = n["control_on_sample"]
            window = max(1, min(SPREAD_WINDOW, (scene.pi2.shape[0] - on) // 2))
            tail = scene.pi2[-window:] - np.asarray(pred["orbit_pi2"])
            out["pi2_spread_window"] = int(window)
            out["pi2_spread_m_and_m_per_s"] = _pair(rig, np.sqrt(np.mean(tail ** 2, axis=0)))
    c = n["corrections"]
    out["largest_correction"] = rig.correction_si(c["max_abs"])
    est = n.get("estimate") or {}
    if "error_std" in est:
        out["estimate_error_std_m_and_m_per_s"] = _pair(rig, est["error_std"])
        out["estimate_reported_std_m_and_m_per_s"] = _pair(rig, est["reported_std"])
    if "measured_spread" in est:
        out["estimate_measured_spread_m"] = est["measured_spread"] * s.length
    if "predicted_spread" in est:
        out["estimate_predicted_spread_m"] = est["predicted_spread"] * s.length
    return out


def model_in_si(rig: Rig, values: dict, covariance) -> dict:
    """The identified model in SI: natural frequency (Hz), damping ratio, restitution,
    gap (m), each {value, stderr}, and the rig file it makes
    (:func:`grazing_control.plant.rig.rig_with_model`).

    ``values``: the fitted zeta, r, omega, d (nondimensional); ``covariance``: their
    (4, 4) covariance in that order (None: standard errors unknown). The lab's forcing
    (frequency f, amplitude, mass) is held: f_n = f / omega, and the gap
    g = d l = d L0 omega^2 with L0 = F0 / (m (2 pi f)^2) (a force; = Y for a base
    excitation). Standard errors by the delta method, J C J^T.
    """
    from grazing_control.oscillator.params import OscillatorParams
    from grazing_control.plant.rig import rig_with_model

    zeta, r, omega, d = (float(values[k]) for k in ("zeta", "r", "omega", "d"))
    f = rig.frequency
    L0 = rig.force_amplitude / (rig.mass * (2.0 * math.pi * f) ** 2)
    p = OscillatorParams(zeta=zeta, r=r, omega=omega, pi2_offset=rig.pi2_offset)
    new = rig_with_model(rig, p.with_(delta_d=d - p.d_star))
    value = {"natural_frequency_Hz": f / omega, "damping_ratio": zeta, "restitution": r,
             "gap_m": d * L0 * omega * omega}
    # d(value) / d(zeta, r, omega, d)
    jac = np.array([[0.0, 0.0, -f / omega ** 2, 0.0],
                    [1.0, 0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 2.0 * d * L0 * omega, L0 * omega * omega]])
    if covariance is None:
        se = np.full(4, math.nan)
    else:
        cov = np.asarray(covariance, dtype=float)
        with np.errstate(invalid="ignore"):
            var = np.einsum("ij,jk,ik->i", jac, np.where(np.isfinite(cov), cov, 0.0), jac)
        se = np.sqrt(np.maximum(var, 0.0))
        unknown = (np.abs(jac) > 0) @ (~np.isfinite(np.diag(cov))).astype(float) > 0
        se[unknown] = math.inf
    out = {k: {"value": v, "stderr": float(e)} for (k, v), e in zip(value.items(), se)}
    return {"parameters": out, "rig": new}

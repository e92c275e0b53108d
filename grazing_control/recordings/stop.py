"""``grazing identify --stop BAG...``: which stop a recorded scene supports (issue 31 part 4).

bag -> Pi2 samples and corrections -> :func:`grazing_control.dynamics.identification.stop.select_stop`
-> report. The data: ``oscillator/pi2`` (position [x], velocity [v]: the sample before the
correction), ``controller/velocity_correction`` (twist.linear.x, stamped with its
sample's stamp), and the samples' frame (the phase tau2 of Pi2 and X**) from the bag's
parameter record (the simulator's parameters at start). The oscillator's parameters
(zeta, omega, the forcing's amplitude and phase, Delta d) are fitted with each candidate
stop, starting from the record's (``oscillator="known"``: held there, the stop alone
fitted). The method and its measured accuracy: docs/theory_contact.md section 17.
"""

from __future__ import annotations

import numpy as np

from grazing_control.dynamics.identification.data import RecordingError
from grazing_control.dynamics.identification.stop import STOPS, select_stop
from grazing_control.oscillator.params import OscillatorParams

from . import reader
from .identify import _sim_parameters

__all__ = ["STOP_TOPICS", "stop_data", "select_bag_stop", "format_stop_report"]

#: Role -> default topic.
STOP_TOPICS = {"pi2": "/oscillator/pi2", "correction": "/controller/velocity_correction",
               "parameters": "/grazing/parameters"}
_MODEL = ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset")


def stop_data(bag) -> tuple:
    """(OscillatorParams, Pi2 deviations n x 2, corrections n, the recorded stop) of a bag.

    Raises RecordingError naming what is missing (no Pi2 samples, no parameter record)."""
    raw = reader.read_raw(bag, topics=list(STOP_TOPICS.values()))
    sim = _sim_parameters(raw, STOP_TOPICS["parameters"])
    if not sim or any(k not in sim for k in _MODEL):
        raise RecordingError(f"{bag}: no simulator parameter record on "
                             f"{STOP_TOPICS['parameters']} (the model is taken from it)")
    p = OscillatorParams(**{k: float(sim[k]) for k in _MODEL})
    if raw.count(STOP_TOPICS["pi2"]) == 0:
        raise RecordingError(f"{bag}: no messages on {STOP_TOPICS['pi2']} (the Pi2 samples)")
    s = reader.decode_joint_stream(raw, STOP_TOPICS["pi2"])
    ok = s["ok"] & np.isfinite(s["v"])
    order = np.argsort(s["stamp"][ok], kind="stable")
    stamp = s["stamp"][ok][order]
    z = np.column_stack([s["x"][ok][order] - p.x_ref, s["v"][ok][order] - p.v_ref])
    dv = np.zeros(len(stamp))
    if raw.count(STOP_TOPICS["correction"]):
        c = reader.decode_twist_stamped(raw, STOP_TOPICS["correction"])
        at = {int(t): float(d) for t, d, good in zip(c["stamp"], c["dv"], c["ok"]) if good}
        dv = np.array([at.get(int(t), 0.0) for t in stamp])
    recorded = {k: sim.get(k) for k in ("contact", "contact_stiffness", "contact_damping",
                                        "friction", "friction_static") if k in sim}
    return p, z, dv, recorded


def select_bag_stop(bag, stops=STOPS, max_samples: int = 200,
                    oscillator: str = "fit") -> dict:
    """The report of one bag: each candidate's parameters with standard errors (the
    oscillator's with them, ``oscillator="fit"``), -2 log L, BIC, and the one the data
    support, over the first ``max_samples`` Pi2 samples (a joint fit of the three
    candidates costs about 20-60 s per 60 samples on a loaded machine, the stop alone
    2-10 s; docs/theory_contact.md section 17)."""
    p, z, dv, recorded = stop_data(bag)
    z, dv = z[:max_samples], dv[:max_samples]
    best, _, fits = select_stop(p, z, dv, stops, oscillator=oscillator)
    recorded.update({k: getattr(p, k) for k in ("zeta", "omega", "delta_d")})
    return {"bag": str(bag), "samples": int(len(z)), "chosen": best, "recorded": recorded,
            "oscillator": oscillator,
            "candidates": [{"stop": f.stop, "bic": f.bic, "minus_2_log_l": f.minus_2_log_l,
                            "parameters": {n: {"value": f.values[n], "stderr": f.stderr[n]}
                                           for n in f.values}} for f in fits]}


def format_stop_report(report: dict) -> str:
    how = ("the oscillator fitted with each stop" if report.get("oscillator") == "fit"
           else "the oscillator from the record")
    lines = [f"{report['bag']}: {report['samples']} Pi2 samples; the data support: "
             f"{report['chosen']} (least BIC; {how})"]
    for c in report["candidates"]:
        pars = ", ".join(f"{n} = {v['value']:.6g} +- {v['stderr']:.2g}"
                         for n, v in c["parameters"].items())
        lines.append(f"  {c['stop']:<22} BIC {c['bic']:10.1f}  {pars}")
    if report["recorded"]:
        lines.append("  recorded: " + ", ".join(f"{k}={v}" for k, v in report["recorded"].items()))
    return "\n".join(lines)

"""The noise gain over the admissible c2 at several Delta d (issue 15 section 3).

For each Delta d, the noise gain of the degenerate design (c1 from Eq. 38 / (D5)) on a
grid of c2 strictly inside each admissible interval
(:func:`grazing_control.dynamics.design.tuning.design_noise_gain`: the stationary std of the
Pi2 position per unit measurement noise, discrete Lyapunov equation of the loop
linearised about the controlled orbit, docs/robustness.md section 3), and the least
gain (:func:`grazing_control.dynamics.design.tuning.optimize_noise`). Plain data for
:func:`.charts.plot_noise_gain` and the JSON record.
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.dynamics.design.gains import C2_LIMIT, admissible_c2
from grazing_control.dynamics.design.tuning import STUDY_C2, design_noise_gain, optimize_noise
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["noise_gain_curves"]


def _finite_or_none(x):
    return float(x) if math.isfinite(x) else None


def noise_gain_curves(base: OscillatorParams, delta_ds, delay: float = 0.0, points: int = 201):
    """{"delay", "intervals", "curves": [{"delta_d", "c2", "gain", "best", "study"}]}.

    ``gain`` is None where the controlled orbit is not stable at that Delta d (no
    stationary spread); ``best`` the optimum {c2, c1, gain}; ``study`` the gain at
    c2 = STUDY_C2 (None where that c2 has no stable orbit with this delay).
    """
    intervals = admissible_c2(base, delay=delay)
    c2s = []
    for lo, hi in intervals:
        a, b = max(lo, -C2_LIMIT), min(hi, C2_LIMIT)
        c2s.extend(a + (b - a) * (np.arange(points) + 0.5) / points)
    curves = []
    for dd in delta_ds:
        p = base.with_(delta_d=float(dd))
        best = optimize_noise(p, delay)
        curves.append({
            "delta_d": float(dd),
            "c2": [float(c) for c in c2s],
            "gain": [_finite_or_none(design_noise_gain(p, float(c), delay)) for c in c2s],
            "best": {"c2": best.c2, "c1": best.c1, "gain": best.noise_gain},
            "study": _finite_or_none(best.study_noise_gain),
        })
    return {"delay": float(delay), "study_c2": STUDY_C2,
            "intervals": [[_finite_or_none(x) for x in iv] for iv in intervals], "curves": curves}

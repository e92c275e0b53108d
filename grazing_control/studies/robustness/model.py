"""Model-error margins: the band of Delta d next to grazing where control fails, against
the error size, per parameter and design (issue 16 section 2; docs/robustness.md s4).

Plain data from :func:`grazing_control.dynamics.design.mismatch.instability_band` (exact route)
and :func:`grazing_control.dynamics.design.mismatch.predicted_band` (series), for
:func:`.charts.plot_model_bands` and the JSON record.
"""

from __future__ import annotations

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.design.mismatch import instability_band
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["ERRORS", "model_error_bands"]

#: Relative error sizes per parameter (both signs are run): omega near the degenerate
#: frequency is ~1e5 times more sensitive than zeta; r does not enter N_g at all.
ERRORS = {
    "zeta": (1e-3, 3e-3, 1e-2, 3e-2, 1e-1),
    "omega": (1e-5, 3e-5, 1e-4, 3e-4, 1e-3),
    "r": (1e-2, 1e-1),
}


def model_error_bands(base: OscillatorParams, designs, errors=None, **band_kwargs):
    """{"designs": [{"label", "c2", "c1", "bands": [{"parameter", "error", "end",
    "predicted", "k"}]}]} with k = end / error^2 (the coefficient of the e^2 law)."""
    errors = ERRORS if errors is None else errors
    out = []
    for label, c2 in designs:
        g = Gains(degenerate_c1(base, c2), c2)
        rows = []
        for name, sizes in errors.items():
            for size in sizes:
                for e in (size, -size):
                    b = instability_band(base, g, name, e, **band_kwargs)
                    rows.append({"parameter": name, "error": e, "end": b.end,
                                 "predicted": b.predicted, "k": b.end / (e * e)})
        out.append({"label": label, "c2": c2, "c1": g.c1, "bands": rows})
    return {"designs": out}

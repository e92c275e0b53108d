"""Model-error margins: the band of Delta d next to grazing where control fails, against
the error size, per parameter and design (issue 16 section 2; docs/robustness.md s4), for
every model (issue 32): the 1-DOF study and an n-DOF model file, one loop over the
designs and errors (:func:`model_error_bands`); the model supplies its design family
(c2 or mu, :mod:`grazing_control.dynamics.design.model_design`), its parameters
(:data:`ERRORS`, :data:`NDOF_ERRORS`) and its extras (the series, or the error tolerated).

Plain data from :func:`grazing_control.dynamics.design.mismatch.instability_band` (exact route)
and :func:`grazing_control.dynamics.design.mismatch.predicted_band` (series), for
:func:`.charts.plot_model_bands` and the JSON record.
"""

from __future__ import annotations

import math

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.design.mismatch import instability_band
from grazing_control.dynamics.maps.model import is_model_file
from grazing_control.oscillator.control import Gains

__all__ = ["ERRORS", "NDOF_ERRORS", "model_error_bands"]

#: Relative error sizes per parameter (both signs are run): omega near the degenerate
#: frequency is ~1e5 times more sensitive than zeta; r does not enter N_g at all.
ERRORS = {
    "zeta": (1e-3, 3e-3, 1e-2, 3e-2, 1e-1),
    "omega": (1e-5, 3e-5, 1e-4, 3e-4, 1e-3),
    "r": (1e-2, 1e-1),
}

#: Relative error sizes of the n-DOF parameters (both signs are run); the masses M[i,i]
#: are added per coordinate by :func:`model_error_bands`.
NDOF_ERRORS = {"M": (1e-3, 1e-2), "C": (1e-2, 1e-1), "K": (1e-3, 1e-2), "r": (1e-2, 1e-1),
               "omega": (1e-4, 1e-3)}


def model_error_bands(model, designs, errors=None, *, delay: float = 0.0, **band_kwargs):
    """{"designs": [{"label", the design, "bands": [{"parameter", "error", "end",
    "predicted", "k", ...}]}]}: per design (label, value) of the model's family the band
    of each parameter error (:func:`instability_band`) and k = end / error^2 (the
    coefficient of the e^2 law). ``errors``: {name: sizes}, both signs run.

    * 1-DOF (OscillatorParams): value = c2, the design c2 and c1 (degenerate, no delay),
      "predicted" the series' band end; default errors :data:`ERRORS`.
    * A model file: value = mu, the design mu and gains k(mu; ``delay``) of the family
      (docs/theory_ndof.md (N2), (N9)), "predicted" None (no series for n > 1) and
      "tolerated" the error the design tolerates at the model's delta_d by the e^2 law
      (None where delta_d >= 0 or no band); default errors :data:`NDOF_ERRORS` plus each
      mass M[i,i] with the sizes of M.
    """
    file = is_model_file(model)
    if errors is None:
        errors = _file_errors(model) if file else ERRORS
    out = []
    for label, value in designs:
        gains, design = _file_design(model, value, delay) if file else _closed_form(model, value)
        rows = []
        for name, sizes in errors.items():
            for size in sizes:
                for e in (size, -size):
                    b = instability_band(model, gains, name, e, delay=delay, **band_kwargs)
                    row = {"parameter": name, "error": e, "end": b.end,
                           "predicted": None if file else b.predicted, "k": b.end / (e * e)}
                    if file:
                        row["tolerated"] = _tolerated(model, b.end, e)
                    rows.append(row)
        out.append({"label": label, **design, "bands": rows})
    return {"designs": out}


def _closed_form(p, c2: float) -> tuple:
    """The 1-DOF design of c2 (c1 degenerate): (Gains, its JSON fields)."""
    g = Gains(degenerate_c1(p, c2), c2)
    return g, {"c2": c2, "c1": g.c1}


def _file_design(model, mu: float, delay: float) -> tuple:
    """A model file's family member k(mu; delay): (k, its JSON fields)."""
    from grazing_control.dynamics.design.family import gain_family

    k = gain_family(model, mu, delay)
    return k, {"mu": mu, "gains": [float(x) for x in k]}


def _file_errors(model) -> dict:
    """:data:`NDOF_ERRORS` and each mass M[i,i] with the sizes of M (n > 1)."""
    errors = dict(NDOF_ERRORS)
    if model.n > 1:
        errors.update({f"M[{i},{i}]": NDOF_ERRORS["M"] for i in range(model.n)})
    return errors


def _tolerated(model, end: float, error: float):
    """The error the design tolerates at the model's delta_d by the e^2 law (None where
    delta_d >= 0 or there is no band)."""
    from grazing_control.dynamics.design.mismatch import tolerated_error

    if not model.delta_d < 0.0:
        return None
    tol = tolerated_error(end, error, model.delta_d)
    return None if math.isinf(tol) else tol

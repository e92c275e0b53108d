"""Model-error margins: the band of Delta d next to grazing where control fails, against
the error size, per parameter and design (issue 16 section 2; docs/robustness.md s4), for
the 1-DOF study and (issue 32) for an n-DOF model file (:func:`ndof_model_error_bands`).

Plain data from :func:`grazing_control.dynamics.design.mismatch.instability_band` (exact route)
and :func:`grazing_control.dynamics.design.mismatch.predicted_band` (series), for
:func:`.charts.plot_model_bands` and the JSON record.
"""

from __future__ import annotations

from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.design.mismatch import instability_band
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["ERRORS", "NDOF_ERRORS", "model_error_bands", "ndof_model_error_bands"]

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


#: Relative error sizes of the n-DOF parameters (both signs are run); the masses M[i,i]
#: are added per coordinate by :func:`ndof_model_error_bands`.
NDOF_ERRORS = {"M": (1e-3, 1e-2), "C": (1e-2, 1e-1), "K": (1e-3, 1e-2), "r": (1e-2, 1e-1),
               "omega": (1e-4, 1e-3)}


def ndof_model_error_bands(model, mus, delay: float = 0.0, errors=None, **band_kwargs):
    """{"designs": [{"label", "mu", "gains", "bands": [{"parameter", "error", "end",
    "predicted" (None: no series for n > 1), "k", "tolerated"}]}]} for the n-DOF
    ``model``: per design k(mu; delay) of the family (docs/theory_ndof.md (N2), (N9)),
    the band of each parameter error (:func:`instability_band` over the exact n-DOF
    branch), k = end / error^2 and ``tolerated`` the error the design tolerates at the
    model's delta_d by the e^2 law (None where delta_d >= 0). ``errors``: {name: sizes}
    (default :data:`NDOF_ERRORS` plus each mass M[i,i] with the sizes of M)."""
    import math

    from grazing_control.dynamics.design.mismatch import tolerated_error
    from grazing_control.dynamics.design.family import gain_family

    if errors is None:
        errors = dict(NDOF_ERRORS)
        if model.n > 1:
            errors.update({f"M[{i},{i}]": NDOF_ERRORS["M"] for i in range(model.n)})
    out = []
    for mu in mus:
        k = gain_family(model, mu, delay)
        rows = []
        for name, sizes in errors.items():
            for size in sizes:
                for e in (size, -size):
                    b = instability_band(model, k, name, e, delay=delay, **band_kwargs)
                    tol = tolerated_error(b.end, e, model.delta_d) if model.delta_d < 0.0 else None
                    rows.append({"parameter": name, "error": e, "end": b.end, "predicted": None,
                                 "k": b.end / (e * e),
                                 "tolerated": None if tol is None or math.isinf(tol) else tol})
        out.append({"label": f"mu = {mu:g}", "mu": mu, "gains": [float(x) for x in k],
                    "bands": rows})
    return {"designs": out}

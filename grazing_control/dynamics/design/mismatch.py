"""Model error: gains designed on a nominal model acting on a mismatched plant (issue 16 s2).

The plant is the nominal model with one parameter off by a relative error e (zeta,
omega or r: ``p.with_(name=value (1 + e))``); the controller keeps the gains
(c1, c2) designed on the nominal model (Eq. 38 / (D5)) and samples at the plant's Pi2
with the plant's X** (the reference is exact: only the gains carry the error; as
``grazing orbit --zeta ... --c1 ... --c2 ...``). Derivation in docs/theory_mismatch.md:

* N_g does not involve r, so an error in r leaves N_g,12 = 0: no singular multiplier
  (lambda0 moves, bounded). Errors in zeta or omega give N_g,12 = e n' + O(e^2) != 0,
  and with it the singular term chi_m1 / delta2 of the trace (theory_zdm.md (P6)),
  chi_m1 = -(1 + r) alpha* N_g,12.
* The near-grazing orbit loses stability where tr J reaches +-(1 + psi0), at
  delta2* = |chi_m1| / (1 + psi0 -+ chi0) = O(e), i.e. at
  Delta d* = kappa1 delta2* + kappa2 delta2*^2 = O(e^2) (kappa1 ~ N_g,12 too): the
  **band** (Delta d*, 0) of Delta d next to grazing where control fails has a width
  proportional to e^2 (:func:`predicted_band`), on the side of d < d* for one sign of
  the error only.

:func:`instability_band` measures the band by the exact route: the largest Floquet
multiplier of the controlled 1/1 orbit (:func:`grazing_control.dynamics.orbits.orbits.orbit_11`
of the mismatched plant with the nominal gains) on a logarithmic grid of Delta d from
``ceiling`` towards grazing, the band's outer end bisected in log |Delta d|.

For n > 1 (issue 32; docs/theory_mismatch.md section 5) the same band is measured over
the exact n-DOF map: the nominal model is an :class:`~grazing_control.oscillator.ndof.NdofModel`,
the plant has a whole matrix (``M``, ``C``, ``K``), one symmetric pair of entries
(``M[i,j]``, ``C[i,j]``, ``K[i,j]``, 0-based), ``r`` or ``omega`` off by (1 + e)
(:func:`mismatched_model`), the gains are the nominal design's k (the kick k^T z on
Pi2), and the multipliers are those of the controlled 1/1 orbit of the plant
(dynamics/orbits/modal_branch.py: the exact branch, its structured multipliers, and the
certified check that the period has no other contact). There is no series for n > 1:
``predicted`` is nan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.impact import ImpactCapError, InitialStateError
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11
from grazing_control.dynamics.maps.perturbation import series_coefficients

__all__ = ["PARAMETERS", "MODEL_PARAMETERS", "mismatched", "mismatched_model",
           "largest_multiplier", "model_largest_multiplier", "Band", "instability_band",
           "predicted_band", "tolerated_error", "delay_margin"]

#: The parameters an error is put on.
PARAMETERS = ("zeta", "omega", "r")
#: The n-DOF parameters (besides entries ``M[i,j]``, ``C[i,j]``, ``K[i,j]``).
MODEL_PARAMETERS = ("M", "C", "K", "r", "omega")


def mismatched(p: OscillatorParams, name: str, error: float) -> OscillatorParams:
    """The plant: ``p`` with parameter ``name`` multiplied by (1 + error)."""
    if name not in PARAMETERS:
        raise ParameterError(f"name={name!r} is invalid: valid values are {', '.join(PARAMETERS)}")
    if not (math.isfinite(error) and error > -1.0):
        raise ParameterError(f"error={error!r} is invalid: valid range is a relative error > -1")
    return p.with_(**{name: getattr(p, name) * (1.0 + error)})


def _relative_error(error: float) -> float:
    if isinstance(error, bool) or not isinstance(error, (int, float, np.floating)) or \
            not (math.isfinite(error) and error > -1.0):
        raise ParameterError(f"error={error!r} is invalid: valid range is a relative error > -1")
    return float(error)


def mismatched_model(model, name: str, error: float):
    """The n-DOF plant: ``model`` with ``name`` multiplied by (1 + error): a whole matrix
    ``M``, ``C``, ``K``; the symmetric pair of entries ``X[i,j]`` and ``X[j,i]`` of one
    (0-based); ``r``; ``omega``. Delta d stays relative to the plant's own d*, as in
    :func:`mismatched`. Raises ParameterError naming ``name`` or ``error``, or the
    model field that the change makes invalid (e.g. K no longer semi-definite)."""
    import dataclasses
    import re

    error = _relative_error(error)
    if name in ("r", "omega"):
        return dataclasses.replace(model, **{name: getattr(model, name) * (1.0 + error)})
    m = re.fullmatch(r"([MCK])(?:\[(\d+),(\d+)\])?", name) if isinstance(name, str) else None
    if m is None or (m.group(2) is not None and
                     not (int(m.group(2)) < model.n and int(m.group(3)) < model.n)):
        raise ParameterError(
            f"name={name!r} is invalid: valid values are {', '.join(MODEL_PARAMETERS)} and "
            f"M[i,j], C[i,j], K[i,j] with 0 <= i, j < {model.n}")
    field = m.group(1)
    a = np.array(getattr(model, field), dtype=float)
    if m.group(2) is None:
        a = a * (1.0 + error)
    else:
        i, j = int(m.group(2)), int(m.group(3))
        a[i, j] *= 1.0 + error
        if i != j:
            a[j, i] *= 1.0 + error
    return dataclasses.replace(model, **{field: a})


def model_largest_multiplier(model, gains, delay: float = 0.0) -> float:
    """max |lambda| of the controlled 1/1 orbit of the n-DOF ``model`` at its delta_d
    (dynamics/orbits/modal_branch.py: ``orbit_at``); +inf where there is none, or where the
    period has another contact. Without a delay the branch's structured multipliers
    (``branch_multipliers``) and the certified ``other_contacts``; with one (the kick
    ``delay`` after Pi2, docs/theory_ndof.md section 14) one step of the exact delayed
    map from the orbit's Pi2 state (dynamics/maps/modal_map.py): exactly one impact, back
    to the start within 1e-9 of the state's scale, and the eigenvalues of its Jacobian
    (D3)."""
    from grazing_control.dynamics.maps.modal_map import ModalMap
    from grazing_control.dynamics.orbits import modal_branch

    try:
        point = modal_branch.orbit_at(model, gains, model.delta_d, delay=delay)
        if delay == 0.0:
            if modal_branch.other_contacts(model, gains, point) != 0:
                return math.inf
            return float(np.max(np.abs(modal_branch.branch_multipliers(model, gains, point))))
        step = ModalMap(model, gains, delay).step(point.pi2_state, jacobian=True)
        scale = 1.0 + float(np.max(np.abs(point.pi2_state)))
        if len(step.impacts) != 1 or not np.max(np.abs(step.state - point.pi2_state)) <= 1e-9 * scale:
            return math.inf
        return float(np.max(np.abs(np.linalg.eigvals(step.jacobian))))
    except (ImpactCapError, InitialStateError, ValueError, ArithmeticError, RuntimeError):
        return math.inf


def largest_multiplier(p: OscillatorParams, gains: Gains) -> float:
    """max |lambda| of the controlled 1/1 orbit at ``p.delta_d``; +inf where there is none."""
    try:
        return float(np.max(np.abs(orbit_11(p, gains).multipliers)))
    except (OrbitNotFound, ImpactCapError, InitialStateError, ValueError, ArithmeticError):
        return math.inf


def delay_margin(p: OscillatorParams, c1: float, c2: float, upper: float, *,
                 steps: int = 16, iterations: int = 12) -> float:
    """The least actuation delay in [0, ``upper``] at which the gains (c1, c2) lose the
    controlled 1/1 orbit at ``p.delta_d``: its largest Floquet multiplier reaches 1, or
    there is no such orbit (:func:`largest_multiplier` of ``Gains(c1, c2, delay)``, the
    exact route; docs/theory_delay.md). A correction that acts some time after its
    section (on arrival, a realtime answer's latency x time_scale) is one designed for
    another delay: the degenerate condition (D5) holds at its own delay only, and near
    grazing the rest of the multipliers' margin goes fast. The grid of ``steps`` delays
    up to ``upper`` is scanned from 0 and the first crossing bisected ``iterations``
    times; inf when the orbit is stable at every delay of the grid (a narrower unstable
    window between two of its points is not seen)."""
    if not (math.isfinite(upper) and upper >= 0.0):
        raise ParameterError(f"upper={upper!r} is invalid: valid range is a finite delay >= 0")

    def lost(delay: float) -> bool:
        return not largest_multiplier(p, Gains(c1, c2, delay)) < 1.0

    grid = np.linspace(0.0, upper, steps + 1)
    if lost(0.0):
        return 0.0
    for lo, hi in zip(grid[:-1], grid[1:]):
        if lost(float(hi)):
            lo, hi = float(lo), float(hi)
            for _ in range(iterations):
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if lost(mid) else (mid, hi)
            return hi
    return math.inf


@dataclass(frozen=True)
class Band:
    """The band (end, 0) of Delta d next to grazing where control fails.

    end : its outer end (< 0), 0.0 where the orbit is stable down to -floor (no band),
        -ceiling where it fails over the whole range. predicted : :func:`predicted_band`.
    multipliers : (Delta d, max |lambda|) of the scan, nearest to grazing last.
    """

    parameter: str
    error: float
    end: float
    predicted: float
    floor: float
    ceiling: float
    multipliers: tuple


def predicted_band(plant: OscillatorParams, gains: Gains) -> float:
    """Delta d* of the series (limit truncation, theory_zdm.md (P3), (P6)): where a root
    of lambda^2 - (chi_m1 / delta2 + chi0) lambda + psi0 crosses -1 or +1, the outer one
    with Delta d < 0; 0.0 where none (docs/theory_mismatch.md)."""
    c = series_coefficients(plant, gains)
    ends = []
    for s in (1.0, -1.0):  # s = 1: root -1 (tr = -(1 + psi0)); s = -1: root +1
        den = 1.0 + c.psi0 + s * c.chi0
        d2 = -s * c.chi_m1 / den if den != 0.0 else math.nan
        if d2 > 0.0:
            dd = c.kappa1 * d2 + c.kappa2 * d2 * d2
            if dd < 0.0:
                ends.append(dd)
    return min(ends) if ends else 0.0


def instability_band(nominal, gains, name: str, error: float, *,
                     floor: float = 1e-14, ceiling: float = 1e-2, per_decade: int = 4,
                     rtol: float = 1e-3, delay: float = 0.0) -> Band:
    """The band of Delta d next to grazing where the mismatched plant's controlled orbit
    fails (max |lambda| >= 1, or no 1/1 orbit), exact route (module docstring).

    ``nominal`` is OscillatorParams with :class:`Gains`, or an n-DOF model with its gain
    vector k (2n) acting ``delay`` after Pi2 (docs/theory_ndof.md section 14; n-DOF
    only: a 1-DOF delay is part of its Gains). The scan runs from -ceiling to -floor; the band is the run of failing
    points that reaches the floor, its outer end bisected in log |Delta d| to ``rtol``
    relative.
    """
    if isinstance(nominal, OscillatorParams):
        plant = mismatched(nominal, name, error)

        def rho(dd):
            return largest_multiplier(plant.with_(delta_d=dd), gains)
        pred = predicted_band(plant, gains)
    else:
        import dataclasses

        from grazing_control.dynamics.maps.modal_map import ModalMap

        plant = mismatched_model(nominal, name, error)
        ModalMap(plant, gains, delay)   # refuses bad gains or delay by name, before the scan

        def rho(dd):
            return model_largest_multiplier(dataclasses.replace(plant, delta_d=dd), gains, delay)
        pred = math.nan
    end, scan = _band_end(rho, floor, ceiling, per_decade, rtol)
    return Band(name, error, end, pred, floor, ceiling, scan)


def _band_end(rho, floor: float, ceiling: float, per_decade: int, rtol: float):
    """(end, scan) of :func:`instability_band` for the largest multiplier ``rho(Delta d)``."""
    n = int(round(per_decade * math.log10(ceiling / floor))) + 1
    dds = -np.logspace(math.log10(ceiling), math.log10(floor), n)
    rhos = [rho(float(d)) for d in dds]
    fails = [not r < 1.0 for r in rhos]
    scan = tuple((float(d), float(r)) for d, r in zip(dds, rhos))
    if not fails[-1]:
        return 0.0, scan
    k = len(fails) - 1
    while k > 0 and fails[k - 1]:
        k -= 1
    if k == 0:
        return float(dds[0]), scan
    stable, failing = math.log10(-dds[k - 1]), math.log10(-dds[k])
    while stable - failing > rtol / math.log(10.0):
        mid = 0.5 * (stable + failing)
        if rho(-10.0 ** mid) < 1.0:
            stable = mid
        else:
            failing = mid
    return -10.0 ** failing, scan


def tolerated_error(band_end: float, error: float, delta_d: float) -> float:
    """The relative error that the design tolerates at ``delta_d`` (< 0), from one band
    end by the e^2 law (docs/theory_mismatch.md (M1)): |e| sqrt(delta_d / end); inf where
    the error opens no band."""
    if band_end == 0.0:
        return math.inf
    return abs(error) * math.sqrt(delta_d / band_end)

"""The 1/1 orbit and its branch in Delta d, one entry for every model (issue 32).

What a caller asks of the 1/1 orbit is the same for every model: the orbit at a wall
offset Delta d (its Pi2 state, impact phase and velocity v-, Floquet multipliers, which
branch it lies on), and the branch over a range of Delta d with the bifurcations on it.
The model supplies the route (:func:`grazing_control.dynamics.maps.model.is_model_file`):

* the 1-DOF oscillator (:class:`OscillatorParams`, its :class:`Gains` carrying the
  actuation delay): the closed form explicit in the impact phase, certified and fast
  (:func:`.orbits.orbit_11`, :func:`.continuation.continue_11`; docs/theory.md §5),
  every number the same bit for bit (tests/test_one_one.py);
* a model file of any n (:class:`NdofModel`, gains the vector k, ``delay`` the
  actuation delay, ``width`` the width of the force pulse that carries the correction):
  the branch explicit in the impact phase with its factored monodromy and global check
  (:mod:`.modal_branch`), else Newton shooting from the local map's prediction on the
  exact map ``ModalMap(model, k, delay, width)`` (:mod:`.near_grazing`;
  docs/theory_ndof.md §5, §14, §18).

The 1-DOF closed form runs the kick only: a pulse there is refused (one line naming
``width``; the n = 1 model file config/models/study_1dof.yaml is the same oscillator).

For n = 1 the two routes give the same orbit to 1e-12 (tests/test_one_one.py,
tests/test_n1_model_file.py): the model is the difference, not the caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from grazing_control.oscillator.control import Gains

from grazing_control.dynamics.maps.model import is_model_file
from grazing_control.dynamics.orbits.continuation import OrbitBifurcation, OrbitPoint

__all__ = ["Orbit11", "Branch11", "orbit", "branch", "continuation_values", "CLOSED_FORM",
           "EXPLICIT"]

#: The route of an orbit of the 1-DOF closed form (:attr:`Orbit11.route`).
CLOSED_FORM = "impact phase (closed form)"
#: The route of an orbit of a model file's branch explicit in the impact phase.
EXPLICIT = "impact phase (the branch explicit in psi)"


@dataclass(frozen=True)
class Orbit11:
    """A 1/1 orbit, the same for every model.

    Attributes
    ----------
    delta_d : the wall offset.
    state : the Pi2 deviation from the grazing orbit (before the kick), length 2n.
    physical : the Pi2 state itself.
    multipliers : Floquet multipliers, decreasing modulus.
    monodromy : the Jacobian of one period (at the impact for the 1-DOF closed form, at
        Pi2 for a model file: similar matrices, the same multipliers).
    impact_dt, impact_phase, v_minus : the impact's time after the sample, its forcing
        phase in [0, 2 pi) and its velocity.
    branch : which part of the 1/1 solutions it lies on (:data:`.orbits.BRANCHES`):
        'grazing' (born at grazing), 'grazing past a fold', or 'other'.
    route : how it was found: :data:`CLOSED_FORM`, :data:`EXPLICIT`, or the starting
        guess of a shooting (a model file away from its explicit branch).
    prediction_offset : a model file's relative distance to the local map's prediction
        (inf without one, and for the 1-DOF closed form).
    """

    delta_d: float
    state: np.ndarray
    physical: np.ndarray
    multipliers: np.ndarray
    monodromy: np.ndarray = field(repr=False)
    impact_dt: float
    impact_phase: float
    v_minus: float
    branch: str
    route: str
    prediction_offset: float = math.inf

    @property
    def stable(self) -> bool:
        """All multipliers strictly inside the unit circle."""
        return bool(np.max(np.abs(self.multipliers)) < 1.0)

    @property
    def near_grazing(self) -> bool:
        """The orbit is on the branch born at grazing (before or past a fold)."""
        return self.branch != "other"


def orbit(model, gains=None, delta_d: float | None = None, *, delay: float = 0.0,
          width: float = 0.0, check: bool = True, branch: str = "any",
          extra_guesses=()) -> Orbit11:
    """The 1/1 orbit at ``delta_d`` (default the model's).

    ``gains``: a 1-DOF :class:`Gains` (its ``delay`` the actuation delay; a nonzero
    ``delay`` here replaces it), or a model file's gain vector k (``delay`` the actuation
    delay, docs/theory_ndof.md §14; ``width`` > 0: the correction is the force pulse of
    that width centred ``delay`` after the sample, §15, §18); None: uncontrolled.
    ``check`` and ``branch``: the 1-DOF closed form's (:func:`.orbits.orbit_11`: the
    flow's check of the orbit, and 'grazing' for the branch born at grazing only);
    ``extra_guesses``: a model file's further starting guesses for shooting
    (:func:`.near_grazing.model_file_orbit`).

    Raises :class:`.orbits.OrbitNotFound` where there is none; ParameterError for a pulse
    of the 1-DOF closed form or a width that is not finite and >= 0.
    """
    if is_model_file(model):
        from grazing_control.dynamics.orbits.near_grazing import model_file_orbit

        return model_file_orbit(model, gains, delta_d, extra_guesses=extra_guesses,
                                delay=_actuation(delay, width, gains))
    _closed_form_kick(width)
    from grazing_control.dynamics.orbits.orbits import orbit_11

    p = model if delta_d is None else model.with_(delta_d=float(delta_d))
    o = orbit_11(p, _delayed(gains, delay), check=check, branch=branch)
    imp = o.impacts[0]
    return Orbit11(o.params.delta_d, np.array(o.pi2_deviation), np.array(o.pi2),
                   o.multipliers, o.monodromy, imp.dt, o.impact_phase, o.v_minus, o.branch,
                   CLOSED_FORM)


def _actuation(delay: float, width: float, gains):
    """A model file's ``delay`` argument of :mod:`.near_grazing` and :mod:`.modal_branch`:
    the kick's delay, or the ideal pulse as an ``Actuation(delay, width)``
    (``family.design_actuation``: width checked finite and >= 0); 0 uncontrolled."""
    from grazing_control.dynamics.design.family import design_actuation

    actuation = design_actuation(float(delay), pulse_width=float(width))
    return 0.0 if gains is None else actuation


def _closed_form_kick(width: float) -> None:
    """The 1-DOF closed form runs the kick: a pulse width other than 0 is refused in one
    line (module docstring)."""
    if width != 0.0:
        from grazing_control.oscillator.params import ParameterError

        raise ParameterError(f"width={width!r} is invalid for the 1-DOF oscillator's 1/1 "
                             "orbit: its closed form runs the kick (valid: 0); the pulse's "
                             "orbit is the n = 1 model file's (config/models/study_1dof.yaml)")


def _delayed(gains, delay: float):
    """The 1-DOF gains with the actuation ``delay`` when one is given (else as they are)."""
    if gains is None or not delay:
        return gains
    return Gains(gains.c1, gains.c2, float(delay))


def continuation_values(start: float, stop: float, points: int) -> np.ndarray:
    """Delta d from ``start`` to ``stop``: log-spaced in |Delta d| when both have one sign
    (points crowd towards grazing; ``stop`` = 0: down to 1e-12 |start|), else linear:
    the grid of :func:`branch`, the same for every model."""
    from grazing_control.oscillator.params import ParameterError

    if points < 2:
        raise ParameterError(f"points={points!r} is invalid: valid range is points >= 2")
    if start == stop:
        raise ParameterError("--from and --to must differ")
    if start != 0.0 and stop == 0.0:
        stop = start * 1e-12
    if start * stop > 0.0:
        return math.copysign(1.0, start) * np.geomspace(abs(start), abs(stop), points)
    return np.linspace(start, stop, points)


@dataclass(frozen=True)
class Branch11:
    """The 1/1 branch over Delta d (:func:`branch`): its points in the order continued
    (:class:`.continuation.OrbitPoint`: value = Delta d, the Pi2 deviation, multipliers,
    impacts, v-), the bifurcations between them (:class:`.continuation.OrbitBifurcation`),
    why it stopped ('end' of the values, else the reason), the route ('impact phase':
    every point exact to rounding; 'shooting'), a model file's orbit at the first value,
    and a fold beyond the last point (:func:`.near_grazing.fold_beyond`; None for the
    1-DOF closed form, which passes folds in psi)."""

    points: list
    bifurcations: list
    stopped: str
    route: str
    first: Orbit11 | None = None
    fold: dict | None = None


def branch(model, gains, start: float, stop: float, points: int, *,
           delay: float = 0.0, width: float = 0.0) -> Branch11:
    """The 1/1 branch born at grazing at the Delta d of :func:`continuation_values`
    (``start`` to ``stop``, ``points``), with its multipliers and bifurcations.

    The 1-DOF closed form (:func:`.continuation.continue_11`: every point checked by the
    flow, a 'grazing' bifurcation where an end is Delta d = 0); a model file: the branch
    explicit in the impact phase where the orbit at ``start`` lies on it
    (:func:`.modal_branch.continue_branch`, exact to rounding whatever v-), else
    continuation by shooting over the exact map (:func:`.continuation.continue_orbit`),
    and the fold where it stopped short of ``stop`` (:func:`.near_grazing.fold_beyond`).
    ``gains``, ``delay`` and ``width`` as in :func:`orbit`.
    """
    values = continuation_values(start, stop, points)
    if is_model_file(model):
        return _model_file_branch(model, gains, values, _actuation(delay, width, gains))
    _closed_form_kick(width)
    from grazing_control.dynamics.orbits.continuation import continue_11
    from grazing_control.dynamics.orbits.orbits import _orbit_from_phase

    g = _delayed(gains, delay)
    found = continue_11(model, start, stop, g, points=points, check=True, values=values)
    pts = [OrbitPoint(b.delta_d,
                      np.array(_orbit_from_phase(model, b.psi, g, check=False).pi2_deviation),
                      b.multipliers, 1, b.v_minus) for b in found.points]
    bifs = [OrbitBifurcation(b.type, b.delta_d, b.multipliers) for b in found.bifurcations]
    return Branch11(pts, bifs, "end", "impact phase")


def _model_file_branch(model, gains, values, delay) -> Branch11:
    """A model file's branch (:func:`branch`); ``delay`` the kick's delay or the pulse's
    ``Actuation`` (:func:`_actuation`)."""
    import dataclasses

    from grazing_control.dynamics.orbits.continuation import continue_orbit
    from grazing_control.dynamics.orbits.modal_branch import continue_branch
    from grazing_control.dynamics.orbits.near_grazing import (closed_loop_map, fold_beyond,
                                                              model_file_orbit)

    model = dataclasses.replace(model, delta_d=float(values[0]))
    first = model_file_orbit(model, gains, delay=delay)
    # the branch born at grazing: explicit in the impact phase, every point exact to
    # rounding (issue 32: shooting returned points 1e-2 off near |Delta d| = 3e-8); with
    # a delay or a pulse the delayed kick's or the pulse's, its impacts after the
    # correction has acted (docs/theory_ndof.md §14, §18)
    explicit = first.route == EXPLICIT
    found = continue_branch(model, gains, values, delay=delay) if explicit else \
        continue_orbit(closed_loop_map(model, gains, delay), "delta_d", values, first.state)
    fold = fold_beyond(model, gains, found, float(values[-1]), delay)
    return Branch11(found.points, found.bifurcations, found.stopped,
                    "impact phase" if explicit else "shooting", first, fold)

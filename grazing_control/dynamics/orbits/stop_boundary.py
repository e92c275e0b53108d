"""Where the rigid design stops working on a compliant stop (issue 31 part 3;
docs/theory_contact.md sections 15 and 19).

The designer knows the stop's restitution r and ignores its compliance and any friction:
the gains are the rigid design at r (c1 of Eq. 38 for the given c2,
:func:`grazing_control.dynamics.design.gains.degenerate_c1`). The controlled 1/1 orbit of
the compliant model (:class:`~grazing_control.dynamics.maps.compliant_model.CompliantOneDOF`:
Kelvin-Voigt at fixed restitution, i.e. fixed contact damping ratio (Eq. C3), with
optional Coulomb friction; or Hertz / Hunt-Crossley at fixed alpha) is continued in
``log10_stiffness`` from the stiff end by
:func:`~grazing_control.dynamics.orbits.continuation.continue_orbit`, started from the
rigid controlled orbit; every crossing of the unit circle it reports (period doubling,
fold, Neimark-Sacker: zeros of its test functions, located by Brent in the parameter) is
returned with the side on which the largest multiplier exceeds 1, together with the
largest multiplier along the branch and where the branch ends (the orbit stops existing,
grazes, or changes its number of contacts a period).

One function, :func:`stop_boundary`, for ``grazing stop --boundary`` (cli/stop.py) and the
chart (benchmarks/chart_contact.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["Crossing", "StopBoundary", "stop_boundary", "rigid_design_plant", "LAWS",
           "STATIC_RATIO", "STIFF", "SOFT"]

#: the stop laws: Kelvin-Voigt (at fixed restitution) and Hertz / Hunt-Crossley (fixed alpha)
LAWS = ("kelvin_voigt", "hertz")
#: F_s / F_f where the static level is not given (the chart's, section 15)
STATIC_RATIO = 1.2
#: the default range of k_c (the stop's stiffness over the oscillator's)
STIFF, SOFT = 1e8, 1e1
#: what a multiplier crossing the unit circle means, by the continuation's test
_CROSSES = {"period-doubling": "a multiplier crosses -1 (period doubling)",
            "fold": "a multiplier crosses +1 (fold)",
            "neimark-sacker": "a complex pair crosses the unit circle (Neimark-Sacker)"}


@dataclass(frozen=True)
class Crossing:
    """A multiplier of the controlled orbit on the unit circle at ``log10_stiffness``:
    ``type`` as the continuation reports it; ``fails`` 'above' where the largest
    multiplier exceeds 1 on the stiffer side (the rigid design fails for k_c above
    it), 'below' on the softer side, None where it does on both or neither
    (another multiplier decides); ``rho`` the largest |multiplier| at the branch's
    neighbours (stiffer, softer)."""

    type: str
    log10_stiffness: float
    multipliers: np.ndarray
    fails: str | None
    rho: tuple

    @property
    def stiffness(self) -> float:
        return 10.0 ** self.log10_stiffness

    def sentence(self) -> str:
        """One line: 'the rigid design fails for k_c > 19.61 (log10 k_c = 1.292396): a
        multiplier crosses -1 (period doubling)'."""
        at = f"{self.stiffness:.4g} (log10 k_c = {self.log10_stiffness:.6f})"
        what = _CROSSES.get(self.type, self.type)
        if self.fails == "above":
            return f"the rigid design fails for k_c > {at}: {what}"
        if self.fails == "below":
            return f"the rigid design fails for k_c < {at}: {what}"
        return (f"at k_c = {at} {what}; the largest multiplier is {self.rho[0]:.3f} above "
                f"and {self.rho[1]:.3f} below it")


@dataclass(frozen=True)
class StopBoundary:
    """The answer of :func:`stop_boundary`: the crossings (stiff to soft); the largest
    |multiplier| along the branch and its log10 k_c; the branch's ``start`` and ``end``
    (log10 k_c of its first and last orbit), its contacts a period there, why it stopped
    ('end': the range's end reached; else the continuation's reason), a located
    'grazing' end (log10 k_c) or None; the gains (c1, c2) and the stop law's description;
    and the continued branch itself (:class:`~.continuation.OrbitBranch`)."""

    crossings: tuple
    rho_max: float
    rho_max_at: float
    start: float
    end: float
    contacts: tuple
    stopped: str
    grazing: float | None
    gains: tuple
    law: dict
    branch: object

    @property
    def complete(self) -> bool:
        """The branch spans the whole range requested."""
        return self.stopped == "end"

    def at(self, stiffness: float):
        """The branch's point nearest to k_c = ``stiffness`` on the same side of every
        crossing (its multipliers stand for that k_c's), or None outside the branch."""
        lk = math.log10(stiffness)
        pts = self.branch.points
        if not pts or not min(q.value for q in pts) <= lk <= max(q.value for q in pts):
            return None
        same = [q for q in pts
                if all((q.value - c.log10_stiffness) * (lk - c.log10_stiffness) > 0.0
                       for c in self.crossings)]
        return min(same or pts, key=lambda q: abs(q.value - lk))

    def lines(self, lo: float, hi: float) -> list:
        """The report, one line per crossing, or the 'none' line; then the branch's end
        where it did not reach the range's (``lo``, ``hi``: the range of k_c)."""
        rng = f"[{_k(min(lo, hi))}, {_k(max(lo, hi))}]"
        if not self.branch.points:
            return [f"no controlled 1/1 orbit of the compliant model near the rigid one at "
                    f"k_c = {_k(max(lo, hi))}: {self.stopped}"]
        out = [c.sentence() for c in self.crossings]
        touch = {0: "it does not touch the stop (0 contacts a period)",
                 1: "1 contact a period"}.get(self.contacts[0],
                                              f"{self.contacts[0]} contacts a period")
        rhos = [_rho(q.multipliers) for q in self.branch.points]
        if not out and min(rhos) > 1.0:
            out.append(f"no crossing in {rng}: the rigid design fails over the whole branch "
                       f"(the largest multiplier >= {min(rhos):.3f}); the controlled orbit: "
                       f"{touch}")
        elif not out and max(rhos) >= 1.0:
            out.append(f"the largest multiplier passes 1 on {rng} (between {min(rhos):.3f} and "
                       f"{max(rhos):.3f}) where the continuation located no crossing")
        if not out:
            out.append(f"none in {rng}: the largest multiplier stays <= {self.rho_max:.3f} "
                       f"(at k_c = {_k(10.0 ** self.rho_max_at)})"
                       + ("" if self.complete else
                          f" down to k_c = {_k(10.0 ** self.end)}, where the branch ends")
                       + f"; the controlled orbit: {touch}")
        if not self.complete:
            why = (f"it grazes at k_c = {10.0 ** self.grazing:.4g}" if self.grazing is not None
                   else self.stopped)
            out.append(f"the controlled 1/1 orbit (contacts a period: {self.contacts[0]}) "
                       f"ends at k_c = {10.0 ** self.end:.4g} (log10 k_c = {self.end:.6f}): "
                       f"{why}")
        return out

    def as_dict(self) -> dict:
        """Plain JSON (``grazing stop --boundary --json``)."""
        return {
            "crossings": [{"type": c.type, "log10_stiffness": c.log10_stiffness,
                           "stiffness": c.stiffness, "fails": c.fails,
                           "rho_stiffer": c.rho[0], "rho_softer": c.rho[1],
                           "multipliers": [[float(z.real), float(z.imag)]
                                           for z in np.asarray(c.multipliers, complex)]}
                          for c in self.crossings],
            "rho_max": _plain(self.rho_max), "rho_max_log10_stiffness": _plain(self.rho_max_at),
            "branch": {"start_log10_stiffness": _plain(self.start),
                       "end_log10_stiffness": _plain(self.end),
                       "contacts_start": self.contacts[0], "contacts_end": self.contacts[1],
                       "complete": self.complete, "stopped": self.stopped,
                       "grazing_log10_stiffness": self.grazing,
                       "points": len(self.branch.points)},
            "gains": {"c1": self.gains[0], "c2": self.gains[1]},
            "law": self.law,
        }


def rigid_design_plant(p: OscillatorParams, c2: float, law: str = "kelvin_voigt", *,
                       friction: float = 0.0, friction_static: float | None = None,
                       alpha: float | None = None, restitution: float | None = None,
                       stiffness: float = STIFF):
    """(the compliant model with the rigid design's gains at k_c = ``stiffness``, the
    rigid model's controlled 1/1 orbit). The design is made for ``p.r``; the stop's
    ``restitution`` is r_c (default ``p.r``: the designer knows it): Kelvin-Voigt at
    restitution r_c (Eq. C3, fixed contact damping ratio); Hertz at Hunt-Crossley
    ``alpha``, default (1 - r_c) / v- at the rigid orbit's impact (Eq. C5, section 19). ``friction``: Coulomb F_f (0: none), static level
    ``friction_static`` (default :data:`STATIC_RATIO` F_f). A ParameterError names a
    bad value."""
    from grazing_control.dynamics.design.gains import degenerate_c1
    from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
    from grazing_control.dynamics.maps.model import OneDOF
    from grazing_control.dynamics.orbits.orbits import OrbitNotFound, orbit_11
    from grazing_control.dynamics.orbits.shooting import ShootingFailed, find_periodic
    from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
    from grazing_control.oscillator.control import Gains
    from grazing_control.oscillator.hertz import HuntCrossley

    if law not in LAWS:
        raise ParameterError(f"law={law!r} is invalid: valid values are {', '.join(LAWS)}")
    if not (math.isfinite(friction) and friction >= 0.0):
        raise ParameterError(f"friction={friction!r} is invalid: valid range is F_f >= 0")
    if not p.delta_d < 0.0:
        raise ParameterError(f"delta_d={p.delta_d!r} is invalid: valid range is Delta d < 0 "
                             "(the controlled 1/1 orbit impacts)")
    c1 = degenerate_c1(p, c2)
    if not math.isfinite(c1):
        raise ParameterError(f"c2={c2!r} is invalid: no degenerate design c1 (Eq. 38) for it")
    gains = Gains(c1, c2)
    try:      # shot from the explicit 1/1 orbit (orbits.orbit_11), exact to rounding
        rigid = find_periodic(OneDOF(p, gains), np.asarray(orbit_11(p, gains).pi2_deviation))
    except (OrbitNotFound, ShootingFailed, ValueError, ArithmeticError) as exc:
        raise ParameterError(f"c2={c2!r}: the rigid design has no controlled 1/1 orbit at "
                             f"delta_d={p.delta_d!r} ({exc})") from None
    fr = None
    if friction > 0.0:
        static = STATIC_RATIO * friction if friction_static is None else friction_static
        fr = Coulomb(friction, static)
    rc = p.r if restitution is None else restitution
    if law == "kelvin_voigt":
        stop = KelvinVoigt.from_restitution(stiffness, rc)
    elif alpha is None:
        stop = HuntCrossley.from_restitution(stiffness, rc, rigid.impacts[0].v_minus)
    else:
        stop = HuntCrossley(stiffness, alpha)
    return CompliantOneDOF(p, gains, law=stop, friction=fr), rigid


def _plain(x: float) -> float | None:
    """Standard JSON: nan (no orbit) as null."""
    return x if math.isfinite(x) else None


def _k(k: float) -> str:
    """k_c as written on the command line: 1e8 for a power of ten, else 4 digits."""
    e = math.log10(k)
    return f"1e{round(e)}" if abs(e - round(e)) < 1e-12 else f"{k:.4g}"


def _rho(multipliers) -> float:
    return float(np.max(np.abs(multipliers)))


def stop_boundary(p: OscillatorParams, c2: float, law: str = "kelvin_voigt", *,
                  friction: float = 0.0, friction_static: float | None = None,
                  alpha: float | None = None, restitution: float | None = None,
                  stiffness_range=(STIFF, SOFT),
                  per_decade: int = 2) -> StopBoundary:
    """Where the rigid design (gains for ``c2`` at ``p``'s restitution) stops working on
    the compliant stop ``law``, over k_c in ``stiffness_range`` (stiff end first; the
    default 1e8 down to 1e1).

    The model: :func:`rigid_design_plant` (its keywords ``friction``, ``friction_static``,
    ``alpha``, ``restitution``). The controlled 1/1 orbit is continued in
    log10 k_c from the first end to the second on ``per_decade`` points a decade (plus
    the points the continuation adds where it halves a step), from the rigid orbit (or,
    where the compliant model has no orbit near it at the stiff end, from the grazing
    point X**; none there either: a StopBoundary without points, its lines say so);
    the crossings are the continuation's located bifurcations (Brent in log10 k_c to
    rtol 1e-13 on its test functions). The grid between points is where a pair of
    crossings closer than 1/per_decade decades would be missed.

    Returns
    -------
    StopBoundary
    """
    from grazing_control.dynamics.orbits.continuation import continue_orbit

    ends = [float(k) for k in stiffness_range]
    if len(ends) != 2 or not all(math.isfinite(k) and k > 0.0 for k in ends) or \
            ends[0] == ends[1]:
        raise ParameterError(f"stiffness_range={stiffness_range!r} is invalid: two different "
                             "k_c > 0 (stiff end first)")
    if not (isinstance(per_decade, int) and per_decade >= 1):
        raise ParameterError(f"per_decade={per_decade!r} is invalid: valid range is an "
                             "integer >= 1")
    a, b = (math.log10(k) for k in ends)
    model, rigid = rigid_design_plant(p, c2, law, friction=friction,
                                      friction_static=friction_static, alpha=alpha,
                                      restitution=restitution, stiffness=ends[0])
    n = max(2, int(math.ceil(abs(a - b) * per_decade)) + 1)
    grid = np.linspace(a, b, n)
    branch = continue_orbit(model, "log10_stiffness", grid, rigid.state)
    if not branch.points:     # friction near grazing: the orbit may be off the rigid one's
        again = continue_orbit(model, "log10_stiffness", grid, np.zeros(2))   # from X**
        branch = again if again.points else branch
    pts = branch.points
    if not pts:       # no orbit at the stiff end: an answer, not a bad value
        law_info = {"type": law}
        return StopBoundary((), math.nan, math.nan, math.nan, math.nan, (None, None),
                            branch.stopped, None, (model.gains.c1, model.gains.c2), law_info,
                            branch)
    crossings = []
    for bif in branch.bifurcations:
        if bif.type == "grazing":
            continue
        # the branch's neighbours of the crossing, stiffer (larger value) and softer
        stiffer = min((q for q in pts if q.value > bif.value), key=lambda q: q.value)
        softer = max((q for q in pts if q.value < bif.value), key=lambda q: q.value)
        rho = (_rho(stiffer.multipliers), _rho(softer.multipliers))
        fails = ("above" if rho[0] > 1.0 >= rho[1] else
                 "below" if rho[1] > 1.0 >= rho[0] else None)
        crossings.append(Crossing(bif.type, bif.value, bif.multipliers, fails, rho))
    crossings.sort(key=lambda c: -c.log10_stiffness if a > b else c.log10_stiffness)
    top = max(pts, key=lambda q: _rho(q.multipliers))
    grazing = next((g.value for g in branch.bifurcations if g.type == "grazing"), None)
    law_info = {"type": law}
    if law == "kelvin_voigt":
        law_info.update(restitution=model.law.restitution, contact_zeta=model.law.contact_zeta)
    else:
        law_info["alpha"] = model.law.alpha
    if model.friction is not None:
        law_info.update(friction=model.friction.kinetic,
                        friction_static=model.friction.static)
    return StopBoundary(tuple(crossings), _rho(top.multipliers), top.value, pts[0].value,
                        pts[-1].value, (pts[0].impacts, pts[-1].impacts), branch.stopped,
                        grazing, (model.gains.c1, model.gains.c2), law_info, branch)

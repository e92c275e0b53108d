"""Poincare maps on the sections Pi1 and Pi2, with the discrete controller optional.

* Pi1 = {tau = tau*} (the grazing phase), Pi2 = {tau = tau* + pi2_offset} (Eqs. 4, 27).
* The Pi2 map takes the state *sampled* on Pi2 (before the controller acts), applies
  the correction of Eq. 28 if gains are given, and flows one forcing period with
  impacts, to the next sample.
* The Pi1 map flows s = pi2_offset / omega to Pi2, applies the correction, and flows
  T - s back to Pi1.
* :func:`smooth_return_matrix` is the linear map of the non-impacting deviation over
  one period, N_g = Phi(T - s) G Phi(s) (Eqs. 29-32); uncontrolled N_g = Phi(T).
* With an actuation delay (``gains.delay`` = delta > 0) the correction computed from
  the sample acts delta later; the maps then flow delta, kick, and flow on, and their
  monodromy is M2 (M1 + e2 k^T) (exact, impacts inside the delay included). Without
  an impact inside the delay this is M2 Phi(delta) G_delta, G_delta = I + b_delta k^T
  (docs/theory_delay.md, sections 1-2).

States are deviations (dx, dv) from the non-impacting motion x_p (see
:mod:`grazing_control.oscillator.flow`); on Pi2 that motion passes through X**, so (dx, dv) is
exactly (x - x**, v - v**).
"""

from __future__ import annotations

import numpy as np

import math

from grazing_control.oscillator.control import Gains, gain_matrix
from grazing_control.oscillator.flow import matmul2, transition_matrix
from grazing_control.oscillator.impact import Segment, advance
from grazing_control.oscillator.params import OscillatorParams

__all__ = ["pi2_map", "pi1_map", "flow_through_pi2", "period_matrix", "smooth_return_matrix",
           "section_phase"]


def section_phase(p: OscillatorParams, section: str) -> float:
    """Forcing phase of section 'pi1' (tau*) or 'pi2' (tau2)."""
    if section == "pi1":
        return p.tau_star
    if section == "pi2":
        return p.tau2
    raise ValueError(f"section={section!r} is invalid: valid values are 'pi1', 'pi2'")


def pi2_map(p: OscillatorParams, dx: float, dv: float, gains: Gains | None = None, *,
            monodromy: bool = False) -> Segment:
    """One iteration of the Pi2 return map (with the controller of Eq. 28 if gains).

    The monodromy, if asked, is d(next sample)/d(sample) = M_flow G; with an actuation
    delay (``gains.delay`` > 0) it is M2 (M1 + e2 k^T), M1 the flow over the delay and
    M2 the flow after the kick (docs/theory_delay.md, (D3)); the trajectory is that of
    :func:`grazing_control.dynamics.simulation.simulate.period_step` with ``delay``.
    """
    if gains is not None and gains.delay != 0.0:
        return _delayed_step(p, p.tau2, dx, dv, gains, p.period, monodromy)
    if gains is not None:
        dv = dv + gains.c1 * dx + gains.c2 * dv
    seg = advance(p, p.tau2, dx, dv, p.period, monodromy=monodromy)
    if monodromy and gains is not None:
        seg = seg._replace(monodromy=matmul2(seg.monodromy, gain_matrix(gains)))
    return seg


def _delayed_step(p, tau0, dx, dv, gains, duration, monodromy):
    """From a Pi2 sample at phase tau0: flow delta, kick k^T z (z the sample), flow on
    to ``duration``. Impact times count from the sample."""
    delay = gains.delay
    if not delay < duration:
        raise ValueError(f"delay={delay!r} is invalid: valid range is 0 <= delay < {duration!r} "
                         f"(the correction must act before the end of the segment)")
    dvc = gains.c1 * dx + gains.c2 * dv
    first = advance(p, tau0, dx, dv, delay, monodromy=monodromy)
    tau = (tau0 + p.omega * delay) % (2.0 * math.pi)
    second = advance(p, tau, first.dx, first.dv + dvc, duration - delay, monodromy=monodromy)
    later = [i._replace(dt=i.dt + delay, release=i.release + delay) for i in second.impacts]
    mono = None
    if monodromy:
        m1 = first.monodromy
        mono = matmul2(second.monodromy, (m1[0], m1[1], m1[2] + gains.c1, m1[3] + gains.c2))
    return Segment(second.dx, second.dv, first.impacts + later, mono)


def flow_through_pi2(p: OscillatorParams, tau0: float, dx: float, dv: float, to_pi2: float,
                     gains: Gains | None = None, *, monodromy: bool = False) -> Segment:
    """Flow from phase tau0 for ``to_pi2`` (arriving on Pi2), control, flow T - s further.

    The composition behind the Pi1 map (s = pi2_offset / omega): it ends at phase
    tau* + T. Impact times are measured from the start; the monodromy is
    M_second G M_first.
    """
    s = p.pi2_offset / p.omega
    first = advance(p, tau0, dx, dv, to_pi2, monodromy=monodromy)
    dx2, dv2 = first.dx, first.dv
    if gains is not None and gains.delay != 0.0:
        # the kick acts delta after Pi2, before the end at tau* + T (docs/theory_delay.md)
        second = _delayed_step(p, p.tau2, dx2, dv2, gains, p.period - s, monodromy)
        mono = matmul2(second.monodromy, first.monodromy) if monodromy else None
        impacts = first.impacts + [i._replace(dt=i.dt + to_pi2) for i in second.impacts]
        return Segment(second.dx, second.dv, impacts, mono)
    if gains is not None:
        dv2 = dv2 + gains.c1 * dx2 + gains.c2 * dv2
    second = advance(p, p.tau2, dx2, dv2, p.period - s, monodromy=monodromy)
    mono = None
    if monodromy:
        mono = matmul2(second.monodromy, matmul2(gain_matrix(gains), first.monodromy))
    impacts = first.impacts + [i._replace(dt=i.dt + to_pi2) for i in second.impacts]
    return Segment(second.dx, second.dv, impacts, mono)


def pi1_map(p: OscillatorParams, dx: float, dv: float, gains: Gains | None = None, *,
            monodromy: bool = False) -> Segment:
    """One iteration of the Pi1 return map: flow to Pi2, control, flow back to Pi1."""
    return flow_through_pi2(p, p.tau_star, dx, dv, p.pi2_offset / p.omega, gains,
                            monodromy=monodromy)


def period_matrix(p: OscillatorParams, gains: Gains | None = None, s: float | None = None):
    """Deviation map over one period with the controller acting after time s, as a 4-tuple.

    Phi(T - s) G Phi(s) (Eqs. 29-32); s defaults to pi2_offset / omega (then this is N_g on
    Pi1). Uncontrolled it is Phi(T), evaluated directly: near the degenerate frequency
    N12 = Phi12(T) is small and the product Phi(T - s) Phi(s) would lose ~1e-13 of it.
    With an actuation delay G is G_delta = I + b_delta k^T (docs/theory_delay.md, (D2)),
    valid while the kick acts inside the segment: delay < T - s, else ValueError.
    """
    if gains is None:
        return transition_matrix(p.zeta, p.period)
    if s is None:
        s = p.pi2_offset / p.omega
    if gains.delay != 0.0 and not gains.delay < p.period - s:
        raise ValueError(f"delay={gains.delay!r} is invalid here: valid range is 0 <= delay < "
                         f"T - s = {p.period - s!r} (the kick must act before the segment ends)")
    return matmul2(transition_matrix(p.zeta, p.period - s),
                   matmul2(gain_matrix(gains, p.zeta), transition_matrix(p.zeta, s)))


def smooth_return_matrix(p: OscillatorParams, gains: Gains | None = None) -> np.ndarray:
    """N_g = Phi(T - s) G Phi(s), s = pi2_offset / omega (Eqs. 29-32), as a 2x2 array."""
    return np.array(period_matrix(p, gains)).reshape(2, 2)

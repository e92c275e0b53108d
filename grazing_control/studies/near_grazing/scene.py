"""A control scene of an n-DOF model on Pi2 (issue 17, figure (c); the study's Figs. 2(f, g)).

The period map (:class:`~grazing_control.dynamics.maps.modal_map.ModalMap`) is iterated without
control for ``control_after`` periods, then with the kick v[i_a] += k^T z at every Pi2
sample. The distance of each sample to the controlled 1/1 orbit
(the one entry :func:`grazing_control.dynamics.orbits.one_one.orbit`) says whether, and how fast, the controller captures
the motion: near the orbit it shrinks like |lambda_max|^k.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.maps.modal_map import ModalMap
from grazing_control.oscillator.params import ParameterError

from grazing_control.dynamics.orbits import one_one
from grazing_control.dynamics.orbits.near_grazing import with_delta_d
from grazing_control.dynamics.orbits.orbits import OrbitNotFound

__all__ = ["Scene", "StreamLoop", "simulate_pi2", "control_scene", "stream_loop"]


class Scene(NamedTuple):
    """Pi2 samples (periods + 1, 2n) as deviations from the grazing orbit (sample k is
    taken before the kick of period k), impacts in each period, the sample at which
    control went on (-1: never), and, with gains, the controlled 1/1 orbit and each
    sample's Euclidean distance to it (None when that orbit was not found: ``orbit_error``)."""

    delta_d: float
    samples: np.ndarray
    impacts_per_period: np.ndarray
    control_after: int
    orbit: np.ndarray | None
    distance: np.ndarray | None
    orbit_error: str


def simulate_pi2(model, periods: int, start=None, gains=None, control_after: int | None = None,
                 delay: float = 0.0, width: float = 0.0):
    """(samples, impacts per period): ``periods`` applications of the period map from
    ``start`` (default the grazing point), the kick on from sample ``control_after``,
    acting ``delay`` after each sample (``ModalMap``'s exact delayed map); with ``width``
    > 0 the correction is the force pulse of that width centred ``delay`` after the
    sample (``ModalMap(model, k, delay, width)``, docs/theory_ndof.md §15)."""
    if isinstance(periods, bool) or int(periods) != periods or periods < 0:
        raise ParameterError(f"periods={periods!r} is invalid: valid range is an integer >= 0")
    n2 = 2 * model.n
    z = np.zeros(n2) if start is None else np.asarray(start, dtype=float).reshape(-1)
    if z.shape != (n2,) or not np.all(np.isfinite(z)):
        raise ParameterError(f"start is invalid: expected {n2} finite values (deviation from "
                             "the grazing orbit on Pi2)")
    free = ModalMap(model)
    ctl = None if gains is None else ModalMap(model, np.asarray(gains, dtype=float), delay,
                                              width)
    after = periods if ctl is None else (0 if control_after is None else int(control_after))
    samples = np.empty((int(periods) + 1, n2))
    counts = np.zeros(int(periods), dtype=np.int32)
    samples[0] = z
    for k in range(int(periods)):
        step = (ctl if k >= after else free).step(z)
        z = step.state
        if not np.all(np.isfinite(z)):
            raise ArithmeticError(f"the state is not finite after period {k}: an input is "
                                  "outside the computable range")
        samples[k + 1] = z
        counts[k] = len(step.impacts)
    return samples, counts


def control_scene(model, gains, *, delta_d: float | None = None, control_after: int,
                  periods: int, start=None, delay: float = 0.0) -> Scene:
    """Run a scene (module docstring) and measure the distance to the controlled orbit;
    the kick acts ``delay`` after each sample (the orbit is the delayed kick's)."""
    if delta_d is not None:
        model = with_delta_d(model, delta_d)
    samples, counts = simulate_pi2(model, periods, start, gains, control_after, delay)
    orbit = distance = None
    error = ""
    if gains is not None:
        try:
            orbit = one_one.orbit(model, gains, delay=delay).state
            distance = np.linalg.norm(samples - orbit, axis=1)
        except OrbitNotFound as exc:
            error = str(exc)
    after = -1 if gains is None else int(control_after)
    return Scene(model.delta_d, samples, counts, after, orbit, distance, error)


class StreamLoop(NamedTuple):
    """A closed loop on the sensor stream (:func:`stream_loop`): the true Pi2 deviations
    z_k (before the kick), the estimates, the corrections, the impacts per period and
    the estimator's resets."""

    truth: np.ndarray
    estimate: np.ndarray
    corrections: np.ndarray
    impacts_per_period: np.ndarray
    resets: int


def stream_loop(model_file, gains, *, delta_d: float, delay: float, sigma: float,
                rate: int, coordinate: int, periods: int, control_after: int,
                seed: int, width: float = 0.0, actuator=None) -> StreamLoop:
    """The n-DOF closed loop on a position-only sensor stream in one process (issue 32,
    docs/ndof_scene.md): the simulator's engine (:class:`grazing_control.plant.engine.Engine`
    over the model file, its sensor of ``sigma`` at T / ``rate``, seeded by ``seed``), the
    controller's estimator (:class:`grazing_control.dynamics.estimation.stream.
    StreamEstimator` over the model, reading ``coordinate``) and the kick k^T z^ acting
    ``delay`` after each section from ``control_after`` on (with ``width`` > 0 the force
    pulse carrying it, centred at ``delay``: docs/theory_ndof.md section 15; with an
    ``actuator`` (:class:`grazing_control.dynamics.simulation.actuator.Actuator`) the pulse
    through its first-order lag, in the plant and the filter): the calls the nodes make
    in lockstep, without the middleware."""
    from grazing_control.dynamics.estimation.stream import StreamEstimator
    from grazing_control.plant.engine import Engine
    from grazing_control.plant.settings import load_model_file, settings_from_values

    model = load_model_file(str(model_file))
    st = settings_from_values(
        {"delta_d": delta_d, "actuation_delay": delay, "sensor_noise": sigma,
         "sensor_velocity": False, "sensor_seed": seed, "pulse_width": width,
         "state_period": model.period / rate,
         **({} if actuator is None else
            {"actuator_bandwidth": 1.0 / actuator.time_constant
             if actuator.time_constant > 0.0 else 0.0,
             "actuator_latency": actuator.latency})}, str(model_file), model)
    model, k = st.model, np.asarray(gains, dtype=float)
    eng = Engine(st)
    est = StreamEstimator(model, "model", sigma, "stream", model.period / rate,
                          coordinate=coordinate, pulse_width=width, actuator=actuator)
    due = []
    for ev in eng.initial_states():
        due += est.add_sample(ev.t, ev.x[coordinate], ev.v[coordinate])
    n2 = 2 * model.n
    truth, estimate = np.empty((periods, n2)), np.empty((periods, n2))
    corrections, counts = np.zeros(periods), np.zeros(periods, dtype=np.int32)
    for j in range(periods):
        due += est.flush(j)
        (e,) = [d[2] for d in due if d[0] == j]
        truth[j], estimate[j] = eng.z, e.z
        dv = float(k @ np.asarray(e.z)) if j >= control_after else 0.0
        corrections[j] = dv
        est.set_correction(j, dv, delay)
        events = eng.begin_period(dv, delay)
        counts[j] = sum(ev.kind == "impact" for ev in events)
        states = [ev for ev in events if ev.kind == "state"]
        due = est.add_samples([ev.t for ev in states], [ev.x[coordinate] for ev in states],
                              [ev.v[coordinate] for ev in states])
        eng.end_period()
    return StreamLoop(truth, estimate, corrections, counts, est.resets)

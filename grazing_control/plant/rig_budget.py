"""The rig's timing budget: is there time between a Pi2 section and its force pulse?

A rig's controller answers section k at rig time t_k + budget (the centre of the force
pulse, docs/rig.md "The timing budget"). Its pulse of width w starts at
t_k + budget - w / 2, and before that instant the answer must exist:

    sensor latency + one sample interval + the Pi2 estimate's compute time
        + actuator latency  <=  budget - pulse_width / 2.

The sample interval is there because the estimate of section k is made once the first
sample after t_k has come (docs/driver_contract.md, "Sections"; the stream estimator's
``after_section``); the sensor latency is that sample's way to the controller; the
actuator latency is the command's way from its apply time to the force. The compute
time is measured, not assumed: :func:`time_estimate` times the stream estimator the
controller uses (:class:`grazing_control.dynamics.estimation.stream.StreamEstimator`, the model
filter by default) on this machine, on the rig's controlled 1/1 orbit at the rig's
samples per period with its sensor noise, and reports the tail (p99) of a few hundred
estimates. :func:`timing_budget` adds the terms, :func:`check_budget` refuses an
infeasible budget with one line naming the field to change.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from grazing_control.dynamics.estimation.stream import StreamEstimator
from grazing_control.oscillator.params import OscillatorParams
from .rig import Rig, RigError

__all__ = ["EstimateTiming", "TimingBudget", "samples_per_period", "time_estimate",
           "timing_budget", "check_budget", "TIMED_RUNS"]

#: Estimates timed by default (p99 of 300: the 4th largest).
TIMED_RUNS = 300
#: Estimates made before the timed ones (the filter starts from an arc fit).
_WARMUP = 5
#: The noise an exact sensor (noise 0) is timed with: the model filter needs sigma > 0.
_EXACT_SIGMA = 1e-9


def samples_per_period(rig: Rig) -> int:
    """The rig's sensor samples per forcing period as the design takes them: the nearest
    integer to f_s / f (docs/rig.md, "The predicted spread")."""
    return max(2, int(round(rig.sensor.rate / rig.frequency)))


@dataclass(frozen=True)
class EstimateTiming:
    """Wall seconds of the Pi2 estimates timed by :func:`time_estimate`: ``p50``,
    ``p99``, ``max`` over ``runs`` estimates of the ``estimator`` at
    ``samples_per_period``; ``cpu_p99`` the p99 of the process's CPU time over the same
    calls (wall - CPU: the time other processes had the core); ``resets`` the model
    filter's fallbacks to the arc fit; ``load`` the 1-minute load average after."""

    estimator: str
    samples_per_period: int
    runs: int
    p50: float
    p99: float
    max: float
    cpu_p99: float
    resets: int
    load: float


def time_estimate(p: OscillatorParams, gains, rate: int, sigma: float, *,
                  target=None, estimator: str = "model", runs: int = TIMED_RUNS,
                  seed: int = 0) -> EstimateTiming:
    """Time the stream estimator on the controlled orbit (module docstring).

    Parameters
    ----------
    p : the rig's model (Delta d included).
    gains : the controller's Gains (their delay places the correction in the period).
    rate : samples per forcing period.
    sigma : the sensor's noise (dimensionless, as the controller is given it).
    target : the Pi2 deviation of the orbit the samples come from (default: the exact
        controlled 1/1 orbit for Delta d < 0, the grazing orbit's section otherwise).
    runs : estimates timed (>= 1), after a few untimed ones.

    Each period's samples are the exact orbit's positions at t_k + j T / rate plus fresh
    Gaussian noise of std ``sigma`` (seeded); the call that makes section k due, the one
    a controller makes when the first sample after t_k arrives, is timed with
    ``time.perf_counter``.
    """
    from grazing_control.dynamics.estimation.motion import trajectory

    if target is None:
        target = (0.0, 0.0)
        if p.delta_d < 0.0:
            from grazing_control.dynamics.orbits.one_one import orbit

            target = orbit(p, gains).state
    sigma = float(sigma) if sigma > 0.0 else _EXACT_SIGMA
    T = p.period
    h = T / rate
    s = np.arange(1, rate + 1) * h
    dv = gains.c1 * target[0] + gains.c2 * target[1]
    dev, *_ = trajectory(p, target, s, dv, gains.delay)
    psi = p.tau2 + p.omega * s - p.lag
    x = p.amplitude * np.cos(psi) + dev[:, 0]
    est = StreamEstimator(p, estimator, sigma, "stream", h, after_section=True)
    rng = np.random.default_rng(seed)
    wall, cpu = [], []
    est.add_sample(0.0, float(x[-1]))
    k = 0
    while len(wall) < runs:
        noisy = x + sigma * rng.standard_normal(rate)
        for j in range(rate):
            w0, c0 = time.perf_counter(), time.process_time()
            due = est.add_sample(k * T + s[j], float(noisy[j]))
            w1, c1 = time.perf_counter(), time.process_time()
            if due:
                if due[-1][0] > _WARMUP and len(wall) < runs:
                    wall.append(w1 - w0)
                    cpu.append(c1 - c0)
                for kk, _tk, _e in due:
                    est.set_correction(kk, dv, gains.delay)
        k += 1
    a, c = np.array(wall), np.array(cpu)
    return EstimateTiming(estimator, int(rate), int(a.size), float(np.percentile(a, 50)),
                          float(np.percentile(a, 99)), float(a.max()),
                          float(np.percentile(c, 99)), est.resets, os.getloadavg()[0])

@dataclass(frozen=True)
class TimingBudget:
    """The terms of the feasibility rule (module docstring), all in seconds."""

    sensor_latency: float
    sample_interval: float
    compute: float
    actuator_latency: float
    budget: float
    pulse_width: float

    @property
    def needed(self) -> float:
        """Sensor latency + sample interval + compute + actuator latency."""
        return self.sensor_latency + self.sample_interval + self.compute + self.actuator_latency

    @property
    def available(self) -> float:
        """budget - pulse_width / 2: when the pulse starts, after the section."""
        return self.budget - self.pulse_width / 2.0

    @property
    def slack(self) -> float:
        return self.available - self.needed

    @property
    def feasible(self) -> bool:
        return self.needed <= self.available


def timing_budget(rig: Rig, compute: float) -> TimingBudget:
    """The rig's budget with ``compute`` (s) the estimate's compute tail."""
    return TimingBudget(rig.sensor.latency, 1.0 / rig.sensor.rate, float(compute),
                        rig.actuator.latency, rig.budget, rig.actuator.pulse_width)


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.4g} ms"


def check_budget(b: TimingBudget, rate: float, how: str) -> None:
    """Raise RigError (one line) where ``b`` is infeasible: naming ``sensor.rate`` when
    the budget would hold with samples arriving at once (the sample interval tips it),
    ``controller.budget`` otherwise; ``how`` says where the compute time came from."""
    if b.feasible:
        return
    terms = (f"sensor latency {_ms(b.sensor_latency)} + sample interval "
             f"{_ms(b.sample_interval)} + estimate {_ms(b.compute)} ({how}) + actuator "
             f"latency {_ms(b.actuator_latency)} = {_ms(b.needed)} > budget - pulse_width / 2"
             f" = {_ms(b.budget)} - {_ms(b.pulse_width / 2)} = {_ms(b.available)}")
    rest = b.needed - b.sample_interval
    if rest < b.available:
        need = 1.0 / (b.available - rest)
        raise RigError(f"sensor.rate={rate:.6g} Hz is too slow for the timing budget: "
                       f"{terms}; valid range is sensor.rate >= {need:.6g} Hz (or a larger "
                       "controller.budget)")
    raise RigError(f"controller.budget={_ms(b.budget)} is infeasible: {terms}; valid range "
                   f"is controller.budget >= {_ms(b.needed + b.pulse_width / 2)} "
                   "(or shorter latencies, a narrower pulse)")


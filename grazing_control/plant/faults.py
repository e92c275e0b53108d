"""Faults of a real-time control loop: lost corrections, measurement noise, delay jitter.

One immutable :class:`FaultModel` describes what can go wrong between a Pi2 sample and
its correction, and :meth:`FaultModel.draw` gives the faults of sample k as a pure
function of (seed, k). The core simulation and the ROS nodes draw the same faults for
the same seed, so a run through the nodes can be compared with the core sample for
sample.

* loss: the correction of a sample is dropped with probability ``loss``;
* noise: the sample the controller sees is (x + sigma e_x, v + sigma e_v), e ~ N(0, 1);
  an n-DOF sample's n positions and velocities (:meth:`FaultModel.coordinate_noise`);
* jitter: the correction acts at delay + jitter e_d after the sample, clipped to
  [0, T) (it cannot act before the sample, nor after the next one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from grazing_control.oscillator.params import ParameterError

__all__ = ["FaultModel", "SampleFaults", "NO_FAULTS"]


class SampleFaults(NamedTuple):
    """The faults of one sample: measurement noise, whether the correction is lost,
    and the offset of its actuation time from the designed delay."""

    noise_x: float
    noise_v: float
    dropped: bool
    delay_offset: float


@dataclass(frozen=True)
class FaultModel:
    """Loss probability, measurement-noise std and delay-jitter std, with a seed.

    Parameters
    ----------
    loss : float
        Probability that a correction is dropped, 0 <= loss <= 1.
    noise : float
        Std of the Gaussian noise on the x and v of the sample the controller sees, >= 0.
    jitter : float
        Std of the Gaussian error of the actuation time around the designed delay, >= 0
        (simulation time units).
    seed : int
        Seed, >= 0: the faults of sample k are a pure function of (seed, k).
    """

    loss: float = 0.0
    noise: float = 0.0
    jitter: float = 0.0
    seed: int = 0

    def __post_init__(self):
        for name, ok, valid in (("loss", lambda x: 0.0 <= x <= 1.0, "0 <= loss <= 1"),
                                ("noise", lambda x: x >= 0.0, "a finite noise >= 0"),
                                ("jitter", lambda x: x >= 0.0, "a finite jitter >= 0")):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                value = math.nan
            if not (math.isfinite(value) and ok(value)):
                raise ParameterError(f"{name}={getattr(self, name)!r} is invalid: valid range is {valid}")
            object.__setattr__(self, name, value)
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParameterError(f"seed={seed!r} is invalid: valid range is an integer >= 0")
        object.__setattr__(self, "seed", int(seed))

    @property
    def active(self) -> bool:
        """True if any fault can occur."""
        return self.loss > 0.0 or self.noise > 0.0 or self.jitter > 0.0

    def draw(self, k: int) -> SampleFaults:
        """The faults of sample k (k >= 0), from the generator seeded with (seed, k)."""
        if not self.active:
            return SampleFaults(0.0, 0.0, False, 0.0)
        u = np.random.default_rng((self.seed, int(k))).standard_normal(4)
        dropped = bool(0.5 * math.erfc(-u[2] / math.sqrt(2.0)) < self.loss)  # Phi(u) < loss
        return SampleFaults(self.noise * float(u[0]), self.noise * float(u[1]), dropped,
                            self.jitter * float(u[3]))

    def coordinate_noise(self, k: int, n: int) -> tuple:
        """The measurement noise of an n-DOF sample k: (noise on x_0..x_{n-1}, noise on
        v_0..v_{n-1}), arrays of n. Coordinate 0's are :meth:`draw`'s ``noise_x``,
        ``noise_v`` (so n = 1 is the 1-DOF scene's bit for bit); coordinate i >= 1 takes
        the normal draws 4 + 2 (i - 1) and 5 + 2 (i - 1) of the same generator seeded with
        (seed, k) (its first four draws are :meth:`draw`'s: loss and jitter unchanged)."""
        if self.noise == 0.0:
            return np.zeros(n), np.zeros(n)
        u = np.random.default_rng((self.seed, int(k))).standard_normal(2 + 2 * n)
        x = np.concatenate([u[:1], u[4::2]])
        v = np.concatenate([u[1:2], u[5::2]])
        return self.noise * x, self.noise * v

    def actuation_delay(self, delay: float, k: int, period: float) -> float:
        """Actual delay of sample k's correction: delay + jitter e_k clipped to [0, T)."""
        if self.jitter == 0.0:
            return delay
        return min(max(0.0, delay + self.draw(k).delay_offset), math.nextafter(period, 0.0))


#: No faults: the ideal loop.
NO_FAULTS = FaultModel()

"""A rig's motion sensor: sampled, noisy, biased, quantised, position only or with velocity.

The simulator's state stream (``oscillator/state``) is what such a sensor would give
(docs/nodes.md, "The sensor stream"). Sample j of the stream at time t_j measures

    x~_j = Q(x(t_j) + bias + sigma e_j),     v~_j = v(t_j) + sigma f_j   (if carried)

with e_j, f_j standard normal and Q(y) = q round(y / q) the quantiser of step q (none
for q = 0). The draws are a pure function of (seed, j): any sample is reproducible from
the seed alone, however the stream was cut into periods or split by corrections, so a
node run and a core run with the same seed see the same measurements. The shaker's
phase reference (cos tau, sin tau) at t_j is exact: a rig reads it from its signal
generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from grazing_control.oscillator.params import ParameterError

__all__ = ["SensorModel", "EXACT_SENSOR", "BLOCK"]

#: Samples drawn per generator: sample j's draws come from the block j // BLOCK,
#: seeded by (seed, block), so drawing them costs one generator per BLOCK samples.
BLOCK = 256


@lru_cache(maxsize=8)
def _block_draws(seed: int, block: int) -> np.ndarray:
    """The (BLOCK, 2) standard normal draws of block ``block`` (read-only). Kept for the
    next calls: the simulator measures a period's samples in 2-4 segments, and each made
    its block's generator again (12.9 % of a T/200 scene's simulator CPU, py-spy, issue
    30)."""
    e = np.random.default_rng([seed, block]).standard_normal((BLOCK, 2))
    e.flags.writeable = False
    return e


@dataclass(frozen=True)
class SensorModel:
    """Noise std ``noise`` (position, and velocity where carried), ``velocity`` (the
    stream carries v), quantisation step ``quantum`` (0: none), position ``bias`` and
    ``seed``; each validated with the node's parameter name in its message."""

    noise: float = 0.0
    velocity: bool = True
    quantum: float = 0.0
    bias: float = 0.0
    seed: int = 0

    def __post_init__(self):
        for name, attr, ok, valid in (
                ("sensor_noise", "noise", lambda x: x >= 0.0, "a finite sensor_noise >= 0"),
                ("sensor_quantum", "quantum", lambda x: x >= 0.0,
                 "a finite sensor_quantum >= 0 (0: no quantisation)"),
                ("sensor_bias", "bias", lambda x: True, "a finite sensor_bias")):
            value = getattr(self, attr)
            try:
                value = float(value)
            except (TypeError, ValueError):
                value = math.nan
            if not (math.isfinite(value) and ok(value)):
                raise ParameterError(f"{name}={getattr(self, attr)!r} is invalid: valid range "
                                     f"is {valid}")
            object.__setattr__(self, attr, value)
        if not isinstance(self.velocity, (bool, np.bool_)):
            raise ParameterError(f"sensor_velocity={self.velocity!r} is invalid: valid values "
                                 "are true, false")
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParameterError(f"seed={seed!r} is invalid: valid range is an integer >= 0")
        object.__setattr__(self, "seed", int(seed))
        object.__setattr__(self, "velocity", bool(self.velocity))

    @property
    def exact(self) -> bool:
        """The sensor returns the state itself (no noise, bias nor quantisation)."""
        return self.noise == 0.0 and self.quantum == 0.0 and self.bias == 0.0

    def draws(self, j0: int, n: int) -> np.ndarray:
        """(n, 2) standard normal draws of samples j0 .. j0 + n - 1 (a pure function of
        (seed, j))."""
        out = np.empty((n, 2))
        j = j0
        while j < j0 + n:
            block, offset = divmod(j, BLOCK)
            take = min(BLOCK - offset, j0 + n - j)
            out[j - j0:j - j0 + take] = _block_draws(self.seed, block)[offset:offset + take]
            j += take
        return out

    def measure(self, j0: int, x, v):
        """Measured (x~, v~) of samples j0, j0 + 1, ... with true states x, v (arrays):
        v~ is NaN where the sensor does not measure velocity."""
        x = np.asarray(x, dtype=float)
        v = np.asarray(v, dtype=float)
        if self.exact:
            xm, vm = x.copy(), v.copy()
        else:
            e = self.draws(j0, x.size) if self.noise > 0.0 else np.zeros((x.size, 2))
            xm = x + self.bias + self.noise * e[:, 0]
            vm = v + self.noise * e[:, 1]
            if self.quantum > 0.0:
                xm = self.quantum * np.round(xm / self.quantum)
        if not self.velocity:
            vm = np.full_like(vm, math.nan)
        return xm, vm


#: The sensor of the ideal scenes: the exact state, with velocity.
EXACT_SENSOR = SensorModel()

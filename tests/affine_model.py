"""A second implementation of the model protocol, with everything known in closed form.

z -> A(mu) z + b: the fixed point is (I - A)^-1 b, the monodromy A, the multipliers the
eigenvalues of A. A(mu) = Q diag-blocks Q^-1 in any dimension n >= 3, with a real
multiplier mu (period doubling at mu = -1), a complex pair rho e^{+-i theta} (a
Neimark-Sacker at rho = 1) and further real multipliers 0.3, 0.2, ...
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from grazing_control.dynamics.maps.model import Step


@dataclass(frozen=True)
class Affine:
    mu: float = 0.5
    rho: float = 0.6
    theta: float = 0.9
    dimension: int = 4
    seed: int = 7

    @property
    def period(self) -> float:
        return 1.0

    @property
    def section_phase(self) -> float:
        return 0.0

    @property
    def coordinates(self) -> tuple:
        return tuple(f"z{i}" for i in range(self.dimension))

    def matrix(self) -> np.ndarray:
        n = self.dimension
        d = np.zeros((n, n))
        d[0, 0] = self.mu
        c, s = np.cos(self.theta), np.sin(self.theta)
        d[1:3, 1:3] = self.rho * np.array([[c, -s], [s, c]])
        for i in range(3, n):
            d[i, i] = 0.3 / (i - 2)
        q = np.random.default_rng(self.seed).normal(size=(n, n)) + 3.0 * np.eye(n)
        return q @ d @ np.linalg.inv(q)

    def offset(self) -> np.ndarray:
        return np.arange(1.0, self.dimension + 1.0)

    def fixed_point(self) -> np.ndarray:
        return np.linalg.solve(np.eye(self.dimension) - self.matrix(), self.offset())

    def step(self, state, jacobian: bool = False) -> Step:
        a = self.matrix()
        return Step(a @ np.asarray(state, float) + self.offset(), a if jacobian else None, ())

    def grazing_state(self) -> np.ndarray:
        return np.zeros(self.dimension)

    def parameter(self, name: str) -> float:
        if name not in ("mu", "rho", "theta"):
            raise ValueError(f"parameter {name!r} is invalid: valid names are mu, rho, theta")
        return getattr(self, name)

    def with_parameter(self, name: str, value: float) -> "Affine":
        self.parameter(name)
        return dataclasses.replace(self, **{name: value})

    def jacobian_det(self, periods: int, impacts: int):
        return None

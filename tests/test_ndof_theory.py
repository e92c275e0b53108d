"""Linear-algebra checks of docs/theory_ndof.md on seeded random matrices."""

import numpy as np
import pytest

SEEDS = range(20)


def _random(n, seed):
    rng = np.random.default_rng(seed)
    d = 2 * n
    return rng.normal(size=(d, d)), rng.normal(size=(d, d)), rng.normal(size=d), rng.normal(size=d)


@pytest.mark.parametrize("seed", SEEDS)
def test_determinant_lemma_singular_term(seed):
    n_mat, _, u, w = _random(2, seed)
    s = 0.37
    jac = n_mat @ (np.eye(4) + np.outer(u, w) / (2 * s))
    for lam in (0.3 + 0.2j, -1.1, 2.0 - 0.5j):
        res = lam * np.eye(4) - n_mat
        adj = np.linalg.det(res) * np.linalg.inv(res)
        expected = np.linalg.det(res) - (w @ adj @ n_mat @ u) / (2 * s)
        assert np.isclose(np.linalg.det(lam * np.eye(4) - jac), expected, rtol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_kick_family_pins_transmission_zeros(seed):
    a1, a2, b, w = _random(2, seed)
    m, g = a2 @ a1, a2 @ b
    c = w @ g
    zeros = None
    for mu in (0.1, -0.6, 0.9):
        k = np.linalg.solve(a1.T, (mu * w - w @ m) / c)
        n_k = a2 @ (np.eye(4) + np.outer(b, k)) @ a1
        assert np.allclose(w @ n_k, mu * w, atol=1e-9)
        eig = np.linalg.eigvals(n_k)
        i = np.argmin(abs(eig - mu))
        rest = np.sort_complex(np.delete(eig, i))
        for lam in rest:  # each is a zero of w^T adj(lam I - M) g
            res = lam * np.eye(4) - m
            num = np.linalg.det(res) * (w @ np.linalg.solve(res, g))
            assert abs(num) < 1e-7 * (1 + abs(np.linalg.det(res)))
        if zeros is None:
            zeros = rest
        assert np.allclose(rest, zeros, atol=1e-7)


@pytest.mark.parametrize("seed", SEEDS)
def test_left_eigenvector_kills_markov_parameters(seed):
    a1, a2, b, w = _random(2, seed)
    u = np.random.default_rng(seed + 100).normal(size=4)
    u -= w * (w @ u) / (w @ w)  # w^T u = 0
    m, g = a2 @ a1, a2 @ b
    k = np.linalg.solve(a1.T, (0.4 * w - w @ m) / (w @ g))
    n_k = a2 @ (np.eye(4) + np.outer(b, k)) @ a1
    for j in range(1, 5):
        power = np.linalg.matrix_power(n_k, j)
        scale = np.linalg.norm(w) * np.linalg.norm(power) * np.linalg.norm(u)
        assert abs(w @ power @ u) < 1e-11 * scale

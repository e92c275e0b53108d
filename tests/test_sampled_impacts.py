"""dynamics.estimation.sampled_impacts: the impact times found in the sampled wall
coordinate (issue 32), against the exact n-DOF plant's own impacts over random models
(a seeded differential test: the detector has no certificate, so the truth it is held to
is the exact motion's event search, dynamics.estimation.motion.trajectory)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from grazing_control.dynamics.estimation.motion import trajectory
from grazing_control.dynamics.estimation.sampled_impacts import impacts_from_samples
from grazing_control.oscillator.ndof.flow import NdofFlow
from grazing_control.oscillator.ndof.model import load_model

ROOT = Path(__file__).resolve().parents[1]
BASE = load_model(ROOT / "config" / "models" / "two_mass_scene.yaml")
SIGMA, RATE, PERIODS, DELAY = 1e-4, 200, 8, 1.0


def _random_scene(rng):
    """A random two-mass model near the scene's (damping x 0.7-1.5, stiffness x 0.9-1.1,
    r 0.5-0.9, omega 0.22-0.34, Delta d -1e-4 to -1e-2), PERIODS periods of its exact
    motion from a random state with a random kick DELAY after each section, its wall
    coordinate sampled at T/RATE with noise SIGMA: (t, x, kick times, true impact times,
    their |v-|)."""
    m = dataclasses.replace(BASE, C=BASE.C * rng.uniform(0.7, 1.5),
                            K=BASE.K * rng.uniform(0.9, 1.1), r=rng.uniform(0.5, 0.9),
                            delta_d=-10 ** rng.uniform(-4, -2), omega=rng.uniform(0.22, 0.34))
    flow = NdofFlow.of(m)
    h = m.period / RATE
    z = rng.normal(0.0, 1e-2, 2 * m.n)
    t, x, kicks, times, speeds = [], [], [], [], []
    for k in range(PERIODS):
        j = np.arange(k * RATE + 1, (k + 1) * RATE + 1)
        s = j * h - k * m.period
        dev, _jac, z, _m, imps = trajectory(m, z, s, rng.uniform(-0.02, 0.02), DELAY)
        wave = np.exp(1j * (flow.tau2 + m.omega * s))
        x += list((flow.amplitudes[m.i_w] * wave).real + dev[:, m.i_w]
                  + rng.normal(0.0, SIGMA, s.size))
        t += list(j * h)
        kicks.append(k * m.period + DELAY)
        times += [k * m.period + i[0] for i in imps]
        speeds += [abs(i[2]) for i in imps]
    return np.array(t), np.array(x), kicks, np.array(times), np.array(speeds), h


def test_the_impacts_found_are_the_exact_plants_over_random_models():
    """60 seeded random models, 8 periods each at T/200 and sigma 1e-4: no time found
    that is not an impact of the exact motion (within half a sample), every impact
    faster than 0.05 found within a tenth of a sample, and nearly all the slower ones
    (the detector's floor is ~0.01, module docstring). Seed 32, measured: 282 impacts,
    280 found; the 202 faster than 0.05 within 0.066 of a sample, 78 of the 80 slower."""
    rng = np.random.default_rng(32)
    true = found = fast = slow_found = slow = 0
    worst = 0.0
    for _ in range(60):
        t, x, kicks, times, speeds, h = _random_scene(rng)
        got = impacts_from_samples(t, x, kicks, sigma=SIGMA)
        true, found = true + times.size, found + got.size
        for g in got:                    # none that is not an impact
            assert times.size and np.min(np.abs(times - g)) < 0.5 * h, (g, times)
        for when, v in zip(times, speeds):
            d = np.min(np.abs(got - when)) / h if got.size else np.inf
            if v >= 0.05:
                fast += 1
                worst = max(worst, d)
            else:
                slow += 1
                slow_found += d < 0.5
    assert worst < 0.1, worst
    assert fast >= 150 and slow >= 30, (fast, slow)
    assert slow_found >= 0.9 * slow and found >= 0.97 * true, (found, true, slow_found, slow)


def test_the_kinked_fits_are_a_least_squares_fit_per_tau():
    """kinked_fits (all the grid's taus at once, by stacked QR) against NumPy's lstsq of
    each tau's design alone, over 100 seeded random windows (17 samples at a random
    step, a random kink and noise from 1e-8 to 1e-2, the grid of impacts_from_samples):
    every residual sum within 1e-9 of the window's sum of squares, every slope and
    position within 1e-8 of the largest, and the same best tau."""
    from grazing_control.dynamics.estimation.sampled_impacts import _GRID, kinked_fits

    rng = np.random.default_rng(7)
    half = 8
    for _ in range(100):
        h = 10.0 ** rng.uniform(-4, 0)
        u = (np.arange(-half, half + 1) + rng.uniform(-0.3, 0.3)) * h
        kink = rng.uniform(-2, 2) * h
        y = (np.where(u < kink, rng.normal() * (u - kink), rng.normal() * (u - kink))
             + 0.1 * rng.normal() * u ** 2 + 10.0 ** rng.uniform(-8, -2) * rng.normal(size=u.size))
        taus = np.linspace(u[half - 2], u[half + 2], 4 * _GRID + 1)[1:-1]
        rss, before, after, apex = kinked_fits(u, y, taus)
        ref = []
        for tau in taus:
            s = u - tau
            left = s < 0.0
            B = np.column_stack([np.ones_like(s)] + [c for p in (1, 2, 3) for c in
                                (np.where(left, s ** p, 0.0), np.where(left, 0.0, s ** p))])
            coef = np.linalg.lstsq(B, y, rcond=None)[0]
            ref.append((float(np.sum((y - B @ coef) ** 2)), coef[1], coef[2], coef[0]))
        ref = np.array(ref)
        scale = float(y @ y)
        assert np.max(np.abs(rss - ref[:, 0])) <= 1e-9 * scale
        for got, want in zip((before, after, apex), ref[:, 1:].T):
            assert np.max(np.abs(got - want)) <= 1e-8 * max(1.0, np.max(np.abs(want)))
        assert np.argmin(rss) == np.argmin(ref[:, 0]) or \
            abs(rss[np.argmin(ref[:, 0])] - rss.min()) <= 1e-9 * scale

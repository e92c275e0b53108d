"""dynamics.simulation.lyapunov: the Lyapunov spectrum on Pi2 by tangent propagation through the exact
flow, the saltation matrices and the controller's kick (docs/theory_lyapunov.md).

Checked against: the determinant identity (L3) lambda1 + lambda2 = -2 zeta T + 2 nu ln r
(+ ln|1 + c2| per controlled period), exact for every orbit without sticking; the pure-
Python core and the generic numpy-QR route (the same orbit, other arithmetic); a
finite-difference two-trajectory estimate (Benettin's renormalised separation) that
never uses a Jacobian; the linear stability of the periodic orbits (Floquet
multipliers from orbits.orbit_11 / shooting)."""

import math

import numpy as np
import pytest

from grazing_control.dynamics.simulation.lyapunov import (determinant_sum, lyapunov_exact,
                                               lyapunov_spectrum)
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.orbits.shooting import find_periodic, floquet_multipliers
from grazing_control.dynamics.simulation.simulate import core_period_step
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

CHAOTIC = (-5e-6, -3e-6, -6e-6, -7e-6)     # the study's chaotic window past the PD cascade


def _two_trajectory(p, start, periods, transient, eps=1e-9):
    """Largest exponent from two nearby orbits, the separation renormalised to eps every
    period (Benettin et al.); only the exact flow, no Jacobian."""
    dx, dv = start
    for _ in range(transient):
        s = core_period_step(p, dx, dv)
        dx, dv = s.dx, s.dv
    ox, ov = dx + eps, dv
    total = 0.0
    for _ in range(periods - transient):
        a = core_period_step(p, dx, dv)
        b = core_period_step(p, ox, ov)
        ddx, ddv = b.dx - a.dx, b.dv - a.dv
        d = math.hypot(ddx, ddv)
        total += math.log(d / eps)
        dx, dv = a.dx, a.dv
        ox, ov = dx + eps * ddx / d, dv + eps * ddv / d
    return total / (periods - transient)


@pytest.mark.parametrize("delta_d", CHAOTIC)
def test_the_exponents_sum_to_the_determinant_identity_on_chaotic_orbits(delta_d):
    p = OscillatorParams(delta_d=delta_d)
    res = lyapunov_exact(p, (1e-4, 0.0), 2500, 500)
    assert res.stuck_periods == 0 and 0.0 < res.impacts_per_period < 1.0
    assert res.maximum > 0.05                                    # chaotic
    assert res.expected_sum == pytest.approx(
        -2 * p.zeta * p.period + 2 * res.impacts_per_period * math.log(p.r), abs=1e-15)
    assert abs(res.sum_residual) < 1e-10


def test_the_identity_holds_with_the_controller_and_its_kick_determinant():
    p = OscillatorParams(delta_d=-5e-6)
    g = Gains(-0.5, -0.6)
    res = lyapunov_exact(p, (1e-4, 0.0), 1500, 500, gains=g, control_after=700)
    # 800 controlled of the 1000 measured periods contribute ln|1 + c2| each
    expected = determinant_sum(p, round(res.impacts_per_period * 1000), 1000, 800 * math.log(0.4))
    assert res.expected_sum == pytest.approx(expected, rel=1e-14)
    assert abs(res.sum_residual) < 1e-10


def test_the_kernel_the_python_core_and_the_generic_route_agree():
    p = OscillatorParams(delta_d=-5e-6)
    k = lyapunov_exact(p, (1e-4, 0.0), 1200, 200)
    py = lyapunov_exact(p, (1e-4, 0.0), 1200, 200, engine="python")
    gen = lyapunov_spectrum(OneDOF(p), (1e-4, 0.0), 1200, 200)
    assert k.final == py.final == gen.final                      # the same orbit, bit for bit
    assert k.impacts_per_period == py.impacts_per_period == gen.impacts_per_period
    for a, b in ((k, py), (k, gen)):
        assert np.allclose(a.exponents, b.exponents, rtol=1e-11, atol=1e-12)
    g = Gains(-0.5, -0.6, delay=0.5)
    kd = lyapunov_exact(p, (1e-4, 0.0), 800, 100, gains=g, control_after=300)
    pd = lyapunov_exact(p, (1e-4, 0.0), 800, 100, gains=g, control_after=300, engine="python")
    assert kd.final == pd.final
    assert np.allclose(kd.exponents, pd.exponents, rtol=1e-11, atol=1e-12)
    assert math.isnan(kd.expected_sum)            # (L3) is not claimed with a delay


@pytest.mark.parametrize("delta_d", (-5e-6, -3e-6))
def test_the_largest_exponent_matches_a_two_trajectory_estimate(delta_d):
    p = OscillatorParams(delta_d=delta_d)
    res = lyapunov_exact(p, (1e-4, 0.0), 2200, 200)
    fd = _two_trajectory(p, (1e-4, 0.0), 2200, 200)
    # the same orbit; the separated one differs from the tangent by O(eps) per period and
    # by rare straddles of a grazing contact: agreement to 1 %
    assert fd == pytest.approx(res.maximum, rel=1e-2)


def test_periodic_windows_have_negative_exponents_equal_to_the_multipliers():
    # Delta d = -9e-6: the stable 2-cycle of the study's Fig. 2; -1.5e-5: the stable 1/1
    for delta_d, periods in ((-9e-6, 2), (-1.5e-5, 1)):
        p = OscillatorParams(delta_d=delta_d)
        model = OneDOF(p)
        res = lyapunov_exact(p, (1e-4, 0.0), 3000, 2000)
        assert res.maximum < 0.0
        orbit = find_periodic(model, res.final, periods)
        mults = floquet_multipliers(orbit.monodromy)
        logs = sorted(np.log(np.abs(mults)) / periods, reverse=True)
        # a complex pair (both cases here): each exponent tends to log|mu| / n, the spread
        # decaying like 1/N over the window; their sum is log|det| / n exactly
        assert abs(mults[0].imag) > 0
        assert sum(res.exponents) == pytest.approx(sum(logs), rel=1e-9)
        assert np.allclose(res.exponents, logs, atol=0.01)


def test_a_singular_kick_gives_minus_infinity_and_sticking_is_reported():
    p = OscillatorParams(delta_d=-5e-6)
    res = lyapunov_exact(p, (1e-4, 0.0), 600, 300, gains=Gains(-1.0206, -1.0))
    assert res.exponents[1] == -math.inf and res.maximum < 0.0
    # a motion that sticks every period (slow forcing, the wall well inside the amplitude):
    # all nearby states leave the wall together, the map is singular
    sticky = OscillatorParams.from_d(0.2, r=0.3, omega=0.4)
    res = lyapunov_exact(sticky, (0.0, 0.0), 30, 5)
    py = lyapunov_exact(sticky, (0.0, 0.0), 30, 5, engine="python")
    assert res.stuck_periods == py.stuck_periods == 25
    assert res.exponents == py.exponents == (-math.inf, -math.inf)
    assert math.isnan(res.expected_sum)


@pytest.mark.parametrize("bad", [dict(periods=0), dict(transient=-1), dict(transient=10),
                                 dict(periods=2.5), dict(engine="gpu")])
def test_bad_arguments_name_the_parameter(bad):
    args = dict(periods=10, transient=0, engine="kernel") | bad
    with pytest.raises(ValueError, match=next(iter(bad))):
        lyapunov_exact(OscillatorParams(delta_d=-5e-6), (0.0, 0.0), **args)


def test_grazing_simulate_reports_the_exponents_and_the_identity():
    import json
    import subprocess
    import sys
    run = subprocess.run([sys.executable, "-m", "grazing_control.cli", "simulate", "--delta-d",
                          "-5e-6", "--periods", "1000", "--lyapunov", "--json"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    ly = json.loads(run.stdout)["lyapunov"]
    assert ly["periods"] == 500 and ly["exponents"][0] > 0.05
    assert abs(sum(ly["exponents"]) - ly["expected_sum"]) < 1e-10
    bad = subprocess.run([sys.executable, "-m", "grazing_control.cli", "simulate", "--delta-d",
                          "-5e-6", "--periods", "10", "--lyapunov", "--fidelity", "zdm1"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "--lyapunov needs --fidelity exact" in bad.stderr

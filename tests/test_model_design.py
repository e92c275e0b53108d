"""The one design entry (dynamics/design/model_design.py, issue 32): the 1-DOF closed form
behind it bit for bit, a model file's family behind it bit for bit, and for n = 1 the
two one family (mu <-> c2 through the family's k_v0(mu)) to 1e-12."""

from pathlib import Path

import numpy as np
import pytest

from grazing_control.dynamics.design import family, gains
from grazing_control.dynamics.design import model_design as md
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.ndof import load_model
from grazing_control.oscillator.params import OscillatorParams

MODELS = Path(__file__).resolve().parents[1] / "config" / "models"
P = OscillatorParams()
ONE = load_model(MODELS / "study_1dof.yaml")
CHAIN = load_model(MODELS / "two_mass_chain.yaml")
CONDITIONS = ("combined", "impacting", "non-impacting")


@pytest.mark.parametrize("delay", [0.0, 2.0])
def test_the_1dof_closed_form_is_behind_the_entry_bit_for_bit(delay):
    assert md.parameter_name(P) == "c2"
    for c2 in (-1.0, -0.4, 0.3):
        g = Gains(gains.degenerate_c1(P, c2, delay), c2, delay)
        want, got = gains.evaluate_design(P, c2, delay), md.evaluate_design(P, c2, delay)
        assert (got.c1, got.c2, got.gamma1, got.delay) == (want.c1, want.c2, want.gamma1,
                                                           want.delay)
        assert np.array_equal(got.multipliers_limit, want.multipliers_limit)
        assert np.array_equal(got.multipliers_free, want.multipliers_free)
        assert np.array_equal(md.limit_multipliers(P, c2, delay), gains.limit_multipliers(P, g))
        assert md.existence_coefficient(P, c2, delay) == gains.existence_coefficient(P, g)
        assert np.array_equal(md.free_multipliers(P, c2, delay), gains.free_multipliers(P, g))
    for c in CONDITIONS:
        assert md.admissible_set(P, c, delay) == gains.admissible_c2(P, delay=delay,
                                                                     conditions=c)


def test_a_model_files_family_is_behind_the_entry_bit_for_bit():
    assert md.parameter_name(CHAIN) == "mu"
    for mu in (-0.3, 0.0, 0.2):
        want, got = family.evaluate_design(CHAIN, mu), md.evaluate_design(CHAIN, mu)
        assert np.array_equal(got.gains, want.gains) and got.gamma1 == want.gamma1
        assert np.array_equal(md.limit_multipliers(CHAIN, mu),
                              family.limit_multipliers(CHAIN, mu))
        assert md.existence_coefficient(CHAIN, mu) == family.existence_coefficient(CHAIN, mu)
        assert np.array_equal(md.free_multipliers(CHAIN, mu), family.free_multipliers(CHAIN, mu))
    for c in CONDITIONS:
        assert md.admissible_set(CHAIN, c) == family.admissible_mu(CHAIN, c)


def _sorted(z):
    return np.array(sorted(np.asarray(z, dtype=complex), key=lambda x: (x.real, x.imag)))


@pytest.mark.parametrize("delay", [0.0, 2.0])
def test_n1_the_family_and_the_closed_form_are_one_design(delay):
    """On the n = 1 file the member mu is the 1-DOF design at c2 = k_v0(mu): the same c1,
    limit and free multipliers and gamma1 to 1e-12, and the admissible mu sets map onto
    the admissible c2 sets, ends to 1e-12 (each end is bisected on its own parameter).
    Measured: c1 6e-15, gamma1 5e-15, multipliers 2e-15, interval ends 1.3e-14 relative."""
    k0 = np.asarray(family.gain_family(ONE, 0.0, delay))
    dk = np.asarray(family.gain_family(ONE, 1.0, delay)) - k0
    for mu in (-0.5, 0.0, 0.3):
        c2 = float(k0[1] + dk[1] * mu)
        fam, one = md.evaluate_design(ONE, mu, delay), md.evaluate_design(P, c2, delay)
        assert fam.gains[0] == pytest.approx(one.c1, rel=1e-12, abs=1e-12)
        assert fam.gamma1 == pytest.approx(one.gamma1, rel=1e-12)
        for a, b in ((md.limit_multipliers(ONE, mu, delay), md.limit_multipliers(P, c2, delay)),
                     (md.free_multipliers(ONE, mu, delay), md.free_multipliers(P, c2, delay))):
            assert np.abs(_sorted(a) - _sorted(b)).max() <= 1e-12 * max(1.0, np.abs(b).max())
    for c in CONDITIONS:
        mapped = sorted(tuple(sorted(float(k0[1] + dk[1] * m) for m in iv))
                        for iv in md.admissible_set(ONE, c, delay))
        want = md.admissible_set(P, c, delay)
        assert len(mapped) == len(want)
        for iv, jv in zip(mapped, want):
            for a, b in zip(iv, jv):
                assert a == b or a == pytest.approx(b, rel=1e-12, abs=1e-12)


def test_anything_else_is_refused_naming_the_model():
    with pytest.raises(TypeError, match="model="):
        md.evaluate_design("chain.yaml", 0.0)

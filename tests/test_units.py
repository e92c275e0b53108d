"""support/units.py: a rig file's quantities, "0.5 kg", "2 um", read into SI and written back.

Checked against the SI prefixes by hand (the factors are written here, not taken from
the module), round trips of format_quantity over seeded random values, and refusals
(bare numbers, foreign units, non-finite values, wrong types): each one line naming
the field.
"""

import math
import random

import pytest

from grazing_control.support.units import DIMENSIONS, SI_UNIT, UnitError, format_quantity, quantity

CASES = [
    ("0.5 kg", "mass", 0.5), ("500 g", "mass", 0.5), ("2 um", "length", 2e-6),
    ("2 µm", "length", 2e-6), ("2 μm", "length", 2e-6), ("11.4 mm", "length", 11.4e-3),
    ("3 nm", "length", 3e-9), ("1.5 m", "length", 1.5), ("0.5 ms", "time", 5e-4),
    ("20 us", "time", 2e-5), ("7 ns", "time", 7e-9), ("2 s", "time", 2.0),
    ("2 kHz", "frequency", 2000.0), ("20 Hz", "frequency", 20.0), ("5 mHz", "frequency", 5e-3),
    (f"{2 * math.pi} rad/s", "frequency", 1.0), ("50 N", "force", 50.0),
    ("3 mN", "force", 3e-3), ("4 uN", "force", 4e-6), ("1 kN", "force", 1e3),
    ("7.9e3 N/m", "stiffness", 7.9e3), ("2 kN/m", "stiffness", 2e3), ("3 N/mm", "stiffness", 3e3),
    ("1.2 N*s/m", "damping", 1.2), ("1.2 N s/m", "damping", 1.2), ("1.2 Ns/m", "damping", 1.2),
    ("1.2 kg/s", "damping", 1.2), ("3 N/A", "force_constant", 3.0), ("0 rad", "angle", 0.0),
    ("180 deg", "angle", math.pi), ("-90 deg", "angle", -math.pi / 2), (" 1e-3 m ", "length", 1e-3),
    (".5 s", "time", 0.5), ("+2 Hz", "frequency", 2.0), ("2E3 Hz", "frequency", 2000.0),
]


@pytest.mark.parametrize("text,dimension,si", CASES)
def test_a_quantity_is_read_in_si(text, dimension, si):
    assert quantity("f", text, dimension) == pytest.approx(si, rel=1e-15, abs=0.0)


def test_format_quantity_round_trips_over_random_values():
    rng = random.Random(28)
    for _ in range(3000):
        dim = rng.choice(sorted(SI_UNIT))
        v = rng.choice([-1, 1]) * 10 ** rng.uniform(-14, 14) * rng.random()
        assert quantity("f", format_quantity(v, dim), dim) == v


BAD = [
    (0.5, "has no unit"), (2, "has no unit"), (True, "invalid"), ("0.5", "has no unit"),
    ("0.5 kg", "not a length unit"), ("2 Hz", "not a length unit"), ("2 mm/s", "not a length"),
    ("nan m", "invalid"), ("inf m", "invalid"), ("1e400 m", "not a finite length"),
    ("m", "invalid"), ("", "invalid"), ("two m", "invalid"), (None, "invalid"),
    ([1, "m"], "invalid"), ({"value": 1}, "invalid"), ("1 m m", "not a length unit"),
    ("1 M", "not a length unit"), ("1 km", "not a length unit"),
]


@pytest.mark.parametrize("value,why", BAD)
def test_a_bad_quantity_is_one_line_naming_the_field(value, why):
    with pytest.raises(UnitError) as err:
        quantity("sensor.noise", value, "length")
    text = str(err.value)
    assert text.startswith("sensor.noise=") and "\n" not in text
    assert why in text


def test_every_dimension_lists_its_si_unit_first_class():
    for dim, units in DIMENSIONS.items():
        assert SI_UNIT[dim] in units and units[SI_UNIT[dim]] == 1.0

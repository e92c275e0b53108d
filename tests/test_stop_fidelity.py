"""The cheapest adequate stop for a scene (dynamics/simulation/stop_fidelity.py; issue 31 part 4,
docs/theory_contact.md section 18): rigid where the stop is stiff enough for the
tolerance, compliant where it is not, friction only where it matters; the chosen model
run over the scene stays within the tolerance of the full one."""

from __future__ import annotations

import numpy as np
import pytest

from grazing_control.dynamics.maps.compliant_model import CompliantOneDOF
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.model import OneDOF
from grazing_control.dynamics.orbits.shooting import iterate
from grazing_control.dynamics.simulation.stop_fidelity import choose_stop_fidelity
from grazing_control.oscillator.contact import Coulomb, KelvinVoigt
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

P = OscillatorParams(delta_d=-0.05)
GAINS = Gains(degenerate_c1(P, -1.0), -1.0)
START = (0.01, 0.0)
PERIODS = 100


def _choose(k, friction, tol):
    return choose_stop_fidelity(P, KelvinVoigt.from_restitution(k, P.r), friction, PERIODS,
                                tol, deviation=START, gains=GAINS)


@pytest.mark.parametrize("k, friction, tol, chosen", [
    (1e8, None, 1e-3, "rigid"),                   # one-period error 2.1e-4, contracting loop
    (1e8, None, 1e-5, "compliant"),               # the same stop, a tighter tolerance
    (1e3, Coulomb(1e-9), 1e-3, "compliant"),      # friction far below the tolerance
    (1e3, Coulomb(0.01), 1e-3, "compliant_friction"),
])
def test_the_cheapest_adequate_stop_is_chosen_and_named(k, friction, tol, chosen):
    c = _choose(k, friction, tol)
    assert c.stop == chosen, c.reason
    assert c.reason.startswith(chosen) and "tol" in c.reason


def test_the_chosen_rigid_model_stays_within_the_tolerance_over_the_scene():
    """Where rigid is chosen (k_c = 1e8, tol 1e-3), the rigid and the compliant scene
    differ by less than tol over all 100 periods (measured, not estimated)."""
    law = KelvinVoigt.from_restitution(1e8, P.r)
    assert _choose(1e8, None, 1e-3).stop == "rigid"
    full = CompliantOneDOF(P, GAINS, law=law)
    rigid = OneDOF(P.with_(r=law.restitution), GAINS)
    a = b = np.array(START)
    worst = 0.0
    for _ in range(PERIODS):
        a, b = iterate(full, a)[0], iterate(rigid, b)[0]
        worst = max(worst, float(np.max(np.abs(a - b))))
    assert 1e-6 < worst <= 1e-3, worst


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="periods"):
        choose_stop_fidelity(P, KelvinVoigt(1e3), None, 0, 1e-3)
    with pytest.raises(ValueError, match="tol"):
        choose_stop_fidelity(P, KelvinVoigt(1e3), None, 10, 0.0)


def test_grazing_stop_reports_the_choice_and_refuses_bad_values(capsys):
    """``grazing stop``: the choice and its reason (status 0, --json standard JSON); a
    stop given both ways, or overdamped, is one line naming it (status 2)."""
    import json

    from grazing_control.cli.commands import main

    assert main(["stop", "--stiffness", "1e8", "--restitution", "0.68", "--c2", "-1",
                 "--dx", "0.01", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stop"] == "rigid" and out["estimates"]["rigid"]["bound"] <= 1e-3
    assert main(["stop", "--stiffness", "1e3", "--restitution", "0.68", "--friction", "0.01",
                 "--c2", "-1", "--dx", "0.01"]) == 0
    assert "stop model = compliant_friction" in capsys.readouterr().out
    assert main(["stop", "--stiffness", "1e3", "--damping", "1", "--restitution", "0.5"]) == 2
    assert "--damping and --restitution" in capsys.readouterr().err
    assert main(["stop", "--stiffness", "1e3", "--damping", "100"]) == 2
    assert "damping=100.0 is invalid" in capsys.readouterr().err

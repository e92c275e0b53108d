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
from grazing_control.dynamics.simulation.simulate import simulate
from grazing_control.dynamics.simulation.stop_fidelity import (choose_stop_fidelity,
                                                              rigid_stand_in, simulate_stop)
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


# ============================================================ the scene on its choice
def test_a_scene_runs_on_the_model_its_bound_chooses_on_both_sides_of_the_tolerance():
    """simulate_stop (``grazing simulate --contact``): with the tolerance just above the
    rigid model's bound the scene runs on the rigid wall, just below it on the compliant
    stop; either way the samples are those of the chosen model run directly (the rigid
    wall's exact flow, the compliant period map's loop), bit for bit."""
    law = KelvinVoigt.from_restitution(1e8, P.r)
    bound = _choose(1e8, None, 1.0).estimates["rigid"][1]
    assert 1e-5 < bound < 1e-3, bound                     # measured 2.8e-4
    above, choice, warning = simulate_stop(P, law, None, PERIODS, deviation=START,
                                           gains=GAINS, tol=1.01 * bound)
    assert choice.stop == "rigid" and warning is None, choice.reason
    direct = simulate(rigid_stand_in(P, law), PERIODS, deviation=START, gains=GAINS)
    assert np.array_equal(above.pi2, direct.pi2)
    assert np.array_equal(above.impacts_per_period, direct.impacts_per_period)
    below, choice, _ = simulate_stop(P, law, None, PERIODS, deviation=START, gains=GAINS,
                                     tol=0.99 * bound)
    assert choice.stop == "compliant", choice.reason
    assert "rigid refused" in choice.reason
    model, z = CompliantOneDOF(P, GAINS, law=law), np.array(START)
    for k in range(PERIODS):
        assert np.array_equal(below.pi2_deviation[k], z), k
        z = iterate(model, z)[0]
    # measured: the two scenes differ by less than the bound said
    assert 0.0 < np.max(np.abs(above.pi2 - below.pi2)) <= bound


def test_a_model_forced_against_its_bound_runs_with_a_warning_giving_the_numbers():
    law = KelvinVoigt.from_restitution(1e4, P.r)
    res, choice, warning = simulate_stop(P, law, Coulomb(0.01), 20, deviation=START,
                                         gains=GAINS, stop="rigid", tol=1e-3)
    assert choice.stop == "rigid" and warning is not None
    bound = choice.estimates["rigid"][1]
    assert bound > 1e-3 and f"{bound:.3g}" in warning and "compliant_friction" in warning
    assert np.array_equal(res.pi2, simulate(rigid_stand_in(P, law), 20, deviation=START,
                                            gains=GAINS).pi2)
    # an adequate choice is honoured without a warning; friction without friction refused
    _, choice, warning = simulate_stop(P, law, Coulomb(0.01), 20, deviation=START,
                                       gains=GAINS, stop="compliant_friction")
    assert choice.stop == "compliant_friction" and warning is None
    with pytest.raises(ValueError, match="compliant_friction"):
        simulate_stop(P, law, None, 20, stop="compliant_friction")
    with pytest.raises(ValueError, match="stop="):
        simulate_stop(P, law, None, 20, stop="soft")


def test_grazing_simulate_reports_the_stop_model_and_equals_it_run_directly(capsys):
    """``grazing simulate --contact kelvin_voigt``: the chosen model, its reason and every
    candidate's bound in the JSON, the samples those of the chosen model; a forced model
    over its bound warns on stderr (status 0); a stop option without the stop is one
    line (status 2)."""
    import json

    from grazing_control.cli.commands import main

    scene = ["simulate", "--delta-d", "-0.05", "--periods", "30", "--dx0", "0.01", "--c2",
             "-1", "--contact", "kelvin_voigt", "--contact-stiffness", "1e4", "--json"]
    assert main(scene) == 0
    out = json.loads(capsys.readouterr().out)
    law = KelvinVoigt.from_restitution(1e4, P.r)
    assert out["stop"] == "compliant" and out["stop_reason"].startswith("compliant")
    assert out["stop_estimates"]["rigid"]["bound"] > 1e-3
    direct, _, _ = simulate_stop(P, law, None, 30, deviation=START, gains=GAINS,
                                 stop="compliant")
    assert np.array_equal(np.array(out["pi2"]), direct.pi2)
    assert main(scene + ["--stop", "rigid"]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert out["stop"] == "rigid" and "not adequate" in out["stop_warning"]
    assert "grazing: warning: stop model rigid is not adequate" in cap.err
    assert main(["simulate", "--delta-d", "-0.05", "--periods", "3", "--friction",
                 "0.01"]) == 2
    assert "--friction: valid only with --contact kelvin_voigt" in capsys.readouterr().err


def test_grazing_run_stop_applies_the_choice_to_the_simulator_before_any_node_starts():
    """``grazing run --stop`` (cli/stop.apply_run_stop, no node started here): a stiff
    stop is run as the rigid wall with its restitution, a soft one keeps the compliant
    stop and drops a friction below the tolerance's notice only where the bound says so;
    a model forced over its bound is kept with the warning; --stop without a Kelvin-Voigt
    stop, or --stop-tol without --stop, is one ParameterError line."""
    from grazing_control.cli.commands import build_parser
    from grazing_control.cli.stop import apply_run_stop
    from grazing_control.oscillator.params import ParameterError

    def args(*extra, stiffness=1e8, friction=None):
        law = KelvinVoigt.from_restitution(stiffness, P.r)
        argv = ["run", "--periods", "100", "--delta-d", "-0.05", "--enable-after", "0",
                "--sim-param", "contact:=kelvin_voigt",
                "--sim-param", f"contact_stiffness:={law.stiffness!r}",
                "--sim-param", f"contact_damping:={law.damping!r}",
                "--sim-param", f"x0:={P.x_ref + START[0]!r}"]
        if friction is not None:
            argv += ["--sim-param", f"friction:={friction!r}"]
        return build_parser().parse_args(argv + list(extra))

    a = args("--stop", "auto")
    report = apply_run_stop(a)
    over = dict(a.sim_overrides)
    assert report["stop"] == "rigid" and report["warning"] is None, report
    assert over["contact"] == "rigid" and over["r"] == pytest.approx(P.r, abs=1e-12)
    assert report["estimates"]["rigid"]["bound"] == pytest.approx(
        _choose(1e8, None, 1e-3).estimates["rigid"][1], rel=1e-9)   # the same scene
    a = args("--stop", "auto", "--stop-tol", "1e-5")
    assert apply_run_stop(a)["stop"] == "compliant"
    assert dict(a.sim_overrides)["contact"] == "kelvin_voigt"
    a = args("--stop", "auto", stiffness=1e3, friction=0.01)
    assert apply_run_stop(a)["stop"] == "compliant_friction"
    assert dict(a.sim_overrides)["friction"] == "0.01"       # as given (text)
    a = args("--stop", "rigid", stiffness=1e3, friction=0.01)
    report = apply_run_stop(a)
    assert report["stop"] == "rigid" and "not adequate" in report["warning"]
    assert dict(a.sim_overrides)["friction"] == 0.0
    assert apply_run_stop(args()) is None
    with pytest.raises(ParameterError, match="--stop-tol needs --stop"):
        apply_run_stop(args("--stop-tol", "1e-3"))
    with pytest.raises(ParameterError, match="kelvin_voigt stop"):
        apply_run_stop(build_parser().parse_args(["run", "--periods", "10", "--stop",
                                                  "auto"]))

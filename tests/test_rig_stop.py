"""The rig file's stop section (grazing_control/plant/rig.py, docs/rig.md "The stop").

* the round trip rig_to_dict -> YAML -> rig_from_dict is exact for every stop, over
  seeded random rigs;
* the scaling is checked independently: the SI equation with the stop's SI force law
  (Kelvin-Voigt, Hertz with Hunt-Crossley damping), integrated by scipy's solve_ivp
  (DOP853, the contact's start and end as events), against the core's dimensionless
  contact flow with Rig.contact_values, scaled back;
* each refusal is one line naming the field;
* a rig scene runs a compliant stop (rig_boundary.sim_values gives sim_node its contact
  parameters): one short scene through the nodes with a Kelvin-Voigt stop and friction,
  its Pi2 samples the core's pulse map of that stop with the pulses that acted.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from grazing_control.oscillator.contact import KelvinVoigt, advance_compliant
from grazing_control.oscillator.flow import to_physical
from grazing_control.oscillator.hertz import HuntCrossley, advance_hertz
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.rig import RigError, Stop, rig_from_dict, rig_to_dict
from grazing_control.ros.rig_boundary import sim_values

from rig_files import LAB as LAB_RIGID
from rig_files import dump, load, random_rig


def _random_stop(rng, doc, kind):
    """A stop section for the rig of ``doc``: K = k_c k with k_c in 1e1..1e6, C a fraction
    of the underdamped limit; Hertz K_H = k_c k / sqrt(l), A = alpha / (omega_n l)."""
    rig = rig_from_dict(doc)
    k, m, wn, L = rig.stiffness, rig.mass, rig.omega_n, rig.scales.length
    kc = min(10 ** rng.uniform(1, 6), 1e11 / k)   # K within the file's 1e12 N/m
    if kind == "hertz":      # within the file's magnitudes (1e-12 .. 1e12 SI)
        kc = float(np.clip(kc, 1e-11 * math.sqrt(L) / k, 1e11 * math.sqrt(L) / k))
        return {"type": "hertz", "stiffness": f"{kc * k / math.sqrt(L)!r} N/m^1.5",
                "damping": f"{rng.uniform(0, 0.5) / (wn * L)!r} s/m"}
    cc = rng.uniform(0, 0.9) * min(2 * math.sqrt(1 + kc) - 2 * rig.zeta, 2 * math.sqrt(kc))
    out = {"type": "kelvin_voigt", "stiffness": f"{kc * k!r} N/m",
           "damping": f"{cc * m * wn!r} N*s/m"}
    if rng.random() < 0.5:
        ff = rng.uniform(0, 0.02) * rig.scales.force
        out["friction"] = f"{ff!r} N"
        out["friction_static"] = f"{ff * rng.uniform(1, 1.5)!r} N"
    return out


def test_the_round_trip_with_a_stop_is_exact_over_random_rigs():
    rng = np.random.default_rng(3131)
    kinds = ("rigid", "kelvin_voigt", "hertz")
    for i in range(600):
        doc = random_rig(rng)
        kind = kinds[i % 3]
        if kind != "rigid":
            doc["stop"] = _random_stop(rng, doc, kind)
        rig = rig_from_dict(doc)
        assert rig.stop.type == kind
        again = rig_from_dict(load(dump(rig_to_dict(rig))))
        assert again.stop == rig.stop
        a, b = again.contact_values(), rig.contact_values()
        assert a.pop("contact") == b.pop("contact") == kind
        assert a == pytest.approx(b, rel=2e-15)   # omega_n back to 1 ulp
        if kind == "rigid":
            assert "stop" not in rig_to_dict(rig) and rig.contact_values() == {"contact": "rigid"}


def _si_contact_motion(rig, t0, x0, v0, t1):
    """Contact entries (t, v at entry) and the end state of the SI equation with the
    rig's stop, by solve_ivp: m x'' + c x' + k x = F0 cos(Omega t + phi) - F_c, F_c of
    the stop's SI law (rig.py's module docstring) while x > g and F_c > 0. Each region
    integrated on its own, its end an event (entry: x = g rising, or the force's
    return above the stop; exit: F_c = 0 falling)."""
    st = rig.stop
    m, c, k, g = rig.mass, rig.damping, rig.stiffness, rig.gap
    W, phi, F0 = 2 * math.pi * rig.frequency, rig.phase, rig.amplitude
    hertz = st.type == "hertz"

    def force(s):          # the law's value, without the region's sign condition
        delta = s[0] - g
        if hertz:
            return st.stiffness * max(delta, 0.0) ** 1.5 * (1 + 1.5 * st.damping * s[1])
        return st.stiffness * delta + st.damping * s[1]

    def push(s):           # the switching function of the force (0 at the exit)
        return 1 + 1.5 * st.damping * s[1] if hertz else force(s)

    def rhs(contact):
        def f(t, s):
            fc = force(s) if contact else 0.0
            return [s[1], (F0 * math.cos(W * t + phi) - c * s[1] - k * s[0] - fc) / m]
        return f

    def ev(fun, direction):
        fun.terminal, fun.direction = True, direction
        return fun

    L = rig.scales.length
    state, t, entries = [x0, v0], t0, []
    mode = "below"
    while t < t1:
        if mode == "contact":
            events = [ev(lambda t, s: push(s), -1.0), ev(lambda t, s: s[0] - g, -1.0)]
        elif mode == "below":
            events = [ev(lambda t, s: s[0] - g, 1.0)]
        else:              # above the stop after an exit: back below, or the force returns
            events = [ev(lambda t, s: s[0] - g, -1.0), ev(lambda t, s: push(s), 1.0)]
        sol = solve_ivp(rhs(mode == "contact"), (t, t1), state, method="DOP853", rtol=1e-13,
                        atol=[1e-16 * L, 1e-16 * L * rig.omega_n], events=events)
        if sol.status != 1:
            state, t = list(sol.y[:, -1]), t1
            continue
        i = next(j for j, te in enumerate(sol.t_events) if len(te))
        t, state = sol.t_events[i][0], list(sol.y_events[i][0])
        if mode == "contact":
            mode = "above" if i == 0 and state[0] > g else "below"
        elif mode == "below" or i == 1:
            mode = "contact"
            entries.append((t, state[1]))
        else:
            mode = "below"
        if mode == "below":
            state[0] = min(state[0], g)     # on the surface: the root to rounding
    return entries, state


@pytest.mark.parametrize("kind", ["kelvin_voigt", "hertz"])
def test_the_si_stop_agrees_with_the_scaled_contact_flow(kind):
    """The scaling of rig.py's docstring, independently: k_c = K/k, c_c = C/(m omega_n);
    Hertz k_c = K_H sqrt(l)/k, alpha = A omega_n l."""
    rng = np.random.default_rng(311 if kind == "kelvin_voigt" else 312)
    contacts = 0
    for case in range(4):
        doc = random_rig(rng, forcing="force", depth=float(rng.uniform(0.05, 0.3)))
        doc["damping_ratio"] = float(rng.uniform(0.02, 0.2))
        doc.pop("damping", None)
        doc["stop"] = _random_stop(rng, doc, kind)
        doc["stop"].pop("friction", None)
        doc["stop"].pop("friction_static", None)
        rig = rig_from_dict(doc)
        p, s, cv = rig.params(), rig.scales, rig.contact_values()
        duration = 3 * p.period
        dx, dv = p.delta_d - 0.3 * p.d_star, 0.2
        x0, v0 = to_physical(p, p.tau2, dx, dv)
        if kind == "hertz":
            seg = advance_hertz(p, HuntCrossley(cv["contact_stiffness"], cv["contact_damping"]),
                                p.tau2, x0, v0, duration)
        else:
            seg = advance_compliant(p, KelvinVoigt(cv["contact_stiffness"], cv["contact_damping"]),
                                    p.tau2, x0, v0, duration)
        t0 = rig.rig_time(0.0)
        entries, (x1, v1) = _si_contact_motion(rig, t0, x0 * s.length, v0 * s.velocity,
                                               rig.rig_time(duration))
        assert len(seg.contacts) == len(entries), case
        contacts += len(entries)
        for con, (te, vm) in zip(seg.contacts, entries):
            assert te == pytest.approx(rig.rig_time(con.dt), abs=1e-8 * rig.forcing_period)
            assert vm == pytest.approx(con.v_minus * s.velocity, abs=1e-7 * s.velocity)
        assert x1 == pytest.approx(seg.x * s.length, abs=1e-7 * s.length)
        assert v1 == pytest.approx(seg.v * s.velocity, abs=1e-7 * s.velocity)
    assert contacts >= 4


@pytest.mark.parametrize("stop, names", [
    ({"type": "soft"}, "stop.type='soft' is invalid"),
    ({"type": "kelvin_voigt"}, "stop.stiffness is missing"),
    ({"type": "kelvin_voigt", "stiffness": 2e5}, "stop.stiffness=200000.0 has no unit"),
    ({"type": "kelvin_voigt", "stiffness": "-1 N/m"}, "stop.stiffness='-1 N/m' is invalid"),
    ({"type": "hertz", "stiffness": "2e5 N/m"}, "unit 'N/m' is not a hertz stiffness unit"),
    ({"type": "kelvin_voigt", "stiffness": "2e5 N/m", "damping": "5e5 N*s/m"},
     "stop.damping='5e5 N*s/m' is invalid: the contact must be underdamped"),
    ({"type": "kelvin_voigt", "stiffness": "2e5 N/m", "friction": "1 N",
      "friction_static": "0.5 N"}, "stop.friction_static='0.5 N' is invalid"),
    ({"type": "hertz", "stiffness": "1e9 N/m^1.5", "friction": "1 N",
      "friction_static": "0.5 N"}, "stop.friction_static='0.5 N' is invalid"),
    ({"type": "rigid", "stiffness": "2e5 N/m"}, "stop.stiffness is a compliant stop's field"),
    ({"type": "kelvin_voigt", "stiffness": "2e5 N/m", "viscosity": "1 N"},
     "stop.viscosity is not a rig field"),
    ("hard", "stop='hard' is invalid"),
])
def test_a_bad_stop_is_one_line_naming_the_field(lab_doc, stop, names):
    lab_doc["stop"] = stop
    with pytest.raises(RigError) as exc:
        rig_from_dict(lab_doc)
    assert names in str(exc.value) and "\n" not in str(exc.value)


@pytest.fixture
def lab_doc():
    import copy

    from rig_files import LAB

    return copy.deepcopy(LAB)


def test_the_lab_rig_with_a_stop_in_dimensionless_units_and_the_rig_scene_takes_it(lab_doc):
    """The lab rig (m 0.5 kg, f_n 20 Hz: k = 7895.68 N/m, omega_n = 125.664 rad/s,
    l = 6.3326 mm): K = 2e5 N/m is k_c = 25.3303, C = 5 N s/m is c_c = 5 / (0.5 * 125.664)
    = 0.0795775, F_f = 0.01 N is 0.01 / (k l = 50 N) = 2e-4."""
    rigid = rig_from_dict(lab_doc)
    assert rigid.stop == Stop() and sim_values(rigid)["zeta"] == rigid.zeta
    lab_doc["stop"] = {"type": "kelvin_voigt", "stiffness": "2e5 N/m", "damping": "5 N*s/m",
                       "friction": "10 mN"}
    rig = rig_from_dict(lab_doc)
    values = rig.contact_values()
    assert values.pop("contact") == "kelvin_voigt"
    assert values == pytest.approx(
        {"contact_stiffness": 2e5 / rigid.stiffness,
         "contact_damping": 5 / (0.5 * rigid.omega_n), "friction": 0.01 / rigid.scales.force,
         "friction_static": 0.01 / rigid.scales.force}, rel=1e-14)
    assert rig.contact_values()["contact_stiffness"] == pytest.approx(25.3303, abs=1e-4)
    assert rig.contact_values()["friction"] == pytest.approx(2e-4, rel=1e-6)
    # the rig scene's simulator takes the stop (realtime, the correction a force pulse)
    from grazing_control.plant.settings import settings_from_values

    sim = sim_values(rig)
    assert {k: sim[k] for k in rig.contact_values()} == rig.contact_values()
    s = settings_from_values({**sim, "mode": "realtime"})
    assert s.contact.law == KelvinVoigt(values["contact_stiffness"], values["contact_damping"])
    assert s.contact.friction.kinetic == values["friction"] and s.pulse_width > 0.0
    assert sim_values(rigid)["contact"] == "rigid"
    # Coulomb friction with the Hertz stop too (issue 31 part 3), through the round trip
    lab_doc["stop"] = {"type": "hertz", "stiffness": "1e9 N/m^1.5", "damping": "0.2 s/m",
                       "friction": "10 mN", "friction_static": "12 mN"}
    hertz = rig_from_dict(lab_doc)
    assert rig_from_dict(load(dump(rig_to_dict(hertz)))) == hertz
    s = settings_from_values({**sim_values(hertz), "mode": "realtime"})
    assert s.contact.friction.kinetic == pytest.approx(2e-4, rel=1e-12)
    assert s.contact.friction.static == pytest.approx(2.4e-4, rel=1e-12)
    assert settings_from_values({**sim_values(rigid), "mode": "realtime"}).contact is None


def test_grazing_rig_prints_the_stop_in_si_and_dimensionless(lab_doc):
    from grazing_control.cli.rig import _stop_lines, _stop_si

    lab_doc["stop"] = {"type": "hertz", "stiffness": "1e9 N/m^1.5", "damping": "0.2 s/m"}
    rig = rig_from_dict(lab_doc)
    lines = _stop_lines({"stop": _stop_si(rig)}, rig.contact_values())
    k_c = 1e9 * math.sqrt(rig.scales.length) / rig.stiffness     # 10078.6
    assert lines[0] == ("  stop               = hertz K_H = 1e+09 N/m^1.5, Hunt-Crossley "
                        "A = 0.2 s/m")
    assert f"k_c = K_H sqrt(l)/k = {k_c:.6g}" in lines[1] and "alpha = A omega_n l = 0.159155" \
        in lines[1]
    assert _stop_lines({"stop": _stop_si(rig_from_dict(LAB_RIGID))}, {}) == [
        "  stop               = rigid wall (restitution r)"]


def test_grazing_run_takes_a_rig_with_a_compliant_stop(lab_doc, tmp_path):
    """The check before any node starts (cli/commands._check_run_files: what sim_node
    refuses) passes a rig file with a compliant stop (it refused it, status 2, before)."""
    import argparse

    from grazing_control.cli.commands import _check_run_files

    lab_doc["stop"] = {"type": "kelvin_voigt", "stiffness": "2e5 N/m", "damping": "5 N*s/m"}
    path = tmp_path / "soft.yaml"
    path.write_text(dump(lab_doc))
    _check_run_files(argparse.Namespace(sim_params=None, model=None, controller_params=None,
                                        rig=str(path), bag_dir=None))


#: an eighth of physical speed (the controller's budget 32 ms of wall time, as
#: tests/test_rig_scene.py); the rig's design c2 of least noise gain (bench_rig_scene.py)
SLOW, C2 = 8.0, 0.03276358910091768


@pytest.mark.timeout(240)
def test_a_rig_scene_on_a_compliant_stop_with_friction_is_the_cores_pulse_map(tmp_path):
    """The acceptance rig on a soft Kelvin-Voigt stop (k_c = 1e3) with friction through
    sim_node and controller_node (the driver contract, realtime, force pulses): every
    Pi2 sample is the core's pulse map of that stop (ContactPlant.pulse_step) from the
    one before, with the correction of the pulse that acted there (rig/applied, SI back
    to Delta v~), to 1e-12; the stop's contacts are published as impacts."""
    from pathlib import Path

    from grazing_control.dynamics.simulation.actuation import pulse_start
    from grazing_control.plant.rig import load_rig
    from grazing_control.plant.settings import settings_from_values
    from grazing_control.ros import launcher
    from grazing_control.ros.rig_boundary import correction_of

    from test_rig_scene import _messages

    rigs = Path(__file__).resolve().parents[1] / "config" / "rigs"
    doc = load((rigs / "acceptance_stop_soft.yaml").read_text())
    doc["stop"]["friction"] = "0.1 mN"
    path = tmp_path / "soft_friction.yaml"
    path.write_text(dump(doc))
    rig = load_rig(path)
    periods = 9
    res = launcher.run(None, None, str(tmp_path / "bag"), periods, rig=str(path),
                       enable_after=3, timeout=180, log_dir=str(tmp_path / "logs"),
                       sim_overrides={"time_scale": rig.omega_n / SLOW, "feasibility": "warn"},
                       controller_overrides={"rig_c2": C2})
    assert res.ok, res
    m = _messages(tmp_path / "bag", ("/oscillator/pi2", "/rig/applied", "/rig/phase",
                                     "/oscillator/impact"))
    s = settings_from_values({**sim_values(rig), "mode": "realtime"})
    assert s.contact.friction.kinetic == pytest.approx(2e-6)
    p, w = s.params, s.pulse_width
    start = pulse_start(p.period, s.actuation_delay, w)
    z = np.array([(msg.position[0] - p.x_ref, msg.velocity[0] - p.v_ref)
                  for _, msg in m["/oscillator/pi2"]])
    phases = [msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
              for _, msg in m["/rig/phase"]]
    applied = {round(msg.wrench.torque.y, 6): msg.wrench.force.x for _, msg in m["/rig/applied"]}
    acted = 0
    for k in range(min(len(z), len(phases)) - 1):
        force = applied.get(round(phases[k], 6), 0.0)
        acted += force != 0.0
        nx, nv, _ = s.contact.pulse_step(p, *z[k], correction_of(rig, force, rig.actuator.pulse_width),
                                         start, w, s.force_limit or math.inf)
        assert (nx, nv) == pytest.approx(tuple(z[k + 1]), abs=1e-12), k
    assert len(z) >= periods - 1 and acted >= 4
    assert len(m["/oscillator/impact"]) >= periods // 2

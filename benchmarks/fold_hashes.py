"""Hashes of the plant engine's output over seeded 1-DOF scenes (issue 32, the fold of the
plant): run on main before the fold and on the branch after it, the lines must be equal.

Each scene drives :class:`grazing_control.plant.engine.Engine` directly, as the loops do
(sample, measured sample, loss, delay, begin_period or begin_head/actuate, a split on
arrival, end_period), with a fixed linear law on the measured sample, and hashes every
event (kind, and t, x, v, phase as float.hex) and every end-of-period state. The scenes
cover the stream and its sensor, velocity and measurement noise, loss and jitter, the
delay, the force pulse, the first-order actuator, the compliant stop with friction, the
drifting wall, a pending model change and corrections on arrival.

    .venv/bin/python benchmarks/fold_hashes.py
"""

from __future__ import annotations

import hashlib

from grazing_control.plant.engine import Engine
from grazing_control.plant.settings import settings_from_values

SCENES = {
    "stream_noise_faults_delay": dict(delta_d=-5e-6, state_period=0.05, sensor_noise=1e-4,
                                      sensor_velocity=False, sensor_quantum=1e-6,
                                      sensor_bias=1e-5, sensor_seed=3, noise=1e-6, seed=7,
                                      measurement_noise=1e-6, loss=0.1, jitter=0.2,
                                      actuation_delay=0.3, max_periods=60),
    "pulse": dict(delta_d=-5e-6, state_period=0.1, pulse_width=0.2, force_limit=5.0,
                  actuation_delay=0.5, max_periods=60),
    "actuator": dict(delta_d=-5e-6, state_period=0.1, actuator_bandwidth=20.0,
                     actuator_latency=0.05, pulse_width=0.1, actuation_delay=0.3,
                     max_periods=60),
    "contact_friction": dict(delta_d=-5e-6, state_period=0.1, contact="kelvin_voigt",
                             contact_stiffness=1e5, contact_damping=0.1, friction=1e-4,
                             friction_static=2e-4, actuation_delay=0.2, max_periods=40),
    "drift": dict(delta_d=-5e-6, delta_d_drift=1e-8, state_period=0.25, max_periods=60),
    "on_arrival": dict(delta_d=-5e-6, state_period=0.1, mode="realtime",
                       actuation="on_arrival", time_scale=1000.0, max_periods=60),
    "pending": dict(delta_d=-5e-6, state_period=0.1, max_periods=60),
}

C1, C2 = -0.4, -0.02


def _h(ev) -> str:
    return f"{ev.kind} {ev.t.hex()} {float(ev.x).hex()} {float(ev.v).hex()} {ev.phase.hex()}"


def run(name: str, values: dict) -> str:
    s = settings_from_values(values)
    eng = Engine(s)
    h = hashlib.sha256()
    ref = eng.sample()
    h.update(_h(ref).encode())
    for ev in eng.initial_states():
        h.update(_h(ev).encode())
    on_arrival = s.mode == "realtime" and not s.scheduled
    while not eng.done:
        ev = eng.measured(eng.sample())
        p = eng.p
        dv = C1 * (ev.x - p.x_ref) + C2 * (ev.v - p.v_ref)
        if eng.correction_lost():
            dv = 0.0
        delay = eng.actuation_delay()
        if on_arrival:
            events = eng.begin_period(0.0)
            events += eng.split(eng.t + 0.37 * p.period, dv)
        elif delay > 0.0 and eng.k % 2 and not eng.lagged:
            events = eng.begin_head(delay) + eng.actuate(dv, delay)
        else:
            events = eng.begin_period(dv, delay)
        for e in events:
            h.update(_h(e).encode())
        if name == "pending" and eng.k == 30:
            eng.pending = p.with_(delta_d=-3e-6, zeta=p.zeta * 1.01)
        sample, warning = eng.end_period()
        h.update(_h(sample).encode())
        h.update(f"{float(eng.dx).hex()} {float(eng.dv).hex()} {warning}".encode())
    return h.hexdigest()


def main() -> None:
    for name, values in SCENES.items():
        print(f"{name} {run(name, values)}")


if __name__ == "__main__":
    main()

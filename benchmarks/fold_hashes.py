"""Hashes of the plant engine's output over seeded 1-DOF scenes (issue 32, the fold of the
plant): run on main before the fold and on the branch after it, the lines must be equal.

Each scene drives :class:`grazing_control.plant.engine.Engine` directly, as the loops do
(sample, measured sample, loss, delay, begin_period or begin_head/actuate, a split on
arrival, end_period), with a fixed linear law on the measured sample, and hashes every
event (kind, and t, x, v, phase as float.hex) and every end-of-period state. The scenes
cover the stream and its sensor, velocity and measurement noise, loss and jitter, the
delay, the force pulse, the first-order actuator, the compliant stop with friction, the
drifting wall, a pending model change and corrections on arrival.

    .venv/bin/python benchmarks/fold_hashes.py          # the engine's scenes
    .venv/bin/python benchmarks/fold_hashes.py --bag    # and a lockstep bag's payloads

Recorded on main 5b8ea17 (before the fold) and kept in tests/test_plant_engine.py
(:data:`MAIN_HASHES`), which runs the engine's scenes against them.

With ``--bag`` it also runs a lockstep 1-DOF scene through the nodes (``grazing run
--compose``, 80 periods, the stream at 0.1, control from sample 30) into a bag and hashes
the payloads of the simulator's and controller's data topics in their order of arrival
(the wall-clock topics -- latency, diagnostics, the parameter and published records,
/clock -- left out).
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


#: The topics of a lockstep scene that carry simulation results only.
BAG_TOPICS = ("/oscillator/pi2", "/oscillator/pi1", "/oscillator/state", "/oscillator/impact",
              "/controller/velocity_correction", "/controller/enabled")


#: ``--bag`` on main 5b8ea17 before the fold: (messages, sha256 of the payloads) per topic.
MAIN_BAG_HASHES = {
    "/oscillator/pi2": "80 afd90c81ebb91b751f8d7a0c56dcbb02828a61ca316d32fc3b9322097a7cd780",
    "/oscillator/pi1": "80 c1b3d54ad9a264666e90861b7286ad78d38a8b5b6d3bc97446f63a4612ca55dd",
    "/oscillator/state": "7535 693ec8e68b7831ea743631738ffacd84dacaf04f71d15cbcb3087f5dead2ebb2",
    "/oscillator/impact": "75 545490a7fda66665dbe6372166d12a0653407f4db329fe545fae9ed89a6418ab",
    "/controller/velocity_correction":
        "80 542c975b55ca28111ff7ce92440287623ab30c4ab49cfec875cadb73b992a682",
    "/controller/enabled": "0 e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855",
}


def bag_hashes() -> dict:
    """{topic: sha256 of its payloads in order} of a lockstep scene run by ``grazing run``."""
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from mcap.reader import make_reader

    from grazing_control.recordings.reader import bag_path

    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bag"
        subprocess.run([str(Path(sys.executable).with_name("grazing")), "run", "--compose",
                        "--bag", str(bag), "--periods", "80", "--delta-d", "-5e-6",
                        "--enable-after", "30", "--sim-param", "state_period:=0.1"],
                       check=True, capture_output=True)
        hashes = {t: hashlib.sha256() for t in BAG_TOPICS}
        counts = dict.fromkeys(BAG_TOPICS, 0)
        with open(bag_path(bag), "rb") as fh:
            for _schema, channel, message in make_reader(fh).iter_messages(
                    topics=list(BAG_TOPICS), log_time_order=False):
                hashes[channel.topic].update(message.data)
                counts[channel.topic] += 1
    return {t: f"{counts[t]} {h.hexdigest()}" for t, h in hashes.items()}


#: An n-DOF scene (config/models/two_mass_scene.yaml): stream, sensor, loss, jitter, delay.
NDOF_SCENE = dict(delta_d=-1e-5, state_period=0.1, sensor_noise=1e-4, sensor_seed=2,
                  loss=0.1, jitter=0.2, seed=5, actuation_delay=0.3, max_periods=60)
NDOF_GAINS = (-0.3, 0.1, -0.05, 0.02)


def ndof_engine(values: dict):
    """The engine of the n-DOF scene: before the fold plant.ndof_engine's, after it the
    one Engine with settings_from_values(..., model_file=...)."""
    path = "config/models/two_mass_scene.yaml"
    try:
        from grazing_control.plant.ndof_engine import NdofEngine
        from grazing_control.plant.ndof_settings import ndof_settings_from_values
        return NdofEngine(ndof_settings_from_values(values, path))
    except ImportError:
        return Engine(settings_from_values(values, model_file=path))


def run_ndof(values: dict) -> str:
    import numpy as np

    eng = ndof_engine(values)
    h = hashlib.sha256()

    def put(ev):
        h.update(f"{ev.kind} {ev.t.hex()} {ev.x} {ev.v} {ev.phase.hex()}".encode())

    put(eng.sample())
    for ev in eng.initial_states():
        put(ev)
    k = np.array(NDOF_GAINS)
    ref = None
    while not eng.done:
        ev = eng.sample()
        X = np.array(ev.x + ev.v)
        ref = X if ref is None else ref
        dv = 0.0 if eng.correction_lost() else float(k @ (X - ref))
        delay = eng.actuation_delay()
        if eng.k % 3 == 1:
            events = eng.begin_period(0.0) + eng.split(eng.t + 0.41 * eng.p.period, dv)
        elif eng.k % 3 == 2 and delay > 0.0:
            events = eng.actuate(dv, delay)
        else:
            events = eng.begin_period(dv, delay)
        for e in events:
            put(e)
        put(eng.end_period()[0])
    return h.hexdigest()


def main() -> None:
    import sys

    for name, values in SCENES.items():
        print(f"{name} {run(name, values)}")
    print(f"ndof_two_mass {run_ndof(NDOF_SCENE)}")
    if "--bag" in sys.argv[1:]:
        for topic, h in bag_hashes().items():
            same = "as on main" if MAIN_BAG_HASHES.get(topic) == h else "DIFFERS from main"
            print(f"bag {topic} {h} {same}")


if __name__ == "__main__":
    main()

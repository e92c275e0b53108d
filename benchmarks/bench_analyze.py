"""Benchmark of the bag analysis: messages per second on a 1e6-message bag, side by side
with reading the same bag with rosbags' AnyReader and with mcap_ros2 alone.

The bag (benchmarks/out/bench_analyze_<N>/, git-ignored, made once) has the project's
topics in the proportions of a lockstep recording with state_period 1 (per forcing
period: one Pi2 sample, one correction, one Pi1 crossing, ~0.85 impact, 9 state and
10 /clock messages): the Pi2 samples, corrections and impacts are a core simulation
of the study's scene (Delta d = -5e-6, control on at sample 1000), the state, Pi1 and
clock messages carry placeholder values of the right size. It is written with the
project's BagWriter (zstd chunks, as the recorder writes), from CDR bytes serialized by
rosbags.

Measured, each best of ``--repeat`` runs, in this one process:

* ``mcap_ros2``: ``read_messages`` (mcap SeekingReader + mcap_ros2 decoder), every
  message of the analysis topics decoded to a Python object and its fields read;
* ``AnyReader``: rosbags' AnyReader over the same topics, ``deserialize_cdr`` of each;
* ``mcap raw``: mcap's reader iterating the same records without decoding (a floor);
* ``bagtools load``: what ``grazing analyze`` reads: stream + decompress + vectorised
  decode of the analysis topics + scenes and stamp matching;
* ``grazing analyze``: the whole analysis without figures (load, numbers, prediction
  from the core, and the model check, which re-integrates up to 20000 periods with the
  core: numerical work, not reading).

Rates are messages of the whole bag per second (every reader skips or reads the other
topics' chunks as it sees fit). The ratio column is against the fastest of the two bare
decoding readers (mcap_ros2, AnyReader).

Run: ``python benchmarks/bench_analyze.py [--messages 1000000] [--repeat 3]``.
"""

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from grazing_control.oscillator.control import Gains  # noqa: E402
from grazing_control.dynamics.design.gains import degenerate_c1  # noqa: E402
from grazing_control.oscillator.params import OscillatorParams  # noqa: E402
from grazing_control.ros.recording import BagWriter  # noqa: E402
from grazing_control.dynamics.simulation.simulate import simulate  # noqa: E402

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
TOPICS = ["/oscillator/pi2", "/controller/velocity_correction", "/oscillator/impact"]
PER_PERIOD = {"pi2": 1, "corr": 1, "pi1": 1, "impact": 0.85, "state": 9, "clock": 10}
_NS = 1_000_000_000


def _time(ns):
    return T["builtin_interfaces/msg/Time"](sec=int(ns // _NS), nanosec=int(ns % _NS))


def _header(ns):
    return T["std_msgs/msg/Header"](stamp=_time(ns), frame_id="")


def js(ns, x, v, e=0.0):
    return bytes(TS.serialize_cdr(T["sensor_msgs/msg/JointState"](
        header=_header(ns), name=["mass"], position=np.array([x]), velocity=np.array([v]),
        effort=np.array([e])), "sensor_msgs/msg/JointState"))


def twist(ns, dv):
    V = T["geometry_msgs/msg/Vector3"]
    return bytes(TS.serialize_cdr(T["geometry_msgs/msg/TwistStamped"](
        header=_header(ns), twist=T["geometry_msgs/msg/Twist"](linear=V(x=dv, y=0.0, z=0.0),
                                                               angular=V(x=0.0, y=0.0, z=0.0))),
        "geometry_msgs/msg/TwistStamped"))


def vec(ns, a, b, c):
    return bytes(TS.serialize_cdr(T["geometry_msgs/msg/Vector3Stamped"](
        header=_header(ns), vector=T["geometry_msgs/msg/Vector3"](x=a, y=b, z=c)),
        "geometry_msgs/msg/Vector3Stamped"))


def clock(ns):
    return bytes(TS.serialize_cdr(T["rosgraph_msgs/msg/Clock"](clock=_time(ns)),
                                  "rosgraph_msgs/msg/Clock"))


def make_bag(path: Path, messages: int) -> int:
    """Write the benchmark bag; returns the number of messages written."""
    periods = int(math.ceil(1.1 * messages / sum(PER_PERIOD.values())))
    p = OscillatorParams(delta_d=-5e-6)
    res = simulate(p, periods, gains=Gains(degenerate_c1(p, -1.0), -1.0), control_after=1000)
    period = p.period
    kinds = {"/oscillator/pi2": "sensor_msgs/msg/JointState",
             "/controller/velocity_correction": "geometry_msgs/msg/TwistStamped",
             "/oscillator/pi1": "sensor_msgs/msg/JointState",
             "/oscillator/impact": "geometry_msgs/msg/Vector3Stamped",
             "/oscillator/state": "sensor_msgs/msg/JointState",
             "/clock": "rosgraph_msgs/msg/Clock"}
    imp = res.impacts
    j, count, log = 0, 0, 1_700_000_000 * _NS
    with BagWriter(path) as bag:
        for topic, kind in kinds.items():
            bag.add_topic(topic, kind)
        for k in range(periods):
            if count >= messages:
                break
            t = k * period
            ns = int(round(t * 1e9))

            def put(topic, data):
                nonlocal count, log
                if count < messages:
                    log += 1000
                    bag.write(topic, data, log)
                    count += 1

            put("/clock", clock(ns))
            put("/oscillator/pi2", js(ns, *res.pi2[k]))
            put("/controller/velocity_correction", twist(ns, res.corrections[k]))
            for s in range(1, 10):                      # state every unit of time
                ts = int(round((t + s) * 1e9))
                if s < period:
                    put("/clock", clock(ts))
                    put("/oscillator/state", js(ts, 0.1, 0.2, 0.3))
                    if s == 2:
                        put("/oscillator/pi1", js(ts + 7, 0.1, 0.2, 0.3))
            while j < len(imp) and imp[j, 0] == k:
                ti = int(round((t + imp[j, 1]) * 1e9))
                put("/oscillator/impact", vec(ti, imp[j, 3], imp[j, 4], imp[j, 2]))
                j += 1
    return count


def bench_mcap_ros2(bag):
    from grazing_control.ros.recording import read_messages

    n, acc = 0, 0.0
    for m in read_messages(bag, topics=TOPICS):
        msg = m.message
        h = msg.header.stamp.sec
        if m.topic == "/oscillator/pi2":
            acc += msg.position[0] + msg.velocity[0] + h
        elif m.topic == "/controller/velocity_correction":
            acc += msg.twist.linear.x
        else:
            acc += msg.vector.x
        n += 1
    return n


def bench_anyreader(bag):
    from rosbags.highlevel import AnyReader

    n, acc = 0, 0.0
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in TOPICS]
        for conn, _t, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            h = msg.header.stamp.sec
            if conn.topic == "/oscillator/pi2":
                acc += msg.position[0] + msg.velocity[0] + h
            elif conn.topic == "/controller/velocity_correction":
                acc += msg.twist.linear.x
            else:
                acc += msg.vector.x
            n += 1
    return n


def bench_mcap_raw(bag):
    from mcap.reader import make_reader

    from grazing_control.recordings.reader import bag_path

    n = 0
    with open(bag_path(bag), "rb") as fh:
        for _s, _c, _m in make_reader(fh).iter_messages(topics=TOPICS):
            n += 1
    return n


def bench_load(bag):
    from grazing_control.recordings.scenes import load

    d = load(bag)
    return sum(len(s.stamp_ns) for s in d.scenes)


def bench_analyze(bag):
    from grazing_control.recordings.analyze import analyze

    rep = analyze([bag], None, figures=False)
    return rep["bags"][0]["scenes"][0]["samples"]


def best(fn, bag, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(bag)
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--messages", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    bag = REPO / "benchmarks" / "out" / f"bench_analyze_{args.messages}"
    if not (bag / "metadata.yaml").is_file():
        import shutil
        shutil.rmtree(bag, ignore_errors=True)
        t0 = time.perf_counter()
        n = make_bag(bag, args.messages)
        print(f"wrote {bag} ({n} messages) in {time.perf_counter() - t0:.1f} s")
    total = __import__("yaml").safe_load((bag / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"]["message_count"]
    rows = []
    for name, fn in (("mcap_ros2 (decode)", bench_mcap_ros2), ("AnyReader (decode)", bench_anyreader),
                     ("mcap raw (no decode)", bench_mcap_raw), ("bagtools load", bench_load),
                     ("grazing analyze (no figures)", bench_analyze)):
        secs, out = best(fn, bag, args.repeat)
        rows.append((name, secs, out))
    base = min(r[1] for r in rows[:2])
    import os
    print(f"analysis benchmark: {total} messages in the bag, analysis topics {', '.join(TOPICS)}; "
          f"best of {args.repeat}; python {sys.version.split()[0]}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'reader':32s} {'seconds':>9s} {'msg/s (bag)':>13s} {'vs fastest decoding reader':>27s}  "
          "messages (readers) / Pi2 samples (bagtools)")
    print("-" * 100)
    for name, secs, out in rows:
        print(f"{name:32s} {secs:9.3f} {total / secs:13,.0f} {secs / base:26.2f}x  {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

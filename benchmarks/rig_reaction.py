"""The controller's reaction in a rig scene's bag (issues 28 and 30), per section, from the
publishers' source timestamps (publish_time): when the Pi2 sample (rig/phase) went out,
when the sensor sample that makes the section due went out (the first with stamp
>= t_k - lead - h: the controller answers ``answer_lead`` = 4 ms before the section's
last sample, h = 0.5 ms), when the controller's force pulse went out, and when the
simulator's rig/applied went out; where rig/applied says a prediction or nothing acted:
who was late. ``react`` (pulse out - due sample out) is the controller's compute and
its middleware hops; the 4 ms of answer lead are its deadline.

    .venv/bin/python benchmarks/rig_reaction.py BAGDIR

BAGDIR: a bag of ``benchmarks/bench_rig_scene.py --out DIR`` (DIR/bag), recorded with
the rig topics. Section 0 (the pre-roll) is left out of the percentiles. Results in
docs/benchmarks.md ("The controller's compute per section").
"""

from __future__ import annotations

import bisect
import glob
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

#: The acceptance rig's answer lead and sample period (s).
LEAD, H = 4e-3, 0.5e-3
TOPICS = ["/rig/phase", "/rig/force_pulse", "/rig/applied", "/rig/sensor"]
WHAT = [("trig", "sensor sample making it due went out"),
        ("react", "controller: pulse out after that sample"),
        ("pulse", "pulse went out"), ("act", "rig/applied went out")]


def sections(bagdir: str) -> list:
    """One dict per section with an answer and a rig/applied: times in ms from its Pi2
    sample going out (module docstring), ``st`` the rig/applied status."""
    path = glob.glob(bagdir + "/*.mcap")[0]
    phase, pulse, applied, sensor = [], {}, {}, []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _sch, ch, m, msg in reader.iter_decoded_messages(topics=TOPICS):
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            if ch.topic == "/rig/phase":
                phase.append((stamp, m.publish_time))
            elif ch.topic == "/rig/force_pulse":
                pulse[round(msg.wrench.torque.y, 6)] = m.publish_time
            elif ch.topic == "/rig/applied":
                applied[round(msg.wrench.torque.y, 6)] = (msg.wrench.force.z, m.publish_time)
            else:
                sensor.append((stamp, m.publish_time))
    sensor.sort()
    sens_t = [s[0] for s in sensor]
    rows = []
    for tk, pub in phase:
        key = round(tk, 6)
        if key not in pulse or key not in applied:
            continue
        i = bisect.bisect_left(sens_t, tk - LEAD - H)
        trig = sensor[i][1] if i < len(sensor) else None
        status, apub = applied[key]
        rows.append(dict(tk=tk, st=status, pulse=(pulse[key] - pub) / 1e6,
                         act=(apub - pub) / 1e6,
                         trig=(trig - pub) / 1e6 if trig else float("nan"),
                         react=(pulse[key] - trig) / 1e6 if trig else float("nan")))
    return rows


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: rig_reaction.py BAGDIR", file=sys.stderr)
        return 2
    rows = sections(argv[0])
    print("sections", len(rows), "(all times in ms from the Pi2 sample going out)")
    for name, what in WHAT:
        v = sorted(r[name] for r in rows[1:])
        print(f"  {what:42s} p50 {v[len(v) // 2]:.3f} p99 {v[int(.99 * len(v))]:.3f} "
              f"max {v[-1]:.3f}")
    for r in rows:
        if r["st"] != 0.0:
            print("  status %g at t_k=%.6f: due sample %+.3f, pulse %+.3f (reaction %.3f), "
                  "applied %+.3f" % (r["st"], r["tk"], r["trig"], r["pulse"], r["react"],
                                     r["act"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())

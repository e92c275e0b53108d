"""Who was late, section by section, in a rig scene's bag (used by bench_rig_scene.py).

Every message of a bag carries its publisher's source timestamp (MCAP ``publish_time``,
the system clock of this machine, shared by every process). Per section, measured from
its Pi2 reference (``rig/phase``) going out: when the sensor sample that makes the section
due went out (the first with a stamp at or after t_k - answer_lead - h: the controller
answers on it), when the controller's ``rig/force_pulse`` went out (its reaction: the
pulse less that sample), and when the simulated rig's ``rig/applied`` went out (it acts
at t_k + budget - w/2). A section where a prediction or nothing acted is listed with the
three, so that a miss is seen to be the stream's (the due sample late), the
controller's (a long reaction), or neither.

    .venv/bin/python benchmarks/rig_timing.py BAG_DIR [--lead SECONDS] [--h SECONDS]
"""

from __future__ import annotations

import argparse
import bisect
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

TOPICS = ["/rig/phase", "/rig/force_pulse", "/rig/applied", "/rig/sensor"]


def stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def section_timing(bag_dir, lead: float, h: float) -> list[dict]:
    """One row per section with a pulse and a rig/applied: t_k (rig s), status (the
    rig/applied code) and, in ms from the Pi2 reference going out, ``due`` (the due
    sample out), ``pulse``, ``applied``, and ``reaction`` (pulse less due)."""
    path = next(Path(bag_dir).glob("*.mcap"))
    phase, pulse, applied, sensor = [], {}, {}, []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, m, msg in reader.iter_decoded_messages(topics=TOPICS):
            if channel.topic == "/rig/phase":
                phase.append((stamp(msg), m.publish_time))
            elif channel.topic == "/rig/force_pulse":
                pulse[round(msg.wrench.torque.y, 6)] = m.publish_time
            elif channel.topic == "/rig/applied":
                applied[round(msg.wrench.torque.y, 6)] = (msg.wrench.force.z, m.publish_time)
            else:
                sensor.append((stamp(msg), m.publish_time))
    sensor.sort()
    stamps = [s for s, _ in sensor]
    rows = []
    for t_k, out in phase:
        key = round(t_k, 6)
        if key not in pulse or key not in applied:
            continue
        i = bisect.bisect_left(stamps, t_k - lead - h)
        due = (sensor[i][1] - out) / 1e6 if i < len(sensor) else float("nan")
        status, act = applied[key]
        p = (pulse[key] - out) / 1e6
        rows.append(dict(t_k=t_k, status=status, due=due, pulse=p, reaction=p - due,
                         applied=(act - out) / 1e6))
    return rows


def report(rows: list[dict], skip: int = 1) -> list[str]:
    """Percentiles of each time over the sections after the first ``skip`` (the
    pre-roll), and a line per section where a prediction or nothing acted."""
    lines = [f"timing of {len(rows)} sections (ms from the Pi2 reference going out; source "
             "timestamps of the bag):"]
    body = rows[skip:]
    for name, what in (("due", "the due sensor sample out"), ("reaction", "the controller's "
                       "reaction (pulse - due)"), ("pulse", "the force pulse out"),
                       ("applied", "rig/applied out (acted)")):
        v = sorted(r[name] for r in body)
        if v:
            lines.append(f"  {what:38s} p50 {v[len(v) // 2]:.3f} p99 "
                         f"{v[min(len(v) - 1, int(0.99 * len(v)))]:.3f} max {v[-1]:.3f}")
    for r in rows:
        if r["status"] != 0.0:
            lines.append(f"  rig/applied {r['status']:g} at t_k = {r['t_k']:.6f} s: due "
                         f"{r['due']:+.3f}, pulse {r['pulse']:+.3f} (reaction "
                         f"{r['reaction']:.3f}), applied {r['applied']:+.3f}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag")
    ap.add_argument("--lead", type=float, default=4e-3, help="answer_lead, rig s (4 ms)")
    ap.add_argument("--h", type=float, default=0.5e-3, help="sample period, s (0.5 ms)")
    args = ap.parse_args(argv)
    print("\n".join(report(section_timing(args.bag, args.lead, args.h))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

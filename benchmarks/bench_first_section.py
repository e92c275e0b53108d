"""Section 0 of the T/200 scene at x1000: how its answer's budget is spent (issue 30).

Section 0's deadline missed in 2 of about 40 scenes of 3000 periods (docs/benchmarks.md,
"Section 0"): the first message on each of the loop's paths costs more than the rest.
This runs ``--reps`` short scenes of ``bench_stream_blocks`` (``--variant``, default
block+fifo, answer_lead 2.95: the rig's lead; ``--periods``, default 60) and reads from
each bag, in wall milliseconds after section 0's Pi2 sample was published
(``publish_time`` of the first ``oscillator/pi2`` message):

- ``block``: the stream's message with the t = 0 sample published (the sample section 0
  is answered from, with the lead);
- ``answer``: section 0's correction published by the controller;
- ``miss``: whether the simulator declared section 0's deadline missed
  (``oscillator/deadline_miss`` with k = 0); its budget is ``actuation_delay`` of
  simulation time after the sample, 3.0 ms here.

With ``--baseline DIR`` (a git worktree of an older commit) each scene also runs on that
checkout (bench_stream_blocks.baseline_scene), the two alternating, rows ``base``.

Run: ``.venv/bin/python benchmarks/bench_first_section.py --reps 10 --baseline /tmp/base``
(about 4 s a scene). Results in docs/benchmarks.md, "Section 0".
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

import bench_stream_blocks as scenes  # noqa: E402
from grazing_control.recordings import reader  # noqa: E402
from grazing_control.recordings.scenes import DEFAULT_TOPICS  # noqa: E402
from grazing_control.ros import stream_block  # noqa: E402


def section_zero(bag: Path) -> dict:
    """(block, answer, miss) of section 0 from a scene's bag (module docstring)."""
    topics = [DEFAULT_TOPICS[r] for r in ("pi2", "state_block", "correction", "deadline_miss")]
    raw = reader.read_raw(bag, topics)
    pi2 = reader.serialized(raw, DEFAULT_TOPICS["pi2"])
    t0 = int(pi2["publish_time"][0])
    blocks = reader.serialized(raw, DEFAULT_TOPICS["state_block"])
    block = next(int(p) for p, d in zip(blocks["publish_time"], blocks["data"])
                 if stream_block.samples(stream_block.read(d), 0)[0][:2] == (0, 0))
    corr = reader.decode_twist_stamped(raw, DEFAULT_TOPICS["correction"])
    answer = min(int(p) for p, s in zip(corr["publish_time"], corr["stamp"]) if s == 0)
    misses = reader.decode_vector3_stamped(raw, DEFAULT_TOPICS["deadline_miss"]) \
        if raw.count(DEFAULT_TOPICS["deadline_miss"]) else None
    missed = bool(misses is not None and any(int(round(k)) == 0 for k in misses["vx"]))
    return {"block": (block - t0) / 1e6, "answer": (answer - t0) / 1e6, "miss": missed}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--periods", type=int, default=60)
    ap.add_argument("--variant", default="block+fifo", choices=scenes.VARIANTS)
    ap.add_argument("--answer-lead", type=float, default=2.95)
    ap.add_argument("--baseline", type=Path, default=None)
    args = ap.parse_args(argv)
    arms = ["this"] + (["base"] if args.baseline is not None else [])
    rows = {arm: [] for arm in arms}
    with tempfile.TemporaryDirectory(prefix="first_section_") as tmp:
        controller = scenes.design(Path(tmp))
        for rep in range(args.reps):
            for arm in (arms if rep % 2 == 0 else arms[::-1]):
                one = Path(tmp) / f"{arm}{rep}"
                one.mkdir()
                run = (scenes.scene if arm == "this" else
                       lambda *a: scenes.baseline_scene(args.baseline.resolve(), *a))
                r = run(args.variant, controller, args.periods, 1, 1000.0, one,
                        args.answer_lead)
                if "failed" in r:
                    print(f"{arm} scene {rep}: failed: {r['failed']}")
                    continue
                s = section_zero(one / "bag")
                rows[arm].append(s)
                print(f"{arm} scene {rep}: block {s['block']:.3f} ms, answer "
                      f"{s['answer']:.3f} ms, section 0 {'MISSED' if s['miss'] else 'in time'}"
                      f" (missed in all {r['missed']})", flush=True)
    print(f"\n{args.variant}, answer_lead {args.answer_lead:g}, {args.periods} periods, ms "
          "after section 0's sample went out (its deadline: 3.0)")
    print(f"{'arm':5s} {'scenes':>6s} {'block p50':>9s} {'max':>7s} {'answer p50':>10s} "
          f"{'max':>7s} {'missed':>6s}")
    for arm, rs in rows.items():
        if not rs:
            continue
        b, a = [r["block"] for r in rs], [r["answer"] for r in rs]
        print(f"{arm:5s} {len(rs):6d} {statistics.median(b):9.3f} {max(b):7.3f} "
              f"{statistics.median(a):10.3f} {max(a):7.3f} "
              f"{sum(r['miss'] for r in rs):6d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark of the recorder's MCAP writer against the ``mcap`` library's, side by side.

Both write the same messages, with the same options (the bag writer's: zstd, 256 KiB
chunks, every index, statistics, summary offsets) into memory, alternating, and the
bytes are compared. The messages are a lockstep scene's mix per period: 12 JointState
samples of the state stream (about 100 bytes each), one section sample each on Π1 and
Π2, one impact, one correction, one clock, round robin on seven channels.

Run: ``.venv/bin/python benchmarks/bench_mcap_writer.py [--messages 200000] [--reps 5]``
"""

import argparse
import io
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcap.writer import CompressionType, IndexType, Writer  # noqa: E402

from grazing_control.ros.recording.mcap_writer import McapWriter  # noqa: E402
from grazing_control.ros.recording.schemas import DEFAULT_CHUNK_SIZE  # noqa: E402

# (channel, payload bytes) of one period: 12 state samples, pi1, pi2, impact,
# correction, clock
PERIOD = [(1, 100)] * 12 + [(2, 100), (3, 100), (4, 52), (5, 76), (6, 12)]


def messages(n, seed=0):
    rng = random.Random(seed)
    payloads = {size: [rng.randbytes(size) for _ in range(64)] for _, size in PERIOD}
    out, t = [], 1_700_000_000 * 10**9
    while len(out) < n:
        for channel, size in PERIOD:
            t += rng.randrange(20_000, 60_000)
            out.append((channel, t, rng.choice(payloads[size]), t - 5_000, len(out) + 1))
    return out[:n]


def write(writer, batch):
    writer.start(profile="ros2", library="bench")
    for channel in range(1, 7):
        writer.register_schema(f"pkg/msg/T{channel}", "ros2msg", b"float64 x")
        writer.register_channel(f"/topic{channel}", "cdr", channel, {"k": "v"})
    start = time.perf_counter()
    for channel, log, data, publish, sequence in batch:
        writer.add_message(channel, log, data, publish, sequence)
    writer.finish()
    return time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=200_000)
    parser.add_argument("--reps", type=int, default=5)
    args = parser.parse_args(argv)
    batch = messages(args.messages)
    times = {"mcap.writer.Writer": [], "McapWriter": []}
    for _ in range(args.reps):
        files = {}
        for name in times:
            out = io.BytesIO()
            writer = (McapWriter(out, chunk_size=DEFAULT_CHUNK_SIZE, compression="zstd")
                      if name == "McapWriter" else
                      Writer(out, chunk_size=DEFAULT_CHUNK_SIZE,
                             compression=CompressionType.ZSTD, index_types=IndexType.ALL,
                             use_statistics=True, use_summary_offsets=True))
            times[name].append(write(writer, batch))
            files[name] = out.getvalue()
        if files["McapWriter"] != files["mcap.writer.Writer"]:
            print("error: the two files differ")
            return 1
    print(f"{args.messages} messages, {args.reps} reps, the files identical "
          f"({len(files['McapWriter'])} bytes)")
    best = {name: min(t) / args.messages * 1e6 for name, t in times.items()}
    for name, us in best.items():
        print(f"  {name:20s} {us:6.2f} µs/message (best of {args.reps})")
    print(f"  ratio mcap.writer.Writer / McapWriter: "
          f"{best['mcap.writer.Writer'] / best['McapWriter']:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())

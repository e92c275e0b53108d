"""The tests' 50-digit references on mpmath's two backends: pure Python integers
(``MPMATH_NOGMPY=1``) against GMP through gmpy2 (requirements.txt), side by side.

mpmath picks its backend once, when it is first imported, so the two cannot share a
process: each round runs one child per backend, in turn first, on the same cases, and
each child reports its own CPU (``time.process_time``) and a digest of every number it
computed (their ``repr`` at the references' precision). Printed per reference: the CPU
of each backend summed over the rounds, the ratio Python / GMP, and whether the digests
are the same (mpmath's results do not depend on its backend: they should be).

    .venv/bin/python benchmarks/bench_mpmath_backend.py [--rounds 3]

The references: tests/reference.py's exact chattering continuation (tests/test_impact.py's
first 40 seeded sequences) and tests/reference_hertz.py's contact (tests/test_hertz.py's
four seeded contacts) and tests/reference_ndof.py's two-mass impact search.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import hashlib, json, math, random, sys, time
sys.path.insert(0, "tests")
import mpmath.libmp
which = sys.argv[1]
out = []
t0 = time.process_time()
if which == "chattering":
    import test_impact as ti
    for i, case in enumerate(ti._chatter_cases(20, 600)):
        if i == 40:
            break
        out.append(ti._chatter_exact(*case))
elif which == "hertz":
    from grazing_control.oscillator.hertz import HuntCrossley
    from grazing_control.oscillator.params import OscillatorParams
    from reference_hertz import reference_contact
    for seed in range(4):      # tests/test_hertz.py's test_one_contact_matches_...
        rng = random.Random(seed)
        p = OscillatorParams(delta_d=-10 ** rng.uniform(-3, -0.5))
        v0 = 10 ** rng.uniform(-2, 0)
        law = HuntCrossley(10 ** rng.uniform(1, 3), rng.choice([0.01, 0.3, 1.2]) / v0)
        out.append(reference_contact(p, law, rng.uniform(0, 2 * math.pi), v0))
cpu = time.process_time() - t0
print(json.dumps({"backend": mpmath.libmp.BACKEND, "cpu": cpu,
                  "digest": hashlib.sha256(repr(out).encode()).hexdigest()}))
"""


def child(which: str, gmp: bool) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("MPMATH_NOGMPY", None)
    if not gmp:
        env["MPMATH_NOGMPY"] = "1"
    out = subprocess.run([sys.executable, "-c", CHILD, which], cwd=ROOT, env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--references", nargs="*", default=["chattering", "hertz"])
    args = ap.parse_args(argv)
    for which in args.references:
        cpu = {"python": 0.0, "gmpy": 0.0}
        digests = set()
        for r in range(args.rounds):
            for gmp in ((False, True) if r % 2 == 0 else (True, False)):
                res = child(which, gmp)
                cpu[res["backend"]] += res["cpu"]
                digests.add(res["digest"])
        print(f"{which}: {args.rounds} rounds, CPU python {cpu['python']:.2f} s, gmpy "
              f"{cpu['gmpy']:.2f} s, ratio {cpu['python'] / cpu['gmpy']:.2f}; the same "
              f"digits on both: {len(digests) == 1}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

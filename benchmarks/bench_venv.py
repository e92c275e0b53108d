"""The venv of a fresh machine: the requirements installed by pip against by uv (issue 30).

``make venv`` creates the venv and runs .ci/install_requirements.py in it. That script
installs with uv, or with pip when ``GRAZING_INSTALLER=pip`` is set (pip was the only way
before). This benchmark runs both, alternating, ``--reps`` times each. Each install gets
a venv of its own and an empty download cache (PIP_CACHE_DIR, UV_CACHE_DIR in a
temporary directory), so every package comes from the index or the local mirrors as on
a fresh machine. Each line is the wall time of venv creation plus the install; at the
end come the medians and their ratio. Every venv is then checked to be exactly
constraints.txt (``pip freeze --all``, uv itself left out), so a fast install of
something else cannot count.

Run: ``.venv/bin/python benchmarks/bench_venv.py --reps 2``. Needs the package index
(network). Results in docs/benchmarks.md, "The venv on a fresh machine".
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = os.environ.get("PYTHON", "python3.11")


def frozen(venv: Path) -> list:
    out = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "freeze", "--all"],
                         check=True, capture_output=True, text=True).stdout
    return sorted(line for line in out.splitlines() if not line.startswith("uv=="))


def install(installer: str, tmp: Path) -> float:
    work = tmp / installer
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    for name in ("requirements.txt", "constraints.txt"):
        shutil.copy2(ROOT / name, work / name)
    env = {**os.environ, "GRAZING_INSTALLER": installer,
           "PIP_CACHE_DIR": str(work / "pip-cache"), "UV_CACHE_DIR": str(work / "uv-cache")}
    start = time.perf_counter()
    subprocess.run([PYTHON, "-m", "venv", str(work / "venv")], check=True, cwd=work)
    subprocess.run([str(work / "venv" / "bin" / "python"),
                    str(ROOT / ".ci" / "install_requirements.py")], check=True, cwd=work,
                   env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    pinned = sorted(line for line in (ROOT / "constraints.txt").read_text().splitlines()
                    if line and not line.startswith("#"))
    if frozen(work / "venv") != pinned:
        raise SystemExit(f"{installer}: the venv is not constraints.txt")
    shutil.rmtree(work)
    return wall


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=2)
    args = ap.parse_args(argv)
    times = {"pip": [], "uv": []}
    with tempfile.TemporaryDirectory(prefix="bench-venv-") as tmp:
        for rep in range(args.reps):
            for installer in ("pip", "uv") if rep % 2 == 0 else ("uv", "pip"):
                wall = install(installer, Path(tmp))
                times[installer].append(wall)
                print(f"rep {rep} {installer:3s} {wall:6.1f} s (load {os.getloadavg()[0]:.1f})",
                      flush=True)
    pip, uv = (statistics.median(times[k]) for k in ("pip", "uv"))
    print(f"median: pip {pip:.1f} s, uv {uv:.1f} s, pip / uv = {pip / uv:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Where a test suite's CPU goes: a pytest plugin that writes each test's CPU, and its summary.

Record (changes nothing in the suite; one file per xdist worker)::

    SUITE_CPU_DIR=/tmp/suite-cpu PYTHONPATH=benchmarks PYTEST_ADDOPTS="-p suite_cpu" make test

Each line: the test's start (Unix s), its wall s, the worker's own CPU s
(``getrusage(RUSAGE_SELF)``: the test's in-process work), the CPU s of the processes the
worker reaped meanwhile (``RUSAGE_CHILDREN``: nodes, commands; the worker is the nodes'
subreaper), the worker's main-thread scheduling after the test (policy, nice), and the
node id.

Summarise::

    .venv/bin/python benchmarks/suite_cpu.py /tmp/suite-cpu [--top 30] [--bin 120]

prints the totals, the modules by in-process CPU, and each worker's CPU per time bin: a
worker that gets far less CPU than the others in the same bins is starved (docs/
benchmarks.md, "A worker left under SCHED_IDLE": a test had left one under SCHED_IDLE).
"""

from __future__ import annotations

import argparse
import collections
import glob
import os
import resource
import time

_started: dict = {}
_out = []
_on = [True]


def pytest_configure(config):
    """Off in xdist's controller (its hooks see the workers' tests again, without their
    CPU); on in each worker and in a run without workers."""
    controller = (getattr(config, "workerinput", None) is None
                  and bool(config.getoption("numprocesses", None, skip=True)))
    _on[0] = not controller


def _cpu() -> tuple:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


def _file():
    if not _out:
        folder = os.environ.get("SUITE_CPU_DIR", "suite-cpu")
        os.makedirs(folder, exist_ok=True)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        _out.append(open(os.path.join(folder, f"{worker}.tsv"), "a", buffering=1))
    return _out[0]


def pytest_runtest_logstart(nodeid, location):
    if _on[0]:
        _started[nodeid] = (time.time(),) + _cpu()


def pytest_runtest_logfinish(nodeid, location):
    if nodeid not in _started:
        return
    t0, own0, kids0 = _started.pop(nodeid)
    own1, kids1 = _cpu()
    sched = f"{os.sched_getscheduler(0)},{os.getpriority(os.PRIO_PROCESS, 0)}"
    _file().write(f"{t0:.3f}\t{time.time() - t0:.3f}\t{own1 - own0:.3f}\t"
                  f"{kids1 - kids0:.3f}\t{sched}\t{nodeid}\n")


def read(folder: str) -> dict:
    """{worker: [(start, wall, own, children, sched, nodeid)]} from a recorded folder."""
    runs = {}
    for path in sorted(glob.glob(os.path.join(folder, "*.tsv"))):
        rows = []
        for line in open(path):
            start, wall, own, kids, sched, nodeid = line.rstrip("\n").split("\t", 5)
            rows.append((float(start), float(wall), float(own), float(kids), sched, nodeid))
        runs[os.path.basename(path)[:-4]] = rows
    return runs


def by_module(runs: dict) -> tuple:
    """({module: in-process CPU s}, {module: reaped children's CPU s})."""
    own, kids = collections.Counter(), collections.Counter()
    for rows in runs.values():
        for r in rows:
            module = r[5].split("::")[0]
            own[module] += r[2]
            kids[module] += r[3]
    return own, kids


def compare(runs: dict, baseline: dict, changed=()) -> None:
    """Print the host factor (the CPU of the modules that start no process, this run over
    the baseline; those in ``changed``, whose CPU the change between the two runs moved,
    left out) and the children's and the total CPU with it divided out. ValueError when
    no module is left for the factor."""
    own, kids = by_module(runs)
    own0, kids0 = by_module(baseline)
    pure = [m for m in own0 if m in own and kids0[m] == 0.0 and kids[m] == 0.0
            and m not in changed]
    if not pure or sum(own0[m] for m in pure) == 0.0:
        raise ValueError("--changed leaves no module that starts no process in both runs "
                         "for the host factor")
    factor = sum(own[m] for m in pure) / sum(own0[m] for m in pure)
    left_out = f", {len(set(changed))} changed ones left out" if changed else ""
    print(f"\nagainst the baseline: the {len(pure)} modules that start no process"
          f"{left_out} took {sum(own0[m] for m in pure):.0f} -> "
          f"{sum(own[m] for m in pure):.0f} CPU-s (host factor {factor:.3f})")
    for name, now, before in (("reaped children", sum(kids.values()), sum(kids0.values())),
                              ("in-process + children", sum(own.values()) + sum(kids.values()),
                               sum(own0.values()) + sum(kids0.values()))):
        print(f"  {name}: {before:.0f} -> {now:.0f} CPU-s; with the host factor divided out "
              f"{now / factor:.0f} ({now / factor / before - 1:+.1%})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--top", type=int, default=30, help="modules to list (default 30)")
    ap.add_argument("--bin", type=float, default=120.0, help="bin width, s (default 120)")
    ap.add_argument("--against", metavar="FOLDER",
                    help="a baseline run: the host factor and the CPU with it divided out")
    ap.add_argument("--changed", nargs="*", default=[], metavar="MODULE",
                    help="test modules (tests/test_x.py) whose CPU the change between the "
                         "runs moved: left out of the host factor")
    args = ap.parse_args(argv)
    runs = read(args.folder)
    if not runs:
        ap.error(f"no *.tsv in {args.folder}")
    rows = [r for rs in runs.values() for r in rs]
    t0 = min(r[0] for r in rows)
    print(f"{len(rows)} tests: in-process CPU {sum(r[2] for r in rows):.1f} s, reaped "
          f"children {sum(r[3] for r in rows):.1f} s, wall summed {sum(r[1] for r in rows):.1f} s")
    own, kids, wall = collections.Counter(), collections.Counter(), collections.Counter()
    for r in rows:
        module = r[5].split("::")[0]
        own[module] += r[2]
        kids[module] += r[3]
        wall[module] += r[1]
    print("\n| module | in-process CPU s | children CPU s | wall s |\n|---|---|---|---|")
    for module, cpu in own.most_common(args.top):
        print(f"| {module} | {cpu:.1f} | {kids[module]:.1f} | {wall[module]:.1f} |")
    print(f"\nCPU s (own + children) per {args.bin:g} s of the suite, by worker:")
    for worker, rs in runs.items():
        bins = collections.Counter()
        for start, _, cpu, kid, _, _ in rs:
            bins[int((start - t0) // args.bin)] += cpu + kid
        changed = sorted({r[4] for r in rs})
        print(f"  {worker}: " + " ".join(f"{k * args.bin:g}:{bins[k]:.0f}"
                                         for k in range(max(bins) + 1))
              + f"   scheduling after tests: {changed}")
    if args.against:
        baseline = read(args.against)
        if not baseline:
            ap.error(f"no *.tsv in {args.against}")
        try:
            compare(runs, baseline, args.changed)
        except ValueError as exc:
            ap.error(str(exc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

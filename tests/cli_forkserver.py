"""Run many ``python -m grazing_control.cli ARGS`` processes, each a fork of one that has
already imported the command line's libraries (tests/test_cli.py's ``runs``).

``python cli_forkserver.py WORKERS`` reads one JSON job per line on stdin until it is
closed, ``{"argv": [...], "cwd": DIR, "stdout": FILE, "stderr": FILE}``, answers one line
per finished job on stdout, ``{"job": INDEX, "returncode": N}`` (-N: killed by signal N;
-14, SIGALRM: ran past JOB_TIMEOUT), and exits once every job has ended. At most WORKERS
jobs run at once.

Each job is a fresh process as far as the command can tell: forked before it runs, it
changes to its directory, writes its fds 1 and 2 into its own files and runs the module
as ``python -m`` does (runpy, ``__main__``); its exit status is ``sys.exit``'s or 1 after
an uncaught exception (its traceback on stderr), as the interpreter's. What the fork
shares is the modules imported here (numpy, scipy, numba, the package): each of the ~30
processes paid ~1.5 s of CPU importing them (issue 30), two at a time on two cores.
"""

import json
import os
import runpy
import signal
import sys
import traceback

import grazing_control.cli  # noqa: F401  (the libraries every command imports)
import grazing_control.dynamics.orbits.continuation  # noqa: F401
import grazing_control.dynamics.simulation.simulate  # noqa: F401
import scipy.optimize  # noqa: F401

from grazing_control.oscillator import kernel

if kernel.available():
    import grazing_control.oscillator.kernel.compiled  # noqa: F401  (numba, ~1.3 s)

#: Wall seconds a job may run (subprocess.run's timeout in test_cli._run).
JOB_TIMEOUT = 120


def _child(job) -> int:
    signal.alarm(JOB_TIMEOUT)               # a hung command ends with -SIGALRM, named
    os.chdir(job["cwd"])
    for fd, path in ((1, job["stdout"]), (2, job["stderr"])):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(f, fd)
        os.close(f)
    sys.argv = ["grazing_control.cli", *job["argv"]]
    try:
        runpy.run_module("grazing_control.cli", run_name="__main__", alter_sys=True)
        code = 0
    except SystemExit as exc:
        if exc.code is None:
            code = 0
        elif isinstance(exc.code, int):
            code = exc.code
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:                  # noqa: BLE001  (the interpreter's behaviour)
        traceback.print_exc()
        code = 1
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except Exception:                      # noqa: BLE001
        code = code or 120                 # as the interpreter: a failed flush at exit
    return code


def main() -> int:
    workers = int(sys.argv[1])
    running = {}                           # pid -> job index
    jobs = [json.loads(line) for line in sys.stdin if line.strip()]
    answer = os.fdopen(os.dup(1), "w")

    def reap():
        pid, status = os.wait()
        answer.write(json.dumps({"job": running.pop(pid),
                                 "returncode": os.waitstatus_to_exitcode(status)}) + "\n")
        answer.flush()

    for index, job in enumerate(jobs):
        while len(running) >= workers:
            reap()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                code = _child(job)
            finally:
                os._exit(code)
        running[pid] = index
    while running:
        reap()
    return 0


if __name__ == "__main__":
    sys.exit(main())

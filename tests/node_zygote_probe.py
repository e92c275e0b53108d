"""A stand-in node for tests/test_node_zygote.py: prints, as one JSON line, what a node
process can see of how it was started, then waits for a signal (SIGTERM: exit 0)."""

import ctypes
import inspect
import json
import os
import signal
import sys
import time

import numpy as np


def _blocked_signals() -> int:
    """This thread's blocked signals, the mask of /proc/self/status (SigBlk)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("SigBlk:"):
                return int(line.split()[1], 16)
    return -1


def main():
    pdeathsig = ctypes.c_int(0)
    ctypes.CDLL(None).prctl(2, ctypes.byref(pdeathsig), 0, 0, 0)   # PR_GET_PDEATHSIG
    with open("/proc/self/cmdline", "rb") as f:
        cmdline = [a.decode() for a in f.read().split(b"\0") if a]
    print(json.dumps({
        "pid": os.getpid(), "ppid": os.getppid(), "pgid": os.getpgid(0),
        "name": __name__, "argv": sys.argv[1:], "path0": sys.path[0], "cwd": os.getcwd(),
        "cmdline": cmdline, "domain": os.environ.get("ROS_DOMAIN_ID"),
        "launcher_pid": os.environ.get("GRAZING_LAUNCHER_PID"),
        "pdeathsig": pdeathsig.value,
        "sigint_default": signal.getsignal(signal.SIGINT) is signal.default_int_handler,
        "stdin": os.readlink("/proc/self/fd/0"),
        "threads": len(os.listdir("/proc/self/task")),
        "blocked": _blocked_signals(),
        "rclpy_before": "rclpy" in sys.modules,
        "modules": len(sys.modules),
        "unmapped": sorted(n for n, m in list(sys.modules.items())   # not in inspect's map
                           if getattr(m, "__file__", None)
                           and inspect._filesbymodname.get(n) != m.__file__),
        "draw": float(np.random.random())}), flush=True)
    print("to stderr", file=sys.stderr, flush=True)
    signal.signal(signal.SIGTERM, lambda s, f: sys.exit(0))
    while True:
        time.sleep(0.05)


if __name__ == "__main__":
    main()

"""Where the package's console scripts are: found as `ros2 run` finds executables.

In the venv (`make test`) they are next to the interpreter; in a colcon install they are
in ``<prefix>/lib/grazing_control/`` (setup.cfg's ``install_scripts``), which `ros2 run`
finds through the ament index (AMENT_PREFIX_PATH), and on PATH after sourcing. The tests
look in that order, so `colcon test` runs them too (issue 19 §4: 9 tests looked next to
the interpreter only)."""

import os
import shutil
import sys
from pathlib import Path

PACKAGE = "grazing_control"


def script(name: str) -> Path:
    """The console script ``name`` (grazing, sim_node, controller_node, recorder_node...)."""
    here = Path(sys.executable).parent / name
    if here.exists():
        return here
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidate = Path(prefix) / "lib" / PACKAGE / name
        if candidate.exists():
            return candidate
    found = shutil.which(name)
    if found:
        return Path(found)
    raise FileNotFoundError(f"console script {name!r}: not next to {sys.executable}, not in "
                            f"<AMENT_PREFIX_PATH>/lib/{PACKAGE}/, not on PATH")



def wait_until_mapped(proc, library: str = "_multiarray_umath", timeout: float = 60.0) -> bool:
    """Wait until the process ``proc`` has mapped a shared library whose path contains
    ``library`` (numpy's core by default), or has ended; True if mapped.

    A console script's quiet SIGINT handler is installed before it imports its heavy
    modules (grazing_control.cli.console, grazing_control.ros.entry), and nothing imports
    numpy before them, so numpy's core in /proc/PID/maps says the handler is in place
    and the heavy import under way. Sleeping "Python's start time" instead (measured in
    another process) missed the handler under load: a KeyboardInterrupt traceback from
    ``import signal`` (the baseline's one failure, issue 27 §2).
    """
    import time

    end = time.monotonic() + timeout
    while proc.poll() is None and time.monotonic() < end:
        try:
            with open(f"/proc/{proc.pid}/maps") as fh:
                if library in fh.read():
                    return True
        except OSError:
            return False
        time.sleep(0.002)
    return False

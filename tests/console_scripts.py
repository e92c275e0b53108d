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


def startup_seconds(module: str, runs: int = 3) -> float:
    """Longest of ``runs`` wall times from exec to ``module`` imported, on this machine
    now: Python's own start comes before any handler of the console script can exist, so
    a test that signals "right after the start" waits this long first."""
    import subprocess
    import time

    times = []
    for _ in range(runs):
        t0 = time.monotonic()
        subprocess.run([sys.executable, "-c", f"import {module}"], check=True)
        times.append(time.monotonic() - t0)
    return max(times)

"""Entry point of the ``grazing`` console script: quiet on a Ctrl-C at any moment.

:mod:`grazing_control.cli` imports numpy and scipy, which takes a few tenths of a second;
a Ctrl-C in that time would end Python with a KeyboardInterrupt traceback. Until the
command line is loaded, a SIGINT here ends the process with status 130 and one line,
as the CLI does once it runs.
"""

from __future__ import annotations

import signal
import sys

__all__ = ["main"]


def _interrupted(signum, frame):
    sys.stderr.write("grazing: interrupted\n")
    raise SystemExit(130)


def main(argv=None) -> int:
    """Load :mod:`grazing_control.cli` with a quiet SIGINT, then run its ``main``; a
    KeyboardInterrupt that escapes the command (one raised in a lazy import, say) ends
    with the same line and status 130."""
    previous = signal.signal(signal.SIGINT, _interrupted)
    from .commands import main as cli_main

    signal.signal(signal.SIGINT, previous)
    try:
        return cli_main(argv)
    except KeyboardInterrupt:
        sys.stderr.write("grazing: interrupted\n")
        return 130

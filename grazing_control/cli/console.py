"""Entry point of the ``grazing`` console script: quiet on a Ctrl-C at any moment.

:mod:`grazing_control.cli` imports numpy and scipy, which takes a few tenths of a second;
a Ctrl-C in that time would end Python with a KeyboardInterrupt traceback. Until the
command line is loaded, a SIGINT here ends the process with status 130 and one line,
as the CLI does once it runs.

While loading, the handler ends the process at once (``os._exit``) instead of raising:
an exception raised inside an extension module's import is not ours to propagate (numpy
turns one raised while it imports its C core into "Original error was: PyCapsule_Import
could not import module 'datetime'", status 1: 6 of 12 Ctrl-C 0.05 s after the start
did that). Nothing has been written yet, so there is nothing to clean up.
"""

from __future__ import annotations

import os
import signal
import sys

__all__ = ["main"]


def _interrupted(signum, frame):
    sys.stderr.write("grazing: interrupted\n")
    sys.stderr.flush()
    os._exit(130)


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

"""Which modules a piece of code imports, run in a fresh interpreter: the checks that a
node, a command or a computation loads no library it does not use (a solver's import is
a quarter second of a node's start, more on a slow machine)."""

from __future__ import annotations

import ast
import subprocess
import sys


def loaded(code: str, modules, env=None, timeout: float = 120.0) -> list[str]:
    """The ``modules`` (names) in ``sys.modules`` after ``code`` ran in a new Python
    process (its own environment ``env``, default this one's), sorted; the process must
    succeed."""
    probe = (f"{code}\nimport sys as _sys\n"
             f"print(sorted(m for m in {tuple(modules)!r} if m in _sys.modules))")
    run = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                         text=True, timeout=timeout)
    assert run.returncode == 0, run.stderr
    return ast.literal_eval(run.stdout.strip().splitlines()[-1])

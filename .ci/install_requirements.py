"""Install requirements.txt under constraints.txt into the venv this interpreter runs.

``make venv`` runs it with the new venv's python. It installs with uv where uv can be
had, else with pip; both end with the same packages at the same versions (constraints.txt
is a full freeze).

Why uv: pip downloads one file at a time, and a fresh machine fetches 139 of the
requirements' files from the package index. uv downloads them in parallel. With empty
caches, venv creation included, pip took 19-42 s and uv 14-20 s (medians 35.4 s and
17.3 s, benchmarks/bench_venv.py; docs/benchmarks.md, "The venv on a fresh machine").

uv reads no pip configuration. The package sources that pip is configured with (the
``pip config list`` of its files and PIP_* variables: find-links, index-url,
extra-index-url, cert) are passed on to it. ``--index-strategy unsafe-best-match`` is
pip's own rule: every index is searched for the pinned version. uv's default takes a
package from the first index that has it at any version; here that is a local mirror
with another numba, so resolving failed.

If uv cannot be installed or fails, the failure is printed and pip does the install as
before. Nothing is half-applied: the Makefile writes its stamp only after this script
succeeds, and it rebuilds the venv from scratch otherwise.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

#: The uv release that does the install (pinned like everything else).
UV = "uv==0.13.9"
REQUIREMENTS = ["-r", "requirements.txt", "-c", "constraints.txt"]
#: pip's option name -> uv's option that takes the same sources (several allowed each).
SOURCES = {"find-links": "--find-links", "index-url": "--index-url",
           "extra-index-url": "--extra-index-url"}


def pip_sources(listing: str) -> tuple[list, str | None]:
    """uv's arguments for the package sources in ``pip config list`` output, and the
    certificate bundle pip is told to trust (None if none). An environment variable's
    value (``:env:.``) comes before a file's, as it does for pip."""
    rows = []
    for line in listing.splitlines():
        key, sep, value = line.partition("=")
        if not sep:
            continue
        scope, _, name = key.rpartition(".")
        rows.append((scope != ":env:", name, value.strip().strip("'\"")))
    args, seen, cert = [], set(), None
    for _, name, value in sorted(rows, key=lambda row: row[0]):
        if name == "cert" and cert is None:
            cert = value
        option = SOURCES.get(name)
        if option is None or (option == "--index-url" and option in seen):
            continue
        for source in value.split():
            if (option, source) not in seen:
                seen.update({(option, source), option})
                args += [option, source]
    return args, cert


def run(cmd: list, env=None) -> None:
    subprocess.run(cmd, check=True, env=env)


def with_uv() -> None:
    python = sys.executable
    run([python, "-m", "pip", "install", "--quiet", "--no-compile", UV])
    listing = subprocess.run([python, "-m", "pip", "config", "list"], check=True,
                             capture_output=True, text=True).stdout
    sources, cert = pip_sources(listing)
    env = dict(os.environ)
    if cert and "SSL_CERT_FILE" not in env:
        env["SSL_CERT_FILE"] = cert
    uv = Path(python).parent / "uv"
    # pip itself too, at constraints.txt's version (make constraints runs it)
    run([str(uv), "pip", "install", "--python", python, "--index-strategy",
         "unsafe-best-match", *sources, "pip", *REQUIREMENTS], env=env)


def with_pip() -> None:
    python = sys.executable
    run([python, "-m", "pip", "install", "--upgrade", "pip", "-c", "constraints.txt"])
    run([python, "-m", "pip", "install", "--no-compile", *REQUIREMENTS])


def main() -> int:
    if os.environ.get("GRAZING_INSTALLER", "uv") == "uv":
        try:
            with_uv()
            return 0
        except (subprocess.CalledProcessError, OSError) as exc:
            print(f"install_requirements: uv did not install the requirements ({exc}); "
                  "installing with pip", file=sys.stderr)
    with_pip()
    return 0


if __name__ == "__main__":
    sys.exit(main())

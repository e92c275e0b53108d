"""make venv's installer (.ci/install_requirements.py): pip's package sources handed to uv.

uv reads no pip configuration. The sources pip would use must therefore reach uv
unchanged: every find-links, index-url and extra-index-url, each once, and an
environment variable's value before a file's. Otherwise uv's venv could differ from
pip's, or fail where pip succeeds.
"""

import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / ".ci" / "install_requirements.py"
spec = importlib.util.spec_from_file_location("install_requirements", SCRIPT)
install_requirements = importlib.util.module_from_spec(spec)
spec.loader.exec_module(install_requirements)
pip_sources = install_requirements.pip_sources


def test_this_machines_listing_gives_every_source_once():
    """`pip config list` as this machine prints it (files and PIP_* variables)."""
    listing = ("\n".join([
        ":env:.cert='/etc/ssl/certs/ca-certificates.crt'",
        ":env:.default-timeout='180'",
        ":env:.find-links='/opt/wheels'",
        "global.cert='/etc/ssl/certs/ca-certificates.crt'",
        "global.constraint='/etc/xdg/pip/constraints.txt'",
        "global.extra-index-url='file:///opt/pypi/simple file:///opt/pypi-more/simple'",
        "global.find-links='/opt/wheels'",
    ]))
    args, cert = pip_sources(listing)
    assert args == ["--find-links", "/opt/wheels",
                    "--extra-index-url", "file:///opt/pypi/simple",
                    "--extra-index-url", "file:///opt/pypi-more/simple"]
    assert cert == "/etc/ssl/certs/ca-certificates.crt"


def test_an_environment_variable_comes_before_a_file_and_one_index_url_is_kept():
    listing = "\n".join(["global.index-url='https://file.example/simple'",
                         "user.cert='/file.pem'",
                         ":env:.index-url='https://env.example/simple'",
                         ":env:.cert='/env.pem'"])
    args, cert = pip_sources(listing)
    assert args == ["--index-url", "https://env.example/simple"]
    assert cert == "/env.pem"


def test_nothing_configured_gives_nothing_and_stray_lines_are_skipped():
    assert pip_sources("") == ([], None)
    assert pip_sources("WARNING: something\nglobal.timeout='60'\n") == ([], None)

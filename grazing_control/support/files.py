"""Writing a ROS 2 parameter file atomically (one implementation for every layer).

The controller's gain files (``dynamics.design.write_controller_yaml``,
``dynamics.ndof_design.write_gain_yaml``) and the model files of ``grazing identify``
(``cli.parameter_file.write_parameter_file``) are written to a temporary file in the
target's folder and renamed onto it: a failure (a full disk, a read-only folder, a
signal) leaves the old file or none, never a half-written one.
"""

from __future__ import annotations

import os
import tempfile

__all__ = ["write_yaml_atomic"]


def write_yaml_atomic(path, doc: dict, comments=()) -> None:
    """Write ``doc`` as YAML to ``path`` with ``comments`` as ``#`` lines on top,
    atomically (temporary file, then rename), with the usual 0666 & ~umask mode.

    Raises ValueError for an empty path, OSError as the file system does.
    """
    import yaml

    path = os.fspath(path)
    if not path.strip():
        raise ValueError(f"path={path!r} is invalid: expected a non-empty file path")
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".yaml.tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            for line in comments:
                fh.write(f"# {line}\n")
            yaml.safe_dump(doc, fh, sort_keys=False)
        mask = os.umask(0)  # mkstemp creates 0600: give the usual 0666 & ~umask
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise

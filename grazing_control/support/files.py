"""Parameter files: reading one within fixed limits, writing one atomically (one
implementation of each for every layer).

:func:`read_yaml_file` is the one reader of the parameter, model and gain files that the
command line and the nodes take (``--params``, ``--model``, ``--sim-params``,
``--controller-params``, ``--params-file``, ``model_file``): a hostile file costs at most
the limits below, and each refusal is one :class:`YamlFileError` line naming the file and
the limit (the callers prefix the option and exit with status 2).

- a regular file only (a FIFO, device or folder is refused before it is read: opening a
  FIFO for reading blocks until a writer appears), of at most MAX_FILE_BYTES;
- UTF-8, strictly: a bad byte is named with its offset;
- YAML through a safe loader (libyaml's parser where present, PyYAML's composer and
  SafeConstructor) whose composer counts the nodes of the document with
  every alias expanded (a "billion laughs" of 400 bytes expands to 10^9) and refuses
  more than MAX_NODES, nests at most MAX_DEPTH deep (aliases included; PyYAML's own
  recursion would end in "maximum recursion depth exceeded"), and refuses an alias to a
  node that contains it (a cycle: ``&a [*a]``);
- numbers as rcl's parameter-file parser reads them: ``1e-4``, ``5E3`` and ``+.5`` are
  floats (YAML 1.2's core schema; PyYAML's YAML 1.1 resolver gave the strings), so a
  file means the same to ``grazing`` and to a node's ``--params-file``
  (:data:`YAML12_FLOAT`; tests/test_parameter_files_hostile.py compares both readings).

The controller's gain files (``dynamics.design.gains.write_controller_yaml``,
``dynamics.design.family.write_gain_yaml``) and the model files of ``grazing identify``
(``cli.parameter_file.write_parameter_file``) are written to a temporary file in the
target's folder and renamed onto it: a failure (a full disk, a read-only folder, a
signal) leaves the old file or none, never a half-written one.
"""

from __future__ import annotations

import os
import re
import stat
import tempfile

__all__ = ["write_yaml_atomic", "read_yaml_file", "parse_yaml_bytes", "ros_parameters",
           "YamlFileError", "MAX_FILE_BYTES",
           "MAX_NODES", "MAX_DEPTH"]

#: The largest parameter file read (a parameter file is a few kB; an n-DOF model of 100
#: masses, three 100 x 100 matrices, is about 250 kB).
MAX_FILE_BYTES = 1 << 20
#: The most YAML nodes (scalars, sequences, mappings) a file's document may have once
#: every alias is expanded (the n-DOF model of 100 masses has 30,000; composing 50,000
#: nodes takes about 0.6 s on a loaded 2-core machine).
MAX_NODES = 50_000
#: The deepest nesting of sequences and mappings, aliases expanded.
MAX_DEPTH = 50


class YamlFileError(ValueError):
    """A parameter file that cannot be used; the message names the file and the limit."""


#: A float of YAML 1.2's core schema (``1e-4``, ``5E3``, ``1.0e4``, ``+.5``): the forms that the
#: YAML 1.1 resolver reads as strings (it wants a dot, a signed exponent, no sign before
#: a leading dot) and rcl's parameter-file parser reads as doubles. An integer (``12``)
#: is resolved as one before this is tried.
YAML12_FLOAT = r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?$"

def read_yaml_file(path):
    """The YAML document of ``path`` (None for an empty file), within the limits of the
    module docstring; YamlFileError (one line naming the file) otherwise."""
    path = os.fspath(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)   # a FIFO must not block here
    except OSError as exc:
        if isinstance(exc, FileNotFoundError):
            raise YamlFileError(f"{path}: cannot be read: no such file") from None
        raise YamlFileError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise YamlFileError(f"{path}: is a folder, expected a YAML file")
        if not stat.S_ISREG(info.st_mode):
            raise YamlFileError(f"{path}: not a regular file (a FIFO or device), expected "
                                "a YAML file")
        with os.fdopen(os.dup(fd), "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise YamlFileError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    return parse_yaml_bytes(data, path)


def parse_yaml_bytes(data: bytes, name: str):
    """The YAML document of ``data`` (a file's bytes, or a recorded text's) within the
    limits of the module docstring; YamlFileError (one line starting with ``name``)
    otherwise."""
    import yaml

    if len(data) > MAX_FILE_BYTES:
        raise YamlFileError(f"{name}: larger than {MAX_FILE_BYTES} bytes, the limit of a "
                            "parameter file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlFileError(f"{name}: not UTF-8 text (byte 0x{data[exc.start]:02x} at "
                            f"offset {exc.start})") from None
    try:
        return yaml.load(text, Loader=_get_loader())
    except _LimitError as exc:
        raise YamlFileError(f"{name}: {exc}") from None
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" (line {where.line + 1})" if where is not None else ""
        why = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise YamlFileError(f"{name}: is not valid YAML{at}: {why}") from None


class _LimitError(ValueError):
    """A document beyond MAX_NODES or MAX_DEPTH, or with a cyclic alias."""


def _bounded_loader():
    import yaml
    from yaml.composer import Composer
    from yaml.constructor import SafeConstructor
    from yaml.resolver import Resolver

    if yaml.__with_libyaml__:      # libyaml's events (3.5x faster), PyYAML's composer
        from yaml.cyaml import CParser as Parser
    else:
        from yaml.parser import Parser
        from yaml.reader import Reader
        from yaml.scanner import Scanner

        class Parser(Reader, Scanner, Parser):
            def __init__(self, stream):
                Reader.__init__(self, stream)
                Scanner.__init__(self)
                Parser.__init__(self)

    class BoundedLoader(Parser, Composer, SafeConstructor, Resolver):
        """SafeLoader whose composer counts the document's nodes as they come, aliases
        expanded (``_count``), and measures each node's subtree: ``_size[id(node)]``
        nodes and ``_height[id(node)]`` levels."""

        def __init__(self, stream):
            Parser.__init__(self, stream)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)

        check_node, get_node = Composer.check_node, Composer.get_node
        get_single_node = Composer.get_single_node

        def compose_document(self):
            self._size, self._height, self._depth, self._count = {}, {}, 0, 0
            return Composer.compose_document(self)

        def compose_node(self, parent, index):
            self._depth += 1
            if self._depth > MAX_DEPTH:
                raise _LimitError(f"nested deeper than {MAX_DEPTH} levels, the limit of a "
                                  f"parameter file{_line(self)}")
            alias = self.check_event(yaml.AliasEvent)
            try:
                node = Composer.compose_node(self, parent, index)
            finally:
                self._depth -= 1
            key = id(node)
            if alias:                       # the anchor's subtree once more
                if key not in self._size:
                    raise _LimitError("an alias refers to a node that contains it (a cycle)"
                                      f"{_line(self)}")
                size, height = self._size[key], self._height[key]
                self._count += size
            else:
                self._count += 1
                if isinstance(node, yaml.ScalarNode):
                    size, height = 1, 0
                else:
                    children = (node.value if isinstance(node, yaml.SequenceNode)
                                else [n for pair in node.value for n in pair])
                    size = 1 + sum(self._size[id(c)] for c in children)
                    height = 1 + max((self._height[id(c)] for c in children), default=0)
            if self._count > MAX_NODES:
                raise _LimitError(f"more than {MAX_NODES} YAML nodes with its aliases "
                                  f"expanded, the limit of a parameter file{_line(self)}")
            if height > MAX_DEPTH:
                raise _LimitError(f"nested deeper than {MAX_DEPTH} levels with its aliases "
                                  f"expanded, the limit of a parameter file{_line(self)}")
            self._size[key], self._height[key] = size, height
            return node

    # 1e-4, 5E3, 1.0e4, +.5: floats, as rcl's parameter-file parser (strtod) and YAML 1.2 read
    # them; PyYAML's YAML 1.1 resolver wants a dot and a signed exponent and gives the
    # string '1e-4', which a model file's ``delta_d: -1e-4`` then failed as "expected a
    # real number" while `ros2 run --params-file` read the same file as a double.
    BoundedLoader.add_implicit_resolver(
        "tag:yaml.org,2002:float", re.compile(YAML12_FLOAT), list("-+0123456789."))
    return BoundedLoader


def _line(loader) -> str:
    mark = getattr(loader.peek_event(), "start_mark", None) if loader.check_event() else None
    return f" (line {mark.line + 1})" if mark is not None else ""


def _get_loader():
    global _LOADER
    if _LOADER is None:
        _LOADER = _bounded_loader()
    return _LOADER


_LOADER = None


def ros_parameters(doc) -> dict:
    """The ``ros__parameters`` of a ROS parameter file's document, merged over its node
    keys (``/**``, ``/sim_node``, ...) in file order; {} for a document of another shape."""
    values = {}
    for section in doc.values() if isinstance(doc, dict) else ():
        if isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict):
            values.update(section["ros__parameters"])
    return values


def write_yaml_atomic(path, doc: dict, comments=()) -> None:
    """Write ``doc`` as YAML to ``path`` with ``comments`` as ``#`` lines on top,
    atomically (temporary file, then rename), with the usual 0666 & ~umask mode.

    Raises ValueError for an empty path, IsADirectoryError (an OSError, as the rename's
    own would be) naming ``path`` for an existing folder (the rename's names the
    temporary file), OSError as the file system does.
    """
    import yaml

    path = os.fspath(path)
    if not path.strip():
        raise ValueError(f"path={path!r} is invalid: expected a non-empty file path")
    if os.path.isdir(path):
        raise IsADirectoryError(f"path={path!r} is invalid: it is a folder; expected a file "
                                "path")
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

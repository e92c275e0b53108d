"""A node's command line, checked before rcl sees it: the arguments outside and inside
``--ros-args``, the ``-p`` overrides and ``--params-file`` files against the node's declared
parameters (one line naming what is wrong; docs/nodes.md, "Command line")."""

from __future__ import annotations

import math
import re
import sys
from typing import NamedTuple

from rclpy.exceptions import ParameterUninitializedException

from .common import StartupError

#: ROS arguments (rcl) that take a value, and those that do not.
_ROS_VALUE_ARGS = {"-p", "--param", "-r", "--remap", "-e", "--enclave", "--params-file",
                   "--log-level", "--log-config-file", "--log-file-name"}
_ROS_FLAGS = {"--disable-rosout-logs", "--enable-rosout-logs", "--disable-stdout-logs",
              "--enable-stdout-logs", "--disable-external-lib-logs",
              "--enable-external-lib-logs"}


class NodeArguments(NamedTuple):
    """What :func:`parse_node_arguments` found on a node's command line."""

    help: bool
    params: dict           # name -> value text of every -p name:=value
    params_files: tuple    # (path, {key: {name: value}}) of every --params-file


def parse_node_arguments(args) -> NodeArguments:
    """Check a node's command line before rcl sees it; StartupError names what is wrong.

    ``-h``/``--help`` outside ``--ros-args`` asks for the usage; any other argument outside
    ``--ros-args`` is refused (node parameters go after ``--ros-args``). Inside, every
    ``-p`` must read ``name:=value``, every ``--params-file`` must be a readable YAML
    parameter file (``<node key>: ros__parameters: {...}``), and an unknown ROS
    argument is refused (rcl would only say ``UnknownROSArgsError``).
    """
    tokens = list(args[1:])
    helped, params, files = False, {}, []
    ros = False
    i = 0
    while i < len(tokens):
        tok = tokens[i]
        i += 1
        if tok == "--ros-args":
            ros = True
            continue
        if not ros:
            if tok in ("-h", "--help"):
                helped = True
                continue
            raise StartupError(f"unexpected argument {tok!r}: node parameters go after "
                               "--ros-args, e.g. --ros-args -p name:=value (see --help)")
        if tok == "--":
            ros = False
            continue
        if tok in _ROS_FLAGS:
            continue
        if tok not in _ROS_VALUE_ARGS:
            raise StartupError(f"unknown ROS argument {tok!r}: valid are "
                               f"{', '.join(sorted(_ROS_VALUE_ARGS | _ROS_FLAGS))}")
        if i >= len(tokens):
            raise StartupError(f"ROS argument {tok} needs a value")
        value = tokens[i]
        i += 1
        if tok in ("-p", "--param"):
            name, sep, text = value.partition(":=")
            if not sep or not name:
                raise StartupError(f"-p {value!r} is invalid: write -p name:=value")
            params[name] = text
        elif tok == "--params-file":
            files.append((value, _load_params_file(value)))
    return NodeArguments(helped, params, tuple(files))


def _load_params_file(path: str) -> dict:
    """{node key: {name: value}} of a ROS parameter file; StartupError if unusable
    (beyond the limits of :func:`grazing_control.support.files.read_yaml_file` too)."""
    from grazing_control.support.files import YamlFileError, read_yaml_file

    try:
        data = read_yaml_file(path)
    except YamlFileError as exc:
        raise StartupError(f"--params-file {exc}") from None
    shape = ("expected '<node name or /**>: ros__parameters: {name: value, ...}' "
             "at the top level")
    if not isinstance(data, dict) or not data:
        raise StartupError(f"--params-file {path!r} is not a ROS parameter file: {shape}")
    out = {}
    for key, body in data.items():
        if (not isinstance(body, dict) or "ros__parameters" not in body
                or not isinstance(body["ros__parameters"], (dict, type(None)))):
            raise StartupError(f"--params-file {path!r}, key {key!r}: {shape}")
        out[str(key)] = dict(_flatten(body["ros__parameters"] or {}))
    return out


def _flatten(tree: dict, prefix: str = ""):
    """Nested parameter maps as rcl reads them: {'a': {'b': 1}} -> ('a.b', 1)."""
    for name, value in tree.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", value


def node_key_matches(key: str, full_name: str) -> bool:
    """Whether a parameter-file key (``/**``, ``/*``, ``/ns/node``, ``node``) applies.

    rcl's rule: ``**`` matches any number of name tokens, ``*`` exactly one; a key
    without a leading ``/`` is absolute all the same.
    """
    pattern = ""
    for token in key.strip("/").split("/"):
        if token == "**":
            pattern += "(/[^/]+)*"
        elif token == "*":
            pattern += "/[^/]+"
        else:
            pattern += "/" + re.escape(token)
    return re.fullmatch(pattern, full_name) is not None


_YAML_FLOATS = {".nan": math.nan, ".NaN": math.nan, ".NAN": math.nan, ".inf": math.inf,
                ".Inf": math.inf, ".INF": math.inf, "-.inf": -math.inf, "-.Inf": -math.inf,
                "-.INF": -math.inf, "+.inf": math.inf}


def _override_problem(param, text: str):
    """Why ``-p name:=text`` did not set ``param`` to that value, or None.

    rcl types a ``-p`` value from its text (integer, double, bool, string, array); a value
    of another type than the declared one, or an integer beyond 64 bits (rcl reads it as
    a double), is not always refused by rclpy: with a parameter file giving the same name,
    the file's value silently stayed (``zeta:=abc``, ``max_periods:=1e23``; issue 21).
    Compared here with what the node holds after declaring its parameters.
    """
    from rclpy.parameter import Parameter

    kind, value = param.type_, param.value
    t = text.strip()
    if kind == Parameter.Type.DOUBLE:
        try:
            want = _YAML_FLOATS[t] if t in _YAML_FLOATS else float(t)
        except ValueError:
            return "expected a double (a number with a decimal point, e.g. 0.01)"
        if not (want == value or (math.isnan(want) and math.isnan(value))):
            return f"not applied (the node holds {value!r})"
    elif kind == Parameter.Type.INTEGER:
        try:
            want = int(t)
        except ValueError:
            return "expected an integer"
        if not -2**63 <= want < 2**63:
            return "beyond the 64-bit integer range"
        if want != value:
            return f"not applied (the node holds {value!r})"
    elif kind == Parameter.Type.BOOL:
        if t.lower() not in ("true", "false"):
            return "expected true or false"
        if (t.lower() == "true") != value:
            return f"not applied (the node holds {value!r})"
    return None


def check_overrides(node, arguments: NodeArguments) -> None:
    """Refuse ``-p`` names the node does not declare; warn about unused file entries.

    A ``-p name:=value`` for a parameter the node does not have is a typo or a wrong
    node: StartupError. A parameter file keyed for another node name (``/sim_node:``
    read by ``/ns/sim_node``) is silently ignored by rcl: a file none of whose keys
    applies to the node is warned about, naming its keys and the node's full name (the
    other sections of a combined file are normal); so are names under a matching key
    that the node does not declare (a shared ``/**:`` file may hold other nodes'
    parameters: a warning, not an error).
    """
    log = node.get_logger()
    unknown = sorted(n for n in arguments.params if not node.has_parameter(n))
    if unknown:
        declared = sorted(node._parameters) if hasattr(node, "_parameters") else []
        raise StartupError(
            f"unknown parameter {', '.join(unknown)} for {node.get_name()}: valid names "
            f"are {', '.join(declared)}")
    for name, text in arguments.params.items():
        try:
            param = node.get_parameter(name)
        except ParameterUninitializedException:     # -p name:=[] (no type): the node's own
            continue                                # check says what is wrong
        problem = _override_problem(param, text)
        if problem:
            raise StartupError(f"{name}:={text} is invalid: {problem}")
    full = node.get_fully_qualified_name()
    for path, keys in arguments.params_files:
        matching = [key for key in keys if node_key_matches(key, full)]
        if not matching:         # a combined file's other sections are normal
            log.warning(f"--params-file {path}: no key applies to this node ({full}): "
                        f"{', '.join(repr(k) for k in keys)} ignored (key the file '/**:' "
                        "to apply to any node name)")
        for key in matching:
            extra = sorted(n for n in keys[key] if not node.has_parameter(n))
            if extra:
                log.warning(f"--params-file {path}: {', '.join(extra)} under {key!r} are "
                            f"not parameters of {full}: ignored")


def usage(factory, name: str) -> str:
    """The usage text of a node: a synopsis and its module's docstring."""
    doc = (sys.modules.get(getattr(factory, "__module__", ""), None).__doc__
           if getattr(factory, "__module__", "") in sys.modules else None) or ""
    return (f"usage: {name} [-h] [--ros-args [--params-file FILE] [-p name:=value] ...]\n\n"
            + doc.strip() + "\n")



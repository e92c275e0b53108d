"""Hostile parameter, model and gain files (issue 27 §4): the one reader
(support/files.read_yaml_file) refuses a FIFO, a device, a folder, a file over 1 MiB, a
non-UTF-8 byte, an alias bomb, a cycle and deep nesting, each with one line naming the
file and the limit; every command line option and node argument that reads such a file
goes through it (status 2, within seconds, bounded memory); and seeded fuzzing of
thousands of random documents never raises anything but the documented error."""

import itertools
import os
import random
import string

import hostile_files
import pytest
import yaml

from grazing_control.cli.commands import main
from grazing_control.ros.common import StartupError
from grazing_control.ros.node_arguments import parse_node_arguments
from grazing_control.support import files
from grazing_control.support.files import YamlFileError, read_yaml_file

TWO = os.path.join(os.path.dirname(__file__), "..", "config", "models", "two_mass_chain.yaml")


def laughs(levels=9, width=9):
    """A "billion laughs" as one flow sequence: ``width ** levels`` scalars once the
    aliases are expanded, in about 40 bytes per level."""
    items = [f"&l0 [{', '.join(['lol'] * width)}]"]
    for i in range(1, levels):
        items.append(f"&l{i} [{', '.join([f'*l{i - 1}'] * width)}]")
    return "[" + ", ".join(items) + "]"


def params_bomb():
    """A ROS 2 parameter file whose ``zeta`` is a billion laughs."""
    return f"/**:\n  ros__parameters:\n    zeta: {laughs()}\n"


def model_bomb(field):
    """The two-mass model with ``field`` (M, f or omega) a billion laughs."""
    lines = [ln for ln in open(TWO).read().splitlines()
             if ln and not ln.startswith("#") and not ln.startswith(f"{field}:")]
    return "\n".join(lines) + f"\n{field}: {laughs()}\n"


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


# ------------------------------------------------------------------ the reader itself
@pytest.mark.parametrize("name, content, needle", [
    ("laughs", f"a: {laughs()}\n", "more than 50000 YAML nodes with its aliases expanded"),
    ("deep_flow", "[" * 100_000 + "]" * 100_000, "nested deeper than 50 levels"),
    ("deep_block", "".join(" " * i + f"k{i}:\n" for i in range(1200)),
     "nested deeper than 50 levels"),
    ("alias_chain", "a0: &a0 [1]\n" + "".join(f"a{i}: &a{i} [*a{i - 1}]\n"
                                              for i in range(1, 80)),
     "nested deeper than 50 levels with its aliases expanded"),
    ("cycle", "a: &a [1, *a]\n", "an alias refers to a node that contains it"),
    ("latin1", b"zeta: 0.01\nname: caf\xe9\n", "not UTF-8 text (byte 0xe9 at offset 20)"),
    ("padded", "zeta: 0.01\n" + "#" * (1 << 20), "larger than 1048576 bytes"),
    ("flat", "[" + "1," * 60_000 + "1]", "more than 50000 YAML nodes"),
    ("broken", "a: [1, 2\n", "is not valid YAML (line 2)"),
])
def test_each_limit_is_one_line_naming_the_file(tmp_path, name, content, needle):
    path = write(tmp_path, f"{name}.yaml", content)
    with pytest.raises(YamlFileError) as info:
        read_yaml_file(path)
    assert str(info.value).startswith(f"{path}: ") and needle in str(info.value)
    assert "\n" not in str(info.value)


def test_special_files_are_refused_without_opening_them_blocking(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    for path, needle in ((fifo, "not a regular file"), ("/dev/zero", "not a regular file"),
                         (tmp_path, "is a folder"), (tmp_path / "none.yaml", "no such file")):
        with pytest.raises(YamlFileError, match=needle):
            read_yaml_file(path)


def test_what_a_parameter_file_needs_is_read_as_safe_load_reads_it(tmp_path):
    text = ("/**:\n  ros__parameters:\n    zeta: 0.01\n    gains: &g [1.0, -2.5e-3]\n"
            "    copy: *g\n    base: &b {x: 1}\n    merged: {<<: *b, y: 2}\n    on: true\n"
            "    name: 'x'\n    none: null\n")
    path = write(tmp_path, "ok.yaml", text)
    assert read_yaml_file(path) == yaml.safe_load(text)
    assert read_yaml_file(write(tmp_path, "empty.yaml", "")) is None
    # the study's own files and models are far inside the limits
    root = os.path.join(os.path.dirname(__file__), "..", "config")
    for folder, _, names in os.walk(root):
        for n in names:
            if n.endswith(".yaml"):
                p = os.path.join(folder, n)
                assert read_yaml_file(p) == yaml.safe_load(open(p, encoding="utf-8"))


def _random_document(rng):
    """Random YAML text: nesting, anchors and aliases (back-references only, some to an
    enclosing node), scalars of every type, and now and then raw random bytes."""
    anchors, left, deepest = [], [rng.randint(1, 400)], rng.choice([3, 10, 40, 80])
    names = itertools.count()

    def node(depth):
        r = rng.random()
        left[0] -= 1
        if anchors and r < 0.2:
            return f"*{rng.choice(anchors)}"
        if left[0] <= 0 or depth >= deepest or (r < 0.3 and depth < deepest - 2):
            return rng.choice(["1", "-2.5e-3", ".nan", "true", "null", "'s'", "~", "0x1F",
                               '"\\u00e9"', "2026-11-27", "!!binary aGk=", "[]", "{}",
                               "'" + "".join(rng.choice(string.ascii_letters + " :,[]{}&*!|>")
                                             for _ in range(3)) + "'"]
                              + (["".join(rng.choice(string.printable[:94]) for _ in range(3))]
                                 if rng.random() < 0.05 else []))
        anchor = ""
        if rng.random() < 0.3:
            name = f"a{next(names)}"
            anchor = f"&{name} "
            cycle = rng.random() < 0.05     # an alias inside its own anchor
            if cycle:
                anchors.append(name)
            items = [node(depth + 1) for _ in range(rng.randint(1, 9))]
            if not cycle:
                anchors.append(name)
        else:
            items = [node(depth + 1) for _ in range(rng.randint(1 if depth < 2 else 0, 4))]
        if rng.random() < 0.5:
            return anchor + "[" + ", ".join(items) + "]"
        return anchor + "{" + ", ".join(f"k{i}: {v}" for i, v in enumerate(items)) + "}"

    text = node(0)
    if rng.random() < 0.1:
        raw = bytearray(text.encode())
        for _ in range(rng.randint(1, 4)):
            raw.insert(rng.randrange(len(raw) + 1), rng.randrange(256))
        return bytes(raw)
    return text.encode()


def test_fuzzed_documents_give_a_document_or_the_documented_error(tmp_path, monkeypatch):
    # small limits, so that random documents reach them often (the same code either way)
    monkeypatch.setattr(files, "MAX_NODES", 2000)
    monkeypatch.setattr(files, "MAX_DEPTH", 30)
    rng = random.Random(27)
    path = tmp_path / "fuzz.yaml"
    reasons = ("more than 2000 YAML nodes", "nested deeper than 30", "a cycle",
               "not UTF-8", "not valid YAML")
    outcomes = dict.fromkeys(("read",) + reasons, 0)
    for _ in range(3000):
        path.write_bytes(_random_document(rng))
        try:
            doc = read_yaml_file(path)
        except YamlFileError as exc:
            assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)
            outcomes[next(r for r in reasons if r in str(exc))] += 1
            continue
        outcomes["read"] += 1
        assert _expanded(doc, 0) <= 2000          # what was read is within the bound
    assert min(outcomes.values()) >= 50, outcomes        # each outcome is exercised


def _expanded(obj, depth):
    """Nodes of ``obj`` with shared objects counted each time (aliases expanded)."""
    assert depth <= 31
    if isinstance(obj, dict):
        return 1 + sum(_expanded(k, depth + 1) + _expanded(v, depth + 1) for k, v in obj.items())
    if isinstance(obj, list):
        return 1 + sum(_expanded(v, depth + 1) for v in obj)
    return 1


# ------------------------------------------------------------------ every reader uses it
def _cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.timeout(60)      # a hang guard: a FIFO opened for reading blocks for ever
@pytest.mark.parametrize("option", ["--params", "--model", "--sim-params",
                                    "--controller-params"])
def test_a_fifo_as_any_file_option_is_refused_at_once(capsys, tmp_path, option):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    code, out, err = _cli(capsys, "run", option, fifo, "--periods", "1")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"{option} {fifo}: not a regular file" in err


@pytest.mark.parametrize("argv, option", [
    (["design", "--params", "{bomb}"], "--params"),
    (["run", "--params", "{bomb}", "--periods", "1"], "--params"),
    (["run", "--sim-params", "{bomb}", "--periods", "1"], "--sim-params"),
    (["run", "--controller-params", "{bomb}", "--periods", "1"], "--controller-params"),
])
def test_an_alias_bomb_in_a_parameter_file_is_one_line(capsys, tmp_path, argv, option):
    bomb = write(tmp_path, "bomb.yaml", params_bomb())
    code, out, err = _cli(capsys, *[a.format(bomb=bomb) for a in argv])
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"{option} {bomb}: more than 50000 YAML nodes" in err


@pytest.mark.parametrize("field", ["M", "f", "omega"])
def test_an_alias_bomb_in_a_model_file_is_one_line_in_bounded_memory(tmp_path, field):
    bomb = write(tmp_path, f"bomb_{field}.yaml", model_bomb(field))
    status, out, err, peak = hostile_files.grazing_measured("design", "--model", bomb)
    assert status == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert f"--model {bomb}: more than 50000 YAML nodes" in err
    assert peak < 200, peak        # before: no output after 30 s and 0.6 to > 2 GB


def test_a_non_utf8_byte_and_deep_nesting_in_params_name_the_file(capsys, tmp_path):
    bad = write(tmp_path, "latin1.yaml", b"/**:\n  ros__parameters:\n    zeta: 0.01 # \xe9\n")
    code, _, err = _cli(capsys, "design", "--params", bad)
    assert code == 2 and f"--params {bad}: not UTF-8 text (byte 0xe9 at offset 41)" in err
    deep = write(tmp_path, "deep.yaml", "[" * 100_000 + "]" * 100_000)
    code, _, err = _cli(capsys, "design", "--params", deep)
    assert code == 2 and f"--params {deep}: nested deeper than 50 levels" in err
    assert "recursion" not in err


def test_a_node_refuses_a_bomb_in_its_parameter_file(tmp_path):
    bomb = write(tmp_path, "bomb.yaml", params_bomb())
    with pytest.raises(StartupError, match=r"--params-file .*bomb.yaml: more than 50000"):
        parse_node_arguments(["node", "--ros-args", "--params-file", str(bomb)])


def test_a_node_refuses_a_bomb_as_its_model_file(tmp_path):
    from grazing_control.oscillator.params import ParameterError
    from grazing_control.plant.settings import load_model_file

    bomb = write(tmp_path, "bomb.yaml", model_bomb("M"))
    with pytest.raises(ParameterError, match=r"model_file=.*bomb.yaml' is invalid: cannot "
                                             r"read it as a model YAML file \(more than 50000"):
        load_model_file(str(bomb))


# ------------------------------------------------- numbers read as rcl reads them
def _numeric_spelling(rng):
    """A random spelling of a number: sign, digits, a dot, digits, an exponent (each part
    optional, some of them malformed: ``1e``, ``-.``, ``+E5``)."""
    digits = lambda lo, hi: "".join(rng.choice("0123456789") for _ in range(rng.randint(lo, hi)))
    s = rng.choice(["", "-", "+"])
    if rng.random() < 0.85:
        s += digits(1, 3)
    if rng.random() < 0.5:
        s += "." + digits(0, 2)
    if rng.random() < 0.7:
        s += rng.choice("eE") + rng.choice(["", "-", "+"]) + digits(0, 2)
    return s or "1"


def test_a_number_in_a_parameter_file_is_read_as_rcl_reads_it(tmp_path):
    """``delta_d: -1e-4`` is a double to rcl's parameter-file parser (and to YAML 1.2) but
    was the string '-1e-4' to PyYAML's YAML 1.1 resolver, so `grazing design --model`
    refused a model file that `ros2 run --params-file` read (84 of these 294 spellings
    differed). Differential, over seeded random spellings: the type and value that
    read_yaml_file gives is the one a node's parameter gets from rcl (or both refuse)."""
    import rclpy
    from rclpy.context import Context

    rng = random.Random(32)
    spellings = sorted({_numeric_spelling(rng) for _ in range(300)})
    kinds = {float: "DOUBLE", int: "INTEGER", str: "STRING"}
    seen = set()
    for text in spellings:
        path = write(tmp_path, "n.yaml", f"/**:\n  ros__parameters:\n    k: {text}\n")
        try:
            ours = read_yaml_file(path)["/**"]["ros__parameters"]["k"]
            ours = (kinds[type(ours)], ours)
        except YamlFileError:
            ours = "refused"
        ctx = Context()
        try:
            rclpy.init(context=ctx, args=["--ros-args", "--params-file", str(path)])
        except Exception:
            rcl = "refused"
        else:
            try:
                node = rclpy.create_node("numbers", context=ctx,
                                         automatically_declare_parameters_from_overrides=True)
                p = node.get_parameter("k")
                rcl = (p.type_.name, p.value)
                node.destroy_node()
            finally:
                rclpy.shutdown(context=ctx)
        assert ours == rcl, (text, ours, rcl)
        seen.add(ours if ours == "refused" else ours[0])
    assert {"DOUBLE", "INTEGER", "STRING"} <= seen, seen


def test_a_model_file_takes_an_exponent_without_a_dot(tmp_path):
    from grazing_control.oscillator.ndof.model import load_model

    text = open(os.path.join(os.path.dirname(__file__), "..", "config", "models",
                             "two_mass_chain.yaml"), encoding="utf-8").read()
    lines = [ln for ln in text.splitlines() if not ln.startswith("delta_d:")]
    path = write(tmp_path, "m.yaml", "\n".join(lines + ["delta_d: -1e-4", ""]))
    assert load_model(path).delta_d == -1e-4

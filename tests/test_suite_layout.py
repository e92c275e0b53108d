"""How `make test` shares the suite between two workers (tests/conftest.py) names real
modules, and every module that starts a node process is in the scene group."""

import re
from pathlib import Path

import conftest

HERE = Path(__file__).parent

#: What a module calls when it starts node processes or a scene (launcher, console
#: scripts, `grazing run`, ros2 launch, colcon).
STARTS_NODES = re.compile(r"launcher\.run\(|start_node\(|run_scene\(|node_command\(|"
                          r"script\(\"(sim|controller|recorder|live)_node\"\)|"
                          r"\[\"run\"|colcon")


def test_the_scene_group_names_existing_modules():
    modules = {p.stem for p in HERE.glob("test_*.py")}
    assert conftest.SCENE_MODULES <= modules, conftest.SCENE_MODULES - modules


def test_the_realtime_tests_are_scene_tests():
    """A test marked realtime waits for the other worker to be idle: it must be a scene
    module's (the scene group runs one scene at a time), and the marker must be in use."""
    marked = {p.stem for p in HERE.glob("test_*.py")
              if p.stem != "test_suite_layout" and "pytest.mark.realtime" in p.read_text()}
    assert marked, "no test is marked realtime: the marker no longer matches the tests"
    assert marked <= conftest.SCENE_MODULES, marked - conftest.SCENE_MODULES


def test_every_module_that_starts_nodes_is_in_the_scene_group():
    """Two scenes at once on two cores would make the realtime checks meaningless: a
    module that starts nodes and is not in the group would run beside the scenes."""
    starts = {p.stem for p in HERE.glob("test_*.py")
              if p.stem != "test_suite_layout" and STARTS_NODES.search(p.read_text())}
    assert starts, "the pattern finds no module: it no longer matches the tests"
    assert starts <= conftest.SCENE_MODULES, starts - conftest.SCENE_MODULES

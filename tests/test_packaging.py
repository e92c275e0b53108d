"""Packaging: package.xml, console scripts, and a real ``colcon build`` of the package.

The console-script tests skip an executable only while the module it points to does
not exist yet; once the module lands they enforce it. The colcon test builds a copy of
the working tree (the files git tracks or would track) in a temporary workspace with
the colcon of this virtual environment, as a ROS 2 machine would, and checks that the
executables land where ``ros2 run grazing_control <exe>`` looks. docs/ros_build.md
describes the build and its quirks.
"""
import importlib.metadata
import importlib.util
import os
import random
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'grazing_control'
BIN_DIR = Path(sys.executable).parent

# Executable name -> module holding its ``main`` (the contract of setup.py).
CONSOLE_SCRIPTS = {
    'grazing': 'grazing_control.cli.console',
    'sim_node': 'sim_node.sim_node',
    'controller_node': 'grazing_control.ros.controller_node',
    'recorder_node': 'grazing_control.ros.recorder_node',
    'live_node': 'grazing_control.ros.live_node',
    'effort_bridge': 'grazing_control.ros.effort_bridge',
    'rig_mock': 'grazing_control.recordings.rig_mock',
}

#: What each console script calls: the nodes' go through grazing_control.ros.entry (a
#: thin module, quiet on a Ctrl-C while the node's module imports; issue 27).
ENTRY_POINTS = {name: f'grazing_control.ros.entry:{name}' if name != 'grazing'
                else f'{mod}:main' for name, mod in CONSOLE_SCRIPTS.items()}

EXEC_DEPENDS = {
    'rclpy', 'sensor_msgs', 'geometry_msgs', 'std_msgs', 'std_srvs', 'rosgraph_msgs',
    'python3-numpy', 'python3-scipy', 'python3-yaml', 'python3-matplotlib', 'python3-tqdm',
    'rcl_interfaces', 'builtin_interfaces', 'ament_index_python', 'launch', 'launch_ros',
    'mcap-ros2-support', 'python3-rosbags-pip',
}
TEST_DEPENDS = {'python3-pytest', 'rclpy', 'rmw_fastrtps_cpp'}
# rosdep key -> Python module it provides (ROS packages import under their own name).
ROSDEP_MODULES = {'python3-numpy': 'numpy', 'python3-scipy': 'scipy', 'python3-yaml': 'yaml',
                  'python3-matplotlib': 'matplotlib', 'python3-tqdm': 'tqdm',
                  'mcap-ros2-support': 'mcap_ros2', 'python3-rosbags-pip': 'rosbags',
                  'python3-pytest': 'pytest', 'rmw_fastrtps_cpp': 'rclpy',
                  'python3-numba': 'numba', 'python3-pil': 'PIL',
                  'python3-zstandard': 'zstandard', 'python3-lz4': 'lz4'}
# Only on a ROS install (no PyPI wheels): the launch file's; `grazing run` needs neither.
ROS_INSTALL_ONLY = {'launch', 'launch_ros'}


def module_exists(name):
    """True if ``name`` can be imported (its parent packages are imported to tell)."""
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


def skip_unless_module(module):
    if not module_exists(module):
        pytest.skip(f'{module} does not exist yet')


@pytest.fixture(scope='module')
def manifest():
    return ET.parse(ROOT / 'package.xml').getroot()


def test_package_xml_identity(manifest):
    assert manifest.tag == 'package'
    assert manifest.get('format') == '3'
    assert manifest.findtext('name') == PACKAGE
    assert manifest.findtext('version') == '0.1.0'
    assert manifest.findtext('license') == 'Apache-2.0'
    assert manifest.findtext('export/build_type') == 'ament_python'
    assert manifest.find('maintainer').get('email')


def test_package_xml_dependencies(manifest):
    exec_depends = {e.text for e in manifest.findall('exec_depend')}
    assert EXEC_DEPENDS <= exec_depends, EXEC_DEPENDS - exec_depends
    assert TEST_DEPENDS <= {e.text for e in manifest.findall('test_depend')}


def test_exec_depends_importable_in_this_environment(manifest):
    """What package.xml promises a ROS machine, the pinned venv provides too."""
    missing = []
    for dep in (e.text for e in manifest.findall('exec_depend')):
        if dep in ROS_INSTALL_ONLY:
            continue
        module = ROSDEP_MODULES.get(dep, dep)
        if not module_exists(module):
            missing.append(f'{dep} (module {module})')
    assert not missing, missing


def test_installed_metadata_matches_manifest(manifest):
    assert importlib.metadata.version(PACKAGE) == manifest.findtext('version')


def test_entry_points_declared():
    eps = importlib.metadata.distribution(PACKAGE).entry_points
    declared = {ep.name: ep.value for ep in eps if ep.group == 'console_scripts'}
    assert declared == ENTRY_POINTS
    from grazing_control.ros.entry import MODULES

    assert MODULES == {n: m for n, m in CONSOLE_SCRIPTS.items() if n != 'grazing'}


@pytest.mark.parametrize('name', sorted(CONSOLE_SCRIPTS))
def test_console_script_installed(name):
    module = CONSOLE_SCRIPTS[name]
    skip_unless_module(module)
    from console_scripts import script as console_script

    script = console_script(name)
    assert script.is_file(), f'{script} missing: run `make venv`'
    assert os.access(script, os.X_OK)
    assert callable(getattr(importlib.import_module(module), 'main', None)), \
        f'{module} has no main()'


def test_grazing_cli_help_runs():
    skip_unless_module(CONSOLE_SCRIPTS['grazing'])
    from console_scripts import script as console_script

    result = subprocess.run([str(console_script('grazing')), '--help'], capture_output=True,
                            text=True, timeout=120, cwd=os.path.expanduser('~'))
    assert result.returncode == 0, result.stderr


def source_files():
    """Files of the working tree that git tracks or would track (not ignored)."""
    if shutil.which('git') is None:
        pytest.skip('git is not installed')
    result = subprocess.run(
        ['git', 'ls-files', '-z', '--cached', '--others', '--exclude-standard'],
        cwd=ROOT, capture_output=True, text=True)
    if result.returncode != 0:
        pytest.skip(f'not a git work tree: {result.stderr.strip()}')
    return sorted({p for p in result.stdout.split('\0') if p and (ROOT / p).is_file()})


def python_packages(root):
    """Dotted names of the regular packages the build installs (see setup.py)."""
    names = []
    for top in ('grazing_control', 'sim_node'):
        for init in sorted((root / top).rglob('__init__.py')):
            rel = init.parent.relative_to(root)
            # find_packages stops at a directory without __init__.py
            if all((root / Path(*rel.parts[:i + 1]) / '__init__.py').is_file()
                   for i in range(len(rel.parts))):
                names.append('.'.join(rel.parts))
    return names


def numba_cache_to(site):
    """Copy this checkout's numba cache (the kernels the suite's session compiled) into
    the installed tree, so that the installed nodes load the kernels instead of
    compiling them again (8-9 CPU-s of the scene's 11, 2026-11-29). The installed sources
    are the same files: the kernel's cache is stamped by their contents
    (oscillator/kernel/caching.py), numba's own by each file's mtime and size, which the
    copies keep; a stale entry is refused by numba and compiled as before. The cold
    compilation itself is test_kernel's (a Ctrl-C during it)."""
    for cached in ROOT.glob('grazing_control/**/__pycache__/*.nb[ic]'):
        dest = site / cached.relative_to(ROOT)
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cached, dest)


@pytest.mark.timeout(600)
@pytest.mark.parametrize('symlink', [False, True], ids=['install', 'symlink-install'])
def test_colcon_build(tmp_path, symlink):
    colcon = BIN_DIR / 'colcon'
    assert colcon.is_file(), f'{colcon} missing: colcon-common-extensions is in requirements.txt'
    src = tmp_path / 'src' / PACKAGE
    for rel in source_files():
        dest = src / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, dest)

    env = dict(os.environ)
    env['COLCON_HOME'] = str(tmp_path / 'colcon_home')  # no user defaults/mixins
    env.pop('PYTHONPATH', None)
    cmd = [str(colcon), 'build', '--base-paths', str(src),
           '--event-handlers', 'console_cohesion+']
    if symlink:
        cmd.append('--symlink-install')
    result = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=540)
    assert result.returncode == 0, result.stdout + result.stderr

    prefix = tmp_path / 'install' / PACKAGE
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()
    assert (prefix / 'share' / PACKAGE / 'package.xml').is_file()
    for name in CONSOLE_SCRIPTS:
        exe = prefix / 'lib' / PACKAGE / name
        assert exe.is_file() and os.access(exe, os.X_OK), f'{exe} missing'
    for pattern, subdir in (('launch/*.py', 'launch'), ('config/*.yaml', 'config'),
                          ('config/*.json', 'config'), ('config/models/*.yaml', 'config/models'),
                          ('config/rigs/*.yaml', 'config/rigs')):
        for f in src.glob(pattern):
            assert (prefix / 'share' / PACKAGE / subdir / f.name).is_file(), f

    site = prefix / 'lib' / f'python{sys.version_info.major}.{sys.version_info.minor}' \
        / 'site-packages'
    if not symlink:
        for pkg in python_packages(src):
            assert (site / Path(*pkg.split('.')) / '__init__.py').is_file(), pkg
        numba_cache_to(site)

    # In a shell that sourced the install space, as for `ros2 run`, the package imports
    # from the workspace (not from this repository) and the installed executable runs.
    probe = ('import grazing_control, sim_node; '
             'print(grazing_control.__file__); print(sim_node.__file__)')
    script = (f'. "{tmp_path}/install/local_setup.bash" && cd / && '
              f'"{sys.executable}" -c "{probe}"')
    if module_exists(CONSOLE_SCRIPTS['grazing']):
        script += f' && "{prefix}/lib/{PACKAGE}/grazing" --help >/dev/null'
        if not symlink and module_exists(CONSOLE_SCRIPTS['sim_node']):
            # a short closed-loop scene through the installed nodes, on a domain of its own
            domain = random.SystemRandom().randrange(101, 232)
            script += (f' && "{prefix}/lib/{PACKAGE}/grazing" run --periods 10 --delta-d -5e-6'
                       f' --enable-after 5 --timeout 90 --domain-id {domain}')
            # a reference bag replayed through the installed controller and simulator
            script += (f' && "{prefix}/lib/{PACKAGE}/grazing" replay "{src}/bags/scene_9e-6"'
                       f' --bag "{tmp_path}/replay" --domain-id {domain}')
    run = subprocess.run(['bash', '-c', script], env=env, capture_output=True, text=True,
                         timeout=180)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.split('\n')
    for line in lines[:2]:
        assert Path(line).resolve().is_relative_to(tmp_path.resolve()), line
    if not symlink and module_exists(CONSOLE_SCRIPTS['sim_node']):
        assert 'sim_node=0 controller_node=0' in run.stdout, run.stdout + run.stderr
        assert 'BIT-IDENTICAL to the recorded corrections' in run.stdout, run.stdout + run.stderr
        assert '1300 bit-identical' in run.stdout, run.stdout + run.stderr

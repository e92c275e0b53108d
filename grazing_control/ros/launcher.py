"""The project's own launcher: the nodes as separate processes, for machines without ``ros2``.

:func:`run` starts ``sim_node``, ``controller_node`` and (with a bag directory)
``recorder_node`` as ``sys.executable -m <module> --ros-args --params-file ... -p key:=value``,
waits for the simulator to finish the scene (it runs ``max_periods`` forcing periods with
``exit_when_done:=true`` and exits with status 0), then stops the controller and, once it
has exited, the recorder (which closes its bag), and returns every exit status.
It only spawns processes: it does not import rclpy.

End of a scene (issue 27): each node, when it stops, says how many messages it published
(``grazing/published``) and waits until every reliable reader has acknowledged them; the
recorder is stopped last, waits for what the nodes said they published, and its closed
record (``metadata.yaml``) names what it missed: the run then fails with that list
(:func:`recorded_losses`).

Start order and readiness: the recorder and the controller start first; the simulator
waits until the controller is matched (``wait_for_controller``) and, with a recorder,
until every data topic has a subscriber (``wait_for_subscribers:=1``) and the recorder
says it has matched a publisher on every topic it records (``wait_for_recorder``), so no
message of the scene is published before someone records it; the recorder checks the
publishers' sequence numbers at the end and fails (``require_complete``) if it missed any.

Isolation: each scene runs on a ROS_DOMAIN_ID of its own unless one is given
(:func:`claim_domain`): a domain id in 1..232 that no other scene of this machine has
claimed (a lock file held for the run) and on which no DDS participant of this host
is running (its first participant's discovery port is free). A domain isolates
everything, ``/clock``, ``/rosout``, ``/parameter_events`` and services included,
without renaming a topic; a namespace would leave the absolute ones shared. The
simulator also refuses to run when another simulator or controller shares its topics.

Failing fast: a node that exits early (a refused parameter) stops the scene at once.
A failed scene names its reason (:attr:`RunResult.reason`): the simulator's own (the
realtime watchdog's trip, a refused feasibility check, a stopped simulation), which it
writes to its ``verdict_file`` at exit, else what the launcher saw (a timeout, a node that
left early or failed).
Ctrl-C (or SIGTERM to the launcher): the nodes run in process groups of their own, so
only the launcher gets the terminal's SIGINT; it sends SIGTERM to every node still
running (handled as SIGINT: summaries, the bag closed; a node still starting ends
quietly), waits for them and returns with ``interrupted=True``. A node sent SIGINT
while it is still importing its modules exits quietly with status 130
(:data:`BOOTSTRAP`); every node gets SIGTERM if the launcher is killed.

``ros2 launch grazing_control grazing_control.launch.py`` is the equivalent on a ROS install.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import importlib.util
import json
import math
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from . import node_zygote
from .entry import MODULES
from .scene_nodes import (design_delay, design_model,  # noqa: F401 (design_delay: API)
                          scene_overrides, sim_values_for_model, sim_values_for_rig)
from .scene_verdict import failure_reason, read_verdict, scene_numbers

__all__ = ["RunResult", "run", "run_scene", "claim_domain", "node_command",
           "recorded_losses",
           "node_env", "MAX_DOMAIN_ID", "BOOTSTRAP",
           "start_node", "stop_nodes", "format_value", "SIM_MODULE", "CONTROLLER_MODULE",
           "RECORDER_MODULE", "CONFIG_DIR"]

#: The nodes' modules, as the executables run them (:data:`.entry.MODULES`).
SIM_MODULE = MODULES["sim_node"]
CONTROLLER_MODULE = MODULES["controller_node"]
RECORDER_MODULE = MODULES["recorder_node"]
LIVE_MODULE = MODULES["live_node"]
#: The source tree's root (so that ``-m sim_node.sim_node`` works from a checkout).
SOURCE_ROOT = Path(__file__).resolve().parents[2]


def _config_dir() -> Path:
    """config/ of the checkout, else the installed package's share/grazing_control/config."""
    local = SOURCE_ROOT / "config"
    if (local / "study.yaml").is_file():
        return local
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("grazing_control")) / "config"
    except Exception:  # not installed with colcon: keep the checkout's path for the message
        return local


#: Parameter files of the study: study.yaml (sim_node) and controller.yaml (c2 = -1).
CONFIG_DIR = _config_dir()


@dataclass
class RunResult:
    """Exit statuses of one scene's processes (None: not started)."""

    sim: int | None
    controller: int | None
    recorder: int | None
    bag_dir: str | None
    wall: float
    timed_out: bool = False
    interrupted: bool = False
    logs: dict = field(default_factory=dict)
    domain_id: int | None = None
    live: int | None = None            # live_node's exit status (None: no live view)
    lost: str = ""                     # what the recorder missed (its closed record)
    reason: str | None = None          # why the scene failed, one line (None when ok)
    sim_verdict: dict | None = None    # sim_node's verdict_file: status, reason, summary,
    #                                    watchdog trip, feasibility verdict,
    #                                    misses, longest_pause
    early: tuple = ()                  # the nodes that left before the simulator was done

    def __str__(self) -> str:
        state = ("timed out" if self.timed_out else "interrupted" if self.interrupted
                 else "finished" if self.ok else "failed")
        numbers = scene_numbers(self.sim_verdict)
        text = (f"scene {state} in {self.wall:.1f} s" + (f" ({numbers})" if numbers else "")
                + f": exit status sim_node={self.sim} controller_node={self.controller}")
        if self.recorder is not None:
            text += f" recorder_node={self.recorder}; bag {self.bag_dir}"
        if self.lost:
            text += f"; the recording lost messages: {self.lost}"
        if self.live is not None:
            text += f"; live_node={self.live}"
        if self.domain_id is not None:
            text += f"; ROS_DOMAIN_ID={self.domain_id}"
        if self.logs:
            text += f"; logs in {Path(next(iter(self.logs.values()))).parent}"
        if self.reason and not self.ok:
            text += f"; reason: {self.reason}"
        return text

    @property
    def exit_code(self) -> int:
        """0 if ok, 130 if interrupted, else 1: what a command returns."""
        return 0 if self.ok else 130 if self.interrupted else 1

    @property
    def ok(self) -> bool:
        """The simulator finished, no node left before it (a controller stopped by a
        SIGTERM of its own exits 0, and the simulator, stopped with it, exits 0 with its
        summary marked '(interrupted)': a scene of 0 of 3000 periods, said "finished"
        with status 0 before), and every node exited with status 0."""
        codes = [self.sim, self.controller] + ([self.recorder] if self.recorder is not None
                                               else [])
        codes += [self.live] if self.live is not None else []
        return (not (self.timed_out or self.interrupted or self.lost or self.early)
                and all(c == 0 for c in codes))


class ParamText(str):
    """A ``-p`` value as typed on a command line (``--sim-param k:=v``): passed verbatim,
    rcl types it (as ``ros2 run`` would)."""


def format_value(value) -> str:
    """A parameter value as ``-p key:=value`` text that rcl parses back to the same type."""
    if isinstance(value, ParamText):
        return str(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        text = repr(value)
        return text if ("." in text or "e" in text) else text + ".0"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    text = str(value)
    if isinstance(value, str) and _typed_as_other(text):
        return "'" + text.replace("'", "''") + "'"    # '0', 'true', '1e-3' stay strings
    return text


def _typed_as_other(text: str) -> bool:
    """Whether rcl would read ``-p name:=text`` as something other than a string."""
    try:
        float(text)
        return True           # rcl reads 1e-3 as a double (YAML 1.1 would not)
    except ValueError:
        pass
    return text == "" or not isinstance(yaml.safe_load(text), str)


#: Runs a node module as ``python -m`` does, with a SIGINT that ends the process quietly
#: (status 130) until the node installs its own handlers (a Ctrl-C while Python is still
#: importing would otherwise print a KeyboardInterrupt traceback), and a SIGTERM when the
#: launcher dies (Linux PR_SET_PDEATHSIG; exits at once if the launcher is already gone).
#: Set here, after exec, rather than in a ``preexec_fn``: Python code between fork and
#: exec would run in the launcher's process group and could print the traceback of a
#: Ctrl-C that reaches it there.
BOOTSTRAP = ("import os, runpy, signal, sys; "
             "signal.signal(signal.SIGINT, lambda s, f: os._exit(130)); "
             "parent = int(os.environ.pop('GRAZING_LAUNCHER_PID', '0')); "
             "exec('try:\\n import ctypes; ctypes.CDLL(None).prctl(1, 15)\\n"
             "except Exception: pass') if parent else None; "
             "os._exit(143) if parent and os.getppid() != parent else None; "
             "runpy.run_module(sys.argv.pop(1), run_name='__main__', alter_sys=True)")

#: Largest ROS_DOMAIN_ID: Fast DDS's ports (7400 + 250 d + 11 + 2 i) must stay below 65536.
MAX_DOMAIN_ID = 232


def check_domain_id(domain_id) -> int:
    """A valid ROS_DOMAIN_ID (0..232) as int, else ValueError naming the range."""
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or not (
            0 <= domain_id <= MAX_DOMAIN_ID):
        raise ValueError(f"domain_id={domain_id!r} is invalid: valid range is 0..{MAX_DOMAIN_ID} "
                         "(Fast DDS on Linux)")
    return domain_id


def _discovery_port_free(domain_id: int) -> bool:
    """Whether no DDS participant of this host uses ``domain_id`` (participant 0's port)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            sock.bind(("0.0.0.0", 7410 + 250 * domain_id))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return False
            raise
    return True


def claim_domain(exclude=()):
    """A ROS_DOMAIN_ID free on this host, and the lock that keeps it ours.

    Tries the ids 1..232 (without ``exclude`` and the environment's ROS_DOMAIN_ID) in a
    random order; an id is free when no other scene of this machine holds its lock file
    (``<tmp>/grazing_control_domains/<id>.lock``, flock) and no DDS participant of this
    host uses it. Returns ``(domain_id, lock file)``; close the file to release it.
    Raises RuntimeError if every id is taken.
    """
    folder = Path(tempfile.gettempdir()) / "grazing_control_domains"
    folder.mkdir(exist_ok=True)
    skip = set(exclude)
    env = os.environ.get("ROS_DOMAIN_ID", "").strip()
    skip.add(int(env) if env.isdigit() else 0)
    ids = [d for d in range(1, MAX_DOMAIN_ID + 1) if d not in skip]
    random.SystemRandom().shuffle(ids)
    for d in ids:
        lock = open(folder / f"{d}.lock", "a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        if _discovery_port_free(d):
            return d, lock
        lock.close()
    raise RuntimeError("no free ROS_DOMAIN_ID on this host: give one with --domain-id")


def node_command(module: str, params_files=(), overrides=None, python: str | None = None) -> list:
    """``python -c BOOTSTRAP module --ros-args --params-file F ... -p key:=value ...``.

    The same as ``python -m module ...`` (:data:`BOOTSTRAP`), quiet on an early Ctrl-C.
    """
    cmd = [python or sys.executable, "-c", BOOTSTRAP, module, "--ros-args"]
    for f in params_files:
        cmd += ["--params-file", os.fspath(f)]
    for key, value in (overrides or {}).items():
        cmd += ["-p", f"{key}:={format_value(value)}"]
    return cmd


#: The nodes' Fast DDS profile: a reliable writer's heartbeat every 5 ms, so that the
#: acknowledgements a node waits for at exit (ros/published.py) come in milliseconds,
#: not at Fast DDS's 3 s heartbeat (issue 30: 2.2 s of a scene's end on average).
FASTDDS_PROFILE = Path(__file__).with_name("fastdds_profile.xml")


#: A node computes on small matrices (2 x 2 to 200 x 2) one section at a time: a BLAS
#: thread pool only adds wake-ups, and on a loaded 2-core machine its spinning threads cost
#: more than the work (tests/test_identification.py: 21.4 s with OpenBLAS's default
#: threads against 8.8 s with one, at load 5-8).
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def use_profile_here() -> None:
    """Give this process's own participants (a replay's session, a test's node) the
    nodes' Fast DDS profile (:data:`FASTDDS_PROFILE`), unless the environment names
    one. Fast DDS reads it once, at the process's first participant: call this before.
    Without it a reliable writer of this process asks for acknowledgements every 3 s,
    and a replay that waits for one (recordings/stream_replay.py) waited that long."""
    _with_profile(os.environ)


def _with_profile(env) -> None:
    """:data:`FASTDDS_PROFILE` as Fast DDS's default profile in ``env`` (a mapping),
    unless it names one already (FASTDDS_DEFAULT_PROFILES_FILE, or the older
    FASTRTPS_DEFAULT_PROFILES_FILE)."""
    if not (env.get("FASTDDS_DEFAULT_PROFILES_FILE")
            or env.get("FASTRTPS_DEFAULT_PROFILES_FILE")) and FASTDDS_PROFILE.is_file():
        # Fast DDS 2 (ROS 2 Jazzy) reads the FASTRTPS_ name, Fast DDS 3 the FASTDDS_ one
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(FASTDDS_PROFILE)
        env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(FASTDDS_PROFILE)


def node_env(domain_id: int | None = None) -> dict:
    """Environment of a node: ours, the source root on PYTHONPATH, the domain if given,
    :data:`FASTDDS_PROFILE` as Fast DDS's default profile unless ours names one
    (FASTDDS_DEFAULT_PROFILES_FILE, or the older FASTRTPS_DEFAULT_PROFILES_FILE), and
    one BLAS thread unless ours sets them (:data:`BLAS_THREADS`)."""
    env = dict(os.environ)
    for name in BLAS_THREADS:
        env.setdefault(name, "1")
    _with_profile(env)
    paths = [str(SOURCE_ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    env["PYTHONUNBUFFERED"] = "1"
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    return env


def start_node(module: str, params_files=(), overrides=None, *, domain_id=None, log=None,
               python=None, command=None) -> subprocess.Popen:
    """Start one node process; its output goes to ``log`` (a path) or is inherited.

    The node gets a process group of its own, so that the terminal's Ctrl-C reaches only
    the launcher, which stops the nodes with SIGTERM (:func:`stop_nodes`): a SIGINT
    while a node's Python is still starting would print a traceback, a SIGTERM ends it
    quietly. The node is sent SIGTERM if the launcher dies (killed with SIGKILL).
    ``command``: this command line instead of the node's (the composed scene).
    With ``GRAZING_NODE_ZYGOTE=1`` in the environment the node is forked from a process
    that has already imported it (:mod:`.node_zygote`; the test suite), else spawned.
    A Ctrl-C (SIGINT, or SIGTERM) while the node starts is acted on once it has: the
    node is stopped (:func:`stop_nodes`) and KeyboardInterrupt raised, so that it never
    outlives a caller that did not get its handle (:func:`interrupts_held`).
    """
    out = open(log, "wb") if log is not None else None
    command = command or node_command(module, params_files, overrides, python)
    env = dict(node_env(domain_id), GRAZING_LAUNCHER_PID=str(os.getpid()))
    streams = dict(stdin=subprocess.DEVNULL, stdout=out,
                   stderr=subprocess.STDOUT if out else None)
    try:
        with interrupts_held() as held:
            proc = _spawn_node(command, env, streams)
    finally:
        if out is not None:
            out.close()
    if held:        # a Ctrl-C while it started: the node it made does not outlive it
        stop_nodes([proc])
        raise KeyboardInterrupt
    return proc


def _spawn_node(command, env: dict, streams: dict):
    """The node process of ``command``: forked from the zygote where there is one
    (:mod:`.node_zygote`), else spawned in a process group of its own."""
    if command[1:3] == ["-c", BOOTSTRAP]:
        zygote = node_zygote.owner_zygote(node_env(), MODULES.values())
        forked = zygote.spawn(command, env, **streams) if zygote else None
        if forked is not None:
            return forked
    return subprocess.Popen(command, env=env, process_group=0, **streams)


@contextlib.contextmanager
def interrupts_held():
    """SIGINT and SIGTERM held (yields the list of those that came) while a node process
    starts, for :func:`start_node` to act on once it has the node's handle. Raised
    inside ``subprocess.Popen`` (its wait for the exec) or the zygote's reply, after the
    node existed but before its handle came back, the KeyboardInterrupt left a node that
    nobody stopped or waited for: a Ctrl-C right at the start of ``grazing run``, or of
    a replay (tests/test_launcher.py). Off the main thread (where signals cannot be
    handled) it holds nothing."""
    held, previous = [], {}
    if threading_is_main():
        for sig in (signal.SIGINT, signal.SIGTERM):
            if signal.getsignal(sig) is not None:    # None: a handler not set from Python
                previous[sig] = signal.signal(sig, lambda signum, frame: held.append(signum))
    try:
        yield held
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def recorded_status(bag_dir) -> int | None:
    """The recorder's exit status from its closed record, or None if it has none.

    The recorder writes its status (0, or 1 for missed messages with
    ``require_complete``) into ``metadata.yaml``'s ``custom_data`` as the last step of
    closing the bag (ros/recorder_node.py, ``RecorderNode.close``): a bag with that
    record is complete whatever happened to the process after it.
    """
    from grazing_control.support.files import read_yaml_file

    try:
        info = read_yaml_file(Path(bag_dir) / "metadata.yaml")["rosbag2_bagfile_information"]
        return int((info.get("custom_data") or {})["recorder_status"])
    except (KeyError, TypeError, ValueError, AttributeError):      # YamlFileError too
        return None


def recorded_losses(bag_dir) -> str:
    """What the recorder missed, from its closed record (``custom_data:
    recorder_missed``, "topic n, ..."), or "" (none, or no closed record)."""
    try:
        text = (Path(bag_dir) / "metadata.yaml").read_text(encoding="utf-8")
        info = yaml.safe_load(text)["rosbag2_bagfile_information"]
        return str((info.get("custom_data") or {}).get("recorder_missed", ""))
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return ""


def stop_nodes(procs, grace: float = 15.0) -> None:
    """SIGTERM every running process, wait ``grace`` s, then SIGKILL.

    The nodes handle SIGTERM as SIGINT (the summary is logged, the recorder closes its
    bag); before a node has installed its handlers, SIGTERM ends it without a traceback.
    """
    procs = [p for p in procs if p is not None]
    for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 5.0)):
        alive = [p for p in procs if p.poll() is None]
        if not alive:
            return
        for p in alive:
            try:
                p.send_signal(sig)
            except ProcessLookupError:
                pass
        end = time.monotonic() + wait
        for p in alive:
            try:
                p.wait(max(0.0, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass


def _params_file(params, node: str, tmp: Path) -> Path:
    """A parameter file: a path as is, a dict written as ``/**: ros__parameters: {...}``."""
    if isinstance(params, (str, os.PathLike)):
        return Path(params)
    path = tmp / f"{node}.yaml"
    values = {k: (float(v) if isinstance(v, float) else v) for k, v in dict(params).items()}
    with open(path, "w") as fh:
        yaml.safe_dump({"/**": {"ros__parameters": values}}, fh, sort_keys=False)
    return path


def run(sim_params=None, controller_params=None, bag_dir=None, periods: int | None = None, *,
        delta_d: float | None = None, enable_after: int | None = None,
        mode: str | None = None, domain_id: int | None = None, timeout: float | None = None,
        sim_overrides: dict | None = None, controller_overrides: dict | None = None,
        recorder_overrides: dict | None = None, log_dir=None,
        python: str | None = None, live: int | None = None, model=None,
        rig=None, compose: bool = False) -> RunResult:
    """Run one scene through the three node processes and wait for it to finish.

    Parameters
    ----------
    sim_params : dict or path, optional
        The simulator's parameters: a ROS parameter file (``/sim_node: ros__parameters``)
        or a dict of values (floats must be floats); default config/study.yaml.
    controller_params : dict or path, optional
        The controller's parameter file (``grazing design --out``) or a dict; default
        config/controller.yaml (c2 = -1, c1 from the degenerate condition). Its
        ``actuation_delay`` (``grazing design --delay``) is passed to the simulator as
        its ``actuation_delay`` unless ``sim_overrides`` sets one.
    bag_dir : path, optional
        Record the scene to this rosbag2-style directory (must not exist or be empty);
        None: no recorder. Skipped with a warning if the recorder node is not available.
    periods : int, optional
        Forcing periods to simulate (``max_periods``); None: the parameter file's value
        (which must be > 0 for the scene to end).
    delta_d, enable_after, mode : optional
        Shortcuts for the simulator's ``delta_d`` and ``mode`` and the controller's
        ``enable_after`` (first controlled sample).
    domain_id : int, optional
        ROS_DOMAIN_ID of the processes, 0..232; default: a free one claimed for the run
        (:func:`claim_domain`), so that two scenes never share their topics.
    timeout : float, optional
        Wall seconds (finite, > 0) to wait for the simulator; then every node is stopped
        and the result has ``timed_out=True``.
    sim_overrides, controller_overrides, recorder_overrides : dict, optional
        Extra ``-p key:=value`` for each node (e.g. ``{"state_period": 0.0}``); a value
        given as text is passed as is (``"-5.0e-06"``), see :func:`format_value`.
    log_dir : path, optional
        Write each node's output to ``<log_dir>/<node>.log`` instead of the terminal.
    python : str, optional
        Interpreter for the nodes (default: this one).
    live : int, optional
        Start ``live_node`` (docs/live.md) with this WebSocket port (0..65535, 0: any
        free port, logged): a live view for Foxglove/Lichtblick that the scene does not
        wait for. None: no live view.
    model : path, optional
        An n-DOF model file (docs/ndof_model.md; issue 17): both nodes get it as
        ``model_file``; default: the ``model_file`` of the controller's parameters (an
        n-DOF design's gain file), else none (the study's 1-DOF scene). The controller's
        parameters must then give ``gains`` (required),
        and the simulator's parameter file is used without its 1-DOF model parameters
        (zeta, r, omega, delta_d, tau0, pi2_offset: the model file's delta_d applies
        unless ``delta_d`` is given).
    rig : path, optional
        A rig file (docs/rig.md; issue 28): a simulated rig in SI at physical speed
        (docs/rig_scene.md). Both nodes get it as ``rig_file``: the simulator is the rig's
        driver (docs/driver_contract.md), realtime; the controller estimates each section
        from ``rig/sensor`` and answers with ``rig/force_pulse``, its model, sensor and
        gains from the rig (``--controller-param rig_c2:=C2``; default the c2 of least
        noise gain); the recorder also records the contract's topics. The simulator's
        parameter file is used without what the rig sets, and no controller file is
        needed (default: none).
    compose : bool, optional
        Run the simulator, the controller and the recorder in one process on one
        executor (:mod:`.composed`; docs/nodes.md, "Composed scene"): one interpreter's
        start-up instead of three, the messages between them delivered in the process.
        Their logs are one file (``<log_dir>/composed.log``, each line names its node);
        ``live_node`` stays a process of its own. Default False: a process per node.

    Returns
    -------
    RunResult
        Exit statuses (sim, controller, recorder), wall time, flags.
    """
    t0 = time.monotonic()
    if domain_id is not None:
        check_domain_id(domain_id)
    if timeout is not None and not (isinstance(timeout, (int, float)) and timeout > 0
                                    and math.isfinite(timeout)):
        raise ValueError(f"timeout={timeout!r} is invalid: valid range is a finite "
                         "number of seconds > 0 (None: no timeout)")
    if model is None and controller_params is not None:
        model = design_model(controller_params)    # the model the gains were designed for
    if model is not None:
        if controller_params is None:
            raise ValueError(f"model={os.fspath(model)!r} needs the controller's gains: give "
                             "controller parameters with gains (2n values; grazing run "
                             "--controller-params GAINS.yaml)")
        # the scene settings of the simulator's file, not its 1-DOF model
        sim_params = sim_values_for_model(CONFIG_DIR / "study.yaml" if sim_params is None
                                          else sim_params)
    if rig is not None:
        if model is not None:
            raise ValueError(f"rig={os.fspath(rig)!r} is invalid with model: a rig file "
                             "gives the model (Rig.model() for n masses); give one of them")
        sim_params = sim_values_for_rig(CONFIG_DIR / "study.yaml" if sim_params is None
                                        else sim_params)
        controller_params = {} if controller_params is None else controller_params
    sim_params = CONFIG_DIR / "study.yaml" if sim_params is None else sim_params
    controller_params = (CONFIG_DIR / "controller.yaml" if controller_params is None
                         else controller_params)
    record = bag_dir is not None
    if record and importlib.util.find_spec(RECORDER_MODULE) is None:
        print(f"warning: {RECORDER_MODULE} is not available: running without recording",
              file=sys.stderr)
        record = False
    logs = {}
    if log_dir is not None:
        Path(log_dir).mkdir(parents=True, exist_ok=True)
        names = ("sim_node", "controller_node") + (("recorder_node",) if record else ())
        names += ("live_node",) if live is not None else ()
        logs = {n: str(Path(log_dir) / f"{n}.log") for n in names}
        if compose:
            logs.update({n: str(Path(log_dir) / "composed.log") for n in names
                         if n != "live_node"})
    over = scene_overrides(controller_params, periods=periods, delta_d=delta_d,
                           enable_after=enable_after, mode=mode,
                           bag=bag_dir if record else None, sim_overrides=sim_overrides,
                           controller_overrides=controller_overrides,
                           recorder_overrides=recorder_overrides, model=model, live=live,
                           rig=rig)
    sim_over, controller_overrides = over["sim_node"], over["controller_node"]
    procs = {"sim_node": None, "controller_node": None, "recorder_node": None,
             "live_node": None}
    timed_out = interrupted = False
    early = []
    verdict = None
    statuses = None         # the composed process's {node: status}

    def on_term(signum, frame):
        raise KeyboardInterrupt

    previous = None
    if threading_is_main():
        previous = signal.signal(signal.SIGTERM, on_term)
    lock = None
    if domain_id is None:
        domain_id, lock = claim_domain()
    with tempfile.TemporaryDirectory(prefix="grazing_run_") as tmp:
        tmp = Path(tmp)
        verdict_file = tmp / "sim_node.verdict.json"     # how the scene ended (reason)
        if "verdict_file" not in sim_over:
            sim_over = {**sim_over, "verdict_file": str(verdict_file)}
        try:
            if compose:
                statuses_file = tmp / "composed.statuses.json"
                spec = {"sim_node": _ros_args(SIM_MODULE, sim_params, sim_over, tmp,
                                              "sim_node"),
                        "controller_node": _ros_args(CONTROLLER_MODULE, controller_params,
                                                     controller_overrides, tmp,
                                                     "controller_node"),
                        "recorder_node": (_ros_args(RECORDER_MODULE, None,
                                                    over["recorder_node"], tmp, None)
                                          if record else None)}
                (tmp / "composed.json").write_text(json.dumps(spec), encoding="utf-8")
            if record and not compose:
                procs["recorder_node"] = start_node(
                    RECORDER_MODULE, (), over["recorder_node"], domain_id=domain_id,
                    log=logs.get("recorder_node"), python=python)
            if live is not None:
                procs["live_node"] = start_node(LIVE_MODULE, (), over["live_node"],
                                                domain_id=domain_id, log=logs.get("live_node"),
                                                python=python)
            if compose:
                procs["sim_node"] = start_node(
                    COMPOSED_MODULE, domain_id=domain_id, log=logs.get("sim_node"),
                    command=[python or sys.executable, "-c", BOOTSTRAP, COMPOSED_MODULE,
                             "--spec", str(tmp / "composed.json"),
                             "--statuses", str(statuses_file)])
            else:
                procs["controller_node"] = start_node(
                    CONTROLLER_MODULE,
                    [_params_file(controller_params, "controller_node", tmp)],
                    controller_overrides, domain_id=domain_id,
                    log=logs.get("controller_node"), python=python)
                procs["sim_node"] = start_node(
                    SIM_MODULE, [_params_file(sim_params, "sim_node", tmp)], sim_over,
                    domain_id=domain_id, log=logs.get("sim_node"), python=python)
            sim = procs["sim_node"]
            end = None if timeout is None else t0 + timeout
            while sim.poll() is None:
                if end is not None and time.monotonic() > end:
                    timed_out = True
                    break
                early = [n for n in ("controller_node", "recorder_node", "live_node")
                         if procs[n] is not None and procs[n].poll() is not None]
                if early:
                    for name in early:
                        print(f"warning: {name} exited early with status "
                              f"{procs[name].returncode}: stopping the scene", file=sys.stderr)
                    break
                try:
                    sim.wait(0.1)
                except subprocess.TimeoutExpired:
                    pass
        except KeyboardInterrupt:
            interrupted = True
        finally:
            try:
                # the simulator first (it has ended, or is stopped), then the others at
                # once: a node that stops says what it published and waits for the
                # recorder's confirmation, and the recorder, stopped, takes messages
                # until every node that sent a parameter record has said what it
                # published (recorder_node.settle), then closes; one after the other
                # they added a node's stop to the scene's end (issue 30)
                stop_nodes([procs["sim_node"]])
                stop_nodes([procs["controller_node"], procs["recorder_node"],
                            procs["live_node"]])
            except KeyboardInterrupt:
                interrupted = True
                stop_nodes(list(procs.values()), grace=2.0)
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)
            if lock is not None:
                lock.close()
            verdict = read_verdict(Path(sim_over["verdict_file"]))
            if compose:
                statuses = _composed_statuses(statuses_file, procs["sim_node"], record)

    def code(name):
        if statuses is not None and name in statuses:
            return statuses[name]
        p = procs[name]
        return None if p is None else p.returncode

    recorder = code("recorder_node")
    closed = recorded_status(bag_dir) if record else None
    if recorder is not None and recorder < 0 and closed is not None:
        # killed after it closed its bag (teardown past the grace under CPU starvation):
        # the bag's own closed record says how the recording ended
        print(f"warning: recorder_node was killed (signal {-recorder}) after closing its "
              f"bag; its closed record says status {closed}", file=sys.stderr)
        recorder = closed
    lost = recorded_losses(bag_dir) if record else ""
    if lost:
        print(f"error: the recording {os.fspath(bag_dir)} lost messages: {lost} (published "
              "by the nodes, not in the bag)", file=sys.stderr)
    res = RunResult(sim=code("sim_node"), controller=code("controller_node"),
                    recorder=recorder,
                    bag_dir=os.fspath(bag_dir) if record else None,
                    wall=time.monotonic() - t0, timed_out=timed_out, interrupted=interrupted,
                    logs=logs, domain_id=domain_id, live=code("live_node"),
                    sim_verdict=verdict, lost=lost, early=tuple(early))
    res.reason = None if res.ok else failure_reason(res, timeout=timeout)
    return res


#: The module that runs a scene's nodes in one process (``run(..., compose=True)``).
COMPOSED_MODULE = "grazing_control.ros.composed"


def _ros_args(module: str, params, overrides, tmp: Path, node: str | None) -> list:
    """A node's ``--ros-args ...`` as its process would get them (:func:`node_command`),
    for the composed process (:mod:`.composed`)."""
    files = [] if params is None else [_params_file(params, node, tmp)]
    return node_command(module, files, overrides)[4:]


def _composed_statuses(path: Path, proc, record: bool) -> dict:
    """{node: exit status} of a composed scene: what its process wrote, else (it was
    killed, or never got that far) the process's own status for each node."""
    try:
        statuses = json.loads(path.read_text(encoding="utf-8"))
        if isinstance(statuses, dict):
            return statuses
    except (OSError, ValueError):
        pass
    code = None if proc is None else proc.returncode
    names = ("sim_node", "controller_node") + (("recorder_node",) if record else ())
    return {name: code for name in names}


def threading_is_main() -> bool:
    """Signal handlers can only be installed from the main thread."""
    import threading

    return threading.current_thread() is threading.main_thread()


def run_scene(p, controller_params=None, bag_dir=None, periods: int = 1300,
              enable_after: int = 1000, **kwargs) -> RunResult:
    """Run the scene of a model ``p`` (OscillatorParams) in lockstep; raise if it fails.

    The study's parameter file with ``p``'s model parameters over it; ``kwargs`` go to
    :func:`run`. Raises RuntimeError (with the simulator's last log lines when logs were
    kept) unless every node finished with status 0.
    """
    over = {k: float(getattr(p, k)) for k in ("zeta", "r", "omega", "delta_d", "tau0",
                                               "pi2_offset")}
    over.update(kwargs.pop("sim_overrides", None) or {})
    res = run(None, controller_params, bag_dir, periods, enable_after=enable_after,
              mode="lockstep", sim_overrides=over, **kwargs)
    if not res.ok:
        detail = ""
        if res.logs.get("sim_node") and Path(res.logs["sim_node"]).is_file():
            lines = Path(res.logs["sim_node"]).read_text(errors="replace").splitlines()
            detail = "\n" + "\n".join(lines[-5:])
        raise RuntimeError(f"{res}{detail}")
    return res

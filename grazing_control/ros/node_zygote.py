"""Node processes forked from one that has already imported them (a zygote), on request.

Each node process pays for its imports before it does anything: numpy, numba and the
compiled kernels' cache, rclpy and the package, 0.4-0.55 s of CPU a node (measured on
this 2-core machine, ``python -c "import grazing_control.ros.controller_node"``: 0.54
CPU-s; sim_node 0.55, recorder_node 0.38). The test suite starts about six hundred
nodes, and on two cores its time is CPU time (issue 30). A zygote is a process that
imports what the node modules import (rclpy and the message types' C type supports
included), loads the compiled kernels, and then forks one child per node: the child runs
the node's module as ``python -m`` does, over the imports it shares with the zygote
copy-on-write. The threads that rclpy's C library starts (the LTTng tracer's listeners)
are forked around with the tracer's own fork protocol (:class:`TracerForkHooks`).

What the child is, as seen from its owner (the process that asked: the launcher of
``grazing run``, a test): the same as the process :func:`launcher.start_node` spawns.
- It is the owner's child. The zygote forks twice and the middle process exits, so the
  node is reparented to the nearest "child subreaper" above it (Linux prctl
  PR_SET_CHILD_SUBREAPER), which the owner makes itself before it starts its zygote;
  the owner waits for it, signals it and reads its status as for any child
  (:class:`ForkedNode`, the part of ``subprocess.Popen`` that the launcher and the tests
  use). The node reports its pid only once its parent is the owner.
- Its process group, its fds 0-2 (passed over the zygote's socket, SCM_RIGHTS), its
  working folder, its environment (``os.environ`` replaced by the request's), its
  SIGINT handling and its PR_SET_PDEATHSIG are those of :data:`launcher.BOOTSTRAP`;
  its command line (``ps``, /proc/PID/cmdline) is the node's command, written over the
  zygote's (:func:`_set_command_line`).
- Its module runs as ``python -m`` runs it: removed from ``sys.modules`` first (the
  zygote imported it only for what it imports), ``__main__``, ``sys.argv`` its own, and
  the interpreter's normal exit (threads joined, ``atexit``, streams flushed).

The zygote refuses (and the owner spawns the node as before) whatever it cannot make
identical: an environment that differs from the zygote's own in a variable read at
import time (anything but :data:`LATE_VARIABLES`), another interpreter, a zygote with a
second thread (a fork copies only the calling thread). It is used where the owner's
environment says ``GRAZING_NODE_ZYGOTE=1`` (the test suite sets it, tests/conftest.py);
without it every node is spawned as before.
"""

from __future__ import annotations

import array
import atexit
import ctypes
import gc
import importlib
import inspect
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

__all__ = ["ENABLE", "LATE_VARIABLES", "ForkedNode", "NodeZygote", "dependencies", "enable",
           "owner_zygote"]

#: The environment variable that turns the zygote on for a process and its children.
ENABLE = "GRAZING_NODE_ZYGOTE"

#: Variables that no library reads before a node runs (rcl reads the ROS ones at
#: ``rclpy.init``, Fast DDS its profile when the participant is made, the bootstrap the
#: launcher's pid, pytest its current test): a request may differ from the zygote in
#: these. Any other difference is refused.
LATE_VARIABLES = frozenset({
    "ROS_DOMAIN_ID", "ROS_LOCALHOST_ONLY", "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_STATIC_PEERS", "ROS_LOG_DIR", "ROS_HOME", "RMW_IMPLEMENTATION",
    "RCUTILS_CONSOLE_OUTPUT_FORMAT", "RCUTILS_COLORIZED_OUTPUT",
    "RCUTILS_LOGGING_BUFFERED_STREAM", "RCUTILS_LOGGING_USE_STDOUT",
    "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
    "GRAZING_LAUNCHER_PID", "PYTEST_CURRENT_TEST", "PYTEST_XDIST_WORKER", ENABLE})

#: Wall seconds the owner waits for the zygote's imports, and for one node's pid.
START_TIMEOUT = 120.0
SPAWN_TIMEOUT = 30.0

#: The zygote's working folder, which ``-m`` put first on its ``sys.path``.
_STARTED_IN = os.getcwd()

_PR_SET_PDEATHSIG = 1
_PR_SET_CHILD_SUBREAPER = 36
_MAX_MESSAGE = 1 << 20


# ------------------------------------------------------------------ the wire

def _send(sock: socket.socket, message: dict, fds=()) -> None:
    data = json.dumps(message).encode()
    header = struct.pack("!I", len(data))
    ancillary = ([(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", fds))]
                 if fds else [])
    sock.sendmsg([header + data], ancillary)


def _receive(sock: socket.socket, max_fds: int = 0):
    """One message and the fds that came with it; (None, []) at the end of the stream."""
    size = socket.CMSG_SPACE(max_fds * array.array("i").itemsize) if max_fds else 0
    data, ancillary, _, _ = sock.recvmsg(4, size)
    while 0 < len(data) < 4:
        more = sock.recv(4 - len(data))
        if not more:
            break
        data += more
    fds = []
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
            got = array.array("i")
            got.frombytes(payload[:len(payload) - len(payload) % got.itemsize])
            fds += list(got)
    if len(data) < 4:
        for fd in fds:
            os.close(fd)
        return None, []
    (length,) = struct.unpack("!I", data)
    if length > _MAX_MESSAGE:
        raise OSError(f"zygote message of {length} bytes")
    body = b""
    while len(body) < length:
        chunk = sock.recv(length - len(body))
        if not chunk:
            return None, fds
        body += chunk
    return json.loads(body), fds


# ------------------------------------------------------------------ the owner's side

class ForkedNode:
    """A node forked by the zygote, reparented to its owner: ``pid``, ``args``,
    ``returncode`` and ``poll``/``wait``/``send_signal``/``terminate``/``kill`` as
    ``subprocess.Popen`` has them (its streams are files, never pipes)."""

    stdin = stdout = stderr = None

    def __init__(self, pid: int, args):
        self.pid = pid
        self.args = args
        self.returncode = None

    def __repr__(self):
        return f"<ForkedNode: returncode: {self.returncode} args: {self.args[:4]!r}>"

    def poll(self):
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:      # reaped elsewhere: as Popen, status unknown
                self.returncode = 0
            else:
                if pid == self.pid:
                    self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout=None):
        if timeout is None and self.returncode is None:
            try:
                _, status = os.waitpid(self.pid, 0)
            except ChildProcessError:
                self.returncode = 0
            else:
                self.returncode = os.waitstatus_to_exitcode(status)
            return self.returncode
        end = None if timeout is None else time.monotonic() + timeout
        delay = 0.0005
        while self.poll() is None:
            if end is not None and time.monotonic() >= end:
                raise subprocess.TimeoutExpired(self.args, timeout)
            time.sleep(delay if end is None else min(delay, max(0.0, end - time.monotonic())))
            delay = min(delay * 2, 0.05)
        return self.returncode

    def send_signal(self, sig):
        if self.poll() is not None:
            return
        try:
            os.kill(self.pid, sig)
        except ProcessLookupError:
            pass

    def terminate(self):
        self.send_signal(signal.SIGTERM)

    def kill(self):
        self.send_signal(signal.SIGKILL)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.wait()


class NodeZygote:
    """The owner's handle on its zygote process (:func:`owner_zygote` makes one)."""

    def __init__(self, env: dict, modules):
        _prctl(_PR_SET_CHILD_SUBREAPER, 1)
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        self.env = {k: v for k, v in env.items() if k not in LATE_VARIABLES}
        self._lock = threading.Lock()
        self._sock = ours
        self.broken = False
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", __name__, str(theirs.fileno()), str(os.getpid()),
                 *modules, _PADDING],
                env=self.env, stdin=subprocess.DEVNULL, pass_fds=(theirs.fileno(),),
                process_group=0)    # a terminal's Ctrl-C is the owner's, not the zygote's
        finally:
            theirs.close()
        ours.settimeout(START_TIMEOUT)
        reply, _ = _receive(ours)
        if not reply or not reply.get("ready"):
            self.close()
            raise OSError(f"the node zygote did not start: {reply}")
        ours.settimeout(SPAWN_TIMEOUT)

    def spawn(self, command, env: dict, *, stdin=None, stdout=None, stderr=None, cwd=None):
        """Fork the node of ``command`` (a :func:`launcher.node_command` list); None if the
        zygote refuses it (then spawn it as before). ``stdin``/``stdout``/``stderr``:
        None (the owner's), ``subprocess.DEVNULL``, ``subprocess.STDOUT`` (stderr only) or
        an fd or file object."""
        module, args = command[3], list(command[4:])
        if command[0] != sys.executable:
            return None
        differs = sorted(k for k in set(env) | set(self.env)
                         if k not in LATE_VARIABLES and env.get(k) != self.env.get(k))
        if differs:
            return None
        opened, fds = [], []
        try:
            for which, given in ((0, stdin), (1, stdout), (2, stderr)):
                if given is None:
                    fds.append(which)
                elif given == subprocess.DEVNULL:
                    fd = os.open(os.devnull, os.O_RDWR)
                    opened.append(fd)
                    fds.append(fd)
                elif given == subprocess.STDOUT and which == 2:
                    fds.append(fds[1])
                elif isinstance(given, int) and given >= 0:
                    fds.append(given)
                elif hasattr(given, "fileno"):
                    fds.append(given.fileno())
                else:
                    return None                 # pipes: not offered
            message = {"module": module, "args": args, "env": env, "cwd": cwd,
                       "command": [os.fspath(c) for c in command]}
            with self._lock:
                if self.broken:
                    return None
                try:
                    _send(self._sock, message, fds)
                    reply, _ = _receive(self._sock)
                except (OSError, ValueError):
                    reply = None
                if not reply:               # no answer: the stream is out of step
                    self.broken = True
                    return None
            if "pid" not in reply:
                return None
            return ForkedNode(int(reply["pid"]), list(command))
        finally:
            for fd in opened:
                os.close(fd)

    def close(self, grace: float = 5.0):
        """End the zygote: its socket closed (it exits at the end of the stream), and
        killed if it has not exited ``grace`` s later."""
        try:
            self._sock.close()
        finally:
            try:
                self.proc.wait(grace)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


_owned: dict = {}
_enabled = False


def enable() -> None:
    """Use a zygote in this process (not in the processes it starts), as
    ``GRAZING_NODE_ZYGOTE=1`` does for a process and its children (tests/conftest.py)."""
    global _enabled
    _enabled = True


def owner_zygote(env: dict, modules) -> NodeZygote | None:
    """This process's zygote, started on first use if :func:`enable` was called or
    ``GRAZING_NODE_ZYGOTE=1`` is in its environment; None if off, not on Linux, or if it
    failed to start (then not tried again: every node is spawned as before)."""
    if not (_enabled or os.environ.get(ENABLE) == "1") or not sys.platform.startswith("linux"):
        return None
    key = os.getpid()                      # a forked owner has a zygote of its own
    if key not in _owned:
        try:
            _owned[key] = NodeZygote(env, modules)
            atexit.register(_end_with_owner, key)
        except (OSError, ValueError) as exc:
            print(f"warning: node zygote off: {exc}", file=sys.stderr)
            _owned[key] = None
    zygote = _owned[key]
    return None if zygote is None or zygote.broken else zygote


def _end_with_owner(owner: int) -> None:
    """At its owner's exit the zygote ends and is waited for. Left to its
    PR_SET_PDEATHSIG, it was still exiting when its owner had gone, and was reparented
    to the child subreaper above (the test worker whose ``grazing run`` had started it:
    its check for processes left behind caught it, once in a few suites). It holds
    nothing to save: the nodes are the owner's children, and it only forks them."""
    zygote = _owned.get(owner)
    if zygote is not None and os.getpid() == owner:    # (not a process forked from it)
        zygote.close(grace=0.0)


# ------------------------------------------------------------------ the zygote's side

#: An argument that reserves room in the zygote's command line for a node's
#: (:func:`_set_command_line`).
_PADDING = "-" * 8192


def _prctl(option: int, value: int) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(option, value, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), f"prctl({option}, {value})")


def _set_command_line(command) -> None:
    """Write ``command`` over this process's original argv, the memory that ``ps`` and
    /proc/PID/cmdline show (its bounds: fields 48-49 of /proc/self/stat), NUL-padded;
    cut at the zygote's own length (:data:`_PADDING` leaves 8 KiB)."""
    try:
        with open("/proc/self/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        start, end = int(fields[45]), int(fields[46])   # arg_start, arg_end (fields 48, 49)
    except (OSError, IndexError, ValueError):
        return
    text = b"\0".join(os.fsencode(c) for c in command)[:end - start - 1]
    ctypes.memmove(start, text + b"\0" * (end - start - len(text)), end - start)


def _serve(sock: socket.socket, owner: int, hooks):
    """Answer requests until the owner closes the socket; return (in the forked node
    only) the request to run. Both forks happen inside the tracer's fork protocol
    (``hooks``, :class:`TracerForkHooks`): its locks are taken in the zygote before the
    first, the middle process forks the node still holding them and exits, and the node
    gives them back and starts its tracer threads as a spawned process has them."""
    while True:
        message, fds = _receive(sock, max_fds=3)
        if message is None:
            return None
        hooks.before()
        try:
            middle = os.fork()
        except BaseException:
            hooks.after_parent()              # the signals and the tracer's locks back
            raise
        if middle == 0:
            middle = os.getpid()              # read here: in the node it may be gone
            try:
                node = os.fork()
            except BaseException:             # noqa: BLE001 - no node: the owner times out
                os._exit(1)
            if node == 0:
                hooks.after_child()
                return {**message, "middle": middle}, fds, sock, owner
            os._exit(0)
        hooks.after_parent()
        for fd in fds:
            os.close(fd)
        os.waitpid(middle, 0)
        # the node answers with its pid itself, once reparented; the zygote waits for
        # the owner's next request


def _become_node(message, fds, sock, owner) -> None:
    """In the forked node: take its parent, fds, group, environment and signals as
    :data:`launcher.BOOTSTRAP` and ``start_node`` give them, then report the pid."""
    middle = message["middle"]
    end = time.monotonic() + SPAWN_TIMEOUT
    while os.getppid() == middle and time.monotonic() < end:   # until it has exited
        time.sleep(0.0002)
    if os.getppid() != owner:                 # the owner is not our subreaper
        _send(sock, {"refused": "not reparented to the owner"})
        os._exit(0)
    os.setpgid(0, 0)
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
    for fd in set(fds):
        if fd > 2:
            os.close(fd)
    if message.get("cwd"):
        os.chdir(message["cwd"])
    os.environ.clear()
    os.environ.update(message["env"])
    signal.signal(signal.SIGINT, lambda s, f: os._exit(130))
    parent = int(os.environ.pop("GRAZING_LAUNCHER_PID", "0"))
    if parent:
        _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != parent:
            os._exit(143)
    _set_command_line(message["command"])
    if "numpy" in sys.modules:             # the legacy global generator: not the zygote's
        sys.modules["numpy"].random.seed()
    _send(sock, {"pid": os.getpid()})
    sock.close()


def _run(message) -> None:
    """Run the node's module as ``python -m`` does."""
    import runpy

    module = message["module"]
    sys.modules.pop(module, None)
    sys.argv = [module, *message["args"]]
    if sys.path and sys.path[0] == _STARTED_IN:   # python -c puts '' there, -m the folder
        sys.path[0] = ""
    runpy.run_module(module, run_name="__main__", alter_sys=True)


class TracerForkHooks:
    """The LTTng-UST tracer's own fork protocol, for a zygote that has imported rclpy.

    Loading rclpy's C library loads ``liblttng-ust`` (ros2_tracing's tracepoints, linked
    into rcl and rclcpp), whose constructor starts two listener threads (/proc/self/task
    goes from 1 to 3 at ``rclpy.impl.implementation_singleton``; gdb shows both in
    ``ust_listener_thread``). A fork copies only the calling thread, so a lock one of
    them held at that moment would stay held in the child. The tracer exports what its
    ``liblttng-ust-fork`` wrapper calls around ``fork()`` for this: ``before`` blocks the
    signals and takes the tracer's locks, ``after_parent`` gives them back, and
    ``after_child`` gives them back in the child and starts its listener threads again,
    so that the child is traced (or not) as a spawned process is (lttng-ust 2.12:
    ``ust_before_fork``, ``ust_after_fork_parent``, ``ust_after_fork_child``; 2.13 and
    later: the same with an ``lttng_`` prefix). :meth:`find` returns None where no tracer
    is mapped (then no thread but the zygote's own may exist)."""

    _NAMES = (("ust_before_fork", "ust_after_fork_parent", "ust_after_fork_child"),
              ("lttng_ust_before_fork", "lttng_ust_after_fork_parent",
               "lttng_ust_after_fork_child"))

    def __init__(self, before, after_parent, after_child):
        self._before, self._after_parent, self._after_child = before, after_parent, after_child
        self._saved = ctypes.create_string_buffer(128)     # a sigset_t (glibc: 128 bytes)

    @classmethod
    def find(cls):
        """The hooks of the LTTng-UST library mapped in this process (a system copy, or a
        wheel's, renamed ``liblttng-ust-<hash>.so``), or None if none is mapped."""
        try:
            with open("/proc/self/maps") as maps:
                paths = sorted({line.split()[-1] for line in maps
                                if os.path.basename(line.split()[-1]).startswith("liblttng-ust")})
        except OSError:
            return None
        for path in paths:
            try:
                lib = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
            except OSError:
                continue
            for names in cls._NAMES:
                if all(hasattr(lib, n) for n in names):
                    return cls(*(getattr(lib, n) for n in names))
        return None

    def before(self) -> None:
        self._before(self._saved)

    def after_parent(self) -> None:
        self._after_parent(self._saved)

    def after_child(self) -> None:
        self._after_child(self._saved)


class _NoHooks:
    """No tracer: a fork needs nothing around it."""

    def before(self) -> None:
        pass

    after_parent = after_child = before


def dependencies(modules) -> list:
    """The modules that ``modules`` import at their top level, transitively through the
    package's own (``grazing_control``, ``sim_node``) sources, dependencies first: read
    from the sources (ast), nothing is imported but the packages' ``__init__``."""
    import ast
    import importlib.util

    own = {"grazing_control", "sim_node"}
    order, seen = [], set()

    def spec_of(name):
        try:
            return importlib.util.find_spec(name)
        except (ImportError, ValueError):
            return None

    def visit(name):
        if name in seen:
            return
        seen.add(name)
        if name.split(".")[0] not in own:     # not looked up: that would import it
            order.append(name)
            return
        spec = spec_of(name)
        if spec is None:
            return
        if spec.origin and spec.origin.endswith(".py"):
            with open(spec.origin, encoding="utf-8") as f:
                tree = ast.parse(f.read())
            package = name if spec.submodule_search_locations else name.rpartition(".")[0]
            for node in _top_level(tree.body):
                if isinstance(node, ast.Import):
                    for alias in node.names:
                        visit(alias.name)
                elif isinstance(node, ast.ImportFrom):
                    base = node.module or ""
                    if node.level:
                        parts = package.split(".")
                        base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
                    visit(base)
                    base_spec = spec_of(base) if base.split(".")[0] in own else None
                    if base_spec is not None and base_spec.submodule_search_locations:
                        for alias in node.names:     # a package's submodules
                            if spec_of(f"{base}.{alias.name}") is not None:
                                visit(f"{base}.{alias.name}")
        order.append(name)

    for module in modules:
        visit(module)
    return order


def _top_level(body):
    """The statements run at import: the module's, and those inside its top-level
    ``if``/``try`` blocks."""
    import ast

    for node in body:
        yield node
        if isinstance(node, ast.If):
            yield from _top_level(node.body + node.orelse)
        elif isinstance(node, ast.Try):
            yield from _top_level(node.body + node.orelse + node.finalbody
                                  + [s for h in node.handlers for s in h.body])


def _threads() -> int:
    return len(os.listdir("/proc/self/task"))


def _load_type_supports() -> None:
    """Load the C type support of every message and service class imported so far (what
    rclpy does on a type's first publisher, subscription or service: a C extension per
    package, and the libraries it links), so that each node does not load it again."""
    for name, module in list(sys.modules.items()):
        parts = name.split(".")
        if module is None or len(parts) != 3 or parts[1] not in ("msg", "srv", "action"):
            continue
        for value in list(vars(module).values()):
            meta = type(value)
            if (isinstance(value, type) and getattr(meta, "_TYPE_SUPPORT", 0) is None
                    and hasattr(meta, "__import_type_support__")):
                meta.__import_type_support__()


def _map_modules_for_inspect() -> None:
    """Fill inspect's map from module files to modules, which the nodes inherit. rclpy's
    logger asks inspect where each log call comes from (``CallerId``), and inspect's first
    answer in a process walks every module imported, a ``realpath`` each: a node's first
    log line took 116 ms of CPU (1253 modules, a slow host) and the next ones 1.2 ms.
    A forked node now walks only what it imports after the fork."""
    inspect.getmodule(None, os.devnull)


def _prepare(modules):
    """Import what the node modules import, rclpy included, load their message types'
    C type supports and the compiled kernels; the node modules themselves are left to run
    as ``__main__``. Returns the fork hooks (:class:`TracerForkHooks`, or nothing to do);
    ValueError if a thread exists that a fork would lose and nothing accounts for."""
    if _threads() != 1:
        raise ValueError(f"{_threads()} threads before the imports")
    # rclpy's C library first: the threads it starts are the tracer's, forked around
    importlib.import_module("rclpy.impl.implementation_singleton")

    traced = _threads()
    hooks = TracerForkHooks.find()
    if traced > 1 and (hooks is None or traced > 3):
        raise ValueError(f"{traced} threads after loading rclpy's C library, "
                         f"{'no tracer mapped' if hooks is None else 'the tracer starts 2'}")
    for name in dependencies(modules):
        if name not in modules:
            try:
                importlib.import_module(name)
            except ImportError:
                pass           # the node imports it and says what is missing, as spawned
    _load_type_supports()
    from grazing_control.dynamics.estimation.stream import warm_up_all

    warm_up_all()          # the kernel and the model filters, as nodes load them at start
    _map_modules_for_inspect()
    if _threads() != traced:
        raise ValueError(f"{_threads()} threads after the imports, {traced} before them")
    return hooks if hooks is not None else _NoHooks()


def main(argv) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # the owner ends it (EOF, PDEATHSIG)
    fd, owner = int(argv[0]), int(argv[1])
    modules = [m for m in argv[2:] if m != _PADDING]
    sock = socket.socket(fileno=fd)
    _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != owner:
        os._exit(143)
    try:
        hooks = _prepare(modules)
    except Exception as exc:              # noqa: BLE001 - the owner spawns as before
        _send(sock, {"ready": False, "error": f"{type(exc).__name__}: {exc}"})
        return
    # the imports' objects to the collector's permanent generation: a node's collections
    # would otherwise walk them all and write every page they are on (copy on write)
    gc.freeze()
    _send(sock, {"ready": True})
    request = _serve(sock, owner, hooks)
    if request is None:
        return
    _become_node(*request)
    _run(request[0])


if __name__ == "__main__":
    main(sys.argv[1:])

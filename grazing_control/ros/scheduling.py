"""Real-time scheduling of a node's process: SCHED_FIFO priority, CPU affinity, locked memory.

What ros2_control's controller manager offers (its ``thread_priority``, ``cpu_affinity``
and ``lock_memory`` parameters), for the nodes of a realtime scene (docs/nodes.md,
"Real-time scheduling"). Each option is opt-in; where the process lacks the privilege
(no CAP_SYS_NICE / CAP_IPC_LOCK, an RLIMIT_RTPRIO of 0, a container that forbids it) the
option is not applied and a clear warning says what was refused and how to grant it:
the node runs on, never crashes. Linux only; elsewhere every option is refused with a
warning.

* priority p in 1..99: ``sched_setscheduler(0, SCHED_FIFO, p)`` for the whole process:
  every thread it has (the middleware's receive threads included, /proc/self/task) and
  every thread it creates afterwards (they inherit it), once its start-up work is done
  (:func:`raise_node_priority`). 0 leaves the scheduler alone.
* cpus: ``sched_setaffinity(0, cpus)``.
* lock memory: ``mlockall(MCL_CURRENT | MCL_FUTURE)``, so that no page of the process
  is paged out (and faulted back in, a millisecond) during a scene.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from typing import NamedTuple

__all__ = ["Scheduling", "parse_cpus", "apply_scheduling", "declare_scheduling",
           "apply_node_scheduling", "raise_node_priority"]

_MCL_CURRENT, _MCL_FUTURE = 1, 2


class Scheduling(NamedTuple):
    """What was asked and what was applied, with the warnings for what was refused."""

    applied: tuple
    warnings: tuple


def parse_cpus(text: str) -> tuple:
    """'0,2-3' -> (0, 2, 3); '' -> () (no affinity). ValueError naming the parameter."""
    cpus = set()
    for part in (p.strip() for p in str(text).split(",")):
        if not part:
            continue
        try:
            if "-" in part:
                lo, hi = (int(x) for x in part.split("-", 1))
                if lo > hi:
                    raise ValueError
                cpus.update(range(lo, hi + 1))
            else:
                cpus.add(int(part))
        except ValueError:
            raise ValueError(f"cpu_affinity={text!r} is invalid: valid values are CPU numbers "
                             "and ranges like '0,2-3' ('' for none)") from None
    if any(c < 0 for c in cpus):
        raise ValueError(f"cpu_affinity={text!r} is invalid: CPU numbers are >= 0")
    return tuple(sorted(cpus))


def _mlockall() -> int:
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
        return ctypes.get_errno()
    return 0


def apply_scheduling(priority: int = 0, cpus=(), lock_memory: bool = False) -> Scheduling:
    """Apply the options to this process; refused ones become warnings (module docstring).

    ValueError for a priority outside 0..99 (the caller's parameter validation);
    everything the operating system refuses is a warning, never an exception.
    """
    _check_priority(priority)
    applied, warnings = [], []
    if priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
            _threads_too(os.SCHED_FIFO, int(priority))
            applied.append(f"SCHED_FIFO priority {int(priority)}")
        except (PermissionError, OSError, AttributeError) as exc:
            warnings.append(f"thread_priority={int(priority)} not applied ({_reason(exc)}): "
                            "grant CAP_SYS_NICE or an rtprio limit (ulimit -r, "
                            "/etc/security/limits.conf) to run under SCHED_FIFO")
    if cpus:
        try:
            os.sched_setaffinity(0, set(cpus))
            applied.append(f"CPU affinity {sorted(cpus)}")
        except (PermissionError, OSError, AttributeError) as exc:
            warnings.append(f"cpu_affinity={sorted(cpus)} not applied ({_reason(exc)}): "
                            f"this machine's CPUs are {_cpus()}")
    if lock_memory:
        try:
            err = _mlockall()
        except (OSError, AttributeError) as exc:
            err = getattr(exc, "errno", None) or -1
        if err == 0:
            applied.append("memory locked (mlockall)")
        else:
            warnings.append(f"lock_memory not applied ({os.strerror(err) if err > 0 else err}): "
                            "grant CAP_IPC_LOCK or raise the memlock limit (ulimit -l)")
    return Scheduling(tuple(applied), tuple(warnings))


def _threads_too(policy: int, priority: int) -> None:
    """The same policy for every other thread the process already has (Linux: each
    thread of /proc/self/task is its own scheduling entity): the middleware's receive
    threads exist once the node does, and left under SCHED_OTHER they kept the samples
    waiting for a core behind every other process (a rig scene's sensor latency p99 217 ms
    at load 6 with only the main thread real-time, docs/rig_scene.md). A thread that ends
    meanwhile is skipped."""
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return
    for tid in tids:
        try:
            os.sched_setscheduler(tid, policy, os.sched_param(priority))
        except ProcessLookupError:
            pass


def _reason(exc: BaseException) -> str:
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else type(exc).__name__


def _cpus() -> str:
    try:
        return str(sorted(os.sched_getaffinity(0)))
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        return "unknown"


def declare_scheduling(node) -> None:
    """Declare a node's three read-only scheduling parameters (docs/nodes.md).

    ``thread_priority`` (0 = off, 1..99 SCHED_FIFO), ``cpu_affinity`` ('' = any, '0,2-3'),
    ``lock_memory`` (mlockall), as ros2_control's controller manager offers them.
    """
    from rcl_interfaces.msg import (IntegerRange, ParameterDescriptor, ParameterType)

    node.declare_parameter("thread_priority", 0, ParameterDescriptor(
        type=ParameterType.PARAMETER_INTEGER, read_only=True,
        description="real-time scheduling: SCHED_FIFO priority 1..99 of the process, "
                    "0 = off (a warning where not permitted)",
        integer_range=[IntegerRange(from_value=0, to_value=99, step=1)]))
    node.declare_parameter("cpu_affinity", "", ParameterDescriptor(
        type=ParameterType.PARAMETER_STRING, read_only=True,
        description="real-time scheduling: CPUs to run on, e.g. '1' or '0,2-3'; '' = any"))
    node.declare_parameter("lock_memory", False, ParameterDescriptor(
        type=ParameterType.PARAMETER_BOOL, read_only=True,
        description="real-time scheduling: lock the process's memory (mlockall; a warning "
                    "where not permitted)"))


def apply_node_scheduling(node) -> Scheduling:
    """Apply a node's CPU affinity and memory lock as it starts, and check its priority;
    log what was applied and what was refused. The priority itself waits for
    :func:`raise_node_priority`, once the node's start-up work is done: under SCHED_FIFO
    that work (imports, compiling or loading numba's cache, the estimator's warm-up, 1.5-2.6
    s of CPU) ran at 100 % of both CPUs, so that no other process ran for a second (the
    recorder starting, another scene's loop) and the kernel throttled the real-time
    threads for the rest of the second (docs/benchmarks.md, "The start under
    SCHED_FIFO").

    ValueError for a malformed value (the caller turns it into its startup error).
    """
    priority = node.get_parameter("thread_priority").value
    _check_priority(priority)
    return _log(node, apply_scheduling(0, parse_cpus(node.get_parameter("cpu_affinity").value),
                                       node.get_parameter("lock_memory").value))


def raise_node_priority(node) -> Scheduling:
    """The node's ``thread_priority`` (SCHED_FIFO for every thread of its process) when
    its loop is about to run: the simulator at its start (sim_node.start.due, before the
    feasibility probe, so that the probe's round trips are those of the scene), the
    controller at the end of its start-up. Logged; once per node (later calls return
    what the first did)."""
    done = getattr(node, "_priority_raised", None)
    if done is None:
        done = node._priority_raised = _log(
            node, apply_scheduling(node.get_parameter("thread_priority").value))
    return done


def _check_priority(priority) -> None:
    if isinstance(priority, bool) or int(priority) != priority or not 0 <= priority <= 99:
        raise ValueError(f"thread_priority={priority!r} is invalid: valid range is 0 (off) "
                         "or 1..99 (SCHED_FIFO)")


def _log(node, sched: Scheduling) -> Scheduling:
    for warning in sched.warnings:
        node.get_logger().warning(warning)
    if sched.applied:
        node.get_logger().info("real-time scheduling: " + ", ".join(sched.applied))
    return sched

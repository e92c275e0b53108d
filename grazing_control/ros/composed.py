"""A scene's nodes in one process on one executor (``grazing run --compose``, issue 30).

ROS 2 composes nodes into one process (component containers) so that they share one
interpreter's start-up and one DDS participant, and a message between them is delivered
in the process (Fast DDS's intra-process delivery: no transport, no socket wake-up).
Here sim_node, controller_node and, when recording, recorder_node are built in one
Python process from the same command lines the launcher gives their processes (each
node's ``--ros-args --params-file F -p name:=value ...`` as its ``cli_args``). The
simulator and the controller share one executor of the simulator's ``executor`` kind,
spun by one thread: in lockstep a Pi2 sample's callback in the controller runs right
after the simulator's publish returns, its answer's right after the controller's. The
recorder runs its own loop on its own executor in a second thread (:func:`_start_recorder`).

The end is the launcher's order (:func:`grazing_control.ros.launcher.run`), inside the
process: the simulator ends (its published record, every reader's acknowledgements),
then the controller (its record, the recorder's confirmation), then the recorder takes
what is left and closes the bag. Each node's exit status goes to ``--statuses FILE``
(a JSON object ``{node: status}``, written whole), and the process's status is the
largest. SIGINT/SIGTERM stop the spin and run the same end, as for the separate
processes. The nodes' behaviour is theirs: the same classes, parameters and checks
(a lockstep scene composed is bit-identical to the separate processes':
tests/test_composed.py).

Run by the launcher (``run(..., compose=True)``): ``python -m grazing_control.ros.composed
--spec SPEC.json --statuses OUT.json`` with SPEC ``{"sim_node": [args], "controller_node":
[args], "recorder_node": [args] or null}``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import threading

from .entry import MODULES

__all__ = ["NODES", "main", "write_statuses"]

#: The nodes a composed scene holds, in the order they are built (the recorder first, so
#: that it has subscribed when the others' latched records go out, as the launcher starts
#: its process first). The simulator first, so that its kernel would load in its thread
#: while the others are built, was slower: overhead 1.67 s against 1.31 s, medians of 4
#: side by side at load 3 (benchmarks/bench_scene_overhead.py --only-composed).
NODES = ("recorder_node", "controller_node", "sim_node")


class _Stop:
    """SIGINT/SIGTERM: asked to stop (the spin ends, the nodes' ends run)."""

    asked = False


def _on_signal(signum, frame):
    _Stop.asked = True


def write_statuses(path: str, statuses: dict) -> None:
    """``statuses`` as one JSON object to ``path``, whole (a file renamed over it)."""
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(statuses, fh)
    os.replace(tmp, path)


def _build(spec: dict, statuses: dict, log):
    """The nodes of ``spec`` built in :data:`NODES` order; {name: node}. A node that
    refuses to start (StartupError, ParameterError, a parameter exception, an unknown
    ``-p`` name) gets status 2 and nothing else is built."""
    from rclpy.exceptions import ParameterException

    from grazing_control.oscillator.params import ParameterError
    from .common import StartupError, _startup_message
    from .node_arguments import check_overrides, parse_node_arguments

    nodes = {}
    for name in NODES:
        args = spec.get(name)
        if args is None:
            continue
        module = importlib.import_module(MODULES[name])
        arguments = parse_node_arguments(["x", *args])
        try:
            if name == "recorder_node":
                node = module.RecorderNode(arguments, cli_args=list(args))
            else:
                node = (module.SimNode if name == "sim_node" else module.ControllerNode)(
                    cli_args=list(args))
                try:
                    check_overrides(node, arguments)
                except StartupError:
                    node.on_exit = lambda: None     # it never ran: no summary
                    nodes[name] = node
                    raise
        except (StartupError, ParameterException, ParameterError, OSError) as exc:
            log(name).error(_startup_message(exc))
            statuses[name] = 2
            break
        nodes[name] = node
    return nodes


def _spin_scene(executor, nodes: dict) -> None:
    """Spin the simulator and the controller until the scene ends (or the controller's
    isolation check stops it, or a signal), the controller's work between the waits as
    in its own process (ControllerNode.between_waits)."""
    from .common import SIGNAL_POLL

    sim, ctl = nodes["sim_node"], nodes["controller_node"]
    while not _Stop.asked and not sim.exit_now and not ctl.exit_now:
        executor.spin_once(timeout_sec=SIGNAL_POLL)
        ctl.between_waits()


def _start_recorder(rec):
    """The recorder's loop (recorder_node.record_until) on an executor of its own, in a
    thread: it takes the queued messages from inside its callbacks, which the
    EventsExecutor does not allow (a message taken behind its back: "SystemError: null
    argument to internal routine"), and it waits its ``batch_window`` between takes.
    Returns (the thread, the Event that stops it)."""
    from rclpy.executors import SingleThreadedExecutor

    from .recorder_node import record_until

    stop = threading.Event()
    executor = SingleThreadedExecutor()
    executor.add_node(rec)
    worker = threading.Thread(target=record_until, args=(rec, executor, stop),
                              name="recorder", daemon=True)
    worker.start()
    return worker, stop


def run(spec: dict, statuses_path: str | None) -> int:
    """Build, spin and end the composed scene; returns the process's exit status."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from .common import make_executor, settle_heap
    from .published import ACK_TIMEOUT, close_publishers

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    statuses = {name: None for name in NODES if spec.get(name) is not None}
    nodes = {}
    executor = recording = None
    try:
        nodes = _build(spec, statuses, rclpy.logging.get_logger)
        rec = nodes.get("recorder_node")
        if rec is not None:
            recording = _start_recorder(rec)
        sim, ctl = nodes.get("sim_node"), nodes.get("controller_node")
        if ctl is not None and rec is not None:
            # its reader stays in the graph until the recorder has closed: no linger
            ctl.recorder.linger = 0.0
        # the simulator's executor kind; one also when a node refused to start, for the
        # others' ends (the controller spins it while it waits for the recorder)
        executor = make_executor(getattr(sim, "executor_kind", "single_threaded"))
        for node in (sim, ctl):
            if node is not None:
                executor.add_node(node)
        if all(n in nodes for n in statuses) and not any(statuses.values()):
            settle_heap()
            _spin_scene(executor, nodes)
            # the simulator's end (its spin_until after the spin): no more answers taken,
            # its published record, the readers' acknowledgements
            if sim.exit_now:
                sim.stop_answers()
                close_publishers(sim.published, ACK_TIMEOUT, also=(sim.pub_done,))
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        for name in ("sim_node", "controller_node"):     # the launcher's order
            node = nodes.get(name)
            if node is not None:
                node.on_exit()
                if statuses.get(name) is None:
                    statuses[name] = int(getattr(node, "exit_code", 0))
        if recording is not None:
            worker, stop = recording
            stop.set()
            worker.join()
            statuses["recorder_node"] = statuses.get("recorder_node") or \
                nodes["recorder_node"].close()
    statuses = {k: (0 if v is None else v) for k, v in statuses.items()}
    if statuses_path:
        write_statuses(statuses_path, statuses)
    code = max(statuses.values(), default=0)
    _leave(nodes, executor)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _leave(nodes: dict, executor, timeout: float = 3.0) -> None:
    """Destroy the nodes and the context (the peers see them leave, nothing of the
    participant is left), ``timeout`` s at most
    (:func:`grazing_control.ros.common.leave_graph`, with every node)."""
    from .common import leave_graph

    if nodes:
        leave_graph(list(nodes.values()), executor, timeout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m grazing_control.ros.composed",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--spec", required=True, help="JSON: {node: [its ROS arguments]}")
    ap.add_argument("--statuses", default=None, help="write {node: exit status} here")
    args = ap.parse_args(argv)
    with open(args.spec, encoding="utf-8") as fh:
        spec = json.load(fh)
    return run(spec, args.statuses)


if __name__ == "__main__":
    sys.exit(main())

"""Entry points of the node executables: quiet on a Ctrl-C at any moment, importing included.

A node's module imports rclpy, numpy and the layers below it, which takes a second or
more on a loaded machine. The console script that setuptools writes imports the module
before calling ``main``, so a Ctrl-C in that time ended the process with a
KeyboardInterrupt traceback (``ros2 launch`` stopped while its nodes were starting; the
one ``colcon test`` failure, issue 27 §2). Each executable's entry point is a function
here, in a module that imports nothing heavy: it installs a SIGINT handler, imports the
node's module and calls its ``main``, which replaces the handler with its own first
thing (:func:`grazing_control.ros.common.run_node`, ``recorder_node.main``).

A SIGINT while importing ends the process at once (``os._exit``) with status 0, without
a traceback, as a Ctrl-C of a running node does (run_node; ros2/demos' nodes return
normally from KeyboardInterrupt): a launch that stops its nodes sees the same status
whenever the signal lands (launch/grazing_control.launch.py treats a nonzero status
outside a shutdown as a failed node). The handler exits rather than raising for the
reason of :mod:`grazing_control.cli.console`: an exception raised inside an extension
module's import is turned into another error by that module (numpy). Nothing has run yet,
so there is nothing to clean up. Only Python's own start, before this module is reached,
remains Python's to report.
"""

import importlib
import os
import signal
import sys

__all__ = ["MODULES", "sim_node", "controller_node", "recorder_node", "live_node",
           "effort_bridge", "rig_mock"]

#: Executable name -> the module whose ``main(args=None)`` runs it.
MODULES = {
    "sim_node": "sim_node.sim_node",
    "controller_node": "grazing_control.ros.controller_node",
    "recorder_node": "grazing_control.ros.recorder_node",
    "live_node": "grazing_control.ros.live_node",
    "effort_bridge": "grazing_control.ros.effort_bridge",
    "rig_mock": "grazing_control.recordings.rig_mock",
}


def _interrupted(signum, frame):
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _run(name: str):
    """Import the node module of ``name`` with a quiet SIGINT, then run its ``main``."""
    signal.signal(signal.SIGINT, _interrupted)     # until main installs its own
    return importlib.import_module(MODULES[name]).main()


def sim_node():
    """The ``sim_node`` executable (:mod:`sim_node.sim_node`)."""
    return _run("sim_node")


def controller_node():
    """The ``controller_node`` executable (:mod:`grazing_control.ros.controller_node`)."""
    return _run("controller_node")


def recorder_node():
    """The ``recorder_node`` executable (:mod:`grazing_control.ros.recorder_node`)."""
    return _run("recorder_node")


def live_node():
    """The ``live_node`` executable (:mod:`grazing_control.ros.live_node`)."""
    return _run("live_node")


def effort_bridge():
    """The ``effort_bridge`` executable (:mod:`grazing_control.ros.effort_bridge`)."""
    return _run("effort_bridge")


def rig_mock():
    """The ``rig_mock`` executable (:mod:`grazing_control.recordings.rig_mock`)."""
    return _run("rig_mock")

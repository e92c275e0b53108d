"""One description of a scene's nodes, for `grazing run` and for `ros2 launch` alike.

The launcher (:mod:`.launcher`, plain processes) and the launch file
(``launch/grazing_control.launch.py``) had drifted apart: the design's actuation delay
reached the simulator through one and not the other, and so did the scene token, the
controller's model of the plant and the realtime answer rule (issue 19 §3). Both now take
every node's parameter overrides from :func:`scene_overrides`; the launch file adds only
what is launch's own (namespaces, remappings, the exit handlers).
"""

from __future__ import annotations

import os
import random

__all__ = ["NODES", "scene_overrides", "design_delay", "design_model", "new_token",
           "parameter_values", "sim_values_for_model", "sim_values_for_rig"]

#: The scene's nodes in start order (the recorder first, so that it matches every topic
#: before the simulator starts; the live view, which nothing waits for; the simulator
#: last).
NODES = ("recorder_node", "live_node", "controller_node", "sim_node")


def design_delay(controller_params):
    """``actuation_delay`` of the controller's parameters (``grazing design --delay``): a
    parameter file's path (any node key, e.g. ``/**``) or a dict; None if absent or the
    file cannot be read (the node then reports the file itself)."""
    delay = _controller_values(controller_params).get("actuation_delay")
    return float(delay) if isinstance(delay, (int, float)) and not isinstance(delay, bool) \
        else None


def design_model(controller_params):
    """``model_file`` of the controller's parameters (an n-DOF design's gain file,
    :func:`grazing_control.dynamics.design.family.write_gain_yaml`), else None: the model the
    gains were designed for, the scene's model when none is given (issue 17)."""
    path = _controller_values(controller_params).get("model_file")
    return path if isinstance(path, str) and path else None


def parameter_values(params) -> dict:
    """A node's parameters: a file's ``ros__parameters`` (any node key) or a dict; {} if
    the file cannot be read (the node then reports the file itself)."""
    return _controller_values(params)


def _positive(value) -> bool:
    """Whether a parameter's value is a number > 0 (a bool is not a number here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0.0


def _controller_values(controller_params) -> dict:
    """The controller's parameters: a file's ``ros__parameters`` (any node key) or a
    dict; {} if the file cannot be read."""
    from grazing_control.support.files import YamlFileError, read_yaml_file, ros_parameters
    if isinstance(controller_params, (str, os.PathLike)):
        try:
            values = ros_parameters(read_yaml_file(controller_params))
        except YamlFileError:
            return {}
    else:
        values = dict(controller_params or {})
    return values


def sim_values_for_model(sim_params) -> dict:
    """The simulator's parameter file (a path: its ``ros__parameters`` under any node
    key; or a dict) without the study model's parameters (zeta, r, omega, delta_d, tau0,
    pi2_offset): what an n-DOF scene's simulator takes from the study's file, whose model
    the model file replaces (docs/nodes.md, "n-DOF scenes")."""
    from grazing_control.plant.settings import MODEL_KEYS
    from grazing_control.support.files import read_yaml_file, ros_parameters

    if isinstance(sim_params, (str, os.PathLike)):
        values = ros_parameters(read_yaml_file(sim_params))
    else:
        values = dict(sim_params or {})
    return {k: v for k, v in values.items() if k not in MODEL_KEYS}


def sim_values_for_rig(sim_params) -> dict:
    """The simulator's parameter file without what a rig file sets (its model, sensor,
    pulse, budget, pace: ros.rig_boundary.SIM_KEYS) and without its mode (a rig scene is
    realtime): what a rig scene's simulator takes from the study's file."""
    from grazing_control.ros.rig_boundary import SIM_KEYS

    return {k: v for k, v in sim_values_for_model(sim_params).items()
            if k not in SIM_KEYS and k != "mode"}


def new_token() -> str:
    """A random scene token (ros/scene.py): this scene's nodes recognise each other."""
    return f"{os.getpid():x}-{random.getrandbits(48):012x}"


#: How a correction acts in the plant: the simulator's parameters that the controller
#: takes from it in a plain scene, of the same names (controller_node.PULSE_KEYS).
ACTUATION_KEYS = ("pulse_width", "force_limit", "actuator_bandwidth", "actuator_latency")

#: A rig scene at physical speed (issue 28): the simulated DAQ delivers the 2 kHz stream
#: in blocks of 2 ms (4 samples; sim_node's stream_block) and the recorder takes what
#: gathered every 20 ms (its batch_window): one wake-up per sample in each cost the
#: simulator 21 and the recorder 15 CPU seconds of a 52 s scene, 12.5 and 6.5 with these
#: (docs/rig_scene.md, "Where the time went").
RIG_STREAM_BLOCK = 2e-3
RIG_BATCH_WINDOW = 0.02
#: A rig's or any realtime scene's simulator and controller run under SCHED_FIFO (their
#: thread_priority, ros/scheduling.py; where the process may not, a warning and the
#: scene runs on): a rig scene at load 11-15 on this 2-core machine missed 3 of 700
#: sections with it, 202-578 at load 7-10 without (docs/rig_scene.md, "Where the time
#: went"); a realtime scene at x1000 beside other work, answer latency p99 0.72 ms
#: against 4.8 ms, T/200 2 misses of 1000 against 549 (docs/benchmarks.md, "the realtime
#: numbers under SCHED_FIFO").
REALTIME_THREAD_PRIORITY = 50


def scene_overrides(controller_params, *, periods=None, delta_d=None, enable_after=None,
                    mode=None, bag=None, token=None, sim_overrides=None,
                    controller_overrides=None, recorder_overrides=None, model=None,
                    live=None, rig=None) -> dict:
    """Node name -> its ``-p key:=value`` overrides (recorder: None without ``bag``; live
    view: None without ``live``).

    - sim_node: exits when done, waits for its controller (and, recording, for the
      recorder's ``recorder/ready`` and one subscriber per topic), ``max_periods``,
      ``delta_d``, ``mode``, and the design's ``actuation_delay`` (and ``pulse_width``,
      a pulsed n-DOF design's: ``grazing design --model M --pulse-width W``, with a model
      file also its ``actuator_bandwidth`` and ``actuator_latency``) from the
      controller's parameters (a simulator applying another delay refuses to start);
    - controller_node: ``enable_after``; the plant's ``delta_d``, ``sensor_noise``,
      ``state_period`` and ``stream_message`` when the simulator's are set (its
      estimator's model, the stream's messages), and without a model or rig file its
      ``pulse_width``, ``force_limit``, ``actuator_bandwidth`` and ``actuator_latency``
      (how a correction acts: the estimator's and the prediction's); answers
      after the section in realtime;
    - recorder_node: ``output`` = bag, ``require_complete``;
    - live_node (docs/live.md): ``port`` = live (0..65535; 0: any free port, logged);
    - both simulator and controller: the scene token; with ``model`` (an n-DOF model
      file, issue 17) its path as ``model_file``; with ``rig`` (a rig file, issue 28) its
      path as ``rig_file`` (the simulated rig and the controller speak the driver
      contract, docs/driver_contract.md), the simulator in realtime (physical speed) and
      the recorder also recording the contract's topics (``rig_topics``); the
      simulator's stream in blocks of RIG_STREAM_BLOCK, the recorder's batch_window
      RIG_BATCH_WINDOW (the CPU they save, docs/rig_scene.md "Where the time went"),
      both nodes under SCHED_FIFO (below);
    - a realtime scene's (a rig's, or ``mode`` realtime): the simulator and the
      controller under SCHED_FIFO, thread_priority REALTIME_THREAD_PRIORITY unless
      given (the controller's ``thread_priority`` 0 turns it off for both, the
      simulator's own overrides its one).
    """
    sim = {"exit_when_done": True, "wait_for_controller": True,
           "wait_for_subscribers": 1 if bag is not None else 0,
           "wait_for_recorder": bag is not None}
    if periods is not None:
        sim["max_periods"] = int(periods)
    if delta_d is not None:
        sim["delta_d"] = float(delta_d)
    if mode is not None:
        sim["mode"] = str(mode)
    controller = dict(controller_overrides or {})
    # an n-DOF or rig scene: both read the file, unless the controller is given its own
    # (a model-error scene: the controller designed on another model; it was overwritten
    # without a word before)
    if model is not None:
        sim["model_file"] = os.path.abspath(os.fspath(model))
        controller.setdefault("model_file", sim["model_file"])
    if rig is not None:
        sim["rig_file"] = os.path.abspath(os.fspath(rig))
        controller.setdefault("rig_file", sim["rig_file"])
        sim["mode"] = "realtime" if mode is None else str(mode)
        sim["stream_block"] = RIG_STREAM_BLOCK
    delay = controller.get("actuation_delay", design_delay(controller_params))
    if delay is not None:               # the gains' design delay is the simulator's too
        sim["actuation_delay"] = delay
    design = _controller_values(controller_params)
    width = controller.get("pulse_width", design.get("pulse_width"))
    if _positive(width):
        sim["pulse_width"] = float(width)   # and a pulsed design's pulse (n-DOF, §15)
        for key in ("actuator_bandwidth", "actuator_latency") if model is not None else ():
            value = controller.get(key, design.get(key))   # and its actuator (the n-DOF
            if _positive(value):                          # gain file's)
                sim[key] = float(value)
    sim.update(sim_overrides or {})
    if rig is not None or sim.get("mode") == "realtime":     # a scene about deadlines
        sim.setdefault("thread_priority",
                       controller.setdefault("thread_priority", REALTIME_THREAD_PRIORITY))
    for key in ("delta_d", "sensor_noise", "state_period",   # the controller's model of
                "stream_message"):                           # the plant and its sensor
        if key in sim:
            controller.setdefault(key, sim[key])
    if model is None and rig is None:    # and of its actuation (a model file's and a rig's
        for key in ACTUATION_KEYS:       # come with their gains)
            if key in sim:
                controller.setdefault(key, sim[key])
    if sim.get("mode") == "realtime" and rig is None:   # a stream controller answers after t_k
        controller.setdefault("answer_after_section", True)
    if enable_after is not None:
        controller["enable_after"] = int(enable_after)
    sim.setdefault("scene", token if token is not None else new_token())
    controller.setdefault("scene", sim["scene"])
    recorder = None
    if bag is not None:
        recorder = {"output": os.fspath(bag), "require_complete": True}
        if rig is not None:
            recorder["rig_topics"] = True
            recorder["batch_window"] = RIG_BATCH_WINDOW
        recorder.update(recorder_overrides or {})
    return {"sim_node": sim, "controller_node": controller, "recorder_node": recorder,
            "live_node": None if live is None else {"port": int(live)}}
